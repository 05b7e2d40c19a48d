"""The Slaves' PWM phases of a robot, read from its CAN log.

Each Slave runs its 20 ms loop (``hardware.PWM_PERIOD_US``) at its own phase, and stays silent
when an actuation packet arrives in the first ``hardware.PWM_BUSY_US`` of its period (seed 002
slide 29; humanoid_twin/slave/can.py). The twin draws the phases from its seed; the robot's are
whatever they were. The log says which actuation packets each Slave answered: a phase ``p`` is
consistent with the log when every unanswered packet arrived ``(t - p) mod 20 ms < 2 ms`` and
every answered one did not. :func:`estimate_phases` counts, for each candidate phase (every
:data:`STEP_US`), the packets it contradicts, and returns the middle of the best candidates'
longest run (circular).

:func:`phases_for` is what ``compare`` runs: the seed's phase of a Slave is kept unless the log
contradicts it more than the estimate does (a log the twin wrote with that seed keeps its
phases exactly); otherwise the estimate is used.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from humanoid_twin.compare.robot_log import ACTUATION_OF, SENSORS_OF, RobotLog
from humanoid_twin.hardware import PWM_BUSY_US, PWM_PERIOD_US

__all__ = ["STEP_US", "answered_packets", "estimate_phases", "phases_for"]

STEP_US = 50          # the candidate phases' spacing


def answered_packets(log: RobotLog) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per SCU: the logged instants (us) of its actuation packets and whether each was answered
    (a Sensors packet of the same index before the next actuation packet of that index)."""
    frames = sorted(log.master + log.sensors, key=lambda f: f.t_us)
    pending: dict[tuple[int, int], int] = {}          # (scu, idx) -> index into that SCU's lists
    times: dict[int, list[int]] = {}
    answered: dict[int, list[bool]] = {}
    for f in frames:
        act = ACTUATION_OF.get(f.arbitration_id)
        if act is not None:
            scu = act[0]
            times.setdefault(scu, []).append(f.t_us)
            answered.setdefault(scu, []).append(False)
            pending[act] = len(times[scu]) - 1
            continue
        key = SENSORS_OF.get(f.arbitration_id)
        i = pending.pop(key, None) if key is not None else None
        if key is not None and i is not None:
            answered[key[0]][i] = True
    return {scu: (np.asarray(times[scu], dtype=np.int64), np.asarray(answered[scu], dtype=bool))
            for scu in times}


def _contradictions(t: np.ndarray, ok: np.ndarray, phases: np.ndarray) -> np.ndarray:
    silent = ((t[None, :] - phases[:, None]) % PWM_PERIOD_US) < PWM_BUSY_US
    return np.count_nonzero(silent == ok[None, :], axis=1)


def estimate_phases(log: RobotLog) -> dict[int, tuple[int, int]]:
    """Per SCU with actuation packets in the log: ``(phase_us, contradictions)``, the estimated
    phase and how many of its packets it contradicts (a Slave that answered every packet still
    tells which phases would have silenced some)."""
    cand = np.arange(0, PWM_PERIOD_US, STEP_US, dtype=np.int64)
    out: dict[int, tuple[int, int]] = {}
    for scu, (t, ok) in answered_packets(log).items():
        if t.size == 0:
            continue
        bad = _contradictions(t, ok, cand)
        best = bad == bad.min()
        # the longest circular run of best candidates: its middle
        idx = np.flatnonzero(best)
        runs: list[tuple[int, int]] = []             # (start index, length)
        start = prev = int(idx[0])
        for i in idx[1:]:
            if i != prev + 1:
                runs.append((start, prev - start + 1))
                start = int(i)
            prev = int(i)
        runs.append((start, prev - start + 1))
        if len(runs) > 1 and runs[0][0] == 0 and runs[-1][0] + runs[-1][1] == cand.size:
            s, n = runs.pop()
            runs[0] = (s, n + runs[0][1])
        s, n = max(runs, key=lambda r: r[1])
        mid = (s + (n - 1) / 2) % cand.size
        out[scu] = (int(round(mid * STEP_US)) % PWM_PERIOD_US, int(bad.min()))
    return out


def phases_for(log: RobotLog, seed_phases: Mapping[int, int]) -> dict[int, tuple[int, str]]:
    """Per SCU of ``seed_phases``: ``(phase_us, "seed")`` when the seed's phase agrees with the
    log as well as the estimate does (or the log does not tell), else ``(estimate, "log")``."""
    est = estimate_phases(log)
    answers = answered_packets(log)
    out: dict[int, tuple[int, str]] = {}
    for scu, p in seed_phases.items():
        e = est.get(scu)
        if e is None:
            out[scu] = (int(p), "seed")
            continue
        t, ok = answers[scu]
        seed_bad = int(_contradictions(t, ok, np.array([p], dtype=np.int64))[0])
        out[scu] = (int(p), "seed") if seed_bad <= e[1] else (e[0], "log")
    return out
