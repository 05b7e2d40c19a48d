"""Scenarios a user runs headless: ``humanoid-twin run stand|flexao|inclinar|levantar_perna``,
or one of the user's own (``run path/to/file.py:NAME``, ``run package.module:NAME``, an entry
point of the group ``humanoid_twin.scenarios``; docs/scenarios.md).

A scenario is host code talking to the in-process twin through its pyserial URL, exactly as the
MATLAB toolbox talked to the robot: :func:`boot` (positions, period, PWM on: the Slaves
calibrate), then the scenario's own program, then the robot settles. A :class:`Scenario` carries
that program as its :meth:`Scenario.drive` hook (in the manner of dm_control's tasks): by default
``exe_traj`` of its :class:`Plan` (the planner's ``pos_apply``, ``k``, ``t`` of seed 000 table 23),
or, for a scenario that does not move (``stand``), :func:`hold` of the plan's gains. A user's
scenario subclasses :class:`Scenario` and overrides ``drive`` (and :meth:`Scenario.motion_s`).

The built-in scenarios are a registry (:data:`REGISTRY`, in the style of dm_control's suite): one
scenario is one small factory below, decorated with :func:`scenario`, that returns its plan from
``T``, ``motion`` and ``perna``. :func:`run` is the whole run: plan -> :class:`~humanoid_twin.rig.Rig`
-> boot -> drive -> settle -> summary (humanoid_twin/summary.py).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from humanoid_twin import plugins
from humanoid_twin.clock import US_PER_S
from humanoid_twin.containment import describe, short_repr, user_fault
from humanoid_twin.controllers import LawError, load_host_controller, run_host_controller
from humanoid_twin.host import drivers
from humanoid_twin.host.motion import exe_traj, send_gains
from humanoid_twin.host.planners import (
    BALANCE_MOTIONS,
    LEG_SCUS,
    control_row,
    empty_plan,
    flexao,
    inclinar,
    leg_pose,
    levantar_perna,
)
from humanoid_twin.limits import MAX_RUN_S
from humanoid_twin.monitor import Monitor
from humanoid_twin.plan import STAND_CONTROL, STAND_GAINS, Plan
from humanoid_twin.plant.plant import quiet_instability_warnings
from humanoid_twin.plugins import is_reference, split_reference
from humanoid_twin.protocol.wire import ControlType
from humanoid_twin.rig import (
    BOOT_TIMEOUT_S,
    TILT_RATE_DEG_S,
    BootError,
    Rig,
    RigOptions,
    ScenarioError,
    boot,
    tilt_profile,
)
from humanoid_twin.signals import check as check_signal
from humanoid_twin.summary import (
    NO_SUPPORT_MARGIN_MM,
    SLIP_HELD_MM,
    SUMMARY_KEYS,
    build_summary,
    note_recording,
    outcome,
    summary_keys_markdown,
)

if TYPE_CHECKING:
    from types import FrameType

    from humanoid_twin.interfaces import HostPort
    from humanoid_twin.outputs import Outputs
    from humanoid_twin.twin import Twin

CONTROL_CHOICES: dict[str, int] = {t.label: t for t in ControlType}   # run --control
# the boot cannot end sooner: the Slaves' calibration waits 100 PWM periods, then averages 25
# (seed 000 SERVO ``calibration``); a --duration below it is refused before the run starts
BOOT_MIN_S = (100 + 25) * 0.020
SETTLE_S = 2.0
ENTRY_POINT_GROUP = plugins.SCENARIO_GROUP     # a package's scenarios, by name


class ScenarioInputError(ScenarioError):
    """The options ask for something the run cannot do (a ``--duration`` shorter than the boot)."""


class ScenarioLoadError(ScenarioInputError):
    """A scenario reference that names no scenario (cannot be imported, or is not a
    :class:`Scenario`): one line naming it."""


class _DurationReachedError(BaseException):
    """Raised by the clock at the run's end (``--duration``, or the default one) when that instant
    falls inside the boot or the scenario's program: the run is cut there and its summary says
    ``completed: false``. A ``BaseException``: a host controller's (or a user scenario's)
    ``except Exception`` does not swallow it; one that swallows it gets it again every 20 ms."""


class _HostBoundReachedError(BaseException):
    """Raised by the clock at the run's end while a host controller runs: whatever the
    controller does (sleeps, loops), the run ends at its duration (issue 24)."""


class _DivergedError(BaseException):
    """Raised by the clock once the ground-truth monitor found the simulation diverged (MuJoCo's
    instability warning, a non-finite state): the run ends there, ``outcome: diverged``."""


class WallTimeoutExpired(BaseException):
    """SIGALRM at ``wall_timeout`` wall seconds (``run --wall-timeout``, a sweep's ``--timeout``),
    raised wherever the process is: :func:`arm_wall_timeout`. :func:`run` turns it into a
    :class:`ScenarioError`; raised before :func:`run` starts (importing, planning, sizing a
    scenario), the caller says so."""


# one simulated day (humanoid_twin/limits.py): a run's --duration, or a scenario's motion_s,
# beyond it is refused
MAX_DURATION_S = MAX_RUN_S
# a run's end (or a divergence) is raised again at the same instant, by the next step of the clock,
# while user code swallows it: simulated time does not go past it (a loop that swallows it spins in
# wall time until --wall-timeout)
BOUND_REPEAT_US = 0


def hold(H: HostPort, plan: Plan, scus: tuple[int, ...] = LEG_SCUS) -> None:
    """A scenario without motions: send the gains and control types of the plan's first motion
    to the boards ``scus`` (``applycontrol``) and let the firmware hold the posture."""
    for scu in scus:
        send_gains(H, scu, plan.k[scu - 1, :, 0, :])


@dataclass
class RunOptions(RigOptions):
    """The ``humanoid-twin run`` options (docs/scenarios.md); the rig's own (seed, faults, laws,
    outputs ...) are :class:`~humanoid_twin.rig.RigOptions`'s, given by keyword."""

    # a registered name, a reference (``file.py:NAME``, ``module:NAME``, an entry point's name)
    # or a Scenario object
    scenario: str | Scenario = "stand"
    duration: float | None = None
    T: float | None = None
    motion: float | None = None
    perna: int = 1
    control: str | None = None
    progress: bool = True
    # a PC-side step(ctx) called every host_period_ms once the scenario's own program is done
    # (humanoid_twin/controllers.py, docs/controllers.md)
    host_controller: Callable[..., Any] | str | None = None
    host_period_ms: float = 20.0
    # wall seconds the run may take (None: unbounded); beyond it the run ends with ScenarioError,
    # its files closed (``run --wall-timeout``, sweep's ``--timeout``)
    wall_timeout: float | None = None
    # a user scenario's own dataclass fields, name -> value (``--set scenario.FIELD=VALUE``,
    # sweep's ``--param scenario.FIELD=...``): :func:`with_fields`
    scenario_fields: dict[str, Any] = field(default_factory=dict)


