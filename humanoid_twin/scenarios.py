"""Scenarios a user runs headless: ``humanoid-twin run stand|flexao|inclinar|levantar_perna``.

A scenario is host code talking to the in-process twin through its pyserial URL, exactly as the
MATLAB toolbox talked to the robot: :func:`boot` (positions, period, PWM on: the Slaves
calibrate), set the controllers, run the planner's motions with ``exe_traj``, let the robot
settle. Meanwhile a :class:`humanoid_twin.monitor.Monitor` samples the plant's ground truth every
20 ms for the summary (docs/scenarios.md).

The scenarios are a registry (:data:`REGISTRY`, in the style of dm_control's suite): one scenario
is one small factory below, decorated with :func:`scenario`, that returns its :class:`Plan` (the
planner's ``pos_apply``, ``k``, ``t`` of seed 000 table 23) from ``T``, ``motion`` and ``perna``.
Adding a scenario is adding one factory here: the CLI's choices, :func:`plan` and :func:`run`
read the registry. :func:`boot` is the one boot sequence (``run``, ``scripts/balance_study.py``
and the tests' ``booted_twin`` fixture use it).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from humanoid_twin.clock import US_PER_S
from humanoid_twin.controllers import load_host_controller, run_host_controller
from humanoid_twin.faults import FaultInjector, FaultSpec
from humanoid_twin.host import drivers
from humanoid_twin.host.motion import exe_traj, power_on, send_gains
from humanoid_twin.host.planners import (
    BALANCE_MOTIONS,
    LEG_SCUS,
    control_row,
    empty_plan,
    flexao,
    inclinar,
    levantar_perna,
    with_control,
)
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.master.supervisor import ESTOP, SAFE, SupervisorConfig
from humanoid_twin.monitor import Monitor
from humanoid_twin.protocol.wire import ControlType
from humanoid_twin.slave.laws import LawError, install_laws
from humanoid_twin.twin import Twin

CONTROL_CHOICES: dict[str, int] = {t.label: t for t in ControlType}   # run --control
BOOT_TIMEOUT_S = 5.0
# the boot cannot end sooner: the Slaves' calibration waits 100 PWM periods, then averages 25
# (seed 000 SERVO ``calibration``); a --duration below it is refused before the run starts
BOOT_MIN_S = (100 + 25) * 0.020
TILT_RATE_DEG_S = 1.0       # "the floor platform tilts slowly": 1 degree per second
SETTLE_S = 2.0


class ScenarioError(RuntimeError):
    """A scenario could not run (the twin did not boot, a request failed ...)."""


class ScenarioInputError(ScenarioError):
    """The options ask for something the run cannot do (a ``--duration`` shorter than the boot)."""


class _DurationReachedError(BaseException):
    """Raised by the clock at ``--duration`` when that instant falls inside the motion: the run is
    cut there and its summary says ``completed: false``. A ``BaseException``: a host controller's
    ``except Exception`` does not swallow it."""


class _HostBoundReachedError(BaseException):
    """Raised by the clock at the run's end while a host controller runs: whatever the
    controller does (sleeps, loops), the run ends at its duration (issue 24)."""


class _WallTimeoutError(BaseException):
    """SIGALRM at ``wall_timeout`` wall seconds (``run --wall-timeout``)."""


class BootError(ScenarioError):
    """:func:`boot` failed; ``port`` is the host end of the link, open (the run may go on)."""

    def __init__(self, message: str, port: Any) -> None:
        super().__init__(message)
        self.port = port


def boot(twin: Twin, timeout: float = BOOT_TIMEOUT_S) -> Any:
    """The one boot sequence: open the host end of the twin's RS-232 link and ``power_on`` every
    board (positions 0, movement period, PWM on; the Slaves calibrate). Returns the open port.
    Attach whatever observes the run (monitor, recorder, CAN log, faults) before calling it.
    :class:`BootError` (with the port) if a request fails."""
    H = twin.open_port()
    try:
        power_on(H, timeout=timeout)
    except drivers.CommError as exc:
        raise BootError(f"the twin did not boot: {exc}", H) from exc
    return H


def hold(H: Any, plan: Plan, scus: tuple[int, ...] = LEG_SCUS) -> None:
    """A scenario without motions: send the gains and control types of the plan's first motion
    to the boards ``scus`` (``applycontrol``) and let the firmware hold the posture."""
    for scu in scus:
        send_gains(H, scu, plan.k[scu - 1, :, 0, :])


@dataclass
class RunOptions:
    """The ``humanoid-twin run`` options (docs/scenarios.md)."""

    scenario: str = "stand"
    duration: float | None = None
    T: float | None = None
    motion: float | None = None
    perna: int = 1
    out: Path | None = None
    can_log: Path | None = None
    can_log_name: str | None = None     # the log's final file name, when can_log is a temporary one
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
    # user controllers (humanoid_twin/controllers.py, docs/controllers.md): firmware laws per
    # control type ((type name or number, law class or "module:Class"), ...), and a PC-side
    # step(ctx) called every host_period_ms once the scenario's own host commands are sent
    laws: tuple[tuple[int | str, Any], ...] = ()
    host_controller: Callable[..., Any] | str | None = None
    host_period_ms: float = 20.0
    # wall seconds the run may take (None: unbounded); beyond it the run ends with ScenarioError,
    # its files closed (``run --wall-timeout``, sweep's ``--timeout``)
    wall_timeout: float | None = None


_BALANCE_TYPES = (ControlType.REACTION_CONTROL, ControlType.BALANCE_CONTROL)
FOOT_SCUS = (1, 2)      # the leg boards (foot lateral, foot front, knee): the summary's ``control``


@dataclass
class Plan:
    """What a scenario asks of the robot: the planner's ``pos_apply``, ``k``, ``t`` (table 23)."""

    pos_apply: np.ndarray
    k: np.ndarray
    t: np.ndarray
    # per motion, the leg board (SCU 1 or 2) that carries the robot, and whether it carries it
    # alone (the other foot up); None: both feet down all along, the right leg leads (stand)
    lead: tuple[int, ...] | None = None
    single: tuple[bool, ...] | None = None

    def with_control(self, ctype: int, split: bool = False) -> Plan:
        """The same motions with every leg and hip board (SCU 1-4) on control type ``ctype``
        (and that type's default gains): ``--control``. ``split`` (the scenarios that keep both
        feet down, ``Scenario.double_support``: stand, flexao, inclinar): for REACTION and BALANCE
        the two legs get the leader/follower pair of :data:`STAND_GAINS` instead of the same law,
        which would make them fight through the pelvis (docs/balance.md 2.2). A plan with
        ``lead``/``single`` (levantar_perna) keeps its own division of labour instead: REACTION or
        BALANCE (with the law's single-support gains, ``planners.GAINS``) on the support leg
        where it carries the robot alone, every other board and motion as planned
        (docs/balance.md 4 has what the other splits measured)."""
        if split and self.single is not None and self.lead is not None and ctype in _BALANCE_TYPES:
            k = np.array(self.k, dtype=float, copy=True)
            for m, alone in enumerate(self.single):
                if alone:
                    k[self.lead[m] - 1, :, m] = control_row(ctype)
            return Plan(self.pos_apply, k, self.t, self.lead, self.single)
        k = with_control(self.k, ctype)
        if split and ctype in _BALANCE_TYPES:
            for scu, gains in STAND_GAINS.items():
                k[scu - 1] = control_row(ctype, gains)[:, None, :]
        return Plan(self.pos_apply, k, self.t, self.lead, self.single)


