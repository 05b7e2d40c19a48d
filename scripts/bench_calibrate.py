"""Benchmark of ``humanoid-twin calibrate``: evaluations per minute and wall time of one fit.

A "robot" is the twin with four parameters away from their defaults; its 10 s flexao CAN log is
written, then the four are fitted back from the nominal twin with ``--jobs`` parallel rollouts
(docs/calibration.md, docs/performance.md). Prints one line per measure and, with ``--json``,
one JSON object.

    python scripts/bench_calibrate.py [--duration 10] [--jobs 2] [--json]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROBOT = {"body.trunk.mass_scale": 1.15, "fsr.r_foot_fl.gain": 1.2, "fsr.l_foot_rr.gain": 0.85,
         "fsr.r_foot_rl.gain": 1.1}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0, help="the log's simulated seconds (default 10)")
    ap.add_argument("--jobs", type=int, default=2, help="parallel rollouts (default 2)")
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args()
    from humanoid_twin.compare import read_robot_log
    from humanoid_twin.compare.calibrate import FitProblem, fit
    from humanoid_twin.compare.fitparams import expand_fit
    from humanoid_twin.master.pic import ROUND_US

    with tempfile.TemporaryDirectory() as d:
        log_path = Path(d) / "robot.blf"
        sets = [a for name, v in ROBOT.items() for a in ("--set", f"{name}={v}")]
        subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "run", "flexao", "--duration",
                        str(args.duration), "--no-record", "--can-log", str(log_path), *sets],
                       check=True, capture_output=True)
        log = read_robot_log(log_path)
    problem = FitProblem(logs=[log], unknowns=expand_fit(",".join(ROBOT)), window=round(1e6 / ROUND_US))
    t0 = time.perf_counter()
    one = problem.residual([u.default for u in problem.unknowns])
    eval_s = time.perf_counter() - t0
    result = fit(problem, jobs=args.jobs, progress=lambda text: print(text, file=sys.stderr))
    per_min = result.evaluations / result.wall_s * 60.0
    out = {
        "log_s": args.duration, "jobs": args.jobs, "unknowns": len(ROBOT), "residual_values": int(one.size),
        "one_evaluation_s": round(eval_s, 3), "evaluations": result.evaluations,
        "evaluations_per_minute": round(per_min, 1), "wall_per_fit_s": round(result.wall_s, 1),
        "fitted": {n: round(e["value"], 4) for n, e in result.fitted.items()}, "robot": ROBOT,
        "residual_before": round(result.residual_before, 4),
        "residual_after": round(result.residual_after, 4),
        "not_identifiable": [n for n, e in result.fitted.items() if not e["identifiable"]],
    }
    if args.json:
        print(json.dumps(out))
    else:
        print(f"one evaluation ({args.duration:g} s log): {eval_s:.2f} s")
        print(f"evaluations per minute ({args.jobs} jobs): {per_min:.1f}")
        print(f"wall per fit ({len(ROBOT)} parameters): {result.wall_s:.1f} s, "
              f"{result.evaluations} evaluations")
        for n, e in result.fitted.items():
            said = "" if e["identifiable"] else ", not identifiable"
            print(f"  {n}: {e['value']:.4f} (robot {ROBOT[n]}){said}")
        print(f"residual {result.residual_before:.3f} -> {result.residual_after:.3f} quanta RMS")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
