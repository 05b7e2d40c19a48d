"""The twin's pty takes the settings serial libraries make, in any order (issue 27).

A Linux pty keeps no parity bit, and the C library of Debian and Ubuntu answers ``EINVAL`` to a
``tcsetattr`` whose only effect would have been ``PARENB`` (docs/serve.md, "The
pty and parity"). These tests drive ``humanoid-twin serve``'s pty with raw termios calls made the
way real clients make them, one setting per call (speed, parity, data bits, stop bits) or all at
once, at open and again later in the same connection, with the short pause between two calls that
a program has; every call must be accepted and the test message must come back afterwards:

- ``pyserial``: read the settings, rewrite them (clears ``INPCK``, ``CMSPAR``, sets the parity),
  write them back;
- ``asio``: read-modify-write as Boost.Asio sets a parity (``INPCK`` on, ``IGNPAR`` off);
- ``octave``: the settings kept by the client from a clean slate and sent whole at every call, as
  Octave's instrument-control does (``c_iflag = 0``, ``c_cflag = CS8|CREAD|CLOCAL`` ...);
- ``bare``: read-modify-write touching nothing but ``PARENB``/``PARODD`` (even parity only: an
  odd request that changes nothing else cannot be told apart from one the pty already holds).

Then pyserial itself, opening at 115200 8E1 and changing its settings later.
"""

from __future__ import annotations

import itertools
import os
import select
import subprocess
import sys
import termios
import time
from collections.abc import Iterator

import pytest
import serial

from humanoid_twin.protocol.rs232 import PARAM_TEST, TEST_MESSAGE, Op, encode_request

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="Linux ptys")

TEST_REQUEST = encode_request(Op.MASTER, 0, PARAM_TEST)   # FF C0 00 00 00 3F
PAUSE_S = 0.05         # between two settings calls, as a program has (serve re-marks within ~10 ms)
T = termios


