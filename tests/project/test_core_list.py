"""The compiled core is named in one list (humanoid_twin/core_modules.py; docs/architecture.md,
"The compiled core"): every ``.pxd`` of the package has its module in the list and every module
of the list has its ``.py`` and ``.pxd``; the build compiles exactly the list's modules, the stale
check compares exactly them, and docs/architecture.md shows the list as it is."""

from __future__ import annotations

import importlib.util
import os
import re

from helpers import REPO

from humanoid_twin import core
from humanoid_twin.core_modules import CORE_MODULES, core_modules_markdown, source_path

ROOT = REPO
PKG = ROOT / "humanoid_twin"


def _setup_py():  # noqa: ANN202 - setup.py as a module
    spec = importlib.util.spec_from_file_location("_humanoid_twin_setup", ROOT / "setup.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)     # setup.py only defines the build when imported
    return module


def test_every_pxd_is_in_the_list_and_every_listed_module_has_its_pxd() -> None:
    pxd_modules = {".".join(p.relative_to(ROOT).with_suffix("").parts) for p in PKG.rglob("*.pxd")}
    not_listed = sorted(pxd_modules - set(CORE_MODULES))
    assert not_listed == [], f"a .pxd whose module humanoid_twin/core_modules.py does not name: {not_listed}"
    without_pxd = sorted(m for m in CORE_MODULES if not (ROOT / source_path(m)).with_suffix(".pxd").is_file())
    assert without_pxd == [], f"listed in humanoid_twin/core_modules.py without a .pxd: {without_pxd}"
    without_py = sorted(m for m in CORE_MODULES if not (ROOT / source_path(m)).is_file())
    assert without_py == [], f"listed in humanoid_twin/core_modules.py without a .py: {without_py}"


def test_each_entry_says_why_in_a_line() -> None:
    for module, why in CORE_MODULES.items():
        assert module.startswith("humanoid_twin."), module
        assert 10 <= len(why) <= 100 and "\n" not in why, f"{module}: {why!r}"


def test_the_list_loads_without_the_package() -> None:
    # setup.py reads it by its path in an isolated build: it must import nothing of the package
    # or of its dependencies
    text = (PKG / "core_modules.py").read_text()
    imports = re.findall(r"^\s*(?:from\s+(\S+)\s+)?import\s+(\S+)", text, re.M)
    assert imports == [("__future__", "annotations")], imports


def test_the_build_compiles_exactly_the_listed_modules() -> None:
    build = _setup_py()
    exts = build.core_extensions()
    assert [e.name for e in exts] == list(CORE_MODULES)
    assert [e.sources for e in exts] == [[source_path(m)] for m in CORE_MODULES]
    assert [e.name for e in build.core_extensions(("humanoid_twin.slave",))] == [
        m for m in CORE_MODULES if m.startswith("humanoid_twin.slave.")]


def test_the_stale_check_compares_the_listed_modules_only(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv(core.PURE_PYTHON_ENV, raising=False)
    pkg = tmp_path / "humanoid_twin"
    (pkg / "slave").mkdir(parents=True)
    (tmp_path / "setup.py").write_text("")
    so = ".cpython-311-x86_64-linux-gnu.so"
    for name in ("slave/servo", "not_in_the_core"):       # a .pxd and a .so beside a .py both
        for suffix in (so, ".py", ".pxd"):
            (pkg / (name + suffix)).write_text("")
        built = (pkg / (name + so)).stat().st_mtime
        os.utime(pkg / (name + ".py"), (built + 10, built + 10))
    assert core.stale_modules(pkg) == ["humanoid_twin.slave.servo"]


def test_docs_show_the_list() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text()
    m = re.search(r"<!-- generated: core-modules -->\n(.*?)<!-- end generated: core-modules -->", text, re.S)
    assert m, "docs/architecture.md: no generated block 'core-modules'"
    assert m.group(1) == core_modules_markdown(), "run scripts/gen_docs.py"
