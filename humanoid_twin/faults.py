"""Seeded fault injection: ``KIND[:ARG][@T0[-T1]]`` from the CLI (``run --fault``, ``serve --fault``)
and the API (:func:`parse_fault`, :class:`FaultInjector`). docs/supervisor.md lists each kind's
effect and what the Master's supervisor makes of it.

Times are simulated seconds from power-on; without ``@`` a fault lasts from power-on to the end;
``@T0`` alone: from T0 to the end. NODE 0 is the Master, 1-8 the Slaves. Every kind accepted here
is implemented (no kind is acknowledged and then ignored):

=====================  ==========================================================================
``can-drop:P``         each CAN frame lost with probability P (it completes, nobody receives it)
``can-corrupt:P``      each CAN frame destroyed by an error frame with probability P (retransmitted)
``silent:NODE``        the node stops transmitting (it still receives)
``bus-off:NODE``       the node's controller goes bus-off at T0 (held there until T1 if given)
``serial-noise:P``     each RS-232 byte gets one bit flipped with probability P (both directions)
``deadline:NODE``      the Slave's loop starts 3 ms late every tick (deadline bit set)
``force-noise:COUNTS`` +-COUNTS uniform noise on every force sensor (8-bit ADC counts)
``force-stuck:SCU``    the foot sensors of leg board SCU (1 or 2) freeze
``servo-stuck:S.I``    servo I (1-3) of board S jams at its angle
``push:NEWTONS``       a 100 ms horizontal shove on the trunk at T0, forward (negative: backward)
=====================  ==========================================================================
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from humanoid_twin.clock import US_PER_S
from humanoid_twin.fault_compose import check_composition, effective, target_of
from humanoid_twin.hardware import FOOT_OF_SCU, N_SERVOS, PWM_PERIOD_US
from humanoid_twin.master.pic import ROUND_US
from humanoid_twin.protocol.wire import node_error, node_name, scu_error

if TYPE_CHECKING:
    from humanoid_twin.twin import Twin

__all__ = ["KINDS", "FaultSpec", "FaultSpecError", "parse_fault", "FaultInjector", "PUSH_US",
           "DEADLINE_DELAY_US"]

PUSH_US = 100_000            # a push lasts 100 ms
DEADLINE_DELAY_US = 3_000    # deadline:NODE: each tick's work starts this late
BUS_OFF_REFORCE_US = ROUND_US  # bus-off:NODE@T0-T1: forced again every CAN round until T1
MAX_PUSH_N = 1000.0

KINDS: dict[str, str] = {
    "can-drop": "P",
    "can-corrupt": "P",
    "silent": "NODE",
    "bus-off": "NODE",
    "serial-noise": "P",
    "deadline": "NODE",
    "force-noise": "COUNTS",
    "force-stuck": "SCU",
    "servo-stuck": "SCU.SERVO",
    "push": "NEWTONS",
}

_SPEC = re.compile(r"^(?P<kind>[a-z-]+)(?::(?P<arg>[^@]*))?(?:@(?P<times>.*))?$")
# numbers as the docs write them, ASCII digits only (1, 0.5, .5, 1e-3, 2.5E+1), and the time
# range T0-T1 split at the '-' that is not an exponent's sign
_NUM = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_NUMBER = re.compile(rf"^{_NUM}$", re.ASCII)
_INTEGER = re.compile(r"^[+-]?\d+$", re.ASCII)
_TIMES = re.compile(rf"^(?P<t0>{_NUM})(?:-(?P<t1>{_NUM}))?$", re.ASCII)
MAX_FAULT_S = 86_400.0       # T0 and T1 within one simulated day (run's --duration bound)


class FaultSpecError(ValueError):
    """A ``--fault`` SPEC that cannot be used (the message is one line)."""


@dataclass(frozen=True)
class FaultSpec:
    """One parsed fault: ``kind``, ``arg`` (float, int or (scu, servo)), ``t0_s``, ``t1_s``
    (None: to the end), and the ``text`` it was parsed from."""

    kind: str
    arg: Any
    t0_s: float = 0.0
    t1_s: float | None = None
    text: str = ""

    def as_dict(self) -> dict[str, Any]:
        """The run summary's ``injected`` entry."""
        arg = list(self.arg) if isinstance(self.arg, tuple) else self.arg
        return {"spec": self.text, "kind": self.kind, "arg": arg, "t0_s": self.t0_s, "t1_s": self.t1_s}


def _bad(text: str, why: str) -> FaultSpecError:
    return FaultSpecError(f"bad --fault {text!r}: {why}")


def _number(text: str, s: str, what: str) -> float:
    if not _NUMBER.match(s.strip()):
        raise _bad(text, f"{what} must be a number, got {s!r}")
    v = float(s)
    if not math.isfinite(v):
        raise _bad(text, f"{what} must be finite, got {s!r}")
    return v


def _int(text: str, s: str, what: str, lo: int, hi: int) -> int:
    if not _INTEGER.match(s.strip()):
        raise _bad(text, f"{what} must be an integer {lo}..{hi}, got {s!r}")
    v = int(s)
    if not lo <= v <= hi:
        raise _bad(text, f"{what} must be {lo}..{hi}, got {v}")
    return v