Factory = Callable[[float | None, float | None, int], Plan]


@dataclass(frozen=True)
class Scenario:
    """One scenario: its name, its factory ``(T, motion, perna) -> Plan`` (``None`` = the
    scenario's default), whether it moves (its default :meth:`drive` runs the plan's motions with
    ``exe_traj``) or holds the boot posture with the plan's gains (:func:`hold`), and
    ``double_support``: both feet stay down all along (``--control reaction|balance`` keeps the
    leader/follower split).

    A user's scenario subclasses it and overrides :meth:`drive` (the program the host runs once
    the twin has booted) and, when that program takes a time of its own, :meth:`motion_s`
    (docs/scenarios.md)."""

    name: str
    factory: Factory
    moves: bool = True
    double_support: bool = False
    doc: str = field(default="", compare=False)

    def plan(self, T: float | None = None, motion: float | None = None, perna: int = 1) -> Plan:
        """The scenario's plan with its defaults for the arguments left ``None``."""
        return self.factory(T, motion, perna)

    def motion_s(self, plan: Plan) -> float:
        """How long :meth:`drive` runs (simulated s): the plan's motions, 0 for a scenario that
        holds. The run lasts the boot, this (or the platform's tilt, if longer), then 2 s of
        settling; a ``--duration`` that ends sooner cuts the program there."""
        return float(np.sum(plan.t)) if self.moves else 0.0

    def drive(self, rig: Rig, plan: Plan) -> None:
        """The scenario's program, called once the twin has booted: ``rig.H`` is the host's
        port, ``rig.twin`` the twin, ``rig.monitor`` the ground truth; time advances as the
        program talks to the twin (each request, :meth:`~humanoid_twin.rig.Rig.sleep`). Default:
        ``exe_traj`` of the plan's motions, or :func:`hold` for a scenario that does not move."""
        if self.moves:
            exe_traj(rig.H, plan.t, plan.pos_apply, 0.0, k=plan.k)
        else:
            hold(rig.H, plan)


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


DEFAULT_T_S = 1.0           # the planners' default motion period (``--T``)
# the planners' default angle (``--motion``, degrees) per scenario; ``--help`` shows them
DEFAULT_MOTION_DEG = {"flexao": 20.0, "inclinar": 10.0, "levantar_perna": 40.0, "excite": 6.0}
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


# ``excite`` (beyond the seeds, docs/calibration.md): the motion whose CAN log determines the
# servo and sensor parameters (``humanoid-twin calibrate``). Both feet stay down all along.
EXCITE_SHIFT_T = 0.75                   # each weight shift's period, times T (``--T``, default 1 s)
EXCITE_CHIRP = (0.75, 0.45, 0.3, 0.2)   # the squat chirp's half periods, times T
EXCITE_SHIFT = 1.5                    # the weight shift's lean, times the amplitude
EXCITE_STEP_S = 0.1                   # a joint's step: 5 PWM periods up, 5 back ...
EXCITE_HOLD_S = 0.2                   # ... then held (the step response settles)
EXCITE_JOINTS = ("ankle_roll", "ankle_pitch", "knee", "hip_roll", "hip_pitch")


def excite_plan(T: float, amplitude: float) -> Plan:
    """The excitation motion: (1) the weight shifted from foot to foot (the ``inclinar`` pose,
    ``EXCITE_SHIFT`` x ``amplitude``, each way and back, ``EXCITE_SHIFT_T`` x ``T`` each);
    (2) a squat chirp (the ``flexao`` pose of ``amplitude``, down and up with half periods
    ``EXCITE_CHIRP`` x ``T``); (3) a step of ``amplitude / 2`` on each leg joint of each leg in
    turn (up and back in ``EXCITE_STEP_S``, held ``EXCITE_HOLD_S``). LOCOMOTION_CONTROL on the
    legs and hips; every angle within the planners' limits (``amplitude`` 1..10 deg)."""
    a = float(amplitude)
    if not 1.0 <= a <= 10.0:
        raise ValueError(f"excite: --motion (the amplitude) must be 1..10 degrees, got {amplitude!r}")
    poses: list[tuple[dict[int, dict[str, float]], float]] = []
    shift = EXCITE_SHIFT * a
    for lean in (shift, 0.0, -shift, 0.0):
        poses.append(({side: {"hip_roll": -lean, "ankle_roll": lean} for side in (0, 1)}, EXCITE_SHIFT_T * T))
    for half in EXCITE_CHIRP:
        squat = {"hip_pitch": -a, "knee": 2 * a, "ankle_pitch": -a}
        poses.append(({0: squat, 1: squat}, half * T))
        poses.append(({0: {}, 1: {}}, half * T))
    for side in (0, 1):
        for joint in EXCITE_JOINTS:
            poses.append(({side: {joint: a / 2}}, EXCITE_STEP_S))
            poses.append(({}, EXCITE_STEP_S))
            poses.append(({}, EXCITE_HOLD_S))
    pos, k, t = empty_plan(len(poses))
    for m, (legs, period) in enumerate(poses):
        for side in (0, 1):
            leg_pose(pos, m, side, **legs.get(side, {}))
        for scu in LEG_SCUS:
            k[scu - 1, :, m] = control_row(ControlType.LOCOMOTION_CONTROL)
        t[m] = period
    return Plan(pos, k, t)


