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

import numpy as np

from humanoid_twin.faults import FaultInjector, FaultSpec
from humanoid_twin.hardware import FOOT_OF_SCU, PWM_PERIOD_US
from humanoid_twin.host import drivers
from humanoid_twin.host.motion import exe_traj, power_on, send_gains
from humanoid_twin.host.planners import GAINS, LEG_SCUS, empty_plan, flexao, inclinar, levantar_perna
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.master.supervisor import ESTOP, SAFE, SupervisorConfig
from humanoid_twin.protocol.rs232 import ControlType
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
    # The ground-truth monitor behind fell / trunk tilt / CoP margin / CoP error. Off only for
    # scripts/bench.py, which times the twin itself (like recording, it is instrumentation).
    monitor: bool = True
    # python-can interface of the CAN wire: the project's own "humanoid_twin" (frames delivered in
    # virtual time only to the nodes whose slide-23 filters take them), or "virtual" / "socketcan"
    can_interface: str = "humanoid_twin"
    can_channel: str | None = None
    # injected faults (humanoid_twin/faults.py) and the supervisor's thresholds (docs/supervisor.md)
    faults: tuple[FaultSpec, ...] = ()
    supervisor: SupervisorConfig | None = None


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
        """Register on the twin's clock: the truth every 20 ms, and the CoP comparison of each
        leg board right after its own tick (its force samples and the truth of the same instant)."""
        self.twin.every(PWM_PERIOD_US, self.sample)
        for scu, foot in FOOT_OF_SCU.items():
            first = self.twin.slaves[scu].next_tick_us()
            self.twin.every(PWM_PERIOD_US, lambda scu=scu, foot=foot: self.compare_cop(scu, foot), first)

    def sample(self) -> None:
        """One 20 ms sample of the truth (after the boards' ticks at this instant)."""
        twin = self.twin
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

    def compare_cop(self, scu: int, foot: str) -> None:
        """Firmware CoP of board ``scu`` (computed at its tick, just now) vs the contact CoP."""
        twin = self.twin
        slave = twin.slaves[scu]
        if twin.now_s < self.start_s or not slave.cop_loaded or not slave.calibrated:
            return
        truth = twin.plant.foot_cop_mm(foot)
        if truth is None:
            return
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


@dataclass
class Plan:
    """What a scenario asks of the robot: the planner's ``pos_apply``, ``k``, ``t`` (table 23)."""

    pos_apply: np.ndarray
    k: np.ndarray
    t: np.ndarray

    def with_control(self, ctype: int) -> Plan:
        """The same motions with every leg and hip board (SCU 1-4) on control type ``ctype``
        (and that type's default gains): ``--control``."""
        k = self.k.copy()
        for row in range(len(LEG_SCUS)):
            k[row, :, :, :3] = np.asarray(GAINS[ControlType(ctype)])[:, None, :]
            k[row, :, :, 3] = ctype
        return Plan(self.pos_apply, k, self.t)


# Default planner arguments per scenario (``--T``, ``--motion``).
DEFAULT_T_S = 1.0
DEFAULT_MOTION_DEG = {"flexao": 20.0, "inclinar": 10.0, "levantar_perna": 40.0}


@dataclass(frozen=True)
class ScenarioInfo:
    """What ``--help`` says about a scenario: one English line and its planner defaults (``T_s``
    and ``motion_deg`` are None where the scenario has no such argument)."""

    name: str
    help: str
    T_s: float | None = None
    motion_deg: float | None = None
    motion_means: str = ""

    def defaults(self) -> str:
        """``--T 1 s, --motion 20 deg (the ankle's bend)``, or why there are none."""
        if self.T_s is None:
            return "no planner: --T and --motion do not apply"
        return f"--T {self.T_s:g} s, --motion {self.motion_deg:g} deg ({self.motion_means})"


