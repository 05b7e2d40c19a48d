"""Entity paths of a twin recording (one place, shared by the recorder, the blueprint, the docs
and the tests). Paths carry no leading ``/``; rerun stores them as ``/scu/...``."""

from __future__ import annotations

from humanoid_twin.hardware import FOOT_OF_SCU, FORCE_SENSOR_NAMES, N_SERVOS, SCU_NAMES

__all__ = [
    "SENSOR_NAMES",
    "POSITION_SERIES",
    "WORLD",
    "BODIES",
    "FEET",
    "ROBOT",
    "CAN",
    "SERIAL",
    "MASTER",
    "SUPERVISOR",
    "KEYS",
    "scu_path",
    "servo_path",
    "foot_side",
    "foot_view_path",
]

# Table 12 order (seed 000): front-left, front-right, rear-left, rear-right.
SENSOR_NAMES: tuple[str, ...] = tuple(n.replace("-", "_") for n in FORCE_SENSOR_NAMES)
# The series of ``<servo>/position`` (degrees, servo frame): the Master's final reference
# (actuators.servo[i].ref), the trajectory set-point of this tick (TRAJECTORY), the position the
# servo is driven to (PWM, after the controller), the firmware's measured position (int8), the
# plant's true shaft angle.
POSITION_SERIES: tuple[str, ...] = ("reference", "trajectory", "commanded", "measured", "true")

WORLD = "world"                       # 3D view root
BODIES = "world/bodies"               # one entity per MuJoCo body (pose on sim_time + static shapes)
FEET = "feet"                         # 2D foot views: feet/right, feet/left
ROBOT = "robot"                       # trunk tilt, CoM height, CoP margin, fell, total force
CAN = "bus/can"
SERIAL = "bus/serial"
MASTER = "master"                     # Master.stats() counters
SUPERVISOR = "supervisor"             # the Master supervisor: mode series, events (TextLog)
KEYS = "keys"                         # static text: the colour keys of the joint tabs (TextDocument)


def scu_path(scu: int) -> str:
    """``scu/1_right_leg`` for SCU 1 (seed 002 slide 19 names)."""
    try:
        return f"scu/{scu}_{SCU_NAMES[scu]}"
    except KeyError:
        raise ValueError(f"SCU address must be 1..8, got {scu!r}") from None


def servo_path(scu: int, i: int) -> str:
    """``scu/1_right_leg/servo1`` for SCU 1, 0-based servo index 0 (the manual's servo 1)."""
    if not 0 <= i < N_SERVOS:
        raise ValueError(f"servo index must be 0..{N_SERVOS - 1}, got {i!r}")
    return f"{scu_path(scu)}/servo{i + 1}"


def foot_side(scu: int) -> str:
    """``right`` / ``left`` for the boards that carry a foot (1, 2)."""
    foot = FOOT_OF_SCU[scu]
    return "right" if foot.startswith("r") else "left"


def foot_view_path(scu: int) -> str:
    """``feet/right`` for SCU 1, ``feet/left`` for SCU 2."""
    return f"{FEET}/{foot_side(scu)}"
