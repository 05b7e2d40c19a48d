"""pyserial URL handler ``twin://NAME``: the host end of a registered :class:`SerialLink`.

``import humanoid_twin.bus`` appends ``"humanoid_twin.bus"`` to
``serial.protocol_handler_packages``; then

    ser = serial.serial_for_url("twin://NAME", baudrate=115200, parity="E", timeout=0.5)

opens, in the same process, the PC end of the cable that the twin registered with
``register_link(NAME, link, advance)``. The twin runs in lockstep with the host code: reading
advances the twin's virtual clock (``advance(t_us)``) until the bytes asked for have arrived or
the *virtual* timeout has elapsed. ``ser.virtual_time_s()`` and ``ser.sleep(seconds)`` give host
code a time base that is the twin's.

Options in the URL query: ``twin://NAME?step_us=100`` (the clock step while waiting for a byte
that has not been sent yet; default 100 us).
"""

from __future__ import annotations

import threading
import urllib.parse
from collections.abc import Callable
from typing import Any

import serial
from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from humanoid_twin.bus.serial_link import SerialLink
from humanoid_twin.clock import US_PER_S
from humanoid_twin.protocol.wire import BAUDRATE, PARITY

DEFAULT_STEP_US = 100

_LINKS: dict[str, tuple[SerialLink, Callable[[int], None]]] = {}
_OPEN: set[str] = set()
_LOCK = threading.Lock()


def register_link(name: str, link: SerialLink, advance: Callable[[int], None]) -> None:
    """Make ``twin://name`` open the host end of ``link``.

    ``advance(t_us)`` must run the twin (its clock and everything on it) up to ``t_us``.
    """
    if not isinstance(name, str) or not name or any(ch in name for ch in "/?#: "):
        raise ValueError(f"twin link name must be a non-empty string without '/?#: ', got {name!r}")
    if not isinstance(link, SerialLink):
        raise TypeError(f"register_link needs a SerialLink, got {type(link).__name__}")
    if not callable(advance):
        raise TypeError("advance must be callable: advance(t_us) runs the twin up to t_us")
    with _LOCK:
        _LINKS[name] = (link, advance)


def unregister_link(name: str) -> None:
    """Forget ``twin://name`` (ports already open keep working)."""
    with _LOCK:
        _LINKS.pop(name, None)


def registered_links() -> list[str]:
    """The names that ``twin://`` can open."""
    with _LOCK:
        return sorted(_LINKS)


