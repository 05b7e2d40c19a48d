"""Module SUPERVISOR of the Master: modes, fault detection, emergency stop (docs/supervisor.md).

Beyond the seeds: the 2006 Master (seed 000 section 2) forwards bytes and never judges them, so a
bus-off Master or a silent Slave fails silently. The hexapod thesis (seed 004) asks for what a
robot lab adds around such a system: a mode machine, a safe state and an emergency stop. This
module is that addition, inside the Master firmware, on the Master's own data only (its global
database, its CAN controller and the bytes the host sends); every timer counts simulated time.

Modes (the numbers are the wire's, ``FD MODE ...``)::

    standby 0 --PWM on requested--> self_check 1 --every Slave answers, PWM on, calibrated--> ready 2
    any mode but estop --fault--> safe 3 (latched)       any mode --estop--> estop 4
    safe / estop --reset--> self_check 1                  ready --PWM off on every board--> standby 0

It is called from two places: by ``usartProcessMsg`` for every valid host request
(:meth:`host_frame`; :meth:`apply_allowed` and :meth:`refusal`, which may refuse an APPLY;
:meth:`applied`; the supervisor request's :meth:`read`, :meth:`estop` and :meth:`reset`), and
:meth:`on_round` by the timer interrupt when a CAN schedule round closes (every 8 ms: the
detection). It puts nothing on the CAN bus of its own (an emergency stop only clears the PWM bit of
the actuation packets the schedule already sends).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, NamedTuple

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import FOOT_OF_SCU, FORCE_CALIBRATION_VALUE, FORCE_SENSOR_XY_MM, PWM_PERIOD_US
from humanoid_twin.protocol.canframes import SFLAGS2_LAW, SFLAGS_CAN_STATE
from humanoid_twin.protocol.rs232 import PARAM_SPECIAL, SUPERVISOR_FAULTS, SUPERVISOR_MODES, Op
from humanoid_twin.protocol.wire import (
    NODES,
    POS_LIMIT_DEG,
    STATUS_CALIB,
    STATUS_DEADLINE,
    STATUS_PWM,
    ErrorState,
)
from humanoid_twin.slave.data import calcCoP

if TYPE_CHECKING:
    from humanoid_twin.clock import Clock
    from humanoid_twin.master.can import MasterCan
    from humanoid_twin.master.database import Database, ScuSensors

__all__ = [
    "STANDBY", "SELF_CHECK", "READY", "SAFE", "ESTOP", "MODE_NAMES",
    "SILENT", "BUS_OFF_FAULT", "SLAVE_CAN", "OVER_TRAVEL", "DEADLINE", "BALANCE", "HOST_LINK", "LAW",
    "FAULT_NAMES", "Fault", "SupervisorConfig", "Supervisor",
]

# --- modes and faults: the wire numbers of rs232.SUPERVISOR_MODES / SUPERVISOR_FAULTS, by name ---
_MODE = {name: code for code, name in SUPERVISOR_MODES.items()}
STANDBY = _MODE["standby"]
SELF_CHECK = _MODE["self_check"]
READY = _MODE["ready"]
SAFE = _MODE["safe"]
ESTOP = _MODE["estop"]
MODE_NAMES: dict[int, str] = SUPERVISOR_MODES

_FAULT = {name: code for code, name in SUPERVISOR_FAULTS.items()}
SILENT = _FAULT["silent"]
BUS_OFF_FAULT = _FAULT["bus_off"]
SLAVE_CAN = _FAULT["slave_can"]
OVER_TRAVEL = _FAULT["over_travel"]
DEADLINE = _FAULT["deadline"]
BALANCE = _FAULT["balance"]
HOST_LINK = _FAULT["host_link"]
LAW = _FAULT["law"]              # a Slave stopped a control law that failed (docs/controllers.md)
FAULT_NAMES: dict[int, str] = SUPERVISOR_FAULTS

_OP_APPLY_JOINT = int(Op.APPLY_JOINT)
_BUS_OFF = ErrorState.BUS_OFF.label      # a CAN controller's ``state`` when bus-off

# The sensor rectangle of a foot (table 12, mm): the edge the firmware's CoP can reach.
_XS = [p[0] for p in FORCE_SENSOR_XY_MM]
_YS = [p[1] for p in FORCE_SENSOR_XY_MM]
SENSOR_X_MIN, SENSOR_X_MAX = min(_XS), max(_XS)
SENSOR_Y_MIN, SENSOR_Y_MAX = min(_YS), max(_YS)

# the same facts under private names, C constants of the compiled round (supervisor.pxd; the
# public names stay Python objects for the modules that import them)
_STANDBY, _SELF_CHECK, _READY, _SAFE, _ESTOP = STANDBY, SELF_CHECK, READY, SAFE, ESTOP
_CAN_STATE = SFLAGS_CAN_STATE
_LAW_STOPPED = SFLAGS2_LAW
_DEADLINE_BIT = STATUS_DEADLINE
_PWM_BIT = STATUS_PWM
_CALIB_BIT = STATUS_CALIB
_X_MIN, _X_MAX, _Y_MIN, _Y_MAX = SENSOR_X_MIN, SENSOR_X_MAX, SENSOR_Y_MIN, SENSOR_Y_MAX
_FEET = tuple(FOOT_OF_SCU)               # the leg boards, in FOOT_OF_SCU's order
_NEVER = -(1 << 62)                      # a hold's start when none runs (no virtual time is this)


def _per_node(value: int) -> list[int]:
    """One ``value`` per node, indexed by its address (0 the Master, 1..8 the Slaves)."""
    return [value] * len(NODES)


def _support_margin(cops: list[tuple[int, int]]) -> float:
    """How far the CoPs of the loaded feet (one or two, mm, foot frames) are inside the edge the
    robot can tip over (:meth:`Supervisor.balance_margin_mm`); -1 with no foot loaded."""
    if not cops:
        return -1.0
    if len(cops) == 1:
        x, y = cops[0]
        m = x - _X_MIN                   # min() of the four edges' distances, as the builtin
        m = _min2(m, _X_MAX - x)         # chooses (the first of equals)
        m = _min2(m, y - _Y_MIN)
        return _min2(m, _Y_MAX - y)
    front = back = 0.0                   # max() over the feet of their distances to the edge
    first = True
    for _, y in cops:
        if first or _Y_MAX - y > front:
            front = _Y_MAX - y
        if first or y - _Y_MIN > back:
            back = y - _Y_MIN
        first = False
    return _min2(front, back)


def _min2(a: float, b: float) -> float:
    """``min(a, b)``: ``b`` only when it is smaller (the builtin's choice among equals)."""
    return b if b < a else a


class Fault(NamedTuple):
    """One detected fault: virtual time, wire code, node (0 Master, 1-8 Slaves)."""

    t_us: int
    code: int
    node: int

    @property
    def name(self) -> str:
        """The JSON name (``silent``, ``bus_off`` ...)."""
        return FAULT_NAMES[self.code]

    def as_dict(self) -> dict[str, Any]:
        """``{"t_s", "code", "name", "node"}`` (the run summary's ``faults`` entries)."""
        return {"t_s": round(self.t_us / US_PER_S, 6), "code": self.code, "name": self.name,
                "node": self.node}


# the largest threshold a config takes: 10**12 (ms: 31 years; the compiled supervisor keeps them,
# in us, as C long long)
_THRESHOLD_MAX = 10**12


@dataclass(frozen=True)
class SupervisorConfig:
    """Detection thresholds (docs/supervisor.md gives the reason for each default). Frozen: the
    supervisor reads the values when it is given the config; another config is set whole
    (``supervisor.config = SupervisorConfig(...)``)."""

    silent_rounds: int = 3           # a board with no packet for this many rounds is silent
    deadline_ticks: int = 5          # deadline bit held for this many Slave ticks
    over_travel_deg: int = POS_LIMIT_DEG   # |measured position| beyond this (the servos' range)
    balance_margin_mm: int = 3       # CoP of every loaded foot this close to its sensor rectangle
    balance_hold_ms: int = 100       # ... for this long (or no foot loaded for this long)
    balance_calib_load: int = 15     # 7-bit counts a sensor carried at calibration (host/cop.py)
    host_link_ms: int | None = None  # no valid host frame for this long while ready: off (None)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None and f.name == "host_link_ms":
                continue
            if type(value) is not int or not -_THRESHOLD_MAX <= value <= _THRESHOLD_MAX:
                raise ValueError(f"SupervisorConfig.{f.name} must be an integer within "
                                 f"+-{_THRESHOLD_MAX}, got {value!r}")
        for name in ("silent_rounds", "deadline_ticks", "balance_hold_ms"):
            if getattr(self, name) < 1:
                raise ValueError(f"SupervisorConfig.{name} must be >= 1, got {getattr(self, name)!r}")
        if self.host_link_ms is not None and self.host_link_ms <= 0:
            raise ValueError(f"SupervisorConfig.host_link_ms must be > 0 or None, got {self.host_link_ms!r}")


Listener = Callable[[str, int, Any], None]


class Supervisor:
    """The Master's mode supervisor: ``Supervisor(clock, db, can, round_us, config)``, ``round_us``
    the length of the Master's CAN round (``ROUND_US`` of pic.py: the Master wires the two).

    ``mode`` (wire number), ``faults`` (every fault detected, in order; the first since the last
    reset is the latched one), ``listeners``: callables ``(kind, t_us, value)`` told of every
    ``"mode"`` change (value: the new mode) and ``"fault"`` (value: the :class:`Fault`).
    """

    def __init__(self, clock: Clock, db: Database, can: MasterCan, round_us: int,
                 config: SupervisorConfig | None = None) -> None:
        self.clock = clock
        self.db = db
        self.can = can
        self._round_us = round_us
        self.config = config or SupervisorConfig()
        self.mode = STANDBY
        self.faults: list[Fault] = []
        self.latched: list[Fault] = []        # faults since the last reset (the first is reported)
        self.listeners: list[Listener] = []
        self.refused = 0                      # APPLY requests answered FC by the supervisor
        self.last_host_us = 0
        self._seen: set[tuple[int, int]] = set()
        # per node, indexed by its address (0 the Master, 1..8 the Slaves; the Master's
        # _packets and _deadline_since entries are unused); _NEVER: no hold running
        self._packets = _per_node(0)
        self._quiet_rounds = _per_node(0)
        self._master_sent = 0
        self._deadline_since = _per_node(_NEVER)
        self._balance_since = _NEVER
        self.reset_refused: str | None = None  # why the last reset was refused (None: it was not)
        # the leg boards' loads before calibration (counts) and the margin they gave (boot falls)
        self._raw_load: dict[int, int] = {k: 0 for k in FOOT_OF_SCU}
        self._raw_margin: float | None = None

    @property
    def config(self) -> SupervisorConfig:
        """The detection thresholds; set a new :class:`SupervisorConfig` whole to change them."""
        return self._config

    @config.setter
    def config(self, config: SupervisorConfig) -> None:
        if not isinstance(config, SupervisorConfig):
            raise TypeError(f"Supervisor.config must be a SupervisorConfig, got {config!r}")
        self._config = config
        # the values the rounds compare with, read once (the config is frozen)
        self._silent_rounds = config.silent_rounds
        self._deadline_hold_us = (config.deadline_ticks - 1) * PWM_PERIOD_US
        self._over_travel_deg = config.over_travel_deg
        self._margin_mm = config.balance_margin_mm
        self._balance_hold_us = config.balance_hold_ms * 1000
        self._force_offset = config.balance_calib_load - FORCE_CALIBRATION_VALUE
        self._host_link_us = -1 if config.host_link_ms is None else config.host_link_ms * 1000

    # -- what the host sees -----------------------------------------------------------------------
    @property
    def mode_name(self) -> str:
        """``standby`` / ``self_check`` / ``ready`` / ``safe`` / ``estop``."""
        return MODE_NAMES[self.mode]

    def read(self) -> tuple[int, int, int, int]:
        """``(MODE, FAULTCODE, NODE, NFAULTS)`` of the read-supervisor answer: the first latched
        fault (0, 0 when none) and the number latched since the last reset (capped at 255)."""
        if self.latched:
            f = self.latched[0]
            return self.mode, f.code, f.node, min(len(self.latched), 255)
        return self.mode, 0, 0, 0

    def apply_allowed(self) -> bool:
        """False in ``safe`` and ``estop``: an APPLY is answered FC (reads always go through)."""
        return self.mode != SAFE and self.mode != ESTOP

    def refusal(self) -> str:
        """Why an APPLY is refused now (for the Master's ``last_invalid``)."""
        mode, code, node, _ = self.read()
        fault = f", fault {FAULT_NAMES[code]} node {node}" if code else ""
        return f"supervisor in {MODE_NAMES[mode]}{fault}: APPLY refused"

    def reset_refusal(self) -> str:
        """Why the last reset was refused (for the Master's ``last_invalid``)."""
        mode, code, node, _ = self.read()
        fault = f", fault {FAULT_NAMES[code]} node {node}" if code else ""
        return f"supervisor in {MODE_NAMES[mode]}{fault}: reset refused: {self.reset_refused}"

    # -- requests from the host (usartProcessMsg) ------------------------------------------------
    def host_frame(self) -> None:
        """A valid host frame arrived (the host_link watchdog)."""
        self.last_host_us = self.clock.now_us

    def applied(self, op: int, param: int, data: tuple[int, int, int]) -> None:
        """An APPLY was accepted: a PWM-on request starts the self-check; PWM off on every board
        in ``ready`` goes back to ``standby``."""
        if op != _OP_APPLY_JOINT or param != PARAM_SPECIAL:
            return
        if data[0] == 1:
            if self.mode == STANDBY:
                self._set_mode(SELF_CHECK)
        elif self.mode in (READY, SELF_CHECK) and not any(a.pwm for a in self.db.actuators.values()):
            self._set_mode(STANDBY)

    def estop(self) -> None:
        """Emergency stop, category 0: PWM off in every board's actuation data (the schedule sends
        it to each board within one 8 ms round; the Slave switches its pulses off on receipt)."""
        for a in self.db.actuators.values():
            if a.pwm:
                a.pwm = False
                a.invalidate()
        self._set_mode(ESTOP)

    def reset(self) -> bool:
        """Reset: forget the latched faults and run a new self-check (from any mode). From safe
        or estop only a healthy robot is reset (:meth:`reset_blocker`): otherwise nothing changes,
        the latch holds, and False is returned (the request is answered FC)."""
        why = self.reset_blocker()
        if why is not None:
            self.reset_refused = why
            return False
        self.reset_refused = None
        self.latched.clear()
        self._seen.clear()
        # the silence counters run on through a reset: a board already quiet is not given
        # a fresh 3-round grace (docs/supervisor.md, "Reset")
        self._deadline_since = _per_node(_NEVER)
        self._balance_since = _NEVER
        self._set_mode(SELF_CHECK)
        return True

    def reset_blocker(self) -> str | None:
        """Why a reset may not open the latch now (None: it may). In safe and estop every board
        must have answered within the last 2 CAN rounds and the Master's own controller must be
        on the bus (not bus-off; the Slaves answer only the Master's packets, so their answers
        say its own frames reach the wire): a reset never re-opens motion on a robot with a dead
        board, however often it is asked (docs/supervisor.md, "Reset")."""
        if self.mode != SAFE and self.mode != ESTOP:
            return None
        now = self.clock.now_us
        if self.can.drivers.controller.state == _BUS_OFF:
            return "the Master's CAN controller is bus-off (read the CAN status first)"
        quiet = [k for k, s in self.db.sensors.items()
                 if s.last_rx_us < 0 or now - s.last_rx_us > 2 * self._round_us]
        if quiet:
            return f"SCU {', '.join(map(str, quiet))} not answering"
        return None

    # -- detection (timer interrupt, end of each CAN round) ------------------------------------
    def on_round(self) -> None:
        """A CAN schedule round closed: check every fault rule, then the self-check."""
        mode = self.mode
        if mode == _ESTOP:
            return
        now = self.clock.now_us
        ctl = self.can.drivers.controller
        silent = self._silent_rounds
        master_down = False
        # the Master's own CAN: bus-off, or nothing of its own got on the wire for N rounds
        if ctl.state == _BUS_OFF:
            self._fault(BUS_OFF_FAULT, 0, now)
            master_down = True
        sent = ctl.frames_sent
        quiet = self._quiet_rounds[0] + 1 if sent == self._master_sent else 0
        self._quiet_rounds[0] = quiet
        self._master_sent = sent
        if quiet >= silent and not master_down:
            self._fault(SILENT, 0, now)
        # a round in which the Master got nothing on the wire says nothing about the Slaves
        # (they only answer the Master's packets): their silence is not counted then
        master_down = master_down or quiet >= 1
        for k, s in self.db.sensors.items():
            n = s.packets1 + s.packets2
            if master_down:
                self._packets[k] = n
                continue
            quiet = self._quiet_rounds[k] + 1 if n == self._packets[k] else 0
            self._quiet_rounds[k] = quiet
            self._packets[k] = n
            # silent: a board heard before, or any board once the self-check has started
            # (a board never heard in standby may simply not be fitted: a bench Master)
            if quiet >= silent and (s.last_rx_us >= 0 or self.mode != _STANDBY):
                self._fault(SILENT, k, now)
                continue
            if s.sflags & _CAN_STATE and now - s.last_rx_us <= self._round_us:   # a fresh report
                self._fault(SLAVE_CAN, k, now)
            if s.sflags2 & _LAW_STOPPED:
                self._fault(LAW, k, now)
            if s.status & _DEADLINE_BIT:
                since = self._deadline_since[k]
                if since == _NEVER:
                    self._deadline_since[k] = s.last_rx_us
                elif s.last_rx_us - since >= self._deadline_hold_us:
                    self._fault(DEADLINE, k, now)
            else:
                self._deadline_since[k] = _NEVER
        if self.mode == _READY:
            lim = self._over_travel_deg
            for k, s in self.db.sensors.items():
                if s.status & _PWM_BIT:
                    for p in s.pos:
                        if p > lim or p < -lim:
                            self._fault(OVER_TRAVEL, k, now)
                            break
            self._check_balance(now)
            if self._host_link_us >= 0 and now - self.last_host_us > self._host_link_us:
                self._fault(HOST_LINK, 0, now)
        elif self.mode == _SELF_CHECK or (self.mode == _STANDBY and self.last_host_us > 0):
            self._check_fall(now)             # a fall during the boot, once the host has started it
        if self.mode == _SELF_CHECK and self._all_ready(now) and self._balance_since == _NEVER:
            self._set_mode(READY)             # (not while a fall is being confirmed, issue 24)

    def _all_ready(self, now: int) -> bool:
        want = _PWM_BIT | _CALIB_BIT
        for s in self.db.sensors.values():
            if s.last_rx_us < 0 or now - s.last_rx_us > 2 * self._round_us or s.status & want != want:
                return False
        return True

    def foot_cop_mm(self, scu: int) -> tuple[int, int] | None:
        """The Master's firmware CoP ``(x, y)`` (mm, foot frame) of leg board ``scu``: ``calcCoP``
        on the forces of its last Sensors 2 packet, each taken as ``reading - 128 + calib_load``
        7-bit counts (128: ``hardware.FORCE_CALIBRATION_VALUE``, the reading at the calibrated
        load; as host/cop.py does); None when the foot is unloaded."""
        return self._foot_cop(self.db.sensors[scu])

    def _foot_cop(self, s: ScuSensors) -> tuple[int, int] | None:
        offset = self._force_offset
        f0, f1, f2, f3 = s.special
        x, y, loaded = calcCoP((max(f0 + offset, 0), max(f1 + offset, 0), max(f2 + offset, 0),
                                max(f3 + offset, 0)))
        return (x, y) if loaded else None

    def balance_margin_mm(self) -> float | None:
        """How far the firmware CoP is inside the edge the robot can tip over (mm), None while
        a foot's PWM is off. The edges are those of the sensor rectangles (the firmware's CoP
        cannot leave them): with one foot loaded, the nearest edge of its rectangle; with both
        loaded, the front (back) edge, the smaller of the two feet's distances to it (the feet
        stand side by side: the lateral edges of the support are the feet's outer edges, which
        the robot only reaches once the other foot is off the ground). -1 with no foot loaded."""
        sensors = self.db.sensors
        cops = []
        for k in _FEET:
            s = sensors[k]
            if not s.status & _PWM_BIT:
                return None
            c = self._foot_cop(s)
            if c is not None:
                cops.append(c)
        return _support_margin(cops)

    def boot_balance_margin_mm(self) -> float | None:
        """:meth:`balance_margin_mm` for standby and self_check, where a fall must be seen too
        (issue 24; docs/supervisor.md, "Falls during the boot"). Before a leg board has
        calibrated its force sensors their offsets are 0, so its readings are the loads
        themselves (7-bit counts): the CoP is ``calcCoP`` of the readings, whatever the PWM. Once
        both are calibrated the readings are taken as in ready (``reading - 128 + calib_load``,
        PWM on), but a calibration is only trusted if it was taken standing: if the last loads
        seen before it put the CoP at the edge (the robot was going down while it calibrated),
        that margin stands; if the feet carried less than half a standing robot's weight (the
        robot was already down), no foot counts as loaded (-1). None while a leg board has not
        been heard."""
        sensors = self.db.sensors
        cfg = self.config
        cops = []
        raw = False
        for k in FOOT_OF_SCU:
            s = sensors[k]
            if s.last_rx_us < 0:
                return None
            if s.status & STATUS_CALIB:
                if not s.status & STATUS_PWM:
                    return None
                c = self._foot_cop(s)
            else:
                raw = True
                self._raw_load[k] = sum(s.special)
                x, y, loaded = calcCoP([int(v) for v in s.special])
                c = (x, y) if loaded else None
            if c is not None:
                cops.append(c)
        margin = _support_margin(cops)
        if raw:
            self._raw_margin = margin
            return margin
        standing = cfg.balance_calib_load * len(FORCE_SENSOR_XY_MM) * len(FOOT_OF_SCU)
        if 2 * sum(self._raw_load.values()) < standing:
            return -1.0
        if self._raw_margin is not None and self._raw_margin <= cfg.balance_margin_mm:
            return min(margin, self._raw_margin)
        return margin

    def _check_fall(self, now: int) -> None:
        """The balance rule of ready (:meth:`_check_balance`) on :meth:`boot_balance_margin_mm`."""
        self._check_margin(self.boot_balance_margin_mm(), now)

    def _check_balance(self, now: int) -> None:
        self._check_margin(self.balance_margin_mm(), now)

    def _check_margin(self, m: float | None, now: int) -> None:
        """The balance rule: a margin at or below ``balance_margin_mm`` for ``balance_hold_ms``
        latches the balance fault (None: no margin to judge, the hold starts again)."""
        if m is None or m > self._margin_mm:
            self._balance_since = _NEVER
            return
        if self._balance_since == _NEVER:
            self._balance_since = now
        elif now - self._balance_since >= self._balance_hold_us:
            self._fault(BALANCE, 0, now)

    # -- bookkeeping -----------------------------------------------------------------------------
    def _fault(self, code: int, node: int, now: int) -> None:
        key = (code, node)
        if key in self._seen:
            return
        self._seen.add(key)
        f = Fault(now, code, node)
        self.faults.append(f)
        self.latched.append(f)
        for cb in self.listeners:
            cb("fault", now, f)
        if self.mode != _SAFE and self.mode != _ESTOP:
            self._set_mode(SAFE)

    def _set_mode(self, mode: int) -> None:
        if mode == self.mode:
            return
        self.mode = mode
        for cb in self.listeners:
            cb("mode", self.clock.now_us, mode)
