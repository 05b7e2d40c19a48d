"""stdout is the command's own: what user code prints goes to stderr (issue 36).

``run --json`` prints one JSON line alone on stdout and ``serve`` the port on its first line;
scripts, CI and ``sweep`` (which reads each run's last stdout line) rely on it. A scenario's
``drive``, a law or a host controller that prints (with or without a newline, through ``print``,
``sys.stdout``, ``sys.__stdout__``, ``os.write(1, ...)`` or a child process), or that closes
``sys.stdout``, must not break it. :func:`command_stdout` therefore, for the duration of a
command:

- keeps the real stdout for the command (a private duplicate of file descriptor 1): the stream
  it returns is what the command writes its summary or its port to;
- points file descriptor 1 at stderr, so that everything else written to stdout, at any level,
  goes to stderr;
- gives ``sys.stdout`` a stream of its own on stderr (unbuffered): user code may close it,
  the command's output is not affected.

When ``sys.stdout`` is not file descriptor 1 (a test's captured stdout), the same holds at the
Python level only: the captured stream is the command's, ``sys.stdout`` writes to ``sys.stderr``.
Everything is put back when the block ends.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
from collections.abc import Iterator
from typing import TextIO

__all__ = ["command_stdout"]


class _ToStderr(io.TextIOBase):
    """``sys.stdout`` while a command runs, where stdout is not file descriptor 1: writes go to
    the ``sys.stderr`` of the moment; closing it closes nothing else."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        if self.closed:
            raise ValueError("I/O operation on closed file.")
        return sys.stderr.write(text)

    def flush(self) -> None:
        if not self.closed:
            sys.stderr.flush()


def _fd_one() -> bool:
    """``sys.stdout`` writes to file descriptor 1 (the process's real stdout)."""
    try:
        return sys.stdout is not None and sys.stdout.fileno() == 1
    except (AttributeError, OSError, ValueError):
        return False


@contextlib.contextmanager
def command_stdout() -> Iterator[TextIO | None]:
    """The command's stdout for the block (None when the process has none: started with stdout
    closed); meanwhile everything else written to stdout goes to stderr (module docstring)."""
    saved = sys.stdout
    if not _fd_one():
        sys.stdout = _ToStderr()
        try:
            yield saved
        finally:
            sys.stdout = saved
        return
    with contextlib.suppress(BaseException):
        saved.flush()
    private = os.dup(1)             # not inheritable: a child process never gets it
    real = open(private, "w", encoding=saved.encoding, errors=saved.errors, closefd=True)  # noqa: SIM115
    try:
        err = os.dup(2)
    except OSError:                 # no stderr either: user output goes nowhere
        err = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(err, 1)
    finally:
        os.close(err)
    user = open(1, "w", buffering=1, encoding=saved.encoding, errors="backslashreplace",  # noqa: SIM115
                closefd=False)
    user.reconfigure(write_through=True)     # in order with stderr's lines, newline or not
    sys.stdout = user
    try:
        yield real
    finally:
        user = sys.stdout
        sys.stdout = saved
        for stream in (user, real):
            with contextlib.suppress(BaseException):
                stream.flush()
        os.dup2(private, 1)
        with contextlib.suppress(BaseException):
            real.close()
