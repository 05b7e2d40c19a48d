"""The facts both buses share, each written once: addresses, the position range, the control
types, the CAN error states, the bits of the control and status bytes, int8 bytes and the
RS-232 line settings.

Every other module (host toolbox, Master and Slave firmware, bridges, recorder) imports these
names instead of re-typing a number or a bit mask. The byte-level contracts are in
``docs/protocol.md``; the sources are named next to each fact.

Pure values and functions: no I/O, no time.
"""

from __future__ import annotations

import operator
from enum import IntEnum
from typing import Any

__all__ = [
    "MASTER_ADDRESS",
    "N_SCU",
    "SCUS",
    "check_scu",
    "scu_error",
    "NODES",
    "node_error",
    "node_name",
    "POS_LIMIT_DEG",
    "ControlType",
    "ErrorState",
    "CONTROL_PWM",
    "CONTROL_CALIB",
    "CONTROL_TYPE_BITS",
    "CONTROL_TYPE_MASK",
    "STATUS_PWM",
    "STATUS_CALIB",
    "STATUS_DEADLINE",
    "STATUS_ALL_FINISHED",
    "STATUS_ONE_FINISHED",
    "STATUS_FINISHED",
    "s8",
    "from_s8",
    "int_in_range",
    "BAUDRATE",
    "BYTESIZE",
    "PARITY",
    "STOPBITS",
    "BITS_PER_CHAR",
    "LINE_SETTINGS",
]

# --- addresses (seed 002 slide 19) ---------------------------------------------------------
MASTER_ADDRESS = 0                               # the Master board (CAN node and OpCode SCU 0)
N_SCU = 8                                        # Slaves (SCUs) 1..8
SCUS: tuple[int, ...] = tuple(range(1, N_SCU + 1))


NODES: tuple[int, ...] = (MASTER_ADDRESS, *SCUS)   # the CAN nodes: 0 the Master, 1..8 the Slaves


def _address_error(value: Any, what: str, lo: int) -> str | None:
    """``None`` if ``value`` is an int (not a bool) in ``lo``..:data:`N_SCU`, else the reason."""
    if type(value) is int and lo <= value <= N_SCU:
        return None
    if isinstance(value, bool):
        return f"{what} must be an integer {lo}..{N_SCU}, got {value!r}"
    try:
        v = operator.index(value)
    except TypeError:
        return f"{what} must be an integer {lo}..{N_SCU}, got {value!r}"
    if not lo <= v <= N_SCU:
        return f"{what} must be {lo}..{N_SCU}, got {v}"
    return None


def scu_error(scu: Any, what: str = "SCU address") -> str | None:
    """``None`` if ``scu`` is a Slave address 1..:data:`N_SCU` (an int, not a bool), else the
    reason in one readable line (the Master's ``usartProcessMsg`` range check, seed 000 table 3)."""
    return _address_error(scu, what, 1)


def check_scu(scu: Any, what: str = "SCU address", error: type[Exception] = ValueError) -> int:
    """``scu`` as a plain int 1..:data:`N_SCU`; ``error`` (default ``ValueError``) with a
    readable message otherwise. The one SCU range check of the host, Master and Slave code."""
    if type(scu) is int and 1 <= scu <= N_SCU:
        return scu
    reason = scu_error(scu, what)
    if reason is not None:
        raise error(reason)
    return operator.index(scu)


def node_error(node: Any, what: str = "CAN node") -> str | None:
    """``None`` if ``node`` is a CAN node address of :data:`NODES` (0 the Master, 1..:data:`N_SCU`
    the Slaves; an int, not a bool), else the reason in one readable line."""
    return _address_error(node, what, MASTER_ADDRESS)


def node_name(node: int) -> str:
    """The name a CAN node's controller has on the network: ``"master"`` for
    :data:`MASTER_ADDRESS`, ``"slave<N>"`` for Slave N."""
    return "master" if node == MASTER_ADDRESS else f"slave{node}"


# --- positions (seed 000 table 16 limitPosition; seed 002 slide 10) --------------------------
# A servo position is a whole number of degrees within -POS_LIMIT_DEG..POS_LIMIT_DEG: the range
# the Master accepts in APPLY_JOINT POSITION, the firmware's limitPosition, and the servos'
# 600..2400 us pulses (hardware.pulse_from_deg).
POS_LIMIT_DEG = 90


# --- control types (seed 000 table 9) --------------------------------------------------------
class ControlType(IntEnum):
    """Control type of a servo: the CONTROLON data bytes and the Control byte's 2-bit fields
    (seed 000 table 9)."""

    NO_CONTROL = 0
    LOCOMOTION_CONTROL = 1
    REACTION_CONTROL = 2
    BALANCE_CONTROL = 3

    @property
    def label(self) -> str:
        """The short name users type (``run --control``, ``--law``): ``"none"``,
        ``"locomotion"``, ``"reaction"`` or ``"balance"``."""
        return _CONTROL_LABELS[self]


