"""The RS-232 and CAN codecs (humanoid_twin.protocol) against the byte-level contract of
docs/protocol.md (seed 002 slides 7-11, 18-23; seed 000 tables 2-3)."""

from __future__ import annotations

import importlib.util
import itertools
import re

import can
import numpy as np
import pytest
from helpers import REPO
from hypothesis import given
from hypothesis import strategies as st

from humanoid_twin.hardware import (
    IMU_GYRO_DPS_PER_COUNT,
    IMU_INCL_DEG_PER_COUNT,
    IMU_SCU,
    IMU_SENSOR_NAMES,
    IMU_ZERO_COUNT,
)
from humanoid_twin.protocol import canframes as cf
from humanoid_twin.protocol import rs232
from humanoid_twin.protocol.canframes import PayloadError
from humanoid_twin.protocol.rs232 import FrameError, Op, Request
from humanoid_twin.protocol.wire import ErrorState

u8 = st.integers(0, 255)
i8 = st.integers(-128, 127)
three_u8 = st.tuples(u8, u8, u8)
three_i8 = st.tuples(i8, i8, i8)
flags3 = st.tuples(st.booleans(), st.booleans(), st.booleans())


# --- RS-232: OpCode -------------------------------------------------------------------------


def test_opcode_round_trip_every_op_scu_param() -> None:
    seen = set()
    for op, scu, param in itertools.product(range(4), range(16), range(4)):
        code = rs232.make_opcode(op, scu, param)
        assert 0 <= code <= 255
        assert rs232.parse_opcode(code) == (op, scu, param)
        seen.add(code)
    assert len(seen) == 256  # every byte is exactly one (op, scu, param)


def test_opcode_bit_layout() -> None:
    # bits 7-6 operation, 5-2 SCU, 1-0 parameter (slide 9)
    assert rs232.make_opcode(Op.APPLY_JOINT, 2, rs232.PARAM_POSITION) == 0x08
    assert rs232.make_opcode(Op.READ_SENSORS, 2, rs232.PARAM_SPECIAL) == 0x8B
    assert rs232.make_opcode(Op.MASTER, 0, rs232.PARAM_CANSTATUS) == 0xC1
    assert rs232.make_opcode(Op.APPLY_CONTROL, 8, rs232.PARAM_CONTROLON) == 0x63


@pytest.mark.parametrize(
    "op, scu, param", [(4, 1, 0), (-1, 1, 0), (0, 16, 0), (0, -1, 0), (0, 1, 4), (0, 1.0, 0)]
)
def test_opcode_fields_out_of_range(op, scu, param) -> None:
    with pytest.raises(ValueError, match="must be"):
        rs232.make_opcode(op, scu, param)


def test_s8_two_complement() -> None:
    assert rs232.s8(-1) == 0xFF
    assert rs232.s8(-90) == 0xA6
    assert rs232.s8(70) == 0x46
    assert [rs232.from_s8(rs232.s8(v)) for v in range(-128, 128)] == list(range(-128, 128))
    for bad in (128, -129):
        with pytest.raises(ValueError, match="-128..127"):
            rs232.s8(bad)
    with pytest.raises(ValueError, match="0..255"):
        rs232.from_s8(256)


# --- RS-232: requests -----------------------------------------------------------------------


def test_bcc_of_slide_11_examples() -> None:
    # applyjoint(H,2,0,[0 0 70]): SCU 2, positions 0 0 70
    assert rs232.encode_request(Op.APPLY_JOINT, 2, rs232.PARAM_POSITION, 0, 0, 70) == bytes.fromhex(
        "FF 08 00 00 46 B1"
    )
    # applyjoint(H,2,1,[100 100 100]): period 2 s on each servo
    assert rs232.encode_request(Op.APPLY_JOINT, 2, rs232.PARAM_VELOCITY, 100, 100, 100) == bytes.fromhex(
        "FF 09 64 64 64 92"
    )
    # readjoint(H,2,0) and readspecial(H,2)
    assert rs232.encode_request(Op.READ_SENSORS, 2, rs232.PARAM_POSITION) == bytes.fromhex(
        "FF 88 00 00 00 77"
    )
    assert rs232.encode_request(Op.READ_SENSORS, 2, rs232.PARAM_SPECIAL) == bytes.fromhex("FF 8B 00 00 00 74")
    assert rs232.bcc(bytes.fromhex("FF 08 00 00 46")) == 0xB1


@given(st.integers(0, 3), st.integers(0, 15), st.integers(0, 3), three_u8)
def test_request_round_trip(op, scu, param, data) -> None:
    frame = Request(op, scu, param, data).encode()
    assert len(frame) == 6 and frame[0] == 0xFF
    assert rs232.bcc(frame) == 0  # XOR over the whole frame, BCC included
    assert frame == rs232.encode_request(op, scu, param, *data)
    assert Request.decode(frame) == Request(op, scu, param, data)


