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

Each interrupt takes the cycles of humanoid_twin/cycles.py at the board's clock: the timer
interrupt's slot work plus the RX interrupts (USART bytes, CAN packets) since the slot before.
A timer interrupt that comes while that work still runs is served when it ends (its flag stays
set); one more that comes meanwhile is lost: the schedule slips (docs/master.md, "Cycle budget").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from humanoid_twin.cycles import DEFAULT_PIC_MHZ, MASTER, check_pic_mhz, cycles_to_us, instructions_per_s
from humanoid_twin.protocol.wire import N_SCU

if TYPE_CHECKING:
    from humanoid_twin.bus.frames import Frame
    from humanoid_twin.clock import Clock
    from humanoid_twin.master.can import MasterCan
    from humanoid_twin.master.database import Database
    from humanoid_twin.master.supervisor import Supervisor
    from humanoid_twin.master.usart import Usart

TIMER_PERIOD_US = 250                              # slide 27
SLOTS_PER_SLAVE = 4
SLAVE_PERIOD_US = TIMER_PERIOD_US * SLOTS_PER_SLAVE  # 1 ms per slave
ROUND_US = SLAVE_PERIOD_US * N_SCU                 # 8 ms per round
_SLOT_US = TIMER_PERIOD_US
_C_TIMER_TX = MASTER["timer_tx"]
_C_TIMER_RX = MASTER["timer_rx"]
_C_CAN_RX = MASTER["can_rx"]
_C_USART = MASTER["usart_byte"]


class Pic:
    """The Master's PIC18F258: initialisation and interrupt service (table 1)."""

    def __init__(self, clock: Clock, usart: Usart, can: MasterCan, db: Database,
                 supervisor: Supervisor, pic_mhz: float = DEFAULT_PIC_MHZ) -> None:
        self.clock = clock
        self.ips = instructions_per_s(check_pic_mhz(pic_mhz))
        self.isr_cycles = 0          # RX interrupts' cycles since the last timer interrupt
        self.busy_until_us = -1      # the end of the timer interrupt's work in progress
        self.slot_load_max = 0.0     # the largest fraction of a 250 us slot the work took
        self.slot_overruns = 0       # slots whose work took more than 250 us
        self.slots_lost = 0          # timer interrupts lost to an overrun
        self._timer_pending = False
        self._late_cb = self._isr_timer_late
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
        self.isr_cycles += _C_USART
        self.usart.rx_byte(byte)

    def isr_can_rx(self, msg: Frame) -> None:
        """``isr``, CAN RX interrupt (RXB0IF/RXB1IF, slide 30): a sensor packet into the database."""
        self.isr_cycles += _C_CAN_RX
        self.can.drivers.rx_interrupt(msg)
        self.can.canReceiveMsg()

    def isr_timer(self) -> None:
        """``isr``, timer interrupt every 250 us (fig. 4, slide 27): one slot of the CAN schedule
        and its cycles (humanoid_twin/cycles.py), served when the work before it ends if it
        comes while that still runs (one more meanwhile is lost)."""
        now = self.clock.now_us
        if now < self.busy_until_us:
            if self._timer_pending:
                self.slots_lost += 1
            else:
                self._timer_pending = True
                self.clock.schedule(self.busy_until_us, self._late_cb)
            return
        slot = self.slot
        cycles = self.isr_cycles + (_C_TIMER_TX if slot == 0 or slot == 2 else _C_TIMER_RX)
        self.isr_cycles = 0
        us = cycles_to_us(cycles, self.ips)
        load = us / _SLOT_US
        if load > self.slot_load_max:
            self.slot_load_max = load
        if us > _SLOT_US:
            self.slot_overruns += 1
        self.busy_until_us = now + us
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

    def _isr_timer_late(self) -> None:
        """The timer interrupt that came while the work before it ran, served at the instant
        that work ends (where :meth:`isr_timer` serves it)."""
        self._timer_pending = False
        self.isr_timer()
