"""The Slave boards on the real plant (MuJoCo), the real CAN network and, at the end, the real Master:
calibration, measurement, the CAN answers of the low-priority interrupt (slide 29) and faults.

A small python-can node attached to the network plays the Master where the test needs exact
control of when each actuation packet is sent."""

from __future__ import annotations

import math

import can
import mujoco
import numpy as np
import pytest

from humanoid_twin import hardware
from humanoid_twin.bus import frame_bits
from humanoid_twin.bus.network import CanNetwork
from humanoid_twin.clock import Clock
from humanoid_twin.plant import Plant
from humanoid_twin.plant.constants import SERVO_SIGN_BY_SCU
from humanoid_twin.protocol import rs232
from humanoid_twin.protocol.canframes import (
    OP_ACTUATION,
    OP_SENSORS,
    can_id,
    control_byte,
    master_filters,
    pack_actuation1,
    pack_actuation2,
    parse_status_byte,
    split_id,
    unpack_sensors1,
    unpack_sensors2,
)
from humanoid_twin.slave import Slave, data
from humanoid_twin.slave.can import ISR_LATENCY_US
from humanoid_twin.slave.slave import LEG_SIGNS

PERIOD = hardware.PWM_PERIOD_US


class Recorder(can.Listener):
    """Every frame that completed on the wire, with its end time in virtual microseconds."""

    def __init__(self) -> None:
        self.frames: list[tuple[int, can.Message]] = []

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append((round(msg.timestamp * 1e6), msg))

    def sensors_from(self, scu: int, after_us: int = 0) -> list[tuple[int, int, can.Message]]:
        out = []
        for t, m in self.frames:
            src, dst, index, op = split_id(m.arbitration_id)
            if src == scu and dst == 0 and op == OP_SENSORS and t >= after_us:
                out.append((t, index, m))
        return out

    def actuations_to(self, scu: int, after_us: int = 0) -> list[tuple[int, int, can.Message]]:
        out = []
        for t, m in self.frames:
            src, dst, index, op = split_id(m.arbitration_id)
            if src == 0 and dst == scu and op == OP_ACTUATION and t >= after_us:
                out.append((t, index, m))
        return out


class Rig:
    """Plant + CAN network + some Slaves + a test node in the Master's place."""

    def __init__(self, addresses=range(1, 9), phases: dict[int, int] | None = None, seed: int = 0) -> None:
        self.clock = Clock()
        self.plant = Plant(seed=seed, clock=self.clock)
        self.net = CanNetwork(self.clock)
        self.rec = Recorder()
        self.net.add_listener(self.rec)
        phases = phases or {}
        self.slaves = {
            k: Slave(k, self.clock, self.plant, self.net, phase_us=phases.get(k, 250 * k + 4000 * (k % 3)))
            for k in addresses
        }
        self.node = self.net.attach("tester", master_filters(), None)
        self.refs = {k: (0, 0, 0) for k in range(1, 9)}
        self.pwm = False
        self.calib = False
        self.types = {k: (0, 0, 0) for k in range(1, 9)}
        self.speeds = {k: (0, 0, 0) for k in range(1, 9)}
        self.kp = {k: (0, 0, 0) for k in range(1, 9)}
        self.ki = {k: (0, 0, 0) for k in range(1, 9)}

    def packet(self, scu: int, index: int, dst: int | None = None, op: int = OP_ACTUATION) -> can.Message:
        if index == 0:
            payload = pack_actuation1(
                self.refs[scu], self.speeds[scu], control_byte(self.pwm, self.calib, self.types[scu]), 0
            )
        else:
            payload = pack_actuation2(self.ki[scu], self.kp[scu], 0, 0)
        arb = can_id(0, scu if dst is None else dst, index, op)
        return can.Message(arbitration_id=arb, data=payload, is_extended_id=False)

    def send_at(self, t_us: int, scu: int, index: int, **kw) -> None:
        self.clock.schedule(t_us, lambda: self.node.send(self.packet(scu, index, **kw)))

    def poll(self) -> None:
        """A Master-like schedule: every 8 ms, 1 ms per slave, packets at 0 and 500 us."""

        def round_() -> None:
            t = self.clock.now_us
            for k in self.slaves:
                self.send_at(t + (k - 1) * 1000, k, 0)
                self.send_at(t + (k - 1) * 1000 + 500, k, 1)

        self.clock.call_every(8000, round_, self.clock.now_us)

    def run_until(self, t_us: int) -> None:
        self.clock.run_until(t_us)
        self.plant.advance_to(t_us)