def test_ff_as_data_byte_is_a_valid_frame() -> None:
    # -1 degree is 0xFF on the wire: the frame still decodes (SOF is only the first byte)
    frame = rs232.encode_request(Op.APPLY_JOINT, 1, rs232.PARAM_POSITION, rs232.s8(-1), 0xFF, rs232.s8(0))
    assert frame == bytes.fromhex("FF 04 FF FF 00 FB")
    req = Request.decode(frame)
    assert [rs232.from_s8(d) for d in req.data] == [-1, -1, 0]
    assert rs232.is_valid_request(req)


@given(st.integers(0, 255), three_u8, st.integers(1, 5), st.integers(1, 255))
def test_any_single_byte_corruption_is_detected(opcode, data, pos, flip) -> None:
    frame = bytearray(rs232.encode_request(opcode >> 6, (opcode >> 2) & 15, opcode & 3, *data))
    frame[pos] ^= flip
    with pytest.raises(FrameError, match="bad BCC"):
        Request.decode(frame)


@pytest.mark.parametrize(
    "frame, match",
    [
        ("FF 08 00 00 46 B0", "bad BCC"),
        ("FE 08 00 00 46 B0", "SOF"),
        ("FF 08 00 00 46", "6 bytes, got 5"),
        ("FF 08 00 00 46 B1 00", "6 bytes, got 7"),
        ("", "6 bytes, got 0"),
    ],
)
def test_request_decode_errors(frame, match) -> None:
    with pytest.raises(FrameError, match=match):
        Request.decode(bytes.fromhex(frame))


def test_request_rejects_bad_fields() -> None:
    with pytest.raises(ValueError, match="D2"):
        Request(0, 1, 0, (0, 256, 0))
    with pytest.raises(ValueError, match="3 bytes"):
        Request(0, 1, 0, (0, 0))
    with pytest.raises(ValueError, match="D1"):
        rs232.encode_request(0, 1, 0, -1)  # signed values must go through s8()


# --- RS-232: responses ----------------------------------------------------------------------


def test_status_response_echoes_request() -> None:
    req = bytes.fromhex("FF 08 00 00 46 B1")
    ok = rs232.status_response(req, rs232.MESSAGE_SUCCESS)
    bad = rs232.status_response(req, rs232.MESSAGE_INVREQ)
    assert ok == bytes.fromhex("FB 08 00 00 46 B5")
    assert bad == bytes.fromhex("FC 08 00 00 46 B2")
    r = rs232.decode_response(ok)
    assert r.kind == "success" and r.values == (0x08, 0, 0, 0x46) and r.echoes(req)
    r = rs232.decode_response(bad)
    assert r.kind == "invreq" and r.echoes(req)
    assert not r.echoes(bytes.fromhex("FF 08 00 00 47 B0"))
    with pytest.raises(ValueError, match="MESSAGE_SUCCESS"):
        rs232.status_response(req, rs232.MESSAGE_DATA)
    with pytest.raises(FrameError, match="6 bytes"):
        rs232.status_response(req[:5], rs232.MESSAGE_SUCCESS)


@given(u8, u8, u8, u8)
def test_data_response_round_trip(v1, v2, v3, v4) -> None:
    frame = rs232.data_response(v1, v2, v3, v4)
    assert frame[0] == 0xFD and rs232.bcc(frame) == 0
    r = rs232.decode_response(frame)
    assert r.kind == "data" and r.values == (v1, v2, v3, v4) and r.raw == frame


def test_read_position_answer_carries_signed_degrees() -> None:
    frame = rs232.data_response(rs232.s8(-90), rs232.s8(-1), rs232.s8(45), 0b1001_1111)
    assert frame == bytes.fromhex("FD A6 FF 2D 9F 16")
    r = rs232.decode_response(frame)
    assert [rs232.from_s8(v) for v in r.values[:3]] == [-90, -1, 45]
    assert cf.parse_status_byte(r.values[3]).fin_all


def test_test_message() -> None:
    r = rs232.decode_response(rs232.TEST_MESSAGE)
    assert r.kind == "test" and r.raw == bytes.fromhex("FA F9 F8 F7 F6 F5")
    with pytest.raises(FrameError, match="corrupt test message"):
        rs232.decode_response(bytes.fromhex("FA F9 F8 F7 F6 F4"))


@pytest.mark.parametrize(
    "frame, match",
    [
        ("FD 01 02 03 04 FE", "bad BCC"),
        ("FB 08 00 00 46 B4", "bad BCC"),
        ("FF 08 00 00 46 B1", "first byte 0xFF"),
        ("00 00 00 00 00 00", "first byte 0x00"),
        ("FD 01 02 03 04", "6 bytes"),
    ],
)
def test_response_decode_errors(frame, match) -> None:
    with pytest.raises(FrameError, match=match):
        rs232.decode_response(bytes.fromhex(frame))


def test_data_response_rejects_non_bytes() -> None:
    with pytest.raises(ValueError, match="V1"):
        rs232.data_response(-5, 0, 0, 0)
    with pytest.raises(ValueError, match="V4"):
        rs232.data_response(0, 0, 0, 256)


# --- RS-232: the Master's validation table --------------------------------------------------

J, C, R, M = Op.APPLY_JOINT, Op.APPLY_CONTROL, Op.READ_SENSORS, Op.MASTER
s8 = rs232.s8


