"""Issue 24, point 2 (and the signal and name parts of point 7): every output fails the same way.

A CAN log whose writer fails in its own thread (python-can's SQLite writer on a full disk) fails
the run as any other format does (exit 1, one line, the old file kept); signals are handled from
the CLI's first instruction to the last rename, the compaction included, and leave no stray
temporary file; the free-space check scales with what the run will write; a failed compaction
keeps the readable recording; a valid 252-character output name works.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import CLI, default_signals

from humanoid_twin import recording
from humanoid_twin.cli import checked_outputs as outputs
from humanoid_twin.cli import main as cli
from humanoid_twin.recording import read_rrd_rows, verify_rrd
from humanoid_twin.twin import Twin

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)



def _fsize_limit(limit: int):
    def setup() -> None:
        default_signals()
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # the write fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return setup


def test_sqlite_can_log_on_a_full_disk_fails_the_run_and_keeps_the_old_file(tmp_path: Path) -> None:
    log = tmp_path / "x.db"
    log.write_bytes(b"the old log")
    res = subprocess.run([*CLI, "run", "stand", "--duration", "4", "--no-record", "--no-progress",
                          "--can-log", str(log), "--json"], capture_output=True, text=True, timeout=120,
                         preexec_fn=_fsize_limit(200_000))
    assert res.returncode == 1, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert "SQLite writer failed" in lines[0] and str(log) in lines[0] and "no file replaced" in lines[0]
    assert ".partial-" not in lines[0]
    assert log.read_bytes() == b"the old log"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert res.stdout == ""                      # no summary claiming every frame


def test_free_space_check_scales_with_the_duration(tmp_path: Path, monkeypatch, capsys) -> None:
    # what a run writes grows with its length; a long recording is counted twice (compaction)
    short = outputs.output_bytes("out", Path("x.rrd"), 60.0)
    long = outputs.output_bytes("out", Path("x.rrd"), 600.0)
    assert long >= 2 * 10 * short * 0.99
    assert (outputs.output_bytes("can_log", Path("x.txt"), 60)
            > outputs.output_bytes("can_log", Path("x.blf"), 60))
    # 120 MB free: a 600 s recording (~130 MB, twice for the compaction) is refused at once
    usage = outputs.shutil.disk_usage(tmp_path)
    monkeypatch.setattr(outputs.shutil, "disk_usage",
                        lambda p: usage._replace(free=120 * 2**20))
    out = tmp_path / "x.rrd"
    with pytest.raises(SystemExit) as exc:
        cli.main(["run", "stand", "--duration", "600", "--out", str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "only 120 MB free" in err[0]
    assert list(tmp_path.iterdir()) == []        # nothing written
    # the same disk takes a 60 s run
    outputs.CheckedOutputs().check_space({"out": (out, "--out")}, 60.0)


def test_a_failed_compaction_keeps_the_readable_recording(tmp_path: Path, monkeypatch) -> None:
    fake = tmp_path / "rerun"
    real = cli_rerun()
    # rerun itself for everything but `rrd optimize`, which fails as on a full disk
    fake.write_text(f"#!/bin/sh\nif [ \"$2\" = optimize ]; then echo 'No space left on device' >&2; "
                    f"exit 1; fi\nexec {real} \"$@\"\n")
    fake.chmod(0o755)
    path = tmp_path / "long.rrd"
    with Twin(seed=0) as twin:
        rec = recording.Recorder(path, twin, compact=True)
        twin.run_for(1.0)
        monkeypatch.setenv("RERUN_CLI_PATH", str(fake))
        rec.close()
    assert rec.compaction_error is not None and "No space left" in rec.compaction_error
    monkeypatch.delenv("RERUN_CLI_PATH")
    verify_rrd(path, check_footers=False)       # complete and readable, without rerun's footer index
    assert read_rrd_rows(path)["robot/trunk_tilt_deg"] == 51
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def cli_rerun() -> str:
    from humanoid_twin.recording.readback import rerun_executable

    return str(rerun_executable())


_COMPACT_CHILD = """
import sys
from humanoid_twin import signals
from humanoid_twin.twin import Twin
from humanoid_twin.recording import Recorder
signals.install()
try:
    with Twin(seed=0) as twin:
        rec = Recorder(sys.argv[1], twin, compact=True)
        twin.run_for(1.0)
        rec.close()
