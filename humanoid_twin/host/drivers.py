"""Device drivers of the main unit (PC): the MATLAB toolbox of seed 000 section 4.1, in Python.

Table 20 of seed 000, one function each, with the manual's outputs as a NamedTuple:

============  =========================================================  ==================
MATLAB        Python                                                     returns
============  =========================================================  ==================
initcom       ``initcom(port, rate=115200)``                             ``(H, state)``
killcom       ``killcom(H)``                                             ``1`` ok / ``0``
calibcom      ``calibcom(H)``                                            :class:`CalibResult`
readcanstat   ``readcanstat(H)``                                         :class:`CanStatResult`
readjoint     ``readjoint(H, scu_id, param)``                            :class:`ReadJointResult`
readspecial   ``readspecial(H, scu_id)``                                 :class:`ReadSpecialResult`
applyjoint    ``applyjoint(H, scu_id, param, servos)``                   :class:`ApplyResult`
applycontrol  ``applycontrol(H, scu_id, param, servos)``                 :class:`ApplyResult`
============  =========================================================  ==================

``H`` is any pyserial port object (``initcom`` opens one from any pyserial URL or device name:
a real port, a pty ``/dev/pts/N``, ``socket://127.0.0.1:PORT`` or the in-process twin
``twin://NAME``). The drivers only ``write``, ``read``, ``reset_input_buffer`` and
``reset_output_buffer``: nothing assumes the in-process port.

Every driver follows figs. 18-20 of seed 000: build the 6-byte request (with
:func:`humanoid_twin.protocol.rs232.encode_request`), write it, read 6 bytes with the port's
timeout; on a timeout, a bad BCC, an unexpected first byte or a wrong echo, reset both buffers and
send again, up to ``max_tries`` times (default 3). ``tries`` counts the attempts made. An ``FC``
answer (invalid request) is a valid answer: it is not retried. Error codes: :class:`ErrorCode`.

Arguments that cannot be put in the frame (a position that is not a whole number of degrees or
outside int8, a byte outside 0..255, an SCU address over 15) raise ``ValueError`` before anything
is sent. Whether a request that fits the frame makes sense (SCU 1..8, positions -90..90, param 2 of
APPLY_JOINT) is the Master's decision: it answers ``FC`` and the driver reports
``ErrorCode.INVALID_REQUEST``.

:class:`HumanoidClient` wraps the drivers in a pythonic class that raises :class:`CommError`
subclasses instead of returning error codes.
"""

from __future__ import annotations

import math
import operator
import sys
import termios
from collections.abc import Sequence
from enum import IntEnum
from typing import TYPE_CHECKING, Any, NamedTuple

import serial

from humanoid_twin.host.timebase import port_of as _port
from humanoid_twin.protocol.rs232 import (
    MESSAGE_DATA,
    MESSAGE_INVREQ,
    MESSAGE_SUCCESS,
    MESSAGE_TEST,
    PARAM_CANSTATUS,
    PARAM_CONTROLON,
    PARAM_CURRENT,
    PARAM_KD,
    PARAM_KI,
    PARAM_KP,
    PARAM_POSITION,
    PARAM_SPECIAL,
    PARAM_SUPERVISOR,
    PARAM_TEST,
    PARAM_VELOCITY,
    SUPERVISOR_ESTOP,
    SUPERVISOR_READ,
    SUPERVISOR_RESET,
    TEST_MESSAGE,
    FrameError,
    Op,
    decode_response,
    encode_request,
    from_s8,
    hexdump,
    parse_opcode,
    s8,
    supervisor_fault_name,
    supervisor_mode_name,
)
from humanoid_twin.protocol.wire import (
    BAUDRATE,
    LINE_SETTINGS,
    STATUS_ALL_FINISHED,
    STATUS_CALIB,
    STATUS_DEADLINE,
    STATUS_ONE_FINISHED,
    STATUS_PWM,
    ControlType,
    ErrorState,
    int_in_range,
)

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort, SerialPort

__all__ = [
    "DEFAULT_RATE",
    "DEFAULT_TIMEOUT_S",
    "DEFAULT_MAX_TRIES",
    "ErrorCode",
    "ERROR_TEXT",
    "CommError",
    "Timeout",
    "InvalidRequest",
    "BadFrame",
    "PortError",
    "ApplyResult",
    "CalibResult",
    "CanStatResult",
    "ReadJointResult",
    "ReadSpecialResult",
    "gate_to_port",
    "initcom",
    "killcom",
    "calibcom",
    "readcanstat",
    "readjoint",
    "readspecial",
    "applyjoint",
    "applycontrol",
    "raise_for_error",
    "SupervisorRefused",
    "SupervisorResult",
    "readsupervisor",
    "estop",
    "reset",
    "Supervisor",
    "HumanoidClient",
    "CanStatus",
    "STATUS_PWM",
    "STATUS_CALIB",
    "STATUS_DEADLINE",
    "STATUS_ALL_FINISHED",
    "STATUS_ONE_FINISHED",
]

