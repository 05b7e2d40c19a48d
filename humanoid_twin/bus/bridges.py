"""Bridges from a :class:`SerialLink` to an outside program (``humanoid-twin serve``).

``PtyBridge(link)`` opens a pseudo-terminal pair; the outside program opens ``port_name``
(``/dev/pts/N``) like any serial port. ``TcpBridge(link)`` listens on a TCP port; the outside
program opens ``socket://127.0.0.1:PORT`` with pyserial. No threads: the serve loop calls
``poll()`` between paced clock steps. Bytes from the client enter the link at the current
virtual time; bytes the link has delivered to the host side are written to the client.
"""

from __future__ import annotations

import contextlib
import errno
import os
import socket
import termios
import tty

from humanoid_twin.bus.serial_link import SerialLink

_CHUNK = 4096


class _Bridge:
    """Common part: the backlog of host-bound bytes and the counters."""

    port_name: str

    def __init__(self, link: SerialLink) -> None:
        if not isinstance(link, SerialLink):
            raise TypeError(f"a bridge needs a SerialLink, got {type(link).__name__}")
        self.link = link
        self._out = bytearray()        # host-bound bytes not yet accepted by the client side
        self.bytes_in = 0              # client -> link
        self.bytes_out = 0             # link -> client
        self.bytes_discarded = 0       # host-bound bytes with no client to take them
        self.closed = False

    def __enter__(self) -> _Bridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:  # pragma: no cover - overridden
        """Release the OS resources."""
        self.closed = True


class PtyBridge(_Bridge):
    """A pty pair: the client opens ``port_name`` (``/dev/pts/N``); the bridge holds the master."""

    def __init__(self, link: SerialLink) -> None:
        super().__init__(link)
        self._master_fd, self._slave_fd = os.openpty()
        try:
            tty.setraw(self._slave_fd, termios.TCSANOW)
            os.set_blocking(self._master_fd, False)
            self.port_name = os.ttyname(self._slave_fd)
        except BaseException:
            os.close(self._master_fd)
            os.close(self._slave_fd)
            raise

    def poll(self) -> int:
        """Move bytes both ways; returns how many bytes moved."""
        if self.closed:
            raise OSError("PtyBridge is closed")
        moved = 0
        while True:
            try:
                data = os.read(self._master_fd, _CHUNK)
            except BlockingIOError:
                break
            except OSError as e:        # EIO: no client has the slave open (we hold it, rare)
                if e.errno == errno.EIO:
                    break
                raise
            if not data:
                break
            self.link.host_write(data)
            self.bytes_in += len(data)
            moved += len(data)
        out = self.link.host_read_available()
        if out:
            self._out += out
        if self._out:
            try:
                n = os.write(self._master_fd, self._out)
            except BlockingIOError:
                n = 0
            del self._out[:n]
            self.bytes_out += n
            moved += n
        return moved

    def close(self) -> None:
        """Close both ends of the pty."""
        if self.closed:
            return
        self.closed = True
        for fd in (self._master_fd, self._slave_fd):
            with contextlib.suppress(OSError):
                os.close(fd)


class TcpBridge(_Bridge):
    """A TCP server for one client at a time; ``port_name`` is ``socket://HOST:PORT``."""

    def __init__(self, link: SerialLink, host: str = "127.0.0.1", port: int = 0) -> None:
        super().__init__(link)
        if not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"TCP port must be 0..65535, got {port!r}")
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        try:
            self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._server.bind((host, port))
            self._server.listen(1)
            self._server.setblocking(False)
        except BaseException:
            self._server.close()
            raise
        self.host, self.port = self._server.getsockname()[:2]
        self.port_name = f"socket://{self.host}:{self.port}"
        self._client: socket.socket | None = None
        self.clients_served = 0

    @property
    def connected(self) -> bool:
        """True while a client is connected."""
        return self._client is not None

    def _drop_client(self) -> None:
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
            self._client = None
            self._out.clear()

    def poll(self) -> int:
        """Accept a client if none, then move bytes both ways; returns how many bytes moved."""
        if self.closed:
            raise OSError("TcpBridge is closed")
        moved = 0
        if self._client is None:
            try:
                client, _ = self._server.accept()
            except BlockingIOError:
                client = None
            if client is not None:
                client.setblocking(False)
                client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self._client = client
                self.clients_served += 1
        client = self._client
        if client is not None:
            while True:
                try:
                    data = client.recv(_CHUNK)
                except BlockingIOError:
                    break
                except OSError:
                    data = b""
                if not data:               # the client hung up: wait for the next one
                    self._drop_client()
                    client = None
                    break
                self.link.host_write(data)
                self.bytes_in += len(data)
                moved += len(data)
        out = self.link.host_read_available()
        if client is None:
            self.bytes_discarded += len(out) + len(self._out)
            self._out.clear()
            return moved
        if out:
            self._out += out
        if self._out:
            try:
                n = client.send(self._out)
            except BlockingIOError:
                n = 0
            except OSError:
                self._drop_client()
                return moved
            del self._out[:n]
            self.bytes_out += n
            moved += n
        return moved

    def close(self) -> None:
        """Close the client connection and the listening socket."""
        if self.closed:
            return
        self.closed = True
        self._drop_client()
        with contextlib.suppress(OSError):
            self._server.close()
