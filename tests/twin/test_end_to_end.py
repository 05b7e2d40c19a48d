"""The whole chain, end to end: CAN log of a run, determinism, and the twin served on a pty and on
TCP to clients in other processes (a plain pyserial client, and the host drivers)."""

from __future__ import annotations

import os
import textwrap
import time
from collections import defaultdict

import can
import numpy as np
import pytest
from helpers import PYSERIAL_FRAME

from humanoid_twin.bus.frames import frame_bits
from humanoid_twin.hardware import PWM_BUSY_US, PWM_PERIOD_US
from humanoid_twin.host.motion import exe_traj, power_on
from humanoid_twin.host.planners import flexao
from humanoid_twin.protocol.canframes import OP_ACTUATION, OP_SENSORS, can_id, load_dbc, split_id
from humanoid_twin.protocol.wire import N_SCU
from humanoid_twin.recording.can_log import CanLog
from humanoid_twin.scenarios import boot
from humanoid_twin.twin import Twin

SLOT_US = 250


# --------------------------------------------------------------------------------------------
# CAN log of a run (issue 3): IDs, 250 us slots, 8 ms rounds, all 8 slaves, silence on PWM
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def logged_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("canlog") / "boot.asc"
    twin = Twin(seed=5)
    log = CanLog(path, twin.network)
    boot(twin)
    twin.run_for(0.5)
    log.close()
    phases = dict(twin.phases_us)
    twin.close()
    msgs = list(can.LogReader(str(path)))
    return msgs, phases


def _start_us(msg: can.Message) -> int:
    """When the frame's first bit went on the wire: its timestamp is the end of its EOF."""
    end = round(msg.timestamp * 1e6)
    return end - (frame_bits(msg.arbitration_id, bytes(msg.data)) - 3)


def test_can_log_ids_are_the_protocols_and_the_dbc_decodes_every_frame(logged_run):
    msgs, _ = logged_run
    db = load_dbc()
    assert len(msgs) > 10_000
    seen = set()
    for m in msgs:
        src, dst, index, op = split_id(m.arbitration_id)
        assert not m.is_extended_id
        if op == OP_ACTUATION:
            assert src == 0 and 1 <= dst <= N_SCU
        else:
            assert op == OP_SENSORS and dst == 0 and 1 <= src <= N_SCU
            assert m.data[0] >> 4 == src and (m.data[0] >> 3) & 1 == index   # SFlags
        seen.add(m.arbitration_id)
        decoded = db.decode_message(m.arbitration_id, bytes(m.data))
        assert decoded
    expected = {can_id(0, k, i, OP_ACTUATION) for k in range(1, 9) for i in (0, 1)}
    expected |= {can_id(k, 0, i, OP_SENSORS) for k in range(1, 9) for i in (0, 1)}
    assert seen == expected        # answers from all 8 slaves, both packets


def test_master_frames_sit_in_250_us_slots_1_ms_per_slave_8_ms_per_round(logged_run):
    msgs, _ = logged_run
    starts: dict[tuple[int, int], list[int]] = defaultdict(list)
    for m in msgs:
        src, dst, index, op = split_id(m.arbitration_id)
        if op == OP_ACTUATION:
            starts[(dst, index)].append(_start_us(m))
    t0 = starts[(1, 0)][0]
    for (dst, index), ts in starts.items():
        offset = (dst - 1) * 1000 + index * 2 * SLOT_US          # slot 0 TX act 1, slot 2 TX act 2
        for t in ts:
            assert (t - t0 - offset) % 8000 == 0, (dst, index, t - t0)
        assert set(np.diff(ts)) == {8000}                      # one round = 8 ms, never skipped


def test_each_answer_follows_its_packet_and_silence_falls_in_the_pwm_window(logged_run):
    msgs, phases = logged_run
    answered = silent = 0
    for i, m in enumerate(msgs):
        src, dst, index, op = split_id(m.arbitration_id)
        if op != OP_ACTUATION:
            continue
        arrival = round(m.timestamp * 1e6)
        reply_id = can_id(dst, 0, index, OP_SENSORS)
        reply = next((r for r in msgs[i + 1:i + 4] if r.arbitration_id == reply_id), None)
        in_window = (arrival - phases[dst]) % PWM_PERIOD_US < PWM_BUSY_US
        if reply is None:
            assert in_window, f"slave {dst} silent outside its PWM window at {arrival} us"
            silent += 1
        else:
            assert not in_window
            assert 0 < _start_us(reply) - arrival < SLOT_US    # answered within the slot
            answered += 1
    assert silent > 0 and answered > 3 * silent                # some silence (~10%), mostly answers


