"""Module SERVO of the Slave firmware (seed 000 section 3, tables 8-11).

Calibration of the position measurement and of the force sensors (``calibration``), the stored
reference of each servo (``servoRequest``), and ``controller`` (table 11), which runs each
servo's control law. The laws are plug-ins (``slave/laws.py``, docs/controllers.md): one per
control type of table 9, by default ``openloopControl`` (NO_CONTROL), ``locomotionControl``
(LOCOMOTION_CONTROL, incremental PID, fig. 8), ``reactionControl`` (REACTION_CONTROL,
proportional CoP law) and ``jacobianControl`` (BALANCE_CONTROL, Jacobian-transpose CoP law),
table 10. Position laws give the position to apply; velocity laws (the balance laws) give joint
*velocities*, turned into positions by ``applyVelocity`` with a velocity limiter. SERVO keeps
what is the board's, whatever the law: the CoP filter and dead band, ``applyVelocity``, and the
stop of a law that fails (it holds the servos and reports a ``LawFault``).

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
from typing import TYPE_CHECKING, Any

from humanoid_twin.containment import describe, law_output, user_fault
from humanoid_twin.cycles import law_cycles
from humanoid_twin.hardware import FORCE_CALIBRATION_VALUE, N_SERVOS, N_SPECIAL_SENSORS, POT_COUNTS_PER_DEG
from humanoid_twin.protocol.wire import POS_LIMIT_DEG, ControlType
from humanoid_twin.slave.data import divround
from humanoid_twin.slave.database import Actuators, Control
from humanoid_twin.slave.laws import (
    BUILTIN_LAWS,
    GAIN_SHIFT_MAX,
    JACOBIAN_SHIFT,
    ONE_DEG_PER_TICK,
    PID_SHIFT,
    POSITION,
    VELOCITY_MAX,
    VELOCITY_MIN,
    ControlLaw,
    LawFault,
    LawInputs,
    balance_gain_bytes,
)
from humanoid_twin.slave.pic2 import limitPosition

if TYPE_CHECKING:
    from humanoid_twin.clock import Clock

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

# Table 9 (protocol.wire.ControlType), as the plain ints the firmware compares
NO_CONTROL = int(ControlType.NO_CONTROL)
LOCOMOTION_CONTROL = int(ControlType.LOCOMOTION_CONTROL)
REACTION_CONTROL = int(ControlType.REACTION_CONTROL)
BALANCE_CONTROL = int(ControlType.BALANCE_CONTROL)

VELOCITY_LIMIT_Q8 = 256      # applyVelocity limiter: 1 degree per tick (50 deg/s)
# Additions to the manual's balance laws (docs/balance.md, "Interpretations"):
COP_FILTER_SHIFT = 3         # CoP low-pass f += (CoP - f) >> 3: time constant 8 ticks (160 ms)
COP_DEAD_BAND_MM = 1         # |e| <= 1 mm (the CoP's resolution) gives no action
_V_MAX16 = VELOCITY_LIMIT_Q8 << 8
assert _V_MAX16 == ONE_DEG_PER_TICK

# the servos under one law in a tick (``controller``), by the bit mask of their indices
_SERVO_SETS: tuple[tuple[int, ...], ...] = tuple(
    tuple(j for j in range(N_SERVOS) if mask >> j & 1) for mask in range(1 << N_SERVOS))

CALIB_SETTLE_TICKS = 100     # "esperar dois segundos" = 100 PWM periods
CALIB_SAMPLES = 25           # "25 medidas (25 períodos de PWM)"


def balance_gain(control: Control) -> tuple[int, int]:
    """The gain of a balance law (REACTION, BALANCE) from a servo's gain bytes: ``(KP, shift)``
    with KP the KP byte read as a signed char (-128..127: a negative gain moves the foot, not
    the mass centre; docs/balance.md) and ``shift`` the KD byte (0..:data:`GAIN_SHIFT_MAX`),
    the gain's binary exponent: the law's velocity is divided by ``2**shift``. KD = 0 gives
    the scales of the module docstring (``laws.balance_gain_bytes``)."""
    return balance_gain_bytes(control.kp, control.kd)


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


def _plain_output(values: Any, servos: Sequence[int], lo: int, hi: int) -> tuple[int, ...] | None:
    """What ``law_output`` returns for a plain good output (a ``list`` or ``tuple`` of
    :data:`N_SERVOS` values, ``int`` s within ``lo..hi`` for ``servos``): the values as a tuple;
    None for anything else, which ``law_output`` then judges (its guards and reasons), also when
    ``servos`` (the law's inputs, which a law may replace) is not indices 0..2. Nothing here can
    run a law's code: the built-in list and tuple, exact ints."""
    kind = type(values)
    if (kind is not list and kind is not tuple) or len(values) != N_SERVOS:
        return None
    out = [0] * N_SERVOS
    for j in servos:
        if type(j) is not int or not 0 <= j < N_SERVOS:    # inp.servos is the law's object too
            return None
        v = values[j]
        if type(v) is not int or not lo <= v <= hi:
            return None
        out[j] = v
    return tuple(out)


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
            self.pos_master[i] = limitPosition(p)
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
    """The SERVO module of one Slave: references, control laws and outputs of 3 servos.

    ``has_foot``: whether the board carries a force-sensing foot (leg boards 1 and 2). On a board
    without one, a law with ``needs_foot`` (REACTION, BALANCE) behaves as NO_CONTROL: the servo
    follows its trajectory (docs/firmware.md); REACTION acts on the two foot joints only (the knee
    follows its trajectory). ``signs``: the servo-to-kinematic angle signs of the leg
    (``data.jacobianMatrix``), which also give the direction of the REACTION law. ``scu`` and
    ``clock``: the board's address and clock, for the :class:`~humanoid_twin.slave.laws.LawFault`
    of a law that fails. The laws: :meth:`law`, :meth:`set_law` (``slave/laws.py``).
    """

    __slots__ = (
        "actuators",
        "has_foot",
        "signs",
        "scu",
        "clock",
        "reference",
        "output",
        "types",
        "acc",
        "cop_ref",
        "cop_f",
        "cop_primed",
        "last_v",
        "laws",
        "inputs",
        "law_fault",
        "_stopped",
        "law_cost",
        "law_cycles_tick",
    )

    def __init__(self, actuators: Actuators, has_foot: bool, signs: Sequence[int] = (1, 1, 1),
                 scu: int = 0, clock: Clock | None = None) -> None:
        self.actuators = actuators
        self.has_foot = has_foot
        self.signs: tuple[int, int, int] = (int(signs[0]), int(signs[1]), int(signs[2]))
        if any(s not in (-1, 1) for s in self.signs):
            raise ValueError(f"leg signs must be +1 or -1, got {signs!r}")
        self.scu = scu
        self.clock = clock
        self.reference: list[int] = [0] * N_SERVOS   # servoRequest (trajectory output)
        self.output: list[int] = [0] * N_SERVOS      # position for servoActuation
        self.types: list[int] = [NO_CONTROL] * N_SERVOS
        self.acc: list[int] = [0] * N_SERVOS         # balance offset accumulator, 1/65536 degree
        self.cop_ref: list[int] = [0, 0]             # CoP reference (mm, foot frame): foot centre
        self.cop_f: list[int] = [0, 0]               # filtered CoP, 1/256 mm
        self.cop_primed = False
        self.last_v: list[int] = [0] * N_SERVOS      # last velocity applied (Q8), for recording
        # one instance of each control type's law on this board (table 9 order)
        self.laws: dict[int, ControlLaw] = {t: make() for t, make in BUILTIN_LAWS.items()}
        # each type's law's cycles per call (humanoid_twin/cycles.py) and the cycles this tick
        self.law_cost: list[int] = [law_cycles(self.laws[t], t)[0] for t in range(len(BUILTIN_LAWS))]
        self.law_cycles_tick = 0
        self.inputs = LawInputs(scu, has_foot, self.signs)
        self.law_fault: LawFault | None = None       # the first law stopped on this board (kept)
        self._stopped: set[int] = set()               # control types whose law was stopped

    # -- laws --------------------------------------------------------------------------------
    def law(self, ctype: int) -> ControlLaw:
        """The law run for control type ``ctype`` (0-3) on this board."""
        return self.laws[ctype if ctype in self.laws else BALANCE_CONTROL]

    def set_law(self, ctype: int, law: ControlLaw, cycles: int | None = None) -> None:
        """Run ``law`` for control type ``ctype`` (0-3) from the next tick; servos already on
        that type start under it now (:meth:`ControlLaw.start`). ``cycles``: its cost per call,
        already asked and checked (``controllers.install_laws``); None: asked here (``law_cycles``)."""
        if ctype not in BUILTIN_LAWS:
            raise ValueError(f"control type must be 0..3 (table 9), got {ctype!r}")
        self.law_cost[ctype] = law_cycles(law, ctype)[0] if cycles is None else cycles
        self.laws[ctype] = law
        self._stopped.discard(ctype)
        self._fill_inputs(None)
        for i in range(N_SERVOS):
            if self.types[i] == ctype:
                law.start(i, self.inputs)

    @property
    def stopped_types(self) -> frozenset[int]:
        """Control types whose law this board stopped (it holds those servos until the next
        calibration, which starts every law again)."""
        return frozenset(self._stopped)

    @property
    def law_stopped(self) -> bool:
        """Whether a law is stopped now (Sensors 2 SFlags bit 2: the supervisor's ``law`` fault)."""
        return bool(self._stopped)

    # -- references --------------------------------------------------------------------------
    def reset(self, positions: Sequence[int]) -> None:
        """Every servo at rest at ``positions`` (after calibration): references, outputs and
        controller state (every law starts every servo: ``initController``; a stopped law
        runs again)."""
        self._stopped.clear()
        for i in range(N_SERVOS):
            p = int(positions[i])
            self.reference[i] = p
            self.output[i] = p
            self.acc[i] = 0
            self.last_v[i] = 0
        self._fill_inputs(None)
        for law in self.laws.values():
            for i in range(N_SERVOS):
                self._start(law, i)

    def servoRequest(self, i: int, position: int) -> None:
        """``servoRequest`` (table 8): store the position servo ``i`` must reach (used by the
        controllers, not applied directly)."""
        self.reference[i] = position

    def newTrajectory(self, i: int) -> None:
        """A new trajectory of servo ``i`` starts from its current output, which already holds
        the balance offset: the offset accumulator restarts from zero."""
        self.acc[i] = 0

    # -- controllers -------------------------------------------------------------------------
    def controller(
        self, measured: Sequence[int], cop_x: int, cop_y: int, loaded: bool, types: Sequence[int],
        forces: Sequence[int] | None = None,
    ) -> None:
        """``controller`` (table 8): run each servo's control law (table 11) for this tick;
        the positions to apply are left in ``output``.

        ``measured``: positions (whole degrees), ``cop_x/cop_y``: the foot's CoP (mm) and
        ``loaded`` whether it is meaningful, ``types``: the control type of each servo,
        ``forces``: the 7-bit force values (for the laws' inputs). On a leg board the CoP is
        filtered every tick (:meth:`filterCoP`), whatever the types, so a balance law switched
        on later starts from a settled value. Each law in use runs once, for its servos.
        """
        loaded = bool(loaded) and self.has_foot
        if self.has_foot:
            self.filterCoP(cop_x, cop_y, loaded)
        inp = self._fill_inputs(measured, loaded, forces)
        mine = self.types
        for i in range(N_SERVOS):
            t = types[i]
            if t != mine[i]:
                mine[i] = t
                self.acc[i] = 0
                self._start(self.law(t), i)
        done = 0
        self.law_cycles_tick = 0
        for i in range(N_SERVOS):
            t = mine[i]
            if done >> i & 1:
                continue
            mask = 0
            for j in range(i, N_SERVOS):
                if mine[j] == t:
                    mask |= 1 << j
            done |= mask
            servos = _SERVO_SETS[mask]
            law = self.law(t)
            if law.needs_foot and not self.has_foot:
                for j in servos:
                    self.output[j] = self.reference[j]
                continue
            if t in self._stopped:
                continue                        # stopped: the servos hold their last output
            inp.servos = servos
            self.law_cycles_tick += self.law_cost[t if t in self.laws else BALANCE_CONTROL]
            values = self._run(law, t, inp)
            if values is None:
                continue
            if law.output == POSITION:
                for j in servos:
                    self.output[j] = values[j]
            else:
                for j in servos:
                    self._apply16(j, values[j])

    def _start(self, law: ControlLaw, i: int) -> None:
        try:
            law.start(i, self.inputs)
        except BaseException as exc:   # a user's law: any failure stops it, named (containment.py)
            if not user_fault(exc):
                raise
            self._stop(law, self._type_of(law), f"start({i}) raised {describe(exc)}")

    def _type_of(self, law: ControlLaw) -> int:
        return next((t for t, x in self.laws.items() if x is law), BALANCE_CONTROL)

    def _run(self, law: ControlLaw, t: int, inp: LawInputs) -> Sequence[int] | None:
        """One step of ``law``; None (and the law stopped) if it raised or returned bad values
        (judged inside the guard, humanoid_twin/containment.py)."""
        try:
            values = law.step(inp)
        except BaseException as exc:   # a user's law: any failure stops it, named
            if not user_fault(exc):
                raise
            self._stop(law, t, f"step raised {describe(exc)}")
            return None
        position = law.output == POSITION
        lo, hi = (-POS_LIMIT_DEG, POS_LIMIT_DEG) if position else (VELOCITY_MIN, VELOCITY_MAX)
        checked = _plain_output(values, inp.servos, lo, hi)
        if checked is not None:
            return checked
        what = "position (degrees)" if position else "velocity (1/65536 degree per tick)"
        checked, why = law_output(values, inp.servos, N_SERVOS, lo, hi, what)
        if why is not None:
            self._stop(law, t, why)
            return None
        return checked

    def _stop(self, law: ControlLaw, t: int, reason: str) -> None:
        """Stop the law of control type ``t``: its servos hold their last output from now on."""
        self._stopped.add(t)
        cls = type(law)
        name = f"{cls.__module__}:{cls.__qualname__}"
        if self.law_fault is None:
            now = self.clock.now_us if self.clock is not None else 0
            self.law_fault = LawFault(now, self.scu, t, name, reason)

    def _fill_inputs(self, measured: Sequence[int] | None, loaded: bool = False,
                     forces: Sequence[int] | None = None) -> LawInputs:
        inp = self.inputs
        if measured is not None:
            inp.measured = tuple(measured)
        inp.reference = tuple(self.reference)
        inp.output = tuple(self.output)
        if loaded:
            f0, f1 = self.cop_f
            inp.cop_mm = ((f0 + 128) >> 8, (f1 + 128) >> 8)
            inp.cop_error_mm = self.copError()
        else:
            inp.cop_mm = None
            inp.cop_error_mm = (0, 0)
        inp.cop_ref_mm = (self.cop_ref[0], self.cop_ref[1])
        if forces is not None:
            inp.forces = tuple(forces)
        c0, c1, c2 = self.actuators.control
        inp.gains = ((c0.ki, c0.kp, c0.kd), (c1.ki, c1.kp, c1.kd), (c2.ki, c2.kp, c2.kd))
        return inp

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
        f0, f1 = self.cop_f
        self.cop_f[0] = f0 + ((x8 - f0) >> COP_FILTER_SHIFT)
        self.cop_f[1] = f1 + ((y8 - f1) >> COP_FILTER_SHIFT)

    def copError(self) -> tuple[int, int]:
        """``e = CoP_ref - CoP_med`` in whole millimetres from the filtered CoP, with the dead
        band: an error within +-:data:`COP_DEAD_BAND_MM` is zero."""
        f0, f1 = self.cop_f
        ex = self.cop_ref[0] - ((f0 + 128) >> 8)
        ey = self.cop_ref[1] - ((f1 + 128) >> 8)
        if -COP_DEAD_BAND_MM <= ex <= COP_DEAD_BAND_MM:
            ex = 0
        if -COP_DEAD_BAND_MM <= ey <= COP_DEAD_BAND_MM:
            ey = 0
        return ex, ey

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
        hi = (POS_LIMIT_DEG - ref) << 16
        lo = (-POS_LIMIT_DEG - ref) << 16
        if acc > hi:
            acc = hi
        elif acc < lo:
            acc = lo
        self.acc[i] = acc
        self.output[i] = ref + ((acc + 32768) >> 16)
