"""The Python API (README.md, "From Python"): ``humanoid_twin.open`` gives a run of a scenario,
booted, to step, read, drive and close from a script or a notebook, with the options of
``humanoid-twin run`` (``RunOptions``); the recording is written as ``run --out`` writes it (under
a temporary name, renamed at the close; a failed session replaces nothing)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import humanoid_twin
from humanoid_twin import scenarios
from humanoid_twin.recording.paths import ROBOT
from humanoid_twin.recording.readback import read_rrd_scalars
from humanoid_twin.scenarios import RunOptions, ScenarioInputError

# what differs between two runs of the same options: the wall clock, and where the files went
WALL_KEYS = {"wall_s", "rtf", "recording"}


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_open_step_read_drive_finish_records_where_asked(tmp_path: Path) -> None:
    out = tmp_path / "flexao.rrd"
    with humanoid_twin.open(RunOptions("flexao", out=out)) as run:
        assert run.now_s == pytest.approx(run.boot_s) and 2.5 < run.boot_s < 3.0     # booted
        assert _files(tmp_path) == [f".partial-{os.getpid()}-flexao.rrd"]   # renamed at the close
        obs = run.step(0.02)
        assert obs["t_s"] == pytest.approx(run.boot_s + 0.02)
        assert obs["mode"] == "ready" and not obs["fell"] and abs(obs["trunk_tilt_deg"]) < 5
        assert len(obs["joints_deg"]) >= 12 and obs["cop_margin_mm"] > 0
        knees = {k: v for k, v in obs["joints_deg"].items() if "knee" in k}
        run.drive()                                   # the squat: 1 s of motion
        assert run.now_s > run.boot_s + 0.9
        bent = run.read()["joints_deg"]
        assert any(abs(bent[k] - v) > 5 for k, v in knees.items()), (knees, bent)
        summary = run.finish()
        assert run.now_s == pytest.approx(run.end_s)
    assert _files(tmp_path) == ["flexao.rrd"]
    assert summary["recording"] == str(out) and summary["completed"] and not summary["fell"]
    t, tilt = read_rrd_scalars(out, f"{ROBOT}/trunk_tilt_deg")     # the whole run, readable
    assert t[-1] == pytest.approx(summary["duration_s"], abs=0.05) and len(tilt) > 200


def test_a_session_finished_at_once_is_the_run_of_the_same_options() -> None:
    opts = RunOptions("stand", duration=3.5, seed=2, tilt=5.0)
    with humanoid_twin.open(opts) as run:
        from_python = run.finish()
    from_run = scenarios.run(opts)
    assert {k: v for k, v in from_python.items() if k not in WALL_KEYS} == \
        {k: v for k, v in from_run.items() if k not in WALL_KEYS}


def test_a_failed_session_replaces_nothing(tmp_path: Path) -> None:
    out = tmp_path / "stand.rrd"
    out.write_bytes(b"an earlier recording")
    with pytest.raises(RuntimeError, match="the user's own error"):
        with humanoid_twin.open("stand", out=out) as run:
            run.step(0.1)
            raise RuntimeError("the user's own error")
    assert _files(tmp_path) == ["stand.rrd"] and out.read_bytes() == b"an earlier recording"


def test_bad_options_are_refused_before_anything_is_written(tmp_path: Path) -> None:
    with pytest.raises(ScenarioInputError, match=r"must end in \.rrd"):
        humanoid_twin.open("stand", out=tmp_path / "stand.txt")
    with pytest.raises(ScenarioInputError, match="cannot write there"):
        humanoid_twin.open("stand", out=tmp_path / "no" / "such" / "stand.rrd")
    with pytest.raises(scenarios.ScenarioLoadError):
        humanoid_twin.open("no_such_scenario", out=tmp_path / "x.rrd")
    assert _files(tmp_path) == []
    with humanoid_twin.open("stand") as run, pytest.raises(ValueError, match="positive"):
        run.step(0)
