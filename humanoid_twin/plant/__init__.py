"""plant: the MuJoCo robot (models/) as the Slave boards see it, plus ground truth.

The only package that touches MuJoCo state. See docs/model.md and docs/architecture.md.
"""

from humanoid_twin.plant.constants import SERVO_SIGN, SERVO_SIGN_BY_SCU
from humanoid_twin.plant.plant import (
    DEFAULT_MODEL,
    FOOT_BODIES,
    GeomInfo,
    GroundTruth,
    Plant,
    PlantError,
    PlantInputError,
)

__all__ = [
    "DEFAULT_MODEL",
    "FOOT_BODIES",
    "SERVO_SIGN",
    "SERVO_SIGN_BY_SCU",
    "GeomInfo",
    "GroundTruth",
    "Plant",
    "PlantError",
    "PlantInputError",
]
