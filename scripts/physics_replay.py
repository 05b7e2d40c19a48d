#!/usr/bin/env python3
"""Why MuJoCo costs more inside the twin than alone: the motion, or the chunked stepping?

Runs a flexao of ``--seconds`` simulated seconds through the whole twin (recording and monitor
off) and logs every ``mj_step`` chunk the plant takes (its number of steps and the servo
controls during it). Then, in the same process, steps a fresh plant three ways, ``--repeat``
times each, and prints the best time of each:

- the standing robot in the same chunk sizes (what ``scripts/bench.py`` calls "MuJoCo alone");
- the twin's own motion replayed (the same chunks, the same controls) with nothing in between;
- the twin itself: MuJoCo's time inside the run (``Plant.step_ns_total``).

If the replay costs about what the standing robot costs, the extra time inside the twin is
not the motion but the stepping interleaved with the boards' Python work (short chunks that
start with cold caches).

    python scripts/physics_replay.py [--seconds 30] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
from bench import standing_plant  # scripts/bench.py, beside this script: the same baseline

from humanoid_twin.scenarios import RunOptions, run


def twin_chunks(seconds: float) -> tuple[float, list[tuple[int, np.ndarray]]]:
    """MuJoCo's time inside a twin run of flexao, and its chunks: (steps, controls) each."""
    chunks: list[tuple[int, np.ndarray]] = []
    twins: list = []

    def watch(twin) -> None:
        plant = twin.plant
        step = plant.advance_to

        def logged(t_us: int) -> None:
            k = (t_us - plant.t_us) // plant.timestep_us
            if k > 0:
                chunks.append((k, plant.data.ctrl.copy()))
            step(t_us)

        plant.advance_to = logged       # this plant object only, for this measurement
        twins.append(twin)

    run(RunOptions(scenario="flexao", duration=seconds, progress=False, monitor=False), on_twin=watch)
    return twins[0].plant.step_ns_total / 1e9, chunks


def alone(chunks: list[tuple[int, np.ndarray]], replay: bool) -> float:
    """Seconds for a fresh plant to take the same chunks, standing or with the logged controls."""
    plant = standing_plant()
    m, d = plant.model, plant.data
    t0 = time.perf_counter()
    if replay:
        for k, ctrl in chunks:
            d.ctrl[:] = ctrl
            mujoco.mj_step(m, d, nstep=k)
    else:
        for k, _ in chunks:
            mujoco.mj_step(m, d, nstep=k)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    inside, chunks = twin_chunks(args.seconds)
    standing = min(alone(chunks, False) for _ in range(args.repeat))
    replayed = min(alone(chunks, True) for _ in range(args.repeat))
    steps = sum(k for k, _ in chunks)
    print(f"{len(chunks)} chunks, {steps} steps ({steps / len(chunks):.1f} per chunk)")
    print(f"standing robot, same chunks, alone   {standing:6.3f} s")
    print(f"the twin's motion replayed, alone    {replayed:6.3f} s   x{replayed / standing:.2f}")
    print(f"MuJoCo inside the twin               {inside:6.3f} s   x{inside / standing:.2f}")


if __name__ == "__main__":
    main()