# The scenarios in English (the planners keep the manual's Portuguese names, seed 000 table 22).
SCENARIO_INFO: dict[str, ScenarioInfo] = {
    "stand": ScenarioInfo(
        "stand", "stand still, balance control on the legs (add --tilt DEG to tilt the platform)"),
    "flexao": ScenarioInfo(
        "flexao", "squat: both legs bend (ankle, knee, hip), feet flat, trunk upright, and hold",
        DEFAULT_T_S, DEFAULT_MOTION_DEG["flexao"], "the ankle's bend; the knee bends twice that"),
    "inclinar": ScenarioInfo(
        "inclinar", "lateral lean: both legs roll sideways, feet flat, trunk upright (+ = to the left)",
        DEFAULT_T_S, DEFAULT_MOTION_DEG["inclinar"], "the foot's lateral joint"),
    "levantar_perna": ScenarioInfo(
        "levantar_perna", "lift a leg (--perna 1 right, 2 left, other: both bend): shift, raise, hold, lower",
        DEFAULT_T_S, DEFAULT_MOTION_DEG["levantar_perna"], "the lifted leg's knee"),
}
# ``stand``: the vertical posture, both feet down, BALANCE_CONTROL on the leg boards and
# LOCOMOTION_CONTROL on the hips. In double support the two legs must not run the same law
# (they fight through the pelvis, docs/balance.md): the right leg leads (its foot front joint
# moves the mass centre to put its CoP on the foot centre, KP 1, KD 2: gain 1/4) and the left
# leg follows (KP -8, KD 2: its foot front joint turns the foot to centre its own CoP, 8 times as
# fast); foot lateral and knee gains 0 (the lateral CoP of a foot in double support is an internal
# force; a knee bent on one leg only twists the pelvis). Rows: servos 1-3, (KI, KP, KD) bytes.
# Measured (scripts/balance_study.py, docs/balance.md): largest platform tilt held 36 deg toes up,
# 37 toes down, against 13 / 12 deg with the controllers off; BALANCE holds from gain 1/8 to 1/2.
STAND_CONTROL = {1: ControlType.BALANCE_CONTROL, 2: ControlType.BALANCE_CONTROL,
                 3: ControlType.LOCOMOTION_CONTROL, 4: ControlType.LOCOMOTION_CONTROL}
STAND_LEAD_KP, STAND_FOLLOW_KP, STAND_KD = 1, -8, 2
STAND_GAINS: dict[int, tuple[tuple[int, int, int], ...]] = {
    1: ((0, 0, 0), (0, STAND_LEAD_KP & 0xFF, STAND_KD), (0, 0, 0)),
    2: ((0, 0, 0), (0, STAND_FOLLOW_KP & 0xFF, STAND_KD), (0, 0, 0)),
}


def plan(scenario: str, T: float | None = None, motion: float | None = None, perna: int = 1) -> Plan:
    """The planner call of a scenario with its defaults."""
    if scenario not in SCENARIOS:
        raise ScenarioError(f"unknown scenario {scenario!r} (choose from {', '.join(SCENARIOS)})")
    if scenario == "stand":
        pos, k, t = empty_plan(1)
        for scu, ctype in STAND_CONTROL.items():
            k[scu - 1, :, 0, :3] = STAND_GAINS.get(scu, GAINS[ctype])
            k[scu - 1, :, 0, 3] = int(ctype)
        t[0] = DEFAULT_T_S
        return Plan(pos, k, t)
    period = DEFAULT_T_S if T is None else T
    amount = DEFAULT_MOTION_DEG[scenario] if motion is None else motion
    if scenario == "flexao":
        return Plan(*flexao(period, amount))
    if scenario == "inclinar":
        return Plan(*inclinar(period, amount))
    return Plan(*levantar_perna(period, amount, perna))


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