Factory = Callable[[float | None, float | None, int], Plan]


@dataclass(frozen=True)
class Scenario:
    """One registered scenario: its name, its factory ``(T, motion, perna) -> Plan`` (``None``
    = the scenario's default), and whether it moves (``exe_traj`` the plan's motions) or holds
    the boot posture with the plan's gains (:func:`hold`); ``double_support``: both feet stay
    down all along (``--control reaction|balance`` keeps the leader/follower split)."""

    name: str
    factory: Factory
    moves: bool = True
    double_support: bool = False
    doc: str = field(default="", compare=False)

    def plan(self, T: float | None = None, motion: float | None = None, perna: int = 1) -> Plan:
        """The scenario's plan with its defaults for the arguments left ``None``."""
        return self.factory(T, motion, perna)


REGISTRY: dict[str, Scenario] = {}


def scenario(name: str, *, moves: bool = True, double_support: bool = False) -> Callable[[Factory], Factory]:
    """Register the decorated factory ``(T, motion, perna) -> Plan`` as scenario ``name``."""

    def register(factory: Factory) -> Factory:
        if name in REGISTRY:
            raise ValueError(f"scenario {name!r} is registered twice")
        doc = (factory.__doc__ or "").strip().splitlines()
        REGISTRY[name] = Scenario(name, factory, moves, double_support, doc[0] if doc else "")
        return factory

    return register


