"""Who may import and call what (docs/architecture.md, the package map), from the source's syntax:

- the command line (``humanoid_twin/cli``) sits on top of the library: nothing below it imports
  it (the library takes typed options, never argparse namespaces; the fault registry,
  ``faults.py`` and ``fault_compose.py``, is the library's, the CLI's ``--fault`` is
  ``cli/fault_options.py``);
- MuJoCo lives in ``plant/`` only. The plant is the one owner of the MuJoCo model and data: its
  physics, its ground truth (``plant/truth.py``), its drawing geometry and viewer window
  (``plant/drawing.py``). Everything else in the package, and the examples, reach MuJoCo through
  the plant's methods, so nothing outside it can step physics by hand or read MuJoCo state the
  plant has not synced. The tests and ``scripts/`` may import ``mujoco`` (they measure and check
  the plant and MuJoCo itself: ``scripts/bench.py`` times bare MuJoCo);
- ``Plant.advance_to`` is the twin's (``Twin.advance_to``): the plant syncs itself to the clock
  before every access (docs/architecture.md, "The one clock").
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "humanoid_twin"
CLI = PACKAGE / "cli"
PLANT = PACKAGE / "plant"


def _imports(path: Path) -> list[str]:
    """Every module ``path`` imports, absolute, at top level or inside a function
    (``from a import b`` gives ``a`` and ``a.b``: ``b`` may be a module). Relative imports stay
    inside their package and are not listed."""
    found: list[str] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found += [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
    return found


def _of(modules: list[str], package: str) -> list[str]:
    """The modules of ``modules`` that are ``package`` or inside it."""
    return [m for m in modules if m == package or m.startswith(package + ".")]


def _sources() -> list[Path]:
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 50                       # the scan sees the package
    return files


def test_no_module_below_the_cli_imports_the_cli() -> None:
    below = [p for p in _sources() if CLI not in p.parents]
    assert PACKAGE / "faults.py" in below and PACKAGE / "fault_compose.py" in below
    offenders = {str(p.relative_to(PACKAGE)): _of(_imports(p), "humanoid_twin.cli") for p in below}
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, offenders


def test_only_the_plant_imports_mujoco() -> None:
    files = [*_sources(), *(ROOT / "examples").rglob("*.py")]
    importers = sorted(str(f.relative_to(ROOT)) for f in files if _of(_imports(f), "mujoco"))
    assert importers and all((ROOT / f).is_relative_to(PLANT) for f in importers), importers


def test_the_scan_finds_an_upward_import(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from humanoid_twin.cli.argtypes import checked\n")
    assert _of(_imports(f), "humanoid_twin.cli") == ["humanoid_twin.cli.argtypes",
                                                     "humanoid_twin.cli.argtypes.checked"]
    f.write_text("import humanoid_twin.cli.main as m\nfrom humanoid_twin import cli, clock\n"
                 "from mujoco import viewer\nimport humanoid_twin.client\n")
    assert _of(_imports(f), "humanoid_twin.cli") == ["humanoid_twin.cli.main", "humanoid_twin.cli"]
    assert _of(_imports(f), "mujoco") == ["mujoco", "mujoco.viewer"]


def test_nothing_but_the_twin_steps_the_plant() -> None:
    callers = []
    for f in _sources():
        for n in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if (isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "advance_to"
                    and isinstance(n.func.value, ast.Attribute) and n.func.value.attr == "plant"):
                callers.append(f"{f.relative_to(ROOT)}:{n.lineno}")
    assert [c.split(":")[0] for c in callers] == ["humanoid_twin/twin.py"], callers
