"""The electrical and mechanical interface between the boards and the robot.

Electrical and mechanical facts only: the wire's facts (addresses, the position range, bits)
are in :mod:`humanoid_twin.protocol.wire`. Both sides import these constants: the Slave firmware
(what the PIC's timers and ADCs see and how the manual's equations convert them) and the plant
(how the MuJoCo model produces those signals). Each value is documented, with its source, in
docs/model.md and docs/firmware.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from math import pi as _pi

# The unit conversions of angles, the products math.radians and math.degrees compute (the same
# doubles on both cores: the compiled modules use these values as C constants)
RAD_PER_DEG = _pi / 180.0
DEG_PER_RAD = 180.0 / _pi
_RAD_PER_DEG = RAD_PER_DEG
_DEG_PER_RAD = DEG_PER_RAD

# --- boards (addresses 1..8 and their range check: protocol/wire.py) -------------------------
SCU_NAMES: dict[int, str] = {
    1: "right_leg",
    2: "left_leg",
    3: "right_hip",
    4: "left_hip",
    5: "body",
    6: "right_arm",
    7: "left_arm",
    8: "head",
}
N_SERVOS = 3
N_SPECIAL_SENSORS = 4

# Servo order per board (humanoid_twin/models/README.md section 8: leg board 1 foot lateral,
# 2 foot front, 3 knee; hip board 1 roll, 2 pitch, 3 yaw). Boards 5-8: the same section.
# ``None`` = a bench servo (a horn with no load, mounted inside the trunk), named ``<board>_spare``.
SERVO_JOINTS: dict[int, tuple[str, str, str]] = {
    1: ("r_ankle_roll", "r_ankle_pitch", "r_knee"),
    2: ("l_ankle_roll", "l_ankle_pitch", "l_knee"),
    3: ("r_hip_roll", "r_hip_pitch", "r_hip_yaw"),
    4: ("l_hip_roll", "l_hip_pitch", "l_hip_yaw"),
    5: ("torso_roll", "torso_pitch", "body_spare"),
    6: ("r_shoulder_pitch", "r_shoulder_roll", "r_elbow"),
    7: ("l_shoulder_pitch", "l_shoulder_roll", "l_elbow"),
    8: ("neck_yaw", "neck_pitch", "head_spare"),
}
# Boards that carry a force-sensing foot (SPECIAL sensors = 4 force sensors).
FOOT_OF_SCU: dict[int, str] = {1: "r_foot", 2: "l_foot"}
# The body board's special sensors (seed 000 section 4, readspecial: "gyroscope + inclinometer";
# seed 002 slide 3): a 2-axis inclinometer and a 2-axis gyroscope on the trunk, read by its ADC
# like the feet's force sensors, in this order (docs/firmware.md, "Trunk inertial sensors").
IMU_SCU = 5
IMU_SENSOR_NAMES: tuple[str, ...] = ("IncRoll", "IncPitch", "GyroRoll", "GyroPitch")
IMU_ZERO_COUNT = 128            # 8-bit ADC count of 0 deg / 0 deg/s (mid-scale)
IMU_INCL_DEG_PER_COUNT = 0.5    # inclinometer: +-64 deg full scale
IMU_GYRO_DPS_PER_COUNT = 1.25   # gyroscope: +-160 deg/s full scale


def imu_from_counts(special: Sequence[int]) -> tuple[float, float, float, float]:
    """``(roll deg, pitch deg, roll rate deg/s, pitch rate deg/s)`` from the body board's four
    special values (``readspecial(H, 5)``, :data:`IMU_SENSOR_NAMES` order): roll about the trunk's
    x (forward), pitch about its y (left)."""
    z = IMU_ZERO_COUNT
    return ((special[0] - z) * IMU_INCL_DEG_PER_COUNT, (special[1] - z) * IMU_INCL_DEG_PER_COUNT,
            (special[2] - z) * IMU_GYRO_DPS_PER_COUNT, (special[3] - z) * IMU_GYRO_DPS_PER_COUNT)


def tilt_from_roll_pitch(roll_deg: float, pitch_deg: float) -> float:
    """The angle (deg) between the trunk's z axis and the vertical, from its roll and pitch (ZYX).

    Compiled (hardware.pxd) with C's libm, the functions Python's math calls: ``math.radians``
    and ``math.degrees`` are written as the products they are, the clamp to [-1, 1] as
    ``max(-1.0, min(1.0, c))`` does it; the same number on both cores. An infinite angle is a
    ``ValueError`` on both (Python's ``math.cos`` refuses it; C's would give NaN)."""
    if math.isinf(roll_deg) or math.isinf(pitch_deg):
        raise ValueError(f"tilt_from_roll_pitch: the angles must not be infinite, got {roll_deg!r}, "
                         f"{pitch_deg!r}")
    c = math.cos(roll_deg * _RAD_PER_DEG) * math.cos(pitch_deg * _RAD_PER_DEG)
    c = c if c < 1.0 else 1.0
    c = c if c > -1.0 else -1.0
    return math.acos(c) * _DEG_PER_RAD

# The leg and hip boards (right leg, left leg, right hip, left hip): the legs the twin moves.
LEG_SCUS: tuple[int, ...] = (1, 2, 3, 4)

# --- PWM actuation (servoActuation, PIC2) ----------------------------------------------------
PWM_PERIOD_US = 20_000          # one tick of the Slave main loop
PULSE_CENTER_US = 1500          # 0 degrees
PULSE_US_PER_DEG = 10           # 600 us = -90 deg, 2400 us = +90 deg (protocol.wire.POS_LIMIT_DEG)
# The Slave generates the three pulses one after the other at the start of each period
# (seed 000 fig. 10/12); while it does, it cannot answer CAN without disturbing the pulses
# (seed 002 slide 29: jitter up to 2 ms).
PWM_BUSY_US = 2_000


def pulse_from_deg(deg: int) -> int:
    """PWM high time (us) for a servo position in whole degrees (-90..90)."""
    return PULSE_CENTER_US + PULSE_US_PER_DEG * deg


def deg_from_pulse(pulse_us: float) -> float:
    """Servo position (degrees) commanded by a PWM high time."""
    return (pulse_us - PULSE_CENTER_US) / PULSE_US_PER_DEG


# --- potentiometer measurement (updateServoMeasures / finalizeServoMeasures) ----------------
# pos_deg = b - m * ADC  (the manual's calibration equation, b = pos_master + ADC_mean * m).
# 10-bit ADC; m = 1/4 degree per count (firmware fixed point: quarter degrees).
POT_ADC_MAX = 1023
POT_COUNTS_PER_DEG = 4          # 1/m
POT_B_NOMINAL_DEG = 128         # b of an ideal servo: ADC 512 at 0 degrees

# --- current measurement --------------------------------------------------------------------
# The servo board gives a current pulse whose width is proportional to the motor current;
# the firmware normalises it to 0..100 (finalizeServoMeasures).
CURRENT_PULSE_FULL_US = 1000    # stall current -> 1000 us -> 100

# --- force sensors (sampleExtraSensors) -----------------------------------------------------
FORCE_ADC_MAX = 255             # 8-bit ADC
FORCE_N_PER_COUNT = 0.2         # 8-bit count -> newtons (255 counts = 51 N)
FORCE_CALIBRATION_VALUE = 128   # offset(7 bit) = 128 - mean(7 bit)
# Smallest sum of the four 7-bit force values for which a foot's CoP means something: 8 counts of
# 7 bits = 16 counts of the 8-bit ADC = 3.2 N, about 6 % of the robot's weight. Below it the foot
# is taken as unloaded (in the air): the Slave's calcCoP and the host's calccop (docs/firmware.md).
COP_MIN_LOAD = 8

# Table 12 (seed 000), foot frame: x to the robot's right, y forward, millimetres.
# Order: front-left, front-right, rear-left, rear-right.
# Interpretation (docs/model.md): the y column is read in centimetres (6.20 cm = 62.0 mm), so
# that the sensors span a 20 x 8 cm foot (seed 002 slide 3); x is read in millimetres as printed.
FORCE_SENSOR_XY_MM: tuple[tuple[float, float], ...] = (
    (-32.5, 62.0),
    (32.0, 62.0),
    (-35.0, -62.5),
    (34.0, -62.5),
)
FORCE_SENSOR_NAMES: tuple[str, str, str, str] = ("front-left", "front-right", "rear-left", "rear-right")
FORCE_SENSOR_LABELS: tuple[str, str, str, str] = ("FL", "FR", "RL", "RR")   # the DBC's signal names
FOOT_LENGTH_MM = 200.0          # seed 002 slide 3: foot print 20 x 8 cm
FOOT_WIDTH_MM = 80.0

# --- leg (table 13, seed 000) ---------------------------------------------------------------
LINK_MASS_KG = 0.450            # M1 = M2
LINK_LENGTH_MM = 95.0           # L1 = L2
LINK_COM_MM = 47.0              # R1 = R2, from the link's proximal joint (docs/model.md)
ROBOT_MASS_KG = 5.0
ROBOT_HEIGHT_MM = 600.0
