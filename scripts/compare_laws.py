#!/usr/bin/env python3
"""Compare the shipped firmware control laws (docs/controllers.md, section 4).

Each law is plugged in for the BALANCE control type (``--law balance=...``), so the host's plans
are the same for all: ``stand`` (leader/follower gains on the leg boards, docs/balance.md) and
``levantar_perna`` (the law on the support leg in the hold and the lower). For each law:

- largest platform tilt held toes up: bisection to 1 deg (1 deg/s ramp, 2 s settling, seed 0;
  held = not fallen, CoP strictly inside the support polygon all along);
- at a 20 deg tilt: the smallest CoP margin and the RMS error of the boards' CoP;
- ``levantar_perna`` perna 1 and 2, seeds 0-9: the smallest CoP margin.

Prints a markdown table on stdout. ``--jobs N`` runs N processes (default 2). The study takes
minutes: its progress goes to stderr (a tqdm bar on a terminal, else one line per finished task,
with the elapsed time and an estimate of the rest; ``--no-progress`` for none).
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from humanoid_twin.scenarios import RunOptions, run

ROOT = Path(__file__).resolve().parents[1]
LAWS: dict[str, str] = {
    "NO_CONTROL law (openloop: controllers off)": "humanoid_twin.slave.laws:OpenLoopLaw",
    "REACTION law (reactionControl)": "humanoid_twin.slave.laws:ReactionLaw",
    "BALANCE law (jacobianControl, shipped default)": "humanoid_twin.slave.laws:JacobianLaw",
    "examples/cop_pd_law.py (CopPD)": "examples.cop_pd_law:CopPD",
}
TILT_MAX = 44
ONE_LEG_SEEDS = range(10)


def _law_class(ref: str) -> Any:
    from humanoid_twin.slave.laws import load_law

    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    return load_law(ref)


def _run(ref: str, scenario: str, **kw: Any) -> dict[str, Any]:
    return run(RunOptions(scenario, laws=(("balance", _law_class(ref)),), progress=False, **kw))


def held(s: dict[str, Any]) -> bool:
    """Stood: not fallen and the CoP strictly inside the support polygon all along."""
    return not s["fell"] and s["cop_margin_min_mm"] is not None and s["cop_margin_min_mm"] > 0


def largest_tilt(ref: str) -> int:
    """Bisection of the largest tilt (whole degrees, toes up) the law holds."""
    lo, hi = 0, TILT_MAX + 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if held(_run(ref, "stand", tilt=float(mid))):
            lo = mid
        else:
            hi = mid
    return lo


def at_20(ref: str) -> dict[str, Any]:
    return _run(ref, "stand", tilt=20.0)


def one_leg(ref: str) -> float:
    margins = [_run(ref, "levantar_perna", perna=p, seed=s)["cop_margin_min_mm"]
               for p in (1, 2) for s in ONE_LEG_SEEDS]
    return min(-1000.0 if m is None else m for m in margins)


def _task(job: tuple[str, str]) -> tuple[str, str, Any]:
    kind, name = job
    ref = LAWS[name]
    fn = {"tilt": largest_tilt, "at20": at_20, "one_leg": one_leg}[kind]
    return kind, name, fn(ref)


class _Progress:
    """Tasks done / total on stderr: a tqdm bar on a terminal, else a plain line per task."""

    def __init__(self, total: int, on: bool) -> None:
        self.total, self.done, self.on = total, 0, on
        self.t0 = time.perf_counter()
        self.bar: Any = None
        if on and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="task", desc="compare_laws", file=sys.stderr)

    def update(self, what: str) -> None:
        self.done += 1
        if self.bar is not None:
            self.bar.set_postfix_str(what, refresh=False)
            self.bar.update(1)
        elif self.on:
            wall = time.perf_counter() - self.t0
            eta = wall / self.done * (self.total - self.done)
            print(f"compare_laws: {self.done}/{self.total} tasks done ({what}), {wall:.0f} s elapsed, "
                  f"ETA {eta:.0f} s", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--no-progress", action="store_true", help="no progress on stderr")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    jobs = [(kind, name) for name in LAWS for kind in ("tilt", "at20", "one_leg")]
    res: dict[tuple[str, str], Any] = {}
    bar = _Progress(len(jobs), not args.no_progress)
    with ProcessPoolExecutor(max(1, args.jobs)) as ex:
        futures = [ex.submit(_task, job) for job in jobs]
        try:
            for fut in as_completed(futures):
                kind, name, value = fut.result()
                res[(kind, name)] = value
                bar.update(f"{kind}: {name.split(' (')[0]}")
        finally:
            bar.close()
    print("| law (for BALANCE_CONTROL) | largest tilt held (deg) | CoP margin at 20 deg (mm) | "
          "CoP error at 20 deg (mm RMS) | levantar_perna CoP margin (mm) |")
    print("|---|---|---|---|---|")
    for name in LAWS:
        s20 = res[("at20", name)]
        m20 = "fell" if s20["fell"] else f"{s20['cop_margin_min_mm']:.1f}"
        err = s20["cop_error_rms_mm"]
        print(f"| {name} | {res[('tilt', name)]} | {m20} | {'-' if err is None else f'{err:.1f}'} | "
              f"{res[('one_leg', name)]:.1f} |")
    print(f"\nGenerated by scripts/compare_laws.py in {time.perf_counter() - t0:.0f} s ({args.jobs} jobs).")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