_CONTROL_LABELS = {ControlType.NO_CONTROL: "none", ControlType.LOCOMOTION_CONTROL: "locomotion",
                   ControlType.REACTION_CONTROL: "reaction", ControlType.BALANCE_CONTROL: "balance"}


# --- CAN error states (seed 002 slides 25-27; the ERRSTATE byte of readcanstat) --------------
class ErrorState(IntEnum):
    """A CAN controller's error state: its code on the wire (the CAN status answer's ERRSTATE,
    SFlags bits 1-0) and its name (:attr:`label`, as python-can and the logs spell it)."""

    ERROR_ACTIVE = 0
    ERROR_PASSIVE = 1
    BUS_OFF = 2

    @property
    def label(self) -> str:
        """``"error-active"``, ``"error-passive"`` or ``"bus-off"``."""
        return _LABELS[self]

    @classmethod
    def from_label(cls, label: str) -> ErrorState:
        """The state named ``label`` (``"bus-off"`` -> :attr:`BUS_OFF`)."""
        return _BY_LABEL[label]


_LABELS = {ErrorState.ERROR_ACTIVE: "error-active", ErrorState.ERROR_PASSIVE: "error-passive",
           ErrorState.BUS_OFF: "bus-off"}
_BY_LABEL = {v: k for k, v in _LABELS.items()}


# --- Actuation 1 Control byte (seed 002 slide 20) --------------------------------------------
CONTROL_PWM = 0x80          # bit 7: PWM on
CONTROL_CALIB = 0x40        # bit 6: calibration requested
CONTROL_TYPE_BITS = 2       # bits 5-0: the control type of servo 3, 2, 1 (servo 1 in bits 1-0)
CONTROL_TYPE_MASK = 0x03

# --- Sensors 1 Status byte (seed 002 slide 20; the READ answers' 4th value) ------------------
STATUS_PWM = 0x80           # bit 7: PWM on
STATUS_CALIB = 0x40         # bit 6: calibration complete
STATUS_DEADLINE = 0x20      # bit 5: deadline violated
STATUS_ALL_FINISHED = 0x10  # bit 4: all motions finished
STATUS_ONE_FINISHED = 0x08  # bit 3: one motion finished
STATUS_FINISHED = (0x01, 0x02, 0x04)   # bits 0, 1, 2: the motion of servo 1, 2, 3 finished


# --- int8 on the wire (two's complement bytes: positions, velocities, KP) --------------------
def int_in_range(name: str, value: Any, lo: int, hi: int | None, what: str) -> int:
    """``value`` as a plain int in ``lo..hi`` (``hi`` None: ``>= lo``; numpy integers accepted,
    floats not), else a readable ``ValueError`` naming ``name`` and ``what`` it is: the codecs'
    field check and the host toolbox's count check (``gate``, ``rate``, ``max_tries`` ...)."""
    if type(value) is int:
        v = value
    else:
        try:
            v = operator.index(value)
        except TypeError:
            raise ValueError(f"{name} must be an integer {_span(lo, hi)} ({what}), got {value!r}") from None
    if v < lo or (hi is not None and v > hi):
        raise ValueError(f"{name} must be {_span(lo, hi)} ({what}), got {v}")
    return v


def _span(lo: int, hi: int | None) -> str:
    """``"lo..hi"``, or ``">= lo"`` when ``hi`` is None (the range in int_in_range's messages)."""
    return f"{lo}..{hi}" if hi is not None else f">= {lo}"


def s8(value: int) -> int:
    """int8 -> byte (two's complement), e.g. -1 -> 0xFF. ``ValueError`` outside -128..127."""
    return int_in_range("int8 value", value, -128, 127, "int8") & 0xFF


def from_s8(byte: int) -> int:
    """byte -> int8 (two's complement), e.g. 0xFF -> -1. ``ValueError`` outside 0..255."""
    byte = int_in_range("byte", byte, 0, 255, "a byte")
    return byte - 256 if byte & 0x80 else byte


# --- the RS-232 line (seed 002 slide 7: 115200 bit/s, 1 start, 8 data, even parity, 1 stop) ---
BAUDRATE = 115_200
BYTESIZE = 8
PARITY = "E"                # pyserial's PARITY_EVEN
STOPBITS = 1
BITS_PER_CHAR = 1 + BYTESIZE + 1 + STOPBITS       # 11 bit times per byte on the wire
# keyword arguments for ``serial.Serial`` / ``serial.serial_for_url`` (values equal pyserial's
# EIGHTBITS, PARITY_EVEN, STOPBITS_ONE)
LINE_SETTINGS: dict[str, Any] = {"baudrate": BAUDRATE, "bytesize": BYTESIZE, "parity": PARITY,
                                 "stopbits": STOPBITS}
