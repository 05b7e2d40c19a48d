"""The package's layers: the command line (``humanoid_twin/cli``) sits on top of the library, and
nothing below it imports it (the library takes typed options, never argparse namespaces).
Who may import MuJoCo: tests/test_package_layers.py."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "humanoid_twin"
CLI = PACKAGE / "cli"


def _imports_cli(path: Path) -> list[str]:
    """Every import of ``humanoid_twin.cli`` in ``path`` (top level or inside a function)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [a.name for a in node.names if a.name.startswith("humanoid_twin.cli")]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.startswith("humanoid_twin.cli"):
                found.append(node.module)
            elif node.module == "humanoid_twin" and any(a.name == "cli" for a in node.names):
                found.append("humanoid_twin.cli")
    return found


def test_no_module_below_the_cli_imports_the_cli() -> None:
    below = [p for p in PACKAGE.rglob("*.py") if CLI not in p.parents]
    assert len(below) > 50                       # the scan sees the package
    offenders = {str(p.relative_to(PACKAGE)): _imports_cli(p) for p in below}
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, offenders


def test_the_scan_finds_an_upward_import(tmp_path: Path) -> None:
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from humanoid_twin.cli.argtypes import checked\n")
    assert _imports_cli(f) == ["humanoid_twin.cli.argtypes"]
    f.write_text("import humanoid_twin.cli.main as m\nfrom humanoid_twin import cli\n")
    assert _imports_cli(f) == ["humanoid_twin.cli.main", "humanoid_twin.cli"]
