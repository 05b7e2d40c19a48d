"""The byte and frame formats of the robot's two buses (seed 002 slides 7-11, 18-23).

- :mod:`humanoid_twin.protocol.rs232`: 6-byte frames between the host (PC) and the Master.
- :mod:`humanoid_twin.protocol.canframes`: CAN identifiers, acceptance filters and 8-byte payloads
  between the Master and the Slaves, and the shipped DBC (:func:`canframes.load_dbc`).

Pure codecs: no I/O, no time. The contract is ``docs/protocol.md``.
"""

from humanoid_twin.protocol import canframes, rs232
from humanoid_twin.protocol.canframes import PayloadError
from humanoid_twin.protocol.rs232 import FrameError

__all__ = ["canframes", "rs232", "FrameError", "PayloadError"]
