"""The host (humanoid_twin.host) against the real twin: real pyserial ports, the real Master,
CAN, Slaves and MuJoCo plant. The drivers are used unchanged, through ``twin.open_port()``,
``initcom(twin.url)`` or a TCP socket; nothing here mocks a library."""

from __future__ import annotations

import socket
import time

import numpy as np
import pytest
import serial

from humanoid_twin.host import (
    HumanoidClient,
    InvalidRequest,
    applycontrol,
    applyjoint,
    calccop,
    calibcom,
    controller,
    controller_off,
    cop_acquire,
    cop_realtime,
    exe_traj,
    flexao,
    inclinar,
    initcom,
    killcom,
    levantar_perna,
    now,
    power_on,
    readcanstat,
    readjoint,
    readspecial,
    recycle,
    sample_traj,
    sample_traj3,
    servo_command,
    sleep,
)
from humanoid_twin.host.drivers import STATUS_CALIB, STATUS_PWM, ErrorCode
from humanoid_twin.host.planners import HOLD
from humanoid_twin.host.trajectory import cubic
from humanoid_twin.protocol.rs232 import TEST_MESSAGE, bcc
from humanoid_twin.twin import Twin


def truth_log(tw: Twin, period_us: int = 20_000) -> list:
    log: list = []
    tw.every(period_us, lambda: log.append(tw.plant.truth()))
    return log


# --- the drivers, one by one ------------------------------------------------------------------

def test_calibcom_gets_the_test_message_through_initcom_and_the_url(twin):
    H, state = initcom(twin.url)
    assert state["baudrate"] == 115200 and state["parity"] == "E" and state["bytesize"] == 8
    r = calibcom(H)
    assert r.rx == TEST_MESSAGE == bytes.fromhex("FAF9F8F7F6F5")
    assert r.ok and r.error == ErrorCode.OK and r.errorstr == "ok" and r.tries == 1
    assert killcom(H) == 1 and not H.is_open


def test_applyjoint_is_answered_FB_with_the_echo(twin):
    H = twin.open_port()
    r = applyjoint(H, 2, 0, [0, 0, 70])                 # seed 002 slide 11's example
    assert r.error == ErrorCode.OK and r.tries == 1
    assert r.rx[0] == 0xFB and r.rx[1:5] == bytes([0x08, 0, 0, 70]) and r.rx[5] == bcc(r.rx[:5])
    r = applyjoint(H, 2, 1, [100, 100, 100])            # period 2 s
    assert r.rx == bytes([0xFB, 0x09, 100, 100, 100, 0xFB ^ 0x09 ^ 100])
    r = applycontrol(H, 1, 3, [1, 1, 3])
    assert r.error == ErrorCode.OK and r.rx[0] == 0xFB
    assert twin.master.db.actuators[2].ref == [0, 0, 70]


@pytest.mark.parametrize(
    "call",
    [lambda H: applyjoint(H, 9, 0, [0, 0, 0]),          # SCU out of range
     lambda H: applyjoint(H, 1, 2, [0, 0, 0]),          # APPLY_JOINT param 10
     lambda H: applyjoint(H, 1, 0, [0, 100, 0]),        # position beyond 90 degrees
     lambda H: applycontrol(H, 3, 3, [0, 4, 0])],       # control type 4
)
def test_an_invalid_request_gives_the_FC_error_code_without_retrying(twin, call):
    H = twin.open_port()
    r = call(H)
    assert r.error == ErrorCode.INVALID_REQUEST and r.tries == 1
    assert r.rx[0] == 0xFC and "FC" in r.errorstr
    with HumanoidClient(H) as robot, pytest.raises(InvalidRequest):
        robot.set_positions(0, [0, 0, 0])


