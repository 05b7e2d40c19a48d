"""The CAN wire through a foreign python-can interface (``virtual``, ``socketcan``).

With ``--can-interface virtual`` (or socketcan on a vcan channel) each node owns a real
python-can bus of that interface; the wire's virtual-time timing and arbitration stay the
twin's own (``network.py``): at the end of each frame the sender's bus sends it and every other
node's bus is drained, and the frames it receives (filtered by python-can, or by the kernel on
socketcan) reach the node's receive interrupt as the wire's own frames
(:class:`~humanoid_twin.bus.frames.Frame`), stamped with the virtual time. The frames and
their instants are the same as on the default ``humanoid_twin`` interface (tests/bus/test_bus_can.py).
"""

from __future__ import annotations

from typing import Protocol

import can

from humanoid_twin.bus.confinement import ErrorConfinement
from humanoid_twin.bus.frames import Frame, as_message
from humanoid_twin.clock import US_PER_S


class ForeignNode(Protocol):
    """What the foreign path uses of a node: a ``CanController`` of network.py, named by its
    members here, so that this module, below the wire's, imports nothing from it."""

    bus: can.BusABC

    def accepts(self, arbitration_id: int) -> bool: ...

    def receive_drained(self, msg: Frame) -> None: ...


def open_foreign_bus(interface: str, channel: str,
                     can_filters: can.typechecking.CanFilters | None) -> can.BusABC:
    """A node's own bus on a foreign python-can interface (its acceptance filters applied)."""
    kwargs: dict = {}
    if interface == "virtual":
        kwargs["preserve_timestamps"] = True
    return can.Bus(interface=interface, channel=channel, can_filters=can_filters,
                   receive_own_messages=False, **kwargs)


class ForeignPath(ErrorConfinement):
    """Frame delivery through a foreign python-can interface (between ``ErrorConfinement`` and
    ``CanNetwork`` in the wire's one inheritance chain; it reads the wire's ``interface``,
    ``channel`` and ``_nodes``)."""

    __slots__ = ()

    def _send_and_drain(self, ctrl: ForeignNode, msg: Frame | can.Message, t_us: int) -> None:
        """Another python-can interface: put the frame on the sender's bus (as a python-can
        message), drain the others."""
        ctrl.bus.send(as_message(msg))
        ts = t_us / US_PER_S
        socket_like = self.interface != "virtual"
        for c in self._nodes:
            if c is ctrl:
                continue
            expected = socket_like and c.accepts(msg.arbitration_id)
            bus = c.bus
            while True:
                m = bus.recv(timeout=0)
                if m is None and expected:
                    m = bus.recv(timeout=0.05)   # kernel loopback may lag a little
                if m is None:
                    break
                expected = False
                c.receive_drained(Frame(m.arbitration_id, m.data, ts, self.channel, True))

