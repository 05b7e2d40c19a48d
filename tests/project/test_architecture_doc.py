"""docs/architecture.md names only what exists: its drawings and its text cannot name a module,
a package or a folder of ``humanoid_twin`` that was moved or renamed (a drawing that named
``bus.serial`` and ``bus.can``, which never existed, is why this test is here).

Checked: every ``humanoid_twin/...`` path and every dotted ``humanoid_twin.x.y`` (a module, or a
name a module defines); in backquotes and in code blocks, every path such as ``bus/network.py``,
``cli/``, ``hardware.py`` (under ``humanoid_twin/``, or the repository's own: ``setup.py``,
``scripts/...``), every ``package/module.Name`` and every dotted name that starts with a
subpackage (``bus.network``, ``slave.servo.ServoControl``). Left out: ``tests/`` (the
suite's layout moves on its own) and ``build/`` (made by a build)."""

from __future__ import annotations

import importlib
import re

from helpers import REPO

ROOT = REPO
PKG = ROOT / "humanoid_twin"
DOC = ROOT / "docs" / "architecture.md"

FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
CODE_SPAN = re.compile(r"(?<!`)`([^`\n]+)`(?!`)")
# a path of the package or of the repository: bus/network.py, cli/, slave/laws.pxd, setup.py
PATH = re.compile(r"(?<![\w./-])((?:[a-z_][a-z0-9_]*/)*[a-z_][a-z0-9_]*(?:/|\.py|\.pxd|\.sh))(?![\w/])")
# a name in a module: bus/frames.Frame, slave/pic2.limitPosition
PATH_NAME = re.compile(r"(?<![\w./-])((?:[a-z_][a-z0-9_]*/)+[a-z_][a-z0-9_]*)"
                       r"\.(?!(?:py|pxd|pyx|c|so|md|sh|txt|toml|json|xml|dbc|html)\b)([A-Za-z_]\w*)(?![\w/(])")
PACKAGE_PATH = re.compile(r"(?<![\w./-])humanoid_twin/[\w/.]*")
DOTTED = re.compile(r"(?<![\w./-])humanoid_twin(?:\.[A-Za-z_]\w*)+")
LEFT_OUT = ("tests/", "build/")
# a subpackage's dotted name without the package's: bus.network, slave.servo.ServoControl
SUBPACKAGES = sorted(p.parent.name for p in PKG.glob("*/__init__.py"))
SUB_DOTTED = re.compile(rf"(?<![\w./-])(?:{'|'.join(SUBPACKAGES)})(?:\.[A-Za-z_]\w*)+(?![\w(])")


def _code(text: str) -> list[str]:
    """The text of the doc's code blocks and code spans."""
    spans = CODE_SPAN.finditer(FENCE.sub("", text))
    return [m.group(1) for m in FENCE.finditer(text)] + [m.group(1) for m in spans]


def path_exists(path: str) -> bool:
    """A path as the doc writes it: under ``humanoid_twin/`` or the repository's; a bare
    ``name.py`` anywhere in the package (the package map names modules inside a package's row)."""
    path = path.removeprefix("humanoid_twin/")
    if (PKG / path).exists() or (ROOT / path).exists():
        return True
    return "/" not in path.rstrip("/") and path.endswith((".py", ".pxd")) and any(PKG.rglob(path))


def dotted_exists(name: str) -> bool:
    """``humanoid_twin.a.b``: a module, or a name the longest importable module before it has."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:n]))
        except ImportError:
            continue
        for attr in parts[n:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def missing(text: str) -> list[str]:
    """Every module, package, path or name of ``text`` (a doc) that does not exist."""
    found: set[str] = set()
    for m in PACKAGE_PATH.finditer(text):
        path = m.group(0).rstrip(".")
        if path != "humanoid_twin/" and not path_exists(path):
            found.add(path)
    for m in DOTTED.finditer(text):
        if not dotted_exists(m.group(0)):
            found.add(m.group(0))
    for code in _code(text):
        for m in PATH.finditer(code):
            path = m.group(1)
            if not path.startswith(LEFT_OUT) and not path_exists(path):
                found.add(path)
        for m in SUB_DOTTED.finditer(code):
            if not m.group(0).endswith((".py", ".pxd")) and not dotted_exists("humanoid_twin." + m.group(0)):
                found.add(m.group(0))
        for m in PATH_NAME.finditer(code):
            module, name = m.groups()
            if module.startswith(LEFT_OUT) or not (PKG / (module + ".py")).is_file():
                if not module.startswith(LEFT_OUT) and not (PKG / module).is_dir():
                    found.add(m.group(0))
                continue
            if not dotted_exists(f"humanoid_twin.{module.replace('/', '.')}.{name}"):
                found.add(m.group(0))
    return sorted(found)


def test_every_module_the_architecture_page_names_exists() -> None:
    absent = missing(DOC.read_text(encoding="utf-8"))
    assert absent == [], f"docs/architecture.md names what does not exist: {absent}"


def test_a_name_that_does_not_exist_is_found() -> None:
    text = """
```text
host/ --RS-232--> bus.serial --> master/  --> bus/serial.py --> plant/
```
The wire (`bus/network.py`, `bus/frames.Frame`, `bus/frames.Frame2`) and `humanoid_twin/bus/can.py`;
`humanoid_twin.open`, `humanoid_twin.slave.servo.ServoControl`, `humanoid_twin.slave.nothing`,
`nowhere.py`, `cli/gone/`, `setup.py`, `scripts/build_core.py`, `tests/test_moved.py`, `build/cython/`.
"""
    assert missing(text) == ["bus.serial", "bus/frames.Frame2", "bus/serial.py", "cli/gone/",
                             "humanoid_twin.slave.nothing", "humanoid_twin/bus/can.py", "nowhere.py"]
