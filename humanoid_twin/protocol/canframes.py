"""CAN identifiers, acceptance filters and 8-byte payloads between the Master and the Slaves.

Seed 002 slides 18-20 (identifier, addresses, payload layouts) and 23-24
(acceptance masks/filters, RX/TX buffers). The contract and the interpretations of the seeds are
written down in ``docs/protocol.md``.

Identifier (11 bits): bits 10-7 source address, 6-3 destination, 2 packet index, 1-0 operation
(:data:`OP_ACTUATION` Master -> Slave, :data:`OP_SENSORS` Slave -> Master).

Pure codecs, no I/O, no time, built for the hot path (thousands of payloads per simulated second):
the pack functions take plain ints/tuples and return bytes over precompiled ``struct.Struct``
objects; the unpack functions read the payload's bytes one by one (an int8 field through a
256-entry table; C byte reads in the compiled core, canframes.pxd) and return plain ints/tuples;
the byte parsers are 256-entry look-up tables.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

from humanoid_twin.protocol.wire import (
    CONTROL_CALIB,
    CONTROL_PWM,
    CONTROL_TYPE_BITS,
    CONTROL_TYPE_MASK,
    MASTER_ADDRESS,
    SCUS,
    STATUS_ALL_FINISHED,
    STATUS_CALIB,
    STATUS_DEADLINE,
    STATUS_FINISHED,
    STATUS_ONE_FINISHED,
    STATUS_PWM,
    ErrorState,
    from_s8,
)

try:        # Cython's pure-Python mode: True in the compiled core (as in clock.py)
    import cython
    _COMPILED = cython.compiled
except ImportError:         # interpreted, Cython not installed
    _COMPILED = False

if TYPE_CHECKING:  # cantools is imported lazily by load_dbc (it is slow to import)
    import can.typechecking
    import cantools.database

__all__ = [
    "sensors1_with_status",
    "OP_ACTUATION",
    "OP_SENSORS",
    "MASTER_ADDRESS",
    "PAYLOAD_LEN",
    "CURRENT_MAX",
    "MASTER_MASK",
    "SLAVE_MASK",
    "ACTUATION_IDS",
    "SENSOR_IDS",
    "PayloadError",
    "SlaveStatus",
    "STD_ID_MAX",
    "CAN_BITRATE",
    "PIC_TX_BUFFERS",
    "PIC_RX_BUFFERS",
    "can_id",
    "split_id",
    "packet_index",
    "master_filters",
    "slave_filters",
    "control_byte",
    "parse_control_byte",
    "status_byte",
    "parse_status_byte",
    "supervisor_flags",
    "SFLAGS_SOURCE_SHIFT",
    "SFLAGS_INDEX",
    "SFLAGS_WATCHDOG",
    "SFLAGS_CAN_STATE",
    "SFLAGS_SUPERVISOR",
    "ID_FIELDS",
    "SFLAGS2_LAW",
    "sflags",
    "ActuationFields",
    "pack_actuation1",
    "unpack_actuation1",
    "unpack_actuation1_into",
    "pack_actuation2",
    "unpack_actuation2",
    "unpack_actuation2_into",
    "pack_sensors1",
    "pack_sensors1_fields",
    "unpack_sensors1",
    "unpack_sensors1_into",
    "pack_sensors2",
    "pack_sensors2_fields",
    "unpack_sensors2",
    "unpack_sensors2_into",
    "load_dbc",
    "DBC_RESOURCE",
]

OP_ACTUATION = 0        # Master -> Slave (a project decision: docs/protocol.md 2.1)
OP_SENSORS = 1          # Slave -> Master
PAYLOAD_LEN = 8         # every packet carries 8 data bytes (slide 20)
CURRENT_MAX = 100       # Curr1..3 are 0..100 (seed 000 finalizeServoMeasures, docs/firmware.md)

# Identifier layout (slide 18): bits 10-7 source, 6-3 destination, 2 packet index, 1-0 operation.
STD_ID_MAX = 0x7FF      # an 11-bit standard identifier

# The PIC18F258's CAN module (seed 002 slide 21): bit rates up to 1 Mbit/s, the robot's bus rate
# (docs/buses.md); 3 prioritized TX buffers and 2 RX buffers (their use: slide 24).
CAN_BITRATE = 1_000_000
PIC_TX_BUFFERS = 3
PIC_RX_BUFFERS = 2
_SRC_SHIFT = 7
_DST_SHIFT = 3
_INDEX_SHIFT = 2
_ADDR_MASK = 0x0F       # 4-bit source and destination addresses
_OP_MASK = 0x03

# Acceptance masks (seed 002 slide 23). A frame is accepted when (id & mask) == (filter & mask).
MASTER_MASK = (_ADDR_MASK << _DST_SHIFT) | (1 << _INDEX_SHIFT)  # 0b00001111100 destination + index:
#                                                                  frames destined to the Master
SLAVE_MASK = (_ADDR_MASK << _SRC_SHIFT) | (1 << _INDEX_SHIFT)   # 0b11110000100 source + index: frames
#                                                   from the Master (destination NOT in the mask)

DBC_RESOURCE = "humanoid_twin.dbc"


class PayloadError(ValueError):
    """A CAN payload that cannot be packed or unpacked: wrong length, a value out of its field's
    range, or SFlags bits 2-0 not zero / SFlags index not the packet's."""


