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

import hashlib
import importlib
import importlib.util
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from humanoid_twin.clock import US_PER_S
from humanoid_twin.containment import attribute_path, describe, user_fault
from humanoid_twin.controllers import load_host_controller, run_host_controller
from humanoid_twin.host import drivers
from humanoid_twin.host.motion import exe_traj, send_gains
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
from humanoid_twin.monitor import Monitor
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
from humanoid_twin.slave.laws import LawError
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
    from humanoid_twin.twin import Twin

CONTROL_CHOICES: dict[str, int] = {t.label: t for t in ControlType}   # run --control
# the boot cannot end sooner: the Slaves' calibration waits 100 PWM periods, then averages 25
# (seed 000 SERVO ``calibration``); a --duration below it is refused before the run starts
BOOT_MIN_S = (100 + 25) * 0.020
SETTLE_S = 2.0
ENTRY_POINT_GROUP = "humanoid_twin.scenarios"     # a package's scenarios, by name


class ScenarioInputError(ScenarioError):
    """The options ask for something the run cannot do (a ``--duration`` shorter than the boot)."""


class ScenarioLoadError(ScenarioInputError):
    """A scenario reference that names no scenario (cannot be imported, or is not a
    :class:`Scenario`): one line naming it."""


class _DurationReachedError(BaseException):
    """Raised by the clock at ``--duration`` when that instant falls inside the scenario's program:
    the run is cut there and its summary says ``completed: false``. A ``BaseException``: a host
    controller's (or a user scenario's) ``except Exception`` does not swallow it."""


class _HostBoundReachedError(BaseException):
    """Raised by the clock at the run's end while a host controller runs: whatever the
    controller does (sleeps, loops), the run ends at its duration (issue 24)."""


class _WallTimeoutError(BaseException):
    """SIGALRM at ``wall_timeout`` wall seconds (``run --wall-timeout``)."""


def hold(H: Any, plan: Plan, scus: tuple[int, ...] = LEG_SCUS) -> None:
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


_BALANCE_TYPES = (ControlType.REACTION_CONTROL, ControlType.BALANCE_CONTROL)


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


SCENARIOS: tuple[str, ...] = tuple(REGISTRY)   # the built-in scenarios, in registration order
DOUBLE_SUPPORT_SCENARIOS: tuple[str, ...] = tuple(n for n, s in REGISTRY.items() if s.double_support)


# -- user scenarios ------------------------------------------------------------------------------
_loaded: dict[str, Scenario] = {}


def is_reference(ref: str) -> bool:
    """``file.py:NAME`` or ``module:NAME`` (a scenario to import), not a name."""
    return ":" in ref


def split_reference(ref: str) -> tuple[str, str]:
    """``FILE.py:NAME`` / ``MODULE:NAME`` -> ``(FILE.py or MODULE, NAME)`` (split at the last
    colon: a file's path may hold one); ``("", ref)`` for a name."""
    where, _, attr = ref.rpartition(":")
    return where, attr


def recording_name(ref: str | Scenario, label: str = "") -> str:
    """The default file name of a run's recording: the scenario's ``name`` (a user's object's
    own, whatever the reference calls it), then ``_LABEL`` (a sweep's grid point), ``.rrd``."""
    name = load_scenario(ref).name
    return f"{name}_{label}.rrd" if label else f"{name}.rrd"


def entry_point_names() -> list[str]:
    """The scenarios installed packages declare in the group :data:`ENTRY_POINT_GROUP`."""
    from importlib.metadata import entry_points

    return sorted(ep.name for ep in entry_points(group=ENTRY_POINT_GROUP))


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
    if is_reference(ref):
        where, attr = split_reference(ref)
        if not where or not attr:
            raise ScenarioLoadError(f"scenario {ref!r}: expected FILE.py:NAME or MODULE:NAME")
        obj: Any = _import(ref, where)
        try:
            obj = attribute_path(obj, attr)
        except AttributeError:
            raise ScenarioLoadError(f"scenario {ref!r}: {where} has no {attr!r}") from None
    else:
        from importlib.metadata import entry_points

        eps = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == ref]
        if not eps:
            raise ScenarioLoadError(
                f"unknown scenario {ref!r} (choose from {', '.join(REGISTRY)}; or FILE.py:NAME, "
                f"MODULE:NAME, an entry point of {ENTRY_POINT_GROUP!r}: "
                f"{', '.join(entry_point_names()) or 'none installed'})")
        try:
            obj = eps[0].load()
        except BaseException as exc:       # noqa: BLE001 - a user's package: judged, not trusted
            if not user_fault(exc):
                raise
            why = describe(exc)
            raise ScenarioLoadError(f"scenario {ref!r}: cannot load its entry point: {why}") from None
    if not isinstance(obj, Scenario):
        raise ScenarioLoadError(f"scenario {ref!r} is not a Scenario (got {type(obj).__name__}; "
                                "docs/scenarios.md, \"Your own scenario\")")
    if not isinstance(obj.name, str) or not obj.name.strip() or "/" in obj.name or "\0" in obj.name:
        raise ScenarioLoadError(f"scenario {ref!r}: its name {obj.name!r} cannot name a file "
                                "(the default recording is NAME.rrd): give it a name without '/'")
    _loaded[ref] = obj
    return obj