def last_status(rig: Rig, scu: int):
    frames = [m for _, i, m in rig.rec.sensors_from(scu) if i == 0]
    return parse_status_byte(frames[-1].data[7]), unpack_sensors1(bytes(frames[-1].data))


# ---------------------------------------------------------------------------------------------
# calibration and measurement


@pytest.fixture(scope="module")
def calibrated_rig() -> Rig:
    """All 8 boards, PWM on at 0.2 s with the stand pose (0 deg) except the right arm (board 6)
    and the head (board 8) at other angles; run to 3 s."""
    rig = Rig(seed=5)
    rig.refs[6] = (30, -20, 40)
    rig.refs[8] = (25, -15, 45)
    rig.poll()
    rig.run_until(200_000)
    rig.before = {  # measurements before calibration, with the nominal pot law
        k: ([s.sensors.servo[i].pos for i in range(3)], [rig.plant.servo_angle_deg(k, i) for i in range(3)])
        for k, s in rig.slaves.items()
    }
    rig.powered_before = any(rig.plant.servo_powered(k, i) for k in range(1, 9) for i in range(3))
    rig.pwm = True
    rig.t_on = rig.clock.now_us
    rig.run_until(2_650_000)
    rig.calibrated_at_2_65 = {k: s.calibrated for k, s in rig.slaves.items()}
    rig.run_until(3_000_000)
    return rig


def test_servos_stay_limp_and_uncalibrated_until_pwm_is_switched_on(calibrated_rig):
    rig = calibrated_rig
    assert not rig.powered_before
    first = [m for t, i, m in rig.rec.sensors_from(1) if i == 0 and t < rig.t_on]
    assert first, "the slave answers before PWM is on"
    st = parse_status_byte(first[-1].data[7])
    assert not st.pwm and not st.calib


def test_calibration_takes_2_5_s_and_positions_then_match_the_request(calibrated_rig):
    rig = calibrated_rig
    for k, s in rig.slaves.items():
        assert s.calibrated and s.calib.runs == 1, k
        # the first tick after PWM-on, then 100 ticks of settling and 25 samples: 2.5 s
        t_first = rig.t_on + (s.phase_us - rig.t_on) % PERIOD
        t_done = t_first + 125 * PERIOD
        assert rig.calibrated_at_2_65[k] == (t_done <= 2_650_000), k
        for i in range(3):
            requested = rig.refs[k][i]
            assert abs(s.sensors.servo[i].pos - requested) <= 1, (k, i)
            assert abs(rig.plant.servo_angle_deg(k, i) - requested) <= 2.0, (k, i)
            assert rig.plant.servo_powered(k, i)
        st, (src, _idx, pos, _vel, _status) = last_status(rig, k)
        assert src == k and st.pwm and st.calib and st.fin_all
        assert list(pos) == [s.sensors.servo[i].pos for i in range(3)]


def test_before_calibration_the_nominal_pot_law_is_off_by_the_servo_offset(calibrated_rig):
    rig = calibrated_rig
    errs_before = []
    for k in rig.slaves:
        measured, true = rig.before[k]
        for i in range(3):
            offset = rig.plant.pot_b_true_deg[k][i] - hardware.POT_B_NOMINAL_DEG
            assert abs(measured[i] - (true[i] - offset)) <= 1.0, (k, i)     # pos = 128 - m ADC
            errs_before.append(abs(measured[i] - true[i]))
    assert max(errs_before) > 4.0          # the plant's offsets (+-8 deg) that calibration removes


