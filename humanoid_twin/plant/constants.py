"""Plant-side constants: the servo model, the servo mounting signs, sensor noise.

The board-facing laws (PWM, potentiometer, current, force ADC) are in ``humanoid_twin.hardware``;
these are the values only the plant needs. Sources: docs/model.md.
"""

from __future__ import annotations

import math

from humanoid_twin import hardware

# --- hobby servo: HITEC HS-805BB at 6 V (datasheet) -------------------------------------------
SERVO_STALL_TORQUE_NM = 24.7 * 0.0980665          # 24.7 kg.cm = 2.422 N.m
SERVO_NO_LOAD_SPEED_RAD_S = math.radians(60.0) / 0.14   # 0.14 s / 60 deg = 7.48 rad/s
SERVO_SATURATION_ERROR_DEG = 3.0                  # chosen: proportional band of the servo
SERVO_KP_NM_PER_RAD = SERVO_STALL_TORQUE_NM / math.radians(SERVO_SATURATION_ERROR_DEG)
SERVO_FRICTION_NM = 0.2                           # chosen: gear-train friction (~8 % of stall)
SERVO_DAMPING_NMS = (SERVO_STALL_TORQUE_NM - SERVO_FRICTION_NM) / SERVO_NO_LOAD_SPEED_RAD_S
SERVO_ARMATURE_KGM2 = 0.005                       # chosen: reflected rotor inertia, tau_m ~ 17 ms

# --- servo frame vs joint frame: joint_angle = SERVO_SIGN[joint] * servo_angle ----------------
# All joint axes of the model follow the world frame at the stand pose (roll about +x forward,
# pitch about +y left, yaw about +z up), the same for both sides. The servos of the left side's
# roll and yaw joints are mounted mirrored, so their servo angle is the opposite of the joint
# angle. The host package keeps the same table in its data file.
SERVO_SIGN: dict[str, int] = {
    joint: (-1 if joint.startswith("l_") and (joint.endswith("_roll") or joint.endswith("_yaw")) else 1)
    for joints in hardware.SERVO_JOINTS.values()
    for joint in joints
}
SERVO_SIGN_BY_SCU: dict[int, tuple[int, int, int]] = {
    scu: tuple(SERVO_SIGN[j] for j in joints)  # type: ignore[misc]  # 3 servos
    for scu, joints in hardware.SERVO_JOINTS.items()
}

# --- sensor imperfections ---------------------------------------------------------------------
POT_OFFSET_RANGE_DEG = 8.0        # b_true = POT_B_NOMINAL_DEG + U(-8, 8) per servo, drawn once
POT_NOISE_STD_COUNTS = 0.5        # Gaussian noise on each potentiometer sample
FORCE_NOISE_STD_COUNTS = 0.5      # Gaussian noise on each loaded force-sensor sample
CURRENT_IDLE_US = 20              # current pulse of a powered servo at zero torque (2 % of stall)

# --- ground truth ------------------------------------------------------------------------------
FELL_TILT_DEG = 45.0              # trunk tilted more than this = fell
FELL_HEIGHT_M = 0.12              # trunk origin lower than this = fell (stand: 0.29 m)
LOADED_MIN_N = 0.01               # a foot (or the robot) with less normal force is "unloaded"
