"""Issue 36, the run's limits that hold whatever user code does (docs/scenarios.md, "What the twin
guarantees"): ``--duration`` over a scenario's ``drive`` and over the boot, a scenario's
``motion_s`` checked like ``--duration``, ``--wall-timeout`` (and a sweep's ``--timeout``) armed
from the first line, a diverged simulation never reported as a run, a law's cost judged once."""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest
from helpers import CLI

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)


SCENARIOS = '''
import math
import sys
from dataclasses import dataclass

from humanoid_twin.scenarios import REGISTRY, Scenario, hold

STAND = REGISTRY["stand"].factory


class Oversleep(Scenario):
    """Says its program lasts 1 s, sleeps 30 s."""
    def motion_s(self, plan):
        return 1.0

    def drive(self, rig, plan):
        rig.sleep(30.0)


class Swallower(Scenario):
    """Swallows the run's end 50 times, then returns."""
    def motion_s(self, plan):
        return 1.0

    def drive(self, rig, plan):
        for _ in range(50):
            try:
                rig.sleep(1.0)
            except BaseException:
                pass


@dataclass(frozen=True)
class Length(Scenario):
    """motion_s returns ``value`` at its ``bad_call``-th call in this process (0: always), 1.0
    otherwise; in the sweep's own process (its checks), always 1.0."""
    value: object = None
    bad_call: int = 0
    calls: list = None

    def motion_s(self, plan):
        self.calls.append(1)
        if "sweep" in sys.argv:
            return 1.0
        return self.value if self.bad_call in (0, len(self.calls)) else 1.0


def length(name, value, bad_call=0):
    return Length(name, STAND, moves=False, value=value, bad_call=bad_call, calls=[])


class Huge(float):
    def __float__(self):
        raise OverflowError("too big to say")


nan = length("nan", math.nan)
inf = length("inf", math.inf)
text = length("text", "abc")
huge = length("huge", 1e12)
negative = length("negative", -1.0)
boolean = length("boolean", True)
hostile = length("hostile", Huge(3.0))
second_nan = length("second_nan", math.nan, bad_call=2)   # the CLI's sizing of the outputs
third_inf = length("third_inf", math.inf, bad_call=3)     # scenarios.run's own call


class LoopsInMotion(Scenario):
    def motion_s(self, plan):
        while True:
            pass


def loops(T, motion, perna):
    while True:
        pass


@dataclass(frozen=True)
class Shove(Scenario):
    force_n: float = 1e6

    def motion_s(self, plan):
        return 1.0

    def drive(self, rig, plan):
        hold(rig.H, plan)
        rig.sleep(0.3)
        rig.twin.plant.set_trunk_force(self.force_n)
        rig.sleep(0.1)
        rig.twin.plant.set_trunk_force(0.0)


oversleep = Oversleep("oversleep", STAND, moves=False)
swallower = Swallower("swallower", STAND, moves=False)
loops_in_motion = LoopsInMotion("loops_in_motion", STAND, moves=False)
loops_in_plan = Scenario("loops_in_plan", loops, moves=False)
mega = Shove("mega", STAND, moves=False)
tera = Shove("tera", STAND, moves=False, force_n=1e12)
'''


@pytest.fixture
def user(tmp_path: Path) -> Path:
    (tmp_path / "user.py").write_text(SCENARIOS)
    (tmp_path / "hangs_on_import.py").write_text("while True:\n    pass\n")
    return tmp_path


def _cli(cwd: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout)


def _run_json(cwd: Path, *args: str) -> tuple[subprocess.CompletedProcess, dict]:
    res = _cli(cwd, "run", *args, "--json", "--no-progress")
    lines = res.stdout.splitlines()
    assert len(lines) == 1, (res.stdout, res.stderr)
    return res, json.loads(lines[0])


def _no_partials(where: Path) -> None:
    assert not [p.name for p in where.iterdir() if p.name.startswith(".partial")]


# -- --duration holds over the scenario's program and over the boot (points 3, 17) ------------------
def test_duration_holds_over_a_drive_that_sleeps_past_its_motion_s(user: Path) -> None:
    """Before: ``--duration 4`` ran to 32.65 simulated s (the drive's own 30 s sleep)."""
    res, s = _run_json(user, "user.py:oversleep", "--duration", "4", "--can-log", "x.csv")
    assert res.returncode == 0, res.stderr
    assert s["duration_s"] == 4.0 and s["completed"] is False, s
    last_frame_s = float((user / "x.csv").read_text().splitlines()[-1].split(",")[0])
    assert last_frame_s <= 4.0


