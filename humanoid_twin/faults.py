"""Seeded fault injection: ``KIND[:ARG][@T0[-T1]]`` from the CLI (``run --fault``, ``serve --fault``)
and the API (:func:`parse_fault`, :class:`FaultInjector`). docs/supervisor.md lists each kind's
effect (a table generated from :data:`KINDS` by scripts/gen_docs.py) and what the Master's
supervisor makes of it.

Times are simulated seconds from power-on; without ``@`` a fault lasts from power-on to the end;
``@T0`` alone: from T0 to the end. NODE 0 is the Master, 1-8 the Slaves. Every kind accepted here
is implemented (no kind is acknowledged and then ignored).

Each kind is one :class:`FaultKind` in :data:`KINDS` (its name, its argument, how the argument is
parsed, what its start and its end do to the twin, how overlapping faults of it combine, its help
line): the parser, the CLI's help, the docs table and humanoid_twin/fault_compose.py read it from
there, so a new kind is one :func:`register` call.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from humanoid_twin.clock import US_PER_S
from humanoid_twin.fault_compose import (  # KINDS and FaultSpecError live there, below this module
    KINDS,
    FaultSpecError,
    check_composition,
    combine_probability,
    effective,
    target_of,
)
from humanoid_twin.hardware import FOOT_OF_SCU, N_SERVOS, PWM_PERIOD_US
from humanoid_twin.limits import MAX_RUN_S
from humanoid_twin.master.pic import ROUND_US
from humanoid_twin.protocol.wire import node_error, node_name, scu_error
from humanoid_twin.seeds import STREAM_SERIAL_NOISE, derive_seed

if TYPE_CHECKING:
    from humanoid_twin.twin import Twin

__all__ = ["KINDS", "FaultKind", "FaultSpec", "FaultSpecError", "parse_fault", "FaultInjector", "PUSH_US",
           "DEADLINE_DELAY_US", "register", "unregister", "kinds_markdown"]

PUSH_US = 100_000            # a push lasts 100 ms
DEADLINE_DELAY_US = 3_000    # deadline:NODE: each tick's work starts this late
BUS_OFF_REFORCE_US = ROUND_US  # bus-off:NODE@T0-T1: forced again every CAN round until T1
MAX_PUSH_N = 1000.0

_SPEC = re.compile(r"^(?P<kind>[a-z-]+)(?::(?P<arg>[^@]*))?(?:@(?P<times>.*))?$")
# numbers as the docs write them, ASCII digits only (1, 0.5, .5, 1e-3, 2.5E+1), and the time
# range T0-T1 split at the '-' that is not an exponent's sign
_NUM = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"
_NUMBER = re.compile(rf"^{_NUM}$", re.ASCII)
_INTEGER = re.compile(r"^[+-]?\d+$", re.ASCII)
_TIMES = re.compile(rf"^(?P<t0>{_NUM})(?:-(?P<t1>{_NUM}))?$", re.ASCII)
MAX_FAULT_S = MAX_RUN_S      # T0 and T1 within one simulated day (humanoid_twin/limits.py)


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
    name, arg_s, times = m["kind"], m["arg"], m["times"]
    t0_s = t1_s = None
    if times is not None:
        tm = _TIMES.match(times.strip())
        if tm is None:
            raise _bad(text, f"expected @T0 or @T0-T1 in simulated seconds (e.g. @3, @1e-3, @2-4.5), "
                       f"got @{times}")
        t0_s, t1_s = tm["t0"], tm["t1"]
    kind = KINDS.get(name)
    if kind is None:
        raise _bad(text, f"unknown kind {name!r} (one of {', '.join(KINDS)})")
    if arg_s is None or arg_s == "":
        raise _bad(text, f"{name} needs an argument: {name}:{kind.arg}")
    arg = kind.parse(text, arg_s)
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
    if kind.lasts_us is not None and t1 is not None:
        raise _bad(text, f"a {name} lasts {kind.lasts_us // 1000} ms: give its start only, "
                   f"{name}:{kind.arg}@T0")
    return FaultSpec(name, arg, t0, t1, text.strip())


class FaultInjector:
    """Applies :class:`FaultSpec` s to a twin on its clock: ``FaultInjector(twin, specs, seed)``,
    then :meth:`install` (before the run). ``events``: ``(t_us, "start"|"end", spec)`` as they
    happen; ``listeners``: callables ``(t_us, what, spec)`` told of each.

    What a start or an end does is its kind's (:data:`KINDS`); the kinds' own functions use the
    public :attr:`twin`, :attr:`seed`, :attr:`active` and :meth:`effective`, and :meth:`toggle`
    for the on/off kinds."""

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
            clock.schedule(t0, lambda s=spec: self._start(s))  # type: ignore[misc]  # a default argument binds the spec
            lasts_us = KINDS[spec.kind].lasts_us
            if spec.t1_s is not None:
                clock.schedule(round(spec.t1_s * US_PER_S), lambda s=spec: self._end(s))  # type: ignore[misc]  # as above
            elif lasts_us is not None:
                clock.schedule(t0 + lasts_us, lambda s=spec: self._end(s))  # type: ignore[misc]  # as above
        return self

    def _note(self, what: str, spec: FaultSpec) -> None:
        t = self.twin.clock.now_us
        self.events.append((t, what, spec))
        for cb in self.listeners:
            cb(t, what, spec)

    def _start(self, spec: FaultSpec) -> None:
        self.active.append(spec)
        self.started.append(spec)
        KINDS[spec.kind].start(self, spec)
        self._note("start", spec)

    def _end(self, spec: FaultSpec) -> None:
        if spec in self.active:
            self.active.remove(spec)
        KINDS[spec.kind].end(self, spec)
        self._note("end", spec)

    def effective(self, spec: FaultSpec) -> Any:
        """What the active set now makes of ``spec``'s kind on ``spec``'s target
        (humanoid_twin/fault_compose.py): overlapping faults of one kind combine, the end of one
        never cancels another."""
        return effective(spec.kind, self.active, target_of(spec))

    def toggle(self, spec: FaultSpec, on: Callable[[bool], None]) -> None:
        """For a kind that is on or off per target (a silent node, a frozen foot or servo): call
        ``on(value)`` when the active set switches ``spec``'s target, and only then (a second
        freeze must not move the jam)."""
        value = self.effective(spec)
        key = (spec.kind, target_of(spec))
        if value == self._on.get(key, False):
            return
        self._on[key] = value
        on(value)

    def set_can(self, spec: FaultSpec) -> None:
        """can-drop, can-corrupt: the wire's two probabilities, its random stream re-seeded at
        each change."""
        self._can[spec.kind] = self.effective(spec)
        self._changes += 1
        self.twin.network.set_faults(self._can["can-drop"], self._can["can-corrupt"],
                                     seed=derive_seed(self.seed, self._changes))

    def deadline(self, spec: FaultSpec) -> None:
        """The Slave ``spec.arg`` late every tick until the last end of its active deadline faults."""
        twin = self.twin
        scu = spec.arg
        ends = [s.t1_s for s in self.active if s.kind == spec.kind and s.arg == scu]
        if not ends:
            return
        if any(e is None for e in ends):
            ticks = 10**9
        else:
            end = max(e for e in ends if e is not None) * US_PER_S
            ticks = max(1, math.ceil((end - twin.clock.now_us) / PWM_PERIOD_US))
        twin.slaves[scu].inject_deadline_violation(DEADLINE_DELAY_US, ticks)

    def bus_off(self, spec: FaultSpec) -> None:
        """The node bus-off now, and again every CAN round until ``spec``'s T1 (if any)."""
        twin = self.twin
        twin.network.force_bus_off(node_name(spec.arg))
        if spec.t1_s is not None:
            nxt = twin.clock.now_us + BUS_OFF_REFORCE_US
            if nxt < spec.t1_s * US_PER_S:
                twin.clock.schedule(nxt, lambda: self.bus_off(spec))


