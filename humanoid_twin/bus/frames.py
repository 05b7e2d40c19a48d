"""Bit-exact length of a CAN 2.0A data frame (the time a frame occupies the wire).

A standard data frame on the wire (ISO 11898-1, seed 002 slides 15-16):

    SOF(1) ID(11) RTR(1) IDE(1) r0(1) DLC(4) DATA(8n) CRC(15)   <- bit-stuffed region
    CRC-delimiter(1) ACK-slot(1) ACK-delimiter(1) EOF(7)         <- fixed form
    IFS / intermission(3)                                        <- before the next SOF

The CRC-15 (generator x^15+x^14+x^10+x^8+x^7+x^4+x^3+1, i.e. 0x4599) is computed over the
un-stuffed bits SOF..DATA. Bit stuffing: after five consecutive bits of equal value the
transmitter inserts one bit of the opposite value; the stuff bit itself starts the next run.
Stuffing covers SOF through the last CRC bit (a run completed by the last CRC bit gets its
stuff bit before the CRC delimiter).

``frame_bits(id, data)`` = 47 + 8n + stuff bits (44 + 8n frame bits + 3 IFS bits): 111..135
for an 8-byte frame (the 0..24 stuff-bit bound is floor((34 + 8n - 1) / 4), Davis et al.
2007; Tindell's older 0..19 bound is exceeded by real frames, see tests/bus/test_bus_can.py).
"""

from __future__ import annotations

from functools import lru_cache

import can

from humanoid_twin.protocol.canframes import STD_ID_MAX

CRC15_POLY = 0x4599
# bits after the stuffed region: CRC delimiter, ACK slot, ACK delimiter, EOF(7), IFS(3)
TRAILER_BITS = 13
IFS_BITS = 3
EOF_BITS = 7
# recessive bits at the end of every frame (ACK delimiter + EOF + IFS): one "11 recessive bits"
# occurrence for bus-off recovery (seed 000 checkCan)
TRAILING_RECESSIVE_BITS = 11


def _crc15_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = 0
        for i in range(8):
            nxt = ((byte >> (7 - i)) & 1) ^ ((crc >> 14) & 1)
            crc = (crc << 1) & 0x7FFF
            if nxt:
                crc ^= CRC15_POLY
        table.append(crc)
    return tuple(table)


def _stuff_table() -> tuple[int, ...]:
    # Bit stuffing as an automaton read a byte at a time. Its state after a bit is the run that
    # bit ends: its value and its length 1..4 (a fifth equal bit gets a stuff bit of the other
    # value, which starts a run of length 1), state = value * 4 + length - 1, 0..7.
    # Entry [state << 8 | byte] = stuff bits inserted into those 8 bits (MSB first) << 3 | the
    # state after them. (The one statement of the stuffing rule; tests/bus/test_bus_can.py checks
    # the frame length against a bit-level reference written from the rule.)
    table = []
    for state in range(8):
        for byte in range(256):
            run_val = state >> 2
            run_len = (state & 3) + 1
            stuffed = 0
            for i in range(8):
                b = (byte >> (7 - i)) & 1
                if b == run_val:
                    run_len += 1
                else:
                    run_val = b
                    run_len = 1
                if run_len == 5:
                    stuffed += 1
                    run_val = 1 - b
                    run_len = 1
            table.append((stuffed << 3) | (run_val * 4 + run_len - 1))
    return tuple(table)


_CRC15_TABLE = _crc15_table()
_STUFF_TABLE = _stuff_table()


def _frame_bits(arbitration_id: int, data: bytes) -> int:
    """:func:`frame_bits` of a ``bytes`` payload, computed (no cache): the CRC a byte at a time
    from a table, the stuff bits a byte at a time from the stuffing automaton's table (the same
    length as a bit-level reference, tests/bus/test_bus_can.py); the compiled core calls it directly
    (a C function on C integers, cheaper than the cache's lookup)."""
    if not 0 <= arbitration_id <= STD_ID_MAX:
        raise ValueError(f"standard CAN ID must be 0..0x7FF, got {arbitration_id:#x}")
    n = len(data)
    if n > 8:
        raise ValueError(f"a CAN 2.0 data frame carries at most 8 bytes, got {n}")
    head = (arbitration_id << 7) | n          # ID(11) RTR IDE r0 DLC(4): the 18 bits after the SOF
    # The CRC, with initial value 0, ignores leading zero bits: it runs over 5 zero bits, the
    # SOF (0) and the 18 bits as 3 bytes. The stuffing runs over the same first byte with the
    # 5 leading bits 10101 instead: they insert no stuff bit and end on a run of 1s, so the SOF
    # starts a new run, as at the start of a frame.
    byte = head >> 16
    crc = _CRC15_TABLE[byte]
    e = _STUFF_TABLE[0xA8 | byte]             # from state 0 (a run of one 0)
    s = e & 7
    stuffed = e >> 3
    for i in range(n + 2):                    # the header's 2 other bytes, then the data
        byte = data[i - 2] if i >= 2 else (head >> (8 - 8 * i)) & 0xFF
        crc = ((crc << 8) & 0x7FFF) ^ _CRC15_TABLE[((crc >> 7) ^ byte) & 0xFF]
        e = _STUFF_TABLE[(s << 8) | byte]
        s = e & 7
        stuffed += e >> 3
    # the CRC's 15 bits: its top 8, then its low 7 and a padding bit of the other value than the
    # 7th (it cannot complete a run of 5: no stuff bit is counted for it)
    e = _STUFF_TABLE[(s << 8) | (crc >> 7)]
    s = e & 7
    stuffed += e >> 3
    e = _STUFF_TABLE[(s << 8) | ((crc << 1) & 0xFF) | ((crc & 1) ^ 1)]
    stuffed += e >> 3
    return 34 + 8 * n + stuffed + TRAILER_BITS   # SOF .. last CRC bit, stuff bits, trailer