@scenario("excite", double_support=True)
def _excite(T: float | None, motion: float | None, perna: int) -> Plan:
    """excitation for calibrate: weight shift foot to foot, a squat chirp, a step on each leg joint;
    --motion = amplitude (deg), --T = time scale"""
    amplitude = DEFAULT_MOTION_DEG["excite"] if motion is None else motion
    return excite_plan(DEFAULT_T_S if T is None else T, amplitude)


SCENARIOS: tuple[str, ...] = tuple(REGISTRY)   # the built-in scenarios, in registration order


# -- user scenarios (the references' rules: humanoid_twin/plugins.py) ---------------------------
_loaded: dict[str, Scenario] = {}


def recording_name(ref: str | Scenario, label: str = "") -> str:
    """The default file name of a run's recording: the scenario's ``name`` (a user's object's
    own, whatever the reference calls it), then ``_LABEL`` (a sweep's grid point), ``.rrd``."""
    name = load_scenario(ref).name
    return f"{name}_{label}.rrd" if label else f"{name}.rrd"


def entry_point_names() -> list[str]:
    """The scenarios installed packages declare in the group :data:`ENTRY_POINT_GROUP`."""
    return plugins.entry_point_names(ENTRY_POINT_GROUP)


def did_you_mean(name: str) -> str:
    """``"; did you mean stand?"`` for a misspelt scenario name (the built-in ones and the entry
    points), or nothing."""
    return plugins.did_you_mean(name, [*REGISTRY, *entry_point_names()])


def load_scenario(ref: str | Scenario) -> Scenario:
    """The scenario ``ref`` names: a registered name, ``path/to/file.py:NAME``,
    ``package.module:NAME``, or the name of an entry point of the group :data:`ENTRY_POINT_GROUP`
    (a :class:`Scenario` is returned as it is). NAME may be dotted (``module:Class.attr``) and
    must be a :class:`Scenario` object. :class:`ScenarioLoadError` (one line naming ``ref``)
    otherwise; each reference is imported once per process."""
    if isinstance(ref, Scenario):
        return ref
    ref = str(ref).strip()
    if ref in REGISTRY:
        return REGISTRY[ref]
    if ref in _loaded:
        return _loaded[ref]
    obj = plugins.load_reference(ref, _KIND)
    if not isinstance(obj, Scenario):
        raise ScenarioLoadError(f"scenario {ref!r} is not a Scenario (got {type(obj).__name__}; "
                                "docs/scenarios.md, \"Your own scenario\")")
    if not isinstance(obj.name, str) or not obj.name.strip() or "/" in obj.name or "\0" in obj.name:
        raise ScenarioLoadError(f"scenario {ref!r}: its name {obj.name!r} cannot name a file "
                                "(the default recording is NAME.rrd): give it a name without '/'")
    _loaded[ref] = obj
    return obj


def _hint(module: Any, where: str, attr: str) -> str:
    """What a module that lacks ``attr`` holds instead: its :class:`Scenario` objects, by the names
    a reference takes (the variables), and the one whose ``name`` is ``attr`` when there is one
    (a scenario is named by its variable, not by its ``name`` field)."""
    found = {var: obj for var, obj in vars(module).items()
             if isinstance(obj, Scenario) and not var.startswith("_")}
    if not found:
        return " (it holds no Scenario object)"
    by_name = [var for var, obj in found.items() if obj.name == attr]
    if by_name:
        return (f": {attr!r} is the name of its Scenario object {by_name[0]!r}; a reference names the "
                f"variable: {where}:{by_name[0]}")
    return f" (its Scenario objects: {', '.join(found)}){plugins.did_you_mean(attr, found)}"


_KIND = plugins.Kind("scenario", ENTRY_POINT_GROUP, ScenarioLoadError, builtins=lambda: REGISTRY, hint=_hint)


SCENARIO_FIELD_PREFIX = "scenario."     # --set scenario.FIELD=VALUE: a user scenario's own field
_FIELD_TYPES = (bool, int, float, str)


def own_fields(spec: Scenario) -> dict[str, Any]:
    """A user scenario's own dataclass fields (those its class adds to :class:`Scenario`) and
    their values; a built-in scenario has none."""
    import dataclasses

    base = {f.name for f in dataclasses.fields(Scenario)}
    return {f.name: getattr(spec, f.name) for f in dataclasses.fields(spec) if f.name not in base}


