"""What the boards' time and the trunk's sensors did in a run: the summary's ``task_load_max``,
``deadline_misses`` and ``imu_tilt_error_rms_deg`` (docs/scenarios.md, docs/firmware.md).

    report = BoardReport(twin)      # before the run: samples the IMU after each body-board tick
    ...
    summary.update(report.summary())

Like the monitor it only reads: a run with and without it is the same run.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from humanoid_twin.hardware import IMU_SCU, PWM_PERIOD_US, imu_from_counts, tilt_from_roll_pitch

if TYPE_CHECKING:
    from humanoid_twin.twin import Twin

__all__ = ["BoardReport"]


class BoardReport:
    """``BoardReport(twin, imu=True)``: attaches the IMU comparison (``imu``: off, the key is
    None, as the monitor's are, for scripts/bench.py); :meth:`summary` gives the three keys."""

    def __init__(self, twin: Twin, imu: bool = True) -> None:
        self.twin = twin
        self._err_sq = 0.0
        self._n = 0
        self._board = board = twin.slaves[IMU_SCU]
        self._plant = twin.plant
        if imu:
            twin.every(PWM_PERIOD_US, self.compare_imu, board.next_tick_us())

    def compare_imu(self) -> None:
        """Right after the body board's tick: the trunk tilt its inclinometer gives (its sensor
        database, the bytes ``readspecial(H, 5)`` returns) against the truth."""
        board = self._board
        if not board.calibrated:
            return
        roll, pitch, _, _ = self._plant.trunk_attitude_deg()
        m_roll, m_pitch, _, _ = imu_from_counts(board.sensors.special)
        d = tilt_from_roll_pitch(m_roll, m_pitch) - tilt_from_roll_pitch(roll, pitch)
        self._err_sq += d * d
        self._n += 1

    @property
    def imu_tilt_error_rms_deg(self) -> float | None:
        """RMS of (inclinometer tilt - true tilt) over the body board's calibrated ticks."""
        return None if self._n == 0 else math.sqrt(self._err_sq / self._n)

    def summary(self) -> dict[str, Any]:
        """``task_load_max``: the largest fraction of its 20 ms period any Slave's pass used
        (interrupts included), the largest fraction of its 250 us slot the Master's timer
        interrupt used; ``deadline_misses``: per board, the Slaves' passes that set
        ``deadlineError`` (late or overrun), the Master's slots that overran."""
        twin = self.twin
        slaves = twin.slaves
        pic = twin.the_master().pic
        misses = {"master": pic.slot_overruns}
        for scu, s in slaves.items():
            misses[str(scu)] = s.deadline_violations
        err = self.imu_tilt_error_rms_deg
        return {
            "task_load_max": {"slaves": round(max(s.task_load_max for s in slaves.values()), 4),
                              "master": round(pic.slot_load_max, 4)},
            "deadline_misses": misses,
            "imu_tilt_error_rms_deg": None if err is None else round(err, 3),
        }
