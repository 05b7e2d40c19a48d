#!/usr/bin/env python3
"""Benchmark: the whole twin vs MuJoCo physics alone, measured in one run (issue 3).

Runs a flexao of ``--seconds`` simulated seconds through the whole chain (host -> RS-232 ->
Master -> CAN with the full time-triggered schedule -> 8 Slaves -> MuJoCo), recording off (and,
for the headline ratio, the summary's ground-truth monitor off too; it is also timed on), and
then MuJoCo stepping the same model alone (``mj_step(m, d, nstep)`` in chunks, servos holding
their stand pose) for the same simulated time. Prints the real-time factor of each and the ratio
twin / physics. Target: ratio <= 3 (aim 1.5).

    python scripts/bench.py [--seconds 10] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import time

import mujoco

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import N_SCU
from humanoid_twin.plant import Plant
from humanoid_twin.scenarios import RunOptions, run


def bare_physics(seconds: float, chunk_us: int = 2_500) -> float:
    """Wall seconds for MuJoCo alone to simulate ``seconds`` (same model, same step size)."""
    plant = Plant()
    pulses = plant.keyframe_pulses("stand")
    for scu in range(1, N_SCU + 1):
        plant.set_pwm(scu, pulses[scu])
    m, d = plant.model, plant.data
    n_total = round(seconds * US_PER_S) // plant.timestep_us
    per_chunk = max(1, chunk_us // plant.timestep_us)
    t0 = time.perf_counter()
    done = 0
    while done < n_total:
        n = min(per_chunk, n_total - done)
        mujoco.mj_step(m, d, nstep=n)
        done += n
    return time.perf_counter() - t0


def twin_run(seconds: float, monitor: bool) -> tuple[float, dict]:
    """Wall seconds of the twin's simulation loop for a flexao of ``seconds`` simulated seconds
    (``monitor``: with the run summary's ground-truth sampling, as ``humanoid-twin run`` does)."""
    summary = run(RunOptions(scenario="flexao", duration=seconds, out=None, progress=False, monitor=monitor))
    return summary["wall_s"], summary


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3, help="best of N for each side")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    phys = min(bare_physics(args.seconds) for _ in range(args.repeat))
    runs = [twin_run(args.seconds, monitor=False) for _ in range(args.repeat)]
    twin = min(w for w, _ in runs)
    summary = runs[0][1]
    monitored = min(twin_run(args.seconds, monitor=True)[0] for _ in range(args.repeat))
    result = {
        "simulated_s": args.seconds,
        "physics_wall_s": round(phys, 4),
        "physics_rtf": round(args.seconds / phys, 2),
        "twin_wall_s": round(twin, 4),
        "twin_rtf": round(args.seconds / twin, 2),
        "overhead_ratio": round(twin / phys, 2),
        "twin_with_monitor_wall_s": round(monitored, 4),
        "overhead_ratio_with_monitor": round(monitored / phys, 2),
        "can_frames": summary["can_frames"],
        "serial_frames": summary["serial_frames"],
        "fell": summary["fell"],
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"simulated time          {args.seconds:.1f} s "
              "(flexao, 8 slaves, full CAN schedule, no recording)")
        print(f"MuJoCo alone            {phys:.3f} s wall   RTF {args.seconds / phys:7.1f}")
        print(f"whole twin              {twin:.3f} s wall   RTF {args.seconds / twin:7.1f}")
        print(f"overhead ratio          {twin / phys:.2f} x bare physics (target <= 3, aim 1.5)")
        print(f"with the run monitor    {monitored:.3f} s wall   {monitored / phys:.2f} x bare physics "
              "(ground truth sampled for the summary, as `humanoid-twin run` does)")
        print(f"CAN frames              {summary['can_frames']}  serial frames {summary['serial_frames']}")


if __name__ == "__main__":
    main()
