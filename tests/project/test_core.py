"""The compiled core (docs/architecture.md, "The compiled core"): built by the install, reported
by ``--version``, and set aside by ``HUMANOID_TWIN_PURE_PYTHON=1``, where every module of the
package runs from its ``.py`` source (breakpoints in the firmware work there).

The golden runs (tests/golden/test_golden.py) check that both cores give the same bytes."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

import humanoid_twin
from humanoid_twin import core


def _python(code: str, pure: bool) -> str:
    env = dict(os.environ)
    env.pop(core.PURE_PYTHON_ENV, None)
    if pure:
        env[core.PURE_PYTHON_ENV] = "1"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip()


def _built() -> bool:
    """True unless this install was asked not to compile (HUMANOID_TWIN_NO_COMPILE at install)."""
    return not os.environ.get("HUMANOID_TWIN_NO_COMPILE")


PROBE = ("import humanoid_twin.scenarios, humanoid_twin.core as c; "
         "print(c.core_kind()); print(','.join(c.compiled_modules()))")


def test_the_install_runs_the_compiled_core_and_version_says_so():
    if not _built():
        pytest.skip("installed with HUMANOID_TWIN_NO_COMPILE: no compiled core to check")
    kind, modules = _python(PROBE, pure=False).splitlines()
    assert kind == "compiled", "pip install -e . built no core: is Cython or a C compiler missing?"
    compiled = set(modules.split(","))
    # the per-event path: the clock, the wires, and both boards' firmware
    for name in ("humanoid_twin.clock", "humanoid_twin.bus.network", "humanoid_twin.master.pic",
                 "humanoid_twin.slave.slave"):
        assert name in compiled, f"{name} is not compiled (compiled: {sorted(compiled)})"
    r = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "--version"],
                       capture_output=True, text=True, timeout=60,
                       env={k: v for k, v in os.environ.items() if k != core.PURE_PYTHON_ENV})
    assert r.returncode == 0 and r.stdout.strip().endswith("(core: compiled)"), r.stdout + r.stderr


@pytest.mark.slow
def test_pure_python_env_loads_every_module_from_its_source():
    kind, modules = (_python(PROBE, pure=True).splitlines() + [""])[:2]
    assert kind == "python"
    assert modules == ""
    where = _python("import humanoid_twin.slave.slave as s, humanoid_twin.clock as c; "
                    "print(s.__file__); print(c.__file__)", pure=True).splitlines()
    assert all(w.endswith(".py") for w in where), where
    r = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "--version"],
                       capture_output=True, text=True, timeout=60,
                       env={**os.environ, core.PURE_PYTHON_ENV: "1"})
    assert r.returncode == 0 and r.stdout.strip().endswith("(core: python)"), r.stdout + r.stderr


def test_pure_python_switch_reads_only_set_values(monkeypatch):
    for value, pure in (("1", True), ("yes", True), ("0", False), ("", False)):
        monkeypatch.setenv(core.PURE_PYTHON_ENV, value)
        assert core.pure_python_requested() is pure, value


def test_this_process_core_matches_the_switch():
    expected = "python" if core.pure_python_requested() or not _built() else "compiled"
    assert core.core_kind() == expected
    assert humanoid_twin.__version__


def test_a_compiled_module_older_than_its_source_is_named(tmp_path):
    pkg = tmp_path / "humanoid_twin"
    (pkg / "bus").mkdir(parents=True)
    (tmp_path / "setup.py").write_text("")
    for name in ("clock", "bus/network"):
        for suffix in (".py", ".pxd", ".cpython-311-x86_64-linux-gnu.so"):
            (pkg / (name + suffix)).write_text("")
    assert core.stale_modules(pkg) == [] or core.pure_python_requested()
    source = pkg / "bus" / "network.py"
    built = pkg / "bus" / "network.cpython-311-x86_64-linux-gnu.so"
    os.utime(source, (built.stat().st_mtime + 10, built.stat().st_mtime + 10))
    if not core.pure_python_requested():
        assert core.stale_modules(pkg) == ["humanoid_twin.bus.network"]
    (tmp_path / "setup.py").unlink()               # an installed package: never stale
    assert core.stale_modules(pkg) == []


def _source_tree_with_an_old_build(tmp_path):
    """A copy of the package as an editable install has it (``setup.py`` beside it) whose compiled
    clock is older than ``clock.py``: an edit not rebuilt. The compiled module is this install's
    own when it has one, else a file that cannot be loaded at all (either must not run)."""
    import importlib.machinery
    import shutil
    from pathlib import Path

    src = Path(humanoid_twin.__file__).resolve().parent
    shutil.copytree(src, tmp_path / "humanoid_twin",
                    ignore=shutil.ignore_patterns("*.so", "*.pyd", "__pycache__"))
    (tmp_path / "setup.py").write_text("")
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    built = tmp_path / "humanoid_twin" / f"clock{suffix}"
    mine = sorted(src.glob("clock.*.so"))
    if mine:
        shutil.copy2(mine[0], built)
    else:
        built.write_bytes(b"an old build of clock.py")
    source = tmp_path / "humanoid_twin" / "clock.py"
    old = source.stat().st_mtime - 60
    os.utime(built, (old, old))
    return tmp_path


def test_an_edit_not_rebuilt_runs_its_source_with_a_warning_from_python(tmp_path):
    # a script (or a notebook) importing the package, not the CLI: it runs the edited source, and
    # a warning on stderr names the stale module and points at the script's import line
    tree = _source_tree_with_an_old_build(tmp_path)
    script = tree / "user_script.py"
    script.write_text("import humanoid_twin.scenarios\n"
                      "import humanoid_twin.clock as c, humanoid_twin.core as k\n"
                      "print(c.__file__); print(k.core_kind())\n")
    env = {k: v for k, v in os.environ.items() if k not in (core.PURE_PYTHON_ENV, "PYTHONWARNINGS")}
    env["PYTHONPATH"] = str(tree)
    r = subprocess.run([sys.executable, script.name], cwd=tree, capture_output=True, text=True, timeout=120,
                       env=env)
    assert r.returncode == 0, r.stderr
    where, kind = r.stdout.split()
    assert where == str(tree / "humanoid_twin" / "clock.py") and kind == "python"
    assert "user_script.py:1: StaleCoreWarning: humanoid-twin: the compiled core is older than its source " \
           "(humanoid_twin.clock): running the source instead" in r.stderr, r.stderr
    assert "scripts/build_core.py" in r.stderr
    assert r.stderr.count("StaleCoreWarning") == 1, r.stderr


def test_the_stale_check_at_import_is_cheap():
    import time

    t0 = time.perf_counter()
    for _ in range(10):
        core.stale_modules()
    assert (time.perf_counter() - t0) / 10 < 0.05