# --- the kinds -----------------------------------------------------------------------------------
Parse = Callable[[str, str], Any]
Action = Callable[[FaultInjector, FaultSpec], None]


def _nothing(injector: FaultInjector, spec: FaultSpec) -> None:
    """An end that does nothing of its own (the kind's start scheduled what it needs)."""


def _any(args: list[Any]) -> bool:
    return bool(args)


@dataclass(frozen=True)
class FaultKind:
    """One fault kind, everything about it in one place.

    ``name`` and ``arg`` (the argument's name: ``P``, ``NODE`` ...) spell ``name:ARG``;
    ``parse(text, arg_s)`` turns the argument into its value (``text``: the whole SPEC, for the
    one-line :class:`FaultSpecError`); ``start`` and ``end`` act on the twin through the
    :class:`FaultInjector` (whose :meth:`~FaultInjector.effective` is what the active set makes of
    the kind); ``help`` is the docs table's line; ``targeted``: the argument names what the fault
    acts on (faults of the kind on different targets are independent); ``combine`` the value of
    several active faults from their arguments (humanoid_twin/fault_compose.py; default: on while
    any is active); ``lasts_us``: a fixed duration (no T1 then).
    """

    name: str
    arg: str
    parse: Parse
    start: Action
    end: Action
    help: str
    targeted: bool = False
    combine: Callable[[list[Any]], Any] = _any
    lasts_us: int | None = None