# --------------------------------------------------------------------------------------------
# Determinism (issue 3): same inputs and seed -> identical bytes and trajectories
# --------------------------------------------------------------------------------------------
def _scripted_run(seed: int) -> tuple[list, bytes, np.ndarray, np.ndarray]:
    twin = Twin(seed=seed)
    frames = can.BufferedReader()
    twin.network.add_listener(frames)
    H = twin.open_port()
    serial_in = bytearray()
    read = H.read

    def recording_read(n: int = 1) -> bytes:
        data = read(n)
        serial_in.extend(data)
        return data

    H.read = recording_read
    power_on(H)
    pos, k, t = flexao(0.5, 10)
    traj = exe_traj(H, t, pos, 0.3, k=k)
    out = []
    while (m := frames.get_message(0)) is not None:
        out.append((m.timestamp, m.arbitration_id, bytes(m.data)))
    qpos = twin.plant.data.qpos.copy()
    twin.close()
    return out, bytes(serial_in), np.asarray(traj.position), qpos


@pytest.mark.slow
def test_same_seed_same_bytes_and_trajectories():
    a = _scripted_run(seed=11)
    b = _scripted_run(seed=11)
    c = _scripted_run(seed=12)
    assert a[0] == b[0]                          # every CAN frame, timestamp and byte
    assert a[1] == b[1]                          # every byte the Master sent to the host
    assert np.array_equal(a[2], b[2])            # exe_traj's measured positions
    assert np.array_equal(a[3], b[3])            # the physics, bit for bit
    assert a[0] != c[0] and not np.array_equal(a[3], c[3])   # another seed is another robot


# --------------------------------------------------------------------------------------------
# serve: a pty and a TCP port for clients in other processes
# --------------------------------------------------------------------------------------------
PLAIN_CLIENT = PYSERIAL_FRAME + textwrap.dedent(r"""
    port = serial.serial_for_url(sys.argv[1], baudrate=115200, parity="E", timeout=1.0)

    def ask(raw):
        port.reset_input_buffer()
        port.write(raw)
        return port.read(6).hex(" ")

    out = {}
    out["test"] = ask(frame(3, 0, 0))
    # head board (8): positions, period 0, PWM on -> the Slave calibrates (2.5 s)
    out["boot"] = [ask(frame(0, 8, 0, 0, 0, 0)), ask(frame(0, 8, 1)), ask(frame(0, 8, 3, 1))]
    time.sleep(3.2)
    out["period"] = ask(frame(0, 8, 1, 25, 25, 25))
    out["move"] = ask(frame(0, 8, 0, 30, -20, 45))
    time.sleep(1.5)
    out["position"] = ask(frame(2, 8, 0))
    out["special"] = ask(frame(2, 1, 3))
    out["invalid"] = ask(frame(0, 8, 2, 1, 2, 3))
    out["range"] = ask(frame(0, 8, 0, 91, 0, 0))
    bad = bytearray(frame(3, 0, 0)); bad[-1] ^= 0x55
    port.reset_input_buffer()
    port.write(bytes(bad) + bytes([0x12, 0xFF, 0x34]) + frame(3, 0, 0))
    out["after_noise"] = port.read(12).hex(" ")
    print(json.dumps(out))
""")


def _bcc(*b: int) -> int:
    x = 0
    for v in b:
        x ^= v
    return x


