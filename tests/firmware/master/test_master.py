"""The Master board twin: RS-232 requests/responses, the time-triggered CAN schedule, the database.

Real python-can bus (CanNetwork), real SerialLink; test slaves are plain python-can nodes attached
to the network that answer like a slave.
"""

from __future__ import annotations

import math
import random

import can
import pytest

from humanoid_twin.bus.frames import IFS_BITS, frame_bits
from humanoid_twin.bus.network import CanNetwork
from humanoid_twin.bus.serial_link import SerialLink
from humanoid_twin.clock import Clock
from humanoid_twin.master import Master
from humanoid_twin.master.database import Database
from humanoid_twin.master.pic import ROUND_US, SLAVE_PERIOD_US
from humanoid_twin.master.usart import FRAME_GAP_US, PROCESS_US
from humanoid_twin.protocol import canframes as cf
from humanoid_twin.protocol import rs232
from humanoid_twin.protocol.rs232 import Op

BYTE6_US = math.ceil(6 * 11 * 1_000_000 / 115_200)   # 6 bytes, 11 bits each, at 115200 baud
ANSWER_US = BYTE6_US + PROCESS_US + BYTE6_US


class Rig:
    """Clock + CAN network + serial link + Master, and a recorder of every completed CAN frame."""

    def __init__(self) -> None:
        self.clock = Clock()
        self.net = CanNetwork(self.clock)
        self.link = SerialLink(self.clock)
        self.frames = can.BufferedReader()
        self.net.add_listener(self.frames)
        self.master = Master(self.clock, self.net, self.link)

    def ask(self, frame: bytes, wait_us: int = ANSWER_US + 200) -> bytes:
        """Write a request on the host side, run the clock, return what came back."""
        self.link.host_write(frame)
        self.clock.run_for(wait_us)
        return self.link.host_read_available()

    def drain(self) -> list[can.Message]:
        out = []
        msg = self.frames.get_message(0)
        while msg is not None:
            out.append(msg)
            msg = self.frames.get_message(0)
        return out


class TestSlave:
    """A python-can node that answers each actuation packet for its address like a slave
    (slide 29): after ``latency_us``, the sensor packet of the same index."""

    __test__ = False

    def __init__(self, rig: Rig, address: int, latency_us: int = 20) -> None:
        self.rig = rig
        self.address = address
        self.latency_us = latency_us
        self.pos = [0, 0, 0]
        self.vel = [0, 0, 0]
        self.status = 0
        self.curr = [0, 0, 0]
        self.special = [0, 0, 0, 0]
        self.received: list[tuple[int, bytes]] = []   # (index, payload) of actuation packets
        self.silent = False
        self.ctl = rig.net.attach(f"test_slave{address}", cf.slave_filters(), self.on_rx)

    def on_rx(self, msg: can.Message) -> None:
        src, dst, index, op = cf.split_id(msg.arbitration_id)
        if dst != self.address or op != cf.OP_ACTUATION:
            return
        self.received.append((index, bytes(msg.data)))
        if not self.silent:
            self.rig.clock.after(self.latency_us, lambda: self.answer(index))

    def answer(self, index: int) -> None:
        if index == 0:
            data = cf.pack_sensors1(self.address, self.pos, self.vel, self.status)
        else:
            data = cf.pack_sensors2(self.address, self.curr, self.special)
        ident = cf.can_id(self.address, 0, index, cf.OP_SENSORS)
        self.ctl.send(can.Message(arbitration_id=ident, data=data, is_extended_id=False))


def req(op: int, scu: int, param: int, d1: int = 0, d2: int = 0, d3: int = 0) -> bytes:
    return rs232.encode_request(op, scu, param, d1, d2, d3)


def echo(frame: bytes, first: int) -> bytes:
    body = bytes([first]) + frame[1:5]
    return body + bytes([rs232.bcc(body)])


@pytest.fixture
def rig() -> Rig:
    return Rig()


# --- RS-232 ------------------------------------------------------------------------------------


