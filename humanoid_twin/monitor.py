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
    mon.trunk_tilt_max_at_s, mon.cop_margin_min_at_s, mon.slip_mm_at_s   # when each extreme was reached
    mon.start_motion(t_s)        # from t_s on, also the extremes over the motion alone:
    mon.motion.cop_margin_min_mm, mon.motion.trunk_tilt_max_deg (and their ``_at_s``)
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

Each extreme comes with the simulated time of the first sample that reached it (``..._at_s``).
The same extremes are also kept over **the motion alone** (:attr:`Monitor.motion`), from the
instant :meth:`Monitor.start_motion` names: :class:`~humanoid_twin.rig.Rig` sets it
:data:`CONTROLLERS_START_S` after the boot's end, once the controllers the scenario's program set
have taken hold, so that a sweep over the platform's tilt shows the tilt's effect, not the
start-up (docs/scenarios.md, "When").

It only reads the plant; a run with and without it is the same run (its CAN log is identical).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import FOOT_OF_SCU, PWM_PERIOD_US
from humanoid_twin.plant.plant import GroundTruth
from humanoid_twin.twin import Twin

__all__ = ["Monitor", "Extremes", "SoleSlide", "SAMPLE_PERIOD_US", "CONTROLLERS_START_S"]

SAMPLE_PERIOD_US = PWM_PERIOD_US      # one sample of the truth per PWM period (20 ms)
SOLE_ON_SURFACE_MM = 5.0              # a sole origin this close to the platform stands on it (slip_mm)
# The controllers' start: how long after the boot's end the extremes "over the motion alone"
# begin. The scenario's program sets the leg boards' control types and gains as the boot ends;
# the balance laws then take hold of a robot that stood on open-loop positions, and its CoP makes
# one large swing before the laws' steady motion (``stand``, seed 0: the swing's low, 34.75 mm
# from the edge, falls at 4.20 s, 1.55 s after the boot, whatever the platform's tilt; from 4.40 s
# on the margin stays within the steady swings). 2 s covers it.
CONTROLLERS_START_S = 2.0


@dataclass
class Extremes:
    """The largest trunk tilt and the smallest CoP margin over a span of samples, each with the
    simulated time of the first sample that reached it (None: no sample yet)."""

    trunk_tilt_max_deg: float = 0.0
    trunk_tilt_max_at_s: float | None = None
    cop_margin_min_mm: float = math.inf
    cop_margin_min_at_s: float | None = None
    samples: int = 0

    def add(self, t_s: float, tilt: float, margin: float) -> None:
        """One sample at ``t_s``: a NaN leaves both (max()/min() semantics of the comparisons)."""
        self.samples += 1
        first = self.trunk_tilt_max_at_s is None
        if tilt > self.trunk_tilt_max_deg or (first and tilt >= self.trunk_tilt_max_deg):
            self.trunk_tilt_max_deg = tilt
            self.trunk_tilt_max_at_s = t_s
        if margin < self.cop_margin_min_mm:
            self.cop_margin_min_mm = margin
            self.cop_margin_min_at_s = t_s


class SoleSlide:
    """How far a foot standing on the platform has slid since it was set down (in the
    platform's frame, mm): from its first sample, or the first sample after it was lifted (more
    than :data:`SOLE_ON_SURFACE_MM` above the surface: a step is not a slide). ``add`` takes one
    sample of ``Plant.soles_on_surface_mm`` and returns the largest slide of that sample (0 for
    none); ``slip_mm`` is the largest so far."""

    def __init__(self) -> None:
        self._ref: list[tuple[float, float] | None] | None = None
        self.slip_mm = 0.0

    def add(self, soles: Sequence[tuple[float, float, float]]) -> float:
        ref = self._ref
        if ref is None:
            ref = self._ref = [None] * len(soles)
        out = 0.0
        for f, (x, y, h) in enumerate(soles):
            if h >= SOLE_ON_SURFACE_MM:
                ref[f] = None
                continue
            r = ref[f]
            if r is None:
                ref[f] = (x, y)
                continue
            d = math.hypot(x - r[0], y - r[1])
            if d > out:
                out = d
        if out > self.slip_mm:
            self.slip_mm = out
        return out