def _import(ref: str, where: str) -> Any:
    """The module of a scenario reference: a ``.py`` file (imported under a name of its own) or an
    importable module."""
    try:
        if where.endswith(".py"):
            path = Path(where).expanduser().resolve()
            if not path.is_file():
                raise ScenarioLoadError(f"scenario {ref!r}: no such file {where}")
            name = "humanoid_twin_user_scenario_" + hashlib.sha256(str(path).encode()).hexdigest()[:12]
            if name in sys.modules:
                return sys.modules[name]
            spec = importlib.util.spec_from_file_location(name, path)
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[name]
                raise
            return module
        return importlib.import_module(where)
    except ScenarioLoadError:
        raise
    except BaseException as exc:           # noqa: BLE001 - a user's module: any import failure
        if not user_fault(exc):
            raise
        raise ScenarioLoadError(f"scenario {ref!r}: cannot import {where}: {describe(exc)}") from None


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


def run_plan(spec: Scenario, opts: RunOptions) -> Plan:
    """The plan a run of ``spec`` executes: the scenario's, with ``--control``'s type if given."""
    the_plan = spec.plan(opts.T, opts.motion, opts.perna)
    if opts.control is not None:
        split = spec.double_support or the_plan.lead is not None
        the_plan = the_plan.with_control(CONTROL_CHOICES[opts.control], split=split)
    return the_plan


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


def expected_run_s(scenario: str | Scenario, duration: float | None = None, T: float | None = None,
                   motion: float | None = None, perna: int = 1, tilt: float = 0.0) -> float:
    """How long a run lasts at most, in simulated seconds, known before it starts: ``duration``
    when given, else the boot's bound (:data:`BOOT_TIMEOUT_S`) + the motion or the tilt + the
    settling (what the CLI sizes the outputs' disk space by)."""
    if duration is not None:
        return duration
    spec = load_scenario(scenario)
    return BOOT_TIMEOUT_S + _after_boot_s(spec.motion_s(spec.plan(T, motion, perna)), tilt)