def _address(text: str, s: str, what: str, error: Callable[[Any, str], str | None]) -> int:
    """``s`` as a node or SCU address, checked by the protocol's ``error`` (``scu_error`` or
    ``node_error``); a :class:`FaultSpecError` naming ``what`` otherwise."""
    v: Any = int(s) if _INTEGER.match(s.strip()) else s   # else the check names it (ASCII digits only)
    reason = error(v, what)
    if reason is not None:
        raise _bad(text, reason)
    return int(v)


def parse_fault(text: str) -> FaultSpec:
    """``KIND[:ARG][@T0[-T1]]`` -> :class:`FaultSpec`; :class:`FaultSpecError` (one line) if bad."""
    m = _SPEC.match(text.strip())
    if m is None:
        raise _bad(text, "expected KIND[:ARG][@T0[-T1]]")
    kind, arg_s, times = m["kind"], m["arg"], m["times"]
    t0_s = t1_s = None
    if times is not None:
        tm = _TIMES.match(times.strip())
        if tm is None:
            raise _bad(text, f"expected @T0 or @T0-T1 in simulated seconds (e.g. @3, @1e-3, @2-4.5), "
                       f"got @{times}")
        t0_s, t1_s = tm["t0"], tm["t1"]
    if kind not in KINDS:
        raise _bad(text, f"unknown kind {kind!r} (one of {', '.join(KINDS)})")
    if arg_s is None or arg_s == "":
        raise _bad(text, f"{kind} needs an argument: {kind}:{KINDS[kind]}")
    arg: Any
    if kind in ("can-drop", "can-corrupt", "serial-noise"):
        arg = _number(text, arg_s, "P")
        if not 0.0 <= arg <= 1.0:
            raise _bad(text, f"probability P must be in [0, 1], got {arg_s}")
    elif kind in ("silent", "bus-off"):
        arg = _address(text, arg_s, "NODE (0 Master, 1-8 Slaves)", node_error)
    elif kind == "deadline":
        arg = _address(text, arg_s, "NODE (a Slave: only Slaves have a deadline)", scu_error)
    elif kind == "force-noise":
        arg = _int(text, arg_s, "COUNTS", 1, 255)
    elif kind == "force-stuck":
        arg = _address(text, arg_s, "SCU", scu_error)
        if arg not in FOOT_OF_SCU:
            raise _bad(text, f"SCU {arg} has no force-sensing foot (feet: {sorted(FOOT_OF_SCU)})")
    elif kind == "servo-stuck":
        scu_s, dot, servo_s = arg_s.partition(".")
        if not dot:
            raise _bad(text, f"servo-stuck needs SCU.SERVO (e.g. 1.3), got {arg_s!r}")
        arg = (_address(text, scu_s, "SCU", scu_error), _int(text, servo_s, "SERVO", 1, N_SERVOS))
    else:  # push
        arg = _number(text, arg_s, "NEWTONS")
        if arg == 0 or abs(arg) > MAX_PUSH_N:
            raise _bad(text, f"NEWTONS must be non-zero and within +-{MAX_PUSH_N:g}, got {arg_s}")
    t0 = 0.0
    t1 = None
    if t0_s is not None:
        t0 = _number(text, t0_s, "T0")
        if t0 < 0:
            raise _bad(text, f"T0 must be >= 0 s, got {t0_s}")
        if t0 > MAX_FAULT_S:
            raise _bad(text, f"T0 must be at most {MAX_FAULT_S:g} s (one simulated day), got {t0_s}")
        if t1_s is not None:
            t1 = _number(text, t1_s, "T1")
            if t1 <= t0:
                raise _bad(text, f"T1 must be after T0, got {t0_s}-{t1_s}")
            if t1 > MAX_FAULT_S:
                raise _bad(text, f"T1 must be at most {MAX_FAULT_S:g} s (one simulated day), got {t1_s}")
    if kind == "push" and t1 is not None:
        raise _bad(text, "a push lasts 100 ms: give its start only, push:NEWTONS@T0")
    return FaultSpec(kind, arg, t0, t1, text.strip())