class Serial(SerialBase):
    """The PC end of a twin serial link, as a pyserial port (reads advance virtual time)."""

    BAUDRATES = SerialBase.BAUDRATES + (230400, 460800, 921600)

    def __init__(self, *args: Any, **kwargs: Any) -> None:   # pyserial's own arguments, passed on
        self._link: SerialLink | None = None
        self._advance: Callable[[int], None] | None = None
        self._name: str | None = None
        self._step_us = DEFAULT_STEP_US
        self._rx = bytearray()
        super().__init__(*args, **kwargs)

    # -- open / close ------------------------------------------------------------------------
    def open(self) -> None:
        """Attach to the registered link named in the URL."""
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        name, step = self.from_url(self._port)
        with _LOCK:
            entry = _LINKS.get(name)
            if entry is None:
                known = ", ".join(sorted(_LINKS)) or "none"
                raise SerialException(
                    f"twin://{name}: no twin link registered under that name (registered: {known}); "
                    "the twin calls humanoid_twin.bus.register_link(name, link, advance)")
            if name in _OPEN:
                raise SerialException(f"twin://{name} is already open (a serial port has one host end)")
            _OPEN.add(name)
        self._link, self._advance = entry
        self._name = name
        self._step_us = step
        self._rx = bytearray()
        self.is_open = True
        try:
            self._reconfigure_port()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Release the host end (the link stays registered)."""
        if self.is_open:
            self.is_open = False
            with _LOCK:
                _OPEN.discard(self._name)
        self._link = None
        self._advance = None

    def from_url(self, url: str) -> tuple[str, int]:
        """Parse ``twin://NAME[?step_us=N]``."""
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "twin" or not parts.netloc:
            raise SerialException(f"expected a URL of the form twin://NAME[?step_us=N], got {url!r}")
        step = DEFAULT_STEP_US
        for option, values in urllib.parse.parse_qs(parts.query, True).items():
            if option == "step_us":
                try:
                    step = int(values[0])
                except ValueError:
                    step = 0
                if step <= 0:
                    raise SerialException(f"twin:// option step_us must be a positive int, got {values[0]!r}")
            else:
                raise SerialException(f"twin:// unknown option {option!r} (known: step_us)")
        return parts.netloc, step

    def _reconfigure_port(self) -> None:
        """Settings are checked against the link when data moves (see ``_check_settings``)."""
        if not isinstance(self._baudrate, int) or self._baudrate <= 0:
            raise ValueError(f"invalid baudrate: {self._baudrate!r}")

    def _check_settings(self) -> SerialLink:
        link = self._link
        if not self.is_open or link is None:
            raise PortNotOpenError()
        stop = 2 if self._stopbits == serial.STOPBITS_TWO else 1 if self._stopbits == 1 else None
        if (self._baudrate != link.baudrate or self._bytesize != link.bytesize
                or self._parity != link.parity or stop != link.stopbits):
            raise SerialException(
                f"twin://{self._name}: the link runs at {link.baudrate} baud "
                f"{link.bytesize}{link.parity}{link.stopbits} (seed 002 slide 7) but the port is set to "
                f"{self._baudrate} baud {self._bytesize}{self._parity}{self._stopbits}: "
                f"open it with baudrate={BAUDRATE}, parity='{PARITY}'")
        return link

    # -- time base ---------------------------------------------------------------------------
    def virtual_time_s(self) -> float:
        """The twin's virtual time in seconds."""
        if self._link is None:
            raise PortNotOpenError()
        return self._link.clock.now_us / US_PER_S

    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` of virtual time pass (the twin runs meanwhile)."""
        if self._link is None or self._advance is None:
            raise PortNotOpenError()
        if seconds < 0:
            raise ValueError(f"sleep needs seconds >= 0, got {seconds!r}")
        self._advance(self._link.clock.now_us + round(seconds * US_PER_S))

    # -- data --------------------------------------------------------------------------------
    def _pull(self, link: SerialLink) -> None:
        data = link.host_read_available()
        if data:
            self._rx += data

    @property
    def in_waiting(self) -> int:
        """Bytes received (stop bit at or before the twin's now) and not read yet."""
        link = self._check_settings()
        self._pull(link)
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Read ``size`` bytes, advancing virtual time until they arrive or ``timeout`` elapses."""
        link = self._check_settings()
        if size < 0:
            raise ValueError(f"read size must be >= 0, got {size!r}")
        self._pull(link)
        if len(self._rx) < size and self._timeout != 0:
            clock = link.clock
            advance = self._advance
            assert advance is not None
            deadline = None if self._timeout is None else clock.now_us + round(self._timeout * US_PER_S)
            while len(self._rx) < size:
                now = clock.now_us
                if deadline is not None and now >= deadline:
                    break
                # the stop bit of the last byte still missing, when it is on its way (the bytes
                # before it arrive on the way: nothing else is waited for)
                nxt = link.host_byte_us(size - len(self._rx))
                target = nxt if nxt is not None and nxt > now else now + self._step_us
                if deadline is not None and target > deadline:
                    target = deadline
                advance(target)
                if clock.now_us < target:
                    raise SerialException(f"twin://{self._name}: advance({target}) did not run the clock")
                self._pull(link)
        out = bytes(self._rx[:size])
        del self._rx[:size]
        return out

    def write(self, data: bytes) -> int:  # type: ignore[override]  # as pyserial's ports (stubs: Buffer)
        """Hand ``data`` to the link; it goes on the line at the twin's now."""
        link = self._check_settings()
        data = serial.to_bytes(data)
        link.host_write(data)
        return len(data)

    def flush(self) -> None:
        """Run the twin until every written byte has reached the device."""
        link = self._check_settings()
        if link.host_out_waiting() and self._advance is not None:
            self._advance(link.host_out_done_us())

    def reset_input_buffer(self) -> None:
        """Discard the bytes already received."""
        link = self._check_settings()
        link.host_reset_input()
        self._rx.clear()

    def reset_output_buffer(self) -> None:
        """Discard written bytes that have not started on the line."""
        link = self._check_settings()
        link.host_reset_output()

    @property
    def out_waiting(self) -> int:
        """Bytes written and not yet at the device."""
        return self._check_settings().host_out_waiting()

    # modem lines: a 3-wire cable (TX, RX, GND), nothing to do
    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        """Always True (no handshake lines)."""
        return True

    @property
    def dsr(self) -> bool:
        """Always True (no handshake lines)."""
        return True

    @property
    def ri(self) -> bool:
        """Always False."""
        return False

    @property
    def cd(self) -> bool:
        """Always True."""
        return True
