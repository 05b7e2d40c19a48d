"""Module SERVO of the Slave firmware (seed 000 section 3, tables 8-11).

Calibration of the position measurement and of the force sensors (``calibration``), the stored
reference of each servo (``servoRequest``), and the controllers called by ``controller`` (table
11): ``openloopControl`` (NO_CONTROL), ``locomotionControl`` (LOCOMOTION_CONTROL, incremental
PID, fig. 8), ``reactionControl`` (REACTION_CONTROL, proportional CoP law) and
``jacobianControl`` (BALANCE_CONTROL, Jacobian-transpose CoP law), table 10; the two balance laws
give joint *velocities*, turned into positions by ``applyVelocity`` with a velocity limiter.

Fixed-point scales (docs/firmware.md, "SERVO"; docs/balance.md): every gain is the raw CAN byte.
- PID: the command ``u`` is held in 1/16 degree, the error ``e`` in whole degrees, so a gain byte
  ``K`` is ``K/16`` (Q4.4): ``u16(k) = u16(k-1) + KP (e(k)-e(k-1)) + KI e(k) + KD (e(k)-2e(k-1)+e(k-2))``.
- Balance laws: ``e = CoP_ref - CoP`` in whole mm from the CoP low-passed once per tick
  (:data:`COP_FILTER_SHIFT`), zero within the dead band :data:`COP_DEAD_BAND_MM`. The KP byte is
  read as a signed char (a negative gain moves the foot toward the reference instead of the mass
  centre: the compliant foot of double support, docs/balance.md) and the KD byte, which the
  manual's balance laws do not use, is the gain's binary exponent (velocity / 2^KD).
  REACTION: ``v = KP * e`` in 1/256 degree per tick (``KP/256`` degree per tick per mm).
  BALANCE: ``v = (KP * (J^T e)) >> 16`` with ``J`` in micrometres per radian (at the straight
  leg ``J`` is 95.5 mm/rad, so the same byte acts 1.46 times as strongly as in REACTION).
- ``applyVelocity`` limits ``|v|`` to :data:`VELOCITY_LIMIT_Q8` (1 degree per tick = 50 deg/s)
  and accumulates it with 16 fractional bits: the balance offset added to the trajectory
  reference is ``round(acc / 65536)`` degrees, so slow velocities still move the int8 position.
"""

from __future__ import annotations

from collections.abc import Sequence

from humanoid_twin.hardware import (
    FORCE_CALIBRATION_VALUE,
    N_SERVOS,
    N_SPECIAL_SENSORS,
    POS_MAX_DEG,
    POS_MIN_DEG,
    POT_COUNTS_PER_DEG,
)
from humanoid_twin.slave.data import divround, jacobianMatrix
from humanoid_twin.slave.database import Actuators, Control

__all__ = [
    "NO_CONTROL",
    "LOCOMOTION_CONTROL",
    "REACTION_CONTROL",
    "BALANCE_CONTROL",
    "PID_SHIFT",
    "JACOBIAN_SHIFT",
    "VELOCITY_LIMIT_Q8",
    "COP_FILTER_SHIFT",
    "COP_DEAD_BAND_MM",
    "GAIN_SHIFT_MAX",
    "balance_gain",
    "CALIB_SETTLE_TICKS",
    "CALIB_SAMPLES",
    "calibration_b",
    "force_offset",
    "Calibration",
    "ServoControl",
]

# Table 9
NO_CONTROL = 0
LOCOMOTION_CONTROL = 1
REACTION_CONTROL = 2
BALANCE_CONTROL = 3

PID_SHIFT = 4                # u in 1/16 degree: gain byte K = K/16
JACOBIAN_SHIFT = 16          # v_q8 = (KP * J^T e) >> 16
VELOCITY_LIMIT_Q8 = 256      # applyVelocity limiter: 1 degree per tick (50 deg/s)
# Additions to the manual's balance laws (docs/balance.md, "Interpretations"):
COP_FILTER_SHIFT = 3         # CoP low-pass f += (CoP - f) >> 3: time constant 8 ticks (160 ms)
COP_DEAD_BAND_MM = 1         # |e| <= 1 mm (the CoP's resolution) gives no action
GAIN_SHIFT_MAX = 15          # KD byte = the balance gain's binary exponent, 0..15
_V_MAX16 = VELOCITY_LIMIT_Q8 << 8