def test_answer_timing_is_six_bytes_plus_processing_plus_six_bytes(rig: Rig) -> None:
    rig.clock.run_until(1_000)
    t0 = rig.clock.now_us
    rig.link.host_write(rs232.encode_request(Op.MASTER, 0, rs232.PARAM_TEST))
    rig.clock.run_until(t0 + ANSWER_US - 1)
    early = rig.link.host_read_available()
    assert len(early) == 5, "the 6th response byte must not be there 1 us early"
    rig.clock.run_until(t0 + ANSWER_US)
    assert early + rig.link.host_read_available() == rs232.TEST_MESSAGE
    assert ANSWER_US == 573 + 20 + 573


def test_slide11_applyjoint_example_is_echoed_with_fb(rig: Rig) -> None:
    # applyjoint(H, 2, 0, [0 0 70]) -> FF 08 00 00 46 BCC (seed 002 slide 11)
    frame = req(Op.APPLY_JOINT, 2, rs232.PARAM_POSITION, 0, 0, 70)
    assert frame == bytes([0xFF, 0x08, 0x00, 0x00, 0x46, 0xFF ^ 0x08 ^ 0x46])
    assert rig.ask(frame) == bytes([0xFB, 0x08, 0x00, 0x00, 0x46, 0xFB ^ 0x08 ^ 0x46])
    assert rig.master.db.actuators[2].ref == [0, 0, 70]


@pytest.mark.parametrize(
    ("param", "data", "field", "expected"),
    [
        (rs232.PARAM_POSITION, (rs232.s8(-90), rs232.s8(-1), 90), "ref", [-90, -1, 90]),
        (rs232.PARAM_VELOCITY, (100, 0, 255), "speed", [100, 0, 255]),
    ],
)
def test_apply_joint_accepted(rig: Rig, param, data, field, expected) -> None:
    frame = req(Op.APPLY_JOINT, 5, param, *data)
    assert rig.ask(frame) == echo(frame, rs232.MESSAGE_SUCCESS)
    assert getattr(rig.master.db.actuators[5], field) == expected


@pytest.mark.parametrize(
    ("param", "field"),
    [(rs232.PARAM_KI, "ki"), (rs232.PARAM_KP, "kp"), (rs232.PARAM_KD, "kd"), (rs232.PARAM_CONTROLON, "type")],
)
def test_apply_control_accepted(rig: Rig, param, field) -> None:
    data = (1, 2, 3) if param == rs232.PARAM_CONTROLON else (7, 200, 255)
    frame = req(Op.APPLY_CONTROL, 8, param, *data)
    assert rig.ask(frame) == echo(frame, rs232.MESSAGE_SUCCESS)
    assert getattr(rig.master.db.actuators[8], field) == list(data)


@pytest.mark.parametrize(
    "frame",
    [
        req(Op.APPLY_JOINT, 1, 2, 0, 0, 0),                           # param 10 invalid
        req(Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, 91, 0, 0),       # out of -90..90
        req(Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, 0, 0, rs232.s8(-91)),
        req(Op.APPLY_JOINT, 9, rs232.PARAM_POSITION, 0, 0, 0),        # SCU 9
        req(Op.APPLY_JOINT, 0, rs232.PARAM_VELOCITY, 1, 1, 1),        # SCU 0 is the Master
        req(Op.APPLY_JOINT, 1, rs232.PARAM_SPECIAL, 2, 0, 0),         # PWM 0/1 only
        req(Op.APPLY_JOINT, 1, rs232.PARAM_SPECIAL, 1, 0, 1),         # D3 must be 0
        req(Op.APPLY_CONTROL, 1, rs232.PARAM_CONTROLON, 0, 4, 0),     # control type 0..3
        req(Op.APPLY_CONTROL, 15, rs232.PARAM_KP, 1, 1, 1),
        req(Op.READ_SENSORS, 0, rs232.PARAM_POSITION),
        req(Op.MASTER, 1, rs232.PARAM_TEST),                          # MASTER needs SCU 0
        req(Op.MASTER, 0, rs232.PARAM_SUPERVISOR, 3, 0, 0),           # supervisor D1 0..2
        req(Op.MASTER, 0, 3),
    ],
)
def test_invalid_requests_get_fc_and_change_nothing(rig: Rig, frame: bytes) -> None:
    def snapshot() -> list:
        acts = rig.master.db.actuators.values()
        return [(a.ref[:], a.speed[:], a.pwm, a.calib, a.type[:], a.kp[:]) for a in acts]

    before = snapshot()
    assert rig.ask(frame) == echo(frame, rs232.MESSAGE_INVREQ)
    assert snapshot() == before
    assert rig.master.stats()["serial_frames_invalid"] == 1
    assert rig.master.usart.last_invalid


