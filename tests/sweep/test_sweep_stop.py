"""Issue 24, point 6: sweeps keep run's contract and stop cleanly.

Every grid value goes through run's own checks before any run starts (exit 2, nothing written);
SIGTERM / SIGINT stop the runs in flight within seconds, keep the finished rows, exit 143 / 130
and leave no process behind (also after SIGKILL); a Ray address where nothing answers fails fast;
a file that is not a sweep table is refused; a repeated grid point and absurd --seeds are usage
errors."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from humanoid_twin.cli.main import main

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

RUN = [sys.executable, "-m", "humanoid_twin.cli.main"]


def _main(argv: list[str], capsys) -> tuple[int, str]:
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("argv,why", [
    (["stand", "--param", "tilt=10,80"], "--tilt 80"),                    # beyond the platform
    (["stand", "--param", "seed=0,-1"], "seeds are 0..4294967295"),
    (["stand", "--param", "law=balance=nosuchmodule:Law"], "cannot import"),
    (["flexao", "--param", "T=1,6"], "flexao:"),                         # the planner's limit
    (["stand", "--param", "tilt=0", "--duration", "1e6"], "--duration 1e+06"),
    (["stand", "--param", "tilt=0", "--timeout", "1e300"], "--timeout"),
    (["stand", "--param", "tilt=10,10.0"], "a value is repeated"),
    (["stand", "--param", "tilt=0", "--seeds", "100000000"], "at most 100000"),
    (["stand", "--param", "tilt=0,5", "--host-controller", "nosuchmodule:step"], "cannot import"),
])
def test_every_grid_value_is_checked_by_run_s_own_checks(tmp_path: Path, capsys, argv, why) -> None:
    out = tmp_path / "t.csv"
    rc, err = _main(["sweep", *argv, "--duration", "3", "--out", str(out)] if "--duration" not in argv
                    else ["sweep", *argv, "--out", str(out)], capsys)
    assert rc == 2, err
    assert why in err and len(err.strip().splitlines()) == 1, err
    assert list(tmp_path.iterdir()) == []


def test_an_unrelated_csv_is_not_rewritten(tmp_path: Path, capsys) -> None:
    out = tmp_path / "mine.csv"
    out.write_text("name,value\na,1\n")
    rc, err = _main(["sweep", "stand", "--param", "tilt=0", "--duration", "3", "--out", str(out)], capsys)
    assert rc == 2 and "not a sweep table" in err
    assert out.read_text() == "name,value\na,1\n"


@pytest.mark.parametrize("address,why", [("127.0.0.1:1", "no Ray cluster answers"),
                                         ("not-an-address", "expected HOST:PORT")])
def test_a_ray_address_where_nothing_answers_fails_fast(tmp_path: Path, capsys, address, why) -> None:
    t0 = time.monotonic()
    rc, err = _main(["sweep", "stand", "--param", "tilt=0", "--duration", "3", "--backend", "ray",
                     "--address", address, "--out", str(tmp_path / "t.csv")], capsys)
    assert time.monotonic() - t0 < 30
    assert rc == 2 and why in err and len(err.strip().splitlines()) == 1, err


def _runs_of(marker: str) -> list[int]:
    """PIDs of live processes whose command line contains ``marker`` (not zombies)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = (d / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if marker in cmd and " run " in cmd and state != "Z":
            pids.append(int(d.name))
    return pids


def _start_sweep(tmp_path: Path) -> tuple[subprocess.Popen, Path, str]:
    out = tmp_path / "t.csv"
    recs = tmp_path / "recs"
    # one short run (it finishes) and one long run (in flight when the signal comes)
    argv = [*RUN, "sweep", "stand", "--param", "duration=3,60", "--jobs", "2", "--no-progress",
            "--recordings", str(recs), "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    deadline = time.monotonic() + 90
    while not out.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    assert out.exists(), proc.stderr.read() if proc.poll() is not None else "no row in 90 s"
    return proc, out, str(recs)


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_stops_the_runs_in_flight_keeps_the_rows_and_leaves_no_process(
        tmp_path: Path, sig: int, code: int) -> None:
    proc, out, marker = _start_sweep(tmp_path)
    try:
        assert _runs_of(marker)                  # the long run is in flight
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, err
    assert took < 5, took
    assert "Traceback" not in err
    with open(out, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["duration"], r["error"]) for r in rows] == [("3", "")]
    time.sleep(0.5)
    assert _runs_of(marker) == []


def test_a_killed_sweep_takes_its_runs_with_it(tmp_path: Path) -> None:
    proc, _, marker = _start_sweep(tmp_path)
    try:
        assert _runs_of(marker)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 10
        while _runs_of(marker) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert _runs_of(marker) == []
    finally:
        for pid in _runs_of(marker):
            os.kill(pid, signal.SIGKILL)