CALIB_SETTLE_TICKS = 100     # "esperar dois segundos" = 100 PWM periods
CALIB_SAMPLES = 25           # "25 medidas (25 períodos de PWM)"

_U_MAX = POS_MAX_DEG << PID_SHIFT
_U_MIN = POS_MIN_DEG << PID_SHIFT


def balance_gain(control: Control) -> tuple[int, int]:
    """The gain of a balance law (REACTION, BALANCE) from a servo's gain bytes: ``(KP, shift)``
    with KP the KP byte read as a signed char (-128..127: a negative gain moves the foot, not
    the mass centre; docs/balance.md) and ``shift`` the KD byte (0..:data:`GAIN_SHIFT_MAX`),
    the gain's binary exponent: the law's velocity is divided by ``2**shift``. KD = 0 gives
    the scales of the module docstring."""
    kp = control.kp
    if kp > 127:
        kp -= 256
    shift = control.kd
    if shift > GAIN_SHIFT_MAX:
        shift = GAIN_SHIFT_MAX
    return kp, shift


def calibration_b(pos_master: int, adc_sum: int, n: int = CALIB_SAMPLES) -> int:
    """Step 6 of the servo calibration: ``b = pos_master + ADC_mean * m`` in quarter degrees
    (``m`` = 1/4 degree per count), with ``ADC_mean`` = the rounded integer mean of ``n``
    samples summing to ``adc_sum``."""
    if n <= 0:
        raise ValueError(f"calibration needs at least one sample, got n={n!r}")
    return POT_COUNTS_PER_DEG * pos_master + divround(adc_sum, n)


def force_offset(sum7: int, n: int = CALIB_SAMPLES) -> int:
    """Force sensor calibration: ``offset(7 bit) = 128 - Sensor_original(7 bit)``, with
    ``Sensor_original`` the rounded integer mean of ``n`` 7-bit samples summing to ``sum7``."""
    if n <= 0:
        raise ValueError(f"calibration needs at least one sample, got n={n!r}")
    return FORCE_CALIBRATION_VALUE - divround(sum7, n)


class Calibration:
    """``calibration`` (table 8) as a per-tick state machine, the manual's two lists literally.

    ``WAIT`` for the first actuation with PWM on (step 1); ``start(pos_master)`` is step 2 (the
    caller applies the positions with ``servoActuation``); then :meth:`step` is called once per
    tick with the measurements of the PWM period that just ended: 100 ticks of settling (step 3),
    25 ticks of samples (step 4), then the means, ``b`` and the force offsets (steps 5-6), and the
    state becomes ``DONE`` (the caller switches the filters on, step 7).
    """

    WAIT = 0
    SETTLE = 1
    SAMPLE = 2
    DONE = 3

    __slots__ = ("state", "ticks", "pos_master", "adc_sum", "force_sum", "b_q", "offsets", "runs")

    def __init__(self) -> None:
        self.state = Calibration.WAIT
        self.ticks = 0
        self.pos_master: list[int] = [0] * N_SERVOS
        self.adc_sum: list[int] = [0] * N_SERVOS
        self.force_sum: list[int] = [0] * N_SPECIAL_SENSORS
        self.b_q: list[int] = [0] * N_SERVOS                 # result, quarter degrees
        self.offsets: list[int] = [0] * N_SPECIAL_SENSORS    # result, 7-bit offsets
        self.runs = 0                                        # calibrations completed

    def reset(self) -> None:
        """Back to step 1 (waiting for an actuation with PWM on)."""
        self.state = Calibration.WAIT
        self.ticks = 0

    def start(self, pos_master: Sequence[int]) -> None:
        """Step 2: the requested positions are latched (the caller applies them directly)."""
        for i in range(N_SERVOS):
            p = int(pos_master[i])
            self.pos_master[i] = POS_MAX_DEG if p > POS_MAX_DEG else POS_MIN_DEG if p < POS_MIN_DEG else p
            self.adc_sum[i] = 0
        for k in range(N_SPECIAL_SENSORS):
            self.force_sum[k] = 0
        self.ticks = 0
        self.state = Calibration.SETTLE

    def step(self, adc: Sequence[int], force7: Sequence[int]) -> bool:
        """One tick of steps 3-6 with the raw pot ADC counts and the 7-bit force values of the
        period that just ended. Returns True on the tick the calibration completes."""
        if self.state == Calibration.SETTLE:
            self.ticks += 1
            if self.ticks >= CALIB_SETTLE_TICKS:
                self.state = Calibration.SAMPLE
                self.ticks = 0
            return False
        if self.state != Calibration.SAMPLE:
            return False
        for i in range(N_SERVOS):
            self.adc_sum[i] += adc[i]
        for k in range(N_SPECIAL_SENSORS):
            self.force_sum[k] += force7[k]
        self.ticks += 1
        if self.ticks < CALIB_SAMPLES:
            return False
        for i in range(N_SERVOS):
            self.b_q[i] = calibration_b(self.pos_master[i], self.adc_sum[i], CALIB_SAMPLES)
        for k in range(N_SPECIAL_SENSORS):
            self.offsets[k] = force_offset(self.force_sum[k], CALIB_SAMPLES)
        self.state = Calibration.DONE
        self.runs += 1
        return True

    @property
    def done(self) -> bool:
        """Whether the last calibration completed (Status bit 6)."""
        return self.state == Calibration.DONE


