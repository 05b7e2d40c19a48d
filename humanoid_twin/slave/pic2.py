"""Module PIC2 of the Slave firmware (seed 000 section 3, tables 16-17, fig. 10-17).

The low-level servo interface: PWM actuation (``servoActuation``, ``statusPWM``), the servo
measurements over each PWM period (``updateServoMeasures`` / ``finalizeServoMeasures``), the
position filters (``filter``, ``statusFilter``), ``limitPosition`` and the force sensors
(``sampleExtraSensors``). In the twin the electrical side is the plant's: ``set_pwm`` takes the
pulse widths, ``read_servos`` gives the potentiometer ADC counts and current-pulse widths measured
over the period, ``read_force_adc`` the four 8-bit force ADC values.

Arithmetic (docs/firmware.md, "PIC2"):
- position: ``pos = b - m * ADC`` with ``m = 1/4`` degree per count, in integer quarter degrees
  (``b`` in quarter degrees from the calibration, ``hardware.POT_B_NOMINAL_DEG`` before it),
  rounded to whole degrees and clamped to int8;
- current: ``100 * pulse / CURRENT_PULSE_FULL_US``, truncated, clamped to 0..100;
- mean velocity: the change of the (filtered) position over the period, degrees per tick, int8;
- filters (when on): a median of the last 3 raw positions (non-linear, removes one-period
  spikes) followed by the mean of the last 2 medians (linear), rounded half up;
- force: ``Resultado(8 bit) = (ADC >> 1) + offset`` clamped to 0..255; the 7-bit values
  ``ADC >> 1`` are kept for the CoP (``calcCoP``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from humanoid_twin.hardware import (
    CURRENT_PULSE_FULL_US,
    FOOT_OF_SCU,
    IMU_SCU,
    N_SERVOS,
    N_SPECIAL_SENSORS,
    POT_B_NOMINAL_DEG,
    POT_COUNTS_PER_DEG,
    pulse_from_deg,
)
from humanoid_twin.protocol.wire import POS_LIMIT_DEG

__all__ = [
    "B_NOMINAL_Q",
    "limitPosition",
    "position_from_adc",
    "current_from_pulse",
    "force_result",
    "median3",
    "Pic2",
]

B_NOMINAL_Q = POT_B_NOMINAL_DEG * POT_COUNTS_PER_DEG    # b before calibration, quarter degrees
_HALF_Q = POT_COUNTS_PER_DEG // 2
_SHIFT_Q = POT_COUNTS_PER_DEG.bit_length() - 1          # 4 counts per degree -> >> 2
if 1 << _SHIFT_Q != POT_COUNTS_PER_DEG:                 # pragma: no cover - hardware constant
    raise ImportError("POT_COUNTS_PER_DEG must be a power of two for the firmware's shifts")

_PULSE_OFF: list[int | None] = [None] * N_SERVOS


class ServoPlant(Protocol):
    """What PIC2 needs from the plant (``humanoid_twin.plant.Plant``)."""

    def set_pwm(self, scu: int, pulses_us: Sequence[int | None]) -> None: ...
    def read_servos(self, scu: int) -> tuple[list[int], list[int]]: ...
    def read_force_adc(self, scu: int) -> list[int]: ...
    def read_imu_adc(self, scu: int) -> list[int]: ...


def limitPosition(position: int) -> int:
    """``limitPosition`` (table 16): a position limited to the servo's -90..+90 degrees."""
    if position > POS_LIMIT_DEG:
        return POS_LIMIT_DEG
    if position < -POS_LIMIT_DEG:
        return -POS_LIMIT_DEG
    return position


def position_from_adc(b_q: int, adc: int) -> int:
    """``finalizeServoMeasures`` position: ``round((b_q - ADC) / 4)`` whole degrees (halves up),
    clamped to int8, with ``b_q`` in quarter degrees."""
    p = (b_q - adc + _HALF_Q) >> _SHIFT_Q
    return 127 if p > 127 else -128 if p < -128 else p


