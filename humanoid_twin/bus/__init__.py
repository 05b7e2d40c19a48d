"""The buses: the CAN wire (Master <-> Slaves) and the RS-232 cable (PC <-> Master).

Importing this package registers the ``twin://`` pyserial URL handler
(``serial.protocol_handler_packages``) and the python-can interface ``humanoid_twin`` is an
entry point of the project. See docs/buses.md.
"""

from __future__ import annotations

import serial as _serial

from humanoid_twin.bus.bridges import PtyBridge, TcpBridge
from humanoid_twin.bus.frames import frame_bits, max_frame_bits
from humanoid_twin.bus.network import (
    BUS_OFF,
    ERROR_ACTIVE,
    ERROR_PASSIVE,
    ERROR_STATE_CODE,
    CanController,
    CanError,
    CanNetwork,
)
from humanoid_twin.bus.protocol_twin import register_link, registered_links, unregister_link
from humanoid_twin.bus.serial_link import SerialLink
from humanoid_twin.bus.twin_bus import TwinBus

if "humanoid_twin.bus" not in _serial.protocol_handler_packages:
    _serial.protocol_handler_packages.append("humanoid_twin.bus")

__all__ = [
    "BUS_OFF",
    "ERROR_ACTIVE",
    "ERROR_PASSIVE",
    "ERROR_STATE_CODE",
    "CanController",
    "CanError",
    "CanNetwork",
    "PtyBridge",
    "SerialLink",
    "TcpBridge",
    "TwinBus",
    "frame_bits",
    "max_frame_bits",
    "register_link",
    "registered_links",
    "unregister_link",
]