def test_master_test_message(rig: Rig) -> None:
    assert rig.ask(req(Op.MASTER, 0, rs232.PARAM_TEST, 9, 9, 9)) == bytes.fromhex("FAF9F8F7F6F5")


def test_can_status_of_a_healthy_bus_with_nobody_answering(rig: Rig) -> None:
    rig.clock.run_until(3 * ROUND_US)
    assert rig.ask(req(Op.MASTER, 0, rs232.PARAM_CANSTATUS)) == rs232.data_response(0, 0, 0, 0)


def test_read_before_any_slave_answered_is_zeros(rig: Rig) -> None:
    assert rig.ask(req(Op.READ_SENSORS, 4, rs232.PARAM_CURRENT)) == rs232.data_response(0, 0, 0, 0)


# --- the resynchronising receiver -----------------------------------------------------------------


def test_bad_bcc_is_not_answered_and_the_next_good_frame_is(rig: Rig) -> None:
    good = req(Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, 10, 20, 30)
    bad = good[:5] + bytes([good[5] ^ 0x01])
    assert rig.ask(bad) == b""
    assert rig.master.db.actuators[1].ref == [0, 0, 0]
    assert rig.ask(good) == echo(good, rs232.MESSAGE_SUCCESS)
    s = rig.master.stats()
    counts = (s["serial_frames_rejected"], s["serial_frames_received"], s["serial_frames_answered"])
    assert counts == (1, 1, 1)


def test_ff_data_byte_minus_one_degree_is_a_normal_frame(rig: Rig) -> None:
    frame = req(Op.APPLY_JOINT, 3, rs232.PARAM_POSITION, rs232.s8(-1), rs232.s8(-1), rs232.s8(-1))
    assert frame[2:5] == b"\xff\xff\xff"
    assert rig.ask(frame) == echo(frame, rs232.MESSAGE_SUCCESS)
    assert rig.master.db.actuators[3].ref == [-1, -1, -1]


def test_resync_inside_a_bad_frame_finds_the_good_frame_without_a_gap(rig: Rig) -> None:
    # A stray FF and a byte, then a good frame back to back: the first 6 bytes fail the BCC, the
    # receiver restarts at the good frame's FF (the 3rd byte) and answers it, once.
    good = req(Op.APPLY_JOINT, 2, rs232.PARAM_POSITION, 0, 0, 70)
    out = rig.ask(b"\xff\x12" + good)
    assert out == echo(good, rs232.MESSAGE_SUCCESS)
    assert rig.master.stats()["serial_frames_rejected"] == 1


def test_noise_then_good_frame_only_good_one_answered(rig: Rig) -> None:
    rnd = random.Random(3)
    good = req(Op.APPLY_CONTROL, 6, rs232.PARAM_KP, 1, 2, 3)
    for trial in range(20):
        noise = bytes(rnd.randrange(256) for _ in range(rnd.randrange(1, 12)))
        rig.link.host_write(noise)
        rig.clock.run_for(len(noise) * 100 + FRAME_GAP_US + 100)  # noise, then a silence > 2 ms
        early = rig.link.host_read_available()
        # noise can form a valid frame by chance: whatever was answered must be a valid response
        for i in range(0, len(early), 6):
            rs232.decode_response(early[i:i + 6])
        assert rig.ask(good) == echo(good, rs232.MESSAGE_SUCCESS), f"trial {trial}, noise {noise.hex()}"


