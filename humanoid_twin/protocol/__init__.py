"""The byte and frame formats of the robot's two buses (seed 002 slides 7-11, 18-23).

- :mod:`humanoid_twin.protocol.wire`: the facts both buses share, once (addresses and
  :func:`~humanoid_twin.protocol.wire.check_scu`, the +-90 degree position range, ``ControlType``,
  ``ErrorState``, the Control and Status byte bits, int8 bytes, the 115200 8E1 line settings).
- :mod:`humanoid_twin.protocol.rs232`: 6-byte frames between the host (PC) and the Master.
- :mod:`humanoid_twin.protocol.canframes`: CAN identifiers, acceptance filters and 8-byte payloads
  between the Master and the Slaves, and the shipped DBC (:func:`canframes.load_dbc`).

Pure codecs: no I/O, no time. The contract is ``docs/protocol.md``.
"""

from humanoid_twin.protocol import canframes, rs232, wire
from humanoid_twin.protocol.canframes import PayloadError
from humanoid_twin.protocol.rs232 import FrameError
from humanoid_twin.protocol.wire import ControlType, ErrorState, check_scu

__all__ = ["canframes", "rs232", "wire", "FrameError", "PayloadError", "ControlType", "ErrorState",
           "check_scu"]
