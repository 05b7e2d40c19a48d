"""Issue 24, point 1: a latch that only a healthy robot opens (docs/supervisor.md, "Reset").

A host that answers FC with "reset and retry" must not drive a robot with a dead board: after a
silent Slave latched safe, reset is refused for as long as a board does not answer, however often
it is sent, and no APPLY is accepted in between; once the board answers again a reset opens it.
"""

from __future__ import annotations

import socket
import time

import pytest
from helpers import wait_for_mode

from humanoid_twin.host import drivers
from humanoid_twin.host.motion import power_on
from humanoid_twin.master import supervisor as sv
from humanoid_twin.protocol import rs232
from humanoid_twin.scenarios import boot
from humanoid_twin.twin import Twin

RESET = bytes([0xFF, 0xC2, 2, 0, 0, 0xFF ^ 0xC2 ^ 2])


def _apply_knee(d2: int) -> bytes:
    """APPLY_JOINT positions to SCU 1 (the right leg): the knee to ``d2`` degrees."""
    return rs232.encode_request(rs232.Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, 0, d2 & 0xFF, 0)


def test_reset_and_apply_against_a_silent_board_in_process_accepts_no_apply() -> None:
    with Twin(seed=1) as twin:
        H = boot(twin)
        twin.run_for(0.05)
        sup = twin.master.supervisor
        assert sup.mode == sv.READY
        twin.network.silence("slave3")
        twin.run_for(0.06)
        assert sup.mode == sv.SAFE
        knee0 = twin.slaves[1].servo.output[2]
        accepted = resets_ok = 0
        for i in range(200):                       # 200 x (reset, APPLY), 1.6 s of simulated time
            H.write(RESET)
            resets_ok += H.read(6)[0] == rs232.MESSAGE_SUCCESS
            H.write(_apply_knee(30 if i % 2 else -30))
            accepted += H.read(6)[0] == rs232.MESSAGE_SUCCESS
        assert (accepted, resets_ok) == (0, 0)
        assert sup.mode == sv.SAFE and twin.slaves[1].servo.output[2] == knee0
        # the host's typed error says why
        with pytest.raises(drivers.SupervisorRefused, match="latch holds until every board answers"):
            drivers.HumanoidClient(H).reset()
        # the board answers again: one reset opens the latch, the self-check reaches ready
        twin.network.silence("slave3", False)
        twin.run_for(0.05)
        assert drivers.reset(H).error == 0
        twin.run_for(0.05)
        assert sup.mode == sv.READY
        H.write(_apply_knee(5))
        assert H.read(6)[0] == rs232.MESSAGE_SUCCESS


def test_reset_after_estop_with_every_board_answering_still_recovers() -> None:
    with Twin(seed=2) as twin:
        H = boot(twin)
        twin.run_for(0.05)
        assert drivers.estop(H).error == 0
        twin.run_for(0.05)
        assert drivers.reset(H).error == 0
        assert drivers.readsupervisor(H).mode == sv.SELF_CHECK
        power_on(H)
        twin.run_for(0.05)
        assert drivers.readsupervisor(H).mode == sv.READY


def _exchange(sock: socket.socket, frame: bytes) -> bytes:
    sock.sendall(frame)
    got = b""
    deadline = time.monotonic() + 2.0
    while len(got) < 6 and time.monotonic() < deadline:
        got += sock.recv(6 - len(got))
    return got


def test_reset_and_apply_over_serve_tcp_against_a_silent_board_accepts_no_apply(serve) -> None:
    """The issue's own reproduction: ``serve --tcp`` with a board that falls silent; once safe, a
    client alternating reset and APPLY for 1.5 s gets no APPLY accepted."""
    proc, port = serve("--tcp", "0", "--fault", "silent:3@3")
    host, _, tcp = port.removeprefix("socket://").rpartition(":")
    with drivers.HumanoidClient(port, timeout=1.0) as robot:
        power_on(robot.serial_port, timeout=10.0)
        assert wait_for_mode(robot, "safe", 8) == "safe"
    with socket.create_connection((host, int(tcp)), timeout=2.0) as sock:
        accepted = resets = applies = 0
        end = time.monotonic() + 1.5
        i = 0
        while time.monotonic() < end:
            resets += _exchange(sock, RESET)[:1] == b"\xfb"
            ans = _exchange(sock, _apply_knee(30 if i % 2 else -30))
            applies += len(ans) == 6
            accepted += ans[:1] == b"\xfb"
            i += 1
        assert applies > 50                     # the client did drive the port
        assert (accepted, resets) == (0, 0)
    with drivers.HumanoidClient(port, timeout=1.0) as robot:
        sup = robot.supervisor()
        assert (sup.mode_name, sup.fault_name, sup.node) == ("safe", "silent", 3)