def test_broken_off_frame_is_discarded(rig: Rig) -> None:
    good = req(Op.APPLY_JOINT, 4, rs232.PARAM_VELOCITY, 5, 6, 7)
    rig.link.host_write(good[:3])
    rig.clock.run_for(3 * 100 + FRAME_GAP_US + 50)
    rig.link.host_write(good[3:])          # the rest arrives too late: dropped as noise
    rig.clock.run_for(3 * 100 + FRAME_GAP_US + 50)
    assert rig.link.host_read_available() == b""
    assert rig.master.db.actuators[4].speed == [0, 0, 0]
    assert rig.ask(good) == echo(good, rs232.MESSAGE_SUCCESS)
    s = rig.master.stats()
    assert s["serial_frames_broken"] == 1 and s["serial_frames_answered"] == 1


def test_gap_just_under_2ms_keeps_the_frame(rig: Rig) -> None:
    good = req(Op.APPLY_JOINT, 4, rs232.PARAM_VELOCITY, 5, 6, 7)
    rig.link.host_write(good[:3])
    rig.clock.run_for(3 * 96)            # the 3 bytes are in
    t_last = rig.clock.now_us
    rig.clock.run_until(t_last + FRAME_GAP_US - 200)
    rig.link.host_write(good[3:])        # the 4th byte's stop bit is < 2 ms after the 3rd's
    assert rig.ask(b"", ANSWER_US) == echo(good, rs232.MESSAGE_SUCCESS)


def test_request_during_a_response_is_answered_after_it(rig: Rig) -> None:
    a = req(Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, 1, 2, 3)
    b = req(Op.MASTER, 0, rs232.PARAM_TEST)
    rig.link.host_write(a + b)          # b completes while a's response is on the line
    rig.clock.run_for(4 * BYTE6_US)
    assert rig.link.host_read_available() == echo(a, rs232.MESSAGE_SUCCESS) + rs232.TEST_MESSAGE


# --- the CAN schedule -------------------------------------------------------------------------------


def _request_us(msg: can.Message) -> int:
    """When the frame started on the wire (= its request, on an idle wire): the network stamps
    the end of its EOF, i.e. start + frame_bits - IFS bit times (1 us per bit at 1 Mbit/s)."""
    end_us = round(msg.timestamp * 1_000_000)
    return end_us - (frame_bits(msg.arbitration_id, bytes(msg.data)) - IFS_BITS)


def test_schedule_slots_ids_and_round_period(rig: Rig) -> None:
    rig.clock.run_until(2 * ROUND_US - 1)
    frames = rig.drain()
    assert len(frames) == 2 * 8 * 2
    expected = [
        (r * ROUND_US + (k - 1) * SLAVE_PERIOD_US + index * 500, cf.can_id(0, k, index, cf.OP_ACTUATION))
        for r in range(2)
        for k in range(1, 9)
        for index in (0, 1)
    ]
    assert [(_request_us(m), m.arbitration_id) for m in frames] == expected
    assert all(len(m.data) == 8 and not m.is_extended_id for m in frames)
    assert rig.master.stats()["rounds"] == 1


