"""The RS-232 cable between the PC and the Master, in virtual time.

Seed 002 slide 7: asynchronous, 1 start + 8 data + 1 parity (even) + 1 stop = 11 bits per
character at 115200 bit/s. Each direction is independent (full duplex). Byte ``n`` (1-based) of
a burst that starts at ``t0`` has its stop bit at ``t0 + ceil(n * 11e6 / baudrate)`` us
(integers, no drift over a long burst); a byte written while the line is busy queues behind the
previous ones; a byte written when the line is idle starts a new burst at ``clock.now_us``.

Device (Master) side: ``set_device_rx(cb)`` gets each byte at its stop bit (one clock event per
byte), ``device_write(data)``. Host side: ``host_write(data)``, ``host_read_available()`` (the
bytes whose stop bit is <= now), ``next_host_byte_us()`` (a reader's next instant).
Observers: ``add_tap(cb)`` sees every write in either direction and every drop of bytes on their
way (``recording/serial_log.py`` writes them to a file).
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Callable

from humanoid_twin.clock import US_PER_S, Clock
from humanoid_twin.protocol.wire import BAUDRATE, BYTESIZE, PARITY, STOPBITS

DEFAULT_BAUDRATE = BAUDRATE
TAP_TO_DEVICE = "host>twin"     # the tap's events (add_tap)
TAP_TO_HOST = "twin>host"
TAP_FLUSH = "flush"
TAP_UNPLUG = "unplug"
_PARITY_BITS = {"N": 0, "E": 1, "O": 1, "M": 1, "S": 1}


def _as_bytes(data: object, who: str) -> bytes:
    if isinstance(data, bytes):
        return data
    if isinstance(data, (bytearray, memoryview)):
        return bytes(data)
    raise TypeError(f"{who} needs bytes, bytearray or memoryview, got {type(data).__name__}")


class _Direction:
    """One direction of the cable: the transmitter's shift register and its queue."""

    __slots__ = ("burst_start", "n", "last_end", "queue")

    def __init__(self) -> None:
        self.burst_start = 0
        self.n = 0
        self.last_end = 0
        self.queue: deque[tuple[int, int]] = deque()   # (stop-bit time, byte), in order