def run(opts: RunOptions, on_progress: Callable[[float, float | None], None] | None = None
        ) -> dict[str, Any]:
    """Run one scenario headless and return the SPEC.md section 6 summary.

    ``on_progress(t_s, end_s)`` is called every 0.1 s of virtual time: ``end_s`` is None during
    the boot (its length is not known in advance), then the run's end time."""
    if opts.scenario not in SCENARIOS:
        raise ScenarioError(f"unknown scenario {opts.scenario!r} (choose from {', '.join(SCENARIOS)})")
    twin = Twin(seed=opts.seed, can_interface=opts.can_interface, can_channel=opts.can_channel,
                supervisor=opts.supervisor)
    sup = twin.master.supervisor
    injector = FaultInjector(twin, opts.faults, opts.seed)
    host_error: str | None = None

    def stopped() -> bool:
        return sup.mode in (SAFE, ESTOP)

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
        if opts.monitor:
            monitor.attach()
        if recorder is not None:
            rec_ = recorder
            injector.listeners.append(
                lambda t, what, spec: rec_.log_event(t, f"injected {spec.text}: {what}", "WARN"))
        injector.install()
        end: list[float | None] = [None]      # the run's end time, known once the boot is over
        if on_progress is not None:
            twin.every(100_000, lambda: on_progress(twin.now_s, end[0]))
        H = twin.open_port()
        try:
            power_on(H, timeout=BOOT_TIMEOUT_S)
        except drivers.CommError as exc:
            if not stopped() and not opts.faults:
                raise ScenarioError(f"the twin did not boot: {exc}") from exc
            host_error = f"boot: {exc}"     # the supervisor stopped the boot: the run goes on
        boot_s = twin.now_s
        the_plan = plan(opts.scenario, T=opts.T, motion=opts.motion, perna=opts.perna)
        if opts.control is not None:
            the_plan = the_plan.with_control(CONTROL_CHOICES[opts.control])
        motion_s = 0.0 if opts.scenario == "stand" else float(np.sum(the_plan.t))
        tilt_s = abs(opts.tilt) / TILT_RATE_DEG_S
        duration = opts.duration
        if duration is None:
            duration = boot_s + max(motion_s, tilt_s) + SETTLE_S
        if opts.tilt:
            twin.plant.set_tilt_profile(tilt_profile(opts.tilt, boot_s))
        end[0] = duration
        try:
            if host_error is not None:
                pass
            elif opts.scenario == "stand":
                for scu in LEG_SCUS:
                    send_gains(H, scu, the_plan.k[scu - 1, :, 0, :])
            elif duration > twin.now_s:
                exe_traj(H, the_plan.t, the_plan.pos_apply, 0.0, k=the_plan.k)
        except drivers.CommError as exc:
            # with the supervisor stopped, or faults injected, a failed request is part of what
            # the run shows (summary host_error); the robot is left to the firmware meanwhile
            if not stopped() and not opts.faults:
                raise ScenarioError(f"{opts.scenario}: {exc}") from exc
            host_error = f"{opts.scenario}: {exc}"
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
            "mode": sup.mode_name,
            "faults": [f.as_dict() for f in sup.faults],
            "injected": [s.as_dict() for s in opts.faults],
        }
        if host_error is not None:
            summary["host_error"] = host_error
        return summary
    finally:
        if recorder is not None:
            recorder.close()
        if canlog is not None:
            canlog.close()
        twin.close()


def _round(x: float | None) -> float | None:
    return None if x is None else round(x, 3)


# cop_margin_min_mm when no foot pad touched the platform at some sample (airborne or fallen):
# the CoP is then outside any support polygon, by more than any foot length.
NO_SUPPORT_MARGIN_MM = -1000.0


def _finite(x: float) -> float | None:
    if math.isinf(x):
        return None if x > 0 else NO_SUPPORT_MARGIN_MM
    return round(max(x, NO_SUPPORT_MARGIN_MM), 3)


__all__ = ["RunOptions", "Monitor", "Plan", "ScenarioError", "ScenarioInfo", "SCENARIOS", "SCENARIO_INFO",
           "CONTROL_CHOICES", "plan",
           "run", "tilt_profile"]