def with_fields(spec: Scenario, values: dict[str, Any]) -> Scenario:
    """``spec`` with some of its own fields (:func:`own_fields`) replaced; a text value is read as
    the field's current type (int, float, bool, str). :class:`ScenarioInputError` (one line) for a
    field it does not have or a value of the wrong kind."""
    import dataclasses

    if not values:
        return spec
    mine = own_fields(spec)
    changes: dict[str, Any] = {}
    for name, value in values.items():
        if name not in mine:
            have = f"its fields: {', '.join(sorted(mine))}" if mine else "it has no field of its own"
            raise ScenarioInputError(f"scenario {spec.name} has no field {name!r} of its own ({have})")
        current = mine[name]
        kind = type(current)
        if not isinstance(current, _FIELD_TYPES):
            raise ScenarioInputError(f"scenario.{name}: a {kind.__name__} field cannot be set from the "
                                     "command line (int, float, bool, str fields can)")
        changes[name] = _field_value(name, kind, value)
    return dataclasses.replace(spec, **changes)


def _field_value(name: str, kind: type, value: Any) -> Any:
    if not isinstance(value, str):
        return value
    text = value.strip()
    try:
        if kind is bool:
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.lower() in ("true", "1")
        v = kind(text)
        if kind is float and not math.isfinite(v):
            raise ValueError(text)
        return v
    except ValueError:
        raise ScenarioInputError(f"scenario.{name}={value!r}: not a {kind.__name__}") from None


def scenario_name(ref: str | Scenario) -> str:
    """How a run names its scenario (the summary's ``scenario``): the name or reference as given,
    or a Scenario object's ``name``."""
    return ref.name if isinstance(ref, Scenario) else str(ref)


def is_builtin(spec: Scenario) -> bool:
    """``spec`` is one of the registered scenarios (not a user's)."""
    return REGISTRY.get(spec.name) is spec


def plan(scenario: str | Scenario, T: float | None = None, motion: float | None = None,
         perna: int = 1) -> Plan:
    """The plan of the scenario ``scenario`` (:func:`load_scenario`) with its defaults."""
    return load_scenario(scenario).plan(T, motion, perna)


def _with_control(spec: Scenario, the_plan: Plan, control: str | None) -> Plan:
    if control is None:
        return the_plan
    split = spec.double_support or the_plan.lead is not None
    return the_plan.with_control(CONTROL_CHOICES[control], split=split)


_wall: dict[str, Any] = {"armed": False, "previous": None}


def wall_timeout_armed() -> bool:
    """A wall-clock limit is armed in this process (:func:`arm_wall_timeout`)."""
    return bool(_wall["armed"])


def arm_wall_timeout(seconds: float | None) -> None:
    """From now on, SIGALRM after ``seconds`` of wall time raises :class:`WallTimeoutExpired` where
    the process is (also in a host controller's ``time.sleep``, a scenario's import or its
    planning); the caller disarms it (:func:`disarm_wall_timeout`, in a ``finally``: the alarm
    may already have fired inside this call). Nothing when ``seconds`` is None, off the main
    thread, or when a limit is armed already (the CLI arms ``--wall-timeout`` at its first line,
    :func:`run` keeps it). While the outputs are closed or renamed (``signals.deferred``) the
    alarm waits for the next 0.5 s."""
    import signal
    import threading

    if seconds is None or _wall["armed"] or threading.current_thread() is not threading.main_thread():
        return
    from humanoid_twin import signals

    fired = [0]

    def on_alarm(signum: int, frame: FrameType | None) -> None:
        if signals.deferring():          # a file's last write and rename: not cut in the middle
            return
        # raised again every 0.5 s while user code swallows it; after 5 s of that, the process
        # ends (one line, temporary files removed, exit 1): humanoid_twin/signals.hard_exit
        fired[0] += 1
        if fired[0] > 10:
            signals.hard_exit(1, f"humanoid-twin: the run took more than {seconds:g} wall seconds "
                              "(--wall-timeout) and user code swallowed the stop: ended at once")
        raise WallTimeoutExpired

    _wall["previous"] = signal.signal(signal.SIGALRM, on_alarm)
    _wall["armed"] = True
    # at least 1 us: a smaller value would be rounded to 0, which disarms the interval timer
    signal.setitimer(signal.ITIMER_REAL, max(float(seconds), 1e-6), 0.5)


def disarm_wall_timeout() -> None:
    """Disarm :func:`arm_wall_timeout`'s limit (nothing when none is armed)."""
    import signal

    if not _wall["armed"]:
        return
    signal.setitimer(signal.ITIMER_REAL, 0)
    previous = _wall["previous"]
    signal.signal(signal.SIGALRM, previous if previous is not None else signal.SIG_DFL)
    _wall["armed"] = False


class _Bound:
    """A run's end (or its divergence) on the twin's clock: from :meth:`arm`'s instant on, the clock
    raises ``error`` while armed, again at each step user code asks of it after swallowing it
    (``except BaseException``: :data:`BOUND_REPEAT_US`); ``fired``: it was raised at least once."""

    def __init__(self, twin: Twin, error: type[BaseException]) -> None:
        self.twin, self.error = twin, error
        self.armed = self.fired = False
        self.at_us: int | None = None

    def arm(self, t_s: float) -> None:
        at = max(round(t_s * US_PER_S), self.twin.clock.now_us)
        if self.armed and self.at_us == at:
            return
        self.armed, self.at_us = True, at
        self.twin.clock.schedule(at, self._fire)

    def disarm(self) -> None:
        self.armed = False

    def _fire(self) -> None:
        if self.armed and self.twin.clock.now_us >= (self.at_us or 0):
            self.fired = True
            self.twin.clock.schedule(self.twin.clock.now_us + BOUND_REPEAT_US, self._fire)
            raise self.error


