"""The CAN wire in virtual time: arbitration by ID, frame bit times, error confinement.

``CanNetwork`` is the 1 Mbit/s bus between the Master and the 8 Slaves (seed 002 slides 13-30,
docs/buses.md). Each board attaches one ``CanController`` (its PIC18F258 CAN module: 3 TX
buffers, the acceptance mask/filters of slide 23 as python-can ``can_filters``, TEC/REC and the
error states). Every controller owns a real python-can bus: by default the project's own
``humanoid_twin`` interface (:mod:`humanoid_twin.bus.twin_bus`), or python-can's ``virtual`` or
``socketcan`` by option.

Timing (all integer microseconds on the lockstep :class:`~humanoid_twin.clock.Clock`):

* ``send`` requests transmission at ``clock.now_us`` (TXREQ).
* When the wire is idle, the pending frame with the lowest ID wins arbitration (ties, which
  the protocol never produces, go to the earlier request). Every request made up to and
  including the instant the frame starts (its SOF bit) takes part.
* The frame occupies ``frame_bits(id, data)`` bit times. At the end of its EOF
  (``start + frame_bits - 3`` bits) it is put on the sender's python-can bus with
  ``timestamp`` = that instant in seconds: the receivers' ``on_rx`` (their RXBnIF) run then,
  and the listeners get it. The wire is idle again after the 3-bit intermission.
* ``abort()`` (TXABT) drops the controller's frames that have not started; a frame already on
  the wire finishes, but is not retransmitted if it fails.

See docs/buses.md for the error-confinement rules and the fault-injection hooks.
"""

from __future__ import annotations

import itertools
import random
from collections.abc import Callable, Collection

import can

from humanoid_twin.bus.confinement import (  # noqa: F401  (re-exported: the error-state names)
    BUS_OFF,
    BUS_OFF_LIMIT,
    ERROR_ACTIVE,
    ERROR_PASSIVE,
    ERROR_STATE_CODE,
    PASSIVE_LIMIT,
    RECOVERY_SEQUENCES,
)
from humanoid_twin.bus.foreign import ForeignPath, open_foreign_bus
from humanoid_twin.bus.frames import (
    TRAILING_RECESSIVE_BITS,
    Filters,
    Frame,
    _frame_bits_cached,  # compiled core: the uncached C function _frame_bits instead (network.pxd)
    filters_accept,
    load_frame,
    parse_filters,
)
from humanoid_twin.bus.twin_bus import RxPort, TwinBus, get_medium, release_medium
from humanoid_twin.clock import US_PER_S, Clock
from humanoid_twin.protocol.canframes import CAN_BITRATE, PIC_TX_BUFFERS, STD_ID_MAX

TWIN_INTERFACE = "humanoid_twin"
EXTERNAL_TX_QUEUE = 64          # an outside python-can bus (a tool): a socketcan-like TX queue

# error frame after a CRC error: detected after the ACK delimiter, 6-bit error flag, 8-bit
# error delimiter, 3-bit intermission: an error frame takes frame_bits - 10 + 17 bits.
ERROR_FLAG_BITS = 6
ERROR_EXTRA_BITS = 7            # (6 flag + 8 delimiter + 3 IFS) - (7 EOF + 3 IFS)
SUSPEND_BITS = 8                # error-passive transmitter: suspend transmission after IFS

_OK, _DROP, _CORRUPT = 0, 1, 2
_MAX_INLINE = 4                 # nested frame ends handled inline at most (a bounded call depth)
_channel_ids = itertools.count(1)


class CanError(ValueError):
    """A frame the PIC18F258 configuration of the robot cannot send (seed 002 slide 24)."""