DEFAULT_RATE = BAUDRATE
# Read timeout per attempt. A request is answered in 1.17 ms at 115200 baud (docs/master.md);
# 0.1 s leaves room for a pty or a TCP bridge paced in real time.
DEFAULT_TIMEOUT_S = 0.1
DEFAULT_MAX_TRIES = 3

# Status byte (READ answers' 4th value): STATUS_* of protocol/wire.py, re-exported here.


class ErrorCode(IntEnum):
    """The drivers' ``error`` output (the manual names the output, not its values: settled here)."""

    OK = 0
    INVALID_REQUEST = 1       # the Master answered FC (MESSAGE_INVREQ)
    TIMEOUT = 2               # fewer than 6 bytes arrived within the port's timeout
    BAD_BCC = 3               # 6 bytes with the expected first byte, but the BCC does not match
    UNEXPECTED_RESPONSE = 4   # first byte not one this request can get (or a corrupt test message)
    ECHO_MISMATCH = 5         # FB/FC that does not echo the request's OP D1 D2 D3
    PORT_ERROR = 6            # the serial port raised (closed, unplugged, write timeout)


ERROR_TEXT: dict[ErrorCode, str] = {
    ErrorCode.OK: "ok",
    ErrorCode.INVALID_REQUEST: "invalid request (Master answered FC)",
    ErrorCode.TIMEOUT: "timeout (no complete 6-byte answer)",
    ErrorCode.BAD_BCC: "bad BCC in the answer",
    ErrorCode.UNEXPECTED_RESPONSE: "unexpected answer (wrong first byte)",
    ErrorCode.ECHO_MISMATCH: "answer does not echo the request",
    ErrorCode.PORT_ERROR: "serial port error",
}


# ------------------------------------------------------------------------------------------
# exceptions (HumanoidClient and the high-level routines)


class CommError(Exception):
    """A request that failed after all its tries. ``code``, ``rx`` (last bytes) and ``tries``."""

    def __init__(self, message: str, code: int = ErrorCode.PORT_ERROR, rx: bytes = b"", tries: int = 0):
        super().__init__(message)
        self.code = ErrorCode(code)
        self.rx = rx
        self.tries = tries


class Timeout(CommError):  # noqa: N818  (the names of the task's API)
    """No complete answer within the timeout, on every try."""


class InvalidRequest(CommError):  # noqa: N818  (the names of the task's API)
    """The Master answered FC: it refused the request (SCU, parameter or value out of range)."""


class BadFrame(CommError):  # noqa: N818  (the names of the task's API)
    """Answers arrived but were corrupt or not the expected ones (bad BCC, first byte, echo)."""


class SupervisorRefused(InvalidRequest):  # noqa: N818  (the names of the task's API)
    """The Master refused an APPLY because its supervisor is in ``safe`` or ``estop``
    (docs/supervisor.md). ``mode``, ``fault``, ``node`` name why (wire numbers)."""

    def __init__(self, message: str, code: int, rx: bytes, tries: int, mode: int, fault: int, node: int):
        super().__init__(message, code, rx, tries)
        self.mode = mode
        self.fault = fault
        self.node = node

    @property
    def mode_name(self) -> str:
        """``safe`` or ``estop``."""
        return supervisor_mode_name(self.mode)

    @property
    def fault_name(self) -> str | None:
        """The latched fault's name (``silent``, ``bus_off`` ...), None without one."""
        return supervisor_fault_name(self.fault)


class PortError(CommError):
    """The serial port itself failed (could not be opened, closed, unplugged)."""


_EXC: dict[ErrorCode, type[CommError]] = {
    ErrorCode.INVALID_REQUEST: InvalidRequest,
    ErrorCode.TIMEOUT: Timeout,
    ErrorCode.BAD_BCC: BadFrame,
    ErrorCode.UNEXPECTED_RESPONSE: BadFrame,
    ErrorCode.ECHO_MISMATCH: BadFrame,
    ErrorCode.PORT_ERROR: PortError,
}


# ------------------------------------------------------------------------------------------
# results: the MATLAB output lists of seed 000 section 4.1


class ApplyResult(NamedTuple):
    """``[rx, error, errorstr, tries] = applyjoint(...)`` / ``applycontrol(...)``."""

    rx: bytes
    error: int
    errorstr: str
    tries: int


class CalibResult(NamedTuple):
    """``calibcom(H)``: what arrived, whether it is the test message FA F9 F8 F7 F6 F5."""

    rx: bytes
    ok: bool
    error: int
    errorstr: str
    tries: int


