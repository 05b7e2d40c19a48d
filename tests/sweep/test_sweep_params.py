"""Sweeps over the robot's named parameters (docs/parameters.md, docs/sweeps.md): ``--param`` with
a parameter (a glob sets every match) or a user scenario's field (``scenario.FIELD``), and
domain randomisation (``--randomize NAME=DIST --samples N``): the rows carry the values used and
each run's ``params``; bad input is one line, exit 2, no table written."""

from __future__ import annotations

import csv
import subprocess
from pathlib import Path

import pytest
from helpers import CLI, REPO

from humanoid_twin.params import params_digest, registry
from humanoid_twin.sweep.params import draw_samples, parse_randomize


def sweep(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, "sweep", *args, "--no-progress"], capture_output=True, text=True,
                          timeout=600, cwd=cwd)


def rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def row_params(row: dict[str, str]) -> dict[str, float]:
    """The run's non-default parameters in a row: one column each, ``params_NAME`` (the summary's
    ``params`` object as columns: no JSON in a cell), empty where the run did not set it."""
    return {k.removeprefix("params_"): float(v) for k, v in row.items()
            if k.startswith("params_") and k != "params_digest" and v != ""}


def test_a_parameter_glob_is_a_column_and_each_run_says_what_it_set(tmp_path: Path) -> None:
    kp = registry().get("servo.r_knee.kp").default
    r = sweep("stand", "--param", f"servo.*_knee.kp=30,{kp:g}", "--duration", "3", "--jobs", "2",
              "--out", "t.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    t = rows(tmp_path / "t.csv")
    assert [row["servo.*_knee.kp"] for row in t] == ["30", f"{kp:g}"] and not any(row["error"] for row in t)
    assert row_params(t[0]) == {"servo.l_knee.kp": 30.0, "servo.r_knee.kp": 30.0}
    assert t[0]["params_digest"] == params_digest({"servo.*_knee.kp": 30})
    assert row_params(t[1]) == {} and t[1]["params_digest"] == ""      # every default: today's twin


def test_a_user_scenarios_own_field(tmp_path: Path) -> None:
    """``gentle`` shoves twice, ``every_s`` apart: its length follows the field."""
    scen = f"{REPO / 'examples' / 'push_recovery.py'}:gentle"
    r = sweep(scen, "--param", "scenario.every_s=1.0,1.5", "--out", "t.csv", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    t = rows(tmp_path / "t.csv")
    assert [row["scenario.every_s"] for row in t] == ["1.0", "1.5"] and not any(row["error"] for row in t)
    durations = [float(row["duration_s"]) for row in t]
    assert durations[1] - durations[0] == pytest.approx(2 * 0.5, abs=0.05)   # two shoves, 0.5 s longer each


def test_randomised_robots_are_seeded_drawn_within_bounds_and_in_the_rows(tmp_path: Path) -> None:
    args = ["stand", "--randomize", "servo.*_knee.kp=uniform(37.0091,55.5137)",
            "--randomize", "body.trunk.mass_scale=normal(1,0.05)",
            "--randomize", "floor.friction=uniform(0.5,1)",
            "--samples", "3", "--duration", "3", "--jobs", "2", "--out", "r.csv"]
    r = sweep(*args, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    t = rows(tmp_path / "r.csv")
    draws = draw_samples(parse_randomize([args[2], args[4], args[6]]), 3)
    assert len(t) == 3 and not any(row["error"] for row in t)
    for row, draw in zip(t, draws, strict=True):
        got = {name: float(row[name]) for name, _ in draw}
        assert got == dict(draw)
        assert 37.0091 <= got["servo.*_knee.kp"] <= 55.5137 and 0.5 <= got["floor.friction"] <= 1
        assert row_params(row) == {"body.trunk.mass_scale": got["body.trunk.mass_scale"],
                                             "floor.friction": got["floor.friction"],
                                             "servo.l_knee.kp": got["servo.*_knee.kp"],
                                             "servo.r_knee.kp": got["servo.*_knee.kp"]}
    assert len({row["params_digest"] for row in t}) == 3
    r = sweep(*args, cwd=tmp_path)      # the same draws: every row is already there, none run again
    assert r.returncode == 0 and rows(tmp_path / "r.csv") == t        # wall_s kept: not run again


def test_draws_are_the_same_every_time_and_clipped_to_the_bounds() -> None:
    spec = parse_randomize(["floor.friction=normal(0.05,1)"])
    a, b = draw_samples(spec, 20), draw_samples(spec, 20)
    assert a == b
    values = [v for ((_, v),) in a]
    assert min(values) == 0.01 and max(values) <= 5.0       # the normal's tail clipped to 0.01..5


@pytest.mark.parametrize("args, message", [
    (["--param", "servo.nope.kp=1,2"], "unknown parameter 'servo.nope.kp'"),
    (["--param", "servo.*_kne.kp=1,2"], "matches no parameter"),
    (["--param", "floor.friction=0.5,99"], "outside its bounds"),
    (["--param", "scenario.every_s=1,2"], "has no field 'every_s'"),
    (["--randomize", "floor.friction=uniform(0.5,9)", "--samples", "2"], "outside the bounds"),
    (["--randomize", "floor.friction=uniform(0.5,1)"], "needs --samples"),
    (["--samples", "3"], "goes with --randomize"),
    (["--randomize", "floor.friction=gauss(1,2)", "--samples", "2"], "expected NAME=uniform(A,B)"),
    (["--randomize", "floor.friction=normal(1,0)", "--samples", "2"], "SIGMA > 0"),
    (["--param", "floor.friction=0.5", "--randomize", "floor.friction=uniform(0.5,1)", "--samples", "2"],
     "both as --param and as --randomize"),
    (["--set", "floor.friction=nan"], "not a finite number"),
])
def test_bad_sweep_input_is_one_line_exit_2_no_table(tmp_path: Path, args: list[str], message: str) -> None:
    r = sweep("stand", *args, "--out", "t.csv", cwd=tmp_path)
    assert r.returncode == 2 and message in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert not (tmp_path / "t.csv").exists()


def test_a_parquet_folder_of_sweeps_over_different_robot_parameters_reads_back_whole(tmp_path: Path) -> None:
    """Two sweeps over two different parameters, written into one folder: read as one table
    (pandas, as docs/sweeps.md says), neither sweep's parameter column is lost."""
    pd = pytest.importorskip("pandas")
    (tmp_path / "sw").mkdir()
    for param, out in (("servo.r_knee.kp=40", "sw/a.parquet"), ("floor.friction=0.7", "sw/b.parquet")):
        r = sweep("stand", "--param", param, "--duration", "3", "--out", out, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
    df = pd.read_parquet(tmp_path / "sw").sort_values("params_digest")
    got = {(None if pd.isna(a) else a, None if pd.isna(b) else b)
           for a, b in zip(df["servo.r_knee.kp"], df["floor.friction"], strict=True)}
    assert got == {(40.0, None), (None, 0.7)}
    assert sorted(df["params_servo.r_knee.kp"].dropna()) == [40.0]
    assert sorted(df["params_floor.friction"].dropna()) == [0.7]
