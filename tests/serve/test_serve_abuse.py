"""``humanoid-twin serve`` under abuse, on loopback only: a real server process, real sockets,
real ptys and pyserial clients. Bounded in count and time; every server is stopped at the end.

What a user notices: the bytes a client gets back, how long it waits, the server's memory, the
lines on the server's stderr.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time

import pytest
import serial

from humanoid_twin.protocol.rs232 import PARAM_TEST, TEST_MESSAGE, Op, encode_request

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

TEST_REQUEST = encode_request(Op.MASTER, 0, PARAM_TEST)
# a partial frame that, completed by the next client's 0xFF, is a valid APPLY_JOINT (BCC FF^04^5A^5A^04 = FF)
CRAFTED_LEFTOVER = bytes.fromhex("FF045A5A04")


class Server:
    """``humanoid-twin serve`` in a child process; ``stop()`` returns its stderr."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "humanoid_twin.cli.main", "serve", *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        self.url = self.proc.stdout.readline().strip()
        if not self.url:
            self.proc.kill()
            raise AssertionError(f"serve printed no port: {self.proc.communicate()[1][-2000:]}")
        self.err = ""

    @property
    def address(self) -> tuple[str, int]:
        host, port = self.url.removeprefix("socket://").rsplit(":", 1)
        return host.strip("[]"), int(port)

    def rss_mb(self) -> float:
        with open(f"/proc/{self.proc.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024
        raise AssertionError("no VmRSS")

    def stop(self) -> str:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            _, self.err = self.proc.communicate(timeout=20)
        finally:
            self.proc.kill()
        return self.err


@pytest.fixture(scope="module")
def tcp_server():
    srv = Server("--tcp", "0", "--idle-timeout", "2")
    yield srv
    srv.stop()


def connect(address: tuple[str, int], timeout: float = 2.0) -> socket.socket:
    return socket.create_connection(address, timeout=timeout)


def read_n(s: socket.socket, n: int, timeout: float = 2.0) -> bytes:
    """Up to ``n`` bytes, or what came before EOF / ``timeout``."""
    s.settimeout(timeout)
    got = b""
    end = time.monotonic() + timeout
    try:
        while len(got) < n and time.monotonic() < end:
            d = s.recv(n - len(got))
            if not d:
                break
            got += d
    except (TimeoutError, ConnectionError):
        pass
    return got


def ask(address: tuple[str, int], payload: bytes = TEST_REQUEST, n: int = 6) -> bytes:
    with connect(address) as s:
        s.sendall(payload)
        return read_n(s, n)


def test_a_client_gets_its_own_answer_after_a_client_died_mid_frame(tcp_server):
    for _ in range(5):
        with connect(tcp_server.address) as dying:
            dying.sendall(CRAFTED_LEFTOVER)          # dies before the BCC
        assert ask(tcp_server.address) == TEST_MESSAGE   # not FB 04 5A 5A 04 FB (an APPLY it never sent)


def test_fifty_reconnects_are_quick_and_each_gets_its_answer(tcp_server):
    t0 = time.monotonic()
    answers = [ask(tcp_server.address) for _ in range(50)]
    elapsed = time.monotonic() - t0
    assert answers == [TEST_MESSAGE] * 50
    assert elapsed < 10.0, f"50 reconnects took {elapsed:.1f} s (a dropped SYN costs 1 s)"


def test_half_close_still_gets_the_answer(tcp_server):
    with connect(tcp_server.address) as s:
        s.sendall(TEST_REQUEST)
        s.shutdown(socket.SHUT_WR)                   # printf ... | socat - tcp:...
        assert read_n(s, 7) == TEST_MESSAGE          # the answer, then EOF


def test_second_client_is_refused_while_the_first_keeps_its_line(tcp_server):
    with connect(tcp_server.address) as first:
        first.sendall(TEST_REQUEST)
        assert read_n(first, 6) == TEST_MESSAGE
        with connect(tcp_server.address) as second:
            second.sendall(TEST_REQUEST)
            assert read_n(second, 6, timeout=3.0) == b""      # closed: EOF, no answer
        first.sendall(TEST_REQUEST)
        assert read_n(first, 6) == TEST_MESSAGE


def test_a_silent_client_is_disconnected_after_the_idle_timeout(tcp_server):
    with connect(tcp_server.address) as silent:
        t0 = time.monotonic()
        assert read_n(silent, 1, timeout=8.0) == b""
        waited = time.monotonic() - t0
    assert 1.5 < waited < 6.0
    assert ask(tcp_server.address) == TEST_MESSAGE


def test_garbage_flood_is_bounded_and_the_next_client_is_answered(tcp_server):
    rss0 = tcp_server.rss_mb()
    garbage = os.urandom(1 << 20)
    sent = 0
    with connect(tcp_server.address) as flood:
        flood.setblocking(False)
        end = time.monotonic() + 4.0
        while sent < 10 * len(garbage) and time.monotonic() < end:
            try:
                sent += flood.send(garbage[sent % len(garbage):])
            except BlockingIOError:
                time.sleep(0.01)
        rss = tcp_server.rss_mb()
        # the server takes about 1 s of line time (10 473 bytes), the kernel buffers hold the rest
        assert rss - rss0 < 20, f"RSS {rss0:.0f} -> {rss:.0f} MB after {sent} garbage bytes"
        assert sent < 10 * len(garbage)              # backpressure: the client could not push 10 MB
    t0 = time.monotonic()
    assert ask(tcp_server.address) == TEST_MESSAGE
    assert time.monotonic() - t0 < 1.0


def test_server_log_lines(tcp_server):
    ask(tcp_server.address)
    err = tcp_server.stop()
    assert "one client at a time" in err
    assert "connected" in err and "left (closed the connection)" in err
    assert "left (half-closed, answered)" in err
    assert "refused: busy with client" in err
    assert "left (idle for more than 2 s)" in err
    assert "sends faster than the line carries" in err
    assert "Traceback" not in err


def test_ipv6_loopback():
    if not socket.has_ipv6:
        pytest.skip("no IPv6")
    try:
        with socket.socket(socket.AF_INET6) as s:
            s.bind(("::1", 0))
    except OSError:
        pytest.skip("no IPv6 loopback here")
    srv = Server("--tcp", "0", "--host", "::1")
    try:
        assert srv.url.startswith("socket://[::1]:")
        assert ask(srv.address) == TEST_MESSAGE
        # pyserial opens the printed URL as it is
        port = serial.serial_for_url(srv.url, timeout=2)
        try:
            port.write(TEST_REQUEST)
            assert port.read(6) == TEST_MESSAGE
        finally:
            port.close()
    finally:
        assert "Traceback" not in srv.stop()


PTY_CLIENT = (
    "import sys, serial\n"
    "p = serial.Serial(sys.argv[1], 115200, parity='E', timeout=2)\n"
    "p.write(bytes.fromhex(sys.argv[2])); print(p.read(6).hex()); p.close()\n"
)


def test_pty_every_client_opens_it_at_8e1_and_starts_clean():
    srv = Server("--pty")
    try:
        port = srv.url
        assert port.startswith("/dev/")
        for payload in (TEST_REQUEST, CRAFTED_LEFTOVER, TEST_REQUEST, TEST_REQUEST):
            r = subprocess.run([sys.executable, "-c", PTY_CLIENT, port, payload.hex()],
                               capture_output=True, text=True, timeout=30)
            assert r.returncode == 0, r.stderr[-1500:]
            if payload == TEST_REQUEST:
                assert r.stdout.strip() == TEST_MESSAGE.hex()
        time.sleep(0.1)
    finally:
        err = srv.stop()
    assert err.count("closed the port") >= 4
    assert "Traceback" not in err


@pytest.mark.skipif(shutil.which("setpriv") is None and os.geteuid() == 0,
                    reason="root opens an exclusive tty anyway; setpriv is needed to drop that right")
def test_pty_is_exclusive_while_a_client_has_it_open():
    srv = Server("--pty")
    try:
        first = serial.Serial(srv.url, 115200, parity="E", timeout=2)
        try:
            first.write(TEST_REQUEST)
            assert first.read(6) == TEST_MESSAGE        # the session has started (exclusive now)
            second = [sys.executable, "-c", PTY_CLIENT, srv.url, TEST_REQUEST.hex()]
            if os.geteuid() == 0:                       # as a user without CAP_SYS_ADMIN
                second = ["setpriv", "--inh-caps=-sys_admin", "--bounding-set=-sys_admin", *second]
            r = subprocess.run(second, capture_output=True, text=True, timeout=30)
            assert r.returncode != 0 and "Device or resource busy" in r.stderr
            first.write(TEST_REQUEST)
            assert first.read(6) == TEST_MESSAGE
        finally:
            first.close()
    finally:
        assert "Traceback" not in srv.stop()