def test_apply_joint_over_the_link_reaches_the_actuation_packets(rig: Rig) -> None:
    rig.ask(req(Op.APPLY_JOINT, 3, rs232.PARAM_POSITION, rs232.s8(-20), 0, 45))
    rig.ask(req(Op.APPLY_JOINT, 3, rs232.PARAM_VELOCITY, 100, 50, 0))
    rig.ask(req(Op.APPLY_JOINT, 3, rs232.PARAM_SPECIAL, 1, 0, 0))
    rig.ask(req(Op.APPLY_CONTROL, 3, rs232.PARAM_CONTROLON, 1, 2, 3))
    rig.ask(req(Op.APPLY_CONTROL, 3, rs232.PARAM_KI, 11, 12, 13))
    rig.ask(req(Op.APPLY_CONTROL, 3, rs232.PARAM_KP, 21, 22, 23))
    rig.ask(req(Op.APPLY_CONTROL, 3, rs232.PARAM_KD, 31, 32, 33))
    rig.drain()
    rig.clock.run_for(ROUND_US)
    mine = {m.arbitration_id: bytes(m.data) for m in rig.drain()}
    refs, speeds, control, kd3 = cf.unpack_actuation1(mine[cf.can_id(0, 3, 0, cf.OP_ACTUATION)])
    assert (refs, speeds, kd3) == ((-20, 0, 45), (100, 50, 0), 33)
    assert cf.parse_control_byte(control) == (True, False, (1, 2, 3))
    act2 = cf.unpack_actuation2(mine[cf.can_id(0, 3, 1, cf.OP_ACTUATION)])
    assert act2 == ((11, 12, 13), (21, 22, 23), 31, 32)
    # other slaves keep their defaults: PWM off, zeros
    assert mine[cf.can_id(0, 4, 0, cf.OP_ACTUATION)] == bytes(8)


def test_each_new_position_goes_out_in_the_next_round(rig: Rig) -> None:
    ident = cf.can_id(0, 1, 0, cf.OP_ACTUATION)
    for refs in ((10, 20, 30), (-90, 0, 90), (0, 0, 0)):
        rig.ask(req(Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, *(rs232.s8(r) for r in refs)))
        t_ack = rig.clock.now_us
        rig.clock.run_for(ROUND_US)
        sent = [m for m in rig.drain() if m.arbitration_id == ident and m.timestamp * 1e6 > t_ack]
        assert sent and cf.unpack_actuation1(bytes(sent[-1].data))[0] == refs
    s = rig.master.stats()
    assert s["can_tx_requests"] >= 2 * 8 * 3 and s["can_tx_refused"] == 0


def test_sensor_packets_land_in_the_database_and_come_back_on_read(rig: Rig) -> None:
    slave = TestSlave(rig, 2)
    slave.pos = [-5, 0, 70]
    slave.vel = [1, -2, 3]
    slave.status = cf.status_byte(True, True, False, True, False, (True, True, True))
    slave.curr = [10, 55, 100]
    slave.special = [128, 0, 255, 17]
    rig.clock.run_until(2 * ROUND_US)
    assert rig.ask(req(Op.READ_SENSORS, 2, rs232.PARAM_POSITION)) == rs232.data_response(
        rs232.s8(-5), 0, 70, slave.status
    )
    assert rig.ask(req(Op.READ_SENSORS, 2, rs232.PARAM_VELOCITY)) == rs232.data_response(
        1, rs232.s8(-2), 3, slave.status
    )
    assert rig.ask(req(Op.READ_SENSORS, 2, rs232.PARAM_CURRENT)) == rs232.data_response(
        10, 55, 100, slave.status
    )
    assert rig.ask(req(Op.READ_SENSORS, 2, rs232.PARAM_SPECIAL)) == rs232.data_response(128, 0, 255, 17)
    # CAN status: only slave 2 answered both packets of the last round
    assert rig.ask(req(Op.MASTER, 0, rs232.PARAM_CANSTATUS)) == rs232.data_response(0, 0, 0, 0b10)
    # the slave got its actuation packets once per round
    assert [i for i, _ in slave.received[:4]] == [0, 1, 0, 1]


def test_answered_mask_tracks_slaves_that_answer_both_packets(rig: Rig) -> None:
    s1, s8 = TestSlave(rig, 1), TestSlave(rig, 8)
    rig.clock.run_until(ROUND_US + 10)
    assert rig.master.db.answered_mask == 0b1000_0001
    s8.silent = True
    rig.clock.run_until(2 * ROUND_US + 10)
    assert rig.master.db.answered_mask == 0b0000_0001
    assert rig.master.db.sensors[8].rounds_missed == 1
    assert s1.received


