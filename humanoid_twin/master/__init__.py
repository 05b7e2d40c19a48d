"""The Master board firmware (seed 000 section 2): modules Master, PIC, USART, CAN, CANDRIVERS and
the global database (seed 002 slide 32). See docs/master.md."""

from humanoid_twin.master.database import Database
from humanoid_twin.master.master import Master

__all__ = ["Master", "Database"]
