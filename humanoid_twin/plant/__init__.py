"""plant: the MuJoCo robot (humanoid_twin/models/, shipped in the package) as the Slave boards
see it, plus ground truth.

The only package that touches MuJoCo state. See humanoid_twin/models/README.md, docs/model.md
and docs/architecture.md.
"""

from humanoid_twin.plant.constants import SERVO_SIGN, SERVO_SIGN_BY_SCU
from humanoid_twin.plant.plant import (
    DEFAULT_MODEL,
    FOOT_BODIES,
    MODELS,
    GeomInfo,
    GroundTruth,
    PlainTruth,
    Plant,
    PlantError,
    PlantInputError,
)

__all__ = [
    "DEFAULT_MODEL",
    "FOOT_BODIES",
    "MODELS",
    "SERVO_SIGN",
    "SERVO_SIGN_BY_SCU",
    "GeomInfo",
    "GroundTruth",
    "PlainTruth",
    "Plant",
    "PlantError",
    "PlantInputError",
]