def get_scenario(name: str) -> Scenario:
    """The registered scenario ``name``; :class:`ScenarioError` naming the choices otherwise."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ScenarioError(f"unknown scenario {name!r} (choose from {', '.join(REGISTRY)})") from None


DEFAULT_T_S = 1.0           # the planners' default motion period (``--T``)
# the planners' default angle (``--motion``, degrees) per scenario; ``--help`` shows them
DEFAULT_MOTION_DEG = {"flexao": 20.0, "inclinar": 10.0, "levantar_perna": 40.0}
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
    1: ((0, 0, 0), (0, STAND_LEAD_KP, STAND_KD), (0, 0, 0)),
    2: ((0, 0, 0), (0, STAND_FOLLOW_KP, STAND_KD), (0, 0, 0)),
}


@scenario("stand", moves=False, double_support=True)
def _stand(T: float | None, motion: float | None, perna: int) -> Plan:
    """stand still, balance control on the legs; --tilt DEG tilts the platform under it"""
    pos, k, t = empty_plan(1)
    for scu, ctype in STAND_CONTROL.items():
        k[scu - 1, :, 0] = control_row(ctype, STAND_GAINS.get(scu))
    t[0] = DEFAULT_T_S
    return Plan(pos, k, t)


@scenario("flexao", double_support=True)
def _flexao(T: float | None, motion: float | None, perna: int) -> Plan:
    """squat: both legs bend, feet flat, trunk upright (table 22); --motion = the ankle's bend"""
    default = DEFAULT_MOTION_DEG["flexao"]
    return Plan(*flexao(DEFAULT_T_S if T is None else T, default if motion is None else motion))


@scenario("inclinar", double_support=True)
def _inclinar(T: float | None, motion: float | None, perna: int) -> Plan:
    """lateral lean: both legs roll sideways, feet flat (table 22); --motion = foot lateral angle, + = left"""
    default = DEFAULT_MOTION_DEG["inclinar"]
    return Plan(*inclinar(DEFAULT_T_S if T is None else T, default if motion is None else motion))


@scenario("levantar_perna")
def _levantar_perna(T: float | None, motion: float | None, perna: int) -> Plan:
    """lift a leg: --perna 1 the right, 2 the left (table 22); --motion = the lifted knee's angle"""
    knee = DEFAULT_MOTION_DEG["levantar_perna"] if motion is None else motion
    pos, k, t = levantar_perna(DEFAULT_T_S if T is None else T, knee, perna)
    if perna not in (1, 2):
        return Plan(pos, k, t)
    support = 2 if perna == 1 else 1            # the leg board that stays down
    n = len(t)
    single = tuple(m in BALANCE_MOTIONS for m in range(n))   # the other foot is up
    return Plan(pos, k, t, lead=(support,) * n, single=single)


SCENARIOS: tuple[str, ...] = tuple(REGISTRY)   # the CLI's choices, in registration order
DOUBLE_SUPPORT_SCENARIOS: tuple[str, ...] = tuple(n for n, s in REGISTRY.items() if s.double_support)


def plan(scenario: str, T: float | None = None, motion: float | None = None, perna: int = 1) -> Plan:
    """The plan of the registered scenario ``scenario`` with its defaults."""
    return get_scenario(scenario).plan(T, motion, perna)


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


