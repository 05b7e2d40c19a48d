"""User controllers: firmware laws (``--law``) and PC-side loops (``--host-controller``).

docs/controllers.md is the how-to. Two ways to put your own controller on the twin:

- **A firmware control law** (``slave/laws.py``): runs inside every Slave each 20 ms tick, in
  integers, for one control type of table 9. ``humanoid-twin run ... --law balance=mypkg.mylaw:MyLaw``
  (repeatable), ``RunOptions(laws=(("balance", "mypkg.mylaw:MyLaw"),))``, or an entry point of
  the group ``humanoid_twin.laws`` (``--law balance=NAME``).
- **A PC-side controller**: a function ``step(ctx)`` the host calls every N ms of simulated time
  (``--host-controller mypkg.ctl:step --host-period-ms 20``) with :class:`HostContext`: the host
  toolbox bound to the twin's serial port (``ctx.host.readspecial(1)``, the same functions that
  drive the real robot, docs/host.md), the ground-truth :class:`~humanoid_twin.monitor.Monitor`
  (for evaluation: a real robot has none) and a ``state`` dict for the function's own memory.
"""

from __future__ import annotations

import functools
import importlib
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from humanoid_twin import host as _host
from humanoid_twin.containment import attribute_path, describe, user_fault
from humanoid_twin.host.timebase import now as host_now
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.monitor import Monitor

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort

__all__ = [
    "DEFAULT_HOST_PERIOD_MS",
    "ControllerError",
    "HostToolbox",
    "HostContext",
    "law_reference",
    "load_host_controller",
    "run_host_controller",
]

DEFAULT_HOST_PERIOD_MS = 20
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
    """``"module.path:function"`` (or a callable) -> the ``step(ctx)`` function; raises
    :class:`ControllerError` with a one-line reason."""
    if callable(ref):
        return ref
    mod_name, sep, attr = str(ref).strip().partition(":")
    if not sep or not mod_name or not attr:
        raise ControllerError(f"--host-controller {ref!r}: expected module:function")
    try:
        obj: Any = importlib.import_module(mod_name)
    except Exception as exc:   # a user's module: any import failure is a bad option
        raise ControllerError(f"--host-controller {ref!r}: cannot import {mod_name!r}: "
                              f"{type(exc).__name__}: {exc}") from None
    try:
        obj = attribute_path(obj, attr)
    except AttributeError:
        obj = None
    if obj is None:
        raise ControllerError(f"--host-controller {ref!r}: module {mod_name!r} has no {attr!r}")
    if not callable(obj):
        raise ControllerError(f"--host-controller {ref!r} is not a function")
    return obj


def run_host_controller(H: HostPort, step: HostStep, monitor: Monitor, until_s: float,
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
