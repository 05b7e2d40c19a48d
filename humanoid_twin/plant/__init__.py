"""plant: the MuJoCo robot (humanoid_twin/models/, shipped in the package) as the Slave boards
see it (``plant.py``), its ground truth (``truth.py``) and its drawing geometry and viewer window
(``drawing.py``).

The only package that imports ``mujoco`` (tests/project/test_layers.py checks it). See
humanoid_twin/models/README.md, docs/model.md and docs/architecture.md.
"""

from humanoid_twin.plant.constants import SERVO_SIGN, SERVO_SIGN_BY_SCU
from humanoid_twin.plant.drawing import GeomInfo, ViewerWindow, ViewerWindowError
from humanoid_twin.plant.plant import DEFAULT_MODEL, MODELS, Plant, PlantError, PlantInputError
from humanoid_twin.plant.truth import FOOT_BODIES, GroundTruth, PlainTruth

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
    "ViewerWindow",
    "ViewerWindowError",
]