def _arm_wall_timeout(seconds: float | None) -> Callable[[], None]:
    """SIGALRM after ``seconds`` of wall time raises :class:`_WallTimeoutError` where the run is
    (also in a host controller's ``time.sleep``); returns the function that disarms it. Main
    thread only (elsewhere, and with None, nothing is armed)."""
    import signal
    import threading

    if seconds is None or threading.current_thread() is not threading.main_thread():
        return lambda: None

    fired = [0]

    def on_alarm(signum: int, frame: Any) -> None:
        # raised again every 0.5 s while user code swallows it; after 5 s of that, the process
        # ends (one line, temporary files removed, exit 1): humanoid_twin/signals.hard_exit
        fired[0] += 1
        if fired[0] > 10:
            from humanoid_twin.signals import hard_exit

            hard_exit(1, f"humanoid-twin: the run took more than {seconds:g} wall seconds (--wall-timeout) "
                      "and user code swallowed the stop: ended at once")
        raise _WallTimeoutError

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds, 0.5)

    def disarm() -> None:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous if previous is not None else signal.SIG_DFL)

    return disarm


def _arm_host_bound(twin: Twin, duration: float) -> dict[str, Any]:
    """From ``duration`` on, every 20 ms of the clock raises :class:`_HostBoundReachedError`
    while the returned dict's ``armed`` is true: a host controller cannot run the twin past the
    run's end, even one that swallows the first (``except BaseException``)."""
    state: dict[str, Any] = {"armed": True}

    def bound() -> None:
        if state["armed"]:
            twin.clock.schedule(twin.clock.now_us + 20_000, bound)
            raise _HostBoundReachedError

    twin.clock.schedule(max(round(duration * US_PER_S), twin.clock.now_us), bound)
    return state


def _after_boot_s(motion_s: float, tilt: float) -> float:
    """The run after the boot: the motion or the platform's tilt, whichever is longer, then settle."""
    return max(motion_s, abs(tilt) / TILT_RATE_DEG_S) + SETTLE_S


def expected_run_s(scenario: str, duration: float | None = None, T: float | None = None,
                   motion: float | None = None, perna: int = 1, tilt: float = 0.0) -> float:
    """How long a run lasts at most, in simulated seconds, known before it starts: ``duration``
    when given, else the boot's bound (:data:`BOOT_TIMEOUT_S`) + the motion or the tilt + the
    settling (what the CLI sizes the outputs' disk space by)."""
    if duration is not None:
        return duration
    spec = get_scenario(scenario)
    motion_s = float(np.sum(spec.plan(T, motion, perna).t)) if spec.moves else 0.0
    return BOOT_TIMEOUT_S + _after_boot_s(motion_s, tilt)