@pytest.fixture(scope="module")
def pty_port() -> Iterator[str]:
    """One ``humanoid-twin serve`` (pty) for the module; each test is a new client of it."""
    proc = subprocess.Popen([sys.executable, "-m", "humanoid_twin.cli.main", "serve"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 30)
        assert ready, "serve printed no port in 30 s"
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/"), port
        yield port
    finally:
        proc.terminate()
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


class Client:
    """A raw termios client of the pty in one of the styles of the module docstring."""

    def __init__(self, port: str, style: str) -> None:
        self.style = style
        self.fd = os.open(port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        self.kept: list | None = None
        if style == "octave":          # open: a clean slate, 9600 8N1, VMIN 0 VTIME 5, sent whole
            kept = T.tcgetattr(self.fd)
            kept[0] = kept[1] = kept[3] = 0
            kept[2] = T.CS8 | T.CREAD | T.CLOCAL
            kept[4] = kept[5] = T.B9600
            kept[6][T.VMIN], kept[6][T.VTIME] = 0, 5
            T.tcsetattr(self.fd, T.TCSANOW, kept)
            self.kept = kept

    def close(self) -> None:
        os.close(self.fd)
        time.sleep(0.1)                # serve sees the port closed: the next test is a new client

    def set(self, what: str) -> None:
        """One ``tcsetattr`` setting ``what`` (speed, even, odd, bits, stop or all); raises
        ``termios.error`` if refused."""
        attrs = self.kept if self.kept is not None else T.tcgetattr(self.fd)
        for item in (("speed", "even", "bits", "stop") if what == "all" else (what,)):
            self._change(attrs, item)
        T.tcsetattr(self.fd, T.TCSANOW, attrs)

    def _change(self, a: list, what: str) -> None:
        if what == "speed":
            a[4] = a[5] = T.B115200
        elif what == "bits":
            a[2] = (a[2] & ~T.CSIZE) | T.CS8
        elif what == "stop":
            a[2] &= ~T.CSTOPB
        elif what in ("even", "odd"):
            if self.style == "pyserial":
                a[0] &= ~(T.INPCK | T.ISTRIP)
                a[2] &= ~0o10000000000                      # CMSPAR
            elif self.style == "asio":
                a[0] = (a[0] & ~(T.IGNPAR | T.PARMRK)) | T.INPCK
            a[2] |= T.PARENB
            a[2] = a[2] | T.PARODD if what == "odd" else a[2] & ~T.PARODD
        else:
            raise ValueError(what)

    def exchange(self) -> bytes:
        """Send the test message request; the 6 bytes that come back within 5 s."""
        os.write(self.fd, TEST_REQUEST)
        got = b""
        end = time.monotonic() + 5
        while len(got) < 6 and time.monotonic() < end:
            if select.select([self.fd], [], [], 0.2)[0]:
                got += os.read(self.fd, 64)
        return got


def run(port: str, style: str, calls: tuple[str, ...]) -> list[str]:
    """Open, make ``calls`` with a pause before each, get the test message; then, later in the
    same connection, the same calls again and the test message again. Returns the refusals."""
    client = Client(port, style)
    refused = []
    try:
        for round_ in ("at open", "later"):
            for what in calls:
                time.sleep(PAUSE_S)
                try:
                    client.set(what)
                except T.error as exc:
                    refused.append(f"{round_}: {what} -> {exc}")
            assert client.exchange() == TEST_MESSAGE, (style, calls, round_)
    finally:
        client.close()
    return refused


SEQUENCES = [
    ("speed", "even"),            # speed then parity (Octave's order)
    ("even", "speed"),            # parity then speed
    ("even", "even"),             # parity twice
    ("odd", "even"),              # odd then even
    ("even", "odd", "even"),
    ("speed", "even", "bits", "stop"),
    ("all",),                     # everything in one call
    ("all", "all"),
]


@pytest.mark.parametrize("calls", SEQUENCES, ids="-".join)
@pytest.mark.parametrize("style", ["pyserial", "asio", "octave"])
def test_each_setting_in_its_own_call_is_accepted(pty_port: str, style: str, calls: tuple[str, ...]) -> None:
    assert run(pty_port, style, calls) == []


@pytest.mark.parametrize("calls", [c for c in SEQUENCES if "odd" not in c], ids="-".join)
def test_bare_even_parity_requests_are_accepted(pty_port: str, calls: tuple[str, ...]) -> None:
    assert run(pty_port, "bare", calls) == []


def test_every_order_of_the_four_settings_whole_settings_client(pty_port: str) -> None:
    """The strictest client (every call after the parity one carries PARENB again), all 24 orders."""
    refused = {}
    for order in itertools.permutations(("speed", "even", "bits", "stop")):
        client = Client(pty_port, "octave")
        try:
            for what in order:
                time.sleep(0.02)
                try:
                    client.set(what)
                except T.error as exc:
                    refused[order] = f"{what}: {exc}"
            assert client.exchange() == TEST_MESSAGE, order
        finally:
            client.close()
    assert refused == {}


def test_the_pty_shows_no_parity_bit_when_read_back(pty_port: str) -> None:
    """What a client reading its settings back can see: the speed it set, never PARENB."""
    client = Client(pty_port, "pyserial")
    try:
        time.sleep(PAUSE_S)
        client.set("all")
        attrs = T.tcgetattr(client.fd)
        assert attrs[4] == T.B115200 and attrs[2] & T.CSIZE == T.CS8
        assert not attrs[2] & T.PARENB
        assert client.exchange() == TEST_MESSAGE
    finally:
        client.close()


def test_pyserial_opens_at_8e1_and_changes_its_settings_later(pty_port: str) -> None:
    """pyserial rewrites the whole settings on every property change (with the parity bit): a
    timeout, parity or speed set after opening is accepted too (before issue 27: EINVAL)."""
    port = serial.Serial(pty_port, 115200, parity=serial.PARITY_EVEN, timeout=2)
    try:
        port.write(TEST_REQUEST)
        assert port.read(6) == TEST_MESSAGE
        for name, value in (("timeout", 1.0), ("parity", serial.PARITY_ODD),
                            ("parity", serial.PARITY_EVEN), ("baudrate", 115200), ("timeout", 2.0)):
            time.sleep(PAUSE_S)
            setattr(port, name, value)
        port.write(TEST_REQUEST)
        assert port.read(6) == TEST_MESSAGE
    finally:
        port.close()
        time.sleep(0.1)
