"""The collaborators that several classes can play, as structural types (:class:`typing.Protocol`)
for the type checker (tests/project/test_types.py) and the reader.

A function that takes one of these takes any object with these members; nothing here is checked
at run time. This module is at the bottom of the package: it imports nothing of it (a module that
names one of these imports it under ``if TYPE_CHECKING:``). A collaborator that is one class of
the package is named by that class instead, imported the same way.
"""

from __future__ import annotations

from typing import Protocol, TypeAlias


class SerialPort(Protocol):
    """A pyserial port as the host drivers use it (``humanoid_twin.host.drivers``, seed 000's
    ``H``): a ``serial.Serial`` on a device or a pty, a ``socket://`` port, or the in-process
    ``twin://`` port (which also carries the twin's clock: ``virtual_time_s()``, ``sleep(s)``,
    found by ``humanoid_twin.host.timebase``)."""

    @property
    def in_waiting(self) -> int: ...

    def write(self, data: bytes, /) -> int | None: ...

    def read(self, size: int = 1, /) -> bytes: ...

    def reset_input_buffer(self) -> None: ...

    def reset_output_buffer(self) -> None: ...

    def close(self) -> None: ...


class PortHolder(Protocol):
    """An object that holds a :class:`SerialPort` as ``serial_port`` (a
    ``humanoid_twin.host.drivers.HumanoidClient``): the drivers take it wherever they take a port."""

    @property
    def serial_port(self) -> SerialPort: ...


HostPort: TypeAlias = "SerialPort | PortHolder"
"""The host's ``H`` (seed 000: the handle ``initcom`` returns): a port, or a client holding one."""