def run(opts: RunOptions, on_progress: Callable[[float, float | None], None] | None = None,
        on_twin: Callable[[Twin], None] | None = None) -> dict[str, Any]:
    """Run one scenario headless and return its summary (docs/scenarios.md).

    ``on_progress(t_s, end_s)`` is called every 0.1 s of virtual time: ``end_s`` is None during
    the boot (its length is not known in advance), then the run's end time. ``on_twin(twin)`` is
    called once the twin is built, before anything is written (``run --viewer`` attaches there)."""
    spec = get_scenario(opts.scenario)
    twin = Twin(seed=opts.seed, can_interface=opts.can_interface, can_channel=opts.can_channel,
                supervisor=opts.supervisor)
    if on_twin is not None:
        on_twin(twin)
    sup = twin.master.supervisor
    injector = FaultInjector(twin, opts.faults, opts.seed)
    if opts.laws:
        try:
            install_laws(twin, opts.laws)
        except LawError as exc:       # a law that cannot be made for every board: a bad --law
            twin.close()
            raise ScenarioInputError(str(exc)) from None
    host_step = load_host_controller(opts.host_controller) if opts.host_controller is not None else None
    host_error: str | None = None

    def stopped() -> bool:
        return sup.mode in (SAFE, ESTOP)

    recorder = canlog = None
    summary: dict[str, Any] | None = None
    wall0 = time.perf_counter()
    disarm = _arm_wall_timeout(opts.wall_timeout)
    try:
        the_plan = spec.plan(opts.T, opts.motion, opts.perna)
        if opts.control is not None:
            split = spec.double_support or the_plan.lead is not None
            the_plan = the_plan.with_control(CONTROL_CHOICES[opts.control], split=split)
        motion_s = float(np.sum(the_plan.t)) if spec.moves else 0.0
        after_boot_s = _after_boot_s(motion_s, opts.tilt)
        if opts.out is not None:
            from humanoid_twin.recording import Recorder, compact_for

            # the run's length, bounded from above before the boot (BOOT_TIMEOUT_S >= the boot)
            expected_s = opts.duration if opts.duration is not None else BOOT_TIMEOUT_S + after_boot_s
            recorder = Recorder(opts.out, twin, compact=compact_for(expected_s))
        if opts.can_log is not None:
            from humanoid_twin.recording import CanLog

            canlog = CanLog(opts.can_log, twin.network, name=opts.can_log_name)
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
        try:
            H = boot(twin)
        except BootError as exc:
            if not stopped() and not opts.faults:
                raise
            H = exc.port
            host_error = f"boot: {exc.__cause__}"     # the supervisor stopped the boot: the run goes on
        boot_s = twin.now_s
        if opts.duration is not None and opts.duration < boot_s:
            raise ScenarioInputError(
                f"--duration {opts.duration:g} is shorter than the boot ({boot_s:.3f} simulated seconds "
                "from power-on): give at least that")
        duration = opts.duration
        if duration is None:
            duration = boot_s + after_boot_s
        if opts.tilt:
            twin.plant.set_tilt_profile(tilt_profile(opts.tilt, boot_s))
        end[0] = duration
        completed = True
        if opts.duration is not None and spec.moves and duration < boot_s + motion_s:
            def cut() -> None:
                raise _DurationReachedError

            twin.clock.schedule(round(duration * US_PER_S), cut)
        host_calls = None
        try:
            try:
                if host_error is None and not spec.moves:
                    hold(H, the_plan)
                elif host_error is None and duration > twin.now_s:
                    exe_traj(H, the_plan.t, the_plan.pos_apply, 0.0, k=the_plan.k)
            except drivers.CommError as exc:
                # with the supervisor stopped, or faults injected, a failed request is part of what
                # the run shows (summary host_error); the robot is left to the firmware meanwhile
                if not stopped() and not opts.faults:
                    raise ScenarioError(f"{opts.scenario}: {exc}") from exc
                host_error = f"{opts.scenario}: {exc}"
            if host_step is not None and host_error is None:
                bound = _arm_host_bound(twin, duration)
                try:
                    host_calls = run_host_controller(H, host_step, monitor, duration, opts.host_period_ms,
                                                     should_stop=stopped).calls
                except _HostBoundReachedError as exc:  # the run reached its duration: completed
                    host_calls = exc.host_context.calls  # type: ignore[attr-defined]
                except drivers.CommError as exc:
                    if not stopped() and not opts.faults:
                        raise ScenarioError(f"host controller: {exc}") from exc
                    host_error = f"host controller: {exc}"
                except RuntimeError as exc:
                    raise ScenarioError(str(exc)) from exc
                finally:
                    bound["armed"] = False
            rest = duration - twin.now_s
            if rest > 0:
                host_sleep(H, rest)
        except _DurationReachedError:
            completed = False     # --duration fell inside the motion: cut there
        wall = time.perf_counter() - wall0
        summary = {
            "scenario": opts.scenario,
            "duration_s": round(twin.now_s, 6),
            "fell": monitor.fell,
            "fell_at_s": monitor.fell_at_s,
            "trunk_tilt_max_deg": round(monitor.trunk_tilt_max_deg, 3),
            "slip_mm": round(monitor.slip_mm, 1),
            "outcome": outcome(monitor.fell, monitor.slip_mm),
            "cop_margin_min_mm": _finite(monitor.cop_margin_min_mm),
            "cop_error_rms_mm": _round(monitor.cop_error_rms_mm),
            "wall_s": round(wall, 3),
            "rtf": round(twin.now_s / wall, 3) if wall > 0 else None,
            "can_frames": twin.network.frames_sent,
            "serial_frames": twin.master.stats()["serial_frames_received"],
            "boot_s": round(boot_s, 3),
            "completed": completed,
            "tilt_deg": opts.tilt,
            "control": _control_label(the_plan),
            "control_law": _law_label(twin, the_plan),
            "seed": opts.seed,
            "mode": sup.mode_name,
            "faults": [f.as_dict() for f in sup.faults],
            # the faults that started (one whose T0 lies beyond the run's end is listed apart)
            "injected": [s.as_dict() for s in opts.faults if _started(s, injector)],
        }
        not_started = [s.as_dict() for s in opts.faults if not _started(s, injector)]
        if not_started:
            summary["injected_not_started"] = not_started
        if host_error is not None:
            summary["host_error"] = host_error
        law_faults = [sl.servo.law_fault for sl in twin.slaves.values() if sl.servo.law_fault is not None]
        if law_faults:
            summary["law_faults"] = [f.as_dict() for f in law_faults]
        if host_calls is not None:
            summary["host_controller_calls"] = host_calls
        return summary
    except _WallTimeoutError:
        raise ScenarioError(f"the run took more than {opts.wall_timeout:g} wall seconds (--wall-timeout): "
                            f"stopped at t={twin.now_s:.3f} s simulated") from None
    finally:
        disarm()
        _close_all(recorder, canlog, twin)
        if summary is not None and recorder is not None and recorder.compaction_error is not None:
            # the compaction failed (no room for its copy, a signal): the file is kept as recorded
            summary["recording_compacted"] = False
            summary["recording_note"] = recorder.compaction_error