class CanController:
    """One node's CAN module (PIC18F258): 3 TX buffers, TEC/REC, error state.

    Created by :meth:`CanNetwork.attach`. ``bus`` is the node's real python-can bus.
    """

    __slots__ = (
        "name", "bus", "tec", "rec", "state", "silenced", "recovering",
        "frames_sent", "tx_refused", "tx_aborted", "tx_errors", "rx_errors",
        "bus_off_count", "recoveries",
        "_net", "_on_rx", "_tx_buffers", "_n_pending", "_off", "_suspend_until",
        "_rec_count", "_rec_mark", "_filt", "_external", "_loaded", "_loaded_bits", "_port",
    )

    def __init__(self, network: CanNetwork, name: str, on_rx: Callable[[Frame], None] | None,
                 tx_buffers: int = PIC_TX_BUFFERS, external: bool = False) -> None:
        if on_rx is None:
            on_rx = _ignore
        self.name = name
        self.bus: can.BusABC = None  # type: ignore[assignment]  # set by the network
        self.tec = 0
        self.rec = 0
        self.state = ERROR_ACTIVE
        self.silenced = False
        self.recovering = False
        self.frames_sent = 0
        self.tx_refused = 0
        self.tx_aborted = 0
        self.tx_errors = 0
        self.rx_errors = 0
        self.bus_off_count = 0
        self.recoveries = 0
        self._net = network
        self._on_rx = on_rx
        self._tx_buffers = tx_buffers
        self._n_pending = 0
        self._off = False
        self._suspend_until = 0
        self._rec_count = 0
        self._rec_mark = 0
        self._filt: Filters | None = None
        self._external = external
        self._loaded: Frame | None = None          # the frame load_tx built, checked, until sent
        self._loaded_bits = 0
        self._port: RxPort | None = None           # the TwinBus's receive side (set by attach)

    def __repr__(self) -> str:
        return (f"CanController({self.name!r}, {self.state}, tec={self.tec}, rec={self.rec}, "
                f"pending={self._n_pending})")

    # -- the firmware's API ------------------------------------------------------------------
    def send(self, msg: Frame | can.Message) -> bool:
        """Request transmission of ``msg`` now (TXREQ on a free TX buffer: myCANSendMessage).

        Returns False, and counts ``tx_refused``, when all 3 TX buffers are pending or the
        node is bus-off. ``msg``: the :class:`~humanoid_twin.bus.frames.Frame` of
        :meth:`load_tx`, or a :class:`can.Message` (checked, and carried as a frame of its
        own). The frame is handed over: do not modify it until it is sent or aborted (like the
        PIC's TX buffer registers while TXREQ is set).
        """
        return self._net._request(self, msg)

    def send_at(self, msg: Frame | can.Message, t_us: int) -> bool:
        """:meth:`send` with its TXREQ at ``t_us`` (``now <= t_us``), for a caller that knows
        nothing runs on the clock before then (``not clock.due_by(t_us)``): the same as
        scheduling an event at ``t_us`` that calls :meth:`send`, without the event (a Slave's
        answer, ``ISR_LATENCY_US`` after the actuation packet). Checks are made now; the frame
        joins arbitration at ``t_us``. ``ValueError`` if an event is due before ``t_us``."""
        net = self._net
        clock = net.clock
        if t_us < clock.now_us or clock.due_by(t_us):
            raise ValueError(f"send_at({t_us}): an event is due before it "
                             f"(now {clock.now_us}, next {clock.next_due_us()})")
        return net._request(self, msg, t_us)

    def abort(self) -> int:
        """Abort every TX not yet on the wire (TXABT). Returns how many frames were dropped."""
        if not self._n_pending:
            # nothing requested: nothing to drop (a frame of ours still on the wire would have
            # kept _n_pending up, unless we are bus-off, where it cannot be retransmitted anyway)
            return 0
        return self._net._abort(self)

    def clear_status(self) -> None:
        """Reset the error state (canClearStatus on the Master, the recovery in checkCan).

        A bus-off node starts the bus-off recovery: after 128 occurrences of 11 consecutive
        recessive bits on the wire it is error-active again with TEC = REC = 0 (``recovering``
        is True meanwhile). A node that is not bus-off has its counters reset at once (the
        module is re-initialised through configuration mode).
        """
        self._net._clear_status(self)

    @property
    def pending(self) -> int:
        """TX buffers in use (requested frames not yet completed or aborted)."""
        return self._n_pending

    @property
    def rx_skipped(self) -> int:
        """Frames the acceptance filters took that were outside the node's ``rx_ids`` (only
        counted, not handed to its RX interrupt; :meth:`CanNetwork.attach`)."""
        port = self._port
        return port.rx_skipped if port is not None else 0

    def load_tx(self, msg: Frame | None, arbitration_id: int, payload: bytes) -> Frame:
        """The frame to hand to :meth:`send`: ``msg`` (a :class:`~humanoid_twin.bus.frames.Frame`
        this method returned) reloaded with ``payload`` (like loading the PIC's TXBn registers)
        when this controller holds none of the node's frames any more, else a new frame (a
        pending frame, or one on the wire while bus-off, must not change). The frame is checked
        (``CanError``) and its bit length computed here, once: hand it to :meth:`send`
        unchanged."""
        data = payload if type(payload) is bytes else bytes(payload)
        n = len(data)
        if not 0 <= arbitration_id <= STD_ID_MAX:
            raise CanError(f"{self.name}: standard CAN ID must be 0..0x7FF, got {arbitration_id:#x}")
        if n > 8:
            raise CanError(f"{self.name}: a frame carries 0..8 data bytes, got {n}")
        # checked and measured here, once: send() of this frame skips both. Measured again only
        # for another ID or payload than the frame's last load: a board mostly reloads the same
        # bytes (the Master's actuation payloads are kept, the same object, until the host
        # changes them; a Slave's sensor packets change at most once per tick)
        last = msg if type(msg) is Frame else None
        if (last is not None and last.bits and last.arbitration_id == arbitration_id
                and (last.data is data or last.data == data)):
            bits = last.bits
        else:
            bits = _frame_bits_cached(arbitration_id, data)
        if last is None or self._n_pending or self._off:   # _off: the state is BUS_OFF
            frame = load_frame(None, arbitration_id, data, bits)
        else:
            frame = load_frame(last, arbitration_id, data, bits)
        self._loaded = frame
        self._loaded_bits = bits
        return frame

    @property
    def error_state_code(self) -> int:
        """0 error-active, 1 error-passive, 2 bus-off (ERRSTATE of the CAN status, docs/protocol.md)."""
        return ERROR_STATE_CODE[self.state]

    # -- receive interrupt ---------------------------------------------------------------------
    def accepts(self, arbitration_id: int) -> bool:
        """Whether this node's acceptance filters (slide 23) let a frame with this ID in."""
        return filters_accept(self._filt, arbitration_id)

    def receive_drained(self, msg: Frame) -> None:
        """The receive interrupt for a frame drained from another python-can interface (the twin
        bus calls it directly); nothing while bus-off."""
        if not self._off:
            self._on_rx(msg)


