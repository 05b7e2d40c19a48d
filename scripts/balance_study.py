"""Balance study: the largest platform tilt the robot stands, as a function of the balance gains.

For each controller (REACTION_CONTROL, BALANCE_CONTROL) and each gain of a sweep, the ``stand``
scenario is run on a platform that tilts at 1 deg/s (as ``humanoid-twin run stand --tilt DEG``)
and the largest tilt *held* is found by bisection: held = the robot did not fall and the
ground-truth CoP stayed strictly inside the support polygon for the whole run (ramp + 2 s of
settling). The same search with the controllers off (NO_CONTROL) gives the reference line.

Gains (docs/balance.md): in double support the right leg's board runs the law with the gain
``g = KP / 2**KD`` (the leader) and the left leg's board runs it with ``-FOLLOW_RATIO * g`` (the
compliant follower); the ankle roll gains are 0 (the lateral CoP of a foot in double support is an
internal force). The effective gain on the x axis is ``g`` in the firmware's units.

Built on the sweep API (humanoid_twin/sweep, docs/sweeps.md): the bisections of all the lines
(controller, gain, tilt direction) advance together, one grid of runs per step (the first grid: every
line at the top of the search; then every unresolved line at its mid-point), on the local process
pool (``--jobs``, default the cores) or on Ray (``--backend ray [--address ADDR]``). Every run is a
row of ``--runs`` (default ``out/balance_study_runs.csv``); running again with the same table runs
nothing already there (an interrupted study resumes; an unchanged one only redraws).

Writes ``balance_study.md`` (a markdown table) and ``balance_study.png`` into ``--out-dir``
(default the scratch folder ``out/``; ``--out-dir docs`` regenerates the docs' copies) and prints the
table. ``--quick``: 3 gains instead of 7.

    python scripts/balance_study.py [--quick] [--out-dir out] [--runs FILE.csv] [--jobs N]
                                    [--backend local|ray] [--address ADDR]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from humanoid_twin.host.planners import control_row
from humanoid_twin.plan import STAND_KD, STAND_LEAD_KP
from humanoid_twin.plant.plant import TILT_MAX_DEG as PLATFORM_TILT_MAX_DEG
from humanoid_twin.protocol.wire import ControlType
from humanoid_twin.rig import Rig, RigOptions
from humanoid_twin.scenarios import (
    SETTLE_S,
    TILT_RATE_DEG_S,
    Plan,
    hold,
    plan,
)
from humanoid_twin.summary import NO_SUPPORT_MARGIN_MM
from humanoid_twin.sweep import Point, run_sweep

FOLLOW_RATIO = 8          # the follower complies 8 times as fast as the leader balances
TILT_RES_DEG = 1.0        # bisection resolution
TILT_MAX_DEG = PLATFORM_TILT_MAX_DEG - TILT_RES_DEG   # the top of the search, one step inside the platform


@dataclass(frozen=True)
class Gain:
    """A leader gain ``kp / 2**kd`` (KP a signed byte, KD the exponent byte)."""

    kp: int
    kd: int

    @property
    def value(self) -> float:
        return self.kp / 2**self.kd

    def label(self) -> str:
        return f"{self.kp}/2^{self.kd}" if self.kd else f"{self.kp}"


def stand_plan(ctype: ControlType, g: Gain) -> Plan:
    """The ``stand`` scenario's plan with leader (right leg) / follower (left leg) balance gains
    ``g`` on the foot front joint only (ankle roll and knee gains 0, docs/balance.md), hips on
    LOCOMOTION; with NO_CONTROL every leg and hip board is off."""
    p = plan("stand")
    k = p.k.copy()
    if ctype == ControlType.NO_CONTROL:
        k[:4, :, 0] = 0
        return Plan(p.pos_apply, k, p.t)
    for scu, kp in ((1, g.kp), (2, -FOLLOW_RATIO * g.kp)):
        k[scu - 1, :, 0] = control_row(ctype, ((0, 0, g.kd), (0, kp, g.kd), (0, 0, g.kd)))
    for scu in (3, 4):
        k[scu - 1, :, 0] = control_row(ControlType.LOCOMOTION_CONTROL)
    return Plan(p.pos_apply, k, p.t)


def run_stand(ctype: ControlType, g: Gain | None, tilt: float, seed: int = 0) -> dict[str, Any]:
    """One ``stand --tilt`` run with the given gains (a :class:`Rig`, as ``run`` assembles one);
    returns the Monitor's verdict."""
    with Rig(RigOptions(seed=seed, tilt=tilt)) as rig:
        H = rig.boot()                        # the platform tilts from the boot's end
        boot_s = rig.now_s
        hold(H, stand_plan(ctype, g or Gain(0, 0)))
        rig.sleep_until(boot_s + abs(tilt) / TILT_RATE_DEG_S + SETTLE_S)
        margin = rig.monitor.cop_margin_min_mm
        return {
            "fell": rig.monitor.fell,
            "cop_margin_min_mm": margin if math.isfinite(margin) else NO_SUPPORT_MARGIN_MM,
            "trunk_tilt_max_deg": rig.monitor.trunk_tilt_max_deg,
        }