@pytest.mark.parametrize(
    "op, scu, param, data, valid",
    [
        # SCU range for the three board operations
        (J, 0, 0, (0, 0, 0), False),
        (J, 1, 0, (0, 0, 0), True),
        (J, 8, 0, (0, 0, 0), True),
        (J, 9, 0, (0, 0, 0), False),
        (C, 15, 0, (0, 0, 0), False),
        (R, 0, 0, (0, 0, 0), False),
        (R, 9, 2, (0, 0, 0), False),
        # APPLY_JOINT POSITION: int8 degrees -90..90
        (J, 2, 0, (s8(-90), s8(0), s8(90)), True),
        (J, 2, 0, (s8(-1), s8(-1), s8(-1)), True),
        (J, 2, 0, (s8(91), 0, 0), False),
        (J, 2, 0, (0, 0, s8(-91)), False),
        (J, 2, 0, (0, s8(-128), 0), False),
        (J, 2, 0, (0, s8(127), 0), False),
        # VELOCITY: any byte; param 10 invalid
        (J, 2, 1, (0, 100, 255), True),
        (J, 2, 2, (0, 0, 0), False),
        # SPECIAL: D1 PWM 0/1, D2 calibration request 0/1, D3 = 0
        (J, 2, 3, (1, 0, 0), True),
        (J, 2, 3, (0, 1, 0), True),
        (J, 2, 3, (1, 1, 0), True),
        (J, 2, 3, (2, 0, 0), False),
        (J, 2, 3, (0, 2, 0), False),
        (J, 2, 3, (0, 0, 1), False),
        # APPLY_CONTROL: gains any byte, CONTROLON types 0..3
        (C, 1, 0, (255, 0, 17), True),
        (C, 1, 1, (255, 255, 255), True),
        (C, 1, 2, (0, 128, 0), True),
        (C, 1, 3, (0, 1, 3), True),
        (C, 1, 3, (4, 0, 0), False),
        (C, 1, 3, (0, 0, 255), False),
        # READ_SENSORS: any param, data ignored
        (R, 1, 0, (0, 0, 0), True),
        (R, 8, 2, (255, 7, 9), True),
        (R, 3, 3, (1, 2, 3), True),
        # MASTER: SCU 0 only; param 0 test, 1 CAN status, 2 supervisor (D1 0..2), 3 invalid
        (M, 0, 0, (0, 0, 0), True),
        (M, 0, 1, (0, 0, 0), True),
        (M, 0, 2, (0, 0, 0), True),
        (M, 0, 2, (2, 0, 0), True),
        (M, 0, 2, (3, 0, 0), False),
        (M, 0, 3, (0, 0, 0), False),
        (M, 1, 0, (0, 0, 0), False),
    ],
)
def test_validation_table(op, scu, param, data, valid) -> None:
    req = Request(op, scu, param, data)
    assert rs232.is_valid_request(req) is valid
    reason = rs232.invalid_reason(req)
    assert (reason is None) is valid
    if reason is not None:
        assert isinstance(reason, str) and len(reason) > 10


def test_validation_applies_to_decoded_frames() -> None:
    req = Request.decode(rs232.encode_request(J, 2, 0, s8(0), s8(0), s8(120)))
    assert "120 deg" in rs232.invalid_reason(req)
    # what the Master answers to it
    answer = rs232.decode_response(rs232.status_response(req.encode(), rs232.MESSAGE_INVREQ))
    assert answer.kind == "invreq" and answer.values[3] == 120


# --- CAN identifiers and filters ------------------------------------------------------------


def test_can_id_round_trip_and_layout() -> None:
    ids = set()
    for src, dst, index, op in itertools.product(range(16), range(16), range(2), range(4)):
        i = cf.can_id(src, dst, index, op)
        assert 0 <= i <= 0x7FF
        assert cf.split_id(i) == (src, dst, index, op)
        ids.add(i)
    assert len(ids) == 2048
    assert cf.can_id(0, 2, 0, cf.OP_ACTUATION) == 0b0000_0010_0_00
    assert cf.can_id(2, 0, 1, cf.OP_SENSORS) == 0b0010_0000_1_01
    with pytest.raises(ValueError, match="out of range"):
        cf.can_id(16, 0, 0, 0)
    with pytest.raises(ValueError, match="0x7FF"):
        cf.split_id(0x800)


def test_priorities_follow_slide_18() -> None:
    act = [i for k in range(1, 9) for i in cf.ACTUATION_IDS[k]]
    sen = [i for k in range(1, 9) for i in cf.SENSOR_IDS[k]]
    assert max(act) < min(sen)  # actuation (Master) beats any sensor packet
    assert sen == sorted(sen)  # lower address, then first packet, wins
    assert act == sorted(act)
    assert cf.ACTUATION_IDS[3] == (cf.can_id(0, 3, 0, 0), cf.can_id(0, 3, 1, 0))
    assert cf.SENSOR_IDS[3] == (cf.can_id(3, 0, 0, 1), cf.can_id(3, 0, 1, 1))


def _accepted(filters, arbitration_id) -> list[int]:
    return [n for n, f in enumerate(filters) if arbitration_id & f["can_mask"] == f["can_id"] & f["can_mask"]]