def register(kind: FaultKind) -> FaultKind:
    """Add ``kind`` to :data:`KINDS` (parsed, started and ended from then on); returns it."""
    if not re.fullmatch(r"[a-z-]+", kind.name):
        raise ValueError(f"a fault kind's name is lower-case letters and '-', got {kind.name!r}")
    if kind.name in KINDS:
        raise ValueError(f"fault kind {kind.name!r} is already registered")
    KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    """Remove the kind ``name`` from :data:`KINDS`."""
    del KINDS[name]


def kinds_markdown() -> str:
    """The kinds as docs/supervisor.md's table (scripts/gen_docs.py)."""
    rows = ["| kind | ARG | effect |", "|---|---|---|"]
    rows += [f"| `{k.name}` | {k.arg} | {k.help} |" for k in KINDS.values()]
    return "\n".join(rows) + "\n"


def _probability(text: str, arg_s: str) -> float:
    p = _number(text, arg_s, "P")
    if not 0.0 <= p <= 1.0:
        raise _bad(text, f"probability P must be in [0, 1], got {arg_s}")
    return p


def _node(text: str, arg_s: str) -> int:
    return _address(text, arg_s, "NODE (0 Master, 1-8 Slaves)", node_error)


def _slave(text: str, arg_s: str) -> int:
    return _address(text, arg_s, "NODE (a Slave: only Slaves have a deadline)", scu_error)


def _counts(text: str, arg_s: str) -> int:
    return _int(text, arg_s, "COUNTS", 1, 255)


def _foot_scu(text: str, arg_s: str) -> int:
    scu = _address(text, arg_s, "SCU", scu_error)
    if scu not in FOOT_OF_SCU:
        raise _bad(text, f"SCU {scu} has no force-sensing foot (feet: {sorted(FOOT_OF_SCU)})")
    return scu


def _servo(text: str, arg_s: str) -> tuple[int, int]:
    scu_s, dot, servo_s = arg_s.partition(".")
    if not dot:
        raise _bad(text, f"servo-stuck needs SCU.SERVO (e.g. 1.3), got {arg_s!r}")
    return (_address(text, scu_s, "SCU", scu_error), _int(text, servo_s, "SERVO", 1, N_SERVOS))


