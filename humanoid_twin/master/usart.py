"""Module USART of the Master (seed 000 section 2, tables 2-3; seed 002 slides 7-11).

The Master's side of the RS-232 link: a resynchronising 6-byte receiver (the USART RX
interrupt stores each byte), the request processing (``usartProcessMsg``) that reads and
writes the global database, and the 6-byte response written on the link.

Receiver rules (settled, docs/master.md and docs/protocol.md):
- a byte that is not ``0xFF`` while no frame is being received is dropped (noise);
- a ``0xFF`` starts a frame; bytes are stored until there are 6;
- more than :data:`FRAME_GAP_US` (2 ms) of virtual time between two bytes of a frame: the
  partial frame is discarded (broken off) and the new byte is treated as a possible start;
- at 6 bytes the BCC is checked: good -> processed and answered; bad -> nothing changes, nothing
  is answered, and the receiver resynchronises on the next ``0xFF`` after the first stored byte
  (a data byte may legitimately be ``0xFF``, e.g. -1 degree).
"""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING

from humanoid_twin.master.database import Database
from humanoid_twin.protocol.rs232 import (
    FRAME_LEN,
    MESSAGE_INVREQ,
    MESSAGE_SUCCESS,
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
    SOF,
    SUPERVISOR_ESTOP,
    SUPERVISOR_READ,
    TEST_MESSAGE,
    Op,
    Request,
    bcc,
    data_response,
    invalid_reason,
    status_response,
)
from humanoid_twin.protocol.wire import ErrorState, from_s8, s8

if TYPE_CHECKING:
    from humanoid_twin.bus.serial_link import SerialLink
    from humanoid_twin.clock import Clock
    from humanoid_twin.master.can import MasterCan
    from humanoid_twin.master.supervisor import Supervisor

FRAME_GAP_US = 2_000      # more than this between two bytes of a frame: the frame is broken off
PROCESS_US = 20           # usartProcessMsg + response build on the PIC (10 MIPS), before the 1st TX byte

_OP_APPLY_JOINT = int(Op.APPLY_JOINT)
_OP_APPLY_CONTROL = int(Op.APPLY_CONTROL)
_OP_READ_SENSORS = int(Op.READ_SENSORS)
_OP_MASTER = int(Op.MASTER)