class Session:
    """One run of a scenario, open in Python: built and booted, then driven step by step or to its
    end (:func:`open_run`, ``humanoid_twin.open``; ``humanoid-twin run`` is :meth:`finish` at once).

    ``Session(opts)`` builds the :class:`~humanoid_twin.rig.Rig` of ``opts`` (the twin, its laws,
    its outputs, monitor and faults) and boots it: the host's port ``H`` is open and every Slave
    calibrated (time advances here, ~2.65 simulated s). From there, in any order:
    :meth:`step` (time passes, the firmware holds the posture or follows what the host sent),
    :meth:`read` (the robot now), :meth:`drive` (the scenario's own program, e.g. the squat),
    ``H`` (the host toolbox on the robot's serial port: ``readjoint(session.H, 1)``, ``applyjoint``
    ... docs/host.md); :meth:`finish` runs the rest as ``humanoid-twin run`` would (the program if
    not driven yet, ``host_controller``, settling until the run's end) and returns the summary;
    :meth:`close` (or leaving the ``with`` block) closes the outputs and the twin.

    Attributes: ``opts``, ``spec`` (the :class:`Scenario`), ``plan`` (its :class:`Plan`, with
    ``control``'s type), ``rig``, ``boot_s``, ``end_s`` (when :meth:`finish` ends the run:
    ``duration``, or the boot + the program or the tilt + settling)."""

    def __init__(self, opts: RunOptions, on_progress: Callable[[float, float | None], None] | None = None,
                 on_twin: Callable[[Any], None] | None = None) -> None:
        self.opts = opts
        self.spec, self.label = load_scenario(opts.scenario), scenario_name(opts.scenario)
        self.plan = run_plan(self.spec, opts)
        self.motion_s = self.spec.motion_s(self.plan)
        self._host_step = (load_host_controller(opts.host_controller)
                           if opts.host_controller is not None else None)
        self.expected_s = expected_run_s(self.spec, opts.duration, opts.T, opts.motion, opts.perna, opts.tilt)
        self.summary: dict[str, Any] | None = None
        self.outputs: Any = None            # the files' temporary names (open_run), else None
        self._driven = False
        self._wall0 = time.perf_counter()
        self.rig = _open_rig(opts, self.expected_s, on_twin, on_progress)
        try:
            self.rig.boot()                                   # time advances here: the boot
            self.boot_s = self.rig.now_s
            self.end_s = self.rig.end_s = _duration(opts, self.boot_s, self.motion_s)
        except BaseException:
            self.rig.close()
            raise

    @property
    def H(self) -> Any:  # noqa: N802 - the toolbox's name for the host's port (seed 000 table 20)
        """The host's end of the robot's RS-232 link (the toolbox's ``H``: docs/host.md)."""
        return self.rig.H

    @property
    def twin(self) -> Twin:
        """The twin (boards, buses, plant)."""
        return self.rig.twin

    @property
    def now_s(self) -> float:
        """The virtual time (simulated s)."""
        return self.rig.now_s

    def step(self, seconds: float = 0.02) -> dict[str, Any]:
        """Let ``seconds`` of virtual time pass (the host waits on the twin's clock; the boards
        run); returns :meth:`read`."""
        if not seconds > 0:
            raise ValueError(f"step({seconds!r}): give a positive number of simulated seconds")
        self.rig.sleep(seconds)
        return self.read()

    def read(self) -> dict[str, Any]:
        """The robot now, from the plant's ground truth and the Master's supervisor (reading takes
        no time): ``t_s``, ``mode`` (the supervisor's), ``fell`` (at any sample so far),
        ``fell_at_s``, ``trunk_tilt_deg``, ``cop_margin_mm`` (the CoP's distance inside the
        support polygon), ``platform_tilt_deg``, ``joints_deg`` (every joint's true angle,
        by MuJoCo joint name)."""
        twin, mon = self.rig.twin, self.rig.monitor
        truth = twin.plant.truth()
        return {
            "t_s": twin.now_s,
            "mode": twin.master.supervisor.mode_name,
            "fell": mon.fell or truth.fell,
            "fell_at_s": mon.fell_at_s,
            "trunk_tilt_deg": truth.trunk_tilt_deg,
            "cop_margin_mm": truth.cop_margin_mm,
            "platform_tilt_deg": twin.plant.tilt_deg,
            "joints_deg": dict(truth.joint_angles_deg),
        }

    def drive(self) -> None:
        """The scenario's own program (:meth:`Scenario.drive`: the planner's motions, or the
        hold of its gains), once; time advances by its length. A failed request is the run's
        ``host_error`` where the run tolerates it (faults, a stopped supervisor), as in ``run``."""
        if self._driven:
            raise ScenarioError(f"{self.label}: its program was driven already")
        self._driven = True
        if self.rig.host_error is None:
            _drive(self.spec, self.rig, self.plan, self.label)

    def finish(self) -> dict[str, Any]:
        """The rest of the run as ``humanoid-twin run`` has it: the scenario's program (unless
        :meth:`drive` ran it), the ``host_controller``, the robot settling until :attr:`end_s`
        (``duration`` cuts the program where it falls inside it: ``completed`` false). Returns the
        summary (docs/scenarios.md), also kept in :attr:`summary`."""
        rig, duration, spec = self.rig, self.end_s, self.spec
        completed, host_calls = True, None
        if rig.now_s < duration < self.boot_s + self.motion_s:
            _cut_at(rig, duration)                   # --duration ends inside the program
        try:
            if not self._driven and (not spec.moves or duration > rig.now_s):
                self.drive()                         # time advances here: the scenario's program
            if self._host_step is not None and rig.host_error is None:
                host_calls = _host_controller(rig, self._host_step, duration, self.opts.host_period_ms)
            rig.sleep_until(duration)                # time advances here: the robot settles
        except _DurationReachedError:
            completed = False                        # --duration fell inside the program: cut there
        self.summary = build_summary(rig, self.label, self.plan, completed=completed,
                                     wall_s=time.perf_counter() - self._wall0, host_calls=host_calls)
        return self.summary

    def close(self, failed: bool = False) -> None:
        """Close the outputs and the twin (:meth:`Rig.close`); a recording's summary notes are
        added to :attr:`summary` then (its compaction happens at the close). Files written under
        temporary names (:func:`open_run`) take their final names now, or are removed when
        ``failed`` (an exception left the ``with`` block) or the close itself failed: an
        existing file is never replaced by a failed run. Closing twice does nothing."""
        if getattr(self, "_closed", False):
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
    except OSError as exc:
        outputs.discard()
        raise ScenarioInputError(f"cannot write there: {exc}") from None
    if temp:
        opts = dataclasses.replace(opts, **temp, can_log_name=finals["can_log"].name if "can_log" in finals
                                   else opts.can_log_name)
    try:
        session = Session(opts)
    except BaseException:
        outputs.discard()
        raise
    session.outputs = outputs
    return session


