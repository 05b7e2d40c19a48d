"""Module PIC of the Master (seed 000 section 2, table 1, figs. 2-4; seed 002 slides 26-30).

``initPic`` configures the USART and the CAN peripheral and starts the 250 us timer; ``isr`` is
the Master's only running code, split here into its interrupt paths:

- USART RX (fig. 2): each received byte -> :meth:`Usart.rx_byte` (store, check, process,
  answer);
- CAN RX (RXB0/RXB1 interrupt, slide 30): a sensor packet -> database, whenever it arrives;
- timer (fig. 4, slide 27): the time-triggered CAN schedule. Per slave, four 250 us slots:

  ====  ==========================================================================
  slot  action
  ====  ==========================================================================
  0     TX actuation 1 (TXB0)
  1     RX sensors 1 (arrived by interrupt); abort actuation 1 if still pending
  2     TX actuation 2 (TXB1)
  3     RX sensors 2 (arrived by interrupt); abort actuation 2 if still pending;
        set next destination address
  ====  ==========================================================================

  1 ms per slave, 8 ms per round for slaves 1..8. A round is closed (``answered_mask``,
  ``rounds``) at the first tick of the next round, so that the answer to slave 8's actuation 2
  (which may end after slot 3's tick) still counts for its round.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from humanoid_twin.protocol.wire import N_SCU

if TYPE_CHECKING:
    import can

    from humanoid_twin.clock import Clock
    from humanoid_twin.master.can import MasterCan
    from humanoid_twin.master.database import Database
    from humanoid_twin.master.supervisor import Supervisor
    from humanoid_twin.master.usart import Usart

TIMER_PERIOD_US = 250                              # slide 27
SLOTS_PER_SLAVE = 4
SLAVE_PERIOD_US = TIMER_PERIOD_US * SLOTS_PER_SLAVE  # 1 ms per slave
ROUND_US = SLAVE_PERIOD_US * N_SCU                 # 8 ms per round


class Pic:
    """The Master's PIC18F258: initialisation and interrupt service (table 1)."""

    def __init__(self, clock: Clock, usart: Usart, can: MasterCan, db: Database,
                 supervisor: Supervisor) -> None:
        self.clock = clock
        self.supervisor = supervisor
        self.usart = usart
        self.can = can
        self.db = db
        self.slot = 0            # 0..3 within the current slave's 1 ms
        self.slave = 1           # destination address being served, 1..8
        self.started_us = -1     # virtual time of the first timer interrupt (-1: not started)
        self._round_open = False

    def initPic(self) -> None:
        """``initPic`` (table 1): USART and CAN peripherals, interrupts, and the 250 us timer,
        whose first interrupt is at the current virtual instant."""
        if self.started_us >= 0:
            raise RuntimeError("initPic: the Master's PIC is already initialised")
        self.usart.usartInit()
        self.usart.link.set_device_rx(self.isr_usart_rx)
        self.can.canInit(self.isr_can_rx)
        self.started_us = self.clock.now_us
        self.clock.call_every(TIMER_PERIOD_US, self.isr_timer, first_us=self.started_us)

    # --- isr (table 1), by interrupt source ------------------------------------------------
    def isr_usart_rx(self, byte: int) -> None:
        """``isr``, USART RX interrupt (RCIF, fig. 2): one byte from the host."""
        self.usart.rx_byte(byte)

    def isr_can_rx(self, msg: can.Message) -> None:
        """``isr``, CAN RX interrupt (RXB0IF/RXB1IF, slide 30): a sensor packet into the database."""
        self.can.drivers.rx_interrupt(msg)
        self.can.canReceiveMsg()

    def isr_timer(self) -> None:
        """``isr``, timer interrupt every 250 us (fig. 4, slide 27): one slot of the CAN schedule."""
        slot = self.slot
        if slot == 0:
            if self.slave == 1:
                if self._round_open:
                    self.db.finish_round()
                    self.supervisor.on_round()
                self._round_open = True
            self.can.canSendMsg(self.slave, 0)
            self.slot = 1
        elif slot == 2:
            self.can.canSendMsg(self.slave, 1)
            self.slot = 3
        else:
            self.can.canAbort()
            if slot == 1:
                self.slot = 2
            else:
                self.slot = 0
                self.slave = self.slave % N_SCU + 1