class CanStatResult(NamedTuple):
    """``[array, state, rx, error, errorstr, tries] = readcanstat(H)``.

    ``array`` = (error state 0 active / 1 passive / 2 bus-off, TEC, REC); ``state`` = the bitmask
    of slaves that answered the last CAN round (bit k-1 = slave k). ``None`` on error.
    """

    array: tuple[int, int, int] | None
    state: int | None
    rx: bytes
    error: int
    errorstr: str
    tries: int


class ReadJointResult(NamedTuple):
    """``[servos, state, rx, error, errorstr, tries] = readjoint(H, scu_id, param)``.

    ``servos``: positions in signed degrees, mean velocities in signed degrees per 20 ms tick, or
    currents 0..100; ``state``: the slave's status byte (``STATUS_*`` bits). ``None`` on error.
    """

    servos: tuple[int, int, int] | None
    state: int | None
    rx: bytes
    error: int
    errorstr: str
    tries: int


class SupervisorResult(NamedTuple):
    """``[mode, fault, node, nfaults, rx, error, errorstr, tries] = readsupervisor(H)``.

    ``mode``: 0 standby, 1 self_check, 2 ready, 3 safe, 4 estop; ``fault``: the first latched
    fault's code (0 none; 1 silent .. 7 host_link), ``node`` its board (0 Master, 1-8 Slaves),
    ``nfaults`` how many are latched. ``None`` on error. docs/supervisor.md.
    """

    mode: int | None
    fault: int | None
    node: int | None
    nfaults: int | None
    rx: bytes
    error: int
    errorstr: str
    tries: int

    @property
    def mode_name(self) -> str | None:
        """The mode's name, None on error."""
        return None if self.mode is None else supervisor_mode_name(self.mode)

    @property
    def fault_name(self) -> str | None:
        """The latched fault's name, None when there is none (or on error)."""
        return supervisor_fault_name(self.fault)


class ReadSpecialResult(NamedTuple):
    """``[special, rx, error, errorstr, tries] = readspecial(H, scu_id)``: 4 force readings 0..255
    (table 12 order; 128 = the calibration load). ``None`` on error."""

    special: tuple[int, int, int, int] | None
    rx: bytes
    error: int
    errorstr: str
    tries: int


# ------------------------------------------------------------------------------------------
# opening and closing (initcom / killcom)


def gate_to_port(gate: int, platform: str | None = None) -> str:
    """The MATLAB ``gate`` number (1, 2, ...) as a platform port name: ``COMn`` on Windows,
    ``/dev/ttyS{n-1}`` elsewhere (COM1 is ``/dev/ttyS0`` on Linux)."""
    n = int_in_range("gate", gate, 1, None, "a port number 1, 2, ...")
    platform = sys.platform if platform is None else platform
    return f"COM{n}" if platform.startswith("win") else f"/dev/ttyS{n - 1}"


def initcom(
    port: str | int, rate: int = DEFAULT_RATE, *, timeout: float = DEFAULT_TIMEOUT_S
) -> tuple[Any, dict[str, Any]]:
    """``[H, state] = initcom(gate, rate)``: open the RS-232 line to the Master, 8E1.

    ``port``: any pyserial URL or device (``/dev/ttyUSB0``, ``/dev/pts/3``,
    ``socket://127.0.0.1:5000``, ``twin://NAME``) or the MATLAB gate number (see
    :func:`gate_to_port`). ``timeout``: read timeout of each try, seconds (virtual seconds for a
    ``twin://`` port). Returns the open port ``H`` and the line settings ``state``.
    Raises :class:`PortError` if the port cannot be opened.
    """
    if isinstance(port, str):
        url = port
    else:
        url = gate_to_port(port)
    if not url:
        raise ValueError("port must be a non-empty pyserial URL or device name")
    rate = int_in_range("rate", rate, 1, None, "a baud rate")
    if not (isinstance(timeout, int | float) and timeout > 0 and math.isfinite(timeout)):
        raise ValueError(f"timeout must be a positive number of seconds, got {timeout!r}")
    if url.startswith("twin://"):
        import humanoid_twin.bus  # noqa: F401  (registers the twin:// URL handler with pyserial)
    try:
        H = serial.serial_for_url(
            url,
            **{**LINE_SETTINGS, "baudrate": rate},
            timeout=timeout,
            write_timeout=max(1.0, timeout),
        )
    except (serial.SerialException, OSError, ValueError, termios.error) as exc:
        # termios.error: the device refused the 8E1 settings (a Linux pty opened again at the
        # same speed refuses PARENB with EINVAL; docs/serve.md)
        raise PortError(f"initcom: cannot open {url!r} at {rate} 8E1: {exc}") from exc
    state = {
        "port": url,
        "baudrate": H.baudrate,
        "bytesize": H.bytesize,
        "parity": H.parity,
        "stopbits": H.stopbits,
        "timeout": H.timeout,
    }
    return H, state