class _Request:
    """One TXREQ waiting for the wire (or on it): the arbitration ``key`` (the ID << 40, then the
    request's order: ties never happen in the protocol), the instant ``req`` it joins arbitration,
    the node ``ctrl``, its ``frame`` and the frame's length ``bits``. The wire's own record (typed
    C fields in the compiled core: bus/network.pxd); :class:`CanNetwork` keeps the records of
    finished requests for the next ones (``_release``)."""

    __slots__ = ("key", "req", "ctrl", "frame", "bits")
    key: int
    req: int
    ctrl: CanController
    frame: Frame
    bits: int


class CanNetwork(ForeignPath):
    """The CAN wire: virtual-time frame timing, arbitration by ID, error counters.

    This module holds the wire's timing and arbitration; the error confinement (TEC/REC,
    error-passive, bus-off and its recovery) is ``bus/confinement.py`` and the path through a
    foreign python-can interface (virtual, socketcan) is ``bus/foreign.py``: one inheritance
    chain, ``ErrorConfinement`` <- ``ForeignPath`` <- ``CanNetwork``.

    :param clock: the twin's lockstep clock.
    :param interface: ``"humanoid_twin"`` (default, filtered zero-copy delivery), ``"virtual"``
        or ``"socketcan"`` (then ``channel`` is e.g. ``"vcan0"``), or any python-can interface.
    :param channel: channel name; None gives a fresh unique name.
    :param bitrate: bits per second (:data:`~humanoid_twin.protocol.canframes.CAN_BITRATE`,
        1 Mbit/s on the robot, also the PIC's highest).
    """

    def __init__(self, clock: Clock, interface: str = TWIN_INTERFACE, channel: str | None = None,
                 bitrate: int = CAN_BITRATE) -> None:
        if not isinstance(bitrate, int) or not 0 < bitrate <= CAN_BITRATE:
            raise ValueError(f"CAN bitrate must be an int in 1..{CAN_BITRATE} bit/s, got {bitrate!r}")
        if interface != TWIN_INTERFACE and interface not in can.VALID_INTERFACES:
            raise ValueError(f"unknown python-can interface {interface!r} "
                             f"(known: {', '.join(sorted(can.VALID_INTERFACES))})")
        if channel is None:
            if interface == "socketcan":
                raise ValueError("interface='socketcan' needs a channel, e.g. channel='vcan0'")
            channel = f"twin-{next(_channel_ids)}"
        self.clock = clock
        self.interface = interface
        self.channel = channel
        self.bitrate = bitrate
        # integer microseconds per bit when the bitrate allows (1 us at 1 Mbit/s), else 0
        self._bit_us = US_PER_S // bitrate if US_PER_S % bitrate == 0 else 0
        self._twin = interface == TWIN_INTERFACE
        self._medium = None
        if self._twin:
            medium = get_medium(channel)
            if medium.wire is not None:
                raise ValueError(f"CAN channel {channel!r} already belongs to another CanNetwork")
            medium.wire = self
            self._medium = medium
        self._controllers: dict[str, CanController] = {}
        self._nodes: list[CanController] = []          # attached nodes (not outside tools)
        self._external: dict[int, CanController] = {}
        self._listeners: list[can.Listener] = []
        self._recovering: list[CanController] = []
        # wire state
        # the requests not on the wire yet, _pending[:_n_req] (in no order), and the records of
        # finished requests, _spare[:_n_spare]: both lists only grow, their slots are reused (no
        # list operation and no allocation a frame)
        self._pending: list[_Request] = []
        self._n_req = 0
        self._spare: list[_Request] = []
        self._n_spare = 0
        self._busy = False          # a decision is scheduled or a frame/error frame is on the wire
        self._start = 0             # start (SOF) of the frame being decided / on the wire
        self._current: _Request | None = None
        self._current_aborted = False
        self._outcome = _OK
        self._idle_from = 0         # the wire is idle from this instant (end of last IFS)
        self._dom_end = 0           # end of the last dominant bit on the wire
        self._seq = 0
        self._rec_dirty = False     # some REC may be > 0
        self._inline = 0            # frame ends being handled inline (Clock.skip_to), nested
        # faults
        self._faults_on = False
        self._drop_prob = 0.0
        self._corrupt_prob = 0.0
        self._rng = random.Random(0)
        # counters
        self.frames_sent = 0
        self.frames_dropped = 0
        self.error_frames = 0
        self.busy_us = 0
        self._closed = False
        # bound methods used as clock callbacks (no allocation per frame)
        self._decide_cb = self._decide
        self._complete_cb = self._complete
        self._error_cb = self._error

    # -- setup -------------------------------------------------------------------------------
    def attach(self, name: str, can_filters: can.typechecking.CanFilters | None,
               on_rx: Callable[[Frame], None] | None, rx_ids: Collection[int] | None = None) -> CanController:
        """Connect a node: its acceptance filters (slide 23) and its RX interrupt ``on_rx``, called
        with each frame as a :class:`~humanoid_twin.bus.frames.Frame` (python-can's attribute
        names; on every interface, and for frames a tool sent as a ``can.Message``).

        ``rx_ids``: the standard identifiers ``on_rx`` acts on, when the filters let in more
        (a Slave's mask lets in every Master frame; its ``lowISR`` drops the frames for other
        boards at once). On this project's own interface a frame the filters take with
        another identifier is only counted (:attr:`CanController.rx_skipped`), without the
        call; on a foreign python-can interface every accepted frame reaches ``on_rx``.
        """
        if self._closed:
            raise RuntimeError("CanNetwork was shut down")
        if not isinstance(name, str) or not name:
            raise ValueError(f"node name must be a non-empty string, got {name!r}")
        if name in self._controllers:
            raise ValueError(f"a node named {name!r} is already attached to {self.channel!r}")
        if on_rx is not None and not callable(on_rx):
            raise TypeError(f"on_rx must be callable, got {on_rx!r}")
        ctrl = CanController(self, name, on_rx)
        ctrl._filt = parse_filters(can_filters)
        if self._twin:
            # the RX interrupt is called straight from the bus; a bus-off node is muted instead
            bus = TwinBus(self.channel, can_filters=can_filters, rx_callback=ctrl._on_rx,  # type: ignore[arg-type]
                          rx_ids=rx_ids)   # (ignore: a network node's callback takes Frames)
            bus.mark_network_node()
            ctrl._port = bus.port
            ctrl.bus = bus
        else:
            ctrl.bus = open_foreign_bus(self.interface, self.channel, can_filters)
        self._controllers[name] = ctrl
        self._nodes.append(ctrl)
        return ctrl

    @property
    def frames_by_node(self) -> dict[str, int]:
        """Frames each node (and each outside tool's bus) put on the wire."""
        return {c.name: c.frames_sent for c in (*self._nodes, *self._external.values())}

    def add_listener(self, listener: can.Listener) -> None:
        """Give ``listener`` every completed frame (virtual timestamps, ``channel`` set), in order.

        Error frames are passed as ``can.Message(is_error_frame=True)``.
        """
        if not hasattr(listener, "on_message_received"):
            raise TypeError(f"a listener needs on_message_received(), got {listener!r}")
        self._listeners.append(listener)

    def remove_listener(self, listener: can.Listener) -> None:
        """Stop giving frames to ``listener``."""
        self._listeners.remove(listener)

    def node(self, name: str) -> CanController:
        """The controller attached under ``name``."""
        try:
            return self._controllers[name]
        except KeyError:
            raise KeyError(f"no CAN node named {name!r} (attached: {sorted(self._controllers)})") from None

    @property
    def nodes(self) -> list[CanController]:
        """The attached controllers, in attach order."""
        return list(self._nodes)

    def shutdown(self) -> None:
        """Shut every node's python-can bus down and release the channel."""
        if self._closed:
            return
        self._closed = True
        for c in self._nodes + list(self._external.values()):
            if not c._external:
                c.bus.shutdown()
        for lst in self._listeners:
            stop = getattr(lst, "stop", None)
            if stop is not None:
                stop()
        if self._medium is not None:
            release_medium(self._medium)

    def __enter__(self) -> CanNetwork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

    # -- fault injection ---------------------------------------------------------------------
    def set_faults(self, drop_prob: float = 0.0, corrupt_prob: float = 0.0, seed: int = 0) -> None:
        """Random frame faults, deterministic per ``seed``.

        ``drop_prob``: the frame completes (the sender counts a success, listeners log it) but
        no node receives it (a lost frame). ``corrupt_prob``: the frame is destroyed by an error
        frame: nobody receives it, sender TEC +8, every other node REC +1, and the sender
        retransmits it automatically.
        """
        for label, p in (("drop_prob", drop_prob), ("corrupt_prob", corrupt_prob)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{label} must be in [0, 1], got {p!r}")
        if drop_prob + corrupt_prob > 1.0:
            raise ValueError("drop_prob + corrupt_prob must not exceed 1")
        self._drop_prob = float(drop_prob)
        self._corrupt_prob = float(corrupt_prob)
        self._faults_on = drop_prob > 0.0 or corrupt_prob > 0.0
        self._rng = random.Random(seed)

    def silence(self, node_name: str, silent: bool = True) -> None:
        """Make a node stop (or resume) transmitting; it still receives. Its requests stay pending."""
        c = self.node(node_name)
        c.silenced = bool(silent)
        if not silent and self._n_req and not self._busy:
            self._kick(self.clock.now_us)

    def force_bus_off(self, node_name: str) -> None:
        """Put a node in bus-off at once (TEC past 255) until its ``clear_status()``."""
        c = self.node(node_name)
        c.tec = BUS_OFF_LIMIT + 1
        self._update_state(c)

    # -- counters ----------------------------------------------------------------------------
    @property
    def bus_load(self) -> float:
        """Fraction of virtual time the wire carried frames (incl. IFS and error frames)."""
        now = self.clock.now_us
        return self.busy_us / now if now > 0 else 0.0

    def stats(self) -> dict:
        """Counters for the recording."""
        return {
            "frames": self.frames_sent,
            "frames_dropped": self.frames_dropped,
            "error_frames": self.error_frames,
            "tx_refused": sum(c.tx_refused for c in self._nodes),
            "tx_aborted": sum(c.tx_aborted for c in self._nodes),
            "bus_load": self.bus_load,
            "frames_by_node": self.frames_by_node,
            "nodes": {c.name: {"state": c.state, "tec": c.tec, "rec": c.rec} for c in self._nodes},
        }

    # -- timing helpers ----------------------------------------------------------------------
    def _dur(self, bits: int) -> int:
        """Duration of ``bits`` bit times in integer microseconds (rounded up)."""
        if self._bit_us:
            return bits * self._bit_us
        br = self.bitrate
        return (bits * US_PER_S + br - 1) // br

    # -- transmit path -----------------------------------------------------------------------
    def _request(self, ctrl: CanController, msg: Frame | can.Message, at: int = -1) -> bool:
        """TXREQ of ``msg`` by ``ctrl`` now (or at ``at``, :meth:`CanController.send_at`)."""
        if ctrl._off or ctrl._n_pending >= ctrl._tx_buffers:
            ctrl.tx_refused += 1
            return False
        if msg is ctrl._loaded:          # built by load_tx: already checked, its length known
            ctrl._loaded = None
            frame = msg
            bits = ctrl._loaded_bits
        else:
            bits = self._checked_bits(ctrl, msg)
            # the wire carries frames of its own: a python-can message is copied into one
            frame = msg if type(msg) is Frame else Frame(msg.arbitration_id, msg.data)  # type: ignore[arg-type]  # Frame copies it with bytes()
        arb = frame.arbitration_id
        self._seq = seq = self._seq + 1
        clock = self.clock
        now = clock.now_us if at < 0 else at
        n = self._n_spare
        if n:
            self._n_spare = n - 1
            r = self._spare[n - 1]
        else:
            r = _Request.__new__(_Request)
        r.key = (arb << 40) | seq       # arbitration: the ID, then request order
        r.req = now
        r.ctrl = ctrl
        r.frame = frame
        r.bits = bits
        self._add(r)
        ctrl._n_pending += 1
        if not self._busy:
            self._kick(now)
        return True

    @staticmethod
    def _checked_bits(ctrl: CanController, msg: Frame | can.Message) -> int:
        """The frame's bit length, after checking it is one the robot's PIC can send."""
        arb = msg.arbitration_id
        if msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame or msg.is_fd:
            raise CanError(
                f"{ctrl.name}: only standard 11-bit data frames are sent (seed 002 slide 24); "
                f"build the message with can.Message(..., is_extended_id=False), got {msg!r}")
        if not 0 <= arb <= STD_ID_MAX:
            raise CanError(f"{ctrl.name}: standard CAN ID must be 0..0x7FF, got {arb:#x}")
        data = msg.data
        n = len(data)
        if n > 8 or msg.dlc != n:
            raise CanError(f"{ctrl.name}: a frame carries 0..8 data bytes with dlc == len(data), "
                           f"got dlc={msg.dlc}, {n} bytes")
        return _frame_bits_cached(arb, bytes(data))

    def external_send(self, bus: TwinBus, msg: can.Message) -> None:
        """A frame sent on this channel by a python-can bus that is not a node (a tool)."""
        ctrl = self._external.get(id(bus))
        if ctrl is None or ctrl.bus is not bus:
            ctrl = CanController(self, f"external:{id(bus):x}", None, EXTERNAL_TX_QUEUE, external=True)
            ctrl.bus = bus
            ctrl._port = bus.port
            self._external[id(bus)] = ctrl
        if not self._request(ctrl, msg):
            raise can.CanOperationError(f"humanoid_twin channel {self.channel}: TX queue full")

    def _add(self, r: _Request) -> None:
        """``r`` joins the pending requests."""
        n = self._n_req
        if n < len(self._pending):
            self._pending[n] = r
        else:
            self._pending.append(r)
        self._n_req = n + 1

    def _release(self, r: _Request) -> None:
        """``r`` is done with (sent, aborted or dropped): its record serves a later request."""
        n = self._n_spare
        if n < len(self._spare):
            self._spare[n] = r
        else:
            self._spare.append(r)
        self._n_spare = n + 1

    def _kick(self, now: int) -> None:
        """The wire is (or will be) idle and frames are pending, the last requested at ``now``
        (the clock's now or later, :meth:`CanController.send_at`): arbitrate at the next SOF."""
        idle = self._idle_from
        start = now if now > idle else idle
        self._busy = True
        self._start = start
        self.clock.schedule_fast(start + 1, self._decide_cb)

    def _pick(self, start: int) -> _Request | None:
        """The arbitration winner among the frames requested up to ``start`` (lowest ID)."""
        best = None
        best_key = 0
        pending = self._pending
        for k in range(self._n_req):
            e = pending[k]
            if e.req > start:
                continue
            c = e.ctrl
            if c.silenced or c._suspend_until > start:
                continue
            key = e.key
            if best is None or key < best_key:
                best = e
                best_key = key
        return best

    def _decide(self) -> None:
        """End of the SOF bit: every request made up to the SOF instant has joined arbitration."""
        start = self._start
        best = self._pick(start)
        if best is None:
            self._busy = False
            nxt = None
            pending = self._pending
            for k in range(self._n_req):
                e = pending[k]
                c = e.ctrl
                if c.silenced:
                    continue
                t = e.req if e.req > c._suspend_until else c._suspend_until
                if nxt is None or t < nxt:
                    nxt = t
            if nxt is not None:
                now = self.clock.now_us
                self._kick(nxt if nxt > now else now)
            return
        self._begin(best, start)

    def _begin(self, best: _Request, start: int) -> None:
        """``best`` won the arbitration at ``start``: it is on the wire until its end (or its
        error frame)."""
        if self._recovering:
            self._close_recovery_runs(start)
        pending = self._pending
        i = 0
        while pending[i] is not best:
            i += 1
        n = self._n_req - 1
        pending[i] = pending[n]     # in no order: the last request takes the winner's place
        self._n_req = n
        self._current = best
        self._current_aborted = False
        bits = best.bits
        outcome = _OK
        if self._faults_on:
            r = self._rng.random()
            if r < self._drop_prob:
                outcome = _DROP
            elif r < self._drop_prob + self._corrupt_prob:
                outcome = _CORRUPT
        self._outcome = outcome
        if outcome == _CORRUPT:
            end = start + self._dur(bits + ERROR_EXTRA_BITS)
            self._dom_end = end - self._dur(TRAILING_RECESSIVE_BITS)
            self.clock.schedule(start + self._dur(bits - 10 + ERROR_FLAG_BITS), self._error_cb)
        elif self._bit_us:
            bu = self._bit_us
            end = start + bits * bu
            self._dom_end = end - TRAILING_RECESSIVE_BITS * bu
            self._idle_from = end
            clock = self.clock
            t_eof = end - 3 * bu
            # nothing due up to the end of the frame (and within the run in progress): nothing can
            # abort it or join the wire meanwhile, so its end is handled now, at that instant
            if self._inline < _MAX_INLINE and clock.skip_to(t_eof):
                self._inline += 1
                try:
                    self._complete()
                finally:
                    self._inline -= 1
                return
            clock.schedule_fast(t_eof, self._complete_cb)
            return
        else:
            end = start + self._dur(bits)
            self._dom_end = end - self._dur(TRAILING_RECESSIVE_BITS)
            self.clock.schedule(start + self._dur(bits - 3), self._complete_cb)
        self._idle_from = end

    def _complete(self) -> None:
        """End of EOF: the frame is valid; deliver it to the receivers and listeners."""
        cur = self._current
        assert cur is not None
        ctrl = cur.ctrl
        frame = cur.frame
        self._current = None
        self._release(cur)
        t = self.clock.now_us
        frame.timestamp = t / US_PER_S
        frame.channel = self.channel
        frame.is_rx = True
        if ctrl._n_pending:
            ctrl._n_pending -= 1
        ctrl.frames_sent += 1
        if ctrl.tec and not ctrl._off:
            ctrl.tec -= 1
            self._update_state(ctrl)
        self.frames_sent += 1
        self.busy_us += self._idle_from - self._start
        if self._rec_dirty:
            self._rx_success(ctrl)
        if self._outcome == _DROP:
            self.frames_dropped += 1
        elif self._twin:
            ctrl._port.deliver(frame)  # type: ignore[union-attr]  # set with _twin (attach)
        else:
            self._send_and_drain(ctrl, frame, t)
        if self._listeners:
            copy = frame.to_message()        # python-can's loggers get a can.Message of their own
            for lst in self._listeners:
                lst.on_message_received(copy)
        if self._n_req:
            # the wire is idle from the end of the intermission. The fast path: the SOF of the
            # next frame is the first instant a pending frame may start; when nothing on the
            # clock is due up to it, nothing can request (or abort) a frame before then, and
            # the decision taken now is the one _decide would take there (the same winner, the
            # same instants; one clock event less per frame). Otherwise _kick: decide at the SOF.
            idle = self._idle_from
            start = t if t > idle else idle
            first = -1                  # none (virtual times are >= 0)
            if not self._recovering:
                pending = self._pending
                for k in range(self._n_req):
                    e = pending[k]
                    c = e.ctrl
                    if c.silenced:
                        first = -1
                        break
                    r = e.req
                    if c._suspend_until > r:
                        r = c._suspend_until
                    if first < 0 or r < first:
                        first = r
            if first >= 0:
                sof = first if first > start else start
                if not self.clock.due_by(sof + 1):
                    best = self._pick(sof)
                    if best is not None:
                        self._busy = True
                        self._start = sof
                        self._begin(best, sof)
                        return
            self._kick(t)
        else:
            self._busy = False

    def _error(self) -> None:
        """A corrupted frame: error frame, counters, automatic retransmission."""
        e = self._current
        assert e is not None
        self._current = None
        ctrl = e.ctrl
        self.error_frames += 1
        ctrl.tx_errors += 1
        ctrl.tec += 8
        self._update_state(ctrl)
        for c in self._nodes:
            if c is not ctrl and not c._off:
                c.rx_errors += 1
                if c.rec < BUS_OFF_LIMIT:
                    c.rec += 1
                    self._update_state(c)
                self._rec_dirty = True
        self.busy_us += self._idle_from - self._start
        if self._listeners:
            err = can.Message(timestamp=self.clock.now_us / US_PER_S, is_error_frame=True,
                              is_extended_id=False, channel=self.channel, is_rx=True)
            for lst in self._listeners:
                lst.on_message_received(err)
        if ctrl._off or self._current_aborted:
            if not ctrl._off:
                ctrl._n_pending -= 1
                ctrl.tx_aborted += 1
            self._release(e)
        else:
            self._add(e)                # automatic retransmission, same request order
            if ctrl.state == ERROR_PASSIVE:
                ctrl._suspend_until = self._idle_from + self._dur(SUSPEND_BITS)
        if self._n_req:
            self._kick(self.clock.now_us)
        else:
            self._busy = False

    def _abort(self, ctrl: CanController) -> int:
        n = 0
        if ctrl._n_pending:
            pending = self._pending
            kept = 0
            for k in range(self._n_req):
                e = pending[k]
                if e.ctrl is ctrl:
                    self._release(e)
                else:
                    pending[kept] = e
                    kept += 1
            n = self._n_req - kept
            self._n_req = kept
            if n:
                ctrl._n_pending -= n
                ctrl.tx_aborted += n
        cur = self._current
        if cur is not None and cur.ctrl is ctrl:
            self._current_aborted = True
        return n


def _ignore(msg: object) -> None:
    """on_rx of a node that does not listen."""
