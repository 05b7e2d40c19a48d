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
- the buses (``humanoid_twin/bus``: the cables, the bridges, the tap a serial log is written from)
  are built on the clock and the protocol's codecs only: nothing they import is built on them (the
  rig, the replay, the twin ...). The serial log's format is a run log beside the recording
  (``recording/serial_log.py``); its replay builds a rig: it is above it
  (``humanoid_twin/replay.py``), and the rig does not import it;
- the layer order (:data:`LAYERS`, docs/architecture.md "Layers"): every module of the package
  belongs to one layer, and imports only from its own layer and the layers below.
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
    assert BUS / "serial_link.py" in files and BUS / "serial_log.py" in files   # the tap; the alias
    assert not _of(_imports(BUS / "serial_log.py"), "humanoid_twin")   # `python -m` alias: it execs the CLI
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


# -- the layer order ------------------------------------------------------------------------------
# Each layer: its name and the package's units in it (a top-level module, or a subpackage as a
# whole), bottom first. A unit may import from its own layer and the layers below it, never from
# a layer above: top-level imports and imports inside functions alike. An import under
# ``if TYPE_CHECKING:`` is allowed in either direction (it names a type for the reader and the
# type checker and never runs). Derived from the imports (docs/architecture.md, "Layers").
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundations", ("clock", "protocol", "hardware", "limits", "seeds", "signals", "core", "core_modules",
                     "interfaces", "cycles", "containment", "plugins", "outputs", "board_report",
                     "fault_compose")),
    ("bus", ("bus",)),
    ("firmware", ("slave", "master")),
    ("plant", ("plant", "params")),
    ("host", ("host", "plan")),
    ("twin", ("twin", "faults")),
    ("on the twin", ("monitor", "controllers", "recording")),
    ("rig", ("rig", "summary", "serve")),
    ("runs", ("scenarios", "replay", "compare")),
    ("sweep", ("sweep",)),
    ("front", ("cli", "__init__")),
)
LAYER_OF = {unit: n for n, (_, units) in enumerate(LAYERS) for unit in units}


def _unit(path: Path) -> str:
    """The layer table's name of a package file: its top-level module, or its subpackage."""
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _runtime_imports(source: str) -> list[tuple[int, str]]:
    """``(line, unit)`` of each package unit ``source`` imports at run time (at top level or in a
    function; not under ``if TYPE_CHECKING:``). ``from humanoid_twin import x`` imports unit ``x``."""
    tree = ast.parse(source)
    typing_only = {id(n) for node in ast.walk(tree)
                   if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
                   for n in ast.walk(node)}
    found: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = ([f"humanoid_twin.{a.name}" for a in node.names] if node.module == "humanoid_twin"
                     else [node.module])
        else:
            continue
        found += [(node.lineno, n.split(".")[1]) for n in names
                  if n.startswith("humanoid_twin.") and n.split(".")[1] in LAYER_OF]
    return found


def _upward(unit: str, source: str) -> list[str]:
    """The imports of ``source`` (a file of ``unit``) from a layer above ``unit``'s."""
    mine = LAYER_OF[unit]
    return [f"line {line}: {unit} ({LAYERS[mine][0]}) imports {other} ({LAYERS[LAYER_OF[other]][0]})"
            for line, other in _runtime_imports(source) if LAYER_OF[other] > mine]


def test_every_module_has_a_layer() -> None:
    units = {_unit(p) for p in _sources()}
    assert units - set(LAYER_OF) == set(), "a new module: give it a layer in LAYERS"
    assert set(LAYER_OF) - units == set(), "a layer names a module that is gone"


def test_no_module_imports_from_a_layer_above_its_own() -> None:
    offenders = {str(p.relative_to(PACKAGE)): _upward(_unit(p), p.read_text(encoding="utf-8"))
                 for p in _sources()}
    assert not {k: v for k, v in offenders.items() if v}, offenders


def test_the_layer_check_fails_on_an_upward_import() -> None:
    """A synthetic bus module that builds a rig in a function, and one that imports the twin at
    top level: both upward; the same imports under ``if TYPE_CHECKING:`` are not."""
    in_a_function = ("from humanoid_twin.clock import US_PER_S\n\n"
                     "def replay(path):\n    from humanoid_twin.rig import Rig\n")
    assert _upward("bus", in_a_function) == ["line 4: bus (bus) imports rig (rig)"]
    assert _upward("plant", "from humanoid_twin import twin, clock\n") == [
        "line 1: plant (plant) imports twin (twin)"]
    assert _upward("slave", "import humanoid_twin.cli.main\n") == [
        "line 1: slave (firmware) imports cli (front)"]
    typing_only = ("from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n"
                   "    from humanoid_twin.rig import Rig\n")
    assert _upward("bus", typing_only) == []
    assert _upward("rig", "from humanoid_twin.bus.frames import frame_bits\n") == []   # downward


def test_the_docs_layer_table_is_this_one() -> None:
    """docs/architecture.md "Layers" lists the same layers, top first, with the same units."""
    text = (REPO / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("\n## Layers\n", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|")[1:3] for line in section.splitlines() if line.startswith("| ") and "`" in line]
    documented = []
    for number_name, units in rows:
        number, name = number_name.strip().split(" ", 1)
        names = [u.strip("`/").removesuffix(".py") for u in units.split("`")[1::2]]
        documented.append((int(number), name, tuple(names)))
    assert documented == [(n + 1, name, units) for n, (name, units) in reversed(list(enumerate(LAYERS)))]