def test_readjoint_after_a_move_reads_where_the_servos_went(booted_twin):
    tw, H = booted_twin
    target = [30, -20, 45]                              # right arm: harmless for the stance
    assert applyjoint(H, 6, 1, [25, 25, 25]).error == 0  # 0.5 s
    assert applyjoint(H, 6, 0, target).error == 0
    t0 = now(H)
    sleep(H, 1.0)
    assert now(H) - t0 == pytest.approx(1.0, abs=1e-3)   # the twin's virtual time base
    r = readjoint(H, 6, 0)
    assert r.error == ErrorCode.OK
    assert np.allclose(r.servos, target, atol=2)
    assert r.state & (STATUS_PWM | STATUS_CALIB) == STATUS_PWM | STATUS_CALIB
    truth = [tw.plant.servo_angle_deg(6, i) for i in range(3)]
    assert np.allclose(truth, target, atol=2)
    cur = readjoint(H, 6, 2)
    assert all(0 <= c <= 100 for c in cur.servos)
    vel = readjoint(H, 6, 1)
    assert vel.servos == (0, 0, 0)                      # at rest


def test_readspecial_and_readcanstat_on_a_standing_robot(booted_twin):
    tw, H = booted_twin
    sleep(H, 0.1)
    for scu in (1, 2):
        r = readspecial(H, scu)
        assert r.error == ErrorCode.OK and len(r.special) == 4
        # calibrated standing: every sensor reads about 128 (the calibration load)
        assert all(abs(v - 128) <= 3 for v in r.special), r.special
    c = readcanstat(H)
    assert c.error == ErrorCode.OK and c.array[0] == 0        # error-active
    assert c.state != 0                                       # slaves answered the last round


def test_power_on_switches_pwm_on_and_waits_for_the_calibration(twin):
    H = twin.open_port()
    assert readjoint(H, 1, 0).state & STATUS_PWM == 0
    t0 = now(H)
    status = power_on(H, scus=(1, 2))
    assert all(s & (STATUS_PWM | STATUS_CALIB) == STATUS_PWM | STATUS_CALIB for s in status.values())
    assert now(H) - t0 >= 2.0                                  # the Slave waits 2 s + 25 ticks
    # a recalibration request: done only once the Slave has been seen running it again
    t0 = now(H)
    status = power_on(H, scus=(1,), calibrate=True)
    assert status[1] & STATUS_CALIB and now(H) - t0 >= 2.0


def test_controller_and_controller_off_set_every_board(twin):
    H = twin.open_port()
    controller(H)
    db = twin.master.db.actuators
    for scu in (1, 2, 3, 4):
        assert db[scu].type == [1, 1, 1] and db[scu].ki == [1, 1, 1] and db[scu].kp == [0, 0, 0]
    assert db[5].type == [0, 0, 0]
    controller(H, [[3, 4, 5]] * 3, control=3, scus=(2,))
    assert db[2].type == [3, 3, 3] and db[2].ki == [3, 3, 3] and db[2].kd == [5, 5, 5]
    controller_off(H)
    assert all(db[scu].type == [0, 0, 0] for scu in range(1, 9))


# --- retries (figs. 18-20) --------------------------------------------------------------------

def test_a_swallowed_first_frame_is_retried_and_counted(twin):
    """Stray bytes ``FF 00 00 00 00`` on the line make the Master take the driver's first 0xFF as
    the BCC of a frame of their own (answered FC, not an echo of the request): the driver resets
    and sends again. The second try is answered."""
    H = twin.open_port()
    H.write(bytes([0xFF, 0x00, 0x00, 0x00, 0x00]))
    r = calibcom(H)
    assert r.ok and r.error == ErrorCode.OK and r.tries == 2
    H.write(bytes([0xFF, 0x00, 0x00, 0x00, 0x00]))
    r = readjoint(H, 1, 0)
    assert r.error == ErrorCode.OK and r.tries == 2 and r.servos == (0, 0, 0)


