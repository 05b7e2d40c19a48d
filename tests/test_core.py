"""The compiled core (docs/architecture.md, "The compiled core"): built by the install, reported
by ``--version``, and set aside by ``HUMANOID_TWIN_PURE_PYTHON=1``, where every module of the
package runs from its ``.py`` source (breakpoints in the firmware work there).

The golden runs (tests/test_golden.py) check that both cores give the same bytes."""

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
