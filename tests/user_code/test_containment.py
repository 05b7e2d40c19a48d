"""Issue 24, point 5: a containment the law cannot escape, --duration bounds host controllers,
--wall-timeout ends a run that takes too long (one line, exit 1, files closed, nothing replaced)."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import pytest
from helpers import CLI

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)


LAWS = '''
import sys
from humanoid_twin.slave.laws import ControlLaw

class Hostile:
    def __len__(self):
        raise RuntimeError("no len")
    def __getitem__(self, i):
        raise RuntimeError("no item")
    def __repr__(self):
        raise RuntimeError("no repr")

class HostileLaw(ControlLaw):
    def step(self, inputs):
        return Hostile()

class BadIndexLaw(ControlLaw):
    def step(self, inputs):
        class Three:
            def __len__(self):
                return 3
            def __getitem__(self, i):
                raise ValueError("x" * 100000)
            def __repr__(self):
                return "y" * 100000
        return Three()

class ExitLaw(ControlLaw):
    def step(self, inputs):
        sys.exit(0)

class InterruptLaw(ControlLaw):
    def step(self, inputs):
        raise KeyboardInterrupt

class HugeLaw(ControlLaw):
    def step(self, inputs):
        return [0] * 2_000_000

made = [0]

class SecondFails(ControlLaw):
    def __init__(self):
        made[0] += 1
        if made[0] > 2:
            raise RuntimeError("only two")
'''

CONTROLLERS = '''
import sys
import time

def exits(ctx):
    sys.exit(0)

def sleeps(ctx):
    ctx.host.sleep(10.0)

def swallows(ctx):
    while True:
        try:
            ctx.host.sleep(1.0)
        except Exception:
            pass

def swallows_all(ctx):
    while True:
        try:
            ctx.host.sleep(1.0)
        except BaseException:
            pass

def forever(ctx):
    time.sleep(3600)
'''


@pytest.fixture
def plugins(tmp_path: Path) -> Path:
    (tmp_path / "hostile_laws.py").write_text(LAWS)
    (tmp_path / "hostile_ctl.py").write_text(CONTROLLERS)
    return tmp_path


def _run(cwd: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, "run", "stand", "--no-progress", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout)


@pytest.mark.parametrize("law,why", [
    ("HostileLaw", "step returned <Hostile object>: expected 3 ints"),
    ("BadIndexLaw", "its item 0 raised ValueError: xxx"),
    ("ExitLaw", "step raised SystemExit"),
    ("InterruptLaw", "step raised KeyboardInterrupt"),
    ("HugeLaw", "step returned <list of 2000000 items>"),
])
def test_a_hostile_law_is_stopped_as_the_law_s_fault(plugins: Path, law: str, why: str) -> None:
    res = _run(plugins, "--duration", "3.5", "--no-record", "--json", "--law", f"balance=hostile_laws:{law}")
    assert res.returncode == 3, res.stderr              # the supervisor's law fault: safe, exit 3
    assert "Traceback" not in res.stderr and why in res.stderr, res.stderr
    assert max(len(line) for line in res.stderr.splitlines()) < 600
    assert len(res.stdout) < 20_000
    assert '"name": "law"' in res.stdout.splitlines()[-1]


def test_a_law_that_fails_on_a_board_s_instance_is_a_usage_error(plugins: Path) -> None:
    res = _run(plugins, "--duration", "3", "--out", "x.rrd", "--law", "balance=hostile_laws:SecondFails")
    assert res.returncode == 2 and "cannot be made for SCU 2" in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in plugins.iterdir() if not p.name.startswith("__")) == [
        "hostile_ctl.py", "hostile_laws.py"]


def test_sys_exit_in_a_host_controller_is_one_line_exit_1(plugins: Path) -> None:
    res = _run(plugins, "--duration", "3.5", "--no-record", "--host-controller", "hostile_ctl:exits")
    assert res.returncode == 1 and "hostile_ctl:exits raised SystemExit at t=" in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and res.stdout == ""


@pytest.mark.parametrize("ctl", ["sleeps", "swallows"])
def test_duration_bounds_a_host_controller(plugins: Path, ctl: str) -> None:
    res = _run(plugins, "--duration", "4", "--no-record", "--json", "--host-controller", f"hostile_ctl:{ctl}")
    assert res.returncode == 0, res.stderr
    last = res.stdout.splitlines()[-1]
    assert '"duration_s": 4.0,' in last and '"completed": true' in last, last


@pytest.mark.parametrize("ctl", ["forever", "swallows_all"])
def test_wall_timeout_ends_a_controller_that_never_returns(plugins: Path, ctl: str) -> None:
    # time.sleep(3600) in wall time; or a loop that swallows even the end of the run
    (plugins / "x.rrd").write_bytes(b"old")
    t0 = time.monotonic()
    res = _run(plugins, "--duration", "4", "--out", "x.rrd", "--wall-timeout", "6",
               "--host-controller", f"hostile_ctl:{ctl}")
    assert time.monotonic() - t0 < 30
    assert res.returncode == 1, res.stderr
    assert "took more than 6 wall seconds" in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert (plugins / "x.rrd").read_bytes() == b"old"
    assert not [p for p in plugins.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("value", ["0", "-1", "inf", "nan", "1e300"])
def test_bad_wall_timeout_is_one_line_exit_2(plugins: Path, value: str) -> None:
    res = _run(plugins, "--duration", "3", "--no-record", "--wall-timeout", value, timeout=60)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
