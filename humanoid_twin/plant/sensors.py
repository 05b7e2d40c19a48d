"""The Slave boards' sensor electronics on the plant's state: servo potentiometers, current sense
and foot force sensors as the boards' ADCs read them (PIC2 ``updateServoMeasures`` and
``sampleExtraSensors`` inputs).

Part of the compiled core (sensors.pxd). :class:`SensorFrontEnd` does the per-tick arithmetic on
MuJoCo's arrays through C memoryviews instead of one numpy scalar per value: the plant hands over
its ``qpos``, ``qvel``, ``actuator_force`` and ``sensordata`` arrays once, and their memory is
MjData's for the plant's whole life. (Interpreted, each value read is turned into a Python
float at once, as the plant did before: numpy scalars are slower and would leak into results.)
:class:`BoardIO` is the base class of :class:`~humanoid_twin.plant.plant.Plant`: what the boards
call every tick (``read_servos``, ``read_force_adc``, ``read_imu_adc``), each after the physics
sync of its own base class (plant/stepping.py), so a board's read is one C call into the plant.
The models are documented on those methods; the rest of the plant is Python (plant/plant.py).
"""

from __future__ import annotations

import math
from array import array
from typing import Any

from humanoid_twin import hardware
from humanoid_twin.plant import constants as C  # noqa: N812
from humanoid_twin.plant.stepping import PhysicsTime, PlantError, PlantInputError
from humanoid_twin.protocol.wire import check_scu

try:        # Cython's pure-Python mode: True in the compiled core (as in humanoid_twin/clock.py)
    import cython
    _COMPILED = cython.compiled
except ImportError:
    _COMPILED = False

__all__ = ["BoardIO", "SensorFrontEnd", "COUNTS_PER_N", "round_half_even", "PlantError", "PlantInputError"]

COUNTS_PER_N = 1.0 / hardware.FORCE_N_PER_COUNT
_DEG = hardware.DEG_PER_RAD         # the same values as C doubles in the compiled core
_COUNTS = COUNTS_PER_N
_POT_COUNTS_PER_DEG = hardware.POT_COUNTS_PER_DEG
_POT_ADC_MAX = hardware.POT_ADC_MAX
_CURRENT_FULL_US = hardware.CURRENT_PULSE_FULL_US
_CURRENT_IDLE_US = C.CURRENT_IDLE_US
_FORCE_ADC_MAX = hardware.FORCE_ADC_MAX
_IMU_SCU = hardware.IMU_SCU
_NOISE_BLOCK = 8192                 # standard noise draws taken from a stream at a time


def _check_scu(scu: int) -> None:
    check_scu(scu, error=PlantInputError)


def round_half_even(x: float) -> int:
    """``round(x)`` as Python does it (to nearest, ties to even), on C doubles in the compiled core
    (the builtin costs a Python call there; interpreted, the callers use the builtin itself).
    Below ``2**52`` ``a - int(a)`` is exact; beyond, and for inf and NaN, the builtin decides."""
    a = -x if x < 0.0 else x
    if not a < 4503599627370496.0:       # 2**52, inf, NaN: the builtin (its value or its error)
        return round(x)
    r = int(a)
    d = a - r
    if d > 0.5 or (d == 0.5 and r & 1):
        r += 1
    return -r if x < 0.0 else r