@pytest.mark.slow
def test_plain_pyserial_client_over_a_pty(serve):
    proc, port = serve("--pty")
    try:
        assert port.startswith("/dev/pts/") and os.path.exists(port)
        out = serve.client(PLAIN_CLIENT, port)
    finally:
        serve.stop(proc)
    assert out["test"] == "fa f9 f8 f7 f6 f5"
    assert all(r.startswith("fb") for r in out["boot"])
    assert out["move"] == f"fb 20 1e ec 2d {_bcc(0xFB, 0x20, 0x1E, 0xEC, 0x2D):02x}"   # echo, BCC recomputed
    pos = bytes.fromhex(out["position"])
    assert pos[0] == 0xFD and pos[5] == _bcc(*pos[:5])
    measured = [int.from_bytes(pos[i:i + 1], "big", signed=True) for i in (1, 2, 3)]
    assert np.allclose(measured, [30, -20, 45], atol=1)          # the servos got there, in the physics
    special = bytes.fromhex(out["special"])
    assert special[0] == 0xFD and sum(special[1:5]) > 0          # the right foot carries load
    assert out["invalid"].startswith("fc 22 01 02 03")
    assert out["range"].startswith("fc")
    assert out["after_noise"] == "fa f9 f8 f7 f6 f5"             # only the good frame answered


DRIVER_CLIENT = r"""
    import json, sys
    import numpy as np
    from humanoid_twin.host import calibcom, initcom, killcom, power_on, exe_traj, flexao, readcanstat

    # 0.5 s a try, not the toolbox's 0.1: on a loaded machine (the suite on every core) the twin
    # serving in real time can answer 0.1 s late; the late answer's tail then shifts every retry
    # (seen: "first byte 0x00 [00 E1 FB 1B 01 00] (after 3 tries)")
    H, state = initcom(sys.argv[1], 115200, timeout=0.5)
    test = calibcom(H)
    power_on(H)
    pos, k, t = flexao(1.0, 10)
    tt, position, velocity, current = exe_traj(H, t, pos, 0.5, k=k)
    can = readcanstat(H)
    killcom(H)
    print(json.dumps({"test_ok": bool(test.ok) if hasattr(test, "ok") else test.error == 0,
                      "shape": list(np.asarray(position).shape), "n": len(tt),
                      "final": np.asarray(position)[:, :, -1].tolist(), "can_error": int(can.error)}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["pty", "tcp"])
def test_host_drivers_unchanged_against_serve(mode, serve):
    proc, port = serve("--tcp", "0") if mode == "tcp" else serve("--pty")
    try:
        if mode == "tcp":
            assert port.startswith("socket://127.0.0.1:")
        out = serve.client(DRIVER_CLIENT, port, timeout=90)
    finally:
        serve.stop(proc)
    assert out["test_ok"] and out["can_error"] == 0
    n_scu, n_servo, n_t = out["shape"]
    assert (n_scu, n_servo) == (4, 3) and n_t == out["n"] > 10
    final = np.asarray(out["final"])
    # flexao(1, 10): ankle pitch -10, knee +20 on both legs (servo frame = leg frame on these joints)
    assert abs(abs(final[0, 2]) - 20) <= 2 and abs(abs(final[1, 2]) - 20) <= 2


@pytest.mark.slow
def test_serve_keeps_real_time(serve):
    proc, port = serve("--tcp", "0")
    try:
        time.sleep(3.0)
        assert proc.poll() is None
    finally:
        serve.stop(proc)
    err = proc.stderr.read()
    assert "behind real time" not in err, err


BOOT_CLIENT = """
import json, sys, time
from humanoid_twin.host import initcom, killcom, power_on
H, _ = initcom(sys.argv[1])
t0 = time.monotonic()
power_on(H, timeout=30)   # the Slaves calibrate: ~2.65 s of the twin's time (wall timeout)
print(json.dumps({"wall_s": time.monotonic() - t0}))
killcom(H)
"""


@pytest.mark.slow
def test_serve_speed_slows_the_twin_down(serve):
    """Issue 25: `serve --speed X` paces the twin at X times real time (the pacer supported it, the
    CLI did not). At 0.5 the 2.65 s boot takes 5.3 s of wall time (at 1x: 2.7 s). The pacer
    catches up after a stall, so on a loaded machine a boot that starts while the twin lags ends a
    little early (5.15 s seen): the bound keeps 15 % for that and still fails at 1x."""
    proc, port = serve("--tcp", "0", "--speed", "0.5")
    try:
        out = serve.client(BOOT_CLIENT, port, timeout=60)
    finally:
        serve.stop(proc)
    assert out["wall_s"] >= 0.85 * 2.65 / 0.5
    assert "0.5x real time" in proc.stderr.read()
