"""Module Master (seed 000 section 2): the Master board's ``main``.

``main`` calls the PIC's initialisation and then sits in a dummy task: all the Master's work
happens in interrupts (seed 000: "fica preso numa dummy task em que o único software em execução
é proveniente da rotina de serviço à interrupção"). In the twin the interrupts are events on the
virtual clock: bytes from the serial link, frames from the CAN network, the 250 us timer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from humanoid_twin.cycles import DEFAULT_PIC_MHZ
from humanoid_twin.master.can import MasterCan
from humanoid_twin.master.database import Database
from humanoid_twin.master.pic import ROUND_US, Pic
from humanoid_twin.master.supervisor import Supervisor, SupervisorConfig
from humanoid_twin.master.usart import Usart

if TYPE_CHECKING:
    from humanoid_twin.bus.network import CanController, CanNetwork
    from humanoid_twin.bus.serial_link import SerialLink
    from humanoid_twin.clock import Clock


class Master:
    """The Master board: USART <-> global database <-> time-triggered CAN schedule.

    ``Master(clock, network, link)`` attaches the node ``"master"`` to ``network``, takes the
    device side of ``link`` and starts the 250 us timer at ``clock.now_us``.
    """

    def __init__(self, clock: Clock, network: CanNetwork, link: SerialLink,
                 supervisor: SupervisorConfig | None = None, pic_mhz: float = DEFAULT_PIC_MHZ) -> None:
        self.clock = clock
        self.network = network
        self.link = link
        self.db = Database()
        self.can = MasterCan(clock, network, self.db)
        # the mode supervisor (docs/supervisor.md), beyond the seeds
        self.supervisor = Supervisor(clock, self.db, self.can, ROUND_US, supervisor)
        self.usart = Usart(clock, link, self.db, self.can, self.supervisor)
        self.pic = Pic(clock, self.usart, self.can, self.db, self.supervisor, pic_mhz)
        self.main()

    def main(self) -> None:
        """``main`` (module Master): ``initPic``, then the dummy task (nothing: interrupts only)."""
        self.pic.initPic()

    def reset_receiver(self) -> None:
        """Reset the Master's serial receiver (``usartResetRxBuff``, seed 000 table 2): a frame
        half received is dropped, stream mode left. ``serve`` calls it when a client arrives, so
        that no byte of the previous client completes the next one's first frame."""
        self.usart.usartResetRxBuff()

    @property
    def controller(self) -> CanController:
        """The Master's CAN controller (TEC/REC/state)."""
        ctl = self.can.drivers.controller
        assert ctl is not None
        return ctl

    def stats(self) -> dict[str, int]:
        """Counters for the recording (docs/master.md): serial frames, CAN frames, rounds, and
        the bitmask of the slaves that answered in the last complete round."""
        d = self.db.counters.as_dict()
        d["answered_mask"] = self.db.answered_mask
        d["can_rx_overflows"] = self.can.drivers.rx_overflows
        return d
