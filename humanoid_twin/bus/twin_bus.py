"""The project's own python-can interface, ``interface="humanoid_twin"``.

Buses opened on the same channel name share one medium (in this process). ``send(msg)``
delivers the frame at once, and only to the other members whose acceptance filters (python-can
``can_filters``: ``can_id``/``can_mask``, the PIC's masks and filters of seed 002 slide 23) take
it. A member with an ``rx_callback`` (its receive-interrupt line) has it called with the message;
the others queue it for ``recv()``. A member that also names its ``rx_ids`` (the identifiers its
interrupt acts on) has a frame its filters take with another identifier only counted
(``rx_skipped``), without the call: what an interrupt whose first act is to drop such a frame
would do (a Slave's ``lowISR``, whose slide 23 mask lets in every Master frame).

When a :class:`~humanoid_twin.bus.network.CanNetwork` owns the channel, frames sent by a bus
that is not one of the network's nodes (a user script, a python-can tool) are handed to the
network, which puts them on the wire in virtual time (arbitration, frame length), like any
node's. The network's own nodes are delivered through ``deliver`` at the end of each frame.

The wire's per-frame path goes through each bus's :class:`RxPort` (``TwinBus.port``; the
compiled core makes it an extension type the wire calls directly): the routes of the frames the
bus sends and the count of frames it only counts. ``TwinBus.deliver`` is that port's
``deliver``.

The delivery is zero-copy: every receiver gets the same object. Treat a received message as
read-only. The frames the network's nodes send are the wire's own record
(:class:`~humanoid_twin.bus.frames.Frame`, python-can's attribute names): the nodes' receive
interrupts get it as it is, every other member (a tool's ``rx_callback`` or ``recv()``) a
:class:`can.Message`.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Collection
from typing import Any, Protocol

import can
from can.bus import BusABC

from humanoid_twin.bus.frames import Filters, Frame, as_message, filters_accept, parse_filters
from humanoid_twin.protocol.canframes import STD_ID_MAX

DEFAULT_CHANNEL = "humanoid_twin"

RxCallback = Callable[[can.Message], None]


class _Wire(Protocol):
    """What the medium needs from a network that owns the channel."""

    def external_send(self, bus: TwinBus, msg: can.Message) -> None: ...


class _Medium:
    """All TwinBus members of one channel (the electrical bus)."""

    __slots__ = ("channel", "members", "wire", "_routes")

    def __init__(self, channel: str) -> None:
        self.channel = channel
        self.members: list[TwinBus] = []
        self.wire: _Wire | None = None
        # (arbitration_id, is_extended) -> members whose filters accept it
        self._routes: dict[tuple[int, bool], tuple[TwinBus, ...]] = {}

    def invalidate(self) -> None:
        self._routes.clear()
        for b in self.members:
            b.forget_routes()

    def route(self, arbitration_id: int, is_extended: bool) -> tuple[TwinBus, ...]:
        key = (arbitration_id, is_extended)
        r = self._routes.get(key)
        if r is None:
            r = tuple(b for b in self.members
                      if not b.muted and b.accepts(arbitration_id, is_extended))
            self._routes[key] = r
        return r


_MEDIA: dict[str, _Medium] = {}
_MEDIA_LOCK = threading.Lock()


def _join(bus: TwinBus, channel: str) -> _Medium:
    with _MEDIA_LOCK:
        medium = _MEDIA.get(channel)
        if medium is None:
            medium = _MEDIA[channel] = _Medium(channel)
        medium.members.append(bus)
        medium.invalidate()
        return medium


def _leave(bus: TwinBus) -> None:
    with _MEDIA_LOCK:
        medium = bus._medium
        if bus in medium.members:
            medium.members.remove(bus)
            medium.invalidate()
        if not medium.members and medium.wire is None and _MEDIA.get(medium.channel) is medium:
            del _MEDIA[medium.channel]


def get_medium(channel: str) -> _Medium:
    """The medium of ``channel`` (created if needed); used by CanNetwork to own a channel."""
    with _MEDIA_LOCK:
        medium = _MEDIA.get(channel)
        if medium is None:
            medium = _MEDIA[channel] = _Medium(channel)
        return medium


def release_medium(medium: _Medium) -> None:
    """Forget an empty medium (the owning network shut down)."""
    with _MEDIA_LOCK:
        medium.wire = None
        if not medium.members and _MEDIA.get(medium.channel) is medium:
            del _MEDIA[medium.channel]


def _copy(msg: Frame | can.Message) -> can.Message:
    if type(msg) is Frame:
        return msg.to_message()
    return can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id,
                       is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                       is_error_frame=msg.is_error_frame, channel=msg.channel, dlc=msg.dlc,  # type: ignore[arg-type]  # a channel name
                       data=bytearray(msg.data), is_fd=msg.is_fd, is_rx=msg.is_rx,
                       bitrate_switch=msg.bitrate_switch,  # type: ignore[union-attr]  # a Message here
                       error_state_indicator=msg.error_state_indicator)  # type: ignore[union-attr]  # as above


class RxPort:
    """A bus's side of the per-frame path: what the wire calls at the end of each frame the bus
    sent, and what the other members' deliveries count for it.

    ``routes``: a table indexed by the standard ID (0..0x7FF; None where no route is kept yet) of
    (the receive interrupts of the members that take the bus's frame with that ID, the ports of
    the members that only count it, outside their ``rx_ids``), kept when every target has an
    interrupt (the common case: no per-member work, no dict lookup per frame).
    ``rx_skipped``: frames this bus's filters took outside its ``rx_ids`` (:attr:`TwinBus.rx_skipped`).
    """

    __slots__ = ("bus", "routes", "rx_skipped")

    def __init__(self, bus: TwinBus) -> None:
        self.bus = bus
        self.routes: list[tuple[tuple[RxCallback, ...], tuple[RxPort, ...]] | None] = _no_routes()
        self.rx_skipped = 0

    def deliver(self, msg: Frame | can.Message) -> None:
        """:meth:`TwinBus.deliver`: hand ``msg`` (already on the wire) to every accepting member."""
        if type(msg) is Frame:
            frame = msg
            arb = frame.arbitration_id
            extended = False
        else:
            arb = msg.arbitration_id
            extended = msg.is_extended_id
        route = self.routes[arb] if not extended and 0 <= arb <= STD_ID_MAX else None
        if route is None:
            self.bus._deliver_slow(msg)
            return
        cbs, skips = route
        for cb in cbs:
            cb(msg)     # type: ignore[arg-type]  # the network's own nodes take Frames
        for p in skips:
            p.rx_skipped += 1


def _no_routes() -> list:
    """An empty route table: one entry per standard ID."""
    return [None] * (STD_ID_MAX + 1)


def active_channels() -> list[str]:
    """Names of the channels that have members or an owning network."""
    with _MEDIA_LOCK:
        return sorted(_MEDIA)


class TwinBus(BusABC):
    """An in-process CAN bus member delivering only frames its acceptance filters take.

    ``can.Bus(interface="humanoid_twin", channel="x", can_filters=[...])`` opens one.

    :param channel: channel name; buses with the same name share one medium.
    :param can_filters: python-can filters (``can_id``, ``can_mask``, optional ``extended``).
    :param receive_own_messages: also deliver this bus's own frames to itself.
    :param rx_callback: called with each accepted frame instead of queueing it (an interrupt).
    :param rx_ids: with ``rx_callback``: the standard identifiers it acts on. An accepted frame
        with another identifier is counted in :attr:`rx_skipped` and not handed to it (None:
        every accepted frame is).
    """

    def __init__(
        self,
        channel: Any = None,
        can_filters: can.typechecking.CanFilters | None = None,
        receive_own_messages: bool = False,
        rx_callback: RxCallback | None = None,
        rx_ids: Collection[int] | None = None,
        **kwargs: object,
    ) -> None:
        if channel is None:
            channel = DEFAULT_CHANNEL
        if not isinstance(channel, str) or not channel:
            raise ValueError(f"humanoid_twin channel must be a non-empty string, got {channel!r}")
        self.channel = channel
        self.channel_info = f"humanoid_twin channel {channel}"
        self.receive_own_messages = bool(receive_own_messages)
        self._rx_callback: RxCallback | None = rx_callback
        self._rx_ids: frozenset[int] | None = None if rx_ids is None else frozenset(rx_ids)
        # the per-frame path: the routes of this bus's frames and its count of frames outside
        # rx_ids (RxPort)
        self.port = RxPort(self)
        self.deliver = self.port.deliver  # type: ignore[method-assign]  # the port's, one call less
        self._queue: deque[can.Message] = deque()
        self._cond = threading.Condition()
        self._waiting = 0
        self._filt: Filters | None = None
        self._network_node = False  # set by CanNetwork for its own nodes
        self._muted = False         # a bus-off node: receives nothing (set by CanNetwork)
        self._medium = _join(self, channel)
        try:
            super().__init__(channel=channel, can_filters=can_filters, **kwargs)
        except BaseException:
            _leave(self)
            raise

    @property
    def rx_callback(self) -> RxCallback | None:
        """The receive interrupt called with each accepted frame (None: frames queue for recv)."""
        return self._rx_callback

    @rx_callback.setter
    def rx_callback(self, cb: RxCallback | None) -> None:
        self._rx_callback = cb
        medium = getattr(self, "_medium", None)
        if medium is not None:
            medium.invalidate()

    def delivery_callback(self) -> RxCallback:
        """What a route calls for this member: a network node's receive interrupt takes the
        wire's :class:`~humanoid_twin.bus.frames.Frame` as it is; any other ``rx_callback`` (a
        tool's) gets a :class:`can.Message`."""
        cb = self._rx_callback
        assert cb is not None
        if self._network_node:
            return cb

        def as_python_can(msg: Frame | can.Message) -> None:
            cb(as_message(msg))
        return as_python_can

    def forget_routes(self) -> None:
        """Drop the cached delivery routes (the medium's members, filters or mutes changed)."""
        self.port.routes = _no_routes()

    @property
    def rx_skipped(self) -> int:
        """Accepted frames outside ``rx_ids``: counted, not handed to ``rx_callback``."""
        return self.port.rx_skipped

    # -- filters -----------------------------------------------------------------------------
    def _apply_filters(self, filters: can.typechecking.CanFilters | None) -> None:
        """Precompute the filters as int tuples (no dict work per frame; ``frames.parse_filters``)."""
        self._filt = parse_filters(filters)
        medium = getattr(self, "_medium", None)
        if medium is not None:
            medium.invalidate()

    def skips(self, arbitration_id: int, is_extended: bool = False) -> bool:
        """Whether an accepted frame with that ID is only counted (outside ``rx_ids``), not handed
        to ``rx_callback``."""
        ids = self._rx_ids
        return (ids is not None and self._rx_callback is not None and not is_extended
                and arbitration_id not in ids)

    def accepts(self, arbitration_id: int, is_extended: bool = False) -> bool:
        """Whether this bus's acceptance filters take a frame with that ID."""
        return filters_accept(self._filt, arbitration_id, is_extended)

    # -- the wire's side (CanNetwork) ----------------------------------------------------------
    def mark_network_node(self) -> None:
        """This bus is a node of the channel's network: its sends go through the network's own
        arbitration (``CanController.send``), and the network delivers its frames to it."""
        self._network_node = True

    @property
    def muted(self) -> bool:
        """A bus-off node: receives nothing."""
        return self._muted

    def set_muted(self, muted: bool) -> None:
        """Mute (bus-off) or unmute this bus's reception (the network's error confinement)."""
        self._muted = bool(muted)
        self._medium.invalidate()

    # -- transmit ------------------------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Put ``msg`` on the channel.

        Without a network owning the channel the frame is delivered immediately; with one, a
        frame from an outside bus joins the network's virtual-time arbitration.
        """
        if self._is_shutdown:
            raise can.CanOperationError("cannot send on a bus that was shut down")
        if not isinstance(msg, can.Message):
            raise TypeError(f"send() needs a can.Message, got {type(msg).__name__}")
        wire = self._medium.wire
        if wire is not None and not self._network_node:
            wire.external_send(self, msg)
            return
        if msg.channel is None:
            msg.channel = self.channel
        if not msg.timestamp:
            msg.timestamp = time.time()
        self.deliver(msg)

    def deliver(self, msg: Frame | can.Message) -> None:
        """Hand ``msg`` (already on the wire) to every accepting member of the channel.

        (The class's form, for the docs: each instance's ``deliver`` is its :attr:`port`'s,
        which takes a route kept from an earlier frame, else this bus's ``_deliver_slow``.)"""
        self.port.deliver(msg)

    def _deliver_slow(self, msg: Frame | can.Message) -> None:
        """:meth:`deliver` of a frame with no kept route: the medium's route, kept for the next
        frame with this ID when every target has an interrupt, else each target served in turn."""
        extended = msg.is_extended_id
        arb = msg.arbitration_id
        route = self._medium.route(arb, extended)
        targets = [b for b in route if b is not self or self.receive_own_messages]
        if not extended and 0 <= arb <= STD_ID_MAX and all(b.rx_callback is not None for b in targets):
            skips = tuple(b.port for b in targets if b.skips(arb))
            self.port.routes[arb] = (
                tuple(b.delivery_callback() for b in targets if b.port not in skips), skips)
            self.port.deliver(msg)
            return
        for bus in targets:
            cb = bus.rx_callback
            if bus.skips(arb, extended):
                bus.port.rx_skipped += 1
            elif cb is not None:
                cb(msg if bus._network_node else as_message(msg))  # type: ignore[arg-type]  # as above
            else:
                # a queueing reader (a tool) reads later: give it its own copy, the sender may
                # reuse its message object once the frame is done (the twin's boards do)
                bus._queue.append(_copy(msg))
                if bus._waiting:
                    with bus._cond:
                        bus._cond.notify()

    # -- receive -------------------------------------------------------------------------------
    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        q = self._queue
        if q:
            return q.popleft(), True
        if timeout is not None and timeout <= 0:
            return None, True
        with self._cond:
            self._waiting += 1
            try:
                self._cond.wait_for(lambda: bool(q) or self._is_shutdown, timeout)
            finally:
                self._waiting -= 1
        if q:
            return q.popleft(), True
        return None, True

    @property
    def pending(self) -> int:
        """Number of frames queued for ``recv()``."""
        return len(self._queue)

    def shutdown(self) -> None:
        """Detach from the medium."""
        if self._is_shutdown:
            return
        super().shutdown()
        _leave(self)
        with self._cond:
            self._cond.notify_all()

    def __del__(self) -> None:
        # no OS resources: leaving the medium quietly is enough (BusABC would log a warning)
        if not self._is_shutdown:
            self.shutdown()

    @staticmethod
    def _detect_available_configs() -> list[can.typechecking.AutoDetectedConfig]:
        return [{"interface": "humanoid_twin", "channel": ch} for ch in active_channels()]