class ServoControl:
    """The SERVO module of one Slave: references, controller state and outputs of 3 servos.

    ``has_foot``: whether the board carries a force-sensing foot (leg boards 1 and 2). On a board
    without one, and for the knee under REACTION_CONTROL (the law acts on the two foot joints
    only), REACTION and BALANCE behave as NO_CONTROL: the servo follows its trajectory
    (docs/firmware.md). ``signs``: the servo-to-kinematic angle signs of the leg
    (``data.jacobianMatrix``), which also give the direction of the REACTION law.
    """

    __slots__ = (
        "actuators",
        "has_foot",
        "signs",
        "reference",
        "output",
        "types",
        "u16",
        "e1",
        "e2",
        "fresh",
        "acc",
        "cop_ref",
        "cop_f",
        "cop_primed",
        "last_v",
        "last_jacobian",
    )

    def __init__(self, actuators: Actuators, has_foot: bool, signs: Sequence[int] = (1, 1, 1)) -> None:
        self.actuators = actuators
        self.has_foot = has_foot
        self.signs: tuple[int, int, int] = (int(signs[0]), int(signs[1]), int(signs[2]))
        if any(s not in (-1, 1) for s in self.signs):
            raise ValueError(f"leg signs must be +1 or -1, got {signs!r}")
        self.reference: list[int] = [0] * N_SERVOS   # servoRequest (trajectory output)
        self.output: list[int] = [0] * N_SERVOS      # position for servoActuation
        self.types: list[int] = [NO_CONTROL] * N_SERVOS
        self.u16: list[int] = [0] * N_SERVOS         # PID command, 1/16 degree
        self.e1: list[int] = [0] * N_SERVOS
        self.e2: list[int] = [0] * N_SERVOS
        self.fresh: list[bool] = [True] * N_SERVOS
        self.acc: list[int] = [0] * N_SERVOS         # balance offset accumulator, 1/65536 degree
        self.cop_ref: list[int] = [0, 0]             # CoP reference (mm, foot frame): foot centre
        self.cop_f: list[int] = [0, 0]               # filtered CoP, 1/256 mm
        self.cop_primed = False
        self.last_v: list[int] = [0] * N_SERVOS      # last velocity applied (Q8), for recording
        self.last_jacobian: tuple | None = None

    # -- references --------------------------------------------------------------------------
    def reset(self, positions: Sequence[int]) -> None:
        """Every servo at rest at ``positions`` (after calibration): references, outputs and
        controller state."""
        for i in range(N_SERVOS):
            p = int(positions[i])
            self.reference[i] = p
            self.output[i] = p
            self.acc[i] = 0
            self.last_v[i] = 0
            self.initController(i)

    def servoRequest(self, i: int, position: int) -> None:
        """``servoRequest`` (table 8): store the position servo ``i`` must reach (used by the
        controllers, not applied directly)."""
        self.reference[i] = position

    def newTrajectory(self, i: int) -> None:
        """A new trajectory of servo ``i`` starts from its current output, which already holds
        the balance offset: the offset accumulator restarts from zero."""
        self.acc[i] = 0

    # -- controllers -------------------------------------------------------------------------
    def initController(self, i: int) -> None:
        """``initController`` (table 8): the PID state of servo ``i``: command = the position
        applied now (bumpless), past errors taken equal to the first error seen."""
        self.u16[i] = self.output[i] << PID_SHIFT
        self.e1[i] = 0
        self.e2[i] = 0
        self.fresh[i] = True

    def controller(
        self, measured: Sequence[int], cop_x: int, cop_y: int, loaded: bool, types: Sequence[int]
    ) -> None:
        """``controller`` (table 8): run each servo's control law (table 11) for this tick;
        the positions to apply are left in ``output``.

        ``measured``: positions (whole degrees), ``cop_x/cop_y``: the foot's CoP (mm) and
        ``loaded`` whether it is meaningful, ``types``: the control type of each servo. On a
        leg board the CoP is filtered every tick (:meth:`filterCoP`), whatever the types, so a
        balance law switched on later starts from a settled value.
        """
        ex = ey = 0
        if self.has_foot:
            self.filterCoP(cop_x, cop_y, loaded)
            if loaded:
                ex, ey = self.copError()
        jacobian_done = False
        for i in range(N_SERVOS):
            t = types[i]
            if t != self.types[i]:
                self.types[i] = t
                self.acc[i] = 0
                if t == LOCOMOTION_CONTROL:
                    self.initController(i)
            if t == NO_CONTROL:
                self.openloopControl(i)
            elif t == LOCOMOTION_CONTROL:
                self.locomotionControl(i, measured[i])
            elif not self.has_foot:
                self.openloopControl(i)
            elif t == REACTION_CONTROL:
                if i < 2:
                    self.reactionControl(i, ex, ey, loaded)
                else:
                    self.openloopControl(i)
            else:  # BALANCE_CONTROL
                if not jacobian_done:
                    self.jacobianControl(measured, ex, ey, loaded, types)
                    jacobian_done = True

    def openloopControl(self, i: int) -> None:
        """``openloopControl`` (table 11): the requested position goes to the servo unchanged."""
        self.output[i] = self.reference[i]

    def locomotionControl(self, i: int, measured: int) -> None:
        """``locomotionControl`` (table 11, fig. 8): incremental PID on the servo position,
        integers, gains Q4.4 (see the module docstring)."""
        c = self.actuators.control[i]
        e = self.reference[i] - measured
        if self.fresh[i]:
            self.e1[i] = self.e2[i] = e
            self.fresh[i] = False
        e1 = self.e1[i]
        e2 = self.e2[i]
        u = self.u16[i] + c.kp * (e - e1) + c.ki * e + c.kd * (e - 2 * e1 + e2)
        if u > _U_MAX:
            u = _U_MAX
        elif u < _U_MIN:
            u = _U_MIN
        self.u16[i] = u
        self.e2[i] = e1
        self.e1[i] = e
        self.output[i] = (u + 8) >> PID_SHIFT

    def filterCoP(self, cop_x: int, cop_y: int, loaded: bool) -> None:
        """The CoP seen by the balance laws: ``calcCoP``'s value low-passed once per tick,
        ``f += (CoP - f) >> COP_FILTER_SHIFT`` in 1/256 mm (docs/balance.md: the body rocking
        on the servos' stiffness at ~3 Hz must not reach the integrating laws). The filter is
        primed with the first loaded sample and forgotten while the foot is unloaded."""
        if not loaded:
            self.cop_primed = False
            return
        x8 = cop_x << 8
        y8 = cop_y << 8
        if not self.cop_primed:
            self.cop_f[0] = x8
            self.cop_f[1] = y8
            self.cop_primed = True
            return
        self.cop_f[0] += (x8 - self.cop_f[0]) >> COP_FILTER_SHIFT
        self.cop_f[1] += (y8 - self.cop_f[1]) >> COP_FILTER_SHIFT

    def copError(self) -> tuple[int, int]:
        """``e = CoP_ref - CoP_med`` in whole millimetres from the filtered CoP, with the dead
        band: an error within +-:data:`COP_DEAD_BAND_MM` is zero."""
        ex = self.cop_ref[0] - ((self.cop_f[0] + 128) >> 8)
        ey = self.cop_ref[1] - ((self.cop_f[1] + 128) >> 8)
        if -COP_DEAD_BAND_MM <= ex <= COP_DEAD_BAND_MM:
            ex = 0
        if -COP_DEAD_BAND_MM <= ey <= COP_DEAD_BAND_MM:
            ey = 0
        return ex, ey

    def reactionControl(self, i: int, ex: int, ey: int, loaded: bool) -> None:
        """``reactionControl`` (table 10): ``v_x = KPx e_x`` on the foot lateral joint (servo
        0), ``v_y = KPy e_y`` on the foot front joint (servo 1), ``e = CoP_ref - CoP_med`` in
        mm (:meth:`copError`); KPx, KPy = the KP bytes of servos 0 and 1, read as signed
        (:func:`balance_gain`, with KD the gain's binary exponent). The sign of each law is the
        sign of the joint's lever on the mass centre at the straight leg (``signs``), so that a
        positive gain moves the mass centre, and the CoP, toward the reference; a negative gain
        moves the foot instead (compliance). No action while the foot is unloaded."""
        if not loaded:
            self._apply16(i, 0)
            return
        kp, shift = balance_gain(self.actuators.control[i])
        if i == 0:
            v = self.signs[0] * kp * ex
        else:
            v = -self.signs[1] * kp * ey
        # velocity in 1/65536 degree per tick: KP/256 degree per tick per mm, / 2^KD
        self._apply16(i, _shr(v << 8, shift))

    def jacobianControl(
        self, measured: Sequence[int], ex: int, ey: int, loaded: bool, types: Sequence[int]
    ) -> None:
        """``JacobianControl`` (table 10): ``v_j = KP_j (J_1j e_x + J_2j e_y)`` for the foot
        lateral, foot front and knee joints, ``J`` from ``jacobianMatrix`` at the measured
        positions (DATA), ``e = CoP_ref - CoP_med`` (mm, :meth:`copError`), ``e_z = 0``.
        Applied to the servos whose type is BALANCE_CONTROL, with each servo's signed gain
        (:func:`balance_gain`); no action while the foot is unloaded."""
        if not loaded:
            for i in range(N_SERVOS):
                if types[i] == BALANCE_CONTROL:
                    self._apply16(i, 0)
            return
        J = jacobianMatrix(measured[0], measured[1], measured[2], self.signs)
        self.last_jacobian = J
        ctrl = self.actuators.control
        j0 = J[0]
        j1 = J[1]
        for i in range(N_SERVOS):
            if types[i] == BALANCE_CONTROL:
                kp, shift = balance_gain(ctrl[i])
                # (KP * J^T e) >> 16 in 1/256 degree per tick, i.e. >> 8 in 1/65536
                self._apply16(i, _shr(kp * (j0[i] * ex + j1[i] * ey), JACOBIAN_SHIFT - 8 + shift))

    def applyVelocity(self, i: int, v_q8: int) -> None:
        """``applyVelocity``: a velocity (1/256 degree per tick) becomes a position increment
        (see :meth:`_apply16`, which the balance laws call with 8 more fractional bits)."""
        self._apply16(i, v_q8 << 8)

    def _apply16(self, i: int, v: int) -> None:
        """``applyVelocity`` proper, velocity ``v`` in 1/65536 degree per tick. The velocity
        limiter caps ``|v|`` at :data:`VELOCITY_LIMIT_Q8` / 256 degree per tick; the 16-bit
        fraction accumulator keeps slow velocities; the offset is held so that reference +
        offset stays within -90..90 degrees (no wind-up)."""
        if v > _V_MAX16:
            v = _V_MAX16
        elif v < -_V_MAX16:
            v = -_V_MAX16
        self.last_v[i] = v >> 8 if v >= 0 else -((-v) >> 8)
        ref = self.reference[i]
        acc = self.acc[i] + v
        hi = (POS_MAX_DEG - ref) << 16
        lo = (POS_MIN_DEG - ref) << 16
        if acc > hi:
            acc = hi
        elif acc < lo:
            acc = lo
        self.acc[i] = acc
        self.output[i] = ref + ((acc + 32768) >> 16)


def _shr(v: int, n: int) -> int:
    """``v / 2^n`` truncated toward zero (C ``/`` by a power of two on a signed value)."""
    return v >> n if v >= 0 else -((-v) >> n)
