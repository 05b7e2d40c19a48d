"""The guard around user code: control laws (``--law``) and host controllers
(``--host-controller``) (issue 24; docs/controllers.md, "What the twin guards against"), and
around the output paths users name (:func:`output_target`, issue 36).

What user code raises or returns is judged here, inside the guard: any exception, ``SystemExit``
and a ``KeyboardInterrupt`` the code raised itself (not a real Ctrl-C or SIGTERM, which the CLI's
handlers raise as :class:`humanoid_twin.signals.Interrupted` / ``Terminated``) is the code's
fault; what it returns is checked without trusting it (its ``len``, indexing and ``repr`` may
raise or be huge); every message is one line of bounded length.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from humanoid_twin import signals

__all__ = ["MESSAGE_LIMIT", "user_fault", "short_repr", "describe", "law_output", "attribute_path",
           "OutputPathError", "output_target"]

MESSAGE_LIMIT = 200          # characters of a value or an exception message in a fault's reason


def attribute_path(obj: Any, dotted: str) -> Any:
    """The object at ``dotted`` (``NAME`` or ``Class.attr``) inside ``obj`` (a user's module): the
    NAME part of a ``module:NAME`` reference (``--law``, ``--host-controller``, a scenario).
    ``AttributeError`` when a part is missing; each caller says so in its own words."""
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


def user_fault(exc: BaseException) -> bool:
    """True when ``exc``, raised out of user code, is that code's fault: any ``Exception``,
    ``SystemExit``, or a ``KeyboardInterrupt`` it raised itself. False for a real signal and for
    the twin's own control flow (its ``BaseException`` s, e.g. the end of the run)."""
    if isinstance(exc, KeyboardInterrupt):
        return not signals.is_signal(exc)
    return isinstance(exc, (Exception, SystemExit))


def _one_line(text: str, limit: int) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def short_repr(obj: Any, limit: int = MESSAGE_LIMIT) -> str:
    """``repr(obj)`` on one line, at most ``limit`` characters; a ``repr`` that raises or is a
    non-string gives ``<TYPE object>``. Sequences longer than 8 items are not ``repr``'d at all
    (a law returning two million values must not cost a 17 MB line)."""
    name = type(obj).__name__
    try:
        n = len(obj) if isinstance(obj, (list, tuple, dict, set, frozenset, str, bytes)) else None
        if n is not None and n > 8:
            return f"<{name} of {n} items>"
        text = repr(obj)
        if not isinstance(text, str):
            raise TypeError
    except BaseException as exc:       # noqa: BLE001 - a hostile repr: judged, not trusted
        if not user_fault(exc):
            raise
        return f"<{_one_line(name, 60)} object>"
    return _one_line(text, limit)


def describe(exc: BaseException, limit: int = MESSAGE_LIMIT) -> str:
    """``TYPE: message`` of an exception from user code, one line, bounded (its ``str`` may raise)."""
    try:
        text = str(exc)
    except BaseException as err:       # noqa: BLE001
        if not user_fault(err):
            raise
        text = "<unprintable message>"
    name = _one_line(type(exc).__name__, 60)
    return f"{name}: {_one_line(text, limit)}" if text else name


def law_output(values: Any, servos: Sequence[int], n_servos: int, lo: int, hi: int,
               what: str) -> tuple[tuple[int, ...] | None, str | None]:
    """Check what a law's ``step`` returned: ``n_servos`` values, ``int`` s (not ``bool``) within
    ``lo..hi`` for the servos in ``servos``. Returns ``(values as a tuple, None)``, or ``(None,
    reason)`` with a one-line reason. ``len``, indexing and iteration of the returned object are
    guarded (a hostile object is a bad value, not a crash)."""
    try:
        n = len(values)
    except BaseException as exc:       # noqa: BLE001
        if not user_fault(exc):
            raise
        n = -1
    if n != n_servos:
        return None, f"step returned {short_repr(values)}: expected {n_servos} ints, one per servo"
    out = [0] * n_servos
    for j in servos:
        try:
            v = values[j]
        except BaseException as exc:   # noqa: BLE001
            if not user_fault(exc):
                raise
            return None, f"step returned {short_repr(values)}: its item {j} raised {describe(exc)}"
        if type(v) is not int:
            return None, (f"step returned {short_repr(v, 60)} ({_one_line(type(v).__name__, 60)}) for servo "
                          f"{j}: the firmware computes with ints only")
        if not lo <= v <= hi:
            return None, f"step returned {what} {short_repr(v, 60)} for servo {j}, outside {lo}..{hi}"
        out[j] = v
    return tuple(out), None


class OutputPathError(ValueError):
    """An output path the twin must not write (one line: the CLI's exit 2)."""


_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory"))


def output_target(path: str | Path, what: str) -> Path:
    """The file an output named ``path`` is written to: ``path`` itself or, through symbolic links,
    the file they lead to (a link is followed, never replaced by a file). An existing target that
    is not a regular file (a FIFO, a device, a socket, a directory) is refused: the twin writes an
    output under a temporary name beside it and renames it there at the end, which would replace
    it (``--serial-log /dev/null`` as root: the system's ``/dev/null``), and writing in place would
    block on a FIFO without a reader and cannot be undone when the run fails.
    :class:`OutputPathError` (one line naming ``what``) then, or when the links loop."""
    given = Path(path).expanduser()
    target = Path(os.path.realpath(given))
    via = f" (through a link: {target})" if given.is_symlink() else ""
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        return target
    except OSError as exc:
        raise OutputPathError(f"{what} {path}: {exc.strerror or exc}{via}") from None
    if stat.S_ISREG(mode):
        return target
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    raise OutputPathError(f"{what} {path} is {kind}{via}, not a regular file: the twin writes its outputs "
                          "to files only (it would be replaced); give a file's path")
