"""User scenarios from the command line (docs/scenarios.md, "Your own scenario"): a scenario in a
file (``FILE.py:NAME``) or a module (``MODULE:NAME``) runs with run's options and in a sweep; one
that cannot be loaded is one line and exit 2, one that fails in its own code one line and exit 1."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
from helpers import REPO

from humanoid_twin.cli.main import main
from humanoid_twin.recording.readback import read_rrd_rows
from humanoid_twin.sweep import read_table

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)


EXAMPLE = REPO / "examples" / "push_recovery.py"


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict, str]:
    code = main(["run", *argv, "--json", "--no-progress"])
    out, err = capsys.readouterr()
    return code, json.loads(out), err


def test_the_push_recovery_example_runs_from_the_cli_with_run_s_options(capsys, tmp_path):
    """Two 5 N shoves (``gentle``): the robot recovers, and the shoves show in its trunk tilt
    (the same stand without them stays straighter), in the recording and on the CAN log."""
    out, log = tmp_path / "push.rrd", tmp_path / "push.csv"
    code, s, err = _run(capsys, f"{EXAMPLE}:gentle", "--out", str(out), "--can-log", str(log),
                        "--law", "balance=humanoid_twin.slave.laws:JacobianLaw", "--seed", "1")
    assert code == 0, err
    assert s["scenario"] == f"{EXAMPLE}:gentle" and s["completed"] and s["outcome"] == "held", s
    assert s["duration_s"] == pytest.approx(s["boot_s"] + 2 * 1.5 + 2.0, abs=0.05)   # its own length
    code, still, _ = _run(capsys, "stand", "--duration", str(s["duration_s"]), "--seed", "1",
                          "--out", str(tmp_path / "still.rrd"))
    assert s["trunk_tilt_max_deg"] > still["trunk_tilt_max_deg"] + 0.5, (s, still)
    assert out.exists() and log.exists() and s["recording"] == str(out)
    # the event log: the stand's own (the supervisor's modes), and "push +5 N ...", "push -5 N ..."
    events = read_rrd_rows(out)["supervisor/events"]
    assert events == read_rrd_rows(tmp_path / "still.rrd")["supervisor/events"] + 2


def test_a_user_scenario_from_a_module_and_in_a_two_run_sweep(capsys, tmp_path, monkeypatch):
    """``MODULE:NAME`` (the current directory importable, as ``python -m``), and the file in a
    sweep of two seeds: every run, in its own process, loads it."""
    monkeypatch.chdir(REPO)
    code, s, _ = _run(capsys, "examples.push_recovery:gentle", "--duration", "4", "--no-record")
    assert code == 0 and s["completed"] is False and s["duration_s"] == pytest.approx(4.0, abs=0.01)
    table = tmp_path / "pushes.csv"
    code = main(["sweep", "examples/push_recovery.py:gentle", "--param", "seed=0,1", "--out", str(table),
                 "--jobs", "2", "--no-progress", "--duration", "4"])
    assert code == 0, capsys.readouterr().err
    rows = read_table(table)
    assert sorted(int(r["seed"]) for r in rows) == [0, 1] and not any(r.get("error") for r in rows), rows
    assert all(r["scenario"] == "examples/push_recovery.py:gentle" for r in rows)   # as given (issue 37)
    assert rows[0]["trunk_tilt_max_deg"] != rows[1]["trunk_tilt_max_deg"]     # two seeds, two runs


BROKEN = '''
from humanoid_twin.scenarios import REGISTRY, Scenario


class Boom(Scenario):
    def drive(self, rig, plan):
        raise ZeroDivisionError("the experiment divided by zero")


class SlowBoom(Scenario):
    def motion_s(self, plan):
        raise KeyError("no such motion")


boom = Boom("boom", REGISTRY["stand"].factory, moves=False)
slow_boom = SlowBoom("slow_boom", REGISTRY["stand"].factory, moves=False)
not_a_scenario = 42
alias = REGISTRY["stand"]            # the reference says alias, the scenario's name is stand
nameless = Boom("", REGISTRY["stand"].factory, moves=False)
'''


@pytest.mark.parametrize("ref, message", [
    ("{dir}/missing.py:x", "no such file"),
    ("{dir}/user.py:nope", "has no 'nope'"),
    ("{dir}/user.py:not_a_scenario", "is not a Scenario (got int"),
    ("{dir}/user.py:nameless", "cannot name a file"),
    ("{dir}/syntax.py:x", "cannot import"),
    ("no_such_module_xyz:x", "cannot import no_such_module_xyz"),
    ("walk", "invalid choice: 'walk'"),
])
def test_a_scenario_that_cannot_be_loaded_is_one_line_exit_2_nothing_written(capsys, tmp_path, ref, message):
    (tmp_path / "user.py").write_text(BROKEN)
    (tmp_path / "syntax.py").write_text("def (:\n")
    log = tmp_path / "x.asc"
    with pytest.raises(SystemExit) as exc:
        main(["run", ref.format(dir=tmp_path), "--no-record", "--can-log", str(log)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err, err
    assert not log.exists() and [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_scenario_that_fails_in_its_own_code_is_one_line_exit_1_nothing_replaced(capsys, tmp_path):
    (tmp_path / "user.py").write_text(BROKEN)
    log = tmp_path / "x.asc"
    log.write_text("an earlier log\n")
    code = main(["run", f"{tmp_path}/user.py:boom", "--no-record", "--can-log", str(log), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1 and len(err.strip().splitlines()) == 1, err
    assert f"scenario {tmp_path}/user.py:boom raised ZeroDivisionError: the experiment divided by zero" in err
    assert log.read_text() == "an earlier log\n"


def test_a_scenario_whose_motion_s_raises_is_one_line_exit_1_nothing_replaced(capsys, tmp_path):
    (tmp_path / "user.py").write_text(BROKEN)
    log = tmp_path / "x.asc"
    log.write_text("an earlier log\n")
    with pytest.raises(SystemExit) as exc:
        main(["run", f"{tmp_path}/user.py:slow_boom", "--no-record", "--can-log", str(log), "--no-progress"])
    err = capsys.readouterr().err
    assert exc.value.code == 1 and len(err.strip().splitlines()) == 1, err
    assert f"scenario {tmp_path}/user.py:slow_boom raised KeyError: " in err and "in its motion_s" in err, err
    assert log.read_text() == "an earlier log\n"


def test_run_and_sweep_name_recordings_after_the_scenario_s_own_name(capsys, tmp_path, monkeypatch):
    """One rule (docs/scenarios.md): the object's ``name``, not the reference's NAME."""
    from humanoid_twin.sweep.engine import Point, RunCli

    (tmp_path / "user.py").write_text(BROKEN)
    monkeypatch.chdir(tmp_path)
    code = main(["run", "user.py:alias", "--duration", "3", "--no-progress"])
    assert code == 0 and (tmp_path / "stand.rrd").is_file(), capsys.readouterr().err
    argv = RunCli(f"{tmp_path}/user.py:alias", recordings="recs").argv(Point(0, (("tilt", "5"),), 1))
    assert f"--out={Path('recs') / 'stand_tilt=5_seed=1.rrd'}" in argv, argv


def test_an_entry_point_scenario_runs_by_its_name(capsys, tmp_path, monkeypatch):
    """A package declares ``[humanoid_twin.scenarios] boom = ...``: ``run boom`` loads it."""
    pkg = tmp_path / "ht_user_scen"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(BROKEN)
    dist = tmp_path / "ht_user_scen-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: ht-user-scen\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent("""
        [humanoid_twin.scenarios]
        boom = ht_user_scen:boom
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    code = main(["run", "boom", "--no-record", "--no-progress"])
    assert code == 1 and "scenario boom raised ZeroDivisionError" in capsys.readouterr().err