# --- identifiers ---------------------------------------------------------------------------


def can_id(src: int, dst: int, index: int, op: int) -> int:
    """11-bit identifier: bits 10-7 source, 6-3 destination, 2 index, 1-0 operation (slide 18).
    ``ValueError`` when a field does not fit its bits."""
    if not (0 <= src <= _ADDR_MASK and 0 <= dst <= _ADDR_MASK and 0 <= index <= 1 and 0 <= op <= _OP_MASK):
        raise ValueError(
            f"CAN id fields out of range: src={src!r} (0..15), dst={dst!r} (0..15), "
            f"index={index!r} (0..1), op={op!r} (0..3)"
        )
    return (src << _SRC_SHIFT) | (dst << _DST_SHIFT) | (index << _INDEX_SHIFT) | op


def split_id(arbitration_id: int) -> tuple[int, int, int, int]:
    """Identifier -> ``(src, dst, index, op)``; ``ValueError`` if not an 11-bit standard id."""
    if not 0 <= arbitration_id <= STD_ID_MAX:
        raise ValueError(f"standard CAN id must be 0..0x7FF, got {arbitration_id!r}")
    return (arbitration_id >> _SRC_SHIFT, (arbitration_id >> _DST_SHIFT) & _ADDR_MASK,
            packet_index(arbitration_id), arbitration_id & _OP_MASK)


def packet_index(arbitration_id: int) -> int:
    """The packet index (bit 2) of an identifier: 0 for Actuation 1 / Sensors 1, 1 for
    Actuation 2 / Sensors 2; the bit the acceptance filters route to RXB0 / RXB1."""
    return (arbitration_id >> _INDEX_SHIFT) & 1


# Every standard identifier's fields, ``ID_FIELDS[id] = split_id(id)`` (the receive paths' look-up).
ID_FIELDS: tuple[tuple[int, int, int, int], ...] = tuple(split_id(i) for i in range(0x800))

# Precomputed identifiers, scu 1..8 -> (packet index 0, packet index 1).
ACTUATION_IDS: dict[int, tuple[int, int]] = {
    k: (can_id(MASTER_ADDRESS, k, 0, OP_ACTUATION), can_id(MASTER_ADDRESS, k, 1, OP_ACTUATION))
    for k in SCUS
}
SENSOR_IDS: dict[int, tuple[int, int]] = {
    k: (can_id(k, MASTER_ADDRESS, 0, OP_SENSORS), can_id(k, MASTER_ADDRESS, 1, OP_SENSORS))
    for k in SCUS
}


def master_filters() -> list[can.typechecking.CanFilter]:
    """python-can ``can_filters`` of the Master (slide 23): ``[RXB0, RXB1]``.

    RXB0 ``0bxxxx00000xx`` (to the Master, index 0), RXB1 ``0bxxxx00001xx`` (index 1), both with
    :data:`MASTER_MASK`. List position 0 = RXB0, 1 = RXB1.
    """
    return [{"can_id": can_id(0, MASTER_ADDRESS, i, 0), "can_mask": MASTER_MASK, "extended": False}
            for i in (0, 1)]


def slave_filters() -> list[can.typechecking.CanFilter]:
    """python-can ``can_filters`` of a Slave (slide 23): ``[RXB0, RXB1]``.

    RXB0 ``0b0000xxxx0xx`` (from the Master, index 0), RXB1 ``0b0000xxxx1xx`` (index 1), both
    with :data:`SLAVE_MASK`. The destination is not in the mask: every slave receives every
    Master frame and checks the destination in software (``receiveCanMessage``).
    """
    return [{"can_id": can_id(MASTER_ADDRESS, 0, i, 0), "can_mask": SLAVE_MASK, "extended": False}
            for i in (0, 1)]


# --- control, status and SFlags bytes ------------------------------------------------------