def _arm_host_bound(twin: Twin, duration: float) -> _Bound:
    """From ``duration`` on, the clock raises :class:`_HostBoundReachedError` while the returned
    bound is armed: a host controller cannot run the twin past the run's end, even one that
    swallows it (``except BaseException``)."""
    bound = _Bound(twin, _HostBoundReachedError)
    bound.arm(duration)
    return bound


def check_motion_s(value: Any, label: str) -> float:
    """A scenario's ``motion_s`` checked like ``--duration``: a number of simulated seconds, finite,
    0..:data:`MAX_DURATION_S`; :class:`ScenarioInputError` (one line naming the scenario)
    otherwise. Its ``float`` is judged as user code (it may raise)."""
    import numbers

    why = None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        why = f"returned {short_repr(value, 60)} ({type(value).__name__}): not a number of seconds"
    else:
        try:
            seconds = float(value)
        except BaseException as exc:       # noqa: BLE001 - a user's number: judged, not trusted
            if not user_fault(exc):
                raise
            seconds, why = math.nan, f"returned a number whose float() raised {describe(exc)}"
        if why is None and not (math.isfinite(seconds) and 0 <= seconds <= MAX_DURATION_S):
            why = (f"returned {short_repr(value, 60)}: must be a finite number of simulated seconds, "
                   f"0..{MAX_DURATION_S:g} (as --duration)")
    if why is not None:
        raise ScenarioInputError(f"scenario {label}: its motion_s {why}")
    return seconds


def scenario_motion_s(spec: Scenario, plan: Plan, label: str) -> float:
    """``spec.motion_s(plan)``, checked (:func:`check_motion_s`): a user's scenario that raises
    there is a :class:`ScenarioError` naming it (one line), never a traceback."""
    try:
        value = spec.motion_s(plan)
    except BaseException as exc:
        if is_builtin(spec) or not user_fault(exc):
            raise
        raise ScenarioError(f"scenario {label} raised {describe(exc)} in its motion_s") from None
    return check_motion_s(value, label)


def _after_boot_s(motion_s: float, tilt: float) -> float:
    """The run after the boot: the motion or the platform's tilt, whichever is longer, then settle."""
    return max(motion_s, abs(tilt) / TILT_RATE_DEG_S) + SETTLE_S


def expected_run_s(scenario: str | Scenario, duration: float | None = None, T: float | None = None,
                   motion: float | None = None, perna: int = 1, tilt: float = 0.0) -> float:
    """How long a run lasts at most, in simulated seconds, known before it starts: ``duration``
    when given, else the boot's bound (:data:`BOOT_TIMEOUT_S`) + the motion or the tilt + the
    settling (what the CLI sizes the outputs' disk space by). The run is cut there whatever its
    program does. A scenario's ``motion_s`` is checked (:func:`check_motion_s`)."""
    if duration is not None:
        return duration
    spec = load_scenario(scenario)
    label = scenario_name(scenario)
    the_plan = scenario_plan(spec, label, T, motion, perna)
    return BOOT_TIMEOUT_S + _after_boot_s(scenario_motion_s(spec, the_plan, label), tilt)


def scenario_plan(spec: Scenario, label: str, T: float | None, motion: float | None, perna: int,
                   control: str | None = None) -> Plan:
    """The plan a run of ``spec`` executes (its name as given: ``label``): the scenario's, with
    ``--control``'s type ``control`` if given. A ``ValueError`` (the planners' own limits: ``--T``
    fits one byte of 20 ms ticks, each joint's range ...) is a :class:`ScenarioInputError`;
    anything else a user's factory raises, a :class:`ScenarioError` naming it (one line)."""
    try:
        the_plan = spec.plan(T, motion, perna)
    except ValueError as exc:
        raise ScenarioInputError(f"{label}: {describe(exc) if not is_builtin(spec) else exc}") from None
    except BaseException as exc:
        if is_builtin(spec) or not user_fault(exc):
            raise
        raise ScenarioError(f"scenario {label} raised {describe(exc)} in its plan") from None
    return _with_control(spec, the_plan, control)


