"""SIGINT and SIGTERM for the CLI: one exception each, raised where the program is, and critical
sections (closing and renaming the outputs) during which a signal waits (docs/scenarios.md,
"Signals").

``install()`` (the CLI's first instruction): SIGINT raises :class:`Interrupted`, SIGTERM
:class:`Terminated`, both ``KeyboardInterrupt`` s, so every ``finally`` closes its files as for
Ctrl-C, and the CLI exits 130 or 143. ``with deferred():`` holds both signals back for the
duration of a block that must not be cut in the middle (a file's last write and rename): a signal
that arrives meanwhile is recorded (:func:`pending`, so a long block such as the compaction of a
recording can give up early) and delivered when the outermost block ends. Outside the main
thread, or where nobody installed handlers, the same code runs with Python's defaults.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any

__all__ = ["Interrupted", "Terminated", "EXIT_CODES", "install", "restore", "deferred", "pending",
           "deferring", "exit_code", "is_signal", "signal_cause", "on_hard_exit", "hard_exit"]


class Interrupted(KeyboardInterrupt):
    """SIGINT (Ctrl-C) delivered by :func:`install`'s handler."""


class Terminated(KeyboardInterrupt):
    """SIGTERM delivered by :func:`install`'s handler."""


EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}
_RAISE = {signal.SIGINT: Interrupted, signal.SIGTERM: Terminated}
_state: dict[str, Any] = {"depth": 0, "pending": [], "saved": {}, "installed": {}}


def _raise(signum: int, frame: FrameType | None) -> None:
    raise _RAISE[signal.Signals(signum)]()


def _record(signum: int, frame: FrameType | None) -> None:
    _state["pending"].append(signum)


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def install() -> None:
    """SIGINT -> :class:`Interrupted`, SIGTERM -> :class:`Terminated` (main thread only)."""
    if not _main_thread():
        return
    for sig in _RAISE:
        prev = signal.signal(sig, _raise)
        _state["installed"].setdefault(sig, prev)


def restore(exiting: bool = False) -> None:
    """Put back the handlers :func:`install` replaced; ``exiting``: the process ends now (the
    console script), so SIGINT and SIGTERM are ignored instead: after the last rename a signal
    changes nothing, and the interpreter's shutdown (rerun's, MuJoCo's) must not end by the raw
    signal (exit -15) a run that has finished."""
    if not _main_thread():
        return
    for sig, prev in _state["installed"].items():
        signal.signal(sig, signal.SIG_IGN if exiting else signal.SIG_DFL if prev is None else prev)
    _state["installed"].clear()


def pending() -> int:
    """How many signals arrived during the current :func:`deferred` block (0: none)."""
    return len(_state["pending"])


def deferring() -> bool:
    """A :func:`deferred` block is running (the outputs' last writes and renames): the run's
    wall-clock limit waits too (``scenarios.arm_wall_timeout``)."""
    return _state["depth"] > 0


def is_signal(exc: BaseException) -> bool:
    """True for the exceptions :func:`install`'s handlers raise (a real Ctrl-C or SIGTERM), as
    opposed to a ``KeyboardInterrupt`` raised by user code (a control law, a host controller)."""
    return isinstance(exc, (Interrupted, Terminated))


def signal_cause(exc: BaseException) -> BaseException | None:
    """The :class:`Interrupted` / :class:`Terminated` that ``exc`` was raised from, if any: a
    signal landing in the import of an extension module (rerun, MuJoCo) comes out of it as an
    ``ImportError: initialization failed`` caused by the signal's exception."""
    seen = 0
    cur: BaseException | None = exc
    while cur is not None and seen < 20:
        if is_signal(cur):
            return cur
        cur = cur.__cause__ or cur.__context__
        seen += 1
    return None


def exit_code(exc: BaseException) -> int:
    """143 for :class:`Terminated`, 130 for any other ``KeyboardInterrupt``."""
    return EXIT_CODES[signal.SIGTERM] if isinstance(exc, Terminated) else EXIT_CODES[signal.SIGINT]


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back for the block; deliver the first that arrived at its end."""
    if not _main_thread():
        yield
        return
    outer = _state["depth"] == 0
    if outer:
        _state["pending"] = []
        _state["saved"] = {sig: signal.signal(sig, _record) for sig in _RAISE}
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1
        if outer:
            for sig, prev in _state["saved"].items():
                signal.signal(sig, signal.SIG_DFL if prev is None else prev)
            got, _state["pending"] = _state["pending"], []
            if got:
                signal.raise_signal(got[0])    # the handler in place now: ours raises, SIG_DFL ends


_cleanups: list[Any] = []


def on_hard_exit(fn: Any) -> None:
    """Run ``fn()`` in :func:`hard_exit` (the CLI removes its temporary files there)."""
    _cleanups.append(fn)


def hard_exit(code: int, message: str) -> None:
    """The last resort for user code that swallows every exception the run raises to end it
    (``except BaseException: pass`` in a loop): one line on stderr, the registered clean-ups,
    and the process ends with ``code`` at once (``os._exit``: no ``finally`` of the stuck code)."""
    import os
    import sys

    with contextlib.suppress(BaseException):
        sys.stderr.write(message.rstrip("\n") + "\n")
        sys.stderr.flush()
    for fn in _cleanups:
        with contextlib.suppress(BaseException):
            fn()
    os._exit(code)
