"""The Slave boards' sensor electronics on the plant's state: servo potentiometers, current sense
and foot force sensors as the boards' ADCs read them (PIC2 ``updateServoMeasures`` and
``sampleExtraSensors`` inputs; the models are in :meth:`Plant.read_servos
<humanoid_twin.plant.plant.Plant.read_servos>` and :meth:`Plant.read_force_adc
<humanoid_twin.plant.plant.Plant.read_force_adc>`, which call this module).

Part of the compiled core (sensors.pxd): the per-tick arithmetic reads MuJoCo's arrays through C
memoryviews instead of one numpy scalar per value. No MuJoCo import here: the plant hands over
its ``qpos``, ``qvel``, ``actuator_force`` and ``sensordata`` arrays once, and their memory is
MjData's for the plant's whole life. (Interpreted, each value read is turned into a Python
float at once, as the plant did before: numpy scalars are slower and would leak into results.)
"""

from __future__ import annotations

import math
from typing import Any

from humanoid_twin import hardware
from humanoid_twin.plant import constants as C  # noqa: N812

try:        # Cython's pure-Python mode: True in the compiled core (as in humanoid_twin/clock.py)
    import cython
    _COMPILED = cython.compiled
except ImportError:
    _COMPILED = False

__all__ = ["SensorFrontEnd", "DEG_PER_RAD", "COUNTS_PER_N", "round_half_even"]

DEG_PER_RAD = 180.0 / math.pi
COUNTS_PER_N = 1.0 / hardware.FORCE_N_PER_COUNT
_DEG = DEG_PER_RAD                  # the same values as C doubles in the compiled core
_COUNTS = COUNTS_PER_N
_POT_COUNTS_PER_DEG = hardware.POT_COUNTS_PER_DEG
_POT_ADC_MAX = hardware.POT_ADC_MAX
_CURRENT_FULL_US = hardware.CURRENT_PULSE_FULL_US
_CURRENT_IDLE_US = C.CURRENT_IDLE_US
_FORCE_ADC_MAX = hardware.FORCE_ADC_MAX


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
            f = float(sd[adrs[k]])
            if f <= 0.0:
                out.append(0)
                continue
            x = f * _COUNTS + noise.pop()
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
