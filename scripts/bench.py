#!/usr/bin/env python3
"""Benchmark: the whole twin vs MuJoCo physics alone, measured in one run.

Runs a flexao of ``--seconds`` (default 30) simulated seconds through the whole chain (host ->
RS-232 -> Master -> CAN with the full time-triggered schedule -> 8 Slaves -> MuJoCo) three ways:
recording off with the summary's ground-truth monitor off (the twin itself), recording off with
the monitor on (``humanoid-twin run --no-record``), and recording on (``humanoid-twin run``,
a rerun ``.rrd``); then MuJoCo stepping the same model alone (``mj_step(m, d, nstep)`` in chunks,
servos holding their stand pose) for the same simulated time. Prints the real-time factor of each
and the ratios twin / physics. Targets (issue 22, the compiled core): the twin itself <= x1.4,
recording off <= x1.5, recording on <= x1.8. It prints which core ran (compiled or python).
It also times the startup of a fresh process to the first simulated step (target < 1 s).

    python scripts/bench.py [--seconds 30] [--repeat 3]

Each configuration runs ``--repeat`` times, interleaved, and the best time of each is kept. Wall
and CPU time (the process's, all threads; rerun encodes on its own threads, the compaction at
close runs in rerun's own program and counts in wall time only) are both printed: on a machine
shared with other jobs the CPU ratios are the steadier ones. The one-time import of the recording
stack (rerun, pyarrow) is measured apart, before the runs.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco

from humanoid_twin.clock import US_PER_S
from humanoid_twin.plant import Plant
from humanoid_twin.protocol.wire import N_SCU
from humanoid_twin.scenarios import RunOptions, run


def standing_plant() -> Plant:
    """A fresh plant, every servo holding the ``stand`` keyframe: MuJoCo alone, the baseline."""
    plant = Plant()
    pulses = plant.keyframe_pulses("stand")
    for scu in range(1, N_SCU + 1):
        plant.set_pwm(scu, pulses[scu])
    return plant


def bare_physics(seconds: float, chunk_us: int = 2_500) -> tuple[float, float]:
    """(wall, CPU) seconds for MuJoCo alone to simulate ``seconds`` (same model, same step size)."""
    plant = standing_plant()
    m, d = plant.model, plant.data
    n_total = round(seconds * US_PER_S) // plant.timestep_us
    per_chunk = max(1, chunk_us // plant.timestep_us)
    t0, c0 = time.perf_counter(), time.process_time()
    done = 0
    while done < n_total:
        n = min(per_chunk, n_total - done)
        mujoco.mj_step(m, d, nstep=n)
        done += n
    return time.perf_counter() - t0, time.process_time() - c0


def twin_run(seconds: float, monitor: bool, out: Path | None = None) -> tuple[float, float, float, dict]:
    """(wall, CPU) seconds of a whole ``run()`` of flexao for ``seconds`` simulated seconds (twin
    built, booted, moved, recording closed), the seconds of that spent in MuJoCo, and the run's
    summary (``monitor``: with the run summary's ground-truth sampling, as ``humanoid-twin run``
    does; ``out``: recording on, to that ``.rrd``). CPU time is the process's, all threads (rerun
    encodes and writes on its own threads)."""
    twins: list = []
    t0, c0 = time.perf_counter(), time.process_time()
    summary = run(RunOptions(scenario="flexao", duration=seconds, out=out, progress=False, monitor=monitor),
                  on_twin=twins.append)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return wall, cpu, twins[0].plant.step_ns_total / 1e9, summary


STARTUP = """
import time
t0 = time.perf_counter()
from humanoid_twin.twin import Twin
twin = Twin(seed=0)
twin.advance_to(twin.plant.timestep_us)
print(time.perf_counter() - t0)
twin.close()
"""


def startup_s() -> float:
    """Wall seconds from a fresh interpreter's first import of the twin to its first simulated step."""
    out = subprocess.run([sys.executable, "-c", STARTUP], check=True, capture_output=True, text=True)
    return float(out.stdout.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--repeat", type=int, default=3, help="best of N for each configuration")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    sec = args.seconds
    # one-time costs of a process, measured apart: importing the recording stack (rerun,
    # pyarrow) and a short warm-up run (imports of the firmware, bytecode caches)
    t0 = time.perf_counter()
    import humanoid_twin.recording.rerun_recorder  # noqa: F401  (the package loads rerun lazily)
    rec_import = time.perf_counter() - t0
    run(RunOptions(scenario="flexao", duration=3.0, progress=False, monitor=False))

    def best(samples: list[tuple[float, ...]]) -> tuple[float, float]:
        return min(s[0] for s in samples), min(s[1] for s in samples)

    # the configurations interleaved, best of --repeat each: a machine whose load drifts during
    # the benchmark weighs on every configuration alike
    samples: dict[str, list[tuple[float, float]]] = {"phys": [], "twin": [], "mon": [], "rec": []}
    own_physics: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.repeat):
            samples["phys"].append(bare_physics(sec))
            w, c, physics_s, summary = twin_run(sec, monitor=False)
            samples["twin"].append((w, c))
            own_physics.append(physics_s)
            samples["mon"].append(twin_run(sec, monitor=True)[:2])
            samples["rec"].append(twin_run(sec, monitor=True, out=Path(tmp) / f"bench{i}.rrd")[:2])
            samples["phys"].append(bare_physics(sec))     # physics alone is short: twice per round
    phys, phys_cpu = best(samples["phys"])
    own = min(own_physics)
    twin, twin_cpu = best(samples["twin"])
    monitored, monitored_cpu = best(samples["mon"])
    recorded, recorded_cpu = best(samples["rec"])
    start = min(startup_s() for _ in range(args.repeat))
    result = {
        "simulated_s": sec,
        "physics_wall_s": round(phys, 4),
        "physics_cpu_s": round(phys_cpu, 4),
        "physics_rtf": round(sec / phys, 2),
        "twin_own_physics_s": round(own, 4),
        "twin_wall_s": round(twin, 4),
        "twin_rtf": round(sec / twin, 2),
        "overhead_ratio": round(twin / phys, 2),
        "overhead_ratio_cpu": round(twin_cpu / phys_cpu, 2),
        "twin_with_monitor_wall_s": round(monitored, 4),
        "overhead_ratio_with_monitor": round(monitored / phys, 2),
        "overhead_ratio_with_monitor_cpu": round(monitored_cpu / phys_cpu, 2),
        "twin_recording_wall_s": round(recorded, 4),
        "overhead_ratio_recording": round(recorded / phys, 2),
        "overhead_ratio_recording_cpu": round(recorded_cpu / phys_cpu, 2),
        "startup_to_first_step_s": round(start, 3),
        "recording_import_s": round(rec_import, 3),
        "can_frames": summary["can_frames"],
        "serial_frames": summary["serial_frames"],
        "fell": summary["fell"],
    }
    if args.json:
        print(json.dumps(result))
    else:
        from humanoid_twin.core import core_kind

        print(f"simulated time            {sec:.1f} s (flexao, 8 slaves, full CAN schedule; "
              f"core: {core_kind()})")
        print("                          wall s    CPU s     RTF   ratio to bare physics (wall / CPU)")
        print(f"MuJoCo alone              {phys:7.3f}  {phys_cpu:7.3f}  {sec / phys:6.1f}")
        print(f"twin, no monitor/record   {twin:7.3f}  {twin_cpu:7.3f}  {sec / twin:6.1f}   "
              f"x{twin / phys:.2f} / x{twin_cpu / phys_cpu:.2f}   (target <= 1.4)")
        print(f"recording off (run)       {monitored:7.3f}  {monitored_cpu:7.3f}  {sec / monitored:6.1f}   "
              f"x{monitored / phys:.2f} / x{monitored_cpu / phys_cpu:.2f}   (target <= 1.5)")
        print(f"recording on  (run .rrd)  {recorded:7.3f}  {recorded_cpu:7.3f}  {sec / recorded:6.1f}   "
              f"x{recorded / phys:.2f} / x{recorded_cpu / phys_cpu:.2f}   (target <= 1.8)")
        print(f"MuJoCo inside the twin    {own:7.3f} s (x{own / phys:.2f} of MuJoCo alone: short chunks "
              f"between the boards' work, scripts/physics_replay.py); "
              f"recording on = x{recorded / own:.2f} of it")
        print(f"startup to first step     {start:7.3f} s (fresh process, target < 1 s)")
        print(f"import of the recording   {rec_import:7.3f} s (once per process, when recording)")
        print(f"CAN frames                {summary['can_frames']}  serial frames {summary['serial_frames']}")


if __name__ == "__main__":
    main()