def test_serial_noise_costs_retries_but_never_wrong_data(booted_twin):
    tw, H = booted_twin
    clean = readjoint(H, 6, 0).servos
    tw.link.set_noise(0.03, seed=7)                        # ~30 % of the exchanges hit
    results = [readjoint(H, 6, 0, max_tries=6) for _ in range(40)]
    results += [calibcom(H, max_tries=6) for _ in range(20)]
    tw.link.set_noise(0.0)
    tries = [r.tries for r in results]
    assert max(tries) >= 2 and sum(t > 1 for t in tries) >= 5
    for r in results:
        assert r.error == ErrorCode.OK, r.errorstr
    assert all(r.servos == clean for r in results[:40])
    assert all(r.ok for r in results[40:])
    assert tw.link.stats()["bytes_corrupted"] > 0
    assert tw.master.stats()["serial_frames_rejected"] > 0


def test_a_silent_line_times_out_after_max_tries_on_a_tcp_port():
    """A TCP peer that never answers: the same drivers over ``socket://``, on the wall clock."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    url = f"socket://127.0.0.1:{srv.getsockname()[1]}"
    H, _ = initcom(url, timeout=0.05)
    conn, _ = srv.accept()
    try:
        t0 = time.monotonic()
        r = readjoint(H, 1, 0)
        wall = time.monotonic() - t0
        assert r.error == ErrorCode.TIMEOUT and r.tries == 3 and r.servos is None
        assert "after 3 tries" in r.errorstr
        assert 0.14 <= wall < 2.0
        conn.settimeout(1.0)
        got = b""
        while len(got) < 18:
            got += conn.recv(64)
        assert got == bytes([0xFF, 0x84, 0, 0, 0, 0xFF ^ 0x84]) * 3     # the same request, 3 times
    finally:
        killcom(H)
        conn.close()
        srv.close()


def test_humanoid_client_speaks_for_the_drivers(booted_twin):
    tw, H = booted_twin
    killcom(H)                                  # a serial port has one host end
    with HumanoidClient(tw.url) as robot:
        assert robot.test() == TEST_MESSAGE
        robot.set_period(6, [0, 0, 0])
        robot.set_positions(6, [-10, 10, 20])
        sleep(robot, 0.5)
        assert np.allclose(robot.read_positions(6), [-10, 10, 20], atol=2)
        assert len(robot.read_forces(1)) == 4
        assert robot.can_status().state_name == "error-active"
        assert robot.stats["requests"] == 6 and robot.stats["failures"] == 0
    assert robot.closed


# --- the motions through exe_traj (tables 22-25) -------------------------------------------------

def check_traj(d, n_test: int):
    n = d.tt.shape[0]
    assert d.position.shape == d.velocity.shape == d.current.shape == (n_test, 3, n)
    assert np.all(np.diff(d.tt) > 0)
    assert not np.any(np.isnan(d.position))


def test_flexao_through_exe_traj_bends_both_legs_with_flat_feet(booted_twin):
    tw, H = booted_twin
    pos, k, t = flexao(1.0, 20)
    log = truth_log(tw)
    d = exe_traj(H, t, pos, 1.0, k)
    check_traj(d, 4)
    assert d.tt[-1] == pytest.approx(2.0, abs=0.05)
    # measured positions follow the planned cubic (lag of the LOCOMOTION loop) and end on it
    cmd = np.array([servo_command(s, pos[s - 1, :, 0]) for s in (1, 2, 3, 4)])
    plan, _, _ = cubic(d.tt - d.tt[0], 1.0, np.zeros(12), cmd.ravel())
    err = np.abs(d.position.reshape(12, -1).T - plan)
    assert err.max() <= 20
    assert np.abs(d.position[:, :, -1] - cmd).max() <= 2
    knee = d.position[0, 2]
    assert np.all(np.diff(knee[d.tt < 1.0]) >= -1)        # the knee bends steadily
    # ground truth: trunk upright, feet flat and loaded, knees at 2 x motion
    g = log[-1]
    assert max(x.trunk_tilt_deg for x in log) < 4
    assert g.joint_angles_deg["r_knee"] == pytest.approx(40, abs=1.5)
    assert g.joint_angles_deg["l_ankle_pitch"] == pytest.approx(-20, abs=1.5)
    for foot in ("r_foot", "l_foot"):
        zaxis = tw.plant.data.body(foot).xmat.reshape(3, 3)[:, 2]
        assert np.degrees(np.arccos(min(1.0, zaxis[2]))) < 2
        assert np.all(g.pad_forces_n[foot] > 1.0)


def test_inclinar_through_exe_traj_moves_the_body_sideways(booted_twin):
    tw, H = booted_twin
    pos, k, t = inclinar(1.0, 10)
    log = truth_log(tw)
    com0 = tw.plant.truth().com
    d = exe_traj(H, t, pos, 0.5, k, dt=0.04)
    check_traj(d, 4)
    assert np.all(np.diff(d.tt) >= 0.039)
    cmd = np.array([servo_command(s, pos[s - 1, :, 0]) for s in (1, 2, 3, 4)])
    assert np.abs(d.position[:, :, -1] - cmd).max() <= 1
    assert cmd[1, 0] == -10 and cmd[0, 0] == 10             # mirrored left ankle roll servo
    g = log[-1]
    assert g.com[1] - com0[1] > 0.015                       # leans to its left
    assert max(x.trunk_tilt_deg for x in log) < 3


def test_levantar_perna_through_exe_traj_lifts_the_right_foot_and_stands(booted_twin):
    tw, H = booted_twin
    pos, k, t = levantar_perna(1.0, 50, 1)
    log = truth_log(tw, 50_000)
    t0 = now(H)
    d = exe_traj(H, t, pos, 0.5, k)
    check_traj(d, 5)                                        # legs, hips and the torso (SCU 5)
    assert now(H) - t0 == pytest.approx(float(np.sum(t)) + 0.5, abs=0.1)   # shift 2 T, return 3 T
    # hold (motion 3): the right knee measured at ~50 degrees, the right foot off the floor
    h0 = float(np.sum(t[:HOLD]))
    hold = (d.tt > h0 + 0.7) & (d.tt < h0 + 1.0)
    assert np.all(np.abs(d.position[0, 2, hold] - 50) <= 3)
    times = np.array([x.t_s for x in log]) - t0
    in_hold = [x for x, ts in zip(log, times, strict=True) if h0 + 0.7 < ts < h0 + 1.0]
    assert all(x.pad_forces_n["r_foot"].sum() < 0.5 for x in in_hold)
    assert all(x.pad_forces_n["l_foot"].sum() > 40 for x in in_hold)
    # both feet down again, standing, back to vertical
    g = log[-1]
    assert not any(x.fell for x in log)
    assert max(x.trunk_tilt_deg for x in log) < 10
    assert g.pad_forces_n["r_foot"].sum() > 5 and g.pad_forces_n["l_foot"].sum() > 5
    assert np.abs(d.position[:4, :, -1]).max() <= 2


def test_recycle_brings_the_legs_back_to_vertical(booted_twin):
    tw, H = booted_twin
    pos, k, t = flexao(0.6, 15)
    exe_traj(H, t, pos, 0.2, k)
    t0 = now(H)
    sent = recycle(H, 30, True)
    assert now(H) - t0 == pytest.approx(0.6, abs=0.02)
    assert sent == [[0, 0, 0]] * 4
    sleep(H, 0.6)
    for scu in (1, 2, 3, 4):
        assert np.abs(readjoint(H, scu, 0).servos).max() <= 1


# --- one unit and the feet (tables 21, 27) ------------------------------------------------------

def test_sample_traj3_and_sample_traj_columns_follow_the_manual(booted_twin):
    tw, H = booted_twin
    k = [[1, 0, 0]] * 3
    a3 = sample_traj3(H, 1.0, [0, 0, 0], [30, -30, 20], k, Textra=0.4, settle=0.2)
    assert a3.shape[1] == 16
    assert a3[:, 0] == pytest.approx(np.sort(a3[:, 0]))
    assert a3[-1, 0] == pytest.approx(1.4, abs=0.05)
    # posT ends on posF, measured position close to it
    assert np.allclose(a3[-1, 4:7], [30, -30, 20])
    assert np.allclose(a3[-1, 1:4], [30, -30, 20], atol=2)
    assert np.abs(a3[0, 10:13]).max() < 1                  # velT starts at rest (deg/s)
    assert np.abs(a3[:, 10]).max() == pytest.approx(1.5 * 30 / 1.0, rel=0.02)   # cubic peak
    mid = (a3[:, 0] > 0.4) & (a3[:, 0] < 0.8)
    assert np.all(a3[mid, 7] >= 0) and np.all(a3[mid, 8] <= 0)   # measured velocities' signs
    a1 = sample_traj(H, 0.6, 30, -10, [1, 0, 0], Textra=1.0, settle=0.2)
    assert a1.shape[1] == 6
    assert a1[-1, 4] == -10 and abs(a1[-1, 1] - -10) <= 2
    assert np.all((a1[:, 3] >= 0) & (a1[:, 3] <= 100))


def test_cop_acquire_and_calccop_agree_with_the_ground_truth(booted_twin):
    tw, H = booted_twin
    pos, k, t = inclinar(1.0, 8)
    exe_traj(H, t, pos, 0.5, k)
    log = truth_log(tw)
    data = cop_acquire(H, 0.5, scu=1)
    n = data.time.shape[0]
    assert data.reaction.shape == (4, n) and data.CoP.shape == (2, n)
    assert data.servo.shape == (3, n) and data.current.shape == (3, n)
    assert np.allclose(data.servo[:, -1], [8, 0, 0], atol=1)
    truth = np.array([x.foot_cop_mm["r_foot"] for x in log])
    # host CoP (readings, assumed calibration load) vs MuJoCo contact CoP, right foot frame
    assert np.abs(np.nanmean(data.CoP, axis=1) - truth.mean(axis=0)).max() < 8
    assert np.allclose(calccop(data.reaction), data.CoP, equal_nan=True)


def test_cop_realtime_writes_a_recording_when_headless(booted_twin, tmp_path):
    from rerun.chunk import RrdReader

    tw, H = booted_twin
    path = tmp_path / "cop.rrd"
    data = cop_realtime(H, 2, 0.4, mode="save", path=path, chunk=7)
    assert data.time.shape[0] >= 15
    rows: dict[str, int] = {}
    for c in RrdReader(path).stream():
        rows[c.entity_path.lstrip("/")] = rows.get(c.entity_path.lstrip("/"), 0) + c.num_rows
    for entity in ("foot/outline", "foot/sensors", "foot/cop", "forces/front-left", "servo/position/1",
                   "servo/current/3"):
        assert entity in rows, sorted(rows)
    assert rows["forces/rear-right"] == data.time.shape[0]


def test_nothing_in_the_drivers_needs_the_in_process_port(booted_twin):
    """A plain pyserial loop:// port has no virtual clock: the time base falls back to the wall
    clock and the drivers run (and fail cleanly) without any twin attribute."""
    port = serial.serial_for_url("loop://", timeout=0.01)
    assert not hasattr(port, "virtual_time_s")
    r = readjoint(port, 1, 0)
    assert r.error == ErrorCode.UNEXPECTED_RESPONSE and r.tries == 3


def test_initcom_turns_a_refused_termios_setting_into_port_error():
    from humanoid_twin.host.drivers import PortError

    """A raw pty already at 115200 refuses PARENB (EINVAL, Linux): one PortError, no termios.error."""
    import os
    import termios
    import tty

    master, slave = os.openpty()
    try:
        tty.setraw(slave, termios.TCSANOW)
        name = os.ttyname(slave)
        H, _ = initcom(name, 115200)          # the first open changes the speed: accepted
        H.close()
        with pytest.raises(PortError, match="8E1"):
            initcom(name, 115200)             # same speed, parity asked again: refused
    finally:
        os.close(master)
        os.close(slave)