def test_sensor_packet_with_wrong_sflags_source_is_rejected(rig: Rig) -> None:
    node = rig.net.attach("liar", None, lambda msg: None)
    bad = bytearray(cf.pack_sensors1(5, (40, 40, 40), (0, 0, 0), 0xFF))
    bad[0] = cf.sflags(6, 0)     # SFlags says slave 6, the identifier says slave 5
    node.send(can.Message(arbitration_id=cf.can_id(5, 0, 0, cf.OP_SENSORS), data=bad, is_extended_id=False))
    rig.clock.run_for(1_000)
    assert rig.master.db.sensors[5].pos == [0, 0, 0]
    assert rig.master.stats()["can_rx_rejected"] == 1


def test_calibration_request_is_held_until_the_slave_reports_done(rig: Rig) -> None:
    slave = TestSlave(rig, 1)
    slave.status = 0x40  # calibrated (from before)

    def calib_bits() -> list[bool]:
        return [
            cf.parse_control_byte(d[6])[1]
            for m in rig.drain()
            if m.arbitration_id == cf.can_id(0, 1, 0, cf.OP_ACTUATION)
            for d in [bytes(m.data)]
        ]

    rig.clock.run_until(ROUND_US)
    frame = req(Op.APPLY_JOINT, 1, rs232.PARAM_SPECIAL, 1, 1, 0)
    assert rig.ask(frame) == echo(frame, rs232.MESSAGE_SUCCESS)
    rig.drain()
    rig.clock.run_for(3 * ROUND_US)            # the stale "calibrated" bit does not clear it
    assert calib_bits() == [True, True, True]
    slave.status = 0x80                        # calibrating
    rig.clock.run_for(3 * ROUND_US)
    assert calib_bits() == [True, True, True]
    slave.status = 0xC0                        # done
    rig.clock.run_for(3 * ROUND_US)
    assert calib_bits()[-2:] == [False, False]
    assert rig.master.db.actuators[1].pwm


def test_pending_actuation_is_aborted_at_the_next_slot(rig: Rig) -> None:
    # Two nodes ping-pong higher-priority frames (ids 1 and 2): the Master never wins arbitration,
    # and its requests are aborted at slots 1 and 3 instead of going out late.
    state = {"on": True}
    a = b = None

    def pong_a(msg: can.Message) -> None:
        if state["on"]:
            a.send(can.Message(arbitration_id=1, data=b"\x00", is_extended_id=False))

    def pong_b(msg: can.Message) -> None:
        if state["on"]:
            b.send(can.Message(arbitration_id=2, data=b"\x00", is_extended_id=False))

    a = rig.net.attach("flood_a", [{"can_id": 2, "can_mask": 0x7FF}], pong_a)
    b = rig.net.attach("flood_b", [{"can_id": 1, "can_mask": 0x7FF}], pong_b)
    rig.clock.run_until(1_900)                  # wire idle (slave 2's packets are done)
    a.send(can.Message(arbitration_id=1, data=b"\x00", is_extended_id=False))
    rig.clock.run_until(5_100)                  # flood over slaves 3..5 and the start of 6
    state["on"] = False
    rig.clock.run_until(ROUND_US)
    master_frames = [m for m in rig.drain() if m.arbitration_id >> 7 == 0 and m.arbitration_id > 7]
    served = [cf.split_id(m.arbitration_id)[1:3] for m in master_frames]
    for k in (3, 4, 5):
        assert (k, 0) not in served and (k, 1) not in served, f"slave {k}'s packets must be aborted"
    assert served[:4] == [(1, 0), (1, 1), (2, 0), (2, 1)]
    assert served[4:] == [(6, 0), (6, 1), (7, 0), (7, 1), (8, 0), (8, 1)]
    # slave 6's first packet, requested at 5000 while flooded, won the wire when the flood
    # stopped, before slot 1 (5250) could abort it: it went out late, once
    late = _request_us(master_frames[4])
    assert 5_100 < late < 5_250
    assert _request_us(master_frames[5]) == 5_500