def control_byte(pwm: bool, calib: bool, types: Sequence[int]) -> int:
    """Actuation 1 Control byte (slide 20): bit 7 PWM, bit 6 Calib, bits 5-0 control types of
    servo 3, 2, 1 (2 bits each; servo 1 in bits 1-0). ``types`` = (servo 1, servo 2, servo 3)."""
    try:
        t1, t2, t3 = types
        m = CONTROL_TYPE_MASK
        if 0 <= t1 <= m and 0 <= t2 <= m and 0 <= t3 <= m:
            return ((CONTROL_PWM if pwm else 0) | (CONTROL_CALIB if calib else 0)
                    | (t3 << 2 * CONTROL_TYPE_BITS) | (t2 << CONTROL_TYPE_BITS) | t1)
    except TypeError:
        pass
    except ValueError:
        raise PayloadError(f"control types must be 3 values (servo 1, 2, 3), got {types!r}") from None
    raise PayloadError(f"control types must be 3 integers 0..3 (servo 1, 2, 3), got {types!r}")


class ActuationFields:
    """The fields of an actuation packet (slide 20) as a record the caller owns and reuses:
    :func:`unpack_actuation1_into` and :func:`unpack_actuation2_into` write their packet's fields
    into it (the Slave's ``receiveCanMessage``: no tuple per packet; C fields in the compiled
    core, canframes.pxd). Actuation 1: ``ref1..3`` (int8 degrees), ``speed1..3`` (period in
    ticks), ``control`` (the Control byte) read as ``pwm``, ``calib``, ``type1..3`` (servo 1, 2,
    3), ``kd3``. Actuation 2: ``ki1..3``, ``kp1..3``, ``kd1``, ``kd2``."""

    __slots__ = ("ref1", "ref2", "ref3", "speed1", "speed2", "speed3", "control", "pwm", "calib",
                 "type1", "type2", "type3", "kd3", "ki1", "ki2", "ki3", "kp1", "kp2", "kp3", "kd1",
                 "kd2")

    def __init__(self) -> None:
        self.ref1 = self.ref2 = self.ref3 = 0
        self.speed1 = self.speed2 = self.speed3 = 0
        self.control = 0
        self.pwm = self.calib = False
        self.type1 = self.type2 = self.type3 = 0
        self.kd3 = 0
        self.ki1 = self.ki2 = self.ki3 = 0
        self.kp1 = self.kp2 = self.kp3 = 0
        self.kd1 = self.kd2 = 0


def _control_into(b: int, out: ActuationFields) -> None:
    """The Control byte ``b`` (0..255) into ``out.control``, ``pwm``, ``calib``, ``type1..3``:
    the one reading of its bits (:func:`control_byte` writes them; :func:`parse_control_byte`'s
    table is built from this)."""
    out.control = b
    out.pwm = (b & _PWM) != 0
    out.calib = (b & _CALIB) != 0
    out.type1 = b & _TYPE_MASK
    out.type2 = (b >> _TYPE_BITS) & _TYPE_MASK
    out.type3 = (b >> 2 * _TYPE_BITS) & _TYPE_MASK


def _control_fields(b: int) -> tuple[int, bool, bool, int, int, int]:
    f = ActuationFields()
    _control_into(b, f)
    return f.control, f.pwm, f.calib, f.type1, f.type2, f.type3


# C constants of the Control byte's bits (canframes.pxd; the public names are wire.py's)
_PWM = CONTROL_PWM
_CALIB = CONTROL_CALIB
_TYPE_BITS = CONTROL_TYPE_BITS
_TYPE_MASK = CONTROL_TYPE_MASK
# every Control byte's fields: (control, pwm, calib, type1, type2, type3), and as
# parse_control_byte returns them
_CONTROL_FIELDS: tuple[tuple[int, bool, bool, int, int, int], ...] = tuple(
    _control_fields(b) for b in range(256)
)
_CONTROL_TABLE: tuple[tuple[bool, bool, tuple[int, int, int]], ...] = tuple(
    (pwm, calib, (t1, t2, t3)) for _, pwm, calib, t1, t2, t3 in _CONTROL_FIELDS
)


def parse_control_byte(b: int) -> tuple[bool, bool, tuple[int, int, int]]:
    """Control byte -> ``(pwm, calib, (type servo 1, type servo 2, type servo 3))``."""
    if not 0 <= b <= 255:
        raise PayloadError(f"control byte must be 0..255, got {b!r}")
    return _CONTROL_TABLE[b]


