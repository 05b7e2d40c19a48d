"""stdout is the command's own: what user code prints goes to stderr (issue 36).

``run --json`` prints one JSON line alone on stdout and ``serve`` the port on its first line;
scripts, CI and ``sweep`` (which reads each run's last stdout line) rely on it. A scenario's
``drive``, a law or a host controller that prints (with or without a newline, through ``print``,
``sys.stdout``, ``sys.__stdout__``, ``os.write(1, ...)`` or a child process), or that closes
``sys.stdout``, ``sys.stderr`` or their file descriptors, must not break it. For the duration of a
command, :func:`command_streams` therefore:

- keeps the real stdout for the command (a private duplicate of file descriptor 1): the stream
  it returns is what the command writes its summary or its port to;
- points file descriptor 1 at stderr, so that everything else written to stdout, at any level,
  goes to stderr, in order with stderr's own lines (unbuffered);
- gives ``sys.stdout`` a stream of its own on stderr: user code may close it;
- gives ``sys.stderr`` a stream on a private duplicate of file descriptor 2 that closing does
  not close: the command's own messages (one line on failure, the files written) still get out
  when user code closed ``sys.stderr`` or file descriptor 2.

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

__all__ = ["command_streams"]


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


class _KeptOpen(io.TextIOWrapper):
    """``sys.stderr`` while a command runs: ``close()`` (user code's) only flushes it."""

    def close(self) -> None:
        with contextlib.suppress(OSError, ValueError):
            self.flush()

    def really_close(self) -> None:
        io.TextIOWrapper.close(self)


def _fd_one() -> bool:
    """``sys.stdout`` writes to file descriptor 1 (the process's real stdout)."""
    try:
        return sys.stdout is not None and sys.stdout.fileno() == 1
    except (AttributeError, OSError, ValueError):
        return False


def _dup(fd: int) -> int | None:
    try:
        return os.dup(fd)           # not inheritable: a child process never gets it
    except OSError:                 # the process was started without it
        return None


@contextlib.contextmanager
def command_streams() -> Iterator[TextIO | None]:
    """The command's stdout for the block (None when the process has none: started with stdout
    closed); meanwhile everything else written to stdout goes to stderr (module docstring)."""
    saved_out, saved_err = sys.stdout, sys.stderr
    if not _fd_one():
        sys.stdout = _ToStderr()
        try:
            yield saved_out
        finally:
            sys.stdout = saved_out
        return
    for stream in (saved_out, saved_err):
        with contextlib.suppress(BaseException):
            if stream is not None:
                stream.flush()
    out_fd, err_fd = _dup(1), _dup(2)
    real = None if out_fd is None else open(out_fd, "w", encoding=saved_out.encoding,  # noqa: SIM115
                                            errors=saved_out.errors, closefd=True)
    err = None
    if err_fd is not None:
        encoding = getattr(saved_err, "encoding", None) or "utf-8"
        err = _KeptOpen(open(os.dup(err_fd), "wb", buffering=0), encoding=encoding,  # noqa: SIM115
                        errors="backslashreplace", line_buffering=True, write_through=True)
    to_err = os.open(os.devnull, os.O_WRONLY) if err_fd is None else os.dup(err_fd)
    try:
        os.dup2(to_err, 1)
    finally:
        os.close(to_err)
    user = io.TextIOWrapper(open(1, "wb", buffering=0, closefd=False),  # noqa: SIM115
                            encoding=saved_out.encoding, errors="backslashreplace", line_buffering=True,
                            write_through=True)
    sys.stdout = user
    if err is not None:
        sys.stderr = err
    try:
        yield real
    finally:
        sys.stdout, sys.stderr = saved_out, saved_err
        for stream in (user, err, real):
            with contextlib.suppress(BaseException):
                if stream is not None:
                    stream.flush()
        if out_fd is not None:
            os.dup2(out_fd, 1)
        if err_fd is not None:
            os.dup2(err_fd, 2)
            os.close(err_fd)
        with contextlib.suppress(BaseException):
            if err is not None:
                err.really_close()
        with contextlib.suppress(BaseException):
            if real is not None:
                real.close()