def killcom(H: HostPort) -> int:
    """``stat = killcom(H)``: close the line; 1 on success (also if it was closed), 0 on failure."""
    try:
        _port(H).close()
    except (serial.SerialException, OSError):
        return 0
    return 1


# ------------------------------------------------------------------------------------------
# the exchange of figs. 18-20


def _tries(max_tries: int) -> int:
    return int_in_range("max_tries", max_tries, 1, None, "tries")


def _reset(port: SerialPort) -> None:
    """Fig. 19/20: re-initialise the communications (drop whatever is in both buffers)."""
    try:
        port.reset_input_buffer()
        port.reset_output_buffer()
    except (serial.SerialException, OSError, AttributeError):
        pass


# What each kind of request may get back (first byte).
_EXPECT_STATUS = (MESSAGE_SUCCESS, MESSAGE_INVREQ)
_EXPECT_DATA = (MESSAGE_DATA, MESSAGE_INVREQ)
_EXPECT_TEST = (MESSAGE_TEST, MESSAGE_INVREQ)


def _check(frame: bytes, rx: bytes, expect: tuple[int, ...]) -> tuple[ErrorCode, str]:
    """Classify one answer ``rx`` to request ``frame``."""
    if len(rx) < 6:
        return ErrorCode.TIMEOUT, f"{len(rx)} of 6 bytes received [{hexdump(rx)}]"
    first = rx[0]
    if first not in expect:
        return ErrorCode.UNEXPECTED_RESPONSE, (
            f"first byte 0x{first:02X}, expected {'/'.join(f'{e:02X}' for e in expect)} [{hexdump(rx)}]"
        )
    try:
        resp = decode_response(rx)
    except FrameError as exc:
        code = ErrorCode.UNEXPECTED_RESPONSE if first == MESSAGE_TEST else ErrorCode.BAD_BCC
        return code, str(exc)
    if resp.kind in ("success", "invreq") and not resp.echoes(frame):
        return ErrorCode.ECHO_MISMATCH, f"sent [{hexdump(frame)}], got [{hexdump(rx)}]"
    if resp.kind == "invreq":
        return ErrorCode.INVALID_REQUEST, f"request [{hexdump(frame)}] refused [{hexdump(rx)}]"
    return ErrorCode.OK, ""


def _exchange(H: HostPort, frame: bytes, expect: tuple[int, ...],
              max_tries: int) -> tuple[bytes, int, str, int]:
    """Write ``frame``, read 6 bytes, retry as figs. 18-20. Returns ``(rx, error, errorstr, tries)``."""
    port = _port(H)
    n = _tries(max_tries)
    rx = b""
    code, detail = ErrorCode.TIMEOUT, ""
    tries = 0
    try:
        if port.in_waiting:   # stale bytes (a late answer to an earlier request): not ours
            port.reset_input_buffer()
    except (serial.SerialException, OSError, AttributeError):
        pass
    while tries < n:
        tries += 1
        try:
            port.write(frame)
            rx = bytes(port.read(6))
        except (serial.SerialException, OSError, ValueError) as exc:
            # pyserial raises SerialException (or PortNotOpenError, a subclass) or ValueError
            # ("Attempting to use a port that is not open") depending on the port class.
            rx = b""
            code, detail = ErrorCode.PORT_ERROR, f"{type(exc).__name__}: {exc}"
        else:
            code, detail = _check(frame, rx, expect)
            if code in (ErrorCode.OK, ErrorCode.INVALID_REQUEST):
                break
        _reset(port)
    text = ERROR_TEXT[code] if not detail else f"{ERROR_TEXT[code]}: {detail}"
    if code != ErrorCode.OK and code != ErrorCode.INVALID_REQUEST:
        text += f" (after {tries} tries)"
    return rx, int(code), text, tries


# ------------------------------------------------------------------------------------------
# argument checks


def _whole(name: str, value: Any) -> int:
    """A whole number (int, numpy integer, or a float with no fractional part) as int."""
    try:
        return operator.index(value)
    except TypeError:
        pass
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a whole number, got {value!r}") from None
    if not math.isfinite(f) or f != int(f):
        raise ValueError(
            f"{name} must be a whole number (the wire carries integers; round first), got {value!r}"
        )
    return int(f)


def _three(what: str, servos: Any) -> list[Any]:
    try:
        vals = list(servos)
    except TypeError:
        raise ValueError(f"{what} must be 3 values [servo1, servo2, servo3], got {servos!r}") from None
    if len(vals) != 3:
        raise ValueError(f"{what} must be 3 values [servo1, servo2, servo3], got {len(vals)}: {servos!r}")
    return vals