def test_the_default_end_holds_over_a_drive_that_overruns_and_one_that_swallows_it(user: Path) -> None:
    """Without --duration the run ends at boot + motion_s + 2 s (what the outputs were sized by);
    a drive that swallows that end (``except BaseException``) gets it again at the same instant:
    simulated time never passes it."""
    res, s = _run_json(user, "user.py:oversleep", "--no-record")
    assert res.returncode == 0, res.stderr
    assert s["duration_s"] == pytest.approx(s["boot_s"] + 1.0 + 2.0, abs=1e-3) and s["completed"] is False, s
    res, s = _run_json(user, "user.py:swallower", "--duration", "4", "--no-record")
    assert res.returncode == 0, res.stderr
    assert s["duration_s"] == 4.0 and s["completed"] is False, s


@pytest.mark.parametrize("duration, fault, code", [
    ("2.7", "can-corrupt:0.2", 3),      # the boot took 5.07 s: the supervisor went safe meanwhile
    ("2.6", None, 0),                   # the boot takes ~2.65 s: 2.6 passes the check (>= 2.5)
])
def test_a_duration_that_ends_inside_the_boot_is_a_run_with_a_summary(user: Path, duration: str,
                                                                      fault: str | None, code: int) -> None:
    """Before: exit 2 after the whole boot had run, no summary. Now the run ends at --duration,
    its summary says the boot did not end (``boot_s`` none, ``completed`` false), one warning line."""
    (user / "x.rrd").write_bytes(b"old")
    extra = ("--fault", fault) if fault else ()
    res, s = _run_json(user, "stand", "--duration", duration, "--out", "x.rrd", *extra)
    assert res.returncode == code, res.stderr
    assert s["duration_s"] == float(duration) and s["boot_s"] is None and s["completed"] is False, s
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "before the boot did" in err[0], res.stderr
    assert (user / "x.rrd").read_bytes() != b"old"      # a run like any other: its recording kept
    _no_partials(user)


# -- motion_s checked like --duration (points 9, 11) ----------------------------------------------
@pytest.mark.parametrize("name, said", [
    ("nan", "returned nan"),
    ("inf", "returned inf"),
    ("text", "returned 'abc' (str): not a number"),
    ("huge", "returned 1000000000000.0: must be a finite number of simulated seconds, 0..86400"),
    ("negative", "returned -1.0"),
    ("boolean", "returned True (bool)"),
    ("hostile", "returned a number whose float() raised OverflowError: too big to say"),
    ("second_nan", "returned nan"),
    ("third_inf", "returned inf"),
])
def test_a_motion_s_that_is_not_a_length_is_one_line_exit_2_nothing_replaced(user: Path, name: str,
                                                                             said: str) -> None:
    (user / "x.csv").write_text("an earlier log\n")
    res = _cli(user, "run", f"user.py:{name}", "--no-record", "--can-log", "x.csv", "--no-progress",
               timeout=60)
    assert res.returncode == 2, res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and f"scenario user.py:{name}: its motion_s {said}" in err[0], res.stderr
    assert res.stdout == "" and (user / "x.csv").read_text() == "an earlier log\n"
    _no_partials(user)


def test_a_sweep_row_of_a_bad_motion_s_is_one_line_not_a_traceback(user: Path) -> None:
    """The sweep's own checks see 1.0; each run's process sees NaN: the rows say why in one line."""
    res = _cli(user, "sweep", "user.py:nan", "--param", "tilt=1,2", "--out", "t.csv", "--no-progress")
    assert res.returncode == 102, res.stderr
    rows = (user / "t.csv").read_text().splitlines()[1:]
    assert len(rows) == 2, rows
    assert all("its motion_s returned nan" in r and "Traceback" not in r for r in rows), rows


# -- --wall-timeout armed from the first line (points 7, 13) -----------------------------------------
@pytest.mark.parametrize("ref", ["hangs_on_import.py:x", "user.py:loops_in_motion", "user.py:loops_in_plan"])
def test_wall_timeout_ends_a_scenario_that_hangs_while_loaded_planned_or_sized(user: Path, ref: str) -> None:
    """Before: not armed until the twin was built: ``run`` hung for ever."""
    (user / "x.rrd").write_bytes(b"old")
    t0 = time.monotonic()
    res = _cli(user, "run", ref, "--out", "x.rrd", "--wall-timeout", "3", "--no-progress", timeout=60)
    assert time.monotonic() - t0 < 30
    assert res.returncode == 1, res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "took more than 3 wall seconds (--wall-timeout)" in err[0], res.stderr
    assert (user / "x.rrd").read_bytes() == b"old"
    _no_partials(user)


