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
  before every access (docs/architecture.md, "The one clock");
- the buses (``humanoid_twin/bus``: the cables, the bridges, the serial log's format) are built on
  the clock and the protocol's codecs only: nothing they import is built on them (the rig, the
  replay, the twin ...). The replay of a serial log builds a rig: it is above it
  (``humanoid_twin/replay.py``), and the rig does not import it.
"""

from __future__ import annotations

import ast
from pathlib import Path

from helpers import REPO

PACKAGE = REPO / "humanoid_twin"
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


BUS = PACKAGE / "bus"
BUS_MAY_IMPORT = ("humanoid_twin.bus", "humanoid_twin.protocol", "humanoid_twin.clock")


def _above_the_bus(path: Path) -> list[str]:
    return [m for m in _of(_imports(path), "humanoid_twin")
            if m != "humanoid_twin" and not any(m == ok or m.startswith(ok + ".") for ok in BUS_MAY_IMPORT)]


def test_the_buses_import_nothing_built_on_them() -> None:
    files = sorted(BUS.glob("*.py"))
    assert BUS / "serial_log.py" in files
    offenders = {str(f.relative_to(PACKAGE)): _above_the_bus(f) for f in files}
    assert not {k: v for k, v in offenders.items() if v}, offenders
    assert not _of(_imports(PACKAGE / "rig.py"), "humanoid_twin.replay")
    assert _of(_imports(PACKAGE / "replay.py"), "humanoid_twin.rig")       # the replay builds a rig


def test_the_scan_finds_the_replay_below_the_rig(tmp_path: Path) -> None:
    """bus/serial_log.py as it was (its replay built a Rig): the rule above fails on it."""
    f = tmp_path / "serial_log.py"
    f.write_text("from humanoid_twin.bus.serial_link import SerialLink\n\n"
                 "def replay(path):\n    from humanoid_twin.rig import Rig, RigOptions\n")
    assert _above_the_bus(f) == ["humanoid_twin.rig", "humanoid_twin.rig.Rig", "humanoid_twin.rig.RigOptions"]


def test_only_the_plant_imports_mujoco() -> None:
    files = [*_sources(), *(REPO / "examples").rglob("*.py")]
    importers = sorted(str(f.relative_to(REPO)) for f in files if _of(_imports(f), "mujoco"))
    assert importers and all((REPO / f).is_relative_to(PLANT) for f in importers), importers


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
                callers.append(f"{f.relative_to(REPO)}:{n.lineno}")
    assert [c.split(":")[0] for c in callers] == ["humanoid_twin/twin.py"], callers