def _position_bytes(servos: Any) -> tuple[int, int, int]:
    out = []
    for i, v in enumerate(_three("positions", servos)):
        name = f"position of servo {i + 1}"
        out.append(s8(int_in_range(name, _whole(name, v), -128, 127, "degrees, int8")))
    return out[0], out[1], out[2]


def _unsigned_bytes(what: str, servos: Any) -> tuple[int, int, int]:
    out = []
    for i, v in enumerate(_three(what, servos)):
        name = f"{what} of servo {i + 1}"
        out.append(int_in_range(name, _whole(name, v), 0, 255, "a byte"))
    return out[0], out[1], out[2]


def _scu(scu_id: Any) -> int:
    return int_in_range("scu_id", _whole("scu_id", scu_id), 0, 15, "the OpCode's 4 bits; slaves are 1..8")


def _param(param: Any, allowed: Sequence[int], what: str) -> int:
    p = _whole("param", param)
    if p not in allowed:
        raise ValueError(f"{what}: param must be one of {list(allowed)}, got {p}")
    return p


# ------------------------------------------------------------------------------------------
# the drivers (table 20)


def calibcom(H: HostPort, *, max_tries: int = DEFAULT_MAX_TRIES) -> CalibResult:
    """``calibcom(H)``: ask the Master for its test sequence (usartSendTestMsg).

    ``ok`` is True when ``rx`` is exactly FA F9 F8 F7 F6 F5.
    """
    frame = encode_request(Op.MASTER, 0, PARAM_TEST)
    rx, err, text, tries = _exchange(H, frame, _EXPECT_TEST, max_tries)
    return CalibResult(rx, rx == TEST_MESSAGE, err, text, tries)


def readcanstat(H: HostPort, *, max_tries: int = DEFAULT_MAX_TRIES) -> CanStatResult:
    """``[array, state, rx, error, errorstr, tries] = readcanstat(H)``: the CAN bus state.

    ``array`` = [error state, TEC, REC] of the Master's CAN controller (0 error-active,
    1 error-passive, 2 bus-off; reading it clears a bus-off, docs/master.md); ``state`` = bitmask of
    the slaves that answered the last round.
    """
    frame = encode_request(Op.MASTER, 0, PARAM_CANSTATUS)
    rx, err, text, tries = _exchange(H, frame, _EXPECT_DATA, max_tries)
    if err != ErrorCode.OK:
        return CanStatResult(None, None, rx, err, text, tries)
    return CanStatResult((rx[1], rx[2], rx[3]), rx[4], rx, err, text, tries)


def readjoint(H: HostPort, scu_id: int, param: int, *, max_tries: int = DEFAULT_MAX_TRIES) -> ReadJointResult:
    """``[servos, state, rx, error, errorstr, tries] = readjoint(H, scu_id, param)``.

    ``param``: 0 position (signed degrees), 1 mean velocity (signed degrees per 20 ms tick),
    2 current (0..100). The force sensors (param 3) are :func:`readspecial`.
    """
    p = _param(param, (PARAM_POSITION, PARAM_VELOCITY, PARAM_CURRENT),
               "readjoint (0 position, 1 velocity, 2 current; readspecial reads the force sensors)")
    frame = encode_request(Op.READ_SENSORS, _scu(scu_id), p)
    rx, err, text, tries = _exchange(H, frame, _EXPECT_DATA, max_tries)
    if err != ErrorCode.OK:
        return ReadJointResult(None, None, rx, err, text, tries)
    if p == PARAM_CURRENT:
        servos = (rx[1], rx[2], rx[3])
    else:
        servos = (from_s8(rx[1]), from_s8(rx[2]), from_s8(rx[3]))
    return ReadJointResult(servos, rx[4], rx, err, text, tries)


def readspecial(H: HostPort, scu_id: int, *, max_tries: int = DEFAULT_MAX_TRIES) -> ReadSpecialResult:
    """``[special, rx, error, errorstr, tries] = readspecial(H, scu_id)``: the 4 force sensors
    (front-left, front-right, rear-left, rear-right; 8-bit, 128 = the calibration load); on the
    body board (5) its inclinometer and gyroscope, 128 = zero (``hardware.imu_from_counts``)."""
    frame = encode_request(Op.READ_SENSORS, _scu(scu_id), PARAM_SPECIAL)
    rx, err, text, tries = _exchange(H, frame, _EXPECT_DATA, max_tries)
    if err != ErrorCode.OK:
        return ReadSpecialResult(None, rx, err, text, tries)
    return ReadSpecialResult((rx[1], rx[2], rx[3], rx[4]), rx, err, text, tries)


