"""Who may import what (docs/architecture.md, the package map): MuJoCo lives in ``plant/`` only.

The plant is the one owner of the MuJoCo model and data: its physics, its ground truth
(``plant/truth.py``), its drawing geometry and viewer window (``plant/drawing.py``). Everything else
in the package, and the examples, reach MuJoCo through the plant's methods, so nothing outside it
can step physics by hand or read MuJoCo state the plant has not synced. The tests and the
scripts under ``scripts/`` may import ``mujoco`` (they measure and check the plant and MuJoCo
itself: ``scripts/bench.py`` times bare MuJoCo, ``scripts/physics_replay.py`` replays a model).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and not n.level}
    return names


def test_only_the_plant_imports_mujoco() -> None:
    files = [*(ROOT / "humanoid_twin").rglob("*.py"), *(ROOT / "examples").rglob("*.py")]
    assert len(files) > 50
    plant = ROOT / "humanoid_twin" / "plant"
    importers = sorted(str(f.relative_to(ROOT)) for f in files
                       if any(m == "mujoco" or m.startswith("mujoco.") for m in _imports(f)))
    assert importers and all(Path(ROOT / f).is_relative_to(plant) for f in importers), importers


def test_nothing_outside_the_plant_steps_physics_by_hand() -> None:
    """``Plant.advance_to`` is the twin's (``Twin.advance_to``): the plant syncs itself to the
    clock before every access (docs/architecture.md, "The one clock")."""
    callers = []
    for f in (ROOT / "humanoid_twin").rglob("*.py"):
        tree = ast.parse(f.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            if (isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "advance_to"
                    and isinstance(n.func.value, ast.Attribute) and n.func.value.attr == "plant"):
                callers.append(f"{f.relative_to(ROOT)}:{n.lineno}")
    assert [c.split(":")[0] for c in callers] == ["humanoid_twin/twin.py"], callers