def test_filters_match_slide_23_on_every_id() -> None:
    assert cf.MASTER_MASK == 0x07C and cf.SLAVE_MASK == 0x784
    mf, sf = cf.master_filters(), cf.slave_filters()
    for i in range(0x800):
        src, dst, index, _ = cf.split_id(i)
        # the Master takes what is destined to it, index 0 in RXB0 and index 1 in RXB1
        assert _accepted(mf, i) == ([index] if dst == 0 else [])
        # a slave takes everything the Master sends, whatever the destination
        assert _accepted(sf, i) == ([index] if src == 0 else [])


def _drain(bus: can.BusABC) -> list[int]:
    got = []
    while (msg := bus.recv(timeout=0)) is not None:
        got.append(msg.arbitration_id)
    return got


def test_filters_on_real_python_can_buses() -> None:
    channel = "test_protocol_filters"
    with (
        can.Bus(interface="virtual", channel=channel, can_filters=cf.master_filters()) as master,
        can.Bus(interface="virtual", channel=channel, can_filters=cf.slave_filters()) as slave5,
        can.Bus(interface="virtual", channel=channel, can_filters=cf.slave_filters()) as slave1,
    ):
        act = cf.pack_actuation1((0, 0, 70), (100, 100, 100), cf.control_byte(True, False, (1, 1, 1)), 0)
        for k in (1, 5):
            for i in cf.ACTUATION_IDS[k]:
                master.send(can.Message(arbitration_id=i, data=act, is_extended_id=False))
        s1 = cf.pack_sensors1(5, (0, 0, 70), (0, 0, 0), 0)
        s2 = cf.pack_sensors2(5, (10, 20, 30), (128, 128, 128, 128))
        slave5.send(can.Message(arbitration_id=cf.SENSOR_IDS[5][0], data=s1, is_extended_id=False))
        slave5.send(can.Message(arbitration_id=cf.SENSOR_IDS[5][1], data=s2, is_extended_id=False))
        # an extended frame with the same low bits is not for this network
        slave5.send(can.Message(arbitration_id=cf.SENSOR_IDS[5][0], data=s1, is_extended_id=True))

        expected_act = [*cf.ACTUATION_IDS[1], *cf.ACTUATION_IDS[5]]
        assert _drain(slave1) == expected_act  # both slaves hear both Master messages...
        assert _drain(slave5) == expected_act  # ...and neither hears the other slave's sensors
        assert _drain(master) == list(cf.SENSOR_IDS[5])  # the Master hears sensors only


# --- CAN control / status / SFlags bytes ----------------------------------------------------


def test_control_byte_layout() -> None:
    # bit 7 PWM, bit 6 Calib, bits 5-4 servo 3, 3-2 servo 2, 1-0 servo 1
    assert cf.control_byte(True, False, (1, 2, 3)) == 0b1011_1001
    assert cf.control_byte(False, True, (0, 0, 0)) == 0b0100_0000
    assert cf.parse_control_byte(0b0111_0010) == (False, True, (2, 0, 3))
    with pytest.raises(PayloadError, match="0..3"):
        cf.control_byte(True, False, (0, 4, 0))
    with pytest.raises(PayloadError, match="3 values"):
        cf.control_byte(True, False, (0, 1))
    with pytest.raises(PayloadError, match="0..255"):
        cf.parse_control_byte(256)


@given(st.booleans(), st.booleans(), st.tuples(*[st.integers(0, 3)] * 3))
def test_control_byte_round_trip(pwm, calib, types) -> None:
    assert cf.parse_control_byte(cf.control_byte(pwm, calib, types)) == (pwm, calib, types)


def test_status_byte_layout() -> None:
    assert cf.status_byte(True, False, False, False, False, (True, False, False)) == 0b1000_0001
    assert cf.status_byte(False, True, True, True, True, (False, False, True)) == 0b0111_1100
    s = cf.parse_status_byte(0b0100_0010)
    assert s.calib and not s.pwm and s.fin == (False, True, False)
    with pytest.raises(PayloadError, match="3 flags"):
        cf.status_byte(True, True, True, True, True, (True, True))


@given(st.booleans(), st.booleans(), st.booleans(), st.booleans(), st.booleans(), flags3)
def test_status_byte_round_trip(pwm, calib, deadline, fin_all, fin_one, fin) -> None:
    b = cf.status_byte(pwm, calib, deadline, fin_all, fin_one, fin)
    assert tuple(cf.parse_status_byte(b)) == (pwm, calib, deadline, fin_all, fin_one, fin)


def test_sflags() -> None:
    assert cf.sflags(3, 1) == 0b0011_1000
    assert cf.sflags(8, 0) == 0b1000_0000
    with pytest.raises(PayloadError, match="source"):
        cf.sflags(16, 0)


# --- CAN payloads -----------------------------------------------------------------------------


@given(three_i8, three_u8, u8, u8)
def test_actuation1_round_trip(refs, speeds, control, kd3) -> None:
    data = cf.pack_actuation1(refs, speeds, control, kd3)
    assert len(data) == 8
    assert cf.unpack_actuation1(data) == (refs, speeds, control, kd3)
    assert cf.unpack_actuation1(bytearray(data)) == (refs, speeds, control, kd3)  # can.Message.data