except KeyboardInterrupt as exc:
    print("compaction:", rec.compaction_error, flush=True)
    sys.exit(signals.exit_code(exc))
"""


@pytest.mark.parametrize("signals_sent", [1, 2])
def test_sigterm_during_the_compaction_keeps_a_verified_recording_and_exits_143(
        tmp_path: Path, signals_sent: int) -> None:
    """One SIGTERM lets the compaction finish (the file verifies, footer included); a second
    stops it at once and keeps the recording as recorded (readable, no footer index)."""
    fake = tmp_path / "rerun"
    marker = tmp_path / "optimizing"
    fake.write_text(f"#!/bin/sh\nif [ \"$2\" = optimize ]; then touch {marker}; sleep 2; fi\n"
                    f"exec {cli_rerun()} \"$@\"\n")
    fake.chmod(0o755)
    path = tmp_path / "long.rrd"
    env = {**os.environ, "RERUN_CLI_PATH": str(fake)}
    proc = subprocess.Popen([sys.executable, "-c", _COMPACT_CHILD, str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, preexec_fn=default_signals)
    try:
        deadline = time.monotonic() + 60
        while not marker.exists() and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.02)
        assert marker.exists()
        t0 = time.monotonic()
        for _ in range(signals_sent):
            proc.send_signal(signal.SIGTERM)
            time.sleep(0.2)
        out, err = proc.communicate(timeout=30)
        assert time.monotonic() - t0 < (1.5 if signals_sent == 2 else 15)
    finally:
        proc.kill()
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "finishing the recording's compaction" in err
    if signals_sent == 1:
        assert "compaction: None" in out
        verify_rrd(path)
    else:
        assert "stopped by a signal" in out
        verify_rrd(path, check_footers=False)
    assert read_rrd_rows(path)["robot/trunk_tilt_deg"] == 51
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
@pytest.mark.parametrize("delay", [0.25, 0.6, 1.2])
def test_a_signal_at_any_early_instant_is_one_line_and_leaves_no_temporary_file(
        tmp_path: Path, sig: int, code: int, delay: float) -> None:
    out = tmp_path / "x.rrd"
    proc = subprocess.Popen([*CLI, "run", "stand", "--duration", "3", "--no-progress", "--out", str(out),
                             "--can-log", str(tmp_path / "x.asc")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    time.sleep(delay)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:                      # too late: the run had finished (a fast machine)
        return
    assert proc.returncode == code, err
    assert "Traceback" not in err and len(err.strip().splitlines()) <= 2, err
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    if out.exists():
        verify_rrd(out)


def test_sigterm_while_a_slow_law_module_imports_leaves_no_temporary_file(tmp_path: Path) -> None:
    (tmp_path / "slowlaw.py").write_text("import time\ntime.sleep(30)\n")
    proc = subprocess.Popen([*CLI, "run", "stand", "--duration", "3", "--law", "balance=slowlaw:Law",
                             "--out", "x.rrd"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=default_signals,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    time.sleep(1.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143 and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != "__pycache__") == ["slowlaw.py"]


def test_a_252_character_output_name_works(tmp_path: Path) -> None:
    out = tmp_path / ("n" * 248 + ".rrd")
    log = tmp_path / ("c" * 244 + ".asc.gz")
    res = subprocess.run([*CLI, "run", "stand", "--duration", "3", "--no-progress", "--out", str(out),
                          "--can-log", str(log)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    verify_rrd(out)
    assert log.stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([log.name, out.name])
