"""humanoid-twin sweep (docs/sweeps.md): a grid of runs into one table, on the local process pool
or Ray. Runs are `stand` for 3 s of simulated time (just past the boot) to keep the suite short."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from humanoid_twin.cli.main import main
from humanoid_twin.sweep import Point, grid, run_sweep
from humanoid_twin.sweep.engine import TIMING_COLUMNS

RUN = [sys.executable, "-m", "humanoid_twin.cli.main"]
GRID = ["--param", "tilt=0,3", "--seeds", "2", "--duration", "3"]


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _untimed(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def _sweep(argv: list[str], capsys) -> tuple[int, str, str]:
    rc = main(["sweep", "stand", *argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def two_jobs(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sweep") / "grid.csv"
    assert main(["sweep", "stand", *GRID, "--jobs", "2", "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_grid_rows_equal_single_runs(two_jobs):
    rows = _rows(two_jobs)
    assert [(r["tilt"], r["seed"]) for r in rows] == [("0", "0"), ("0", "1"), ("3", "0"), ("3", "1")]
    for r in rows:
        assert r["error"] == ""
        single = subprocess.run(RUN + ["run", "stand", "--duration", "3", "--tilt", r["tilt"], "--seed",
                                       r["seed"], "--no-record", "--no-progress", "--json"],
                                capture_output=True, text=True, check=True)
        summary = json.loads(single.stdout.strip().splitlines()[-1])
        for key, value in summary.items():
            if key in TIMING_COLUMNS:
                continue
            if isinstance(value, dict):       # one column per key, numbers (issue 37: no JSON in a cell)
                for sub, v in value.items():
                    assert r[f"{key}_{sub}"] == str(v), (key, sub, r[f"{key}_{sub}"], v)
                continue
            # a list: empty, or the words of the run's own table; true/false as --json spells them
            cell = "" if value is None or value == [] else json.dumps(value) \
                if isinstance(value, bool) else str(value)
            assert r[key] == cell, (key, r[key], value)
    # the seeds are different runs (sensor noise): the table is not one run copied four times
    assert rows[0]["cop_error_rms_mm"] != rows[1]["cop_error_rms_mm"]


@pytest.mark.slow
def test_rerun_skips_rows_already_there(two_jobs, capsys):
    before = _rows(two_jobs)
    rc, _, err = _sweep([*GRID, "--out", str(two_jobs)], capsys)
    assert rc == 0
    assert "4 of 4 runs already in" in err
    assert _rows(two_jobs) == before        # wall_s unchanged: nothing ran again


@pytest.mark.slow
def test_one_job_gives_the_same_rows_as_two(two_jobs, tmp_path, capsys):
    out = tmp_path / "one.csv"
    rc, _, err = _sweep([*GRID, "--jobs", "1", "--out", str(out)], capsys)
    assert rc == 0
    assert "\r" not in err and "4/4 runs done, 0 failed" in err    # plain progress lines off a TTY
    assert _untimed(_rows(out)) == _untimed(_rows(two_jobs))
    assert list(_rows(out)[0]) == list(_rows(two_jobs)[0])          # same columns, same order


def test_a_failing_point_is_a_row_with_its_error(tmp_path, capsys, monkeypatch):
    out = tmp_path / "fail.csv"
    # both points pass run's checks (checked before any run: docs/sweeps.md); one fails while it
    # runs (its host controller raises): that run is a row with its error, the other works
    (tmp_path / "ctlmod.py").write_text("def ok(ctx):\n    pass\n\ndef boom(ctx):\n    1 / 0\n")
    monkeypatch.chdir(tmp_path)
    rc, stdout, _ = _sweep(["--param", "host-controller=ctlmod:ok,ctlmod:boom",
                            "--duration", "3", "--out", str(out)], capsys)
    assert rc == 101 and "2 runs, 1 failed" in stdout     # 100 + the number of failed runs
    ok, bad = _rows(out)
    assert ok["host_controller"] == "ctlmod:ok" and ok["error"] == "" and ok["fell"] == "false"
    assert bad["host_controller"] == "ctlmod:boom" and bad["error"].startswith("RuntimeError: exit 1")
    assert "ZeroDivisionError" in bad["error"]
    assert bad["fell"] == ""


def _flaky(point: Point) -> dict:
    mode = dict(point.params)["mode"]
    if mode == "crash":
        os._exit(7)                       # the worker process dies
    if mode == "raise":
        raise ValueError("bad point")
    return {"value": point.seed + 1}


@pytest.mark.slow
def test_a_crashed_worker_is_a_row_and_the_sweep_goes_on(tmp_path):
    points = grid({"mode": ["ok", "raise", "crash", "ok2"]})
    rows = run_sweep(points, _flaky, tmp_path / "t.csv", jobs=1)
    assert [r["error"][:16] for r in rows] == ["", "ValueError: bad ", "BrokenProcessPoo", ""]
    assert rows[3]["value"] == 1
    # a re-run runs the failed points again, not the good ones
    rows2 = run_sweep(points, _flaky, tmp_path / "t.csv", jobs=1)
    assert [bool(r["error"]) for r in rows2] == [False, True, True, False]


@pytest.mark.slow
def test_parquet_and_csv_read_back_the_same(two_jobs, tmp_path, capsys):
    pq = pytest.importorskip("pyarrow.parquet")
    pacsv = pytest.importorskip("pyarrow.csv")
    out = tmp_path / "grid.parquet"
    rc, _, _ = _sweep([*GRID, "--jobs", "2", "--out", str(out)], capsys)
    assert rc == 0
    table = pq.read_table(out).to_pylist()
    # pyarrow reads an empty CSV cell as null
    from_csv = [{**r, "error": r["error"] or ""} for r in pacsv.read_csv(two_jobs).to_pylist()]
    assert len(table) == 4 and table[2]["tilt"] == 3 and table[2]["fell"] is False
    # the Parquet table also carries every other column a sweep can have, empty here (issue 37)
    assert _untimed([{k: r[k] for k in from_csv[0]} for r in table]) == _untimed(from_csv)
    extra = set(table[0]) - set(from_csv[0])
    assert {"motion", "T", "pic_mhz", "host_error"} <= extra
    assert all(r[k] is None for r in table for k in extra)
    rc, _, err = _sweep([*GRID, "--out", str(out)], capsys)        # resume from a Parquet table
    assert rc == 0 and "4 of 4 runs already in" in err


@pytest.mark.parametrize("argv, message", [
    (["--param", "bogus=1,2"], "--param bogus: not a run option"),
    (["--param", "tilt=0,abc"], "argument --tilt"),
    (["--param", "tilt"], "expected NAME=V1,V2"),
    (["--param", "tilt=1", "--tilt", "2"], "given both"),
    (["--param", "out=x.rrd"], "not a run option"),
    (["--param", "perna=1,3"], "argument --perna"),
    (["--seed", "3"], "--seeds N"),
    (["--backend", "local", "--address", "auto"], "--address is for --backend ray"),
    (["--plot", "p.png", "--metric", "fell"], "--plot needs"),
])
def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, capsys, argv, message):
    out = tmp_path / "t.csv"
    rc = None
    try:
        rc = main(["sweep", "stand", *argv, "--out", str(out)])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_bad_table_suffix_and_an_existing_file_kept(tmp_path, capsys):
    bad = tmp_path / "t.txt"
    assert main(["sweep", "stand", "--out", str(bad)]) == 2
    junk = tmp_path / "junk.parquet"
    junk.write_bytes(b"not parquet")
    assert main(["sweep", "stand", "--duration", "3", "--out", str(junk)]) == 2
    assert junk.read_bytes() == b"not parquet"
    assert "not a sweep table" in capsys.readouterr().err


@pytest.mark.slow
def test_plot(two_jobs, tmp_path, capsys):
    png = tmp_path / "p.png"
    rc, stdout, _ = _sweep([*GRID, "--out", str(two_jobs), "--plot", str(png), "--metric",
                            "trunk_tilt_max_deg", "--x", "tilt"], capsys)
    assert rc == 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_ray_backend_gives_the_same_rows(two_jobs, tmp_path, capsys):
    pytest.importorskip("ray")
    out = tmp_path / "ray.csv"
    rc, _, _ = _sweep([*GRID, "--backend", "ray", "--jobs", "2", "--out", str(out)], capsys)
    assert rc == 0
    assert _untimed(_rows(out)) == _untimed(_rows(two_jobs))


@pytest.mark.slow
def test_a_run_past_the_timeout_is_a_row_with_its_error(tmp_path, capsys):
    out = tmp_path / "slow.csv"
    rc, stdout, _ = _sweep(["--param", "tilt=0", "--duration", "30", "--timeout", "0.5", "--out", str(out)],
                           capsys)
    assert rc == 101 and "1 run, 1 failed" in stdout
    (row,) = _rows(out)
    assert row == {"tilt": "0", "seed": "0", "error": "RuntimeError: timeout: the run took more than 0.5 s"}


@pytest.mark.slow
def test_sigterm_keeps_the_finished_runs_and_a_rerun_resumes(tmp_path):
    out = tmp_path / "t.csv"
    # six runs of 20 simulated s: the signal must find the sweep still running after its first
    # run (with three of 10 s the compiled twin could finish the rest before it arrived)
    argv = RUN + ["sweep", "stand", "--param", "tilt=0,1,2,3,4,5", "--duration", "20", "--jobs", "1",
                  "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # the table appears with the first finished run; the signal follows at once, while the
        # sweep forks its next run (a signal raised in the fork's at-fork callbacks was lost:
        # this caught it 7 times in 8)
        deadline = time.monotonic() + 60
        while not out.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.002)
        proc.send_signal(15)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143 and "terminated" in err
    done = _rows(out)
    assert 1 <= len(done) < 6 and all(r["error"] == "" for r in done)
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]    # no temporary file left behind
    rerun = subprocess.run(argv, capture_output=True, text=True, timeout=180)
    assert rerun.returncode == 0 and f"{len(done)} of 6 runs already in" in rerun.stderr
    assert _rows(out)[:len(done)] == done and len(_rows(out)) == 6


def _listening(pids: set[int]) -> set[str]:
    import psutil

    return {c.laddr.ip for c in psutil.net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN and c.pid in pids}


@pytest.mark.slow
def test_a_local_ray_listens_on_loopback_only(tmp_path):
    """Issue 25: a local Ray (no --address) opened its GCS, raylet and worker ports on the machine's
    network address; every other server of the project binds loopback."""
    pytest.importorskip("ray")
    psutil = pytest.importorskip("psutil")
    from humanoid_twin.sweep.engine import _ray

    rows = _ray(vars, grid({"x": [1, 2]}), 1, None)     # a task the workers can import: vars(point)
    first = next(rows)         # Ray is up (started by this process) while the generator is open
    me = psutil.Process()
    pids = {p.pid for p in me.children(recursive=True)} | {me.pid}
    addresses = _listening(pids)
    rest = list(rows)          # the generator ends: Ray is shut down
    assert first["error"] == "" and len(rest) == 1
    assert addresses, "found no listening socket of the local Ray"
    assert addresses <= {"127.0.0.1", "::ffff:127.0.0.1", "::1"}, addresses


def test_a_failed_run_keeps_its_whole_error(monkeypatch):
    """Issue 25: only the last stderr line of a failed run was kept (a traceback lost its cause)."""
    from humanoid_twin.sweep import engine

    trace = "Traceback (most recent call last):\n  File \"x.py\", line 1, in f\nValueError: boom\n"
    monkeypatch.setattr(engine.subprocess, "run",
                        lambda argv, **kw: subprocess.CompletedProcess(argv, 1, "", trace))
    row = engine.run_point(engine.RunCli("stand"), Point(0, (("tilt", "0"),)))
    assert row["error"] == ('RuntimeError: exit 1: Traceback (most recent call last): | File "x.py", line 1, '
                            'in f | ValueError: boom')


def test_sweep_exit_codes_count_the_failed_runs():
    from humanoid_twin.cli.sweep import exit_code

    assert [exit_code(n) for n in (0, 1, 2, 99, 500)] == [0, 101, 102, 199, 199]


@pytest.mark.slow
def test_two_parquet_sweeps_read_as_one_dataset_with_the_users_umask(tmp_path):
    """Issue 25: a column empty in one sweep was Arrow null, an int parameter int64 in one sweep and
    double in another: the folder did not read as one dataset; the tables were created 0600."""
    ds = pytest.importorskip("pyarrow.dataset")
    from humanoid_twin.sweep.table import write_table

    cols = ["tilt", "seed", "fell", "fell_at_s", "cop_margin_min_mm", "host_error", "error"]
    write_table(tmp_path / "a.parquet", [{"tilt": 10, "seed": 0, "fell": False, "fell_at_s": None,
                                          "cop_margin_min_mm": 20.5, "error": ""}], cols)
    write_table(tmp_path / "b.parquet", [{"tilt": 2.5, "seed": 1, "fell": True, "fell_at_s": 5.5,
                                          "cop_margin_min_mm": -1000.0, "host_error": "x", "error": ""}],
                cols)
    table = ds.dataset(tmp_path, format="parquet").to_table()
    assert sorted(table.column("tilt").to_pylist()) == [2.5, 10.0]
    assert str(table.schema.field("fell_at_s").type) == "double"
    assert str(table.schema.field("seed").type) == "int64"
    assert str(table.schema.field("host_error").type) == "string"
    old = os.umask(0o022)
    try:
        write_table(tmp_path / "c.csv", [{"tilt": 1}], ["tilt"])
    finally:
        os.umask(old)
    assert {oct((tmp_path / n).stat().st_mode & 0o777) for n in ("c.csv",)} == {"0o644"}