def applyjoint(
    H: HostPort, scu_id: int, param: int, servos: Sequence[int], *, max_tries: int = DEFAULT_MAX_TRIES
) -> ApplyResult:
    """``[rx, error, errorstr, tries] = applyjoint(H, scu_id, param, servos)``.

    ``param``: 0 position (``servos`` = signed whole degrees; the Master accepts -90..90),
    1 velocity (``servos`` = movement period in 20 ms ticks, 0..255; 0 = go at once),
    3 special (``servos`` = [PWM on 1/off 0, calibration request 1/0, 0]). Param 2 is invalid
    (the Master answers FC).
    """
    p = _param(param, (0, 1, 2, 3), "applyjoint")
    if p == PARAM_POSITION:
        data = _position_bytes(servos)
    elif p == PARAM_VELOCITY:
        data = _unsigned_bytes("period (ticks)", servos)
    else:
        data = _unsigned_bytes("value", servos)
    frame = encode_request(Op.APPLY_JOINT, _scu(scu_id), p, *data)
    return ApplyResult(*_exchange(H, frame, _EXPECT_STATUS, max_tries))


def applycontrol(
    H: HostPort, scu_id: int, param: int, servos: Sequence[int], *, max_tries: int = DEFAULT_MAX_TRIES
) -> ApplyResult:
    """``[rx, error, errorstr, tries] = applycontrol(H, scu_id, param, servos)``.

    ``param``: 0 KI, 1 KP, 2 KD (``servos`` = gain bytes 0..255, the slave's fixed point, see
    docs/firmware.md), 3 control type (``servos`` = 0 NO_CONTROL, 1 LOCOMOTION_CONTROL,
    2 REACTION_CONTROL, 3 BALANCE_CONTROL; seed 000 table 9).
    """
    p = _param(param, (PARAM_KI, PARAM_KP, PARAM_KD, PARAM_CONTROLON), "applycontrol")
    what = "control type" if p == PARAM_CONTROLON else "gain"
    data = _unsigned_bytes(what, servos)
    frame = encode_request(Op.APPLY_CONTROL, _scu(scu_id), p, *data)
    return ApplyResult(*_exchange(H, frame, _EXPECT_STATUS, max_tries))


def readsupervisor(H: HostPort, *, max_tries: int = DEFAULT_MAX_TRIES) -> SupervisorResult:
    """``[mode, fault, node, nfaults, rx, error, errorstr, tries] = readsupervisor(H)``: the
    Master's supervisor (``FF C2 00 00 00 BCC`` -> ``FD MODE FAULT NODE NFAULTS BCC``)."""
    frame = encode_request(Op.MASTER, 0, PARAM_SUPERVISOR, SUPERVISOR_READ)
    rx, err, text, tries = _exchange(H, frame, _EXPECT_DATA, max_tries)
    if err != ErrorCode.OK:
        return SupervisorResult(None, None, None, None, rx, err, text, tries)
    return SupervisorResult(rx[1], rx[2], rx[3], rx[4], rx, err, text, tries)


def estop(H: HostPort, *, max_tries: int = DEFAULT_MAX_TRIES) -> ApplyResult:
    """``[rx, error, errorstr, tries] = estop(H)``: emergency stop (``FF C2 01 00 00 BCC``, FB
    echo): PWM off on every board within one CAN round; only reads and reset accepted after."""
    frame = encode_request(Op.MASTER, 0, PARAM_SUPERVISOR, SUPERVISOR_ESTOP)
    return ApplyResult(*_exchange(H, frame, _EXPECT_STATUS, max_tries))


def reset(H: HostPort, *, max_tries: int = DEFAULT_MAX_TRIES) -> ApplyResult:
    """``[rx, error, errorstr, tries] = reset(H)``: clear the latched faults and run a new
    self-check (``FF C2 02 00 00 BCC``, FB echo); after an emergency stop, power on again."""
    frame = encode_request(Op.MASTER, 0, PARAM_SUPERVISOR, SUPERVISOR_RESET)
    return ApplyResult(*_exchange(H, frame, _EXPECT_STATUS, max_tries))