def held(r: dict[str, Any]) -> bool:
    """Stood: not fallen, the CoP strictly inside the support polygon all along."""
    return not r["fell"] and r["cop_margin_min_mm"] > 0.0


def stand_point(point: Point) -> dict[str, Any]:
    """The sweep task: one ``stand --tilt`` run of a grid point (controller, kp, kd, tilt)."""
    p = dict(point.params)
    ctype = ControlType[p["controller"]]
    r = run_stand(ctype, Gain(int(p["kp"]), int(p["kd"])), float(p["tilt"]), point.seed)
    return {**r, "held": held(r)}


Line = tuple[str, int, int, int]       # controller name, KP, KD, tilt sign
Results = dict[tuple[str, float | None, int], float]


def lines(quick: bool) -> list[Line]:
    """The bisections: (controller name, KP, KD, tilt sign); controllers off first."""
    gains = [Gain(1, 3), Gain(1, 1), Gain(2, 0)] if quick else [
        Gain(1, 4), Gain(1, 3), Gain(1, 2), Gain(1, 1), Gain(1, 0), Gain(2, 0), Gain(4, 0)]
    out: list[Line] = []
    for sign in (1, -1):
        out.append(("NO_CONTROL", 0, 0, sign))
        for name in ("REACTION_CONTROL", "BALANCE_CONTROL"):
            out += [(name, g.kp, g.kd, sign) for g in gains]
    return out


def tilt_limits(todo: list[Line], runs: Path, jobs: int | None, backend: str, address: str | None,
                progress: bool) -> tuple[dict[Line, float], int]:
    """Largest tilt held on every line, to :data:`TILT_RES_DEG`: the bisections as successive
    grids (step 0: every line at the top of the search; then every unresolved line at its
    mid-point). Returns the limits and the number of runs."""
    lo = {ln: 0.0 for ln in todo}
    hi = {ln: TILT_MAX_DEG for ln in todo}
    limit: dict[Line, float] = {}
    n_runs = 0
    step = 0
    while len(limit) < len(todo):
        open_lines = [ln for ln in todo if ln not in limit]
        tilts = {ln: TILT_MAX_DEG if step == 0 else round((lo[ln] + hi[ln]) / 2) for ln in open_lines}
        points = [Point(i, (("controller", ln[0]), ("kp", ln[1]), ("kd", ln[2]), ("tilt", ln[3] * tilts[ln])))
                  for i, ln in enumerate(open_lines)]
        rows = run_sweep(points, stand_point, runs, jobs=jobs, backend=backend, address=address,
                         progress=sys.stderr if progress else None)
        n_runs += len(points)
        for ln, row in zip(open_lines, rows, strict=True):
            if row.get("error"):
                raise RuntimeError(f"{ln} at {tilts[ln]} deg: {row['error']}")
            ok = str(row["held"]).lower() == "true"       # a bool, or a CSV's true (or an older True)
            if step == 0:
                if ok:
                    limit[ln] = ln[3] * TILT_MAX_DEG
                continue
            if ok:
                lo[ln] = tilts[ln]
            else:
                hi[ln] = tilts[ln]
        for ln in open_lines:
            if ln not in limit and hi[ln] - lo[ln] <= TILT_RES_DEG:
                limit[ln] = ln[3] * lo[ln]
        step += 1
    return limit, n_runs


