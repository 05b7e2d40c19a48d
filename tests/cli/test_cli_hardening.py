"""The CLI under mistakes, signals and a full disk: one line and exit 2 for every bad input (checked
before anything runs or is written), an existing output never replaced by a failed run, SIGTERM
and SIGINT leave files that rerun and python-can read back, a write error is one line."""

from __future__ import annotations

import resource
import signal
import socket
import subprocess
import time

import pytest
from helpers import CLI, default_signals

from humanoid_twin.recording import read_can_log, verify_rrd

OLD = b"an older recording the user wants to keep"


def cli(*args: str, cwd, timeout: float = 120, preexec=default_signals) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout, cwd=cwd,
                          preexec_fn=preexec)


@pytest.fixture(scope="module")
def busy_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    yield s.getsockname()[1]
    s.close()


BAD_RUN = [
    (["--duration", "1e308"], "--duration"),
    (["--T", "6"], "255 ticks"),                       # the planner's one-byte limit, before boot
    (["--motion", "60"], "motion must be 0..45"),
    (["--seed", "-1"], "--seed -1"),
    (["--tilt", "60"], "+-45"),
    (["--out", "/proc/old.rrd"], "--out"),             # unwritable even for root
    (["--can-log", "/proc/frames.asc"], "--can-log"),
    (["--can-log", "frames.mf4"], "asammdf"),
    (["--can-interface", "socketcan"], "needs --can-channel"),
    (["--can-interface", "socketcan", "--can-channel", "nosuchcan7"], "nosuchcan7"),
    (["--no-record"], "contradict"),                   # with --out old.rrd (added below)
    (["--duration", "1"], "shorter than the boot"),    # found after the boot: nothing replaced
]


@pytest.mark.parametrize("extra, message", BAD_RUN, ids=[" ".join(a) for a, _ in BAD_RUN])
def test_bad_run_input_is_one_line_exit_2_and_the_old_file_survives(extra, message, tmp_path):
    old = tmp_path / "old.rrd"
    old.write_bytes(OLD)
    args = ["run", "flexao", "--no-progress", *extra]
    if "--out" not in extra:
        args += ["--out", "old.rrd"]
    r = cli(*args, cwd=tmp_path)
    assert r.returncode == 2, r.stderr[-2000:]
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert old.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.rrd"]     # no temporary file left


@pytest.mark.slow
def test_bad_serve_input_is_one_line_exit_2(tmp_path, busy_port):
    cases = [
        (["--tcp", "70000"], "0..65535"),
        (["--tcp", str(busy_port)], "cannot listen"),
        (["--tcp", "0", "--host", "no-such-host.invalid"], "--host"),
        (["--tcp", "0", "--host", "192.0.2.1"], "cannot listen"),     # not an address of this machine
        (["--seed", "-1"], "--seed"),
        (["--tilt", "60"], "+-45"),
    ]
    for extra, message in cases:
        r = cli("serve", *extra, cwd=tmp_path, timeout=60)
        assert r.returncode == 2, (extra, r.stderr[-2000:])
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], (extra, r.stderr)
        assert r.stdout == ""


def test_a_successful_run_replaces_the_old_file(tmp_path):
    old = tmp_path / "old.rrd"
    old.write_bytes(OLD)
    r = cli("run", "stand", "--duration", "3", "--no-progress", "--out", "old.rrd", "--can-log", "f.db",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    verify_rrd(old)
    frames = read_can_log(tmp_path / "f.db")
    summary = dict(line.split(None, 1) for line in r.stdout.splitlines() if line.strip())
    assert len(frames) == int(summary["can_frames"])      # the SQLite log lost no frame
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.db", "old.rrd"]


@pytest.mark.slow
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)],
                         ids=["SIGTERM", "SIGINT"])
def test_signal_mid_run_closes_the_recording_and_the_can_log(sig, code, tmp_path):
    args = ["run", "stand", "--duration", "600", "--out", "s.rrd", "--can-log", "s.asc"]
    proc = subprocess.Popen([*CLI, *args], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True,
                            preexec_fn=default_signals)
    try:
        line = "x"
        while "booted by" not in line:           # the progress line: the run is under way
            line = proc.stderr.readline()
            assert line, "the run ended early"
        time.sleep(1.0)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == code, err[-2000:]
    assert "Traceback" not in err
    verify_rrd(tmp_path / "s.rrd")
    assert len(read_can_log(tmp_path / "s.asc")) > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.asc", "s.rrd"]


@pytest.mark.slow
def test_disk_full_mid_run_is_one_line_and_the_old_file_survives(tmp_path):
    """A file-size limit stands for a full disk (no root needed): writes fail with EFBIG."""
    old = tmp_path / "old.rrd"
    old.write_bytes(OLD)

    def limited() -> None:
        default_signals()
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))

    r = cli("run", "flexao", "--no-progress", "--out", "old.rrd", cwd=tmp_path, timeout=120, preexec=limited)
    assert r.returncode == 1, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert "humanoid-twin: error: cannot write the outputs" in r.stderr
    assert old.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.rrd"]
