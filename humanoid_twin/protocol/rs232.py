"""RS-232 frames between the host (PC) and the Master board.

Seed 002 slides 7-11 (frame layout, OpCode table, examples); seed 000 tables 2-3
(``usartSendTestMsg``, ``usartSendStatus``, ``usartProcessMsg``). The byte-level contract and every
interpretation of the seeds are written down in ``docs/protocol.md``.

Every frame is 6 bytes. Request (host -> Master): ``FF OP D1 D2 D3 BCC``; responses (Master -> host):
``FB|FC <echo of OP D1 D2 D3> BCC``, ``FD V1 V2 V3 V4 BCC`` and the test message ``FA F9 F8 F7 F6 F5``.
``BCC`` is the XOR of the 5 bytes before it.

Pure codecs: no I/O, no time. The plain functions work on ints and bytes; :class:`Request` and
:class:`Response` are a convenience layer on top of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from humanoid_twin.protocol.wire import (
    MASTER_ADDRESS,
    N_SCU,
    POS_LIMIT_DEG,
    ControlType,
    from_s8,
    int_in_range,
    s8,
    scu_error,
)

__all__ = [
    "FRAME_LEN",
    "SOF",
    "MESSAGE_TEST",
    "MESSAGE_SUCCESS",
    "MESSAGE_INVREQ",
    "MESSAGE_DATA",
    "Op",
    "PARAM_POSITION",
    "PARAM_VELOCITY",
    "PARAM_CURRENT",
    "PARAM_SPECIAL",
    "PARAM_KI",
    "PARAM_KP",
    "PARAM_KD",
    "PARAM_CONTROLON",
    "PARAM_TEST",
    "PARAM_CANSTATUS",
    "PARAM_SUPERVISOR",
    "SUPERVISOR_READ",
    "SUPERVISOR_ESTOP",
    "SUPERVISOR_RESET",
    "SUPERVISOR_MODES",
    "SUPERVISOR_FAULTS",
    "supervisor_mode_name",
    "supervisor_fault_name",
    "ControlType",
    "TEST_MESSAGE",
    "N_SCU",
    "POS_LIMIT_DEG",
    "FrameError",
    "bcc",
    "make_opcode",
    "parse_opcode",
    "s8",
    "from_s8",
    "encode_request",
    "Request",
    "status_response",
    "data_response",
    "Response",
    "decode_response",
    "invalid_reason",
    "is_valid_request",
    "hexdump",
]

FRAME_LEN = 6

# First byte of a frame (seed 002 slide 8, seed 000 table 3).
SOF = 0xFF              # request, host -> Master
MESSAGE_TEST = 0xFA     # usartSendTestMsg
MESSAGE_SUCCESS = 0xFB  # usartSendStatus: APPLY accepted (the manual spells it MESSAGE_SUCESS)
MESSAGE_INVREQ = 0xFC   # usartSendStatus: invalid request
MESSAGE_DATA = 0xFD     # READ answers


class Op(IntEnum):
    """OpCode bits 7-6 (seed 002 slide 9; MASTER: docs/protocol.md 1.2)."""

    APPLY_JOINT = 0
    APPLY_CONTROL = 1
    READ_SENSORS = 2
    MASTER = 3


# OpCode bits 1-0, per operation (seed 002 slide 9).
PARAM_POSITION = 0      # APPLY_JOINT / READ_SENSORS
PARAM_VELOCITY = 1
PARAM_CURRENT = 2       # READ_SENSORS only (APPLY_JOINT param 10 is invalid)
PARAM_SPECIAL = 3
PARAM_KI = 0            # APPLY_CONTROL
PARAM_KP = 1
PARAM_KD = 2
PARAM_CONTROLON = 3
PARAM_TEST = 0          # MASTER
PARAM_CANSTATUS = 1
PARAM_SUPERVISOR = 2    # MASTER param 0b10: the mode supervisor (docs/supervisor.md; beyond the seeds)

# MASTER / PARAM_SUPERVISOR request, D1 (docs/supervisor.md "Serial bytes"):
SUPERVISOR_READ = 0     # -> FD MODE FAULTCODE NODE NFAULTS BCC
SUPERVISOR_ESTOP = 1    # -> FB echo; PWM off on every board within one CAN round
SUPERVISOR_RESET = 2    # -> FB echo; a new self-check
# The read answer's MODE and FAULTCODE bytes (docs/supervisor.md): wire number -> name.
SUPERVISOR_MODES: dict[int, str] = {0: "standby", 1: "self_check", 2: "ready", 3: "safe", 4: "estop"}
SUPERVISOR_FAULTS: dict[int, str] = {1: "silent", 2: "bus_off", 3: "slave_can", 4: "over_travel",
                                     5: "deadline", 6: "balance", 7: "host_link", 8: "law"}


def supervisor_mode_name(mode: int) -> str:
    """A MODE byte's name (``"ready"``, ``"safe"`` ...); ``"mode N"`` for a number not in
    :data:`SUPERVISOR_MODES`."""
    return SUPERVISOR_MODES.get(mode, f"mode {mode}")


def supervisor_fault_name(fault: int | None) -> str | None:
    """A FAULTCODE byte's name (``"silent"``, ``"bus_off"`` ...); None for 0 (no fault) or
    None; ``"fault N"`` for a number not in :data:`SUPERVISOR_FAULTS`."""
    return SUPERVISOR_FAULTS.get(fault, f"fault {fault}") if fault else None


TEST_MESSAGE = bytes([0xFA, 0xF9, 0xF8, 0xF7, 0xF6, 0xF5])  # usartSendTestMsg (seed 000 table 3)

_MAX_CONTROL_TYPE = int(max(ControlType))   # seed 000 table 9: 0..3


class FrameError(ValueError):
    """A 6-byte RS-232 frame that cannot be decoded: wrong length, first byte or BCC."""


def hexdump(data: bytes | bytearray | memoryview) -> str:
    """``b'\\xff\\x08'`` -> ``'FF 08'`` (for error messages and logs)."""
    return bytes(data).hex(" ").upper()


def bcc(data: bytes | bytearray | memoryview) -> int:
    """Block check character: the XOR of all bytes of ``data`` (seed 002 slide 7, "EXOR")."""
    x = 0
    for b in data:
        x ^= b
    return x


def _byte(name: str, value: int) -> int:
    return int_in_range(name, value, 0, 255, "a byte")


def _frame(b0: int, b1: int, b2: int, b3: int, b4: int) -> bytes:
    """The 6-byte frame ``b0 b1 b2 b3 b4 BCC`` (bytes already checked)."""
    return bytes((b0, b1, b2, b3, b4, b0 ^ b1 ^ b2 ^ b3 ^ b4))


# OpCode layout (seed 002 slide 9): bits 7-6 operation, 5-2 SCU address, 1-0 parameter.
_OP_SHIFT = 6
_SCU_SHIFT = 2
_SCU_MASK = 0x0F
_PARAM_MASK = 0x03


def _join_opcode(op: int, scu: int, param: int) -> int:
    return (op << _OP_SHIFT) | (scu << _SCU_SHIFT) | param


def _split_opcode(opcode: int) -> tuple[int, int, int]:
    return opcode >> _OP_SHIFT, (opcode >> _SCU_SHIFT) & _SCU_MASK, opcode & _PARAM_MASK


def make_opcode(op: int, scu: int, param: int) -> int:
    """OpCode byte: bits 7-6 operation, 5-2 SCU address, 1-0 parameter (seed 002 slide 9).

    Raises ``ValueError`` when a field does not fit its bits (op 0..3, scu 0..15, param 0..3);
    whether the combination is meaningful is :func:`is_valid_request`'s business.
    """
    op = int_in_range("operation", op, 0, 3, "2 bits")
    scu = int_in_range("SCU address", scu, 0, 15, "4 bits")
    param = int_in_range("parameter", param, 0, 3, "2 bits")
    return _join_opcode(op, scu, param)


def parse_opcode(opcode: int) -> tuple[int, int, int]:
    """OpCode byte -> ``(op, scu, param)``."""
    return _split_opcode(_byte("OpCode", opcode))


def encode_request(op: int, scu: int, param: int, d1: int = 0, d2: int = 0, d3: int = 0) -> bytes:
    """Request frame ``FF OP D1 D2 D3 BCC`` (seed 002 slides 8-9). ``d1..d3`` are bytes 0..255:
    signed positions go through :func:`s8` first."""
    opcode = make_opcode(op, scu, param)
    d1 = _byte("D1", d1)
    d2 = _byte("D2", d2)
    d3 = _byte("D3", d3)
    return _frame(SOF, opcode, d1, d2, d3)


def _check_frame(frame: bytes | bytearray | memoryview) -> bytes:
    if not isinstance(frame, bytes):
        frame = bytes(frame)
    if len(frame) != FRAME_LEN:
        raise FrameError(f"RS-232 frame must be {FRAME_LEN} bytes, got {len(frame)}: [{hexdump(frame)}]")
    return frame


def _check_bcc(frame: bytes) -> None:
    x = bcc(frame[:5])
    if x != frame[5]:
        raise FrameError(f"bad BCC: expected 0x{x:02X}, got 0x{frame[5]:02X}: [{hexdump(frame)}]")


@dataclass(frozen=True, slots=True)
class Request:
    """A host -> Master request (seed 002 slides 8-9). ``data`` are the raw bytes D1 D2 D3."""

    op: int
    scu: int
    param: int
    data: tuple[int, int, int] = (0, 0, 0)

    def __post_init__(self) -> None:
        # Field ranges (the combination is is_valid_request's business); stored as plain ints.
        setattr_ = object.__setattr__
        setattr_(self, "op", int_in_range("operation", self.op, 0, 3, "2 bits"))
        setattr_(self, "scu", int_in_range("SCU address", self.scu, 0, 15, "4 bits"))
        setattr_(self, "param", int_in_range("parameter", self.param, 0, 3, "2 bits"))
        try:
            d1, d2, d3 = self.data
        except (TypeError, ValueError):
            raise ValueError(f"Request data must be 3 bytes, got {self.data!r}") from None
        setattr_(self, "data", (_byte("D1", d1), _byte("D2", d2), _byte("D3", d3)))

    @property
    def opcode(self) -> int:
        """The OpCode byte."""
        return _join_opcode(self.op, self.scu, self.param)

    def encode(self) -> bytes:
        """The 6-byte frame ``FF OP D1 D2 D3 BCC``."""
        return encode_request(self.op, self.scu, self.param, *self.data)

    @classmethod
    def decode(cls, frame: bytes | bytearray | memoryview) -> Request:
        """Parse a request frame; :class:`FrameError` on a bad length, SOF or BCC."""
        frame = _check_frame(frame)
        if frame[0] != SOF:
            raise FrameError(f"request must start with SOF 0xFF, got 0x{frame[0]:02X}: [{hexdump(frame)}]")
        _check_bcc(frame)
        return cls(*_split_opcode(frame[1]), (frame[2], frame[3], frame[4]))


def status_response(request: bytes | bytearray | memoryview, status: int) -> bytes:
    """``usartSendStatus`` (seed 000 table 3): the request echoed with its first byte replaced by
    ``status`` (:data:`MESSAGE_SUCCESS` or :data:`MESSAGE_INVREQ`) and the BCC recomputed."""
    if status not in (MESSAGE_SUCCESS, MESSAGE_INVREQ):
        raise ValueError(f"status must be MESSAGE_SUCCESS (0xFB) or MESSAGE_INVREQ (0xFC), got {status!r}")
    request = _check_frame(request)
    if request[0] != SOF:
        raise FrameError(f"can only echo a request (first byte 0xFF), got [{hexdump(request)}]")
    return _frame(status, request[1], request[2], request[3], request[4])


def data_response(v1: int, v2: int, v3: int, v4: int) -> bytes:
    """``FD V1 V2 V3 V4 BCC`` (seed 002 slide 8): READ answers and the CAN status answer.
    Values are bytes 0..255 (signed values through :func:`s8`)."""
    v1 = _byte("V1", v1)
    v2 = _byte("V2", v2)
    v3 = _byte("V3", v3)
    v4 = _byte("V4", v4)
    return _frame(MESSAGE_DATA, v1, v2, v3, v4)


_KIND = {MESSAGE_SUCCESS: "success", MESSAGE_INVREQ: "invreq", MESSAGE_DATA: "data"}


@dataclass(frozen=True, slots=True)
class Response:
    """A decoded Master -> host response.

    ``kind``: ``"success"`` / ``"invreq"`` (``values`` = the echoed OP D1 D2 D3), ``"data"``
    (``values`` = V1..V4) or ``"test"`` (``values`` = F9 F8 F7 F6). ``raw`` = the 6 bytes.
    """

    kind: str
    raw: bytes
    values: tuple[int, int, int, int]

    def echoes(self, request: bytes | bytearray | memoryview) -> bool:
        """True if this is a success/invreq answer echoing ``request`` (bytes 2-5 equal)."""
        return self.kind in ("success", "invreq") and bytes(request[1:5]) == self.raw[1:5]


def decode_response(frame: bytes | bytearray | memoryview) -> Response:
    """Parse a Master -> host frame; :class:`FrameError` on a bad length, first byte or BCC."""
    frame = _check_frame(frame)
    first = frame[0]
    if first == MESSAGE_TEST:
        if frame != TEST_MESSAGE:
            raise FrameError(
                f"corrupt test message: expected [{hexdump(TEST_MESSAGE)}], got [{hexdump(frame)}]"
            )
        return Response("test", frame, (frame[1], frame[2], frame[3], frame[4]))
    kind = _KIND.get(first)
    if kind is None:
        raise FrameError(
            f"unknown response first byte 0x{first:02X} (expected FA/FB/FC/FD): [{hexdump(frame)}]"
        )
    _check_bcc(frame)
    return Response(kind, frame, (frame[1], frame[2], frame[3], frame[4]))


def invalid_reason(req: Request) -> str | None:
    """The Master's request validation (``usartProcessMsg``), one place for it.

    ``None`` if the Master accepts ``req``, else a readable reason it answers ``FC`` (INVREQ).
    The table is in docs/protocol.md ("Validation").
    """
    op, scu, param = req.op, req.scu, req.param
    d1, d2, d3 = req.data
    if op == Op.MASTER:
        if scu != MASTER_ADDRESS:
            return f"MASTER operation needs SCU 0, got SCU {scu}"
        if param > PARAM_SUPERVISOR:
            return f"MASTER parameter {param} is invalid (0 test, 1 CAN status, 2 supervisor)"
        if param == PARAM_SUPERVISOR and d1 > SUPERVISOR_RESET:
            return f"supervisor D1 must be 0 read, 1 emergency stop or 2 reset, got {d1}"
        return None
    reason = scu_error(scu)
    if reason is not None:
        return reason
    if op == Op.APPLY_JOINT:
        if param == PARAM_POSITION:
            for i, d in enumerate(req.data):
                deg = from_s8(d)
                if not -POS_LIMIT_DEG <= deg <= POS_LIMIT_DEG:
                    return f"position D{i + 1} = {deg} deg out of -{POS_LIMIT_DEG}..{POS_LIMIT_DEG}"
            return None
        if param == PARAM_VELOCITY:
            return None
        if param == PARAM_SPECIAL:
            if d1 > 1:
                return f"SPECIAL D1 (PWM) must be 0 or 1, got {d1}"
            if d2 > 1:
                return f"SPECIAL D2 (calibration request) must be 0 or 1, got {d2}"
            if d3 != 0:
                return f"SPECIAL D3 must be 0, got {d3}"
            return None
        return "APPLY_JOINT parameter 2 (0b10) is invalid"
    if op == Op.APPLY_CONTROL:
        if param == PARAM_CONTROLON:
            for i, d in enumerate(req.data):
                if d > _MAX_CONTROL_TYPE:
                    return f"CONTROLON D{i + 1} = {d}: control type must be 0..{_MAX_CONTROL_TYPE}"
        return None
    return None  # READ_SENSORS: any parameter, data bytes ignored


def is_valid_request(req: Request) -> bool:
    """True if the Master accepts ``req`` (see :func:`invalid_reason` for why not)."""
    return invalid_reason(req) is None