def _started(spec: FaultSpec, injector: FaultInjector) -> bool:
    return any(s is spec for s in injector.started)


def _close_all(*things: Any) -> None:
    """Close every output and the twin, each even when an earlier one failed; the first error
    is raised once all are closed (a recording that failed must not leave the CAN log open)."""
    first: BaseException | None = None
    for thing in things:
        if thing is None:
            continue
        try:
            thing.close()
        except BaseException as exc:    # noqa: BLE001 - raised again below, after the others
            first = first or exc
    if first is not None:
        raise first


# a foot that moved less than this along the platform held its place: a foot rolling onto an edge
# of its pads moves its sole origin a few mm without sliding (levantar_perna --perna 2: 7.1 mm)
SLIP_HELD_MM = 10.0


def outcome(fell: bool, slip_mm: float) -> str:
    """The run in one word: ``fell`` (the plant's fall test, against the platform), ``slid`` (did
    not fall, but a foot moved ``SLIP_HELD_MM`` or more along the platform), or ``held``."""
    if fell:
        return "fell"
    return "slid" if slip_mm >= SLIP_HELD_MM else "held"


# Every key a run's summary may hold, in the order the summary gives them, with what it means:
# docs/scenarios.md's table is generated from this (scripts/gen_docs.py; a test fails when they
# drift, another when a run's summary holds a key that is not here).
SUMMARY_KEYS: dict[str, str] = {
    "scenario": "the scenario run",
    "duration_s": "simulated seconds run (boot included)",
    "fell": "the plant's fall test at any 20 ms sample, against the platform the feet stand on: the "
            "trunk origin less than 0.12 m above the platform's plane, or the trunk more than 45 deg "
            "from both the vertical and the platform's normal (humanoid_twin/models/README.md section 9)",
    "fell_at_s": "the first sample that saw the robot fallen (none: it did not fall)",
    "trunk_tilt_max_deg": "largest angle between the trunk's z axis and the vertical",
    "slip_mm": "the largest distance a sole moved along the platform's surface while standing on it "
               "(since the run began, or since that foot was last set down): feet sliding down a "
               "tilted platform, not a fall",
    "outcome": "the run in one word: `fell`; `slid` (not fallen, but `slip_mm` reached 10 mm: a foot "
               "rolling onto an edge of its pads moves a few mm without sliding); `held`",
    "cop_margin_min_mm": "smallest signed distance of the ground-truth CoP (MuJoCo contact forces) inside "
                         "the support polygon (hull of the foot pads in contact), sampled every 20 ms; "
                         "negative when outside; **-1000** when at some sample no pad touched the "
                         "platform (the robot in the air or lying)",
    "cop_error_rms_mm": "RMS distance between each leg board's firmware CoP (`calcCoP`, 7-bit forces, "
                        "integer mm) and the contact-force CoP of its foot, compared right after the "
                        "board's own 20 ms tick, while the foot is loaded and the board calibrated",
    "wall_s": "wall time of the run (simulation, host and recording)",
    "rtf": "real-time factor: simulated / wall seconds",
    "can_frames": "frames on the CAN wire",
    "serial_frames": "RS-232 requests the Master received",
    "boot_s": "when the boot ended (virtual seconds)",
    "completed": "false when `--duration` cut the motion before its end, else true",
    "tilt_deg": "the platform's tilt asked for (`--tilt`)",
    "control": "the control type(s) the leg boards (SCU 1-2) ran, `+` between them: the scenario's "
               "own (`stand`: `balance`) or `--control`'s",
    "control_law": "the law that ran each of those types on the leg boards, `type=Class` (built-in), "
                   "or `type=module:Class` (a `--law` plug-in, docs/controllers.md)",
    "seed": "the run's seed",
    "mode": "the Master supervisor's mode at the end (`ready`; `safe` or `estop`: exit code 3; "
            "docs/supervisor.md)",
    "faults": "the faults the supervisor latched: name, node, time, detail each",
    "injected": "the `--fault` specs injected that started (docs/supervisor.md)",
    "injected_not_started": "only when some `--fault` starts beyond the run's end: those specs",
    "host_error": "only when a host request failed while the supervisor was stopped or faults were "
                  "injected: that request's error (the run went on)",
    "law_faults": "only when a control law raised or returned a bad value: which law, board, time "
                  "and why (the board fell back to holding; docs/controllers.md)",
    "host_controller_calls": "only with `--host-controller`: how many times its `step` was called",
    "recording": "the `.rrd` written (the CLI)",
    "can_log": "the CAN log written (the CLI)",
    "recording_compacted": "only when the compaction of a long recording failed: `false`, the file "
                           "kept as recorded (docs/recording.md)",
    "recording_note": "only with `recording_compacted`: why the compaction failed",
}