class SlaveStatus(NamedTuple):
    """Sensors 1 Status byte (slide 20), as parsed by :func:`parse_status_byte`."""

    pwm: bool                       # bit 7: PWM on
    calib: bool                     # bit 6: calibration complete
    deadline: bool                  # bit 5: deadline violated
    fin_all: bool                   # bit 4: all motions finished
    fin_one: bool                   # bit 3: one motion finished
    fin: tuple[bool, bool, bool]    # bits 0, 1, 2: motion of servo 1, 2, 3 finished


def status_byte(
    pwm: bool, calib: bool, deadline: bool, fin_all: bool, fin_one: bool, fin: Sequence[bool]
) -> int:
    """Sensors 1 Status byte (slide 20): bit 7 PWM, 6 Calib, 5 deadline violated, 4 all motions
    finished, 3 one motion finished, 2-0 motion finished per servo (servo 1 = bit 0)."""
    try:
        f1, f2, f3 = fin
    except (TypeError, ValueError):
        raise PayloadError(f"fin must be 3 flags (servo 1, 2, 3), got {fin!r}") from None
    return (
        (STATUS_PWM if pwm else 0)
        | (STATUS_CALIB if calib else 0)
        | (STATUS_DEADLINE if deadline else 0)
        | (STATUS_ALL_FINISHED if fin_all else 0)
        | (STATUS_ONE_FINISHED if fin_one else 0)
        | (_FIN3 if f3 else 0)
        | (_FIN2 if f2 else 0)
        | (_FIN1 if f1 else 0)
    )


_FIN1, _FIN2, _FIN3 = STATUS_FINISHED


_STATUS_TABLE: tuple[SlaveStatus, ...] = tuple(
    SlaveStatus(
        bool(b & STATUS_PWM),
        bool(b & STATUS_CALIB),
        bool(b & STATUS_DEADLINE),
        bool(b & STATUS_ALL_FINISHED),
        bool(b & STATUS_ONE_FINISHED),
        (bool(b & _FIN1), bool(b & _FIN2), bool(b & _FIN3)),
    )
    for b in range(256)
)


def parse_status_byte(b: int) -> SlaveStatus:
    """Status byte -> :class:`SlaveStatus`."""
    if not 0 <= b <= 255:
        raise PayloadError(f"status byte must be 0..255, got {b!r}")
    return _STATUS_TABLE[b]


# SFlags, byte 0 of a sensor packet (slide 20): bits 7-4 source address, bit 3 packet index,
# bits 2-0 zero in the seed (the supervisor's flags below use them).
SFLAGS_SOURCE_SHIFT = 4
SFLAGS_INDEX = 0x08
_SFLAGS_LOW = 0x07


def sflags(src: int, index: int) -> int:
    """SFlags byte of a sensor packet (slide 20): bits 7-4 source address, bit 3 index, 2-0 zero."""
    if not (0 <= src <= _ADDR_MASK and 0 <= index <= 1):
        raise PayloadError(f"SFlags: source must be 0..15 and index 0..1, got src={src!r}, index={index!r}")
    return (src << SFLAGS_SOURCE_SHIFT) | (SFLAGS_INDEX if index else 0)


def _split_sflags(sf: int, index: int, packet: str) -> int:
    if sf & _SFLAGS_LOW:
        raise PayloadError(f"{packet}: SFlags 0x{sf:02X} has bits 2-0 set (must be zero)")
    got = 1 if sf & _SF_INDEX else 0
    if got != index:
        raise PayloadError(f"{packet}: SFlags 0x{sf:02X} carries index {got}, expected {index}")
    return sf >> _SF_SHIFT


# --- payloads ------------------------------------------------------------------------------

_ACT1 = struct.Struct("<3b3B2B")   # Ref1..3 int8 deg, Speed1..3 (period, ticks), Control, KD3
_ACT2 = struct.Struct("<8B")       # KI1..3, KP1..3, KD1, KD2
_SEN1 = struct.Struct("<B3b3bB")   # SFlags, Pos1..3 int8 deg, Speed1..3 int8 deg/tick, Status
_SEN2 = struct.Struct("<8B")       # SFlags, Curr1..3 (0..100), Data1..4


def _pack_error(packet: str, exc: Exception, **fields: object) -> PayloadError:
    what = ", ".join(f"{k}={v!r}" for k, v in fields.items())
    return PayloadError(f"{packet}: cannot pack {what}: {exc}")


def _length_error(packet: str, data: bytes | bytearray | memoryview) -> PayloadError:
    return PayloadError(
        f"{packet}: payload must be {PAYLOAD_LEN} bytes, got {len(data)}: [{bytes(data).hex(' ').upper()}]"
    )


