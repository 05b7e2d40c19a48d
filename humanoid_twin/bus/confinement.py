"""Error confinement of the CAN wire (ISO 11898 as the PIC18F258 implements it; seed 002
slides 25-27, docs/buses.md): transmit/receive error counters, error-active -> error-passive ->
bus-off, and the bus-off recovery after 128 sequences of 11 recessive bits.

``ErrorConfinement`` is the part of the wire, ``CanNetwork`` (network.py), that keeps
these counters (the root of the wire's one inheritance chain: ``ErrorConfinement`` <-
``ForeignPath`` <- ``CanNetwork``, one chain because the compiled core makes each an extension
type, which has one base); the wire's timing and arbitration (``network.py``) calls it when a
frame completes (``_rx_success``), when an error frame ends one (``_update_state``), and when a
board clears its status (``_clear_status``).
"""

from __future__ import annotations

from typing import Any, Protocol

from humanoid_twin.bus.frames import TRAILING_RECESSIVE_BITS
from humanoid_twin.bus.twin_bus import TwinBus
from humanoid_twin.clock import US_PER_S
from humanoid_twin.protocol.wire import ErrorState

# a controller's ``state`` is the label of its protocol.wire.ErrorState (names and codes live there)
ERROR_ACTIVE = ErrorState.ERROR_ACTIVE.label
ERROR_PASSIVE = ErrorState.ERROR_PASSIVE.label
BUS_OFF = ErrorState.BUS_OFF.label
ERROR_STATE_CODE: dict[str, int] = {s.label: int(s) for s in ErrorState}   # label -> wire code

PASSIVE_LIMIT = 127             # TEC or REC > 127 -> error-passive
BUS_OFF_LIMIT = 255             # TEC > 255 -> bus-off
RECOVERY_SEQUENCES = 128        # 128 occurrences of 11 consecutive recessive bits


class ConfinedNode(Protocol):
    """A node's error-confinement record, what this module reads and sets of it: a
    ``CanController`` of network.py, named by its fields here, so that this module, below the
    wire's, imports nothing from it."""

    bus: Any
    tec: int
    rec: int
    state: str
    recovering: bool
    bus_off_count: int
    recoveries: int
    _off: bool                  # the state is BUS_OFF (a C flag for the wire's per-frame path)
    _n_pending: int             # TX buffers in use
    _rec_count: int             # bus-off recovery: 11-recessive-bit sequences counted ...
    _rec_mark: int              # ... up to this instant


class ErrorConfinement:
    """TEC/REC, error states and bus-off recovery of every node on one wire (the base of
    ``CanNetwork``, which sets the wire's clock, nodes, bit rate and last dominant instant
    read here: ``clock``, ``bitrate``, ``_nodes``, ``_recovering``, ``_rec_dirty``, ``_dom_end``)."""

    # CanNetwork provides _dur(bits) (bit times in us) and _abort(ctrl) (TXABT of every
    # pending frame of ctrl), used here
    __slots__ = ()

    def _rx_success(self, sender: ConfinedNode) -> None:
        dirty = False
        for c in self._nodes:
            if c is sender or c._off:
                continue
            r = c.rec
            if r:
                c.rec = r - 1 if r <= PASSIVE_LIMIT else 119   # ISO 11898: back to 119..127
                self._update_state(c)
                if c.rec:
                    dirty = True
        self._rec_dirty = dirty  # type: ignore[misc]  # a CanNetwork slot (this base has none)

    def _update_state(self, c: ConfinedNode) -> None:
        if c.state == BUS_OFF:
            return
        if c.tec > BUS_OFF_LIMIT:
            c.tec = BUS_OFF_LIMIT      # the PIC's TXERRCNT is an 8-bit register
            c.state = BUS_OFF
            c._off = True
            self._mute(c, True)
            c.bus_off_count += 1
            # the TX buffers are cleared: pending requests are dropped (a frame of c's still
            # on the wire is not retransmitted: c is off)
            self._abort(c)
            c._n_pending = 0
        elif c.tec > PASSIVE_LIMIT or c.rec > PASSIVE_LIMIT:
            c.state = ERROR_PASSIVE
        else:
            c.state = ERROR_ACTIVE

    def _clear_status(self, c: ConfinedNode) -> None:
        if c.state != BUS_OFF:
            c.tec = 0
            c.rec = 0
            c.state = ERROR_ACTIVE
            return
        if c.recovering:
            return
        c.recovering = True
        c._rec_count = 0
        c._rec_mark = self.clock.now_us
        self._recovering.append(c)
        self._schedule_recovery_check(c)

    def _bits_in(self, us: int) -> int:
        return us * self.bitrate // US_PER_S

    def _recovery_progress(self, c: ConfinedNode, t: int) -> int:
        """11-recessive-bit sequences seen by ``c`` up to ``t`` if the wire stayed idle."""
        begin = c._rec_mark if c._rec_mark > self._dom_end else self._dom_end
        if t <= begin:
            return c._rec_count
        return c._rec_count + self._bits_in(t - begin) // TRAILING_RECESSIVE_BITS

    def _close_recovery_runs(self, start: int) -> None:
        """A new frame starts at ``start``: close the recessive run of every recovering node."""
        for c in list(self._recovering):
            c._rec_count = self._recovery_progress(c, start)
            c._rec_mark = start
            if c._rec_count >= RECOVERY_SEQUENCES:
                self._recovered(c)

    def _schedule_recovery_check(self, c: ConfinedNode) -> None:
        begin = max(c._rec_mark, self._dom_end, self.clock.now_us)
        need = RECOVERY_SEQUENCES - c._rec_count
        t = begin + self._dur(need * TRAILING_RECESSIVE_BITS)

        def check() -> None:
            if not c.recovering:
                return
            now = self.clock.now_us
            if self._recovery_progress(c, now) >= RECOVERY_SEQUENCES:
                self._recovered(c)
            else:
                self._schedule_recovery_check(c)

        self.clock.schedule(t, check)

    def _mute(self, c: ConfinedNode, muted: bool) -> None:
        bus = c.bus
        if isinstance(bus, TwinBus):
            bus.set_muted(muted)

    def _recovered(self, c: ConfinedNode) -> None:
        c.recovering = False
        c._off = False
        self._mute(c, False)
        c.tec = 0
        c.rec = 0
        c.state = ERROR_ACTIVE
        c.recoveries += 1
        self._recovering.remove(c)

