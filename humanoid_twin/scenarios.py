"""Scenarios a user runs headless: ``humanoid-twin run stand|flexao|inclinar|levantar_perna``.

A scenario is host code talking to the in-process twin through its pyserial URL, exactly as the
MATLAB toolbox talked to the robot: boot (positions, period, PWM on: the Slaves calibrate), set the
controllers, run the planner's motions with ``exe_traj``, let the robot settle. Meanwhile a
:class:`Monitor` samples the plant's ground truth every 20 ms for the summary (SPEC.md section 6).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import FOOT_OF_SCU, N_SCU, PWM_PERIOD_US
from humanoid_twin.host import drivers
from humanoid_twin.host.timebase import now as host_now
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.protocol.canframes import parse_status_byte
from humanoid_twin.protocol.rs232 import PARAM_CONTROLON, PARAM_POSITION, PARAM_SPECIAL, PARAM_VELOCITY
from humanoid_twin.twin import Twin

SCENARIOS = ("stand", "flexao", "inclinar", "levantar_perna")
CONTROL_CHOICES = {"none": 0, "locomotion": 1, "reaction": 2, "balance": 3}
BOOT_TIMEOUT_S = 5.0
TILT_RATE_DEG_S = 1.0       # "the floor platform tilts slowly": 1 degree per second
SETTLE_S = 2.0


class ScenarioError(RuntimeError):
    """A scenario could not run (the twin did not boot, a request failed ...)."""


@dataclass
class RunOptions:
    """The ``humanoid-twin run`` options (SPEC.md section 6)."""

    scenario: str = "stand"
    duration: float | None = None
    T: float | None = None
    motion: float | None = None
    perna: int = 1
    out: Path | None = None
    can_log: Path | None = None
    control: str | None = None
    tilt: float = 0.0
    seed: int = 0
    progress: bool = True


@dataclass
class Monitor:
    """Samples the ground truth every 20 ms of virtual time for the run summary."""

    twin: Twin
    start_s: float = 0.0
    fell: bool = False
    trunk_tilt_max_deg: float = 0.0
    cop_margin_min_mm: float = math.inf
    _cop_err_sq: float = 0.0
    _cop_err_n: int = 0
    samples: int = 0
    fell_at_s: float | None = None
    tilt_deg: list[float] = field(default_factory=list)

    def attach(self) -> None:
        """Register on the twin's clock."""
        self.twin.every(PWM_PERIOD_US, self.sample)

    def sample(self) -> None:
        """One 20 ms sample of the truth (after the boards' ticks at this instant)."""
        twin = self.twin
        twin.plant.advance_to(twin.clock.now_us)
        if twin.now_s < self.start_s:
            return
        gt = twin.plant.truth()
        self.samples += 1
        if gt.fell and not self.fell:
            self.fell = True
            self.fell_at_s = twin.now_s
        self.trunk_tilt_max_deg = max(self.trunk_tilt_max_deg, gt.trunk_tilt_deg)
        # -inf when nothing touches the platform (the robot is in the air or lying)
        self.cop_margin_min_mm = min(self.cop_margin_min_mm, gt.cop_margin_mm)
        for scu, foot in FOOT_OF_SCU.items():
            slave = twin.slaves[scu]
            truth = gt.foot_cop_mm.get(foot)
            if truth is None or not slave.cop_loaded or not slave.calibrated:
                continue
            dx = slave.cop_x - truth[0]
            dy = slave.cop_y - truth[1]
            self._cop_err_sq += dx * dx + dy * dy
            self._cop_err_n += 1

    @property
    def cop_error_rms_mm(self) -> float | None:
        """RMS distance between the firmware's and the true CoP of the loaded feet."""
        if self._cop_err_n == 0:
            return None
        return math.sqrt(self._cop_err_sq / self._cop_err_n)


def boot(H: Any, pose: dict[int, list[int]] | None = None, timeout_s: float = BOOT_TIMEOUT_S) -> float:
    """Power the robot up as the toolbox did: per SCU the stand positions, period 0, PWM on.

    The Slaves take that first actuation with PWM on as the start of their calibration
    (seed 000, SERVO ``calibration``: move, wait 2 s, 25 samples); this waits until every
    board reports its Calib status bit, and returns the virtual time it took.
    """
    from humanoid_twin.host.motion import adaptate

    t0 = host_now(H)
    for scu in range(1, N_SCU + 1):
        servo = adaptate(scu, (pose or {}).get(scu, [0, 0, 0]))
        _ok(drivers.applyjoint(H, scu, PARAM_POSITION, [int(round(v)) for v in servo]), "boot position", scu)
        _ok(drivers.applyjoint(H, scu, PARAM_VELOCITY, [0, 0, 0]), "boot period", scu)
        _ok(drivers.applyjoint(H, scu, PARAM_SPECIAL, [1, 0, 0]), "PWM on", scu)
    pending = set(range(1, N_SCU + 1))
    while pending:
        if host_now(H) - t0 > timeout_s:
            raise ScenarioError(f"boards {sorted(pending)} did not finish calibration in {timeout_s} s")
        host_sleep(H, 0.1)
        for scu in sorted(pending):
            r = drivers.readjoint(H, scu, PARAM_POSITION)
            if r.error == drivers.ErrorCode.OK and parse_status_byte(r.state).calib:
                pending.discard(scu)
    return host_now(H) - t0