@given(three_u8, three_u8, u8, u8)
def test_actuation2_round_trip(ki, kp, kd1, kd2) -> None:
    data = cf.pack_actuation2(ki, kp, kd1, kd2)
    assert cf.unpack_actuation2(data) == (ki, kp, kd1, kd2)


@given(st.integers(0, 15), three_i8, three_i8, u8)
def test_sensors1_round_trip(src, pos, speed, status) -> None:
    data = cf.pack_sensors1(src, pos, speed, status)
    assert data[0] == cf.sflags(src, 0)
    assert cf.unpack_sensors1(data) == (src, 0, pos, speed, status)


@given(st.integers(0, 15), st.tuples(*[st.integers(0, 100)] * 3), st.tuples(u8, u8, u8, u8))
def test_sensors2_round_trip(src, curr, data4) -> None:
    data = cf.pack_sensors2(src, curr, data4)
    assert data[0] == cf.sflags(src, 1)
    assert cf.unpack_sensors2(data) == (src, 1, curr, data4)


def _unpacked(unpack, *args) -> tuple | str:
    """An unpack function's result, or the message of the PayloadError it raised."""
    try:
        return unpack(*args)
    except PayloadError as exc:
        return f"PayloadError: {exc}"


# any 8 bytes (most with a valid SFlags byte) from any source address
_sflags_bytes = st.one_of(u8, st.sampled_from([cf.sflags(k, i) | f for k in range(16) for i in (0, 1)
                                                for f in range(4)]))


@given(_sflags_bytes, st.binary(min_size=7, max_size=7), st.integers(0, 15))
def test_sensors1_into_stores_what_unpack_sensors1_reads(sf, rest, src) -> None:
    """The Master's receive codec sets the database's lists to unpack_sensors1's fields, or
    raises its error (or a source mismatch) and leaves them as they were."""
    data = bytes([sf]) + rest
    pos, vel = [7, 7, 7], [9, 9, 9]
    got = _unpacked(cf.unpack_sensors1_into, data, src, pos, vel)
    want = _unpacked(cf.unpack_sensors1, data)
    if isinstance(want, tuple) and want[0] != src:
        want = f"PayloadError: SFlags source {want[0]} does not match the identifier's source {src}"
    if isinstance(want, str):
        assert (got, pos, vel) == (want, [7, 7, 7], [9, 9, 9])
    else:
        assert (got, tuple(pos), tuple(vel)) == (want[4], want[2], want[3])


@given(_sflags_bytes, st.binary(min_size=7, max_size=7), st.integers(0, 15))
def test_sensors2_into_stores_what_unpack_sensors2_reads(sf, rest, src) -> None:
    data = bytearray([sf]) + rest                  # python-can's Message.data
    curr, data4 = [7, 7, 7], [9, 9, 9, 9]
    got = _unpacked(cf.unpack_sensors2_into, data, src, curr, data4)
    want = _unpacked(cf.unpack_sensors2, data)
    if isinstance(want, tuple) and want[0] != src:
        want = f"PayloadError: SFlags source {want[0]} does not match the identifier's source {src}"
    if isinstance(want, str):
        assert (got, curr, data4) == (want, [7, 7, 7], [9, 9, 9, 9])
    else:
        assert (got, tuple(curr), tuple(data4)) == (None, want[2], want[3])


_ACT_FIELDS = ("ref1", "ref2", "ref3", "speed1", "speed2", "speed3", "control", "pwm", "calib", "type1",
               "type2", "type3", "kd3", "ki1", "ki2", "ki3", "kp1", "kp2", "kp3", "kd1", "kd2")


@given(st.binary(min_size=7, max_size=9), st.booleans())
def test_actuation_into_stores_what_unpack_actuation_reads(data, second) -> None:
    """The Slave's receive codec writes unpack_actuation1/2's fields (and the Control byte as
    parse_control_byte reads it) into its record, or raises their error and leaves it as it was."""
    f = cf.ActuationFields()
    for k in _ACT_FIELDS:
        setattr(f, k, 1)
    got = _unpacked(cf.unpack_actuation2_into if second else cf.unpack_actuation1_into, data, f)
    want = _unpacked(cf.unpack_actuation2 if second else cf.unpack_actuation1, bytearray(data))
    fields = {k: getattr(f, k) for k in _ACT_FIELDS}
    if isinstance(want, str):
        assert (got, fields) == (want, dict.fromkeys(_ACT_FIELDS, 1))
    elif second:
        assert got is None
        assert ((f.ki1, f.ki2, f.ki3), (f.kp1, f.kp2, f.kp3), f.kd1, f.kd2) == want
        assert all(fields[k] == 1 for k in _ACT_FIELDS if not k.startswith(("ki", "kp", "kd1", "kd2")))
    else:
        assert got is None
        assert ((f.ref1, f.ref2, f.ref3), (f.speed1, f.speed2, f.speed3), f.control, f.kd3) == want
        assert (f.pwm, f.calib, (f.type1, f.type2, f.type3)) == cf.parse_control_byte(want[2])
        assert all(fields[k] == 1 for k in _ACT_FIELDS[13:])