def main(argv: list[str] | None = None) -> int:
    root = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 gains instead of 7")
    ap.add_argument("--out-dir", type=Path, default=root / "out", help="where balance_study.md/.png go "
                    "(default out/; docs to regenerate the docs' copies)")
    ap.add_argument("--runs", type=Path, default=root / "out" / "balance_study_runs.csv",
                    help="the sweep table of every run (resumed when it exists)")
    ap.add_argument("--jobs", type=int, help="runs at a time (default: the cores)")
    ap.add_argument("--backend", choices=("local", "ray"), default="local")
    ap.add_argument("--address", help="ray: the cluster to join")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    args.runs.parent.mkdir(parents=True, exist_ok=True)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    limits, n_runs = tilt_limits(lines(args.quick), args.runs, args.jobs, args.backend, args.address,
                                 not args.no_progress)
    wall = time.perf_counter() - t0
    results: Results = {(name, None if name == "NO_CONTROL" else Gain(kp, kd).value, sign): lim
                        for (name, kp, kd, sign), lim in limits.items()}
    table = write_table(results, args.out_dir / "balance_study.md", wall, n_runs, args)
    print(table)
    write_plot(results, args.out_dir / "balance_study.png")
    return 0


def _rows(results: Results) -> list[tuple[str, float | None, float, float]]:
    keys = sorted({(n, g) for n, g, _ in results}, key=lambda x: (x[0] != "NO_CONTROL", x[0], x[1] or 0))
    return [(n, g, results[(n, g, 1)], results[(n, g, -1)]) for n, g in keys]


def write_table(results: Results, path: Path, wall: float, n_runs: int, args: argparse.Namespace) -> str:
    """The markdown table of the limits."""
    lines = [
        "| controller | leader gain KP/2^KD | follower gain | largest tilt held, toes up (deg) "
        "| largest tilt held, toes down (deg) |",
        "|---|---|---|---|---|",
    ]
    for name, g, pos, neg in _rows(results):
        gs = "-" if g is None else f"{g:g}"
        fs = "-" if g is None else f"{-FOLLOW_RATIO * g:g}"
        lines.append(f"| {name} | {gs} | {fs} | {pos:g} | {neg:g} |")
    lines.append("")
    lines.append(f"Tilt at {TILT_RATE_DEG_S:g} deg/s then {SETTLE_S:g} s settling, seed 0, bisection to "
                 f"{TILT_RES_DEG:g} deg, {TILT_MAX_DEG:g} deg = the top of the search (platform range "
                 f"+-45). Generated by scripts/balance_study.py ({n_runs} runs, "
                 f"{args.backend} backend, {args.jobs or 'all the'} jobs) in {wall:.0f} s "
                 "(runs already in the --runs table are not run again).")
    text = "\n".join(lines) + "\n"
    path.write_text(text)
    return text


def write_plot(results: Results, path: Path) -> None:
    """Largest tilt held vs gain, both controllers, both tilt directions; the controllers-off
    limits as horizontal lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 4.6), dpi=100)
    styles = {"REACTION_CONTROL": ("tab:blue", "REACTION (v = KP e)"),
              "BALANCE_CONTROL": ("tab:red", "BALANCE (v = KP J^T e)")}
    for name, (color, label) in styles.items():
        gs = sorted({g for (n, g, _) in results if n == name and g is not None})
        if not gs:
            continue
        ax.plot(gs, [results[(name, g, 1)] for g in gs], "o-", color=color, label=f"{label}, toes up")
        ax.plot(gs, [-results[(name, g, -1)] for g in gs], "s--", color=color, alpha=0.6,
                label=f"{label}, toes down")
    off_pos = results.get(("NO_CONTROL", None, 1))
    off_neg = results.get(("NO_CONTROL", None, -1))
    if off_pos is not None:
        ax.axhline(off_pos, color="k", lw=1.2, label=f"controllers off, toes up ({off_pos:g} deg)")
    if off_neg is not None:
        ax.axhline(-off_neg, color="k", lw=1.2, ls=":",
                   label=f"controllers off, toes down ({-off_neg:g} deg)")
    g_stand = STAND_LEAD_KP / 2**STAND_KD
    ax.axvline(g_stand, color="tab:green", lw=1, ls="-.", label=f"stand's gain ({g_stand:g})")
    ax.set_xscale("log", base=2)
    ax.set_xlabel(f"leader gain KP / 2^KD (firmware units; follower = -{FOLLOW_RATIO} x)")
    ax.set_ylabel("largest platform tilt held (deg)")
    ax.set_ylim(0, TILT_MAX_DEG + 2)
    ax.set_title("Standing on a platform tilting at 1 deg/s, double support")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.02, 0.5))
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
