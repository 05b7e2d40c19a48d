"""Bridges from a :class:`SerialLink` to an outside program (``humanoid-twin serve``).

``PtyBridge(link)`` opens a pseudo-terminal pair; the outside program opens ``port_name``
(``/dev/pts/N``) like any serial port. ``TcpBridge(link)`` listens on a TCP port; the outside
program opens ``socket://127.0.0.1:PORT`` with pyserial. No threads: the serve loop calls
``poll()`` between paced clock steps. Bytes from the client enter the link at the current
virtual time; bytes the link has delivered to the host side are written to the client.

Both bridges serve one client at a time, in *sessions* (docs/serve.md):

- a session starts clean: the cable is "unplugged and plugged back" (:meth:`SerialLink.unplug`:
  the previous client's bytes still on the line, both ways, are dropped) and ``on_session()``
  runs (``serve`` resets the Master's receiver with it), so a client never sees an answer to the
  previous client's bytes and its first frame is never spliced with a previous partial frame;
- between two sessions the line stays quiet for ``quiet_us`` of virtual time (longer than the
  Master's inter-byte break-off and its answer delay), so a late answer of the old session
  never reaches the new one;
- input is bounded (backpressure): the bridge stops reading from the client while the line holds
  ``max_pending_s`` of line time (at 115200 baud 8E1, 1 s is 10 473 bytes), as a real UART's
  transmit buffer blocks the writer. Memory stays a few hundred kB whatever the client sends;
- a client silent (no byte sent) for ``idle_timeout_s`` wall seconds is disconnected;
- a client that half-closes (``shutdown(SHUT_WR)``, ``socat`` at the end of its input) still
  gets the answers to what it sent before the bridge closes its side;
- TCP: a second client while one is served is closed after 0.1 s (it sees EOF) and a line is
  logged; a client arriving while the previous one is leaving waits its turn;
- pty: the bridge does not keep the slave end open, so it sees a client open and close it
  (poll HUP); while a client has it open the pty is exclusive (``TIOCEXCL``: another open fails
  with EBUSY, except for root); each client finds the pty in the same idle settings (raw, 38400
  baud, *marked*), and the bridge marks the client's settings again once they have stayed
  unchanged for ``PtyBridge.REARM_AFTER_S``, so that a client's parity request changes something
  and is accepted (:class:`PtyBridge`; docs/serve.md: Linux ptys have no parity).

``log(text)`` gets one line per event (connect, leave, refuse, backpressure); ``serve`` writes
them to stderr.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import select
import socket
import termios
import time
import tty
from collections.abc import Callable

from humanoid_twin.bus.serial_link import SerialLink
from humanoid_twin.clock import US_PER_S

_CHUNK = 4096
DEFAULT_MAX_PENDING_S = 1.0
DEFAULT_QUIET_US = 3_000
DEFAULT_BACKLOG = 16
DISCARD_PER_POLL = 1 << 20     # bytes of a flood dropped per poll while another client waits
REFUSE_AFTER_S = 0.1           # a connection waits this long for a client that may be leaving
MAX_WAITING = 8                # connections held waiting; more stay in the listen backlog
HALF_CLOSE_GRACE_S = 2.0       # wall seconds a half-closed client is kept, beyond its queued line time


def _nothing() -> None:
    pass


class _Bridge:
    """Common part: sessions, bounded input, the backlog of host-bound bytes, the counters."""

    port_name: str

    def __init__(
        self,
        link: SerialLink,
        *,
        log: Callable[[str], None] | None = None,
        on_session: Callable[[], None] | None = None,
        idle_timeout_s: float | None = None,
        max_pending_s: float = DEFAULT_MAX_PENDING_S,
        quiet_us: int = DEFAULT_QUIET_US,
    ) -> None:
        if not isinstance(link, SerialLink):
            raise TypeError(f"a bridge needs a SerialLink, got {type(link).__name__}")
        if idle_timeout_s is not None and not idle_timeout_s > 0:
            raise ValueError(f"idle_timeout_s must be > 0 or None, got {idle_timeout_s!r}")
        if not max_pending_s > 0:
            raise ValueError(f"max_pending_s must be > 0, got {max_pending_s!r}")
        self.link = link
        self._log = log or (lambda text: None)
        self._on_session = on_session or _nothing
        self.idle_timeout_s = idle_timeout_s
        self.max_pending_bytes = max(64, int(max_pending_s * link.baudrate / link.bits_per_byte))
        self.quiet_us = int(quiet_us)
        self._quiet_until_us = -1
        self._out = bytearray()        # host-bound bytes not yet accepted by the client side
        self.bytes_in = 0              # client -> link
        self.bytes_out = 0             # link -> client
        self.bytes_discarded = 0       # bytes dropped: host-bound with no client, or left on the line
        self.sessions = 0              # clients served so far
        self.refused = 0               # clients turned away (one client at a time)
        self.closed = False
        self._session_open = False
        self._who = ""
        self._s_in = self._s_out = 0
        self._last_rx_wall = 0.0
        self._throttled = False

    # -- sessions -------------------------------------------------------------------------------
    def _quiet(self) -> bool:
        return self.link.clock.now_us < self._quiet_until_us

    def _begin(self, who: str) -> None:
        dropped = sum(self.link.unplug())
        self.bytes_discarded += dropped + len(self._out)
        self._out.clear()
        self._on_session()
        self.sessions += 1
        self._session_open = True
        self._who = who
        self._s_in = self._s_out = 0
        self._last_rx_wall = time.monotonic()
        self._throttled = False
        self._log(f"client {who} connected (session {self.sessions})")

    def _end(self, why: str) -> None:
        to_dev, to_host = self.link.unplug()
        left = to_dev + to_host + len(self._out)
        self.bytes_discarded += left
        self._out.clear()
        self._on_session()
        self._session_open = False
        self._quiet_until_us = self.link.clock.now_us + self.quiet_us
        extra = f", {left} bytes still on the line discarded" if left else ""
        self._log(f"client {self._who} left ({why}): {self._s_in} bytes in, {self._s_out} bytes out{extra}")

    def _room(self) -> int:
        """How many client bytes the line takes now (backpressure beyond ``max_pending_bytes``)."""
        room = self.max_pending_bytes - self.link.host_out_waiting()
        if room <= 0 and not self._throttled:
            self._throttled = True
            self._log(f"client {self._who} sends faster than the line carries: reading paused while "
                      f"{self.max_pending_bytes} bytes are queued")
        return max(0, room)

    def _feed(self, data: bytes) -> None:
        self.link.host_write(data)
        self.bytes_in += len(data)
        self._s_in += len(data)
        self._last_rx_wall = time.monotonic()

    def _idle(self) -> bool:
        return (self.idle_timeout_s is not None
                and time.monotonic() - self._last_rx_wall > self.idle_timeout_s)

    @property
    def connected(self) -> bool:
        """True while a client is being served."""
        return self._session_open

    @property
    def clients_served(self) -> int:
        """Sessions started so far (same as ``sessions``)."""
        return self.sessions

    def __enter__(self) -> _Bridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:  # pragma: no cover - overridden
        """Release the OS resources."""
        self.closed = True


class PtyBridge(_Bridge):
    """A pty pair: the client opens ``port_name`` (``/dev/pts/N``); the bridge holds the master.

    **Parity on a Linux pty.** The pts driver keeps no parity bit (it clears ``PARENB`` and forces
    ``CS8`` in every request), and the C library of Debian and Ubuntu (a glibc patch; Fedora has a
    similar one) reads the settings back after each ``tcsetattr`` and answers ``EINVAL`` when the
    call changed nothing while the driver dropped ``PARENB`` (or a size CS6/CS7); the rest of the
    request *was* applied. So a client's parity request is accepted only if it also changes
    something else. The bridge keeps the pty *marked* with flags that mean nothing on a pty (no
    parity error ever arrives), but that serial libraries rewrite whenever they set parity:

    - ``INPCK`` (pyserial clears it; Octave's instrument-control sends ``c_iflag = 0``),
    - ``IGNPAR`` (Boost.Asio clears it when it enables parity, even or odd),
    - ``PARODD`` (an even-parity request clears it),

    and, between clients, the speed ``IDLE_SPEED`` (38400: a client asking for 115200 changes
    it). A client's request clears the marks it rewrites; once the client's settings have stayed
    unchanged for ``REARM_AFTER_S`` (seen by two polls), the bridge sets the marks again, so its
    next parity request is accepted too. The bytes are not changed (with ``IGNPAR`` set next to
    ``INPCK``, the line discipline keeps its raw path).

    What no state of the pty can give (tests/bus/test_pty_termios.py, docs/serve.md): the *same*
    request with parity sent twice within ``REARM_AFTER_S`` (the first one leaves the pty exactly
    as the second one asks, so the second changes nothing: EINVAL), which is what Octave's
    ``serialport(..., "Parity", "even")`` constructor does (it sends its whole settings again
    for the flow control, the data bits and the stop bits, microseconds apart); and an odd-parity
    request that touches nothing but ``PARENB|PARODD``.

    Writing the marks reads the client's settings and writes them back with the marks: a client
    ``tcsetattr`` landing between that read and that write (a few microseconds, at most once per
    settings change of the client, and only after it has left its settings alone for
    ``REARM_AFTER_S``) would be undone.
    """

    # the slave's speed between clients: a client asking for another speed changes something
    IDLE_SPEED = termios.B38400
    MARK_IFLAG = termios.INPCK | termios.IGNPAR
    MARK_CFLAG = termios.PARODD
    REARM_AFTER_S = 0.002

    def __init__(self, link: SerialLink, **options: object) -> None:
        super().__init__(link, **options)  # type: ignore[arg-type]  # options: the base's keywords
        self._master_fd, slave_fd = os.openpty()
        try:
            tty.setraw(slave_fd, termios.TCSANOW)
            os.set_blocking(self._master_fd, False)
            self.port_name = os.ttyname(slave_fd)
            idle = termios.tcgetattr(self._master_fd)   # the slave's settings, through the master
        except BaseException:
            os.close(self._master_fd)
            os.close(slave_fd)
            raise
        os.close(slave_fd)           # we watch for HUP: no client has the slave open
        idle[4] = idle[5] = self.IDLE_SPEED
        self._idle_attrs = self._marked(idle)
        self._seen: list = []        # the client's settings as last read, and since when
        self._seen_at = 0.0
        self._reset_settings()
        self._poller = select.poll()
        self._poller.register(self._master_fd, select.POLLIN | select.POLLHUP)

    @classmethod
    def _marked(cls, attrs: list) -> list:
        marked = list(attrs)
        marked[0] |= cls.MARK_IFLAG
        marked[2] |= cls.MARK_CFLAG
        return marked

    def _reset_settings(self) -> None:
        """The idle settings, for the next client: raw, ``IDLE_SPEED``, marked."""
        with contextlib.suppress(termios.error):
            termios.tcsetattr(self._master_fd, termios.TCSANOW, self._idle_attrs)
            self._seen = termios.tcgetattr(self._master_fd)
        self._seen_at = time.monotonic()

    def _rearm(self) -> None:
        """Mark the client's settings again once they have stayed unchanged for ``REARM_AFTER_S``."""
        try:
            now = termios.tcgetattr(self._master_fd)
        except termios.error:
            return
        t = time.monotonic()
        if now != self._seen:        # the client changed its settings: wait until they settle
            self._seen, self._seen_at = now, t
            return
        if t - self._seen_at < self.REARM_AFTER_S:
            return
        marked = self._marked(now)
        if marked == now:
            return
        try:
            termios.tcsetattr(self._master_fd, termios.TCSANOW, marked)
            self._seen = termios.tcgetattr(self._master_fd)
        except termios.error:
            return
        self._seen_at = t

    def _slave_open(self) -> bool:
        events = self._poller.poll(0)
        return not any(ev & select.POLLHUP for _, ev in events)

    def _exclusive(self) -> None:
        """TIOCEXCL on the slave: another open fails with EBUSY (root excepted)."""
        with contextlib.suppress(OSError):
            fd = os.open(self.port_name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            try:
                fcntl.ioctl(fd, termios.TIOCEXCL)
            finally:
                os.close(fd)

    def poll(self) -> int:
        """Move bytes both ways; returns how many bytes moved."""
        if self.closed:
            raise OSError("PtyBridge is closed")
        self._follow_client()
        moved = self._receive() if self._session_open else 0
        out = self.link.host_read_available()
        if not self._session_open:
            self.bytes_discarded += len(out)
            return moved
        return moved + self._send(out)

    def _follow_client(self) -> None:
        """A session begins when a client opens the port (after the quiet time) and ends when it
        closes it; an idle client is said once per timeout."""
        present = self._slave_open()
        if present and not self._session_open:
            if self._quiet():
                present = False          # the next poll, after the quiet time, starts it
            else:
                self._begin(self.port_name)
                self._exclusive()
        if self._session_open and not present:
            self._drain_input()
            self._end("closed the port")
            self._reset_settings()
        if self._session_open:
            self._rearm()
        if self._session_open and self._idle():
            # a pty cannot be taken from its client: drop what it sent and say so, once per timeout
            self._log(f"client {self._who} idle for more than {self.idle_timeout_s:g} s "
                      "(a pty client cannot be disconnected: close the port to free it)")
            self._last_rx_wall = time.monotonic()

    def _receive(self) -> int:
        """What the client wrote, onto the line (as much as it has room for); the bytes moved."""
        moved = 0
        while True:
            room = self._room()
            if not room:
                break
            try:
                data = os.read(self._master_fd, min(_CHUNK, room))
            except BlockingIOError:
                break
            except OSError as e:      # EIO: the client closed meanwhile
                if e.errno == errno.EIO:
                    break
                raise
            if not data:
                break
            self._feed(data)
            moved += len(data)
        return moved

    def _send(self, out: bytes) -> int:
        """The line's bytes ``out`` after what the client has not taken yet, to the client; the bytes
        moved."""
        if out:
            self._out += out
        if not self._out:
            return 0
        try:
            n = os.write(self._master_fd, self._out)
        except (BlockingIOError, OSError):
            n = 0
        del self._out[:n]
        self.bytes_out += n
        self._s_out += n
        return n

    def _drain_input(self) -> None:
        """Read and drop what a departed client left in the pty (it is not delivered)."""
        with contextlib.suppress(OSError):
            while True:
                data = os.read(self._master_fd, _CHUNK)
                if not data:
                    break
                self.bytes_discarded += len(data)

    def close(self) -> None:
        """Close the pty."""
        if self.closed:
            return
        self.closed = True
        with contextlib.suppress(OSError):
            os.close(self._master_fd)


class TcpBridge(_Bridge):
    """A TCP server for one client at a time; ``port_name`` is ``socket://HOST:PORT``.

    ``host`` is an IPv4 or IPv6 address (``127.0.0.1``, ``::1``) or a name that resolves to one.
    Raises ``OSError`` if it cannot listen (address in use, not an address of this machine ...).
    """

    def __init__(self, link: SerialLink, host: str = "127.0.0.1", port: int = 0, *,
                 backlog: int = DEFAULT_BACKLOG, **options: object) -> None:
        super().__init__(link, **options)  # type: ignore[arg-type]  # as above
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"TCP port must be 0..65535, got {port!r}")
        infos = socket.getaddrinfo(host, port, 0, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
        family, _, _, _, addr = infos[0]
        self._server = socket.socket(family, socket.SOCK_STREAM)
        try:
            self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._server.bind(addr)
            self._server.listen(backlog)
            self._server.setblocking(False)
        except BaseException:
            self._server.close()
            raise
        self.host, self.port = self._server.getsockname()[:2]
        shown = f"[{self.host}]" if family == socket.AF_INET6 else self.host
        self.port_name = f"socket://{shown}:{self.port}"
        self._client: socket.socket | None = None
        self._waiting: list[tuple[socket.socket, str, float]] = []
        self._eof = False
        self._discarding = False
        self._linger_until = 0.0

    def _drop_client(self, why: str) -> None:
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
            self._client = None
            self._end(why)

    def _discard_excess(self, client: socket.socket) -> bool:
        """Read and drop up to ``DISCARD_PER_POLL`` bytes the line has no room for; True at EOF.

        Only while another client waits: a flooding client's hang-up sits behind its unread
        bytes (its FIN follows them), and the waiting client must not wait minutes of line time.
        """
        if not self._discarding:
            self._discarding = True
            self._log(f"client {self._who}: discarding its input beyond the line's bound while "
                      "another client waits")
        left = DISCARD_PER_POLL
        while left > 0:
            try:
                data = client.recv(min(65536, left))
            except (BlockingIOError, InterruptedError):
                return False
            except OSError:
                return True
            if not data:
                return True
            self.bytes_discarded += len(data)
            left -= len(data)
        return False

    def _accept(self) -> None:
        """Take waiting connections. A connection that arrives while a client is served waits
        up to ``REFUSE_AFTER_S`` (the client may be leaving just now: a quick reconnect); if the
        client is still there then, it is closed (it sees EOF) and a line is logged. Clients
        arriving while the previous one finishes (half-close, quiet time) wait their turn."""
        while len(self._waiting) < MAX_WAITING:
            try:
                conn, peer = self._server.accept()
            except (BlockingIOError, InterruptedError):
                break
            except OSError:            # ECONNABORTED and friends: that client is gone
                continue
            conn.setblocking(False)
            self._waiting.append((conn, f"{peer[0]}:{peer[1]}", time.monotonic()))
        if self._client is None and self._waiting and not self._quiet():
            conn, who, _ = self._waiting.pop(0)
            with contextlib.suppress(OSError):
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._client = conn
            self._eof = False
            self._discarding = False
            self._begin(who)
            return
        if self._client is not None and not self._eof:
            now = time.monotonic()
            while self._waiting and now - self._waiting[0][2] > REFUSE_AFTER_S:
                conn, who, _ = self._waiting.pop(0)
                self.refused += 1
                with contextlib.suppress(OSError):
                    conn.close()
                self._log(f"client {who} refused: busy with client {self._who} (one client at a time)")

    def poll(self) -> int:
        """Serve the client (if any), then take waiting connections; returns how many bytes moved."""
        if self.closed:
            raise OSError("TcpBridge is closed")
        moved = 0
        if self._client is not None and not self._eof:
            moved += self._receive(self._client)
            self._drop_stuck_client()
        out = self.link.host_read_available()
        if self._client is None:
            self.bytes_discarded += len(out)
        else:
            moved += self._send(self._client, out)
            if self._client is not None and self._eof:
                self._end_half_close(self._client)
        self._accept()
        return moved

    def _receive(self, client: socket.socket) -> int:
        """What the client sent, onto the line (as much as it has room for); its end of the
        connection: a half-close (answered first) or a hang-up. The bytes moved."""
        moved = 0
        while True:
            room = self._room()
            if not room:
                break
            try:
                data = client.recv(min(_CHUNK, room))
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._drop_client("connection reset")
                break
            if not data:
                if self.link.host_pending() or self._out:
                    self._eof = True       # half-close: answer what it sent, then close
                    pending_s = self.link.host_out_waiting() * self.link.byte_time_us / US_PER_S
                    self._linger_until = time.monotonic() + pending_s + HALF_CLOSE_GRACE_S
                else:
                    self._drop_client("closed the connection")
                break
            self._feed(data)
            moved += len(data)
        return moved

    def _drop_stuck_client(self) -> None:
        """Drop a client that flooded the line and hung up behind the flood while another waits,
        or that sent nothing for the idle timeout."""
        client = self._client
        if (client is not None and not self._eof and self._waiting
                and self.link.host_out_waiting() >= self.max_pending_bytes
                and self._discard_excess(client)):
            # a flood, then a hang-up hidden behind it: its input beyond the line's bound
            # was discarded to find the end (someone else is waiting for the line)
            self._drop_client("closed the connection after a flood")
            client = None
        if client is not None and not self._eof and self._idle():
            self._drop_client(f"idle for more than {self.idle_timeout_s:g} s")

    def _send(self, client: socket.socket, out: bytes) -> int:
        """The line's bytes ``out`` after what the client has not taken yet, to the client; the bytes
        moved."""
        if out:
            self._out += out
        if not self._out:
            return 0
        try:
            n = client.send(self._out)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError:
            self._drop_client("connection reset")
            return 0
        del self._out[:n]
        self.bytes_out += n
        self._s_out += n
        return n

    def _end_half_close(self, client: socket.socket) -> None:
        """A half-closed client's connection shut once every answer went out (or the grace ran out)."""
        link = self.link
        done = (not self._out and not link.host_pending()
                and link.clock.now_us >= link.host_out_done_us() + self.quiet_us)
        if done or time.monotonic() > self._linger_until:
            with contextlib.suppress(OSError):
                client.shutdown(socket.SHUT_WR)
            self._drop_client("half-closed, answered" if done else "half-closed, gave up waiting")

    def close(self) -> None:
        """Close the client connection and the listening socket."""
        if self.closed:
            return
        self.closed = True
        if self._client is not None:
            self._drop_client("server stopped")
        for conn, _, _ in self._waiting:
            with contextlib.suppress(OSError):
                conn.close()
        self._waiting.clear()
        with contextlib.suppress(OSError):
            self._server.close()