def test_can_status_reports_bus_off_and_reading_it_recovers_the_master(rig: Rig) -> None:
    TestSlave(rig, 7)
    canstatus = req(Op.MASTER, 0, rs232.PARAM_CANSTATUS)
    rig.clock.run_until(2 * ROUND_US)
    assert rig.ask(canstatus) == rs232.data_response(0, 0, 0, 1 << 6)
    rig.net.force_bus_off("master")
    rig.drain()
    rig.clock.run_for(2 * ROUND_US)
    assert not [m for m in rig.drain() if m.arbitration_id >> 7 == 0], "a bus-off Master must not send"
    assert rig.master.stats()["can_tx_refused"] > 0
    # ERRSTATE 2, TEC past 255 clipped to 255, and nobody answered the last round
    assert rig.ask(canstatus) == rs232.data_response(2, 255, 0, 0)
    assert rig.master.stats()["can_clear_status"] == 1
    rig.clock.run_for(2 * ROUND_US)      # recovery: 128 x 11 recessive bits, then the schedule resumes
    assert rig.ask(canstatus) == rs232.data_response(0, 0, 0, 1 << 6)
    assert rig.master.stats()["can_clear_status"] == 1, "no clear when not bus-off"


def test_integrity_of_database_accessors() -> None:
    db = Database()
    with pytest.raises(ValueError, match="1..8"):
        db.actuation(0)
    with pytest.raises(ValueError, match="1..8"):
        db.sensor(9)


# --- with the real Slaves and the real plant ---------------------------------------------------------


class FullRig(Rig):
    """The Master with the 8 real Slave boards on the real plant (MuJoCo)."""

    PHASES_US = (2_750, 5_500, 8_250, 11_000, 13_750, 16_500, 19_250, 2_000)

    def __init__(self) -> None:
        from humanoid_twin.master.supervisor import SupervisorConfig
        from humanoid_twin.plant import Plant
        from humanoid_twin.slave.slave import Slave

        super().__init__()
        # a bench: only the legs are powered, so the robot topples; the supervisor's balance rule
        # (which would latch safe on that fall and refuse the APPLYs these tests send) is held off
        self.master.supervisor.config = SupervisorConfig(balance_hold_ms=10**9)
        self.plant = Plant(seed=0, clock=self.clock)
        self.slaves = {
            k: Slave(k, self.clock, self.plant, self.net, phase_us=self.PHASES_US[k - 1]) for k in range(1, 9)
        }

    def ask(self, frame: bytes, wait_us: int = ANSWER_US + 200) -> bytes:
        out = super().ask(frame, wait_us)
        self.plant.advance_to(self.clock.now_us)
        return out

    def run_for(self, us: int) -> None:
        self.clock.run_for(us)
        self.plant.advance_to(self.clock.now_us)


@pytest.fixture(scope="module")
def full() -> FullRig:
    """One shared run: PWM on and positions for the two legs, 3 s of virtual time."""
    r = FullRig()
    canstatus = req(Op.MASTER, 0, rs232.PARAM_CANSTATUS)
    r.masks = []
    for _ in range(12):                      # 12 CAN status readouts, one every ~10 ms
        r.masks.append(rs232.decode_response(r.ask(canstatus)).values)
        r.run_for(9_000)
    for k, refs in ((1, (-5, 10, 20)), (2, (5, -10, 30))):
        assert r.ask(req(Op.APPLY_JOINT, k, rs232.PARAM_POSITION, *(rs232.s8(x) for x in refs)))[0] == 0xFB
        assert r.ask(req(Op.APPLY_JOINT, k, rs232.PARAM_SPECIAL, 1, 0, 0))[0] == 0xFB
    r.run_for(3_000_000)
    return r


