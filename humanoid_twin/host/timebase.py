"""The host's time base: one clock for every port type.

Host loops (``exe_traj``, ``cop_acquire``, ``recycle``'s wait) measure and wait time through
:func:`now` and :func:`sleep`. A port that carries its own clock (the in-process ``twin://`` port:
reading it advances the twin's virtual clock) exposes ``virtual_time_s()`` and ``sleep(s)``;
any other port (a real device, a pty, ``socket://``) runs on the wall clock
(``time.monotonic()`` / ``time.sleep()``). The host code is the same for all of them.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort, SerialPort

__all__ = ["now", "sleep", "port_of"]


def port_of(H: HostPort) -> SerialPort:
    """The pyserial port behind ``H``: ``H`` itself, or the ``port`` of a :class:`HumanoidClient`."""
    inner = getattr(H, "serial_port", None)
    return H if inner is None else inner  # type: ignore[return-value]  # H holds no port: it is one


def now(H: HostPort) -> float:
    """Seconds on ``H``'s time base (virtual time for a ``twin://`` port, else ``time.monotonic()``)."""
    f = getattr(port_of(H), "virtual_time_s", None)
    return float(f()) if f is not None else time.monotonic()


def sleep(H: HostPort, seconds: float) -> None:
    """Wait ``seconds`` on ``H``'s time base (advances the twin for a ``twin://`` port)."""
    if seconds != seconds or seconds < 0:  # NaN or negative
        raise ValueError(f"sleep needs a duration >= 0 s, got {seconds!r}")
    if seconds == 0:
        return
    f = getattr(port_of(H), "sleep", None)
    if f is not None:
        f(seconds)
    else:
        time.sleep(seconds)