def test_force_sensors_read_128_at_the_calibration_load_and_the_cop_matches_ground_truth(calibrated_rig):
    rig = calibrated_rig
    truth = rig.plant.truth()
    for k, foot in hardware.FOOT_OF_SCU.items():
        s = rig.slaves[k]
        assert all(abs(v - 128) <= 2 for v in s.sensors.special), s.sensors.special
        assert all(o < 128 for o in s.pic.offsets)                 # the foot was loaded
        assert s.cop_loaded
        gt = truth.foot_cop_mm[foot]
        assert abs(s.cop_x - gt[0]) <= 2.0 and abs(s.cop_y - gt[1]) <= 2.0, ((s.cop_x, s.cop_y), gt)
        _, _, _, data4 = unpack_sensors2(bytes([m for _, i, m in rig.rec.sensors_from(k) if i == 1][-1].data))
        assert list(data4) == s.sensors.special
    assert rig.slaves[6].sensors.special == [128] * 4               # no foot: offset 128 - 0
    # the body board's specials are its inclinometer and gyroscope: level and still, mid-scale
    assert all(abs(v - hardware.IMU_ZERO_COUNT) <= 2 for v in rig.slaves[5].sensors.special)


def test_firmware_leg_kinematics_agree_with_the_model():
    """LEG_SIGNS and the DATA derivation against the MuJoCo model: the mass centre of the two
    leg links in the foot frame, for servo angles on both legs."""
    plant = Plant()
    m, d = plant.model, plant.data
    rng = np.random.default_rng(0)

    def body(name: str) -> int:
        return mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)

    for scu, side in ((1, "r"), (2, "l")):
        joints = hardware.SERVO_JOINTS[scu]
        for _ in range(8):
            servo_deg = rng.uniform(-40, 40, 3)
            for j, name in enumerate(joints):
                qadr = m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)]
                d.qpos[qadr] = math.radians(SERVO_SIGN_BY_SCU[scu][j] * servo_deg[j])
            mujoco.mj_kinematics(m, d)
            foot = body(f"{side}_foot")
            links = [body(f"{side}_knee_link"), body(f"{side}_hip_pitch_link")]
            com = sum(m.body_mass[b] * d.xipos[b] for b in links) / sum(m.body_mass[b] for b in links)
            R = d.xmat[foot].reshape(3, 3)
            local = R.T @ (com - d.xpos[foot]) * 1000.0           # body frame: x fwd, y left, z up
            foot_frame = np.array([-local[1], local[0], local[2]])   # x right, y forward, z up
            kin = np.array(servo_deg) * LEG_SIGNS[scu]
            assert np.allclose(data.mass_centre_mm(*kin), foot_frame, atol=1e-6), (scu, servo_deg)


# ---------------------------------------------------------------------------------------------
# the CAN interrupt (slide 29)


@pytest.fixture()
def lone():
    """Slave 3 alone on the network, PWM period starting at phase 0."""
    return Rig(addresses=[3], phases={3: 0})


def test_answers_each_packet_with_the_same_index_after_the_isr_latency(lone):
    rig = lone
    rig.send_at(5_000, 3, 0)
    rig.send_at(5_500, 3, 1)
    rig.run_until(7_000)
    acts = rig.rec.actuations_to(3)
    resp = rig.rec.sensors_from(3)
    assert [i for _, i, _ in acts] == [0, 1] and [i for _, i, _ in resp] == [0, 1]
    for (t_act, _, _), (t_resp, index, m) in zip(acts, resp, strict=True):
        bits = frame_bits(m.arbitration_id, bytes(m.data))
        assert t_resp == t_act + ISR_LATENCY_US + bits - 3     # frame end = start + bits - IFS
        assert m.arbitration_id == can_id(3, 0, index, OP_SENSORS)
    src, idx, pos, vel, status = unpack_sensors1(bytes(resp[0][2].data))
    assert (src, idx) == (3, 0) and list(pos) == [s.pos for s in rig.slaves[3].sensors.servo]
    src, idx, curr, data4 = unpack_sensors2(bytes(resp[1][2].data))
    assert (src, idx) == (3, 1) and list(data4) == rig.slaves[3].sensors.special


