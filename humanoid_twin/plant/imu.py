"""The trunk's inertial sensors as the body board (SCU 5) sees them (docs/firmware.md, "Trunk
inertial sensors"): a 2-axis inclinometer and a 2-axis gyroscope, roll and pitch, read by the
board's 8-bit ADC like the feet's force sensors (seed 000 section 4, ``readspecial``: "gyroscope +
inclinometer"; seed 002 slide 3).

Source: MuJoCo's ``framequat`` and ``gyro`` sensors on the site ``trunk_imu``. The inclinometer
gives the trunk's attitude (roll about the trunk's x, forward; pitch about its y, left: the ZYX
angles of the site), low-passed by its output filter (first order, ``INCL_BANDWIDTH_HZ``); the
gyroscope its body rates about x and y (``GYRO_BANDWIDTH_HZ``). Each reading gets white noise of
``*_NOISE_COUNTS`` standard deviation (seeded by the plant's seed), is rounded to a count around
``hardware.IMU_ZERO_COUNT`` and clamped to 0..255. ``hardware.imu_from_counts`` is the inverse a
host controller uses on ``readspecial(H, 5)``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from humanoid_twin import hardware as hw
from humanoid_twin.plant.sensors import SensorFrontEnd

__all__ = ["INCL_BANDWIDTH_HZ", "GYRO_BANDWIDTH_HZ", "INCL_NOISE_COUNTS", "GYRO_NOISE_COUNTS", "TrunkImu"]

INCL_BANDWIDTH_HZ = 10.0        # the inclinometer's output filter (-3 dB)
GYRO_BANDWIDTH_HZ = 40.0        # the gyroscope's output filter (-3 dB)
INCL_NOISE_COUNTS = 0.5         # standard deviation, counts (0.25 deg)
GYRO_NOISE_COUNTS = 1.0         # standard deviation, counts (1.25 deg/s)
_SITE = "trunk_imu"
_NOISE_BLOCK = 4096


def _count(x: float) -> int:
    v = hw.IMU_ZERO_COUNT + round(x)
    return 0 if v < 0 else 255 if v > 255 else v


class TrunkImu:
    """The sensors' electronics: ``TrunkImu(model, seed_sequence, front_end)``; :meth:`read` at
    each sample. ``front_end``: the plant's :class:`~humanoid_twin.plant.sensors.SensorFrontEnd`
    on the same MjData (it reads the MuJoCo sensors)."""

    def __init__(self, model: mujoco.MjModel, seed: np.random.SeedSequence,
                 front_end: SensorFrontEnd, bias: tuple[float, float, float, float] | None = None) -> None:
        def adr(kind: str) -> int:
            for s in range(model.nsensor):
                if int(model.sensor_type[s]) == int(getattr(mujoco.mjtSensor, kind)) and \
                        model.site(int(model.sensor_objid[s])).name == _SITE:
                    return int(model.sensor_adr[s])
            raise ValueError(f"the model has no {kind} sensor on site {_SITE!r}")

        self._quat = adr("mjSENS_FRAMEQUAT")
        self._gyro = adr("mjSENS_GYRO")
        self._seed = seed
        self._front = front_end
        # the sensors' biases (deg, deg, deg/s, deg/s; the parameters imu.*_bias_*), added to
        # their input; None: none (the input as it is)
        self._bias = bias
        self.reset()

    def reset(self) -> None:
        """Noise restarted, filters empty (the next read starts them at the input)."""
        self._rng = np.random.default_rng(self._seed)
        self._noise: list[float] = []
        self._state: list[float] | None = None
        self._t_us = 0

    def true_attitude(self) -> tuple[float, float, float, float]:
        """The trunk's roll, pitch (deg) and body rates about x, y (deg/s): the sensors' input."""
        return self._front.attitude(self._quat, self._gyro)

    def read(self, t_us: int) -> list[int]:
        """The four 8-bit ADC counts (``hardware.IMU_SENSOR_NAMES`` order) at physics time ``t_us``."""
        x = self.true_attitude()
        if self._bias is not None:
            x = tuple(v + b for v, b in zip(x, self._bias, strict=True))  # type: ignore[assignment]  # four values
        s = self._state
        if s is None:
            s = self._state = list(x)
        else:
            dt = max(0, t_us - self._t_us) * 1e-6
            a_i = 1.0 - math.exp(-2.0 * math.pi * INCL_BANDWIDTH_HZ * dt)
            a_g = 1.0 - math.exp(-2.0 * math.pi * GYRO_BANDWIDTH_HZ * dt)
            for k, a in enumerate((a_i, a_i, a_g, a_g)):
                s[k] += a * (x[k] - s[k])
        self._t_us = t_us
        noise = self._noise
        if len(noise) < 4:          # standard normal draws, a block at a time
            noise.extend(self._rng.normal(0.0, 1.0, _NOISE_BLOCK).tolist())
        n = (noise.pop(), noise.pop(), noise.pop(), noise.pop())
        return [_count(s[0] / hw.IMU_INCL_DEG_PER_COUNT + INCL_NOISE_COUNTS * n[0]),
                _count(s[1] / hw.IMU_INCL_DEG_PER_COUNT + INCL_NOISE_COUNTS * n[1]),
                _count(s[2] / hw.IMU_GYRO_DPS_PER_COUNT + GYRO_NOISE_COUNTS * n[2]),
                _count(s[3] / hw.IMU_GYRO_DPS_PER_COUNT + GYRO_NOISE_COUNTS * n[3])]