@dataclass
class Monitor:
    """Samples the ground truth every 20 ms of virtual time: ``Monitor(twin, start_s=0.0)``.

    Attributes, updated while the twin runs: ``fell`` / ``fell_at_s`` (first sample that saw the
    robot fallen), ``trunk_tilt_max_deg``, ``slip_mm`` (the largest distance a sole moved along
    the platform while standing on it, since it was set down), ``cop_margin_min_mm`` (``inf`` before the first
    sample, ``-inf`` if nothing touched the platform at some sample), each with the time of the
    first sample that reached it (``trunk_tilt_max_at_s``, ``slip_mm_at_s``,
    ``cop_margin_min_at_s``; None before), ``motion`` (the same extremes from
    :meth:`start_motion`'s instant on: an :class:`Extremes`, None before it is called),
    ``samples`` (number of truth samples) and ``last`` (the last :class:`GroundTruth` sampled,
    ``None`` before the first); property :attr:`cop_error_rms_mm`. Samples before ``start_s``
    are ignored.
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
    _slide: SoleSlide = field(default_factory=lambda: SoleSlide(), repr=False)
    # the simulation diverged (Plant.divergence: MuJoCo's instability warning, a non-finite state):
    # why and when (first sample that saw it); the samples after it are not counted. ``on_diverged``
    # is called then (``scenarios.run`` ends the run); without it, the reason is one line on stderr
    diverged: str | None = None
    diverged_at_s: float | None = None
    on_diverged: Callable[[], None] | None = field(default=None, repr=False)
    trunk_tilt_max_at_s: float | None = None
    cop_margin_min_at_s: float | None = None
    slip_mm_at_s: float | None = None
    motion: Extremes | None = None
    motion_from_s: float | None = None

    def start_motion(self, t_s: float) -> None:
        """Keep the extremes over the motion alone (:attr:`motion`) from virtual time ``t_s`` on."""
        self.motion_from_s = t_s
        self.motion = Extremes()

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
        if self.diverged is not None or self._diverges():
            return
        if twin.clock.now_us < self.start_s * US_PER_S:
            return
        gt = twin.plant.truth()
        self.last = gt
        self.samples += 1
        if gt.fell and not self.fell:
            self.fell = True
            self.fell_at_s = twin.now_s
        now_s = twin.now_s
        self._extremes(gt, now_s)
        self._slid(gt, now_s)

    def _diverges(self) -> bool:
        """Whether the simulation diverged at this sample (reported once: ``on_diverged``, or one
        line on stderr)."""
        twin = self.twin
        why = twin.plant.divergence()
        if why is None:
            return False
        self.diverged, self.diverged_at_s = why, twin.now_s
        if self.on_diverged is not None:
            self.on_diverged()
        else:
            sys.stderr.write(f"humanoid-twin: the simulation diverged at t={twin.now_s:.3f} s: {why}\n")
        return True

    def _extremes(self, gt: GroundTruth, now_s: float) -> None:
        """The trunk's largest tilt and the CoP's smallest margin, and when (the run's; the
        motion's from :attr:`motion_from_s`)."""
        tilt = gt.trunk_tilt_deg
        if tilt > self.trunk_tilt_max_deg or (self.trunk_tilt_max_at_s is None
                                              and tilt >= self.trunk_tilt_max_deg):   # NaN leaves it
            self.trunk_tilt_max_deg = tilt
            self.trunk_tilt_max_at_s = now_s
        # -inf when nothing touches the platform (the robot is in the air or lying)
        margin = gt.cop_margin_mm
        if margin < self.cop_margin_min_mm:         # min(): NaN leaves it
            self.cop_margin_min_mm = margin
            self.cop_margin_min_at_s = now_s
        motion = self.motion
        if motion is not None and self.motion_from_s is not None and now_s >= self.motion_from_s:
            motion.add(now_s, tilt, margin)
    def _slid(self, gt: GroundTruth, now_s: float) -> None:
        """How far a foot standing on the platform has slid since it was set down
        (:class:`SoleSlide`), the run's largest and when."""
        d = self._slide.add(gt.soles_on_surface_mm)
        if d > self.slip_mm:
            self.slip_mm = d
            self.slip_mm_at_s = now_s

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