def summary_keys_markdown() -> str:
    """docs/scenarios.md's table of the summary's keys, from :data:`SUMMARY_KEYS`."""
    lines = ["| key | meaning |", "|---|---|"]
    lines += [f"| `{key}` | {meaning} |" for key, meaning in SUMMARY_KEYS.items()]
    return "\n".join(lines) + "\n"


def _leg_control_types(the_plan: Plan) -> list[ControlType]:
    """The control types the leg boards (SCU 1, 2) run over the plan's motions, in type order."""
    types = {int(v) for v in np.asarray(the_plan.k)[[scu - 1 for scu in FOOT_SCUS], :, :, 3].ravel()}
    return [ControlType(t) for t in sorted(types)]


def _control_label(the_plan: Plan) -> str:
    """``control`` of the summary: the leg boards' control types, ``+`` between them (``stand``:
    ``balance``, the scenario's default; ``--control`` replaces them)."""
    return "+".join(t.label for t in _leg_control_types(the_plan))


def _law_label(twin: Twin, the_plan: Plan) -> str:
    """``control_law`` of the summary: which law class ran each of those types on the leg boards
    (``balance=JacobianLaw``; a ``--law`` plug-in by its module and class)."""
    servo = twin.slaves[FOOT_SCUS[0]].servo
    parts = []
    for t in _leg_control_types(the_plan):
        law = servo.law(int(t))
        cls = type(law)
        name = cls.__qualname__
        if cls.__module__ != "humanoid_twin.slave.laws":
            name = f"{cls.__module__}:{name}"
        parts.append(f"{t.label}={name}")
    return " ".join(parts)


def _round(x: float | None) -> float | None:
    return None if x is None else round(x, 3)


# cop_margin_min_mm when no foot pad touched the platform at some sample (airborne or fallen):
# the CoP is then outside any support polygon, by more than any foot length.
NO_SUPPORT_MARGIN_MM = -1000.0


def _finite(x: float) -> float | None:
    if math.isinf(x):
        return None if x > 0 else NO_SUPPORT_MARGIN_MM
    return round(max(x, NO_SUPPORT_MARGIN_MM), 3)


__all__ = ["RunOptions", "outcome", "SLIP_HELD_MM", "SUMMARY_KEYS", "summary_keys_markdown",
           "Monitor", "Plan", "Scenario", "REGISTRY", "scenario", "get_scenario", "boot",
           "hold", "BootError", "ScenarioError", "ScenarioInputError", "SCENARIOS", "CONTROL_CHOICES", "plan",
           "run", "tilt_profile", "expected_run_s"]