class Session:
    """One run of a scenario, open in Python: built and booted, then driven step by step or to its
    end (:func:`open_run`, ``humanoid_twin.open``; ``humanoid-twin run`` is :meth:`finish` at once).

    ``Session(opts)`` loads and plans the scenario as ``run`` does (``scenario_fields``, checked
    ``motion_s``), builds the :class:`~humanoid_twin.rig.Rig` of ``opts`` (the twin, its laws,
    its outputs, monitor and faults) and boots it: the host's port ``H`` is open and every Slave
    calibrated (time advances here, ~2.65 simulated s; a ``duration`` that ends inside the boot
    cuts it there). From there, in any order: :meth:`step` (time passes, the firmware holds the
    posture or follows what the host sent), :meth:`read` (the robot now), :meth:`drive` (the
    scenario's own program, e.g. the squat, cut at :attr:`end_s`), ``H`` (the host toolbox on the
    robot's serial port: ``readjoint(session.H, 1)``, ``applyjoint`` ... docs/host.md);
    :meth:`finish` runs the rest as ``humanoid-twin run`` would (the program if not driven yet,
    ``host_controller``, settling until the run's end) and returns the summary; :meth:`close` (or
    leaving the ``with`` block) closes the outputs and the twin. A simulation that diverges ends
    the run (``outcome: diverged``; :meth:`step` raises :class:`ScenarioError`).

    Attributes: ``opts``, ``spec`` (the :class:`Scenario`), ``plan`` (its :class:`Plan`, with
    ``control``'s type), ``rig``, ``boot_s`` (None: the boot was cut), ``end_s`` (when
    :meth:`finish` ends the run: ``duration``, or the boot + the program or the tilt + settling)."""

    def __init__(self, opts: RunOptions, on_progress: Callable[[float, float | None], None] | None = None,
                 on_twin: Callable[[Any], None] | None = None,
                 on_boot: Callable[[float, str | None], None] | None = None) -> None:
        self.opts = opts
        self.rig: Rig | None = None   # set below; a --wall-timeout may land first
        self.spec = with_fields(load_scenario(opts.scenario), opts.scenario_fields)   # --set scenario.FIELD=V
        self.label = scenario_name(opts.scenario)
        self.plan = scenario_plan(self.spec, self.label, opts.T, opts.motion, opts.perna, opts.control)
        self.motion_s = scenario_motion_s(self.spec, self.plan, self.label)
        self._host_step = (load_host_controller(opts.host_controller)
                           if opts.host_controller is not None else None)
        self.expected_s = (opts.duration if opts.duration is not None
                           else BOOT_TIMEOUT_S + _after_boot_s(self.motion_s, opts.tilt))
        self.summary: dict[str, Any] | None = None
        self.outputs: Outputs | None = None            # the files' temporary names (open_run), else None
        self._driven = False
        self._completed = True              # false once the run's end cut the boot or the program
        self._stopped = False               # the run's end or a divergence ended it: nothing more runs
        self._wall0 = time.perf_counter()
        self.rig = rig = _open_rig(opts, self.expected_s, on_twin, on_progress)
        try:
            self._end = _Bound(rig.twin, _DurationReachedError)
            self._diverged = _Bound(rig.twin, _DivergedError)
            rig.monitor.on_diverged = lambda: self._diverged.arm(rig.now_s)
            if opts.duration is not None:
                self._end.arm(opts.duration)     # faults that stretch the boot past it cut the boot
            try:
                rig.boot()                       # time advances here: the boot
            except (_DurationReachedError, _DivergedError):
                self._completed, self._stopped = False, True
            self._end.disarm()
            self.boot_s: float | None = None if self._stopped else rig.now_s
            if self.boot_s is not None and on_boot is not None:
                on_boot(self.boot_s, rig.boot_error)
            self.end_s: float = (rig.now_s if self.boot_s is None
                                 else _duration(opts, self.boot_s, self.motion_s))
            rig.end_s = self.end_s
        except BaseException:
            rig.close()
            raise

    @property
    def H(self) -> Any:  # noqa: N802 - the toolbox's name for the host's port (seed 000 table 20)
        """The host's end of the robot's RS-232 link (the toolbox's ``H``: docs/host.md)."""
        return self._rig.H

    @property
    def twin(self) -> Twin:
        """The twin (boards, buses, plant)."""
        return self._rig.twin

    @property
    def _rig(self) -> Rig:
        assert self.rig is not None
        return self.rig

    @property
    def now_s(self) -> float:
        """The virtual time (simulated s)."""
        return self._rig.now_s

    def step(self, seconds: float = 0.02) -> dict[str, Any]:
        """Let ``seconds`` of virtual time pass (the host waits on the twin's clock; the boards
        run); returns :meth:`read`. :class:`ScenarioError` when the simulation diverged."""
        if not seconds > 0:
            raise ValueError(f"step({seconds!r}): give a positive number of simulated seconds")
        try:
            self._rig.sleep(seconds)
        except _DivergedError:
            self._stopped_by_divergence()
            raise ScenarioError(f"{self.label}: the simulation diverged ({self._rig.monitor.diverged}): "
                                f"the run ended at t={self.now_s:.3f} s") from None
        return self.read()

    def read(self) -> dict[str, Any]:
        """The robot now, from the plant's ground truth and the Master's supervisor (reading takes
        no time): ``t_s``, ``mode`` (the supervisor's), ``fell`` (at any sample so far),
        ``fell_at_s``, ``trunk_tilt_deg``, ``cop_margin_mm`` (the CoP's distance inside the
        support polygon), ``platform_tilt_deg``, ``joints_deg`` (every joint's true angle,
        by MuJoCo joint name)."""
        twin, mon = self._rig.twin, self._rig.monitor
        truth = twin.plant.truth()
        return {
            "t_s": twin.now_s,
            "mode": twin.the_master().supervisor.mode_name,
            "fell": mon.fell or truth.fell,
            "fell_at_s": mon.fell_at_s,
            "trunk_tilt_deg": truth.trunk_tilt_deg,
            "cop_margin_mm": truth.cop_margin_mm,
            "platform_tilt_deg": twin.plant.tilt_deg,
            "joints_deg": dict(truth.joint_angles_deg),
        }

    def drive(self) -> None:
        """The scenario's own program (:meth:`Scenario.drive`: the planner's motions, or the
        hold of its gains), once, ended at :attr:`end_s` whatever it does (``completed`` false);
        time advances by its length. A failed request is the run's ``host_error`` where the run
        tolerates it (faults, a stopped supervisor), as in ``run``."""
        if self._driven:
            raise ScenarioError(f"{self.label}: its program was driven already")
        self._driven = True
        rig = self._rig
        if self._stopped or rig.host_error is not None:
            return
        self._end.arm(self.end_s)
        try:
            _drive(self.spec, rig, self.plan, self.label)    # time advances here: the scenario's program
        except _DurationReachedError:
            self._stopped = True                 # the run's end fell inside the program: cut there
        except _DivergedError:
            self._stopped_by_divergence()
        finally:
            self._end.disarm()
        if self._end.fired:                      # also a program that swallowed its cut
            self._completed = False

    def finish(self) -> dict[str, Any]:
        """The rest of the run as ``humanoid-twin run`` has it: the scenario's program (unless
        :meth:`drive` ran it), the ``host_controller``, the robot settling until :attr:`end_s`.
        Returns the summary (docs/scenarios.md), also kept in :attr:`summary`."""
        rig, duration = self._rig, self.end_s
        host_calls = None
        try:
            if not self._driven and not self._stopped and (not self.spec.moves or duration > rig.now_s):
                self.drive()
            self._driven = True
            if not self._stopped:
                if self._host_step is not None and rig.host_error is None:
                    host_calls = _host_controller(rig, self._host_step, duration, self.opts.host_period_ms)
                rig.sleep_until(duration)        # time advances here: the robot settles
        except _DurationReachedError:
            self._completed = False
        except _DivergedError:
            self._stopped_by_divergence()
        finally:
            self._end.disarm()
            self._diverged.disarm()
        check_signal()          # a signal that user code swallowed (and returned): not a finished run
        completed = self._completed and rig.boot_error is None    # a failed boot: no program ran
        self.summary = build_summary(rig, self.label, self.plan, completed=completed,
                                     wall_s=time.perf_counter() - self._wall0, host_calls=host_calls)
        return self.summary

    def _stopped_by_divergence(self) -> None:
        self._completed, self._stopped = False, True
        self._diverged.disarm()

    def close(self, failed: bool = False) -> None:
        """Close the outputs and the twin (:meth:`Rig.close`); a recording's summary notes are
        added to :attr:`summary` then (its compaction happens at the close). Files written under
        temporary names (:func:`open_run`) take their final names now, or are removed when
        ``failed`` (an exception left the ``with`` block) or the close itself failed: an
        existing file is never replaced by a failed run. Closing twice does nothing."""
        if getattr(self, "_closed", False) or self.rig is None:
            return
        self._closed = True
        outputs = self.outputs
        try:
            self.rig.close()
        except BaseException:
            if outputs is not None:
                outputs.discard()
            raise
        if outputs is not None and failed:
            outputs.discard()
        elif outputs is not None:
            finals = dict(outputs.final)
            outputs.commit()
            if self.summary is not None:       # where the files are, as ``run`` reports them
                self.summary.update({"recording" if k == "out" else k: str(p) for k, p in finals.items()})
        if self.summary is not None:
            note_recording(self.summary, self.rig)

    def __enter__(self) -> Session:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *exc: object) -> None:
        # Ctrl-C keeps what was recorded, closed and readable (as the CLI does)
        self.close(failed=exc_type is not None and not issubclass(exc_type, KeyboardInterrupt))