# an int8 field (Ref, Pos, Speed of slide 20: two's complement) by its byte's value
_INT8: tuple[int, ...] = tuple(from_s8(b) for b in range(256))


def _payload(data: bytes | bytearray | memoryview, packet: str) -> bytes:
    """A received payload as ``bytes`` of :data:`PAYLOAD_LEN` (``PayloadError`` otherwise)."""
    b = data if type(data) is bytes else bytes(memoryview(data))
    if len(b) != _PAYLOAD_LEN:
        raise _length_error(packet, data)
    return b


def _bytes8(b0: int, b1: int, b2: int, b3: int, b4: int, b5: int, b6: int, b7: int) -> bytes:
    """Eight byte values (0..255) -> 8 bytes (a C buffer copied once in the compiled core)."""
    if _COMPILED:
        buf = cython.declare(cython.uchar[8])
        buf[0] = b0
        buf[1] = b1
        buf[2] = b2
        buf[3] = b3
        buf[4] = b4
        buf[5] = b5
        buf[6] = b6
        buf[7] = b7
        return buf[:8]
    return bytes((b0, b1, b2, b3, b4, b5, b6, b7))


def pack_actuation1(refs: Sequence[int], speeds: Sequence[int], control: int, kd3: int) -> bytes:
    """Actuation 1 ``Ref1 Ref2 Ref3 Speed1 Speed2 Speed3 Control KD3`` (slide 20; ``canSendMsg``).

    ``refs``: int8 degrees; ``speeds``: movement period in 20 ms ticks, 0..255;
    ``control``: :func:`control_byte`; ``kd3``: 0..255.
    """
    try:
        r1, r2, r3 = refs
        s1, s2, s3 = speeds
        return _ACT1.pack(r1, r2, r3, s1, s2, s3, control, kd3)
    except (struct.error, TypeError, ValueError) as exc:
        raise _pack_error("Actuation1", exc, refs=refs, speeds=speeds, control=control, kd3=kd3) from None


def unpack_actuation1(data: bytes) -> tuple[tuple[int, int, int], tuple[int, int, int], int, int]:
    """Actuation 1 payload -> ``((ref1, ref2, ref3), (speed1, speed2, speed3), control, kd3)``."""
    f = ActuationFields()
    unpack_actuation1_into(data, f)
    return (f.ref1, f.ref2, f.ref3), (f.speed1, f.speed2, f.speed3), f.control, f.kd3


def unpack_actuation1_into(data: bytes, out: ActuationFields) -> None:
    """:func:`unpack_actuation1` into the record ``out`` (``receiveCanMessage`` on the Slave):
    sets ``ref1..3``, ``speed1..3``, ``control`` and its bits (``pwm``, ``calib``, ``type1..3``),
    ``kd3``. The same ``PayloadError``, and ``out`` left as it was then."""
    if out is None:
        raise ValueError("unpack_actuation1_into: out must be an ActuationFields")
    b = data if type(data) is bytes and len(data) == _PAYLOAD_LEN else _payload(data, "Actuation1")
    i8 = _INT8
    out.ref1 = i8[b[0]]
    out.ref2 = i8[b[1]]
    out.ref3 = i8[b[2]]
    out.speed1 = b[3]
    out.speed2 = b[4]
    out.speed3 = b[5]
    if _COMPILED:       # C bit operations
        _control_into(b[6], out)
    else:               # interpreted: its table (built by _control_into), no call
        out.control, out.pwm, out.calib, out.type1, out.type2, out.type3 = _CONTROL_FIELDS[b[6]]
    out.kd3 = b[7]


def pack_actuation2(ki: Sequence[int], kp: Sequence[int], kd1: int, kd2: int) -> bytes:
    """Actuation 2 ``KI1 KI2 KI3 KP1 KP2 KP3 KD1 KD2`` (slide 20: "K1 K2" = KD1 KD2), bytes 0..255."""
    try:
        i1, i2, i3 = ki
        p1, p2, p3 = kp
        return _ACT2.pack(i1, i2, i3, p1, p2, p3, kd1, kd2)
    except (struct.error, TypeError, ValueError) as exc:
        raise _pack_error("Actuation2", exc, ki=ki, kp=kp, kd1=kd1, kd2=kd2) from None


def unpack_actuation2(data: bytes) -> tuple[tuple[int, int, int], tuple[int, int, int], int, int]:
    """Actuation 2 payload -> ``((ki1, ki2, ki3), (kp1, kp2, kp3), kd1, kd2)``."""
    f = ActuationFields()
    unpack_actuation2_into(data, f)
    return (f.ki1, f.ki2, f.ki3), (f.kp1, f.kp2, f.kp3), f.kd1, f.kd2