def _newtons(text: str, arg_s: str) -> float:
    f = _number(text, arg_s, "NEWTONS")
    if f == 0 or abs(f) > MAX_PUSH_N:
        raise _bad(text, f"NEWTONS must be non-zero and within +-{MAX_PUSH_N:g}, got {arg_s}")
    return f


def _serial_noise(inj: FaultInjector, spec: FaultSpec) -> None:
    inj.twin.link.set_noise(inj.effective(spec), seed=derive_seed(inj.seed, STREAM_SERIAL_NOISE))


def _force_noise(inj: FaultInjector, spec: FaultSpec) -> None:
    inj.twin.plant.set_force_noise(inj.effective(spec))


def _silent(inj: FaultInjector, spec: FaultSpec) -> None:
    inj.toggle(spec, lambda on: inj.twin.network.silence(node_name(spec.arg), on))


def _force_stuck(inj: FaultInjector, spec: FaultSpec) -> None:
    inj.toggle(spec, lambda on: inj.twin.plant.set_force_stuck(spec.arg, on))


def _servo_stuck(inj: FaultInjector, spec: FaultSpec) -> None:
    scu, servo = spec.arg
    inj.toggle(spec, lambda on: inj.twin.plant.set_servo_stuck(scu, servo - 1, on))


def _push(inj: FaultInjector, spec: FaultSpec) -> None:
    inj.twin.plant.set_trunk_force(inj.effective(spec))


def _max(args: list[Any]) -> Any:
    return max(args, default=0)


def _sum(args: list[Any]) -> float:
    return float(sum(args))


for _kind in (
    FaultKind("can-drop", "P", _probability, FaultInjector.set_can, FaultInjector.set_can,
              "each CAN frame is lost with probability P: it completes (the sender counts a success), "
              "nobody receives it", combine=combine_probability),
    FaultKind("can-corrupt", "P", _probability, FaultInjector.set_can, FaultInjector.set_can,
              "each CAN frame is destroyed by an error frame with probability P: sender TEC +8, receivers "
              "REC +1, automatic retransmission (30 % drives the Master to bus-off)",
              combine=combine_probability),
    FaultKind("silent", "NODE", _node, _silent, _silent,
              "the node stops transmitting (it still receives); NODE 0 is the Master", targeted=True),
    FaultKind("bus-off", "NODE", _node, FaultInjector.bus_off, _nothing,
              "the node's controller goes bus-off at T0; with T1, it is forced again every 8 ms until T1. "
              "A Slave recovers by itself at its next tick (seed 000 `checkCan`); the Master stays off "
              "until the host reads the CAN status", targeted=True),
    FaultKind("serial-noise", "P", _probability, _serial_noise, _serial_noise,
              "each RS-232 byte, both directions, gets one data bit flipped with probability P (the BCC "
              "catches it; the host retries)", combine=combine_probability),
    FaultKind("deadline", "NODE", _slave, FaultInjector.deadline, _nothing,
              "the Slave's loop starts 3 ms late every tick (status bit 5 set)", targeted=True),
    FaultKind("force-noise", "COUNTS", _counts, _force_noise, _force_noise,
              "uniform noise of ±COUNTS 8-bit ADC counts on every force sensor", combine=_max),
    FaultKind("force-stuck", "SCU", _foot_scu, _force_stuck, _force_stuck,
              "the four sensors of the foot of leg board SCU (1 or 2) freeze at their reading",
              targeted=True),
    FaultKind("servo-stuck", "SCU.SERVO", _servo, _servo_stuck, _servo_stuck,
              "servo SERVO (1-3) of board SCU jams at its current angle (its pulses are ignored)",
              targeted=True),
    FaultKind("push", "NEWTONS", _newtons, _push, _push,
              "a 100 ms horizontal force on the trunk at T0, forward (negative: backward)",
              combine=_sum, lasts_us=PUSH_US),
):
    register(_kind)
del _kind