def raise_for_error(result: tuple[Any, ...], what: str = "request", H: HostPort | None = None) -> None:
    """Raise the :class:`CommError` subclass matching a driver result's ``error`` (no-op if 0).

    With the port ``H``, an APPLY answered FC is checked against the Master's supervisor: when
    it is in ``safe`` or ``estop`` the error is a :class:`SupervisorRefused` naming the mode and
    the fault."""
    err = result.error  # type: ignore[attr-defined]  # a driver's NamedTuple result
    if err == ErrorCode.OK:
        return
    code = ErrorCode(err)
    rx = result.rx  # type: ignore[attr-defined]  # as above
    opcode = parse_opcode(rx[1]) if len(rx) == 6 else (-1, -1, -1)
    is_apply = 0 <= opcode[0] <= Op.APPLY_CONTROL
    # a reset the supervisor refused (a board not answering: the latch holds, docs/supervisor.md)
    is_reset = opcode[0] == Op.MASTER and opcode[2] == PARAM_SUPERVISOR and rx[2] == SUPERVISOR_RESET
    if H is not None and code == ErrorCode.INVALID_REQUEST and (is_apply or is_reset):
        sup = readsupervisor(H)
        if sup.error == ErrorCode.OK and sup.mode_name in ("safe", "estop"):
            fault = f", latched fault {sup.fault_name} on node {sup.node}" if sup.fault else ""
            hint = ("a board does not answer: the latch holds until every board answers"
                    if is_reset else "readsupervisor; reset to recover")
            raise SupervisorRefused(
                f"{what}: refused by the Master's supervisor: mode {sup.mode_name}{fault} "
                f"({hint})", code, rx, result.tries,  # type: ignore[attr-defined]  # as above
                sup.mode, sup.fault or 0, sup.node or 0)  # type: ignore[arg-type]  # the state byte of an answered request
    raise _EXC[code](f"{what}: {result.errorstr}", code, result.rx, result.tries)  # type: ignore[attr-defined]  # as above


# ------------------------------------------------------------------------------------------
# pythonic client


class CanStatus(NamedTuple):
    """The Master's CAN controller state and the slaves that answered the last round."""

    error_state: int     # 0 error-active, 1 error-passive, 2 bus-off
    tec: int
    rec: int
    answered_mask: int   # bit k-1 = slave k answered both sensor packets

    @property
    def state_name(self) -> str:
        """``"error-active"``, ``"error-passive"`` or ``"bus-off"``."""
        try:
            return ErrorState(self.error_state).label
        except ValueError:
            return "unknown"


class Supervisor(NamedTuple):
    """The Master's supervisor as :meth:`HumanoidClient.supervisor` returns it."""

    mode: int
    fault: int
    node: int
    nfaults: int

    @property
    def mode_name(self) -> str:
        """``standby`` / ``self_check`` / ``ready`` / ``safe`` / ``estop``."""
        return supervisor_mode_name(self.mode)

    @property
    def fault_name(self) -> str | None:
        """The latched fault's name, None without one."""
        return supervisor_fault_name(self.fault)


