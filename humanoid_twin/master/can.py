"""Module CAN of the Master (seed 000 section 2, table 4; seed 002 slides 18-20, 26-31).

High-level CAN messages of the Master: ``canSendMsg`` builds one actuation packet of one SCU
from the global database, ``canReceiveMsg`` stores a sensor packet in the database,
``canClearStatus`` recovers the controller from bus-off. The time-triggered schedule that calls
them lives in :mod:`humanoid_twin.master.pic` (the timer interrupt).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from humanoid_twin.master.candrivers import CanDrivers
from humanoid_twin.master.database import Database, ScuActuation, ScuSensors
from humanoid_twin.protocol.canframes import (
    ACTUATION_IDS,
    MASTER_ADDRESS,
    SENSOR_IDS,
    SFLAGS_SUPERVISOR,
    STD_ID_MAX,
    PayloadError,
    control_byte,
    master_filters,
    pack_actuation1,
    pack_actuation2,
    packet_index,
    unpack_sensors1_into,
    unpack_sensors2_into,
)
from humanoid_twin.protocol.wire import N_SCU, node_name

if TYPE_CHECKING:
    from collections.abc import Callable

    from humanoid_twin.bus.frames import Frame
    from humanoid_twin.bus.network import CanNetwork
    from humanoid_twin.clock import Clock

class MasterCan:
    """The Master's CAN module: database <-> packets, over :class:`CanDrivers`."""

    def __init__(self, clock: Clock, network: CanNetwork, db: Database,
                 name: str = node_name(MASTER_ADDRESS)) -> None:
        self.clock = clock
        self.db = db
        self.drivers = CanDrivers(network, name)
        self.rejected: list[tuple[int, int, str]] = []  # (t_us, id, reason), the last few rejected frames
        # the schedule's look-ups, by address (0, the Master's, unused): the database's actuation
        # records; and by scu * 2 + index: the last actuation message (None: not requested yet),
        # its identifier
        self._actuators: list[ScuActuation] = [db.actuators.get(k) for k in range(N_SCU + 1)]  # type: ignore[misc]  # [0]: None, unread
        self._tx_msgs: list[Frame | None] = [None] * ((N_SCU + 1) * 2)
        self._tx_ids: list[int] = [ACTUATION_IDS[k][i] if k in ACTUATION_IDS else -1
                                   for k in range(N_SCU + 1) for i in (0, 1)]
        # the receive path's: by identifier, the slave 1..8 whose sensor packet to the Master it
        # is (0: none); by address, the database's sensor records
        self._rx_sources: list[int] = [0] * (STD_ID_MAX + 1)
        for k, ids in SENSOR_IDS.items():
            for ident in ids:
                self._rx_sources[ident] = k
        self._sensors: list[ScuSensors] = [db.sensors.get(k) for k in range(N_SCU + 1)]  # type: ignore[misc]  # [0]: None, unread

    def canInit(self, on_rx: Callable[[Frame], None]) -> None:
        """``canInit`` (table 4): CAN peripheral with the Master's acceptance filters (slide 23:
        RXB0 = frames to the Master with index 0, RXB1 = index 1) and its RX interrupt ``on_rx``."""
        self.drivers.myCANInitialize(master_filters(), on_rx)

    def canSendMsg(self, scu: int, index: int) -> bool:
        """``canSendMsg`` (table 4): request the actuation packet ``index`` (0 or 1) of SCU ``scu``.

        Packet 1: ``Ref1..3 Speed1..3 Control KD3`` with the control byte from PWM, Calib and the
        three control types; packet 2: ``KI1..3 KP1..3 KD1 KD2`` (slide 20). The payloads are
        cached until the host changes the SCU's data. Packet 1 goes through TX buffer 0, packet 2
        through TX buffer 1 (slide 24). Returns False if the controller refused the request.
        An SCU outside 1..8 is a ``KeyError`` (it has no actuation data), an index other than 0
        and 1 a ``ValueError``.
        """
        if not 1 <= scu <= N_SCU:
            raise KeyError(scu)
        if index != 0 and index != 1:
            raise ValueError(f"canSendMsg: the actuation packet index is 0 or 1, got {index}")
        a = self._actuators[scu]
        c = self.db.counters
        c.can_tx_requests += 1
        if index == 0:
            p = a.payload1
            if p is None:
                kd3 = a.kd[2]
                p = a.payload1 = pack_actuation1(a.ref, a.speed, control_byte(a.pwm, a.calib, a.type), kd3)
        else:
            p = a.payload2
            if p is None:
                kd = a.kd
                p = a.payload2 = pack_actuation2(a.ki, a.kp, kd[0], kd[1])
        # the message, reused from its last request when the controller holds none of the
        # Master's frames any more (load_tx)
        drivers = self.drivers
        ctl = drivers.controller
        assert ctl is not None, "canInit attaches the controller before any canSendMsg"
        key = scu * 2 + index
        msgs = self._tx_msgs
        msg = msgs[key] = ctl.load_tx(msgs[key], self._tx_ids[key], p)
        if index == 0:
            ok = drivers.myCANSendMessage0(msg)
        else:
            ok = drivers.myCANSendMessage1(msg)
        if not ok:
            c.can_tx_refused += 1
        return ok

    def canAbort(self) -> None:
        """Abort a pending actuation packet (slide 27, slots 1 and 3: TXABT)."""
        if self.drivers.myCANAbort():
            self.db.counters.can_tx_aborts += 1

    def canReceiveMsg(self) -> bool:
        """``canReceiveMsg`` (table 4): take the packet in the first full RX buffer and store it in
        the database. The SFlags byte must name the same source and index as the identifier, the
        operation must be a sensor reading and the source a slave 1..8; otherwise the packet is
        dropped and counted (``can_rx_rejected``). Returns True when a packet was stored."""
        msg = self.drivers.myCANReceiveMessage()
        if msg is None:
            return False
        db = self.db
        c = db.counters
        c.can_rx_frames += 1
        ident = msg.arbitration_id
        src = self._rx_sources[ident] if 0 <= ident <= STD_ID_MAX else 0
        if src == 0:
            return self._reject(ident, f"id 0x{ident:03X}: not a sensor packet from slave 1..8 to Master")
        s = self._sensors[src]
        index = packet_index(ident)
        data = msg.data
        try:    # the payload's fields straight into the database (nothing stored if rejected)
            if index == 0:
                s.status = unpack_sensors1_into(data, src, s.pos, s.vel)
            else:
                unpack_sensors2_into(data, src, s.current, s.special)
        except PayloadError as exc:
            return self._reject(ident, str(exc))
        if index == 0:
            s.sflags = data[0] & SFLAGS_SUPERVISOR
            s.rx1 = True
            s.packets1 += 1
            db.update_calibration(src, s.status)
        else:
            s.sflags2 = data[0] & SFLAGS_SUPERVISOR
            s.rx2 = True
            s.packets2 += 1
        s.last_rx_us = self.clock.now_us
        return True

    def _reject(self, ident: int, reason: str) -> bool:
        self.db.counters.can_rx_rejected += 1
        rejected = self.rejected
        rejected.append((self.clock.now_us, ident, reason))
        if len(rejected) > 16:
            del rejected[0]
        return False

    def canClearStatus(self) -> None:
        """``canClearStatus`` (table 4): reset the controller's error state (bus-off recovery)."""
        self.db.counters.can_clear_status += 1
        self.drivers.controller.clear_status()

    def error_status(self) -> tuple[int, int, int]:
        """``(ERRSTATE, TEC, REC)`` of the Master's controller for the CAN status response:
        ERRSTATE a :class:`~humanoid_twin.protocol.wire.ErrorState` code; TEC/REC clipped to a byte."""
        ctl = self.drivers.controller
        return ctl.error_state_code, min(ctl.tec, 255), min(ctl.rec, 255)