def test_stays_silent_while_the_pwm_pulses_are_generated(lone):
    rig = lone
    sends = [20_000 * n + off for n, off in enumerate((0, 1_000, 1_700, 1_800, 1_950, 5_000, 19_800))]
    for t in sends:
        rig.send_at(t, 3, 0)
    rig.run_until(sends[-1] + 2_000)
    acts = rig.rec.actuations_to(3)
    answered = {t for t, _, _ in rig.rec.sensors_from(3)}
    assert len(acts) == len(sends)
    for t_end, _, m in acts:
        bits = frame_bits(m.arbitration_id, bytes(m.data))
        in_window = (t_end - rig.slaves[3].phase_us) % PERIOD < hardware.PWM_BUSY_US
        got = any(t_end < t <= t_end + ISR_LATENCY_US + bits for t in answered)
        assert got != in_window, (t_end, in_window)
    assert rig.slaves[3].can.tx_silent == 4     # frames ending ~125 us after 0, 1000, 1700, 1800 us
    assert rig.slaves[3].actuators.received == len(sends)   # the packets are still taken


def test_ignores_packets_for_other_boards_and_non_actuation_frames(lone):
    rig = lone
    rig.refs[5] = (40, 40, 40)
    rig.send_at(5_000, 5, 0)                               # for board 5 (not on the bus)
    rig.send_at(5_500, 5, 0, dst=3, op=OP_SENSORS)          # to board 3 but not an actuation
    rig.run_until(8_000)
    assert rig.rec.sensors_from(3) == []
    assert [s.ref for s in rig.slaves[3].actuators.servo] == [0, 0, 0]
    assert rig.slaves[3].can.rx_ignored == 2 and rig.slaves[3].can.rx_packets == 0


def test_a_new_packet_aborts_the_answer_still_pending(lone):
    rig = lone
    rig.send_at(5_000, 3, 0)
    act0_bits = frame_bits(can_id(0, 3, 0, 0), rig.packet(3, 0).data)
    # the second packet is requested before the answer to the first reaches the wire
    rig.send_at(5_000 + act0_bits - 3 + 5, 3, 1)
    rig.run_until(8_000)
    assert [i for _, i, _ in rig.rec.actuations_to(3)] == [0, 1]
    assert [i for _, i, _ in rig.rec.sensors_from(3)] == [1]   # sensors 1 aborted, sensors 2 sent


def test_malformed_actuation_packet_is_dropped_and_counted(lone):
    rig = lone
    bad = can.Message(arbitration_id=can_id(0, 3, 0, OP_ACTUATION), data=b"\x05\x05", is_extended_id=False)
    rig.clock.schedule(5_000, lambda: rig.node.send(bad))
    rig.run_until(7_000)
    assert rig.rec.sensors_from(3) == [] and rig.slaves[3].can.rx_errors == 1


def test_bus_off_is_recovered_by_check_can(lone):
    rig = lone
    rig.run_until(30_000)
    rig.net.force_bus_off("slave3")
    rig.send_at(31_000, 3, 0)
    rig.run_until(35_000)
    assert rig.rec.sensors_from(3) == []                     # bus-off: deaf and mute
    rig.run_until(45_000)                                     # the tick at 40 ms runs checkCan
    assert rig.slaves[3].can.bus_off_recoveries == 1
    rig.run_until(60_000)
    assert rig.slaves[3].can.controller.state == "error-active"
    rig.send_at(65_000, 3, 0)
    rig.run_until(67_000)
    assert len(rig.rec.sensors_from(3)) == 1


def test_deadline_violation_is_reported_in_the_status_byte(lone):
    rig = lone
    rig.run_until(30_000)
    rig.slaves[3].inject_deadline_violation(3_000)          # the tick at 40 ms starts 3 ms late
    rig.send_at(50_000, 3, 0)
    rig.send_at(70_000 + 5_000, 3, 0)
    rig.run_until(80_000)
    flags = [parse_status_byte(m.data[7]).deadline for _, _, m in rig.rec.sensors_from(3)]
    assert flags == [True, False]
    assert rig.slaves[3].deadline_violations == 1
    with pytest.raises(ValueError, match="delay_us"):
        rig.slaves[3].inject_deadline_violation(PERIOD)


# ---------------------------------------------------------------------------------------------
# control and recalibration on a calibrated board