_OUTPUT_FIELDS = ("out", "can_log", "serial_log")


def open_run(opts: RunOptions | str | Scenario = "stand", /, **fields: Any) -> Session:
    """``humanoid_twin.open``: a run of a scenario, built and booted, to drive from Python or a
    notebook (:class:`Session`: ``step``, ``read``, ``drive``, ``finish``, ``close``).

    ``opts``: :class:`RunOptions` (the options of ``humanoid-twin run``, by the same names), or a
    scenario (a name, ``FILE.py:NAME``, a :class:`Scenario`) with the options as keywords:
    ``open_run("flexao", motion=30, out="flexao.rrd")``. As ``run --out`` does, the recording
    (``out``, a ``.rrd``), the CAN log (``can_log``) and the serial log (``serial_log``) are
    written under temporary names beside their own and renamed when the session closes; a session
    that ended with an error leaves no file and replaces none. Nothing is recorded unless asked
    (``humanoid-twin run`` records ``SCENARIO.rrd`` by default; from Python, name the file).

    :class:`ScenarioInputError` (before anything is written) for a recording not named ``.rrd``,
    a CAN log format python-can cannot write, or a place that cannot be written."""
    import dataclasses

    from humanoid_twin.outputs import Outputs

    if not isinstance(opts, RunOptions):
        opts = RunOptions(scenario=opts, **fields)
    elif fields:
        opts = dataclasses.replace(opts, **fields)
    finals = {k: Path(getattr(opts, k)) for k in _OUTPUT_FIELDS if getattr(opts, k) is not None}
    if "out" in finals and finals["out"].suffix != ".rrd":
        raise ScenarioInputError(f"out={str(finals['out'])!r}: a rerun recording must end in .rrd")
    if "can_log" in finals:
        from humanoid_twin.recording.can_log import CanLogError, check_log_path

        try:
            check_log_path(finals["can_log"])
        except CanLogError as exc:
            raise ScenarioInputError(f"can_log: {exc}") from None
    load_scenario(opts.scenario)            # a reference that names nothing: before any file
    outputs = Outputs()
    try:
        temp = {k: outputs.add(k, path) for k, path in finals.items()}
    except (OSError, ValueError) as exc:     # ValueError: a FIFO, a device (containment.output_target)
        outputs.discard()
        raise ScenarioInputError(f"cannot write there: {exc}") from None
    if temp:
        opts = dataclasses.replace(opts, **temp, can_log_name=finals["can_log"].name if "can_log" in finals  # type: ignore[arg-type]  # the outputs' paths
                                   else opts.can_log_name)
    try:
        session = Session(opts)
    except BaseException:
        outputs.discard()
        raise
    session.outputs = outputs
    return session