class Usart:
    """The Master's USART: receive buffer, external (request) buffer, transmit buffer."""

    def __init__(self, clock: Clock, link: SerialLink, db: Database, can: MasterCan,
                 supervisor: Supervisor) -> None:
        self.clock = clock
        self.supervisor = supervisor
        self.link = link
        self.db = db
        self.can = can
        self.rx_buf = bytearray(FRAME_LEN)   # bytes of the frame being received
        self.rx_len = 0
        self.rx_last_us = -1                 # virtual time of the last stored byte
        self.ext_buf = bytearray(FRAME_LEN)  # the last complete, good request (echoed by usartSendStatus)
        self.ext_len = 0
        self.tx_buf = bytearray(FRAME_LEN)   # the response being built / sent
        self.tx_len = 0
        self.tx_pos = 0
        self.last_invalid: str | None = None  # why the last FC answer was given (rs232.invalid_reason)

    # --- table 2: device drivers -----------------------------------------------------------
    def usartInit(self) -> None:
        """``usartInit`` (table 2): empty buffers; the link's byte timing is 115200 8E1
        (:data:`humanoid_twin.protocol.wire.LINE_SETTINGS`, timed by the SerialLink)."""
        self.usartResetRxBuff()
        self.usartResetTxBuff()
        self.ext_len = 0

    def usartStoreRx(self, byte: int) -> bool:
        """``usartStoreRx`` (table 2): store one received byte; True when the RX buffer holds 6 bytes.

        Applies the receiver rules of the module docstring (start on 0xFF, break-off after
        :data:`FRAME_GAP_US`, noise dropped).
        """
        now = self.clock.now_us
        c = self.db.counters
        c.serial_bytes_received += 1
        if self.rx_len and now - self.rx_last_us > FRAME_GAP_US:
            c.serial_frames_rejected += 1
            c.serial_frames_broken += 1
            c.serial_bytes_discarded += self.rx_len
            self.rx_len = 0
        if not self.rx_len and byte != SOF:
            c.serial_bytes_discarded += 1
            return False
        self.rx_buf[self.rx_len] = byte
        self.rx_len += 1
        self.rx_last_us = now
        return self.rx_len == FRAME_LEN

    def usartGetTx(self) -> int | None:
        """``usartGetTx`` (table 2): next byte of the TX buffer, None when all were taken."""
        if self.tx_pos >= self.tx_len:
            return None
        b = self.tx_buf[self.tx_pos]
        self.tx_pos += 1
        return b

    def usartResetRxBuff(self) -> None:
        """``usartResetRxBuff`` (table 2): clear the RX buffer (leave stream mode)."""
        self.rx_len = 0
        self.rx_buf[:] = bytes(FRAME_LEN)

    def usartResetTxBuff(self) -> None:
        """``usartResetTxBuff`` (table 2): clear the TX buffer."""
        self.tx_len = 0
        self.tx_pos = 0
        self.tx_buf[:] = bytes(FRAME_LEN)

    def usartStore2extBuff(self, byte: int) -> None:
        """``usartStore2extBuff`` (table 2): append a byte to the external buffer, the copy of the
        received request that ``usartProcessMsg`` works on (the RX buffer is free again)."""
        if self.ext_len >= FRAME_LEN:
            self.ext_len = 0
        self.ext_buf[self.ext_len] = byte
        self.ext_len += 1

    # --- the RX interrupt path (part of isr, table 1) ----------------------------------------
    def rx_byte(self, byte: int) -> None:
        """USART RX interrupt (``isr``, table 1 / fig. 2): store the byte; at 6 bytes check and process."""
        if not self.usartStoreRx(byte):
            return
        buf = self.rx_buf
        if bcc(buf[:5]) != buf[5]:
            self._resync()
            return
        self.ext_len = 0
        for b in buf:
            self.usartStore2extBuff(b)
        self.rx_len = 0
        self.db.counters.serial_frames_received += 1
        self.usartProcessMsg()
        self.clock.after(PROCESS_US, partial(self.tx_write, self.tx_drain()))

    def _resync(self) -> None:
        """Bad BCC: drop the frame, keep what follows the next 0xFF after its first byte."""
        c = self.db.counters
        c.serial_frames_rejected += 1
        buf = self.rx_buf
        try:
            i = buf.index(SOF, 1)
        except ValueError:
            i = FRAME_LEN
        c.serial_bytes_discarded += i
        keep = FRAME_LEN - i
        buf[:keep] = buf[i:]
        self.rx_len = keep

    # --- the TX interrupt path (part of isr, table 1 / fig. 3) --------------------------------
    def tx_drain(self) -> bytes:
        """USART TX path (fig. 3): take the TX buffer byte by byte with ``usartGetTx``."""
        out = bytearray()
        b = self.usartGetTx()
        while b is not None:
            out.append(b)
            b = self.usartGetTx()
        return bytes(out)

    def tx_write(self, response: bytes) -> None:
        """USART TX path: put the response on the line (the link times the bytes, 11 bits each)."""
        if response:
            self.link.device_write(response)
            self.db.counters.serial_frames_answered += 1

    def _load_tx(self, frame: bytes) -> None:
        self.tx_buf[:] = frame
        self.tx_len = FRAME_LEN
        self.tx_pos = 0

    # --- table 3: response construction ------------------------------------------------------
    def usartSendTestMsg(self) -> None:
        """``usartSendTestMsg`` (table 3): the response ``FA F9 F8 F7 F6 F5``."""
        self._load_tx(TEST_MESSAGE)

    def usartSendStatus(self, status: int) -> None:
        """``usartSendStatus`` (table 3): the last request echoed with first byte ``status``
        (``MESSAGE_SUCCESS`` 0xFB or ``MESSAGE_INVREQ`` 0xFC), BCC recomputed."""
        self._load_tx(status_response(self.ext_buf, status))

    def usartProcessMsg(self) -> None:
        """``usartProcessMsg`` (table 3): execute the request in the external buffer against the
        database and build its response in the TX buffer (docs/protocol.md section 1)."""
        frame = bytes(self.ext_buf)
        req = Request.decode(frame)
        reason = invalid_reason(req)
        if reason is not None:
            self.last_invalid = reason
            self.db.counters.serial_frames_invalid += 1
            self.usartSendStatus(MESSAGE_INVREQ)
            return
        op, scu, param = req.op, req.scu, req.param
        d = req.data
        db = self.db
        sup = self.supervisor
        sup.host_frame()
        if op <= _OP_APPLY_CONTROL and not sup.apply_allowed():
            # docs/supervisor.md: in safe / estop every APPLY is refused
            self.last_invalid = sup.refusal()
            sup.refused += 1
            self.usartSendStatus(MESSAGE_INVREQ)
            return
        if op == _OP_APPLY_JOINT:
            a = db.actuators[scu]
            if param == PARAM_POSITION:
                a.ref[:] = [from_s8(x) for x in d]
            elif param == PARAM_VELOCITY:
                a.speed[:] = d
            else:  # PARAM_SPECIAL (param 2 is rejected by the validation)
                a.pwm = d[0] == 1
                if d[1] == 1:
                    db.request_calibration(scu)
            a.invalidate()
            sup.applied(op, param, d)
            self.usartSendStatus(MESSAGE_SUCCESS)
        elif op == _OP_APPLY_CONTROL:
            a = db.actuators[scu]
            if param == PARAM_KI:
                a.ki[:] = d
            elif param == PARAM_KP:
                a.kp[:] = d
            elif param == PARAM_KD:
                a.kd[:] = d
            else:  # PARAM_CONTROLON
                assert param == PARAM_CONTROLON
                a.type[:] = d
            a.invalidate()
            self.usartSendStatus(MESSAGE_SUCCESS)
        elif op == _OP_READ_SENSORS:
            s = db.sensors[scu]
            if param == PARAM_POSITION:
                v = s.pos
            elif param == PARAM_VELOCITY:
                v = s.vel
            elif param == PARAM_CURRENT:
                v = s.current
            else:
                assert param == PARAM_SPECIAL
                sp = s.special
                self._load_tx(data_response(sp[0], sp[1], sp[2], sp[3]))
                return
            self._load_tx(data_response(s8(v[0]), s8(v[1]), s8(v[2]), s.status))
        else:
            assert op == _OP_MASTER
            if param == PARAM_TEST:
                self.usartSendTestMsg()
            elif param == PARAM_SUPERVISOR:
                self._supervisor_request(d[0])
            else:
                assert param == PARAM_CANSTATUS
                err, tec, rec = self.can.error_status()
                self._load_tx(data_response(err, tec, rec, db.answered_mask))
                if err == ErrorState.BUS_OFF:
                    self.can.canClearStatus()

    def _supervisor_request(self, d1: int) -> None:
        """MASTER param 2 (docs/supervisor.md): D1 0 read -> ``FD MODE FAULT NODE NFAULTS``,
        1 emergency stop -> FB echo, 2 reset -> FB echo (D1 > 2 was refused by the validation)."""
        sup = self.supervisor
        if d1 == SUPERVISOR_READ:
            self._load_tx(data_response(*sup.read()))
            return
        if d1 == SUPERVISOR_ESTOP:
            sup.estop()
        elif not sup.reset():               # only a healthy robot is reset (docs/supervisor.md)
            self.last_invalid = sup.reset_refusal()
            self.usartSendStatus(MESSAGE_INVREQ)
            return
        self.usartSendStatus(MESSAGE_SUCCESS)
