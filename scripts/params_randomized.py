#!/usr/bin/env python3
"""levantar_perna's CoP margin over randomised robots (docs/parameters.md, its example and plot).

    .venv/bin/python scripts/params_randomized.py                 # 50 robots, 2 jobs: ~5 minutes
    .venv/bin/python scripts/params_randomized.py --samples 4 --table /tmp/r.csv --plot /tmp/r.png

The sweep ``humanoid-twin sweep levantar_perna --randomize ... --samples N`` (seed 0, the right
leg lifted): both knees' servo gain within +-20 % of its default, the trunk's mass within +-10 %,
the floor's friction 0.5..1.0; plus the nominal robot. Writes the table (CSV), the plot (PNG:
each robot's smallest CoP margin against its knee gain, coloured by the floor's friction, sized
by the trunk's mass, the nominal robot's margin as a line) and prints the figures the docs quote.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KNEES = "servo.*_knee.kp"
TRUNK = "body.trunk.mass_scale"
FLOOR = "floor.friction"
METRIC = "cop_margin_min_mm"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=50, help="robots to draw (default 50)")
    ap.add_argument("--jobs", type=int, default=2, help="runs at a time (default 2)")
    ap.add_argument("--table", type=Path, default=Path("params_randomized.csv"), help="the sweep table (CSV)")
    ap.add_argument("--plot", type=Path, default=ROOT / "docs" / "img" / "params_randomized.png")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from humanoid_twin.params import registry
    from humanoid_twin.sweep import RunCli, run_sweep
    from humanoid_twin.sweep.engine import Point, grid
    from humanoid_twin.sweep.params import draw_samples, parse_randomize

    kp = registry().get("servo.r_knee.kp").default
    randomize = [f"{KNEES}=uniform({0.8 * kp:.6g},{1.2 * kp:.6g})", f"{TRUNK}=uniform(0.9,1.1)",
                 f"{FLOOR}=uniform(0.5,1.0)"]
    task = RunCli("levantar_perna", ("--perna", "1"))
    nominal = task(Point(0, (), 0))[METRIC]
    points = grid({}, [0], draw_samples(parse_randomize(randomize), args.samples))
    rows = run_sweep(points, task, args.table, jobs=args.jobs, progress=sys.stderr)
    ok = [r for r in rows if not r.get("error")]
    margins = [float(r[METRIC]) for r in ok]
    fell = sum(str(r.get("fell")).lower() == "true" for r in ok)
    print(f"nominal robot: {METRIC} {nominal} mm")
    print(f"{len(ok)} of {len(rows)} randomised robots ran; fell: {fell}; {METRIC}: min {min(margins):.1f}, "
          f"median {statistics.median(margins):.1f}, max {max(margins):.1f} mm; below nominal: "
          f"{sum(m < nominal for m in margins)}")
    worst = min(ok, key=lambda r: float(r[METRIC]))
    print(f"worst: {KNEES}={worst[KNEES]} {TRUNK}={worst[TRUNK]} {FLOOR}={worst[FLOOR]}: {worst[METRIC]} mm")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=110)
    sc = ax.scatter([float(r[KNEES]) for r in ok], margins, c=[float(r[FLOOR]) for r in ok], cmap="viridis",
                    s=[30 + 600 * (float(r[TRUNK]) - 0.9) for r in ok], edgecolors="k", linewidths=0.4)
    ax.axhline(nominal, color="tab:red", lw=1, ls="--", label=f"nominal robot: {nominal:.1f} mm")
    ax.axvline(kp, color="grey", lw=0.8, ls=":")
    ax.set_xlabel(f"knee servo gain {KNEES} (N·m/rad; default {kp:g})")
    ax.set_ylabel("smallest CoP margin (mm)")
    ax.set_title(f"levantar_perna (right leg lifted, seed 0): {len(ok)} randomised robots\n"
                 "marker size: trunk mass x0.9..x1.1", fontsize=10)
    fig.colorbar(sc, ax=ax, label="floor friction")
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    args.plot.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.plot)
    print(f"wrote {args.table} and {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