# the interpreted source's fast path: the schedule repeats the same frames a lot (the compiled
# core's CanController.load_tx calls _frame_bits itself: bus/network.pxd)
_frame_bits_cached = lru_cache(maxsize=4096)(_frame_bits)


def frame_bits(arbitration_id: int, data: bytes) -> int:
    """Exact length in bits of a CAN 2.0A data frame incl. stuffing, EOF and the 3-bit IFS.

    Cached on ``(arbitration_id, bytes(data))``: the schedule repeats the same frames a lot.
    """
    if type(data) is not bytes:
        data = bytes(data)
    return _frame_bits_cached(arbitration_id, data)


def max_frame_bits(n_bytes: int) -> int:
    """Worst-case length of a standard data frame of ``n_bytes`` (Davis et al. 2007), incl. IFS."""
    return 47 + 8 * n_bytes + (34 + 8 * n_bytes - 1) // 4


# -- the frame record of the wire's per-frame path -------------------------------------------------
class Frame:
    """A standard data frame as the wire carries it between the twin's own nodes: the core's own
    record (a C struct in the compiled core), with python-can's attribute names, so a receive
    interrupt reads it as it would read a :class:`can.Message` (``arbitration_id``, ``dlc``,
    ``data``, ``timestamp``, ``channel``, ``is_rx``; ``is_extended_id``, ``is_remote_frame``,
    ``is_error_frame`` and ``is_fd`` are always False).

    ``data`` is ``bytes`` (0..8). :meth:`CanController.load_tx` builds (or reloads) one and
    measures it (``bits``: its length on the wire, :func:`frame_bits`; 0 for a frame built
    otherwise, not measured); the wire stamps it at the end of its EOF. A listener, a logger, a
    foreign python-can bus and a tool's bus on the same channel get a :class:`can.Message`
    instead (:meth:`to_message`), built only for them."""

    __slots__ = ("arbitration_id", "dlc", "data", "timestamp", "channel", "is_rx", "bits")

    is_extended_id = False
    is_remote_frame = False
    is_error_frame = False
    is_fd = False

    def __init__(self, arbitration_id: int, data: bytes = b"", timestamp: float = 0.0,
                 channel: object = None, is_rx: bool = False) -> None:
        self.arbitration_id = arbitration_id
        self.data = bytes(data)
        self.dlc = len(self.data)
        self.timestamp = timestamp
        self.channel = channel
        self.is_rx = is_rx
        self.bits = 0

    def __repr__(self) -> str:
        return (f"Frame(0x{self.arbitration_id:03X}, [{self.data.hex(' ').upper()}], "
                f"t={self.timestamp!r}, channel={self.channel!r})")

    def to_message(self) -> can.Message:
        """The frame as a new :class:`can.Message` (standard id, ``data`` a bytes copy)."""
        return can.Message(timestamp=self.timestamp, arbitration_id=self.arbitration_id,
                           is_extended_id=False, channel=self.channel, dlc=self.dlc,  # type: ignore[arg-type]  # a channel name
                           data=self.data, is_rx=self.is_rx)


def load_frame(frame: Frame | None, arbitration_id: int, data: bytes, bits: int) -> Frame:
    """``frame`` reloaded with ``arbitration_id`` and ``data`` (``bytes``, 0..8, checked by the
    caller) and its length ``bits`` (:func:`frame_bits` of both), unsent (no timestamp, no
    channel); a new frame when ``frame`` is None."""
    if frame is None:
        frame = Frame.__new__(Frame)
    frame.arbitration_id = arbitration_id
    frame.data = data
    frame.dlc = len(data)
    frame.timestamp = 0.0
    frame.channel = None
    frame.is_rx = False
    frame.bits = bits
    return frame


def as_message(msg: Frame | can.Message) -> can.Message:
    """``msg`` as a :class:`can.Message` for python-can code (a :class:`Frame` converted)."""
    return msg.to_message() if type(msg) is Frame else msg  # type: ignore[return-value]  # a Message


# -- acceptance filtering (the one place it is parsed and matched) ------------------------------
Filters = tuple[tuple[int, int, "bool | None"], ...]


def parse_filters(can_filters: can.typechecking.CanFilters | None) -> Filters | None:
    """python-can ``can_filters`` (``can_id``, ``can_mask``, optional ``extended``) as int tuples
    ``(id & mask, mask, extended-or-None)``; None (or empty) accepts every frame.

    The PIC's acceptance masks and filters (seed 002 slide 23) are given in this form by the boards
    (``master.candrivers``/``slave.can``); the wire applies them before any board's receive
    interrupt runs, as the PIC's CAN module does.
    """
    if not can_filters:
        return None
    out = []
    for f in can_filters:
        try:
            can_id = int(f["can_id"])
            can_mask = int(f["can_mask"])
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"a CAN filter needs int 'can_id' and 'can_mask' keys, got {f!r}") from e
        if can_id < 0 or can_mask < 0 or can_id > 0x1FFFFFFF or can_mask > 0x1FFFFFFF:
            raise ValueError(f"CAN filter id/mask out of range: {f!r}")
        ext = f.get("extended")
        out.append((can_id & can_mask, can_mask, None if ext is None else bool(ext)))
    return tuple(out)


def filters_accept(filt: Filters | None, arbitration_id: int, is_extended: bool = False) -> bool:
    """Whether a frame passes ``filt`` (from :func:`parse_filters`)."""
    if filt is None:
        return True
    for can_id, mask, ext in filt:
        if ext is not None and ext != is_extended:
            continue
        if arbitration_id & mask == can_id:
            return True
    return False