class HumanoidClient:
    """The drivers as a class that raises on failure. A context manager::

        with HumanoidClient("twin://twin0") as robot:
            robot.test()
            robot.set_period(1, [50, 50, 50]); robot.set_positions(1, [0, 10, -20])
            pos, status = robot.read(1, "position")

    Every method raises :class:`Timeout`, :class:`InvalidRequest`, :class:`BadFrame` or
    :class:`PortError` (all :class:`CommError`) when the request failed after ``max_tries``.
    ``serial_port`` is the pyserial port; the high-level routines (``exe_traj`` ...) accept
    the client wherever they take ``H``. ``stats`` counts requests, retries and failures.
    """

    _READ_PARAMS = {"position": PARAM_POSITION, "velocity": PARAM_VELOCITY, "current": PARAM_CURRENT}

    def __init__(
        self,
        url: str | int | Any,
        rate: int = DEFAULT_RATE,
        *,
        timeout: float = DEFAULT_TIMEOUT_S,
        max_tries: int = DEFAULT_MAX_TRIES,
    ) -> None:
        self.max_tries = _tries(max_tries)
        if isinstance(url, str | int):
            self.serial_port, self.line = initcom(url, rate, timeout=timeout)
        else:   # an already open pyserial port
            self.serial_port = url
            self.line = {"port": getattr(url, "port", None), "baudrate": getattr(url, "baudrate", None)}
        self.stats = {"requests": 0, "retries": 0, "failures": 0}

    # -- plumbing -------------------------------------------------------------------------
    def _done(self, result: Any, what: str) -> Any:
        self.stats["requests"] += 1
        self.stats["retries"] += max(0, result.tries - 1)
        if result.error != ErrorCode.OK:
            self.stats["failures"] += 1
            raise_for_error(result, what, self.serial_port)
        return result

    def close(self) -> None:
        """Close the port (``killcom``)."""
        killcom(self.serial_port)

    @property
    def closed(self) -> bool:
        """True once the port is closed."""
        return not getattr(self.serial_port, "is_open", False)

    def __enter__(self) -> HumanoidClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"HumanoidClient({self.line.get('port')!r})"

    # -- requests -------------------------------------------------------------------------
    def test(self) -> bytes:
        """``calibcom``: the Master's test message (raises :class:`BadFrame` if it is not FA..F5)."""
        return self._done(calibcom(self.serial_port, max_tries=self.max_tries), "test message").rx

    def can_status(self) -> CanStatus:
        """``readcanstat``: error state, TEC, REC, answered-slaves mask."""
        r = self._done(readcanstat(self.serial_port, max_tries=self.max_tries), "readcanstat")
        return CanStatus(*r.array, r.state)  # type: ignore[call-arg]  # CanStatus is a NamedTuple of 4

    def read(self, scu: int, what: str = "position") -> tuple[tuple[int, int, int], int]:
        """``readjoint``: (``values``, ``status``) with ``what`` in position/velocity/current."""
        try:
            param = self._READ_PARAMS[what]
        except KeyError:
            raise ValueError(f"what must be one of {list(self._READ_PARAMS)}, got {what!r}") from None
        r = self._done(
            readjoint(self.serial_port, scu, param, max_tries=self.max_tries), f"read {what} SCU {scu}"
        )
        return r.servos, r.state

    def read_positions(self, scu: int) -> tuple[int, int, int]:
        """Servo positions of ``scu``, signed degrees."""
        return self.read(scu, "position")[0]

    def read_velocities(self, scu: int) -> tuple[int, int, int]:
        """Mean servo velocities of ``scu``, signed degrees per 20 ms tick."""
        return self.read(scu, "velocity")[0]

    def read_currents(self, scu: int) -> tuple[int, int, int]:
        """Servo currents of ``scu``, 0..100."""
        return self.read(scu, "current")[0]

    def read_status(self, scu: int) -> int:
        """The slave's status byte (``STATUS_*`` bits)."""
        return self.read(scu, "position")[1]

    def read_forces(self, scu: int) -> tuple[int, int, int, int]:
        """``readspecial``: the 4 force readings (128 = calibration load)."""
        r = self._done(readspecial(self.serial_port, scu, max_tries=self.max_tries), f"readspecial SCU {scu}")
        return r.special

    def set_positions(self, scu: int, degrees: Sequence[int]) -> None:
        """``applyjoint(.., 0, ..)``: reference positions, signed whole degrees (-90..90)."""
        self._done(applyjoint(self.serial_port, scu, PARAM_POSITION, degrees, max_tries=self.max_tries),
                   f"set positions SCU {scu}")

    def set_period(self, scu: int, ticks: Sequence[int]) -> None:
        """``applyjoint(.., 1, ..)``: movement period of the next motion, 20 ms ticks (0 = at once)."""
        self._done(applyjoint(self.serial_port, scu, PARAM_VELOCITY, ticks, max_tries=self.max_tries),
                   f"set period SCU {scu}")

    def set_pwm(self, scu: int, on: bool, calibrate: bool = False) -> None:
        """``applyjoint(.., 3, ..)``: PWM on/off, and optionally request a new calibration."""
        self._done(applyjoint(self.serial_port, scu, PARAM_SPECIAL, [int(bool(on)), int(bool(calibrate)), 0],
                              max_tries=self.max_tries), f"set PWM SCU {scu}")

    def set_gains(
        self,
        scu: int,
        ki: Sequence[int] | None = None,
        kp: Sequence[int] | None = None,
        kd: Sequence[int] | None = None,
    ) -> None:
        """``applycontrol`` KI / KP / KD (bytes, the slave's fixed point); ``None`` leaves one alone."""
        for param, gains, name in ((PARAM_KI, ki, "KI"), (PARAM_KP, kp, "KP"), (PARAM_KD, kd, "KD")):
            if gains is not None:
                self._done(applycontrol(self.serial_port, scu, param, gains, max_tries=self.max_tries),
                           f"set {name} SCU {scu}")

    def set_control(self, scu: int, types: Sequence[int | ControlType]) -> None:
        """``applycontrol(.., 3, ..)``: control type per servo (seed 000 table 9)."""
        data = [int(t) for t in _three("types", types)]
        self._done(applycontrol(self.serial_port, scu, PARAM_CONTROLON, data, max_tries=self.max_tries),
                   f"set control SCU {scu}")

    # -- supervisor (docs/supervisor.md) ---------------------------------------------------
    def supervisor(self) -> Supervisor:
        """``readsupervisor``: mode, latched fault, its node, number of latched faults."""
        r = self._done(readsupervisor(self.serial_port, max_tries=self.max_tries), "readsupervisor")
        return Supervisor(r.mode, r.fault, r.node, r.nfaults)

    def estop(self) -> None:
        """Emergency stop: PWM off on every board within one CAN round."""
        self._done(estop(self.serial_port, max_tries=self.max_tries), "estop")

    def reset(self) -> None:
        """Clear the latched faults and run a new self-check (then power on after an estop)."""
        self._done(reset(self.serial_port, max_tries=self.max_tries), "reset")
