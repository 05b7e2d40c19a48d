"""User controllers: firmware laws (``--law``) and PC-side loops (``--host-controller``).

docs/controllers.md is the how-to. Two ways to put your own controller on the twin:

- **A firmware control law** (``slave/laws.py``): runs inside every Slave each 20 ms tick, in
  integers, for one control type of table 9. ``humanoid-twin run ... --law balance=mypkg.mylaw:MyLaw``
  (repeatable), ``RunOptions(laws=(("balance", "mypkg.mylaw:MyLaw"),))``, or an entry point of
  the group ``humanoid_twin.laws`` (``--law balance=NAME``). Finding a law (:func:`load_law`), the
  ``--law TYPE=REF`` syntax (:func:`parse_law_option`) and putting laws on the boards
  (:func:`install_laws`) are here; the laws' per-tick code is slave/laws.py's.
- **A PC-side controller**: a function ``step(ctx)`` the host calls every N ms of simulated time
  (``--host-controller mypkg.ctl:step --host-period-ms 20``) with :class:`HostContext`: the host
  toolbox bound to the twin's serial port (``ctx.host.readspecial(1)``, the same functions that
  drive the real robot, docs/host.md), the ground-truth :class:`~humanoid_twin.monitor.Monitor`
  (for evaluation: a real robot has none) and a ``state`` dict for the function's own memory.

Both are named by a reference with the rules of every plug-in (humanoid_twin/plugins.py):
``FILE.py:NAME``, ``MODULE:NAME``, or an entry point's name (groups ``humanoid_twin.laws`` and
``humanoid_twin.host_controllers``).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from humanoid_twin import host as _host
from humanoid_twin import plugins
from humanoid_twin.containment import describe, user_fault
from humanoid_twin.cycles import law_cycles, note_default_cost
from humanoid_twin.host.timebase import now as host_now
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.monitor import Monitor
from humanoid_twin.protocol.wire import ControlType
from humanoid_twin.slave.laws import CONTROL_TYPES, POSITION, VELOCITY, LawFactory

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort

__all__ = [
    "DEFAULT_HOST_PERIOD_MS",
    "LAW_ENTRY_POINT_GROUP",
    "HOST_CONTROLLER_ENTRY_POINT_GROUP",
    "ControllerError",
    "LawError",
    "load_law",
    "parse_law_option",
    "resolve_laws",
    "install_laws",
    "HostToolbox",
    "HostContext",
    "law_reference",
    "load_host_controller",
    "run_host_controller",
]

DEFAULT_HOST_PERIOD_MS = 20
LAW_ENTRY_POINT_GROUP = plugins.LAW_GROUP                         # --law balance=NAME
HOST_CONTROLLER_ENTRY_POINT_GROUP = plugins.HOST_CONTROLLER_GROUP   # --host-controller NAME
HostStep = Callable[["HostContext"], Any]


def law_reference(law: Any) -> str:
    """How a run's records name a firmware law (a serial log's meta, its replay's check):
    ``module:Class`` of a class, or the reference text it was given as."""
    return law if isinstance(law, str) else f"{law.__module__}:{law.__qualname__}"


class ControllerError(ValueError):
    """A ``--host-controller`` or ``--law`` value that cannot be used (one line: why)."""


def _takes_port(fn: Any) -> bool:
    try:
        params = list(inspect.signature(fn).parameters)
    except (TypeError, ValueError):
        return False
    return bool(params) and params[0] == "H"


# The toolbox functions whose first argument is the port H (readjoint, applyjoint, exe_traj ...).
_PORT_FUNCTIONS = tuple(n for n in _host.__all__
                        if callable(getattr(_host, n)) and _takes_port(getattr(_host, n)))


class HostToolbox:
    """The host toolbox (``humanoid_twin.host``) with the port bound: ``tb.readspecial(1)`` is
    ``readspecial(H, 1)``. Functions without a port (``calccop``, the planners) are as they are."""

    def __init__(self, H: HostPort) -> None:
        self.H = H

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name not in _host.__all__:
            raise AttributeError(f"the host toolbox has no {name!r} (docs/host.md)")
        fn = getattr(_host, name)
        if name in _PORT_FUNCTIONS:
            return functools.partial(fn, self.H)
        return fn

    def __dir__(self) -> list[str]:
        return sorted(_host.__all__)


@dataclass
class HostContext:
    """What a PC-side controller's ``step(ctx)`` gets each call.

    ``H``: the serial port; ``host``: the toolbox bound to it (:class:`HostToolbox`);
    ``monitor``: the run's ground-truth monitor; ``period_s``: the call period; ``calls``: calls
    so far (0 at the first); ``state``: a dict kept between calls; :attr:`t` the host's clock (s).
    """

    H: HostPort
    host: HostToolbox
    monitor: Monitor
    period_s: float
    calls: int = 0
    state: dict[str, Any] = field(default_factory=dict)

    @property
    def t(self) -> float:
        """The host's time (s): the twin's virtual time on the in-process port."""
        return host_now(self.H)


def _name_of(fn: Any) -> str:
    return f"{getattr(fn, '__module__', '?')}:{getattr(fn, '__qualname__', repr(fn))}"


def load_host_controller(ref: str | HostStep) -> HostStep:
    """``"FILE.py:function"``, ``"module.path:function"`` or an entry point's name (a callable is
    returned as it is) -> the ``step(ctx)`` function; raises :class:`ControllerError` with a
    one-line reason."""
    if callable(ref):
        return ref
    obj = plugins.load_reference(str(ref), _HOST_KIND)
    if not callable(obj):
        raise ControllerError(f"host controller {str(ref).strip()!r} is not a function "
                              f"(got {type(obj).__name__}; docs/controllers.md)")
    return obj


_HOST_KIND = plugins.Kind("host controller", plugins.HOST_CONTROLLER_GROUP, ControllerError,
                          wanted=inspect.isfunction)


def run_host_controller(H: Any, step: HostStep, monitor: Monitor, until_s: float,
                        period_ms: float = DEFAULT_HOST_PERIOD_MS,
                        should_stop: Callable[[], bool] | None = None) -> HostContext:
    """Call ``step(ctx)`` every ``period_ms`` of the host's time until ``until_s`` (a call that
    overruns its period delays the next one, as on a real PC). An exception from ``step`` is
    raised again as :class:`RuntimeError` naming the function."""
    period = period_ms / 1000.0
    ctx = HostContext(H, HostToolbox(H), monitor, period)
    try:
        _host_loop(ctx, step, until_s, period, should_stop)
    except BaseException as exc:
        exc.host_context = ctx       # type: ignore[attr-defined]  # the calls so far, for the summary
        raise
    return ctx


def _host_loop(ctx: HostContext, step: HostStep, until_s: float, period: float,
               should_stop: Callable[[], bool] | None) -> None:
    H = ctx.H
    next_t = host_now(H)
    while next_t < until_s - 1e-9:
        if should_stop is not None and should_stop():
            break
        try:
            step(ctx)
        except BaseException as exc:   # a user's function (SystemExit included): report it by name
            if not user_fault(exc):
                raise                  # a real signal, or the twin's own end of the run
            kind, _, message = describe(exc).partition(": ")
            raise RuntimeError(f"host controller {_name_of(step)[:120]} raised {kind} at "
                               f"t={host_now(H):.3f} s (call {ctx.calls}): {message}") from None
        ctx.calls += 1
        next_t += period
        now = host_now(H)
        if next_t < now:                      # overran: the next call starts now
            next_t = now
        wait = min(next_t, until_s) - now
        if wait > 0:
            host_sleep(H, wait)
    rest = until_s - host_now(H)
    if rest > 0:
        host_sleep(H, rest)


# -- firmware laws: finding them, the --law syntax, putting them on the boards --------------------
class LawError(ValueError):
    """A law could not be found or loaded (bad ``--law`` value, import error, not a law class)."""


def _is_law_class(obj: Any) -> bool:
    return inspect.isclass(obj) and callable(getattr(obj, "step", None))


_LAW_KIND = plugins.Kind("law", plugins.LAW_GROUP, LawError, wanted=_is_law_class)


def load_law(ref: str) -> LawFactory:
    """The law class named by ``ref``: ``"FILE.py:Class"``, ``"module.path:Class"``, or the name of
    an entry point in the group :data:`LAW_ENTRY_POINT_GROUP` (a package's shipped law; the rules
    of humanoid_twin/plugins.py). Raises :class:`LawError` with a one-line reason."""
    ref = ref.strip()
    obj = plugins.load_reference(ref, _LAW_KIND)
    if not callable(obj):
        raise LawError(f"law {ref!r} is not a class (got {type(obj).__name__}; docs/controllers.md)")
    try:
        probe = obj()
    except BaseException as exc:       # a user's class (SystemExit included): a bad --law
        if not user_fault(exc):
            raise
        raise LawError(f"law {ref!r} cannot be made with no arguments: {describe(exc)}") from None
    if not callable(getattr(probe, "step", None)):
        raise LawError(f"law {ref!r} has no step(inputs) method")
    if getattr(probe, "output", VELOCITY) not in (VELOCITY, POSITION):
        raise LawError(f"law {ref!r}: output must be {VELOCITY!r} or {POSITION!r}, got {probe.output!r}")
    _check_cost(probe, ref)
    return obj


def _check_cost(law: Any, name: str, ctype: int = ControlType.BALANCE_CONTROL) -> tuple[int, bool]:
    """``law``'s cost, ``(cycles per call, declared)`` (:func:`~humanoid_twin.cycles.law_cycles`,
    asked once: a ``cycles()`` is user code, whose next answer may differ); :class:`LawError` when
    it declares a cost (``cycles``) that is not one or raises."""
    try:
        return law_cycles(law, ctype)              # the type: the cost of a law declaring none
    except BaseException as exc:       # a user's cycles: not a cost, or it raised
        if not user_fault(exc):
            raise
        raise LawError(f"law {name!s:.80}: {describe(exc)}") from None


def parse_law_option(text: str) -> tuple[int, str]:
    """``TYPE=REF`` (``balance=mypkg.mylaw:MyLaw``) -> ``(control type, REF)``; TYPE is a name of
    :data:`CONTROL_TYPES` or its number. Raises :class:`LawError`."""
    kind, sep, ref = text.partition("=")
    kind = kind.strip().lower()
    if not sep or not ref.strip():
        raise LawError(f"--law {text!r}: expected TYPE=module:Class, TYPE=FILE.py:Class or TYPE=NAME "
                       f"(an entry point's; TYPE one of {', '.join(CONTROL_TYPES)})")
    if kind in CONTROL_TYPES:
        return CONTROL_TYPES[kind], ref.strip()
    if kind.isdigit() and int(kind) in CONTROL_TYPES.values():
        return int(kind), ref.strip()
    raise LawError(f"--law {text!r}: unknown control type {kind!r} (choose from {', '.join(CONTROL_TYPES)})")


def resolve_laws(laws: Mapping[int | str, Any] | Iterable[tuple[int | str, Any]]) -> dict[int, LawFactory]:
    """``{type: law}`` with type a number or a :data:`CONTROL_TYPES` name and law a class or a
    reference string (:func:`load_law`) -> ``{type number: class}``."""
    items = laws.items() if isinstance(laws, Mapping) else laws
    out: dict[int, LawFactory] = {}
    for kind, law in items:
        if isinstance(kind, str):
            if kind.lower() not in CONTROL_TYPES:
                raise LawError(f"unknown control type {kind!r} (choose from {', '.join(CONTROL_TYPES)})")
            ctype = CONTROL_TYPES[kind.lower()]
        else:
            ctype = int(kind)
            if ctype not in CONTROL_TYPES.values():
                raise LawError(f"unknown control type {kind!r} (0..3)")
        out[ctype] = load_law(law) if isinstance(law, str) else law
    return out


def install_laws(twin: Any, laws: Mapping[int | str, Any] | Iterable[tuple[int | str, Any]]) -> None:
    """Put the given laws on every Slave of ``twin`` (each board gets its own instance), replacing
    the built-in law of each control type named: ``install_laws(twin, {"balance": MyLaw})``."""
    first: list[tuple[Any, int, tuple[int, bool]]] = []   # one instance per type: its cost said once
    for ctype, factory in resolve_laws(laws).items():
        for slave in twin.slaves.values():
            try:
                law = factory()
            except BaseException as exc:   # a user's class: its instance for this board failed
                if not user_fault(exc):
                    raise
                raise LawError(f"law {getattr(factory, '__qualname__', '?')!s:.80} cannot be made for "
                               f"SCU {slave.address}: {describe(exc)}") from None
            # each board's instance asked its cost once; the board keeps that answer (issue 36:
            # a cycles() valid for the first check and invalid here was a traceback)
            cost = _check_cost(law, f"{getattr(factory, '__qualname__', '?')!s:.80} for SCU {slave.address}",
                               ctype)
            slave.servo.set_law(ctype, law, cycles=cost[0])
        first.append((law, ctype, cost))
    for law, ctype, cost in first:
        note_default_cost(law, ctype, cost)
