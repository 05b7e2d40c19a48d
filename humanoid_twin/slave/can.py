"""Module CAN of the Slave firmware (seed 000 section 3, table 18; seed 002 slides 23, 29-31;
seed 000 fig. 9, ``lowISR`` of module PIC2).

``initCan`` attaches the board's CAN controller to the network with the slide 23 filters and
``lowISR`` as its receive interrupt. ``lowISR`` (slide 29, fig. 9), for each packet the filters
let in (every Master frame: the destination is not in the slaves' mask):

1. not for this board (destination in the identifier) or not an actuation -> ignored;
2. abort the previous TX (PIC TXABT);
3. ``receiveCanMessage``: the packet into the actuator database;
4. if the packet arrived while the PWM pulses are being generated (the first
   ``hardware.PWM_BUSY_US`` of the board's PWM period), no answer (slide 29: "PWM control can
   cause jitter up to 2 ms. In this case, response is not sent");
5. otherwise ``sendCanMessage`` of the sensor packet with the same index, :data:`ISR_LATENCY_US`
   after the end of the received frame (the interrupt entry, the copy out of RXBn and the load
   of TXBn on the PIC at 40 MHz / 10 MIPS; docs/firmware.md).

The sensor packets are built from the sensor database by the main loop once per tick
(``prepareSensorPackets``): the sensor database only changes there, so the interrupt only copies
bytes, as the PIC did from its global database (slide 31).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from humanoid_twin.cycles import SLAVE
from humanoid_twin.hardware import PWM_BUSY_US, PWM_PERIOD_US
from humanoid_twin.protocol.canframes import (
    ACTUATION_IDS,
    SENSOR_IDS,
    SFLAGS_WATCHDOG,
    ActuationFields,
    PayloadError,
    pack_sensors1_fields,
    pack_sensors2_fields,
    sensors1_with_status,
    slave_filters,
    status_byte,
    unpack_actuation1_into,
    unpack_actuation2_into,
)
from humanoid_twin.protocol.wire import STATUS_DEADLINE, ErrorState, node_name
from humanoid_twin.slave.database import Global

if TYPE_CHECKING:
    from collections.abc import Callable

    from humanoid_twin.bus.frames import Frame
    from humanoid_twin.bus.network import CanController, CanNetwork
    from humanoid_twin.clock import Clock

__all__ = ["ISR_LATENCY_US", "SlaveCan"]

ISR_LATENCY_US = 20   # end of the received frame -> TXREQ of the answer (docs/firmware.md)
_BUS_OFF = ErrorState.BUS_OFF.label   # a controller's ``state`` when bus-off
# lowISR's cycles (humanoid_twin/cycles.py): a packet for this board, its answer, another frame
_C_ISR_RX = SLAVE["isr_actuation"]
_C_ISR_TX = SLAVE["isr_answer"]
_C_ISR_OTHER = SLAVE["isr_other"]


class SlaveCan:
    """The CAN module of one Slave (its part of the low-priority interrupt too)."""

    __slots__ = (
        "address",
        "clock",
        "db",
        "phase_us",
        "controller",
        "node_name",
        "payload",
        "calib_request",
        "_sensor_ids",
        "_rx_index",
        "_rx_id1",
        "_rx_id2",
        "_rx_fields",
        "_tx_msgs",
        "_isr_send_cb",
        "_tx_index",
        "_tx_due_us",
        "rx_packets",
        "_rx_ignored",
        "rx_errors",
        "tx_packets",
        "tx_silent",
        "bus_off_recoveries",
        "last_rx_us",
        "watchdog",
        "law_stopped",
        "bus_off_seen",
        "on_stop",
        "isr_cycles",
        "_skipped_seen",
    )

    def __init__(self, address: int, clock: Clock, db: Global, phase_us: int) -> None:
        self.address = address
        self.clock = clock
        self.db = db
        self.phase_us = phase_us
        self.controller: CanController = None  # type: ignore[assignment]  # set by initCan
        self.node_name = node_name(address)
        self._sensor_ids = SENSOR_IDS[address]
        # the two actuation identifiers addressed to this board -> packet index (the network's
        # rx_ids), and the same two as lowISR's destination and operation check
        self._rx_index = {ACTUATION_IDS[address][i]: i for i in (0, 1)}
        self._rx_id1, self._rx_id2 = ACTUATION_IDS[address]
        # the last actuation packet's fields (RXBn as the PIC copied it out), reused per packet
        self._rx_fields = ActuationFields()
        # the sensor packets' messages (TXB0/TXB1), built once and reloaded for each answer
        self._tx_msgs: list[Frame | None] = [None, None]
        self._isr_send_cb = self._isr_send
        self.payload: list[bytes] = [bytes(8), bytes(8)]   # Sensors 1 / Sensors 2, ready to send
        self.calib_request = False       # Calib bit 0 -> 1 seen (handled by the main loop)
        self._tx_index = 0
        self._tx_due_us = -1
        # counters (recording, tests)
        self.rx_packets = 0              # actuation packets taken
        self._rx_ignored = 0             # frames for other boards / not actuation (see rx_ignored)
        self.rx_errors = 0               # malformed actuation packets dropped
        self.tx_packets = 0              # sensor packets handed to the controller
        self.tx_silent = 0               # packets left unanswered (PWM window)
        self.bus_off_recoveries = 0
        self.last_rx_us = -1
        # supervisor additions (docs/supervisor.md): the CAN watchdog holds the last reference
        # (set by the main loop), a bus-off recovered this tick, and the category-0 stop the
        # board runs at once when an actuation packet switches its PWM off
        self.watchdog = False
        self.law_stopped = False      # a control law was stopped (Sensors 2 SFlags bit 2)
        self.bus_off_seen = False
        self.on_stop: Callable[[], None] | None = None
        # cycles the receive interrupt took since the main loop last asked (take_isr_cycles)
        self.isr_cycles = 0
        self._skipped_seen = 0
        self.prepareSensorPackets()

    def initCan(self, network: CanNetwork) -> None:
        """``initCan`` (table 18): the CAN peripheral on the network, slide 23 mask/filters,
        receive interrupt = :meth:`lowISR`. The frames that interrupt acts on, this board's two
        actuation identifiers, are named to the network (``rx_ids``): every other frame the mask
        lets in is counted by the controller without the call, as lowISR would drop it at once."""
        self.controller = network.attach(self.node_name, slave_filters(), self.lowISR, rx_ids=self._rx_index)

    @property
    def rx_ignored(self) -> int:
        """Frames the slide 23 filters let in that were not an actuation packet for this board:
        those dropped by :meth:`lowISR` plus those the controller did not hand to it."""
        c = self.controller
        return self._rx_ignored + (c.rx_skipped if c is not None else 0)

    # -- interrupt ------------------------------------------------------------------------------
    def lowISR(self, msg: Frame) -> None:
        """``lowISR`` (table 17, fig. 9, slide 29): the CAN receive interrupt (RXBnIF)."""
        arb = msg.arbitration_id
        if arb == self._rx_id1:
            index = 0
        elif arb == self._rx_id2:
            index = 1
        else:                                      # not for this board, or not an actuation
            self._rx_ignored += 1
            self.isr_cycles += _C_ISR_OTHER
            return
        self.isr_cycles += _C_ISR_RX
        self.controller.abort()                    # abort the previous TX
        self._tx_due_us = -1                       # and an answer still in the ISR
        if not self.receiveCanMessage(index, msg.data):
            return
        now = self.clock.now_us
        if (now - self.phase_us) % PWM_PERIOD_US < PWM_BUSY_US:
            self.tx_silent += 1                    # PWM interference: no answer
            return
        due = now + ISR_LATENCY_US
        if not self.clock.due_by(due):
            # nothing runs before the answer's TXREQ (no tick can change the packet, no frame
            # can supersede it): request it for that instant now, without an event
            self.sendCanMessage(index, due)
            return
        self._tx_index = index
        self._tx_due_us = due
        self.clock.schedule(due, self._isr_send_cb)

    def take_isr_cycles(self) -> int:
        """The cycles ``lowISR`` took since the last call (the frames the controller counted
        without calling it included: on the PIC the interrupt ran for them too); restarts the count."""
        c = self.controller
        skipped = c.rx_skipped if c is not None else 0
        cycles = self.isr_cycles + (skipped - self._skipped_seen) * _C_ISR_OTHER
        self._skipped_seen = skipped
        self.isr_cycles = 0
        return cycles

    def _isr_send(self) -> None:
        if self.clock.now_us != self._tx_due_us:   # superseded by a later packet
            return
        self._tx_due_us = -1
        self.sendCanMessage(self._tx_index)

    # -- table 18 -------------------------------------------------------------------------------
    def receiveCanMessage(self, index: int, data: bytes | bytearray) -> bool:
        """``receiveCanMessage`` (table 18): an actuation packet into the actuator database.
        Returns False (and counts it) for a malformed packet, which changes nothing."""
        act = self.db.actuators
        f = self._rx_fields
        try:
            if index == 0:
                unpack_actuation1_into(data, f)  # type: ignore[arg-type]  # the frame's bytes (a bytearray is read alike)
            else:
                unpack_actuation2_into(data, f)  # type: ignore[arg-type]  # as above
        except PayloadError:
            self.rx_errors += 1
            return False
        self.rx_packets += 1
        act.received += 1
        self.last_rx_us = self.clock.now_us
        c0, c1, c2 = act.control
        if index == 0:
            a0, a1, a2 = act.servo
            a0.ref = f.ref1
            a1.ref = f.ref2
            a2.ref = f.ref3
            a0.speed = f.speed1
            a1.speed = f.speed2
            a2.speed = f.speed3
            c0.type = f.type1
            c1.type = f.type2
            c2.type = f.type3
            c2.kd = f.kd3
            pwm = f.pwm
            calib = f.calib
            sys_ = act.sysStatus
            if not pwm and sys_.pwm and self.on_stop is not None:
                sys_.pwm = False
                self.on_stop()                     # PWM off now, not at the next tick
            sys_.pwm = pwm
            if calib and not sys_.calib:
                # Calib request 0 -> 1: a new calibration. Report "not calibrated" from this
                # answer on, so the Master keeps asking until the new calibration is done.
                self.calib_request = True
                st = self.db.sensors.sysStatus
                if st.calib:
                    st.calib = False
                    self.prepareSensorPackets()
            sys_.calib = calib
        else:
            c0.ki = f.ki1
            c1.ki = f.ki2
            c2.ki = f.ki3
            c0.kp = f.kp1
            c1.kp = f.kp2
            c2.kp = f.kp3
            c0.kd = f.kd1
            c1.kd = f.kd2
        return True

    def sendCanMessage(self, index: int, at_us: int = -1) -> None:
        """``sendCanMessage`` (table 18): the sensor packet ``index`` (0: positions, velocities,
        status; 1: currents, force sensors) to the Master; its TXREQ now, or at ``at_us`` when
        nothing runs on the clock before then (``CanController.send_at``)."""
        self.tx_packets += 1
        self.isr_cycles += _C_ISR_TX
        controller = self.controller
        msg = self._tx_msgs[index] = controller.load_tx(
            self._tx_msgs[index], self._sensor_ids[index], self.payload[index])
        if at_us < 0:
            controller.send(msg)
        else:
            controller.send_at(msg, at_us)

    def checkCan(self) -> bool:
        """``checkCan`` (table 18): if the controller is bus-off, recover it (``clear_status``).
        Returns True when a recovery was started."""
        c = self.controller
        if c is not None and c.state == _BUS_OFF and not getattr(c, "recovering", False):
            c.clear_status()
            self.bus_off_recoveries += 1
            self.bus_off_seen = True
            return True
        return False

    def flag_deadline(self) -> None:
        """The deadline bit (status bit 5) set in the prepared Sensors 1 packet, which ``lowISR``
        answers with: PIC2's period interrupt found the main loop's pass still running
        (docs/firmware.md, "Cycle budget"); the rest of the packet stays the pass before's."""
        self.payload[0] = sensors1_with_status(self.payload[0], STATUS_DEADLINE)

    def prepareSensorPackets(self) -> None:
        """Build both sensor packets from the sensor database (main loop, once per tick)."""
        s = self.db.sensors
        st = s.sysStatus
        s0, s1, s2 = s.servo
        status = status_byte(st.pwm, st.calib, st.deadlineError, st.motionFinAll, st.motionFinOne,
                             st.motionFin)
        flags = SFLAGS_WATCHDOG if self.watchdog else 0
        c = self.controller
        if self.bus_off_seen:
            flags |= ErrorState.BUS_OFF
        elif c is not None:
            flags |= c.error_state_code
        self.payload[0] = pack_sensors1_fields(
            self.address, s0.pos, s1.pos, s2.pos, s0.vel, s1.vel, s2.vel, status, flags,
        )
        d1, d2, d3, d4 = s.special
        self.payload[1] = pack_sensors2_fields(
            self.address, s0.current, s1.current, s2.current, d1, d2, d3, d4, self.law_stopped
        )