def set_control(H: Any, types: dict[int, int]) -> None:
    """APPLY_CONTROL CONTROLON with one control type for all three servos of each given SCU."""
    for scu, ctype in types.items():
        _ok(drivers.applycontrol(H, scu, PARAM_CONTROLON, [ctype] * 3), "control type", scu)


def _ok(result: Any, what: str, scu: int) -> None:
    if result.error != drivers.ErrorCode.OK:
        raise ScenarioError(f"{what} on SCU {scu} failed: {result.errorstr} (after {result.tries} tries)")


def tilt_profile(
    target_deg: float, start_s: float, rate_deg_s: float = TILT_RATE_DEG_S
) -> Callable[[float], float]:
    """Platform pitch vs time: flat until ``start_s``, then a ramp at ``rate_deg_s`` to ``target_deg``."""

    def profile(t: float) -> float:
        if t <= start_s or target_deg == 0:
            return 0.0
        ramp = (t - start_s) * rate_deg_s
        return math.copysign(min(abs(target_deg), ramp), target_deg)

    return profile


def run(opts: RunOptions, on_progress: Callable[[float, float], None] | None = None) -> dict[str, Any]:
    """Run one scenario headless and return the SPEC.md section 6 summary."""
    from humanoid_twin.host import motion

    if opts.scenario not in SCENARIOS:
        raise ScenarioError(f"unknown scenario {opts.scenario!r} (choose from {', '.join(SCENARIOS)})")
    twin = Twin(seed=opts.seed)
    recorder = canlog = None
    wall0 = time.perf_counter()
    try:
        if opts.out is not None:
            from humanoid_twin.recording import Recorder

            recorder = Recorder(opts.out, twin)
        if opts.can_log is not None:
            from humanoid_twin.recording import CanLog

            canlog = CanLog(opts.can_log, twin.network)
        monitor = Monitor(twin)
        monitor.attach()
        H = twin.open_port()
        boot_s = boot(H)
        plan = motion.plan(opts.scenario, T=opts.T, motion=opts.motion, perna=opts.perna)
        if opts.control is not None:
            plan = plan.with_control(CONTROL_CHOICES[opts.control])
        motion_s = float(sum(plan.t))
        tilt_s = abs(opts.tilt) / TILT_RATE_DEG_S
        duration = opts.duration
        if duration is None:
            duration = boot_s + max(motion_s, tilt_s) + SETTLE_S
        t_start = twin.now_s
        if opts.tilt:
            twin.plant.set_tilt_profile(tilt_profile(opts.tilt, t_start))
        if on_progress is not None:
            twin.every(100_000, lambda: on_progress(twin.now_s, duration))
        set_control(H, plan.control_types())
        remaining = duration - twin.now_s
        if plan.t and remaining > 0:
            motion.exe_traj(H, plan.t, plan.pos_apply, 0.0, k=plan.k)
        rest = duration - twin.now_s
        if rest > 0:
            host_sleep(H, rest)
        wall = time.perf_counter() - wall0
        summary = {
            "scenario": opts.scenario,
            "duration_s": round(twin.now_s, 6),
            "fell": monitor.fell,
            "fell_at_s": monitor.fell_at_s,
            "trunk_tilt_max_deg": round(monitor.trunk_tilt_max_deg, 3),
            "cop_margin_min_mm": _finite(monitor.cop_margin_min_mm),
            "cop_error_rms_mm": _round(monitor.cop_error_rms_mm),
            "wall_s": round(wall, 3),
            "rtf": round(twin.now_s / wall, 3) if wall > 0 else None,
            "can_frames": twin.network.frames_sent,
            "serial_frames": twin.master.stats()["serial_frames_received"],
            "boot_s": round(boot_s, 3),
            "tilt_deg": opts.tilt,
            "control": opts.control,
            "seed": opts.seed,
        }
        return summary
    finally:
        if recorder is not None:
            recorder.close()
        if canlog is not None:
            canlog.close()
        twin.close()


def _round(x: float | None) -> float | None:
    return None if x is None else round(x, 3)


def _finite(x: float) -> float | None:
    if math.isinf(x):
        return None if x > 0 else -1e9
    return round(x, 3)


__all__ = ["RunOptions", "Monitor", "ScenarioError", "SCENARIOS", "CONTROL_CHOICES", "boot", "run",
           "set_control", "tilt_profile", "US_PER_S"]