def test_all_eight_slaves_answer_through_the_schedule(full: FullRig) -> None:
    union = 0
    for errstate, tec, rec, mask in full.masks:
        assert (errstate, tec, rec) == (0, 0, 0)
        union |= mask
    assert union == 0xFF, "every slave must show up in the CAN status"
    db = full.master.db
    rounds = db.counters.rounds
    assert rounds >= 3_000_000 // ROUND_US
    for k in range(1, 9):
        s = db.sensors[k]
        assert s.rounds_answered + s.rounds_missed == rounds
        # silent only when the Master's visit falls in the slave's 2 ms PWM window (slide 29):
        # at most 1 round in 5 with an 8 ms round and a 20 ms PWM period
        assert s.rounds_missed <= rounds // 5 + 1, (k, s.rounds_missed, rounds)
    assert db.counters.can_rx_rejected == 0 and db.counters.can_tx_refused == 0


def test_legs_reach_the_requested_positions_read_back_over_rs232(full: FullRig) -> None:
    for k, refs in ((1, (-5, 10, 20)), (2, (5, -10, 30))):
        resp = rs232.decode_response(full.ask(req(Op.READ_SENSORS, k, rs232.PARAM_POSITION)))
        pos = [rs232.from_s8(v) for v in resp.values[:3]]
        status = cf.parse_status_byte(resp.values[3])
        assert status.pwm and status.calib, f"SCU {k} status {resp.values[3]:#04x}"
        assert all(abs(p - r) <= 2 for p, r in zip(pos, refs, strict=True)), (k, pos, refs)
        forces = rs232.decode_response(full.ask(req(Op.READ_SENSORS, k, rs232.PARAM_SPECIAL))).values
        assert all(v > 0 for v in forces), f"a standing foot loads its 4 sensors: {forces}"
    # a hip board with PWM off is limp but measured and reported
    resp = rs232.decode_response(full.ask(req(Op.READ_SENSORS, 3, rs232.PARAM_POSITION)))
    assert not cf.parse_status_byte(resp.values[3]).pwm


def test_calibration_request_round_trip_with_a_real_slave(full: FullRig) -> None:
    a = full.master.db.actuators[1]
    assert full.ask(req(Op.APPLY_JOINT, 1, rs232.PARAM_SPECIAL, 1, 1, 0))[0] == 0xFB
    assert a.calib
    full.run_for(100_000)
    status = rs232.decode_response(full.ask(req(Op.READ_SENSORS, 1, rs232.PARAM_POSITION))).values[3]
    assert not status & 0x40, "the slave reports 'calibrating' after the request"
    assert a.calib, "the Master keeps asking while the slave calibrates"
    full.run_for(3_000_000)                  # 2 s settle + 25 samples, seed 000 SERVO calibration
    status = rs232.decode_response(full.ask(req(Op.READ_SENSORS, 1, rs232.PARAM_POSITION))).values[3]
    assert status & 0x40, "calibration done"
    assert not a.calib, "the Master cleared its Calib flag"
    full.drain()
    full.run_for(ROUND_US)
    act1 = [bytes(m.data) for m in full.drain() if m.arbitration_id == cf.can_id(0, 1, 0, cf.OP_ACTUATION)]
    assert act1 and cf.parse_control_byte(act1[-1][6])[:2] == (True, False)


def test_cansendmsg_refuses_an_scu_or_a_packet_index_it_has_no_data_for(rig: Rig) -> None:
    """``canSendMsg`` of an SCU outside 1..8 (no actuation data, as the database's KeyError) or
    of a packet other than 0 and 1 is refused before anything is queued (the compiled core
    would otherwise index its tables out of range)."""
    mcan = rig.master.can
    requests = rig.master.db.counters.can_tx_requests
    for scu in (0, 9, -1, 2048):
        with pytest.raises(KeyError):
            mcan.canSendMsg(scu, 0)
    with pytest.raises(ValueError, match="0 or 1"):
        mcan.canSendMsg(3, 2)
    assert rig.master.db.counters.can_tx_requests == requests
