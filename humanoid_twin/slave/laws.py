"""Firmware control laws as plug-ins: the interface of a Slave's control law (seed 000 tables 9-11).

Each 20 ms tick a Slave's SERVO module (``servo.ServoControl.controller``) groups its three servos
by control type (the wire's ``Control`` byte, table 9: 0 NO_CONTROL, 1 LOCOMOTION_CONTROL,
2 REACTION_CONTROL, 3 BALANCE_CONTROL) and calls, once per type in use, that type's law with the
board's integer inputs (:class:`LawInputs`). The law returns one integer per servo:

- ``output = VELOCITY`` (the balance laws): a velocity in **1/65536 degree per tick**
  (:data:`ONE_DEG_PER_TICK` = 65536 = 50 deg/s). The board's ``applyVelocity`` caps it at 1 degree
  per tick, accumulates it with 16 fractional bits and adds the resulting offset to the
  trajectory reference (held within -90..90); the offset restarts from 0 when the servo changes
  type or starts a new trajectory. Each value must be an ``int`` that fits the PIC's signed 32-bit
  ``long`` (:data:`VELOCITY_MIN`..:data:`VELOCITY_MAX`).
- ``output = POSITION`` (open loop, the PID): the position to apply, whole degrees, an ``int`` in
  -90..90.

Values for servos not in ``inputs.servos`` are ignored (return 0 there). Integer arithmetic is
the rule: the PIC has no floating point; a law that raises, returns something other than three
ints, or an int out of range is **stopped**: the board keeps applying the positions of the last
good tick to those servos (it holds), records a :class:`LawFault` naming the law
(``ServoControl.law_fault``), and tells the Master, whose supervisor reports fault ``law``
(docs/supervisor.md) and goes to safe.

A law is a class; each board makes its own instance (``Law()``, no arguments), so per-servo
state lives on ``self``. :meth:`ControlLaw.start` is called for a servo when the board resets
(after calibration) and whenever that servo switches to the law's control type. Set
``needs_foot = True`` for a law that only makes sense on a board with a force-sensing foot (leg
boards, SCU 1 and 2): on the other boards its servos then follow their trajectory reference, as
the manual's balance laws do.

The four laws of table 9 are written on this interface: :class:`OpenLoopLaw`,
:class:`LocomotionLaw` (incremental PID), :class:`ReactionLaw` and :class:`JacobianLaw`
(docs/balance.md, docs/firmware.md). A user's law replaces one of them for one control type:
``humanoid-twin run ... --law balance=mypkg.mylaw:MyLaw``, ``RunOptions(laws=...)``,
``humanoid_twin.controllers.install_laws``, or a package's entry point in the group
``humanoid_twin.laws`` (``--law balance=NAME``): finding and installing a law is
humanoid_twin/controllers.py's (this module holds what runs each tick). docs/controllers.md is the
how-to.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from humanoid_twin.cycles import LAW
from humanoid_twin.hardware import N_SERVOS
from humanoid_twin.protocol.wire import POS_LIMIT_DEG, ControlType, from_s8
from humanoid_twin.slave.data import jacobianMatrix

__all__ = [
    "VELOCITY",
    "POSITION",
    "ONE_DEG_PER_TICK",
    "VELOCITY_MIN",
    "VELOCITY_MAX",
    "CONTROL_TYPES",
    "PID_SHIFT",
    "JACOBIAN_SHIFT",
    "GAIN_SHIFT_MAX",
    "LawInputs",
    "ControlLaw",
    "LawFault",
    "OpenLoopLaw",
    "LocomotionLaw",
    "ReactionLaw",
    "JacobianLaw",
    "BUILTIN_LAWS",
    "balance_gain_bytes",
    "shr",
]

VELOCITY = "velocity"
POSITION = "position"
ONE_DEG_PER_TICK = 1 << 16           # velocity unit: 1/65536 degree per 20 ms tick
VELOCITY_MAX = (1 << 31) - 1         # a velocity must fit the PIC's signed 32-bit long
VELOCITY_MIN = -(1 << 31)

# Table 9: the wire's control types, by the name the CLI uses (protocol/wire.ControlType.label).
CONTROL_TYPES: dict[str, int] = {t.label: int(t) for t in ControlType}

PID_SHIFT = 4                # PID command u in 1/16 degree: gain byte K = K/16 (Q4.4)
JACOBIAN_SHIFT = 16          # v_q8 = (KP * J^T e) >> 16
GAIN_SHIFT_MAX = 15          # KD byte = the balance gain's binary exponent, 0..15

_U_MAX = POS_LIMIT_DEG << PID_SHIFT
_U_MIN = -POS_LIMIT_DEG << PID_SHIFT


class LawInputs:
    """What a board gives its law each tick (integers only; read-only by convention).

    - ``scu``: the board's address (1-8); ``has_foot``: whether it carries a force-sensing foot;
      ``signs``: the leg's servo-to-kinematic angle signs (``slave.LEG_SIGNS``; (1, 1, 1) off the legs).
    - ``servos``: the indices (0 foot lateral / hip roll, 1 foot front / hip pitch, 2 knee / hip
      yaw) of the servos under this law this tick.
    - ``measured``: the measured positions (whole degrees, filtered, PIC2).
    - ``reference``: the trajectory references of this tick (whole degrees, ``servoRequest``).
    - ``output``: the positions applied during the last tick (whole degrees).
    - ``cop_mm``: the foot's CoP low-passed by the board (whole mm, foot frame: x to the robot's
      right, y forward, table 12), or ``None`` when the foot is unloaded (or there is no foot).
    - ``cop_error_mm``: ``CoP_ref - cop_mm`` with the 1 mm dead band (table 10's ``e``), (0, 0)
      when unloaded; ``cop_ref_mm``: the CoP reference (the foot centre, (0, 0)).
    - ``forces``: the four force sensors, calibrated 7-bit counts (table 12 order: front-left,
      front-right, rear-left, rear-right); zeros off the legs.
    - ``gains``: per servo the raw gain bytes ``(KI, KP, KD)`` 0..255 from the Actuation packets.
    """

    __slots__ = ("scu", "has_foot", "signs", "servos", "measured", "reference", "output", "cop_mm",
                 "cop_error_mm", "cop_ref_mm", "forces", "gains")

    def __init__(self, scu: int = 0, has_foot: bool = False, signs: tuple[int, int, int] = (1, 1, 1)) -> None:
        self.scu = scu
        self.has_foot = has_foot
        self.signs = signs
        self.servos: tuple[int, ...] = ()
        self.measured: tuple[int, ...] = (0,) * N_SERVOS
        self.reference: tuple[int, ...] = (0,) * N_SERVOS
        self.output: tuple[int, ...] = (0,) * N_SERVOS
        self.cop_mm: tuple[int, int] | None = None
        self.cop_error_mm: tuple[int, int] = (0, 0)
        self.cop_ref_mm: tuple[int, int] = (0, 0)
        self.forces: tuple[int, ...] = (0, 0, 0, 0)
        self.gains: tuple[tuple[int, int, int], ...] = ((0, 0, 0),) * N_SERVOS

    def __repr__(self) -> str:
        return "LawInputs(" + ", ".join(f"{k}={getattr(self, k)!r}" for k in self.__slots__) + ")"


class ControlLaw:
    """Base class of a control law (see the module docstring for the contract).

    Class attributes: ``name`` (for messages), ``output`` (:data:`VELOCITY` or :data:`POSITION`),
    ``needs_foot``, ``cycles`` (PIC18 instruction cycles per call of :meth:`step`, an int or a
    method returning one; None: charged like the built-in law of its control type, and the run
    says so; humanoid_twin/cycles.py, docs/controllers.md). Override :meth:`step` and, for a
    law with state, :meth:`start`.
    """

    name: str = "law"
    output: str = VELOCITY
    needs_foot: bool = False
    cycles: int | None = None

    def start(self, servo: int, inputs: LawInputs) -> None:
        """Servo ``servo`` starts under this law (board reset, or its control type switched to
        this law's): ``inputs.output[servo]`` is the position it is applied now."""

    def step(self, inputs: LawInputs) -> Sequence[int]:
        """One tick: three ints, one per servo (velocities or positions, see ``output``)."""
        raise NotImplementedError


@dataclass(frozen=True)
class LawFault:
    """A law stopped by its board: when, where, which law, why."""

    t_us: int
    scu: int
    control_type: int
    law: str
    reason: str

    def __str__(self) -> str:
        name = next((k for k, v in CONTROL_TYPES.items() if v == self.control_type), str(self.control_type))
        return (f"control law {self.law} ({name}) stopped on SCU {self.scu} at t={self.t_us / 1e6:.3f} s: "
                f"{self.reason}; the board holds its servos")

    def as_dict(self) -> dict[str, Any]:
        """JSON form (the run summary's ``law_faults`` entries)."""
        return {"t_s": round(self.t_us / 1e6, 6), "scu": self.scu, "control_type": self.control_type,
                "law": self.law, "reason": self.reason}


def shr(v: int, n: int) -> int:
    """``v / 2^n`` truncated toward zero (C ``/`` by a power of two on a signed value)."""
    return v >> n if v >= 0 else -((-v) >> n)


def balance_gain_bytes(kp: int, kd: int) -> tuple[int, int]:
    """The gain of a balance law from a servo's KP and KD bytes: ``(KP, shift)`` with KP read as
    a signed char (-128..127: a negative gain moves the foot, not the mass centre; docs/balance.md)
    and ``shift`` the KD byte (0..:data:`GAIN_SHIFT_MAX`), the gain's binary exponent."""
    kp = from_s8(kp)
    if kd > GAIN_SHIFT_MAX:
        kd = GAIN_SHIFT_MAX
    return kp, kd


# ---------------------------------------------------------------------------------------------
# the four laws of table 9


class OpenLoopLaw(ControlLaw):
    """``openloopControl`` (NO_CONTROL, table 11): the requested position goes to the servo unchanged."""

    name = "openloop"
    cycles = LAW[0]
    output = POSITION

    def step(self, inputs: LawInputs) -> Sequence[int]:
        return inputs.reference


class LocomotionLaw(ControlLaw):
    """``locomotionControl`` (LOCOMOTION_CONTROL, table 11, fig. 8): incremental PID on the servo
    position, integers, gains Q4.4 (the command ``u`` in 1/16 degree, the error in whole degrees):
    ``u(k) = u(k-1) + KP (e(k)-e(k-1)) + KI e(k) + KD (e(k)-2e(k-1)+e(k-2))``, clamped to -90..90
    degrees; output ``(u + 8) >> 4``. :meth:`start` (``initController``): ``u`` = the position
    applied now (bumpless), the past errors taken equal to the first error seen."""

    name = ControlType.LOCOMOTION_CONTROL.label
    cycles = LAW[1]
    output = POSITION

    def __init__(self) -> None:
        self.u16 = [0] * N_SERVOS
        self.e1 = [0] * N_SERVOS
        self.e2 = [0] * N_SERVOS
        self.fresh = [True] * N_SERVOS

    def start(self, servo: int, inputs: LawInputs) -> None:
        self.u16[servo] = inputs.output[servo] << PID_SHIFT
        self.e1[servo] = 0
        self.e2[servo] = 0
        self.fresh[servo] = True

    def step(self, inputs: LawInputs) -> Sequence[int]:
        out = [0] * N_SERVOS
        ref = inputs.reference
        meas = inputs.measured
        gains = inputs.gains
        for i in inputs.servos:
            ki, kp, kd = gains[i]
            e = ref[i] - meas[i]
            if self.fresh[i]:
                self.e1[i] = self.e2[i] = e
                self.fresh[i] = False
            e1 = self.e1[i]
            e2 = self.e2[i]
            u = self.u16[i] + kp * (e - e1) + ki * e + kd * (e - 2 * e1 + e2)
            if u > _U_MAX:
                u = _U_MAX
            elif u < _U_MIN:
                u = _U_MIN
            self.u16[i] = u
            self.e2[i] = e1
            self.e1[i] = e
            out[i] = (u + 8) >> PID_SHIFT
        return out


class ReactionLaw(ControlLaw):
    """``reactionControl`` (REACTION_CONTROL, table 10): ``v_x = KPx e_x`` on the foot lateral joint
    (servo 0), ``v_y = KPy e_y`` on the foot front joint (servo 1); the knee follows its trajectory.
    ``e`` = ``inputs.cop_error_mm``; KP the signed KP byte, KD the gain's binary exponent
    (:func:`balance_gain_bytes`): ``KP/256`` degree per tick per mm, / 2^KD. The sign of each law
    is the sign of the joint's lever on the mass centre at the straight leg (``signs``): a
    positive gain moves the mass centre, and the CoP, toward the reference; a negative gain moves
    the foot (compliance). No action while the foot is unloaded."""

    name = ControlType.REACTION_CONTROL.label
    cycles = LAW[2]
    output = VELOCITY
    needs_foot = True

    def step(self, inputs: LawInputs) -> Sequence[int]:
        out = [0] * N_SERVOS
        if inputs.cop_mm is None:
            return out
        ex, ey = inputs.cop_error_mm
        signs = inputs.signs
        for i in inputs.servos:
            if i == 0:
                kp, shift = balance_gain_bytes(inputs.gains[0][1], inputs.gains[0][2])
                out[0] = shr((signs[0] * kp * ex) << 8, shift)
            elif i == 1:
                kp, shift = balance_gain_bytes(inputs.gains[1][1], inputs.gains[1][2])
                out[1] = shr((-signs[1] * kp * ey) << 8, shift)
        return out


class JacobianLaw(ControlLaw):
    """``JacobianControl`` (BALANCE_CONTROL, table 10): ``v_j = KP_j (J_1j e_x + J_2j e_y)`` for the
    foot lateral, foot front and knee joints, ``J`` from ``jacobianMatrix`` at the measured
    positions (DATA, micrometres per radian), ``e`` = ``inputs.cop_error_mm``, ``e_z = 0``;
    ``v = (KP * J^T e) >> 16`` in 1/256 degree per tick, / 2^KD. No action while unloaded."""

    name = ControlType.BALANCE_CONTROL.label
    cycles = LAW[3]
    output = VELOCITY
    needs_foot = True

    def __init__(self) -> None:
        self.last_jacobian: tuple | None = None

    def step(self, inputs: LawInputs) -> Sequence[int]:
        out = [0] * N_SERVOS
        if inputs.cop_mm is None:
            return out
        m = inputs.measured
        J = jacobianMatrix(m[0], m[1], m[2], inputs.signs)
        self.last_jacobian = J
        ex, ey = inputs.cop_error_mm
        j0 = J[0]
        j1 = J[1]
        for i in inputs.servos:
            kp, shift = balance_gain_bytes(inputs.gains[i][1], inputs.gains[i][2])
            out[i] = shr(kp * (j0[i] * ex + j1[i] * ey), JACOBIAN_SHIFT - 8 + shift)
        return out


LawFactory = Callable[[], ControlLaw]

BUILTIN_LAWS: dict[int, LawFactory] = {0: OpenLoopLaw, 1: LocomotionLaw, 2: ReactionLaw, 3: JacobianLaw}
