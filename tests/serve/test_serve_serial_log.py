"""``--serial-log FILE`` on ``run`` and ``serve``: every RS-232 byte each way, written beside
``--out`` and ``--can-log`` under a temporary name, and a log that replays into a twin rebuilt
from the options its header records (docs/buses.md, "The serial log"; docs/serve.md). And serve's
live view: ``--connect`` streams the recording to a rerun viewer on loopback."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import can
import pytest
from helpers import CLI, PYSERIAL_FRAME

from humanoid_twin.protocol.rs232 import FrameError, decode_response
from humanoid_twin.recording.readback import read_rrd_rows, rerun_executable, verify_rrd
from humanoid_twin.recording.serial_log import TAP_TO_DEVICE, TAP_TO_HOST, read_log

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

REPLAY = [sys.executable, "-m", "humanoid_twin.bus.serial_log", "replay"]

# a plain pyserial client on serve's TCP port: the Master's TEST, then the head board (SCU 8):
# positions, movement period, PWM on (it calibrates), and its positions read back
PYSERIAL_CLIENT = PYSERIAL_FRAME + textwrap.dedent(r"""
    port = serial.serial_for_url(sys.argv[1], baudrate=115200, parity="E", timeout=2.0)

    def ask(raw):
        port.write(raw)
        return port.read(6).hex(" ")

    out = {"test": ask(frame(3, 0, 0))}
    out["boot"] = [ask(frame(0, 8, 0)), ask(frame(0, 8, 1)), ask(frame(0, 8, 3, 1))]
    time.sleep(1.0)
    out["position"] = ask(frame(2, 8, 0))
    port.close()
    print(json.dumps(out))