def test_trajectory_calibration_request_and_pwm_off():
    rig = Rig(addresses=[5, 8], phases={5: 3_000, 8: 11_000}, seed=2)
    rig.poll()
    rig.pwm = True
    rig.run_until(2_700_000)
    s = rig.slaves[8]
    assert s.calibrated
    # a 1 s cubic move: the measured position follows, and the motion-finished bits come after
    rig.refs[8] = (40, -30, 0)
    rig.speeds[8] = (50, 50, 0)
    t0 = rig.clock.now_us
    rig.run_until(t0 + 500_000)
    mid = [s.sensors.servo[i].pos for i in range(2)]
    st, _ = last_status(rig, 8)
    assert 10 <= mid[0] <= 30 and -25 <= mid[1] <= -5 and not st.fin_all
    rig.run_until(t0 + 1_200_000)
    st, (_, _, pos, _, _) = last_status(rig, 8)
    assert abs(pos[0] - 40) <= 1 and abs(pos[1] + 30) <= 1 and st.fin_all
    # a calibration request: "not calibrated" at once, calibrated again 2.5 s later
    rig.calib = True
    t1 = rig.clock.now_us
    rig.run_until(t1 + 40_000)
    st, _ = last_status(rig, 8)
    assert not st.calib and not s.calibrated
    rig.run_until(t1 + 2_600_000)
    st, (_, _, pos, _, _) = last_status(rig, 8)
    assert st.calib and s.calib.runs == 2 and abs(pos[0] - 40) <= 1
    # PWM off: limp
    rig.pwm = False
    rig.run_until(rig.clock.now_us + 60_000)
    st, _ = last_status(rig, 8)
    assert not st.pwm and not any(rig.plant.servo_powered(8, i) for i in range(3))


def test_with_the_real_master_over_rs232():
    from humanoid_twin.twin import Twin

    with Twin(seed=4) as twin:
        port = twin.open_port()

        def ask(op, scu, param, d1=0, d2=0, d3=0) -> bytes:
            port.write(rs232.encode_request(op, scu, param, d1, d2, d3))
            return port.read(6)

        for scu in range(1, 9):
            assert ask(0, scu, rs232.PARAM_SPECIAL, 1)[0] == rs232.MESSAGE_SUCCESS
        target = (20, -35, 10)
        assert ask(0, 7, rs232.PARAM_POSITION, *(rs232.s8(v) for v in target))[0] == rs232.MESSAGE_SUCCESS
        twin.run_for(2.8)
        r = rs232.decode_response(ask(2, 7, rs232.PARAM_POSITION))
        pos = [rs232.from_s8(v) for v in r.values[:3]]
        assert all(abs(p - t) <= 1 for p, t in zip(pos, target, strict=True)), pos
        status = parse_status_byte(r.values[3])
        assert status.pwm and status.calib
        assert not twin.plant.truth().fell


def test_locomotion_pid_tracks_a_move_and_removes_the_steady_error():
    rig = Rig(addresses=[8], phases={8: 7_000}, seed=3)
    rig.poll()
    rig.pwm = True
    rig.run_until(2_700_000)
    s = rig.slaves[8]
    assert s.calibrated
    rig.types[8] = (1, 1, 0)                       # LOCOMOTION on servos 1 and 2
    rig.ki[8] = (2, 2, 0)                          # KI = 2/16 per tick (the host's default)
    rig.refs[8] = (35, -25, 0)
    rig.speeds[8] = (50, 50, 0)
    t0 = rig.clock.now_us
    rig.run_until(t0 + 2_000_000)
    assert [s.sensors.servo[i].pos for i in range(2)] == [35, -25]
    assert all(abs(rig.plant.servo_angle_deg(8, i) - r) <= 1.0 for i, r in enumerate((35, -25)))
    st, _ = last_status(rig, 8)
    assert st.fin_all
    # with KI = 0 the incremental PID holds its command: the servo does not follow a new reference
    rig.ki[8] = (0, 0, 0)
    rig.refs[8] = (0, 0, 0)
    rig.run_until(rig.clock.now_us + 1_500_000)
    assert abs(s.sensors.servo[0].pos - 35) <= 1