def unpack_actuation2_into(data: bytes, out: ActuationFields) -> None:
    """:func:`unpack_actuation2` into the record ``out``: sets ``ki1..3``, ``kp1..3``, ``kd1``,
    ``kd2``. The same ``PayloadError``, and ``out`` left as it was then."""
    if out is None:
        raise ValueError("unpack_actuation2_into: out must be an ActuationFields")
    b = data if type(data) is bytes and len(data) == _PAYLOAD_LEN else _payload(data, "Actuation2")
    out.ki1 = b[0]
    out.ki2 = b[1]
    out.ki3 = b[2]
    out.kp1 = b[3]
    out.kp2 = b[4]
    out.kp3 = b[5]
    out.kd1 = b[6]
    out.kd2 = b[7]


def pack_sensors1(src: int, pos: Sequence[int], speed: Sequence[int], status: int, flags: int = 0) -> bytes:
    """Sensors 1 ``SFlags Pos1 Pos2 Pos3 Speed1 Speed2 Speed3 Status`` (slide 20; ``sendCanMessage``).

    ``src``: the slave's address; ``pos``: int8 degrees; ``speed``: mean velocity, int8 degrees
    per 20 ms tick; ``status``: :func:`status_byte`. ``flags``: the supervisor flags in SFlags
    bits 2-0 (:func:`supervisor_flags`; 0 on a healthy board, so the seed's bytes are unchanged).
    """
    try:
        if not 0 <= src <= _ADDR_MASK:
            raise ValueError(f"source address must be 0..15, got {src!r}")
        if not 0 <= flags <= _SFLAGS_LOW or flags & SFLAGS_CAN_STATE > ErrorState.BUS_OFF:
            raise ValueError(f"supervisor flags must be 0..7 with CAN state 0..2, got {flags!r}")
        p1, p2, p3 = pos
        v1, v2, v3 = speed
        return _SEN1.pack((src << SFLAGS_SOURCE_SHIFT) | flags, p1, p2, p3, v1, v2, v3, status)
    except (struct.error, TypeError, ValueError) as exc:
        raise _pack_error("Sensors1", exc, src=src, pos=pos, speed=speed, status=status) from None


def pack_sensors1_fields(src: int, pos1: int, pos2: int, pos3: int, speed1: int, speed2: int, speed3: int,
                         status: int, flags: int) -> bytes:
    """:func:`pack_sensors1` on integer fields one by one (the Slave's tick; C integers in the
    compiled core, no ``struct``): the same bytes; a field out of its range goes through
    :func:`pack_sensors1`, which raises its ``PayloadError``."""
    if (0 <= src <= _ADDR_MASK and 0 <= flags <= _SFLAGS_LOW and flags & _CAN_STATE <= _CAN_STATE_MAX
            and -128 <= pos1 <= 127 and -128 <= pos2 <= 127 and -128 <= pos3 <= 127
            and -128 <= speed1 <= 127 and -128 <= speed2 <= 127 and -128 <= speed3 <= 127
            and 0 <= status <= 255):
        return _bytes8((src << _SF_SHIFT) | flags, pos1 & 0xFF, pos2 & 0xFF, pos3 & 0xFF,
                       speed1 & 0xFF, speed2 & 0xFF, speed3 & 0xFF, status)
    return pack_sensors1(src, (pos1, pos2, pos3), (speed1, speed2, speed3), status, flags)


SENSORS1_STATUS_BYTE = 7        # the Status byte's place in Sensors 1 (slide 20), last


def sensors1_with_status(data: bytes, bits: int) -> bytes:
    """The Sensors 1 payload ``data`` with ``bits`` (``STATUS_*``) also set in its Status byte."""
    b = _payload(data, "Sensors1")
    i = SENSORS1_STATUS_BYTE
    return b[:i] + bytes((b[i] | (bits & 0xFF),)) + b[i + 1:]


def unpack_sensors1(data: bytes) -> tuple[int, int, tuple[int, int, int], tuple[int, int, int], int]:
    """Sensors 1 payload -> ``(src, index, (pos1, pos2, pos3), (speed1, speed2, speed3), status)``.
    ``PayloadError`` if its index is not 0 or SFlags bits 1-0 are 3. Bits 2-0 are the supervisor
    flags (:func:`supervisor_flags`)."""
    b = _payload(data, "Sensors1")
    src = _sensors1_source(b)
    pos = [0, 0, 0]
    vel = [0, 0, 0]
    status = unpack_sensors1_into(b, src, pos, vel)
    return src, 0, (pos[0], pos[1], pos[2]), (vel[0], vel[1], vel[2]), status