def test_a_sweep_s_timeout_bounds_its_own_check_of_a_scenario_that_hangs(user: Path) -> None:
    t0 = time.monotonic()
    res = _cli(user, "sweep", "user.py:loops_in_motion", "--param", "tilt=1,2", "--out", "t.csv",
               "--timeout", "3", "--no-progress", timeout=60)
    assert time.monotonic() - t0 < 30
    assert res.returncode == 1, res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "took more than 3 wall seconds (--timeout)" in err[0], res.stderr
    assert not (user / "t.csv").exists()


@pytest.mark.parametrize("value", ["1e-5", "1e-9", "1e-300"])
def test_a_tiny_wall_timeout_is_one_line_exit_1_not_a_traceback(user: Path, value: str) -> None:
    (user / "x.rrd").write_bytes(b"old")
    res = _cli(user, "run", "stand", "--out", "x.rrd", "--wall-timeout", value, "--no-progress", timeout=60)
    assert res.returncode == 1, res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "(--wall-timeout)" in err[0] and "Traceback" not in res.stderr, res.stderr
    assert (user / "x.rrd").read_bytes() == b"old"
    _no_partials(user)


# -- a diverged simulation is not a run (point 18) --------------------------------------------------
@pytest.mark.parametrize("name", ["mega", "tera"])
def test_a_diverged_simulation_ends_the_run_outcome_diverged_exit_1(user: Path, name: str) -> None:
    """Before: 1e6 N gave ``fell``, exit 0; 1e12 N ``held``, exit 0 (MuJoCo had reset the state);
    only MuJoCo's warning on stderr said otherwise."""
    (user / "x.rrd").write_bytes(b"old")
    res, s = _run_json(user, f"user.py:{name}", "--out", "x.rrd")
    assert res.returncode == 1, res.stderr
    assert s["outcome"] == "diverged" and s["completed"] is False, s
    assert "MuJoCo: NaN, Inf or huge value in QACC" in s["diverged"], s
    assert s["duration_s"] < 3.1, s                     # ended there (the shove at ~2.95 s), not at 5.65
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "the simulation diverged" in err[0], res.stderr
    assert (user / "x.rrd").read_bytes() == b"old"
    _no_partials(user)


# -- a law's cost, asked once per board and seen by the supervisor however large (points 14, 16) -----
LAWS = '''
from humanoid_twin.slave.laws import JacobianLaw

answers = [0]


class Changing(JacobianLaw):
    """Its cost is valid for the CLI's check and SCU 1's instance, not for SCU 2's."""
    def cycles(self):
        answers[0] += 1
        return 100 if answers[0] <= 2 else "lots"


class Costly(JacobianLaw):
    cycles = 200_000_000            # 20 s of one PIC18 at 10 MIPS, per call


class Costliest(JacobianLaw):
    cycles = 2**31 - 1              # the largest cost a law may declare (~215 s)
'''


@pytest.fixture
def laws(tmp_path: Path) -> Path:
    (tmp_path / "costly_laws.py").write_text(LAWS)
    return tmp_path


def test_a_law_whose_cost_turns_invalid_on_a_board_is_one_line_exit_2(laws: Path) -> None:
    """Before: a ValueError traceback from the board's own reading of the cost."""
    (laws / "x.rrd").write_bytes(b"old")
    res = _cli(laws, "run", "stand", "--out", "x.rrd", "--no-progress",
               "--law", "balance=costly_laws:Changing", timeout=60)
    assert res.returncode == 2, res.stderr
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and "law Changing for SCU 2: ValueError: a law's cycles must" in err[0], res.stderr
    assert (laws / "x.rrd").read_bytes() == b"old"
    _no_partials(laws)


@pytest.mark.parametrize("law", ["Costly", "Costliest"])
def test_a_law_that_overruns_by_seconds_is_flagged_when_its_period_ends(laws: Path, law: str) -> None:
    """Before: the overrun was flagged only when the pass ended, 20 s to 215 s later: never within
    the run (exit 0, mode ready, task load 1000 to 10 737). Now the period's end sets the deadline
    bit the Master reads: the supervisor's ``deadline`` fault, ``safe``, exit 3."""
    res, s = _run_json(laws, "stand", "--no-record", "--law", f"balance=costly_laws:{law}")
    assert res.returncode == 3, res.stderr
    assert s["mode"] == "safe" and s["task_load_max"]["slaves"] >= 1000, s
    assert s["deadline_misses"]["1"] >= 1 and s["deadline_misses"]["2"] >= 1, s
    assert {(f["name"], f["node"]) for f in s["faults"]} >= {("deadline", 1), ("deadline", 2)}, s