class SensorFrontEnd:
    """``SensorFrontEnd(qpos, qvel, actuator_force, sensordata)``: MjData's arrays (1-D float64)."""

    def __init__(self, qpos: Any, qvel: Any, actuator_force: Any, sensordata: Any) -> None:
        self._qpos = qpos
        self._qvel = qvel
        self._force = actuator_force
        self._sensordata = sensordata
        n = len(sensordata)
        # each force sensor's counts per newton, zero offset (counts) and unloaded reading, by its
        # sensordata address: the named parameters fsr.SITE.gain / offset_counts
        # (set_force_calibration; by default COUNTS_PER_N, 0, 0: the readings of every other day)
        self._fscale = array("d", [_COUNTS]) * n
        self._foffset = array("d", [0.0]) * n
        self._fzero = array("q", [0]) * n
        self._has_offset = False

    def set_force_calibration(self, adr: int, gain: float, offset_counts: float) -> None:
        """The force sensor at ``sensordata[adr]`` reads ``F * COUNTS_PER_N * gain +
        offset_counts`` (+ noise, rounded, clamped), and ``offset_counts`` (rounded, clamped) when
        unloaded: its ``fsr.SITE.gain`` and ``fsr.SITE.offset_counts`` (humanoid_twin/params.py)."""
        self._fscale[adr] = _COUNTS * gain
        self._foffset[adr] = offset_counts
        v = round_half_even(offset_counts)
        self._fzero[adr] = 0 if v < 0 else (_FORCE_ADC_MAX if v > _FORCE_ADC_MAX else v)
        self._has_offset = self._has_offset or offset_counts != 0.0

    def servos(self, rows: tuple[tuple[int, int, int, int, float, float], ...], b_true: tuple[float, ...],
               powered: list[bool], noise: list[float]) -> tuple[list[int], list[int]]:
        """Potentiometer ADC counts and current pulse widths (us) of one board's three servos.

        ``rows``: per servo (qpos adr, dof adr, actuator id, sign, stall torque, damping);
        ``b_true``: the pots' true offsets (deg); ``powered``: per actuator; ``noise``: standard
        draws scaled to counts, taken from the end (at least 3)."""
        qpos = self._qpos
        qvel = self._qvel
        force = self._force
        adc: list[int] = []
        cur: list[int] = []
        for i in range(3):
            qadr, dadr, a, sign, stall, damping = rows[i]
            deg = sign * float(qpos[qadr]) * _DEG
            x = (b_true[i] - deg) * _POT_COUNTS_PER_DEG + noise.pop()
            v = round_half_even(x) if _COMPILED else round(x)
            adc.append(0 if v < 0 else (_POT_ADC_MAX if v > _POT_ADC_MAX else v))
            if powered[a]:
                torque = abs(float(force[a]) - damping * float(qvel[dadr]))
                load = torque / stall if torque < stall else 1.0
                x = _CURRENT_FULL_US * load
                w = _CURRENT_IDLE_US + (round_half_even(x) if _COMPILED else round(x))
                cur.append(w if w < _CURRENT_FULL_US else _CURRENT_FULL_US)
            else:
                cur.append(0)
        return adc, cur

    def forces(self, adrs: tuple[int, int, int, int], noise: list[float]) -> list[int]:
        """The four force sensors of one foot (touch sensor addresses ``adrs``) as 8-bit ADC
        values; an unloaded sensor reads 0. ``noise``: as for :meth:`servos` (at least 4)."""
        sd = self._sensordata
        out: list[int] = []
        for k in range(4):
            adr = adrs[k]
            f = float(sd[adr])
            if f <= 0.0:
                out.append(self._fzero[adr])
                continue
            x = f * self._fscale[adr] + noise.pop()
            if self._has_offset:
                x += self._foffset[adr]
            v = round_half_even(x) if _COMPILED else round(x)
            out.append(0 if v < 0 else (_FORCE_ADC_MAX if v > _FORCE_ADC_MAX else v))
        return out

    def attitude(self, quat_adr: int, gyro_adr: int) -> tuple[float, float, float, float]:
        """Roll, pitch (deg: the ZYX angles of the unit quaternion at ``sensordata[quat_adr:+4]``)
        and the body rates about x, y (deg/s, ``sensordata[gyro_adr:+2]`` in rad/s): the trunk
        inclinometer's and gyroscope's input (humanoid_twin/plant/imu.py)."""
        sd = self._sensordata
        w = float(sd[quat_adr])
        x = float(sd[quat_adr + 1])
        y = float(sd[quat_adr + 2])
        z = float(sd[quat_adr + 3])
        roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)) * _DEG
        s = 2.0 * (w * y - z * x)
        pitch = math.asin(-1.0 if s < -1.0 else (1.0 if s > 1.0 else s)) * _DEG
        return roll, pitch, float(sd[gyro_adr]) * _DEG, float(sd[gyro_adr + 1]) * _DEG


class BoardIO(PhysicsTime):
    """The plant's part the boards call every tick, compiled: the base class of
    :class:`~humanoid_twin.plant.plant.Plant`, which sets every attribute (the MuJoCo model and
    data, the front end, the per-SCU tables, the noise streams) and documents the models.

    Each read first runs the physics due up to the clock's now (``PhysicsTime._sync``)."""

    def read_servos(self, scu: int) -> tuple[list[int], list[int]]:
        """Potentiometer ADC counts and current pulse widths (us) of the three servos of ``scu``.

        Pot: ADC = round((b_true - servo_deg) * POT_COUNTS_PER_DEG + noise), clamped 0..1023,
        i.e. the manual's pos = b - m * ADC (PIC2 ``updateServoMeasures``). Current: width =
        CURRENT_PULSE_FULL_US * min(1, |motor torque| / stall) + idle when powered, where the
        motor torque is the actuator force minus the back-EMF damping term; 0 when PWM is off.
        """
        self._sync()
        rows = self._servo.get(scu) if type(scu) is int else None
        if rows is None:
            _check_scu(scu)
        noise = self._pot_noise
        if len(noise) < 3:
            noise.extend(self._pot_rng.normal(0.0, C.POT_NOISE_STD_COUNTS, _NOISE_BLOCK).tolist())
        return self._sense.servos(rows, self.pot_b_true_deg[scu], self._powered, noise)

    def read_force_adc(self, scu: int) -> list[int]:
        """The four force sensors of the foot of ``scu`` as 8-bit ADC values (table 12 order).

        ADC = clamp(round(F / FORCE_N_PER_COUNT + noise), 0, 255), F the pad's touch-sensor
        normal force; an unloaded sensor reads 0. Boards without a foot read [0, 0, 0, 0]
        (PIC2 ``sampleExtraSensors`` input).
        """
        self._sync()
        adrs = self._foot_touch_of_scu.get(scu) if type(scu) is int else None
        if adrs is None:
            _check_scu(scu)
            return [0, 0, 0, 0]
        noise = self._force_noise
        if len(noise) < 4:
            noise.extend(self._force_rng.normal(0.0, C.FORCE_NOISE_STD_COUNTS, _NOISE_BLOCK).tolist())
        out = self._sense.forces(adrs, noise)
        if self._force_fault:
            return self._faulty_forces(scu, out)
        return out

    def read_imu_adc(self, scu: int) -> list[int]:
        """The body board's (``hardware.IMU_SCU``) inclinometer and gyroscope, four 8-bit ADC
        counts (``hardware.IMU_SENSOR_NAMES``; humanoid_twin/plant/imu.py); other boards read 0."""
        self._sync()
        if scu != _IMU_SCU:
            _check_scu(scu)
            return [0, 0, 0, 0]
        return self._imu.read(self.t_us)