def run(opts: RunOptions, on_progress: Callable[[float, float | None], None] | None = None,
        on_twin: Callable[[Any], None] | None = None) -> dict[str, Any]:
    """Run one scenario headless and return its summary (docs/scenarios.md): a :class:`Session`
    opened and finished at once. The outputs are written to the names in ``opts`` as they go
    (the CLI gives temporary names; :func:`open_run` does the same from Python).

    ``on_progress(t_s, end_s)`` is called every 0.1 s of virtual time: ``end_s`` is None during
    the boot (its length is not known in advance), then the run's end time. ``on_twin(twin)`` is
    called once the twin is built, before anything is written (``run --viewer`` attaches there)."""
    load_scenario(opts.scenario)              # a reference that names nothing: before the timer
    disarm = _arm_wall_timeout(opts.wall_timeout)
    session: Session | None = None
    try:
        # made first, then built: a --wall-timeout during the boot still finds the rig's time
        session = Session.__new__(Session)
        session.__init__(opts, on_progress, on_twin)
        with session:
            session.finish()
        assert session.summary is not None
        return session.summary
    except _WallTimeoutError:
        rig = getattr(session, "rig", None)
        now = rig.now_s if rig is not None else 0.0
        raise ScenarioError(f"the run took more than {opts.wall_timeout:g} wall seconds (--wall-timeout): "
                            f"stopped at t={now:.3f} s simulated") from None
    finally:
        disarm()


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
    if opts.duration < boot_s:
        raise ScenarioInputError(
            f"--duration {opts.duration:g} is shorter than the boot ({boot_s:.3f} simulated seconds "
            "from power-on): give at least that")
    return opts.duration


def _cut_at(rig: Rig, duration: float) -> None:
    def cut() -> None:
        raise _DurationReachedError

    rig.twin.clock.schedule(round(duration * US_PER_S), cut)


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
        return exc.host_context.calls          # type: ignore[attr-defined]
    except drivers.CommError as exc:
        if not rig.tolerates():
            raise ScenarioError(f"host controller: {exc}") from exc
        rig.host_error = f"host controller: {exc}"
        return None
    except RuntimeError as exc:
        raise ScenarioError(str(exc)) from exc
    finally:
        bound["armed"] = False


__all__ = ["RunOptions", "outcome", "SLIP_HELD_MM", "SUMMARY_KEYS", "summary_keys_markdown", "Monitor",
           "NO_SUPPORT_MARGIN_MM",
           "Plan", "Scenario", "REGISTRY", "scenario", "get_scenario", "load_scenario", "scenario_name",
           "ENTRY_POINT_GROUP", "boot", "hold", "BootError", "ScenarioError", "ScenarioInputError",
           "ScenarioLoadError", "SCENARIOS", "CONTROL_CHOICES", "plan", "run", "run_plan", "tilt_profile",
           "expected_run_s", "Session", "open_run",
           "Rig", "RigOptions", "BOOT_TIMEOUT_S", "TILT_RATE_DEG_S", "SETTLE_S", "BOOT_MIN_S"]