""")


def _replay(path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([*REPLAY, str(path)], capture_output=True, text=True, timeout=120)


def test_a_serve_session_leaves_a_recording_a_can_log_and_a_serial_log_that_replays(serve, tmp_path):
    out, canlog, serlog = tmp_path / "s.rrd", tmp_path / "s.asc", tmp_path / "s.serial"
    serlog.write_text("an earlier log")                 # replaced only by a complete one
    proc, port = serve("--tcp", "0", "--speed", "2", "--seed", "7", "--fault", "force-noise:1",
                       "--out", str(out), "--can-log", str(canlog), "--serial-log", str(serlog))
    assert port.startswith("socket://127.0.0.1:")
    answers = serve.client(PYSERIAL_CLIENT, port)
    assert answers["test"] == "fa f9 f8 f7 f6 f5" and all(a.startswith("fb") for a in answers["boot"])
    assert answers["position"].startswith("fd")
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    for path in (out, canlog, serlog):
        assert f"wrote {path}" in err, err
    verify_rrd(out)
    assert read_rrd_rows(out)["robot/trunk_tilt_deg"] > 50
    with can.LogReader(str(canlog)) as reader:
        assert sum(1 for _ in reader) > 1000
    meta, records = read_log(serlog)
    assert meta["seed"] == 7 and meta["faults"] == ["force-noise:1"]
    sent = b"".join(r.data for r in records if r.event == TAP_TO_DEVICE)
    got = b"".join(r.data for r in records if r.event == TAP_TO_HOST)
    assert sent.startswith(bytes.fromhex("ff c0 00 00 00 3f"))       # the client's TEST frame, first
    assert len(sent) == 5 * 6 and got.startswith(bytes.fromhex(answers["test"]))
    assert got.endswith(bytes.fromhex(answers["position"]))           # what the client read, as logged
    rp = _replay(serlog)
    assert rp.returncode == 0, rp.stderr
    assert "30 host bytes" in rp.stdout
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_a_run_with_faults_laws_and_tilt_replays_into_the_rig_its_header_records(tmp_path):
    log = tmp_path / "flexao.serial"
    r = subprocess.run([*CLI, "run", "flexao", "--duration", "6", "--tilt", "4", "--seed", "3",
                        "--fault", "push:30@3", "--fault", "serial-noise:0.01@3", "--host-link", "2",
                        "--law", "balance=humanoid_twin.slave.laws:JacobianLaw", "--serial-log", str(log),
                        "--no-record", "--no-progress", "--json"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode in (0, 3), r.stderr
    assert json.loads(r.stdout)["serial_log"] == str(log)
    meta, records = read_log(log)
    assert meta["tilt"] == 4 and meta["tilt_from_s"] > 2.5 and meta["supervisor"]["host_link_ms"] == 2000
    # the noise flips bits while the host still talks (from 3 s): the answers the host read carry
    # broken BCCs, and the replay's twin, fed the host's bytes as written, flips the same ones
    broken = 0
    for rec in records:
        if rec.event == TAP_TO_HOST:
            try:
                decode_response(rec.data)
            except FrameError:
                broken += 1
    assert broken > 0
    assert meta["laws"] == [[3, "humanoid_twin.slave.laws:JacobianLaw"]]
    rp = _replay(log)
    assert rp.returncode == 0, rp.stderr
    # the same bytes into a twin of the seed alone (no faults, no tilt) answer otherwise: the
    # positions read back once the platform tilts (2.86 s) differ
    text = log.read_text().splitlines()
    plain = tmp_path / "plain.serial"
    plain.write_text("\n".join('# meta {"seed": 3}' if ln.startswith("# meta") else ln for ln in text) + "\n")
    rp = _replay(plain)
    assert rp.returncode == 1 and "differ" in rp.stderr, rp


def test_run_flexao_replays(tmp_path):
    log = tmp_path / "flexao.serial"
    r = subprocess.run([*CLI, "run", "flexao", "--duration", "4", "--serial-log", str(log), "--no-record",
                        "--no-progress"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    rp = _replay(log)
    assert rp.returncode == 0 and "match the log" in rp.stdout, rp.stderr


def test_a_bad_serial_log_path_is_exit_2_with_nothing_written(tmp_path):
    bad = tmp_path / "no" / "f.log"
    r = subprocess.run([*CLI, "run", "flexao", "--duration", "3", "--serial-log", str(bad), "--no-record"],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "" and "--serial-log" in r.stderr, r
    assert len(r.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []
    kept = tmp_path / "kept.serial"
    kept.write_text("an earlier log")
    for cmd in (["run", "flexao", "--duration", "3", "--no-record", "--seed", "-1"],     # a bad option
                ["serve", "--tcp", "0", "--tilt", "80"]):
        r = subprocess.run([*CLI, *cmd, "--serial-log", str(kept)], capture_output=True, text=True,
                           timeout=60, cwd=tmp_path)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r
        assert kept.read_text() == "an earlier log"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.serial"]


def test_sweep_refuses_a_serial_log(tmp_path):
    r = subprocess.run([*CLI, "sweep", "stand", "--out", str(tmp_path / "t.csv"), "--serial-log",
                        str(tmp_path / "f.log")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--serial-log is per run" in r.stderr, r
    assert list(tmp_path.iterdir()) == []


# -- live viewing: serve streams its recording to a rerun viewer on loopback -------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, proc: subprocess.Popen, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.1)
    pytest.fail(f"nothing listens on 127.0.0.1:{port}")


@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # rerun --save streams without one
def test_serve_connect_streams_the_recording_live_to_a_loopback_viewer(serve, tmp_path):
    """``serve --connect PORT`` sends the recording, while serve runs, to the rerun gRPC server
    listening there (here rerun's own, saving what it receives), beside ``--out``."""
    port = _free_port()
    received = tmp_path / "received.rrd"
    viewer = subprocess.Popen([str(rerun_executable()), "--bind", "127.0.0.1", "--port", str(port),
                               "--save", str(received)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        _wait_listening(port, viewer)
        out = tmp_path / "s.rrd"
        proc, _ = serve("--tcp", "0", "--speed", "2", "--connect", f"127.0.0.1:{port}", "--out", str(out))
        time.sleep(3.0)                 # ~6 simulated seconds: several live chunks of 1 s
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 130 and f"wrote {out}" in err, err
    finally:
        viewer.terminate()              # rerun closes the file it saved on SIGTERM
        viewer.wait(30)
    live, kept = read_rrd_rows(received), read_rrd_rows(out)
    assert live["robot/trunk_tilt_deg"] == kept["robot/trunk_tilt_deg"] > 100    # every 20 ms row, live too
    assert live.keys() == kept.keys()


@pytest.mark.parametrize("addr, message", [
    ("192.0.2.1:9876", "not a loopback address"),
    ("example.invalid:1", "not an address"),
    ("nope", "not HOST:PORT"),
])
def test_serve_connect_refuses_what_is_not_a_viewer_on_loopback(tmp_path, addr, message):
    r = subprocess.run([*CLI, "serve", "--tcp", "0", "--connect", addr, "--out", str(tmp_path / "s.rrd")],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "" and message in r.stderr, r
    assert len(r.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_serve_connect_needs_a_viewer_listening_and_viewer_a_display(tmp_path):
    port = _free_port()                 # nothing listens there
    r = subprocess.run([*CLI, "serve", "--tcp", "0", "--connect", str(port)], capture_output=True, text=True,
                       timeout=60, cwd=tmp_path)
    assert r.returncode == 2 and "no viewer listens there" in r.stderr, r
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([*CLI, "serve", "--tcp", "0", "--viewer", "--out", str(tmp_path / "s.rrd")],
                       capture_output=True, text=True, timeout=60, cwd=tmp_path, env=env)
    assert r.returncode == 2 and "--viewer needs a display" in r.stderr, r
    assert list(tmp_path.iterdir()) == []
