"""Module CANDRIVERS of the Master (seed 000 section 2, table 5; seed 002 slides 21-25).

Thin device drivers over the node's :class:`~humanoid_twin.bus.CanController` (the PIC18F258
CAN peripheral): 3 TX buffers, 2 RX buffers. Slide 24: packet index 0 uses TXB0 / RXB0, index 1
uses TXB1 / RXB1, TXB0 has the highest priority. On the wire the controller arbitrates by
identifier, and the index-0 identifier of a packet pair is always the lower one, so the buffer
priority and the identifier priority agree (docs/master.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from humanoid_twin.protocol.canframes import PIC_RX_BUFFERS, PIC_TX_BUFFERS, packet_index

if TYPE_CHECKING:
    from collections.abc import Callable

    from can.typechecking import CanFilters

    from humanoid_twin.bus.frames import Frame
    from humanoid_twin.bus.network import CanController, CanNetwork


class CanDriverError(RuntimeError):
    """A CANDRIVERS call before ``myCANInitialize`` or with a bad buffer number."""


class CanDrivers:
    """CANDRIVERS (table 5) of one board: the RX/TX buffers of its CAN controller."""

    def __init__(self, network: CanNetwork, name: str) -> None:
        self.network = network
        self.name = name
        self.controller: CanController = None  # type: ignore[assignment]  # set by canInit (attach)
        self.rxb: list[Frame | None] = [None] * PIC_RX_BUFFERS  # RXB0, RXB1 (full = not None)
        self.txb: list[Frame | None] = [None] * PIC_TX_BUFFERS  # last message requested per TXBn
        self.rx_overflows = 0

    def myCANInitialize(self, can_filters: CanFilters, on_rx: Callable[[Frame], None]) -> CanController:
        """``myCANInitialize`` (table 5): configuration mode, bit timing, masks/filters, normal mode.

        In the twin: attach the node to the network with ``can_filters`` (slide 23) and ``on_rx``
        as its receive interrupt (RXBnIF). The bit timing is the network's (1 Mbit/s).
        """
        if self.controller is not None:
            raise CanDriverError(f"CAN node {self.name!r} is already initialised")
        self.controller = self.network.attach(self.name, can_filters, on_rx)
        return self.controller

    def _ctl(self) -> CanController:
        ctl = self.controller
        if ctl is None:
            raise CanDriverError(f"CAN node {self.name!r}: myCANInitialize was not called")
        return ctl

    def _send(self, index: int, msg: Frame) -> bool:
        """Send ``msg`` through TX buffer ``index`` (the Master's schedule: 2000 times a second)."""
        self.txb[index] = msg
        ctl = self.controller
        if ctl is None:
            ctl = self._ctl()
        return ctl.send(msg) is not False

    def myCANSendMessage0(self, msg: Frame) -> bool:
        """``myCANSendMessage0`` (table 5): send through TX buffer 0 (packet index 0)."""
        return self._send(0, msg)

    def myCANSendMessage1(self, msg: Frame) -> bool:
        """``myCANSendMessage1`` (table 5): send through TX buffer 1 (packet index 1)."""
        return self._send(1, msg)

    def myCANAbort(self) -> bool:
        """Abort every pending transmission (TXABT, used by the Master's schedule, slide 27).

        Returns True if the controller reports that a frame was dropped.
        """
        ctl = self.controller
        if ctl is None:
            ctl = self._ctl()
        dropped = ctl.abort()
        txb = self.txb
        txb[0] = txb[1] = txb[2] = None
        return bool(dropped)

    def rx_interrupt(self, msg: Frame) -> None:
        """The receive path of the controller: the frame lands in RXB0 or RXB1 by its index bit
        (filters of slide 23). A buffer still full is overwritten and counted (RXBnOVFL)."""
        n = packet_index(msg.arbitration_id)
        if self.rxb[n] is not None:
            self.rx_overflows += 1
        self.rxb[n] = msg

    def myCANReceiveMessage(self) -> Frame | None:
        """``myCANReceiveMessage`` (table 5): read (and free) the first full RX buffer, or None."""
        rxb = self.rxb
        msg = rxb[0]
        if msg is not None:
            rxb[0] = None
            return msg
        msg = rxb[1]
        if msg is not None:
            rxb[1] = None
        return msg
