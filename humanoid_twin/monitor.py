"""The ground-truth run monitor: did the robot fall, how close did its CoP get to the edge of the
support polygon, how well did the firmware estimate each foot's CoP.

Public API (stable; ``scenarios.run``, the balance study and user controllers use it)::

    from humanoid_twin.monitor import Monitor
    twin = Twin(seed=0)
    mon = Monitor(twin)          # start_s=...: ignore the samples before that virtual time
    mon.attach()                 # samples on the twin's clock from now on
    ...                          # run the twin (serial requests, twin.run_for, ...)
    mon.fell, mon.fell_at_s, mon.trunk_tilt_max_deg, mon.cop_margin_min_mm, mon.cop_error_rms_mm
    mon.slip_mm                  # the largest distance a foot slid on the platform
    mon.last                     # the last sampled ``GroundTruth`` (CoP, support polygon, forces)
    mon.diverged                 # None, or why the simulation stopped being one (and diverged_at_s)

What it measures (the plant's ground truth, never visible to the firmware or the host):

- every 20 ms of virtual time (one PWM period, after the boards' ticks of that instant), the
  plant's :class:`~humanoid_twin.plant.plant.GroundTruth`: ``fell`` (trunk height above the
  platform, or its attitude, past the fall limits, docs/model.md), the largest trunk tilt, how
  far a foot slid along the platform (``slip_mm``), and the smallest **CoP margin**: the
  signed distance (mm) of the whole robot's centre of pressure inside the convex hull of the
  foot pads touching the platform (negative outside it; ``-inf`` while nothing touches);
- right after each leg board's own tick, the distance between the CoP that board computed from
  its force sensors (seed 000, ``calcCoP``) and the true CoP of its foot: ``cop_error_rms_mm``.

It only reads the plant; a run with and without it is the same run (its CAN log is identical).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import FOOT_OF_SCU, PWM_PERIOD_US
from humanoid_twin.plant.plant import GroundTruth
from humanoid_twin.twin import Twin

__all__ = ["Monitor", "SAMPLE_PERIOD_US"]

SAMPLE_PERIOD_US = PWM_PERIOD_US      # one sample of the truth per PWM period (20 ms)
SOLE_ON_SURFACE_MM = 5.0              # a sole origin this close to the platform stands on it (slip_mm)


@dataclass
class Monitor:
    """Samples the ground truth every 20 ms of virtual time: ``Monitor(twin, start_s=0.0)``.

    Attributes, updated while the twin runs: ``fell`` / ``fell_at_s`` (first sample that saw the
    robot fallen), ``trunk_tilt_max_deg``, ``slip_mm`` (the largest distance a sole moved along
    the platform while standing on it, since it was set down), ``cop_margin_min_mm`` (``inf`` before the first
    sample, ``-inf`` if nothing touched the platform at some sample), ``samples`` (number of
    truth samples) and ``last`` (the last :class:`GroundTruth` sampled, ``None`` before the
    first); property :attr:`cop_error_rms_mm`. Samples before ``start_s`` are ignored.
    """

    twin: Twin
    start_s: float = 0.0
    fell: bool = False
    trunk_tilt_max_deg: float = 0.0
    cop_margin_min_mm: float = math.inf
    _cop_err_sq: float = 0.0
    _cop_err_n: int = 0
    samples: int = 0
    fell_at_s: float | None = None
    slip_mm: float = 0.0
    last: GroundTruth | None = field(default=None, repr=False)
    _soles0: list | None = field(default=None, repr=False)
    # the simulation diverged (Plant.divergence: MuJoCo's instability warning, a non-finite state):
    # why and when (first sample that saw it); the samples after it are not counted. ``on_diverged``
    # is called then (``scenarios.run`` ends the run); without it, the reason is one line on stderr
    diverged: str | None = None
    diverged_at_s: float | None = None
    on_diverged: Callable[[], None] | None = field(default=None, repr=False)

    def attach(self) -> None:
        """Register on the twin's clock: the truth every 20 ms, and the CoP comparison of each
        leg board right after its own tick (its force samples and the truth of the same instant)."""
        self.twin.every(SAMPLE_PERIOD_US, self.sample)
        for scu, foot in FOOT_OF_SCU.items():
            first = self.twin.slaves[scu].next_tick_us()
            self.twin.every(SAMPLE_PERIOD_US, partial(self.compare_cop, scu, foot), first)

    def sample(self) -> None:
        """One 20 ms sample of the truth (after the boards' ticks at this instant)."""
        twin = self.twin
        if self.diverged is not None:
            return
        why = twin.plant.divergence()
        if why is not None:
            self.diverged, self.diverged_at_s = why, twin.now_s
            if self.on_diverged is not None:
                self.on_diverged()
            else:
                sys.stderr.write(f"humanoid-twin: the simulation diverged at t={twin.now_s:.3f} s: {why}\n")
            return
        if twin.clock.now_us < self.start_s * US_PER_S:
            return
        gt = twin.plant.truth()
        self.last = gt
        self.samples += 1
        if gt.fell and not self.fell:
            self.fell = True
            self.fell_at_s = twin.now_s
        tilt = gt.trunk_tilt_deg
        if tilt > self.trunk_tilt_max_deg:          # max(): NaN leaves it
            self.trunk_tilt_max_deg = tilt
        # -inf when nothing touches the platform (the robot is in the air or lying)
        margin = gt.cop_margin_mm
        if margin < self.cop_margin_min_mm:         # min(): NaN leaves it
            self.cop_margin_min_mm = margin
        # how far a foot standing on the platform has slid since it was set down (in the
        # platform's frame): the first sample, or the first sample after it was lifted (more
        # than SOLE_ON_SURFACE_MM above the surface: a step is not a slide)
        soles = gt.soles_on_surface_mm
        ref = self._soles0
        if ref is None:
            ref = self._soles0 = [None] * len(soles)
        for f, (x, y, h) in enumerate(soles):
            if h >= SOLE_ON_SURFACE_MM:
                ref[f] = None
                continue
            r = ref[f]
            if r is None:
                ref[f] = (x, y)
                continue
            d = math.hypot(x - r[0], y - r[1])
            if d > self.slip_mm:
                self.slip_mm = d

    def compare_cop(self, scu: int, foot: str) -> None:
        """Firmware CoP of board ``scu`` (computed at its tick, just now) vs the contact CoP."""
        twin = self.twin
        slave = twin.slaves[scu]
        if not slave.cop_loaded or twin.clock.now_us < self.start_s * US_PER_S or not slave.calibrated:
            return
        truth = twin.plant.foot_cop_xy_mm(foot)
        if truth is None:
            return
        dx = slave.cop_x - truth[0]
        dy = slave.cop_y - truth[1]
        self._cop_err_sq += dx * dx + dy * dy
        self._cop_err_n += 1

    @property
    def cop_error_rms_mm(self) -> float | None:
        """RMS distance (mm) between the firmware's and the true CoP of the loaded feet, over
        the leg boards' ticks since ``start_s``; ``None`` before any loaded-foot tick."""
        if self._cop_err_n == 0:
            return None
        return math.sqrt(self._cop_err_sq / self._cop_err_n)