def current_from_pulse(pulse_us: int) -> int:
    """``finalizeServoMeasures`` current: the current-pulse width normalised to 0..100."""
    c = (100 * pulse_us) // CURRENT_PULSE_FULL_US
    return 100 if c > 100 else 0 if c < 0 else c


def force_result(adc8: int, offset: int) -> int:
    """``sampleExtraSensors``: ``Resultado(8 bit) = Sensor(7 bit) + offset(7 bit)``, 0..255."""
    r = (adc8 >> 1) + offset
    return 255 if r > 255 else 0 if r < 0 else r


def median3(a: int, b: int, c: int) -> int:
    """Median of three values (the non-linear filter)."""
    if a > b:
        a, b = b, a
    if b > c:
        b = c
    return a if a > b else b


class Pic2:
    """The PIC2 module of one Slave: PWM outputs, servo and force measurements, filters."""

    __slots__ = (
        "address",
        "plant",
        "has_foot",
        "has_imu",
        "pwm",
        "filter_on",
        "b_q",
        "offsets",
        "pulses",
        "applied",
        "adc",
        "current_us",
        "raw_pos",
        "pos",
        "vel",
        "current",
        "force8",
        "force7",
        "special",
        "_hist",
        "_med_prev",
    )

    def __init__(self, address: int, plant: ServoPlant) -> None:
        self.address = address
        self.plant = plant
        self.has_foot = address in FOOT_OF_SCU
        self.has_imu = address == IMU_SCU
        self.pwm = False
        self.filter_on = False
        self.b_q: list[int] = [B_NOMINAL_Q] * N_SERVOS
        self.offsets: list[int] = [0] * N_SPECIAL_SENSORS
        self.pulses: list[int] = [pulse_from_deg(0)] * N_SERVOS   # PWM high times (us)
        self.applied: list[int] = [0] * N_SERVOS                  # positions behind ``pulses``
        self.adc: list[int] = [0] * N_SERVOS                      # last pot ADC counts
        self.current_us: list[int] = [0] * N_SERVOS               # last current-pulse widths
        self.raw_pos: list[int] = [0] * N_SERVOS                  # unfiltered positions
        self.pos: list[int] = [0] * N_SERVOS                      # filtered positions
        self.vel: list[int] = [0] * N_SERVOS
        self.current: list[int] = [0] * N_SERVOS
        self.force8: list[int] = [0] * N_SPECIAL_SENSORS
        self.force7: list[int] = [0] * N_SPECIAL_SENSORS
        self.special: list[int] = [0] * N_SPECIAL_SENSORS
        self._hist: list[list[int]] = [[0, 0, 0] for _ in range(N_SERVOS)]
        self._med_prev: list[int] = [0] * N_SERVOS

    def initPic(self) -> None:
        """``initPic`` (table 16), the servo side: PWM outputs off (servos limp), filters off,
        nominal position law, zero force offsets."""
        self.filter_on = False
        for i in range(N_SERVOS):
            self.b_q[i] = B_NOMINAL_Q
        for k in range(N_SPECIAL_SENSORS):
            self.offsets[k] = 0
        self.pwm = True          # force the plant call
        self.statusPWM(False)

    # -- actuation -----------------------------------------------------------------------------
    def servoActuation(self, positions: Sequence[int]) -> None:
        """``servoActuation`` (table 16): the PWM pulse widths for the given positions (whole
        degrees, limited to -90..90), applied at once when the PWM is on."""
        pulses = self.pulses
        applied = self.applied
        changed = False
        for i in range(N_SERVOS):
            p = limitPosition(positions[i])
            if p != applied[i]:
                applied[i] = p
                pulses[i] = pulse_from_deg(p)
                changed = True
        if changed and self.pwm:
            self.plant.set_pwm(self.address, pulses)

    def statusPWM(self, on: bool) -> None:
        """``statusPWM`` (table 16): PWM signals on (the stored pulse widths) or off (limp)."""
        if on == self.pwm:
            return
        self.pwm = on
        self.plant.set_pwm(self.address, self.pulses if on else _PULSE_OFF)

    def statusFilter(self, on: bool) -> None:
        """``statusFilter`` (table 16): position filters on/off. Switching on primes the filter
        with the last raw positions, so it starts without a transient."""
        if on and not self.filter_on:
            for i in range(N_SERVOS):
                r = self.raw_pos[i]
                h = self._hist[i]
                h[0] = h[1] = h[2] = r
                self._med_prev[i] = r
        self.filter_on = on

    def setCalibration(self, b_q: Sequence[int], offsets: Sequence[int]) -> None:
        """The results of ``calibration`` (SERVO): ``b`` (quarter degrees) of each servo and the
        7-bit force offsets. The measurements of this period are converted again with them (a
        change of ``b`` is not a movement: the velocities are zeroed)."""
        for i in range(N_SERVOS):
            self.b_q[i] = int(b_q[i])
            p = position_from_adc(self.b_q[i], self.adc[i])
            self.raw_pos[i] = p
            self.pos[i] = p
            self.vel[i] = 0
        for k in range(N_SPECIAL_SENSORS):
            self.offsets[k] = int(offsets[k])
            if not self.has_imu:
                self.special[k] = force_result(self.force8[k], self.offsets[k])

    # -- measurement ---------------------------------------------------------------------------
    def updateServoMeasures(self) -> None:
        """``updateServoMeasures`` (table 17, fig. 16): the servo signals measured over the PWM
        period (pot ADC counts and current-pulse widths, from the plant)."""
        adc, cur = self.plant.read_servos(self.address)
        self.adc = adc
        self.current_us = cur

    def finalizeServoMeasures(self) -> None:
        """``finalizeServoMeasures`` (table 17, fig. 17): positions (degrees, filtered when the
        filters are on), mean velocities (degrees per tick) and currents (0..100) of the period
        that ended."""
        adc = self.adc
        cur = self.current_us
        b_q = self.b_q
        pos = self.pos
        for i in range(N_SERVOS):
            p = position_from_adc(b_q[i], adc[i])
            self.raw_pos[i] = p
            if self.filter_on:
                p = self.filter(i, p)
            v = p - pos[i]
            self.vel[i] = 127 if v > 127 else -128 if v < -128 else v
            pos[i] = p
            self.current[i] = current_from_pulse(cur[i])

    def filter(self, i: int, raw: int) -> int:
        """``filter`` (table 17): the non-linear filter (median of the last 3 raw positions)
        then the linear one (mean of the last 2 medians, rounded half up)."""
        h = self._hist[i]
        h[0] = h[1]
        h[1] = h[2]
        h[2] = raw
        m = median3(h[0], h[1], raw)
        out = (m + self._med_prev[i] + 1) >> 1
        self._med_prev[i] = m
        return out

    def sampleExtraSensors(self) -> None:
        """``sampleExtraSensors`` (table 17): the four force sensors, 8-bit ADC -> 7 bits ->
        plus the calibration offset -> 8-bit result (0..255). Boards without a foot read 0.
        The body board (``hardware.IMU_SCU``) reads its inclinometer and gyroscope instead: the
        four 8-bit ADC counts are its special values as they are (docs/firmware.md)."""
        if self.has_foot:
            f8 = self.plant.read_force_adc(self.address)
            self.force8 = f8
        elif self.has_imu:
            f8 = self.plant.read_imu_adc(self.address)
            self.force8 = f8
            sp = self.special
            for k in range(N_SPECIAL_SENSORS):
                sp[k] = f8[k]
            return
        else:
            f8 = self.force8          # stays [0, 0, 0, 0]
        f7 = self.force7
        off = self.offsets
        sp = self.special
        for k in range(N_SPECIAL_SENSORS):
            f7[k] = f8[k] >> 1
            sp[k] = force_result(f8[k], off[k])