class FaultInjector:
    """Applies :class:`FaultSpec` s to a twin on its clock: ``FaultInjector(twin, specs, seed)``,
    then :meth:`install` (before the run). ``events``: ``(t_us, "start"|"end", spec)`` as they
    happen; ``listeners``: callables ``(t_us, what, spec)`` told of each."""

    def __init__(self, twin: Twin, specs: list[FaultSpec] | tuple[FaultSpec, ...], seed: int = 0) -> None:
        self.twin = twin
        self.specs = tuple(specs)
        self.seed = seed
        self.events: list[tuple[int, str, FaultSpec]] = []
        self.listeners: list[Callable[[int, str, FaultSpec], None]] = []
        self._can = {"can-drop": 0.0, "can-corrupt": 0.0}
        self._changes = 0
        self.active: list[FaultSpec] = []     # started and not ended (humanoid_twin/fault_compose.py)
        self.started: list[FaultSpec] = []    # every fault that started, in order
        self._on: dict[tuple[str, Any], bool] = {}
        check_composition(self.specs)

    def install(self) -> FaultInjector:
        """Schedule every fault's start (and end) on the twin's clock."""
        clock = self.twin.clock
        for spec in self.specs:
            t0 = max(round(spec.t0_s * US_PER_S), clock.now_us)
            clock.schedule(t0, lambda s=spec: self._start(s))
            if spec.t1_s is not None:
                clock.schedule(round(spec.t1_s * US_PER_S), lambda s=spec: self._end(s))
            elif spec.kind == "push":
                clock.schedule(t0 + PUSH_US, lambda s=spec: self._end(s))
        return self

    def _note(self, what: str, spec: FaultSpec) -> None:
        t = self.twin.clock.now_us
        self.events.append((t, what, spec))
        for cb in self.listeners:
            cb(t, what, spec)

    def _set_can(self) -> None:
        self._changes += 1
        self.twin.network.set_faults(self._can["can-drop"], self._can["can-corrupt"],
                                     seed=self.seed * 7919 + self._changes)

    def _start(self, spec: FaultSpec) -> None:
        self.active.append(spec)
        self.started.append(spec)
        if spec.kind == "bus-off":
            self._bus_off(spec)
        elif spec.kind == "deadline":
            self._deadline(spec.arg)
        else:
            self._apply(spec)
        self._note("start", spec)

    def _end(self, spec: FaultSpec) -> None:
        if spec in self.active:
            self.active.remove(spec)
        # bus-off: the re-forcing stops at T1 and the node recovers as its firmware does;
        # deadline: the injected ticks run out at the last active end
        if spec.kind not in ("bus-off", "deadline"):
            self._apply(spec)
        self._note("end", spec)

    def _apply(self, spec: FaultSpec) -> None:
        """Give the twin what the active set now makes of ``spec``'s kind on ``spec``'s target
        (humanoid_twin/fault_compose.py): overlapping faults of one kind combine, the end of one
        never cancels another."""
        twin = self.twin
        k, a = spec.kind, spec.arg
        value = effective(k, self.active, target_of(spec))
        if k in self._can:
            self._can[k] = value
            self._set_can()
        elif k == "serial-noise":
            twin.link.set_noise(value, seed=self.seed * 7919 + 1)
        elif k == "force-noise":
            twin.plant.set_force_noise(value)
        elif k in ("silent", "force-stuck", "servo-stuck"):
            key = (k, target_of(spec))
            if value == self._on.get(key, False):
                return                        # already so: a second freeze must not move the jam
            self._on[key] = value
            if k == "silent":
                twin.network.silence(node_name(a), value)
            elif k == "force-stuck":
                twin.plant.set_force_stuck(a, value)
            else:
                twin.plant.set_servo_stuck(a[0], a[1] - 1, value)
        else:  # push
            twin.plant.set_trunk_force(value)

    def _deadline(self, scu: int) -> None:
        """The Slave ``scu`` late every tick until the last end of its active deadline faults."""
        twin = self.twin
        ends = [s.t1_s for s in self.active if s.kind == "deadline" and s.arg == scu]
        if not ends:
            return
        if any(e is None for e in ends):
            ticks = 10**9
        else:
            end = max(e for e in ends if e is not None) * US_PER_S
            ticks = max(1, math.ceil((end - twin.clock.now_us) / PWM_PERIOD_US))
        twin.slaves[scu].inject_deadline_violation(DEADLINE_DELAY_US, ticks)

    def _bus_off(self, spec: FaultSpec) -> None:
        twin = self.twin
        twin.network.force_bus_off(node_name(spec.arg))
        if spec.t1_s is not None:
            nxt = twin.clock.now_us + BUS_OFF_REFORCE_US
            if nxt < spec.t1_s * US_PER_S:
                twin.clock.schedule(nxt, lambda: self._bus_off(spec))


# --- the CLI (``run`` and ``serve``): cli/main.py calls these ------------------------------------
def _fault_arg(text: str) -> FaultSpec:
    import argparse

    try:
        return parse_fault(text)
    except FaultSpecError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_fault_options(p: Any) -> None:
    """``--fault SPEC`` (repeatable) and ``--host-link S`` on an argparse (sub)parser."""
    from humanoid_twin.cli.argtypes import positive_seconds

    p.add_argument("--fault", type=_fault_arg, action="append", default=[], metavar="SPEC",
                   help="inject a fault, KIND[:ARG][@T0[-T1]] (repeatable; seeded by --seed): "
                   + ", ".join(f"{k}:{v}" for k, v in KINDS.items()) + " (docs/supervisor.md)")
    p.add_argument("--host-link", type=positive_seconds, metavar="S",
                   help="supervisor: latch host_link when no valid host frame arrives for S seconds "
                   "while ready (default: off)")


def supervisor_config(args: Any) -> Any:
    """The :class:`~humanoid_twin.master.supervisor.SupervisorConfig` the CLI options ask for."""
    from humanoid_twin.master.supervisor import SupervisorConfig

    if getattr(args, "host_link", None) is None:
        return None
    return SupervisorConfig(host_link_ms=max(1, round(args.host_link * 1000)))