def unpack_sensors1_into(data: bytes, src: int, pos: list[int], vel: list[int]) -> int:
    """:func:`unpack_sensors1` of a packet from slave ``src`` into lists (``canReceiveMsg`` on
    the Master, straight into its database: no tuple per packet): sets ``pos[0:3]`` and
    ``vel[0:3]``, returns the Status byte. The same ``PayloadError`` as :func:`unpack_sensors1`,
    and one when the SFlags source is not ``src``; the lists are left as they were then (and on
    the ``ValueError`` of a list shorter than 3)."""
    if pos is None or vel is None or len(pos) < 3 or len(vel) < 3:
        raise ValueError("unpack_sensors1_into: pos and vel must be lists of at least 3 items")
    b = _payload(data, "Sensors1")
    sf_src = _sensors1_source(b)
    if sf_src != src:
        raise _source_error(sf_src, src)
    i8 = _INT8
    pos[0] = i8[b[1]]
    pos[1] = i8[b[2]]
    pos[2] = i8[b[3]]
    vel[0] = i8[b[4]]
    vel[1] = i8[b[5]]
    vel[2] = i8[b[6]]
    return b[7]


def _sensors1_source(b: bytes) -> int:
    """The source address in a Sensors 1 payload's SFlags (``PayloadError`` as :func:`unpack_sensors1`)."""
    sf = b[0]
    if sf & _CAN_STATE > _CAN_STATE_MAX:
        raise PayloadError(f"Sensors1: SFlags 0x{sf:02X} carries CAN state 3 (0..2 only)")
    return _split_sflags(sf & ~_SUPERVISOR, 0, "Sensors1")


def _source_error(sf_src: int, src: int) -> PayloadError:
    return PayloadError(f"SFlags source {sf_src} does not match the identifier's source {src}")


# Sensors 1 SFlags bits 2-0 (zero in seed 002 slide 20): the supervisor flags of the Slave
# (docs/supervisor.md). Bit 2: the CAN watchdog holds the last reference; bits 1-0: the Slave's
# CAN error state (0 error-active, 1 error-passive, 2 bus-off since its last tick).
SFLAGS_WATCHDOG = 0x04
SFLAGS_CAN_STATE = 0x03
SFLAGS_SUPERVISOR = SFLAGS_WATCHDOG | SFLAGS_CAN_STATE   # bits 2-0 (Sensors 2: bit 2 = a law stopped)
# Sensors 2 SFlags bit 2 (zero in slide 20): a control law of the Slave was stopped (it raised or
# returned bad values; the board holds those servos; docs/controllers.md, docs/supervisor.md).
SFLAGS2_LAW = 0x04

# the same facts under private names, C constants of the compiled codecs (canframes.pxd; the
# public names stay Python objects for the modules that import them)
_CAN_STATE = SFLAGS_CAN_STATE
_CAN_STATE_MAX = int(ErrorState.BUS_OFF)
_SUPERVISOR = SFLAGS_SUPERVISOR
_LAW = SFLAGS2_LAW
_CURRENT_MAX = CURRENT_MAX
_SF_SHIFT = SFLAGS_SOURCE_SHIFT
_SF_INDEX = SFLAGS_INDEX
_PAYLOAD_LEN = PAYLOAD_LEN


def supervisor_flags(data: bytes | bytearray) -> tuple[bool, int]:
    """``(watchdog_holding, can_state)`` from a Sensors 1 payload's SFlags bits 2-0."""
    sf = data[0]
    return bool(sf & SFLAGS_WATCHDOG), sf & SFLAGS_CAN_STATE


def pack_sensors2(src: int, curr: Sequence[int], data4: Sequence[int], law_stopped: bool = False) -> bytes:
    """Sensors 2 ``SFlags Curr1 Curr2 Curr3 Data1 Data2 Data3 Data4`` (slide 20).

    ``curr``: 0..100 (:data:`CURRENT_MAX`); ``data4``: the 4 special sensors (force), bytes;
    ``law_stopped``: SFlags bit 2 (:data:`SFLAGS2_LAW`).
    """
    try:
        if not 0 <= src <= _ADDR_MASK:
            raise ValueError(f"source address must be 0..15, got {src!r}")
        c1, c2, c3 = curr
        d1, d2, d3, d4 = data4
        if c1 > CURRENT_MAX or c2 > CURRENT_MAX or c3 > CURRENT_MAX:
            raise ValueError(f"current must be 0..{CURRENT_MAX}")
        sf = (src << SFLAGS_SOURCE_SHIFT) | SFLAGS_INDEX | (SFLAGS2_LAW if law_stopped else 0)
        return _SEN2.pack(sf, c1, c2, c3, d1, d2, d3, d4)
    except (struct.error, TypeError, ValueError) as exc:
        raise _pack_error("Sensors2", exc, src=src, curr=curr, data=data4) from None