def _packed(pack, *args) -> bytes | str:
    """A pack function's bytes, or the message of the PayloadError it raised."""
    try:
        return pack(*args)
    except PayloadError as exc:
        return f"PayloadError: {exc}"


# the fields around their ranges: mostly inside, some outside (the errors)
@given(st.integers(-1, 16), st.lists(st.integers(-130, 130), min_size=6, max_size=6),
       st.integers(-2, 257), st.integers(-1, 8))
def test_sensors1_fields_pack_as_pack_sensors1(src, pv, status, flags) -> None:
    """The Slave's per-tick codec gives pack_sensors1's bytes, or its error, for the same fields."""
    want = _packed(cf.pack_sensors1, src, tuple(pv[:3]), tuple(pv[3:]), status, flags)
    assert _packed(cf.pack_sensors1_fields, src, *pv, status, flags) == want


@given(st.integers(-1, 16), st.lists(st.integers(-2, 102), min_size=3, max_size=3),
       st.lists(st.integers(-2, 257), min_size=4, max_size=4), st.booleans())
def test_sensors2_fields_pack_as_pack_sensors2(src, curr, data4, law_stopped) -> None:
    """The Slave's per-tick codec gives pack_sensors2's bytes, or its error, for the same fields."""
    want = _packed(cf.pack_sensors2, src, tuple(curr), tuple(data4), law_stopped)
    assert _packed(cf.pack_sensors2_fields, src, *curr, *data4, law_stopped) == want


def test_pack_errors_name_every_field_as_the_packet_does() -> None:
    """A sensor packet the Slave cannot pack (a special value out of its byte) is reported with
    its fields as the packets' other pack errors name them: Data1..4 as ``data``, not as the
    fourth byte's name."""
    msg = "Sensors2: cannot pack src=3, curr=(1, 2, 3), data=(4, 5, 6, 300): "
    with pytest.raises(PayloadError, match=re.escape(msg)):
        cf.pack_sensors2_fields(3, 1, 2, 3, 4, 5, 6, 300, False)
    with pytest.raises(PayloadError, match=re.escape(msg)):
        cf.pack_sensors2(3, (1, 2, 3), (4, 5, 6, 300))


def test_payload_byte_layouts() -> None:
    assert cf.pack_actuation1((-1, 0, 70), (100, 0, 5), 0xB9, 7) == bytes.fromhex("FF 00 46 64 00 05 B9 07")
    assert cf.pack_actuation2((1, 2, 3), (4, 5, 6), 7, 8) == bytes(range(1, 9))
    assert cf.pack_sensors1(2, (-90, 0, 90), (-3, 0, 3), 0xC1) == bytes.fromhex("20 A6 00 5A FD 00 03 C1")
    assert cf.pack_sensors2(2, (0, 50, 100), (128, 0, 255, 1)) == bytes.fromhex("28 00 32 64 80 00 FF 01")


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: cf.pack_actuation1((128, 0, 0), (0, 0, 0), 0, 0), "Actuation1.*127"),
        (lambda: cf.pack_actuation1((0, 0, 0), (-1, 0, 0), 0, 0), "Actuation1"),
        (lambda: cf.pack_actuation1((0, 0, 0, 0), (0, 0), 0, 0), "Actuation1"),
        (lambda: cf.pack_actuation1((0, 0, 0), (0, 0, 0), 256, 0), "Actuation1"),
        (lambda: cf.pack_actuation1((0.5, 0, 0), (0, 0, 0), 0, 0), "Actuation1"),
        (lambda: cf.pack_actuation2((0, 0, 0), (0, 0, 0), 0, 300), "Actuation2"),
        (lambda: cf.pack_sensors1(16, (0, 0, 0), (0, 0, 0), 0), "Sensors1.*source"),
        (lambda: cf.pack_sensors1(1, (0, 0, 0), (0, 0, 200), 0), "Sensors1"),
        (lambda: cf.pack_sensors2(1, (0, 101, 0), (0, 0, 0, 0)), "Sensors2.*0..100"),
        (lambda: cf.pack_sensors2(1, (0, 0, 0), (0, 0, 0)), "Sensors2"),
        (lambda: cf.unpack_actuation1(bytes(7)), "Actuation1.*8 bytes, got 7"),
        (lambda: cf.unpack_actuation2(bytes(9)), "Actuation2.*8 bytes, got 9"),
        (lambda: cf.unpack_sensors1(bytes(0)), "Sensors1.*8 bytes"),
        (lambda: cf.unpack_sensors1(bytes.fromhex("23 00 00 00 00 00 00 00")), "CAN state 3"),
        (lambda: cf.unpack_sensors1(bytes.fromhex("28 00 00 00 00 00 00 00")), "index 1, expected 0"),
        (lambda: cf.unpack_sensors2(bytes.fromhex("20 00 00 00 00 00 00 00")), "index 0, expected 1"),
        (lambda: cf.unpack_sensors2(bytes.fromhex("29 00 00 00 00 00 00 00")), "bits 2-0"),
        (lambda: cf.unpack_sensors2(bytes.fromhex("28 00 65 00 00 00 00 00")), "0..100"),
        (lambda: cf.unpack_sensors1_into(bytes.fromhex("20 00 00 00 00 00 00 00"), 3, [0] * 3, [0] * 3),
         "SFlags source 2 does not match the identifier's source 3"),
        (lambda: cf.unpack_sensors2_into(bytes(8), 0, [0] * 3, [0] * 4), "index 0, expected 1"),
    ],
)
def test_payload_errors(call, match) -> None:
    with pytest.raises(PayloadError, match=match):
        call()