def run(opts: RunOptions, on_progress: Callable[[float, float | None], None] | None = None,
        on_twin: Callable[[Any], None] | None = None,
        on_boot: Callable[[float, str | None], None] | None = None) -> dict[str, Any]:
    """Run one scenario headless and return its summary (docs/scenarios.md): a :class:`Session`
    opened and finished at once. The outputs are written to the names in ``opts`` as they go
    (the CLI gives temporary names; :func:`open_run` does the same from Python).

    ``on_progress(t_s, end_s)`` is called every 0.1 s of virtual time: ``end_s`` is None during
    the boot (its length is not known in advance), then the run's end time. ``on_twin(twin)`` is
    called once the twin is built, before anything is written (``run --viewer`` attaches there).
    ``on_boot(t_s, error)`` is called once the boot is over, before ``on_progress`` hears of the
    run's end: ``error`` None when it worked, else why it failed (a run that tolerates it goes
    on without the scenario's program: the summary's ``booted`` false).

    The run ends at its duration (``opts.duration``, or boot + ``motion_s`` or the tilt + 2 s)
    whatever the scenario's program does (``completed: false`` when it was cut, in the boot
    too); ``opts.wall_timeout`` is armed from this function's first line; a simulation that
    diverges ends the run there (``outcome: diverged``)."""
    outer = wall_timeout_armed()
    session: Session | None = None
    try:
        arm_wall_timeout(opts.wall_timeout)      # from the first line: loading, planning, sizing
        # MuJoCo's instability warning is the run's divergence, reported once (the summary's
        # ``diverged``) rather than as a warning line of its own
        with quiet_instability_warnings():
            # made first, then built: a --wall-timeout during the boot still finds the rig's time
            session = Session.__new__(Session)
            session.rig = None
            session.__init__(opts, on_progress, on_twin, on_boot)   # type: ignore[misc]  # made by __new__ above
            with session:
                summary = session.finish()
        return summary
    except WallTimeoutExpired:
        rig = session.rig if session is not None else None
        where = f"at t={rig.now_s:.3f} s simulated" if rig is not None else "before the twin started"
        raise ScenarioError(f"the run took more than {opts.wall_timeout:g} wall seconds (--wall-timeout): "
                            f"stopped {where}") from None
    finally:
        if not outer:
            disarm_wall_timeout()


def _open_rig(opts: RunOptions, expected_s: float, on_twin: Callable[[Any], None] | None,
              on_progress: Callable[[float, float | None], None] | None) -> Rig:
    try:
        return Rig(opts, expected_s=expected_s, on_twin=on_twin, on_progress=on_progress)
    except LawError as exc:           # a law that cannot be made for every board: a bad --law
        raise ScenarioInputError(str(exc)) from None


def _duration(opts: RunOptions, boot_s: float, motion_s: float) -> float:
    """The run's end (virtual s): ``--duration``, or the boot + the program or the tilt + settling."""
    if opts.duration is None:
        return boot_s + _after_boot_s(motion_s, opts.tilt)
    return opts.duration


def _drive(spec: Scenario, rig: Rig, the_plan: Plan, label: str) -> None:
    """``spec.drive``: a failed request is the run's ``host_error`` when the rig tolerates it
    (faults, a stopped supervisor; the robot is left to the firmware meanwhile), else the run's
    end; a user scenario's own exception ends the run with one line naming it."""
    try:
        spec.drive(rig, the_plan)
    except drivers.CommError as exc:
        if not rig.tolerates():
            raise ScenarioError(f"{label}: {exc}") from exc
        rig.host_error = f"{label}: {exc}"
    except BaseException as exc:
        if is_builtin(spec) or not user_fault(exc):
            raise                              # the twin's own (a bug, a signal, the run's end)
        raise ScenarioError(f"scenario {label} raised {describe(exc)} at t={rig.now_s:.3f} s") from None


def _host_controller(rig: Rig, step: Callable[..., Any], duration: float, period_ms: float) -> int | None:
    """The ``--host-controller`` loop until ``duration``; how many times ``step`` was called (None
    when a request failed and the run went on: the summary's ``host_error``)."""
    bound = _arm_host_bound(rig.twin, duration)
    try:
        ctx = run_host_controller(rig.H, step, rig.monitor, duration, period_ms, should_stop=rig.stopped)
        return ctx.calls
    except _HostBoundReachedError as exc:      # the run reached its duration: completed
        return exc.host_context.calls          # type: ignore[attr-defined]  # set on the exception (controllers.py)
    except drivers.CommError as exc:
        if not rig.tolerates():
            raise ScenarioError(f"host controller: {exc}") from exc
        rig.host_error = f"host controller: {exc}"
        return None
    except RuntimeError as exc:
        raise ScenarioError(str(exc)) from exc
    finally:
        bound.disarm()


__all__ = ["RunOptions", "outcome", "SLIP_HELD_MM", "SUMMARY_KEYS", "summary_keys_markdown", "Monitor",
           "NO_SUPPORT_MARGIN_MM",
           "Plan", "Scenario", "REGISTRY", "scenario", "load_scenario", "scenario_name",
           "ENTRY_POINT_GROUP", "is_reference", "split_reference", "entry_point_names", "did_you_mean",
           "recording_name", "boot", "hold", "BootError", "ScenarioError", "ScenarioInputError",
           "ScenarioLoadError", "SCENARIOS", "with_fields", "own_fields", "SCENARIO_FIELD_PREFIX",
           "CONTROL_CHOICES", "plan", "run", "tilt_profile",
           "expected_run_s", "Session", "open_run", "MAX_DURATION_S", "check_motion_s", "scenario_motion_s",
           "scenario_plan", "WallTimeoutExpired", "arm_wall_timeout", "disarm_wall_timeout",
           "wall_timeout_armed",
           "Rig", "RigOptions", "BOOT_TIMEOUT_S", "TILT_RATE_DEG_S", "SETTLE_S", "BOOT_MIN_S"]