class SerialLink:
    """The RS-232 cable: 11 bits/byte at 115200 baud (8E1), full duplex, in virtual time.

    :param clock: the twin's lockstep clock.
    :param baudrate: bits per second.
    :param bytesize, parity, stopbits: the character frame (seed 002 slide 7: 8, "E", 1).
    """

    def __init__(self, clock: Clock, baudrate: int = DEFAULT_BAUDRATE, *, bytesize: int = BYTESIZE,
                 parity: str = PARITY, stopbits: int = STOPBITS) -> None:
        if not isinstance(baudrate, int) or baudrate <= 0:
            raise ValueError(f"baudrate must be a positive int, got {baudrate!r}")
        if bytesize not in (5, 6, 7, 8):
            raise ValueError(f"bytesize must be 5..8, got {bytesize!r}")
        if parity not in _PARITY_BITS:
            raise ValueError(f"parity must be one of {sorted(_PARITY_BITS)}, got {parity!r}")
        if stopbits not in (1, 2):
            raise ValueError(f"stopbits must be 1 or 2, got {stopbits!r}")
        self.clock = clock
        self.baudrate = baudrate
        self.bytesize = bytesize
        self.parity = parity
        self.stopbits = stopbits
        self.bits_per_byte = 1 + bytesize + _PARITY_BITS[parity] + stopbits
        self._num = self.bits_per_byte * US_PER_S
        self._to_dev = _Direction()
        self._to_host = _Direction()
        self._device_rx: Callable[[int], None] | None = None
        self._taps: list[Callable[[str, int, bytes, int], None]] = []
        self._noise_prob = 0.0
        self._rng = random.Random(0)
        self.bytes_to_device = 0
        self.bytes_to_host = 0
        self.bytes_corrupted = 0
        self.bytes_lost = 0          # reached the device side with no device_rx set

    # -- timing ------------------------------------------------------------------------------
    @property
    def byte_time_us(self) -> float:
        """Duration of one character (11 bits at 115200 baud = 95.49 us)."""
        return self._num / self.baudrate

    def burst_end_us(self, n: int) -> int:
        """Stop-bit instant of byte ``n`` (1-based) of a burst, relative to the burst start."""
        return (n * self._num + self.baudrate - 1) // self.baudrate

    def _push(self, d: _Direction, data: bytes) -> list[int]:
        """Queue ``data`` on direction ``d``; return the stop-bit time of each byte."""
        now = self.clock.now_us
        if d.last_end <= now:
            d.burst_start = now
            d.n = 0
        times = []
        noisy = self._noise_prob > 0.0
        for b in data:
            d.n += 1
            t = d.burst_start + (d.n * self._num + self.baudrate - 1) // self.baudrate
            if noisy and self._rng.random() < self._noise_prob:
                b ^= 1 << self._rng.randrange(self.bytesize)
                self.bytes_corrupted += 1
            d.queue.append((t, b))
            times.append(t)
        if times:
            d.last_end = times[-1]
        return times

    def _cancel_unsent(self, d: _Direction) -> int:
        """Drop the bytes of ``d`` whose start bit is still in the future (a flushed UART)."""
        now = self.clock.now_us
        q = d.queue
        last = len(q) - 1
        kept: deque[tuple[int, int]] = deque()
        for i, tb in enumerate(q):
            k = d.n - (last - i)                      # burst number of this byte (1-based)
            if d.burst_start + self.burst_end_us(k - 1) <= now:
                kept.append(tb)                       # already shifting out: it completes
            else:
                break
        dropped = len(q) - len(kept)
        if dropped:
            d.n -= dropped
            d.queue = kept
            d.last_end = kept[-1][0] if kept else now
        return dropped

    # -- device (Master) side ----------------------------------------------------------------
    def set_device_rx(self, cb: Callable[[int], None] | None) -> None:
        """The Master's USART receive interrupt: ``cb(byte)`` at each byte's stop bit."""
        if cb is not None and not callable(cb):
            raise TypeError(f"device_rx must be callable, got {cb!r}")
        self._device_rx = cb

    def device_write(self, data: bytes) -> None:
        """The Master transmits ``data`` to the host (back to back after anything pending)."""
        data = _as_bytes(data, "device_write")
        times = self._push(self._to_host, data)
        self.bytes_to_host += len(data)
        if self._taps and times:
            q = self._to_host.queue
            n = len(times)
            wire = bytes([q[i][1] for i in range(len(q) - n, len(q))])   # this write: the queue's tail
            self._tap(TAP_TO_HOST, wire, times[n - 1])

    # -- host (PC) side ------------------------------------------------------------------------
    def host_write(self, data: bytes) -> None:
        """The PC transmits ``data`` to the Master, starting now (or behind pending bytes)."""
        data = _as_bytes(data, "host_write")
        times = self._push(self._to_dev, data)
        self.bytes_to_device += len(data)
        if self._taps and times:
            self._tap(TAP_TO_DEVICE, data, times[len(times) - 1])   # as written: before the noise
        deliver = self._deliver_to_device
        for t in times:
            self.clock.schedule(t, deliver)

    def _deliver_to_device(self) -> None:
        # one event per byte; after a flush some events find the head not due yet: skip them
        q = self._to_dev.queue
        if not q or q[0][0] > self.clock.now_us:
            return
        b = q.popleft()[1]
        cb = self._device_rx
        if cb is None:
            self.bytes_lost += 1
        else:
            cb(b)

    def host_read_available(self) -> bytes:
        """The bytes whose stop bit is at or before ``clock.now_us``, removed from the line."""
        q = self._to_host.queue
        if not q:
            return b""
        now = self.clock.now_us
        out = bytearray()
        while q and q[0][0] <= now:
            out.append(q.popleft()[1])
        return bytes(out)

    def next_host_byte_us(self) -> int | None:
        """Stop-bit time of the next byte on its way to the host, or None."""
        q = self._to_host.queue
        return q[0][0] if q else None

    def host_byte_us(self, n: int) -> int | None:
        """Stop-bit time of the ``n``-th byte (1-based) on its way to the host, or of the last
        one when fewer are on their way; None when none is."""
        q = self._to_host.queue
        if not q:
            return None
        return q[n - 1][0] if n <= len(q) else q[-1][0]

    def host_out_waiting(self) -> int:
        """Bytes written by the host that have not reached the device yet."""
        return len(self._to_dev.queue)

    def host_reset_output(self) -> int:
        """Discard host bytes not yet started on the line; returns how many."""
        dropped = self._cancel_unsent(self._to_dev)
        if self._taps and dropped:
            for cb in self._taps:
                cb(TAP_FLUSH, self.clock.now_us, b"", dropped)
        return dropped

    def host_out_done_us(self) -> int:
        """Virtual time at which the last byte written by the host reaches the device."""
        return self._to_dev.last_end

    def host_pending(self) -> bool:
        """True while bytes are on their way in either direction (a request or its answer)."""
        return bool(self._to_dev.queue or self._to_host.queue)

    def unplug(self) -> tuple[int, int]:
        """The cable is unplugged: every byte on its way, in both directions, is lost.

        Returns ``(to_device, to_host)``, the numbers of bytes dropped. The next byte written
        starts a new burst at ``clock.now_us``. (Per-byte clock events already scheduled find
        the queue head not due and skip, see ``_deliver_to_device``.)
        """
        now = self.clock.now_us
        dropped = []
        for d in (self._to_dev, self._to_host):
            dropped.append(len(d.queue))
            d.queue.clear()
            d.n = 0
            d.burst_start = d.last_end = now
        if self._taps:
            for cb in self._taps:
                cb(TAP_UNPLUG, now, b"", dropped[0] + dropped[1])
        return dropped[0], dropped[1]

    def host_reset_input(self) -> int:
        """Discard the bytes already arrived at the host side; returns how many."""
        return len(self.host_read_available())

    # -- observers ---------------------------------------------------------------------------
    def add_tap(self, cb: Callable[[str, int, bytes, int], None]) -> None:
        """Call ``cb(event, t_us, data, n)`` on every event of the cable, at ``clock.now_us``:

        - ``TAP_TO_DEVICE`` / ``TAP_TO_HOST``: ``data`` handed to the host's / the Master's
          transmitter at ``t_us``, ``n`` the stop-bit time of its last byte (each byte's own stop
          bit follows from the burst rule above). Host>twin bytes are the ones the host wrote
          (before an injected bit flip: fed to a twin with the same noise, they flip alike);
          twin>host bytes are the ones the wire carries (after the flip: what the host reads);
        - ``TAP_FLUSH``: the host discarded ``n`` bytes not yet started (``host_reset_output``);
        - ``TAP_UNPLUG``: the cable was unplugged, ``n`` bytes lost in both directions.
        """
        if not callable(cb):
            raise TypeError(f"tap must be callable, got {cb!r}")
        self._taps.append(cb)

    def remove_tap(self, cb: Callable[[str, int, bytes, int], None]) -> None:
        """Undo :meth:`add_tap`."""
        self._taps.remove(cb)

    def _tap(self, event: str, data: bytes, end_us: int) -> None:
        for cb in self._taps:
            cb(event, self.clock.now_us, data, end_us)

    # -- faults --------------------------------------------------------------------------------
    def set_noise(self, prob: float, seed: int = 0) -> None:
        """Flip one random data bit of each byte with probability ``prob`` (both directions).

        Deterministic per ``seed``. Parity is not checked by either end (see docs/buses.md), so
        a corrupted byte is delivered; the protocol's BCC catches it.
        """
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"noise probability must be in [0, 1], got {prob!r}")
        self._noise_prob = float(prob)
        self._rng = random.Random(seed)

    def stats(self) -> dict:
        """Counters for the recording."""
        return {
            "bytes_to_device": self.bytes_to_device,
            "bytes_to_host": self.bytes_to_host,
            "bytes_corrupted": self.bytes_corrupted,
            "bytes_lost": self.bytes_lost,
        }