# --- DBC ----------------------------------------------------------------------------------


def _make_dbc_module():
    spec = importlib.util.spec_from_file_location("make_dbc", REPO / "scripts" / "make_dbc.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def db():
    return cf.load_dbc()


def test_shipped_dbc_is_what_the_script_generates() -> None:
    mod = _make_dbc_module()
    shipped = (REPO / "humanoid_twin" / "protocol" / "humanoid_twin.dbc").read_bytes().decode()
    assert shipped == mod.dbc_text(), "run scripts/make_dbc.py"


def test_dbc_messages_nodes_and_ids(db) -> None:
    assert {n.name for n in db.nodes} == {"MASTER", *(f"SCU{k}" for k in range(1, 9))}
    assert "Right Leg" in db.get_node_by_name("SCU1").comment
    assert len(db.messages) == 32
    for k in range(1, 9):
        for name, fid, sender in (
            (f"Actuation1_S{k}", cf.ACTUATION_IDS[k][0], "MASTER"),
            (f"Actuation2_S{k}", cf.ACTUATION_IDS[k][1], "MASTER"),
            (f"Sensors1_S{k}", cf.SENSOR_IDS[k][0], f"SCU{k}"),
            (f"Sensors2_S{k}", cf.SENSOR_IDS[k][1], f"SCU{k}"),
        ):
            m = db.get_message_by_name(name)
            assert m.frame_id == fid and m.length == 8 and not m.is_extended_frame
            assert m.senders == [sender]


@given(
    st.integers(1, 8),
    three_i8,
    three_u8,
    st.booleans(),
    st.booleans(),
    st.tuples(*[st.integers(0, 3)] * 3),
    u8,
)
def test_dbc_decodes_actuation1(db, k, refs, speeds, pwm, calib, types, kd3) -> None:
    data = cf.pack_actuation1(refs, speeds, cf.control_byte(pwm, calib, types), kd3)
    sig = db.decode_message(cf.ACTUATION_IDS[k][0], data, decode_choices=False)
    assert [sig[f"Ref{i}"] for i in (1, 2, 3)] == list(refs)
    assert [sig[f"Speed{i}"] for i in (1, 2, 3)] == list(speeds)
    assert [sig[f"Type{i}"] for i in (1, 2, 3)] == list(types)
    assert (sig["PWM"], sig["Calib"], sig["KD3"]) == (pwm, calib, kd3)
    # and back: cantools encodes what the codec unpacks
    assert db.encode_message(cf.ACTUATION_IDS[k][0], sig) == data


@given(st.integers(1, 8), three_u8, three_u8, u8, u8)
def test_dbc_decodes_actuation2(db, k, ki, kp, kd1, kd2) -> None:
    data = cf.pack_actuation2(ki, kp, kd1, kd2)
    sig = db.decode_message(cf.ACTUATION_IDS[k][1], data)
    assert [sig[f"KI{i}"] for i in (1, 2, 3)] == list(ki)
    assert [sig[f"KP{i}"] for i in (1, 2, 3)] == list(kp)
    assert (sig["KD1"], sig["KD2"]) == (kd1, kd2)
    assert db.encode_message(cf.ACTUATION_IDS[k][1], sig) == data


@given(
    st.integers(1, 8), three_i8, three_i8, st.booleans(), st.booleans(), st.booleans(), st.booleans(),
    st.booleans(), flags3, st.booleans(), st.sampled_from(list(ErrorState)),
)  # fmt: skip
def test_dbc_decodes_sensors1(db, k, pos, speed, pwm, calib, deadline, fin_all, fin_one, fin, watchdog,
                              can_state) -> None:
    flags = (cf.SFLAGS_WATCHDOG if watchdog else 0) | int(can_state)
    status = cf.status_byte(pwm, calib, deadline, fin_all, fin_one, fin)
    data = cf.pack_sensors1(k, pos, speed, status, flags)
    sig = db.decode_message(cf.SENSOR_IDS[k][0], data)
    assert (sig["SFlagsSource"], sig["SFlagsIndex"]) == (k, 0)
    assert (sig["Watchdog"], str(sig["CanState"])) == (watchdog, can_state.label)
    assert [sig[f"Pos{i}"] for i in (1, 2, 3)] == list(pos)
    assert [sig[f"Speed{i}"] for i in (1, 2, 3)] == list(speed)
    assert (sig["PWM"], sig["Calib"], sig["Deadline"], sig["FinAll"], sig["FinOne"]) == (
        pwm, calib, deadline, fin_all, fin_one,
    )  # fmt: skip
    assert [sig[f"Fin{i}"] for i in (1, 2, 3)] == list(fin)
    assert db.encode_message(cf.SENSOR_IDS[k][0], sig) == data


@given(st.integers(1, 8), st.tuples(*[st.integers(0, 100)] * 3), st.tuples(u8, u8, u8, u8), st.booleans())
def test_dbc_decodes_sensors2(db, k, curr, data4, law_stopped) -> None:
    data = cf.pack_sensors2(k, curr, data4, law_stopped)
    sig = db.decode_message(cf.SENSOR_IDS[k][1], data)
    assert (sig["SFlagsSource"], sig["SFlagsIndex"], sig["LawStopped"]) == (k, 1, law_stopped)
    assert [sig[f"Curr{i}"] for i in (1, 2, 3)] == list(curr)
    if k == IMU_SCU:     # the body board: inclinometer and gyroscope, in physical units
        scales = (IMU_INCL_DEG_PER_COUNT,) * 2 + (IMU_GYRO_DPS_PER_COUNT,) * 2
        assert [sig[name] for name in IMU_SENSOR_NAMES] == [
            (d - IMU_ZERO_COUNT) * sc for d, sc in zip(data4, scales, strict=True)]
    else:
        assert [sig[name] for name in ("FL", "FR", "RL", "RR")] == list(data4)   # table 12 order
    assert db.encode_message(cf.SENSOR_IDS[k][1], sig) == data


# --- protocol/wire.py: the shared facts, once -----------------------------------------------------
def test_check_scu_takes_1_to_8_and_names_what_was_wrong():
    from humanoid_twin.protocol.wire import SCUS, check_scu

    assert [check_scu(s) for s in SCUS] == list(range(1, 9))
    assert type(check_scu(np.int64(3))) is int
    for bad, why in ((0, "1..8, got 0"), (9, "1..8, got 9"), (True, "integer 1..8"), ("1", "integer 1..8")):
        with pytest.raises(ValueError, match=why):
            check_scu(bad, "scuid")
    reason = rs232.invalid_reason(rs232.Request(rs232.Op.READ_SENSORS, 9, 0))
    assert reason == "SCU address must be 1..8, got 9"


def test_error_states_name_the_bus_states_and_carry_the_wire_codes():
    from humanoid_twin.bus.confinement import BUS_OFF, ERROR_ACTIVE, ERROR_PASSIVE, ERROR_STATE_CODE

    assert [ErrorState.from_label(x) for x in (ERROR_ACTIVE, ERROR_PASSIVE, BUS_OFF)] == [0, 1, 2]
    assert ERROR_STATE_CODE == {"error-active": 0, "error-passive": 1, "bus-off": 2}
    assert ErrorState.BUS_OFF.label == "bus-off"


def test_control_and_status_bits_are_the_codecs_bits():
    from humanoid_twin.protocol import wire

    ct = wire.ControlType
    b = cf.control_byte(True, True, (ct.BALANCE_CONTROL, 0, ct.LOCOMOTION_CONTROL))
    assert b == wire.CONTROL_PWM | wire.CONTROL_CALIB | (1 << 4) | 3
    st = cf.status_byte(True, False, True, False, True, (True, False, True))
    assert st == (wire.STATUS_PWM | wire.STATUS_DEADLINE | wire.STATUS_ONE_FINISHED
                  | wire.STATUS_FINISHED[0] | wire.STATUS_FINISHED[2])
    assert cf.parse_status_byte(st) == (True, False, True, False, True, (True, False, True))


def test_the_unpack_into_codecs_refuse_lists_too_short_and_leave_them_as_they_were():
    """The Master's in-place codecs check their lists before writing (in the compiled core a
    short list would be written past its end)."""
    p1 = cf.pack_sensors1(3, (1, 2, 3), (4, 5, 6), 0)
    p2 = cf.pack_sensors2(3, (10, 20, 30), (1, 2, 3, 4))
    for pos, vel in [([0], [0, 0, 0]), ([0, 0, 0], []), (None, [0, 0, 0])]:
        before = None if pos is None else list(pos)
        with pytest.raises(ValueError, match="at least 3"):
            cf.unpack_sensors1_into(p1, 3, pos, vel)
        assert pos == before
    for curr, data4 in [([0, 0], [0, 0, 0, 0]), ([0, 0, 0], [0, 0, 0]), ([0, 0, 0], None)]:
        with pytest.raises(ValueError, match="at least 3 and 4"):
            cf.unpack_sensors2_into(p2, 3, curr, data4)
    pos, vel, curr, data4 = [0] * 3, [0] * 3, [0] * 3, [0] * 4
    assert cf.unpack_sensors1_into(p1, 3, pos, vel) == 0 and pos == [1, 2, 3] and vel == [4, 5, 6]
    cf.unpack_sensors2_into(p2, 3, curr, data4)
    assert curr == [10, 20, 30] and data4 == [1, 2, 3, 4]
    # the Slave's: no record, a ValueError (in the compiled core it would be written through None)
    for unpack in (cf.unpack_actuation1_into, cf.unpack_actuation2_into):
        with pytest.raises(ValueError, match="ActuationFields"):
            unpack(bytes(8), None)
