"""The serial log (humanoid_twin/recording/serial_log.py, docs/buses.md "The serial log"): every RS-232
byte each way with its virtual time, written through the cable's public tap, read back, and
replayed into a fresh twin whose answers must be the logged ones, byte for byte and microsecond
for microsecond."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from humanoid_twin.host import initcom, killcom, power_on, readjoint
from humanoid_twin.recording.serial_log import SerialLog, read_log
from humanoid_twin.replay import replay
from humanoid_twin.twin import Twin

REPLAY = [sys.executable, "-m", "humanoid_twin.cli.main", "replay"]
ALIAS = [sys.executable, "-m", "humanoid_twin.bus.serial_log", "replay"]      # the older spelling
TEST_MSG = bytes([0xFF, 0xC0, 0, 0, 0, 0x3F])      # MASTER test message (docs/protocol.md)


@pytest.fixture(scope="module")
def logged(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, int]]:
    """A host session over the in-process twin:// port: boot, joint reads, a request flushed
    before it left, the cable unplugged mid-answer, the test message."""
    path = tmp_path_factory.mktemp("serial") / "session.serial.log"
    twin = Twin(seed=3)
    log = SerialLog.attach(twin, path)
    H, _ = initcom(twin.url)
    power_on(H)
    for scu in (1, 2):
        readjoint(H, scu, 0)
    H.write(TEST_MSG * 3)
    H.reset_output_buffer()          # the bytes not yet started on the line are dropped
    H.read(6)
    H.reset_input_buffer()
    H.write(TEST_MSG)
    twin.run_for(0.0003)             # the request is on its way, its answer not complete yet
    twin.link.unplug()                     # as a serve session does: the cable, then the receiver
    twin.master.reset_receiver()
    H.write(TEST_MSG)
    answer = H.read(6)
    killcom(H)
    twin.run_for(0.05)
    counts = {"to_device": twin.link.bytes_to_device, "to_host": twin.link.bytes_to_host,
              "answer": answer[0] if answer else -1, "closed_us": twin.clock.now_us}
    log.close()
    twin.close()
    return path, counts


def test_every_byte_each_way_with_its_time(logged) -> None:
    path, counts = logged
    assert counts["answer"] == 0xFA                    # the test message answered FA F9 ...
    meta, records = read_log(path)
    assert meta == {"seed": 3, "end_us": counts["closed_us"]}       # the instant it was closed
    host = b"".join(r.data for r in records if r.event == "host>twin")
    twin = b"".join(r.data for r in records if r.event == "twin>host")
    assert len(host) == counts["to_device"] and len(twin) == counts["to_host"]
    assert host.startswith(bytes([0xFF])) and TEST_MSG in host
    assert bytes([0xFA, 0xF9, 0xF8, 0xF7, 0xF6, 0xF5]) in twin
    # 11 bit times per byte at 115200 baud: 6 bytes written to an idle line end 573 us later
    first = records[0]
    assert first.event == "host>twin" and first.end_us - first.t_us == 573
    assert [r.t_us for r in records] == sorted(r.t_us for r in records)
    events = {r.event for r in records}
    assert {"flush", "unplug"} <= events
    text = path.read_text()
    assert text.startswith("# humanoid-twin serial log 1\n# line 115200 8E1;")
    assert "host>twin 573 ff 05 00 00 00 fa\n" in text      # initcom's first request, in hex


def test_the_replay_gets_the_same_answers_at_the_same_microseconds(logged) -> None:
    path, _ = logged
    for cmd in (REPLAY, ALIAS):         # humanoid-twin replay, and the module's older spelling
        r = subprocess.run([*cmd, str(path)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        assert "match the log" in r.stdout and r.stderr == ""


def test_a_changed_answer_or_time_is_found(logged, tmp_path: Path) -> None:
    path, _ = logged
    lines = path.read_text().splitlines(keepends=True)
    i = next(k for k, ln in enumerate(lines) if " twin>host " in ln and k > 40)
    t, ev, end, *hexes = lines[i].split()
    for changed in (f"{t} {ev} {end} {' '.join(['00'] + hexes[1:])}\n",                # a byte
                    f"{int(t) + 1} {ev} {int(end) + 1} {' '.join(hexes)}\n"):          # a microsecond later
        bad = tmp_path / "bad.log"
        bad.write_text("".join(lines[:i] + [changed] + lines[i + 1:]))
        r = subprocess.run([*REPLAY, str(bad)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 1 and "differ" in r.stderr and changed.strip() in r.stderr, r.stderr
        assert f"line {i + 1}," in r.stderr
    res = replay(path, seed=4)           # another seed: other board phases, other answers
    assert res.difference is not None


def test_a_file_that_is_not_a_serial_log_is_one_line_exit_2(tmp_path: Path) -> None:
    for text in ("hello\n", "# humanoid-twin serial log 1\n12 host>twin 585 ff zz\n",
                 "# humanoid-twin serial log 1\n12 sideways 3\n"):
        f = tmp_path / "x.log"
        f.write_text(text)
        r = subprocess.run([*REPLAY, str(f)], capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stderr.count("\n") == 1 and r.stdout == "", r.stderr


def test_the_tap_is_removed_on_close(tmp_path: Path) -> None:
    with Twin(seed=0) as twin:
        log = SerialLog.attach(twin, tmp_path / "a.log")
        H = twin.open_port()
        H.write(TEST_MSG)
        H.read(6)
        log.close()
        n = len((tmp_path / "a.log").read_text().splitlines())
        H.write(TEST_MSG)
        H.read(6)
        assert len((tmp_path / "a.log").read_text().splitlines()) == n == 4 + 2 + 1     # and its end


@pytest.mark.slow
def test_a_serve_session_in_real_time_replays(tmp_path: Path) -> None:
    """serve's own loop (TcpBridge, RealTimePacer at 4x, twin.run_realtime_step), two clients over
    TCP with pyserial's socket:// URL, the log attached as serve would: the lockstep replay
    gives the same answers at the same microseconds, whatever wall time each step took."""
    import threading
    import time

    from humanoid_twin.bus.bridges import TcpBridge
    from humanoid_twin.clock import RealTimePacer
    from humanoid_twin.master.usart import FRAME_GAP_US, PROCESS_US

    path = tmp_path / "serve.serial.log"
    twin = Twin(seed=1)
    log = SerialLog.attach(twin, path)
    bridge = TcpBridge(twin.link, port=0, log=lambda s: None, on_session=twin.master.reset_receiver,
                       quiet_us=FRAME_GAP_US + PROCESS_US + 1_000)
    errors: list[BaseException] = []

    def clients() -> None:
        try:
            for n in range(2):
                H, _ = initcom(bridge.port_name)
                if n == 0:
                    power_on(H)
                readjoint(H, 1, 0)
                H.write(TEST_MSG)
                assert H.read(6)[:1] == bytes([0xFA])
                killcom(H)
                time.sleep(0.3)
        except BaseException as exc:  # reported by the test below
            errors.append(exc)

    th = threading.Thread(target=clients, daemon=True)
    pacer = RealTimePacer(twin.clock, speed=4.0)
    pacer.start()
    th.start()
    deadline = time.monotonic() + 60
    try:
        while (th.is_alive() or bridge.sessions < 2) and time.monotonic() < deadline:
            bridge.poll()
            if twin.run_realtime_step(pacer, max_step_us=1_000) == 0:
                time.sleep(0.0005)
            bridge.poll()
        for _ in range(200):                  # the second client's leave reaches the bridge
            bridge.poll()
            twin.run_realtime_step(pacer, max_step_us=1_000)
            time.sleep(0.001)
    finally:
        bridge.close()
        log.close()
        twin.close()
    assert not errors, errors
    _, records = read_log(path)
    assert sum(r.event == "unplug" for r in records) >= 3     # two sessions began, at least one ended
    res = replay(path)
    assert res.difference is None, res.difference
    assert res.twin_bytes == sum(len(r.data) for r in records if r.event == "twin>host") > 400



def test_a_header_that_cannot_be_written_leaves_no_open_file(tmp_path):
    twin = Twin(seed=1)
    fds = len(os.listdir("/proc/self/fd"))
    with pytest.raises(TypeError) as exc:
        SerialLog(tmp_path / "x.serial", twin.link, meta={"seed": object()})   # not JSON
    assert exc.value is not None and len(os.listdir("/proc/self/fd")) == fds