def pack_sensors2_fields(src: int, curr1: int, curr2: int, curr3: int, data1: int, data2: int, data3: int,
                         data4: int, law_stopped: bool) -> bytes:
    """:func:`pack_sensors2` on integer fields one by one (the Slave's tick; C integers in the
    compiled core, no ``struct``): the same bytes; a field out of its range goes through
    :func:`pack_sensors2`, which raises its ``PayloadError``."""
    if (0 <= src <= _ADDR_MASK and 0 <= curr1 <= _CURRENT_MAX and 0 <= curr2 <= _CURRENT_MAX
            and 0 <= curr3 <= _CURRENT_MAX and 0 <= data1 <= 255 and 0 <= data2 <= 255
            and 0 <= data3 <= 255 and 0 <= data4 <= 255):
        return _bytes8((src << _SF_SHIFT) | _SF_INDEX | (_LAW if law_stopped else 0),
                       curr1, curr2, curr3, data1, data2, data3, data4)
    return pack_sensors2(src, (curr1, curr2, curr3), (data1, data2, data3, data4), law_stopped)


def unpack_sensors2(data: bytes) -> tuple[int, int, tuple[int, int, int], tuple[int, int, int, int]]:
    """Sensors 2 payload -> ``(src, index, (curr1, curr2, curr3), (data1, data2, data3, data4))``.
    ``PayloadError`` if SFlags bits 1-0 are not zero, its index is not 1, or a current is over 100
    (bit 2, :data:`SFLAGS2_LAW`, is read with ``data[0] & SFLAGS2_LAW``)."""
    b = _payload(data, "Sensors2")
    src = _sensors2_source(b)
    curr = [0, 0, 0]
    data4 = [0, 0, 0, 0]
    unpack_sensors2_into(b, src, curr, data4)
    return src, 1, (curr[0], curr[1], curr[2]), (data4[0], data4[1], data4[2], data4[3])


def unpack_sensors2_into(data: bytes, src: int, curr: list[int], data4: list[int]) -> None:
    """:func:`unpack_sensors2` of a packet from slave ``src`` into lists (``canReceiveMsg``, as
    :func:`unpack_sensors1_into`): sets ``curr[0:3]`` and ``data4[0:4]``. The same
    ``PayloadError`` as :func:`unpack_sensors2`, and one when the SFlags source is not ``src``;
    the lists are left as they were then (and on the ``ValueError`` of a list too short)."""
    if curr is None or data4 is None or len(curr) < 3 or len(data4) < 4:
        raise ValueError("unpack_sensors2_into: curr and data4 must be lists of at least 3 and 4 items")
    b = _payload(data, "Sensors2")
    sf_src = _sensors2_source(b)
    if sf_src != src:
        raise _source_error(sf_src, src)
    curr[0] = b[1]
    curr[1] = b[2]
    curr[2] = b[3]
    data4[0] = b[4]
    data4[1] = b[5]
    data4[2] = b[6]
    data4[3] = b[7]


def _sensors2_source(b: bytes) -> int:
    """The source address in a Sensors 2 payload's SFlags (``PayloadError`` as :func:`unpack_sensors2`)."""
    c1 = b[1]
    c2 = b[2]
    c3 = b[3]
    if c1 > _CURRENT_MAX or c2 > _CURRENT_MAX or c3 > _CURRENT_MAX:
        raise PayloadError(f"Sensors2: current must be 0..{CURRENT_MAX}, got {(c1, c2, c3)}")
    return _split_sflags(b[0] & ~_LAW, 1, "Sensors2")


# --- DBC -----------------------------------------------------------------------------------


def load_dbc() -> cantools.database.Database:
    """The shipped DBC (``humanoid_twin/protocol/humanoid_twin.dbc``, generated by
    ``scripts/make_dbc.py``): the 32 messages (4 per slave) for decoding CAN logs with cantools."""
    from importlib.resources import files

    import cantools

    text = files(__package__).joinpath(DBC_RESOURCE).read_text(encoding="utf-8")
    return cantools.database.load_string(text, database_format="dbc")  # type: ignore[return-value]  # a .dbc loads as a CAN database
