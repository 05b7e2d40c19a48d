"""levantar_perna's smallest CoP margin over seeds and both legs, and where in the motion it happens.

    python scripts/levantar_margins.py [--seeds 10] [--jobs 2] [--law balance=module:Class] [--T 1]

Runs ``humanoid-twin run levantar_perna --perna P --seed S`` in-process (``scenarios.run``, the
same run as the CLI's) for perna 1 and 2 and seeds 0..N-1, 2 at a time, and prints per run the
smallest CoP margin of the ground-truth monitor (``cop_margin_min_mm``, what ``run --json``
reports), when it happened (seconds after the boot) and in which motion of the plan (shift, lift,
hold, lower, return, rest; "after" = the 2 s after the plan), the smallest margin of each motion,
and which pads carried the robot at that instant (pads over 0.5 N; R/L foot CoP in its foot frame,
mm, x to the robot's right). ``--law balance=humanoid_twin.slave.laws:OpenLoopLaw`` switches the
support law off (docs/balance.md 4). Output: a Markdown table (docs/balance.md 4 quotes it).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import sys
import time
from typing import Any

import numpy as np

from humanoid_twin.scenarios import RunOptions, plan, run

MOTIONS = ("shift", "lift", "hold", "lower", "return", "rest")
PADS = ("FL", "FR", "RL", "RR")


def _phase_edges(perna: int, T: float | None) -> list[float]:
    t = plan("levantar_perna", T, None, perna).t
    return list(np.cumsum(t))


def _phases(T: float | None) -> tuple[str, ...]:
    """The plan's motions, then "after" (the run's last 2 s)."""
    return (*MOTIONS[:len(_phase_edges(1, T))], "after")


def one(args: tuple[int, int, tuple[tuple[str, str], ...], float | None]) -> dict[str, Any]:
    perna, seed, laws, T = args
    edges = _phase_edges(perna, T)
    PHASES = _phases(T)
    trace: list[tuple[float, float, str]] = []

    def on_twin(twin: Any) -> None:
        def sample() -> None:
            gt = twin.plant.truth()
            loaded = []
            for foot, tag in (("r_foot", "R"), ("l_foot", "L")):
                f = gt.pad_forces_n[foot]
                loaded += [f"{tag}{p}" for p, v in zip(PADS, f, strict=True) if v > 0.5]
                cop = gt.foot_cop_mm[foot]
                if cop is not None:
                    loaded.append(f"{tag}({cop[0]:.0f},{cop[1]:.0f})")
            trace.append((twin.now_s, gt.cop_margin_mm, " ".join(loaded)))

        twin.every(20_000, sample)

    s = run(RunOptions("levantar_perna", perna=perna, seed=seed, laws=laws, T=T, progress=False),
            on_twin=on_twin)
    b = s["boot_s"]
    per_phase = [math.inf] * len(PHASES)
    worst = (math.inf, 0.0, "")
    for t, m, pads in trace:
        if t < b:
            continue
        rel = t - b
        ph = next((i for i, e in enumerate(edges) if rel < e), len(PHASES) - 1)
        per_phase[ph] = min(per_phase[ph], m)
        if m < worst[0]:
            worst = (m, rel, pads)
    ph = next((i for i, e in enumerate(edges) if worst[1] < e), len(PHASES) - 1)
    return {"perna": perna, "seed": seed, "margin": s["cop_margin_min_mm"], "fell": s["fell"],
            "t_rel": worst[1], "phase": PHASES[ph], "pads": worst[2], "per_phase": per_phase,
            "trace_min": worst[0], "wall_s": s["wall_s"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds 0..N-1 (default 10)")
    ap.add_argument("--first-seed", type=int, default=0, help="start the seeds there (a hold-out set)")
    ap.add_argument("--pernas", default="1,2")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--T", type=float, default=None)
    ap.add_argument("--law", action="append", default=[], help="TYPE=module:Class, as run --law")
    a = ap.parse_args(argv)
    laws = tuple(tuple(x.split("=", 1)) for x in a.law)
    pernas = [int(p) for p in a.pernas.split(",")]
    jobs = [(p, s, laws, a.T) for p in pernas for s in range(a.first_seed, a.first_seed + a.seeds)]
    t0 = time.perf_counter()
    with mp.get_context("spawn").Pool(a.jobs) as pool:
        rows = pool.map(one, jobs, chunksize=1)
    wall = time.perf_counter() - t0
    print(f"levantar_perna, {len(rows)} runs, laws {dict(laws) or 'built-in'}, T {a.T or 'default'}, "
          f"{wall:.0f} s on {a.jobs} processes; margins in mm, t in s after the boot "
          f"(motion ends: {', '.join(f'{e:g}' for e in _phase_edges(1, a.T))})")
    PHASES = _phases(a.T)
    print("| perna | seed | min | t | phase | pads at min | " + " | ".join(PHASES) + " |")
    print("|---" * (6 + len(PHASES)) + "|")
    for r in rows:
        pp = " | ".join(f"{m:.1f}" if math.isfinite(m) else "-" for m in r["per_phase"])
        fell = " FELL" if r["fell"] else ""
        print(f"| {r['perna']} | {r['seed']} | {r['margin']:.1f}{fell} | {r['t_rel']:.2f} | {r['phase']} | "
              f"{r['pads']} | {pp} |")
    for p in pernas:
        ms = [r["margin"] for r in rows if r["perna"] == p]
        print(f"perna {p}: " + " ".join(f"{m:.1f}" for m in ms) + f"  smallest {min(ms):.1f}")
    ms = [r["margin"] for r in rows]
    print(f"smallest {min(ms):.1f} mm; {sum(m >= 10 for m in ms)} of {len(ms)} runs >= 10 mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
