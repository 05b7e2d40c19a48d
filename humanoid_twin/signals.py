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

User code (a scenario's ``drive``, a law, a host controller) may swallow the exception
(``except BaseException: pass``; issue 36). While user code may run (:func:`user_code_runs`, from
the command's start to the rig's close: :func:`user_code_done`), a signal is therefore not only
raised once: it stays *pending*, and the twin raises it again each time it is asked to advance
(:func:`check`, called by ``Twin.advance_to``) and before a run's summary; and if the process has
not reached the rig's close :data:`GRACE_S` later (code that swallows it in a loop, or never
returns), :func:`hard_exit` ends the process (one line, the temporary files removed, 130 / 143).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

__all__ = ["Interrupted", "Terminated", "EXIT_CODES", "GRACE_S", "install", "restore", "deferred", "pending",
           "deferring", "exit_code", "is_signal", "signal_cause", "on_hard_exit", "hard_exit",
           "user_code_runs", "user_code_done", "stop_requested", "check", "end_process"]


class Interrupted(KeyboardInterrupt):
    """SIGINT (Ctrl-C) delivered by :func:`install`'s handler."""


class Terminated(KeyboardInterrupt):
    """SIGTERM delivered by :func:`install`'s handler."""


EXIT_CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}
GRACE_S = 2.0       # user code holding a signal back this long (wall s): the process ends at once
_RAISE = {signal.SIGINT: Interrupted, signal.SIGTERM: Terminated}
_WHY = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated (SIGTERM)"}
# "armed": user code may run (user_code_runs .. user_code_done); "stop": the first signal that
# arrived while armed (raised again by check()); "watchdog": its grace's thread
_state: dict[str, Any] = {"depth": 0, "pending": [], "saved": {}, "installed": {}, "armed": False,
                          "stop": None, "watchdog": None}


def _raise(signum: int, frame: FrameType | None) -> None:
    stop_requested(signum)
    raise _RAISE[signal.Signals(signum)]()


def user_code_runs() -> None:
    """From here on user code may run (the CLI's ``run`` and ``serve``, a sweep's checks): a
    signal stays pending (:func:`check`) and is enforced after :data:`GRACE_S`."""
    _state["armed"] = True


def user_code_done() -> None:
    """No user code runs from here (the rig closes its outputs, the CLI renames them and prints
    the summary): a pending signal is the twin's to handle, without a deadline (a long
    recording's compaction may finish, docs/scenarios.md "Signals")."""
    _state["armed"] = False
    _state["stop"] = None


def stop_requested(signum: int) -> None:
    """Signal ``signum`` asked the process to end: while user code may run, remember it (the
    first one) and start its grace (a daemon thread: after :data:`GRACE_S`, if the process has not
    reached :func:`user_code_done`, :func:`hard_exit`). ``serve``'s handlers call this too."""
    if not _state["armed"] or _state["stop"] is not None:
        return
    _state["stop"] = signum
    if _state["watchdog"] is None:
        watchdog = threading.Thread(target=_grace, args=(signum,), name="humanoid-twin-signal-grace",
                                    daemon=True)
        _state["watchdog"] = watchdog
        watchdog.start()


def _grace(signum: int) -> None:
    import time

    deadline = time.monotonic() + GRACE_S
    while time.monotonic() < deadline:
        if not _state["armed"]:
            _state["watchdog"] = None
            return
        time.sleep(0.02)
    if _state["armed"]:
        hard_exit(EXIT_CODES[signal.Signals(signum)],
                  f"humanoid-twin: {_WHY[signal.Signals(signum)]}; user code held the stop back for "
                  f"{GRACE_S:g} s: ended at once, nothing recorded (no file replaced)")
    _state["watchdog"] = None


def check() -> None:
    """Raise again the signal that arrived while user code may run, if any: called where the twin
    is asked to go on (``Twin.advance_to``, before a run's summary), so that user code that
    swallowed the first exception cannot carry the run on."""
    stop = _state["stop"]
    if stop is not None and _state["armed"] and _main_thread():
        raise _RAISE[signal.Signals(stop)]()


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


def restore(exiting: int | None = None) -> None:
    """Put back the handlers :func:`install` replaced; ``exiting``: the process ends now with
    this exit code (the console script): SIGINT and SIGTERM then end it at once with that code
    (the run is over, its files renamed, its summary printed: a signal changes nothing of it, and
    the interpreter's shutdown, rerun's or MuJoCo's, must not end by the raw signal, exit -15, a
    run that has finished), even while something of the user's holds the shutdown (an ``atexit``
    function that waits; issue 36)."""
    if not _main_thread():
        return
    user_code_done()
    for sig, prev in _state["installed"].items():
        if exiting is not None:
            signal.signal(sig, _exit_with(exiting))
        else:
            signal.signal(sig, signal.SIG_DFL if prev is None else prev)
    _state["installed"].clear()


def _exit_with(code: int) -> Any:
    def handler(signum: int, frame: FrameType | None) -> None:
        import os

        os._exit(code)

    return handler


def end_process(code: int) -> None:
    """The console script's end, with exit ``code``: a normal interpreter exit, unless threads
    started by user code are still running (not daemon threads: the interpreter would wait for
    them, the process outliving its run; a sweep would count it as a timeout): then one line on
    stderr, stdout and stderr flushed, the ``atexit`` functions run (rerun's), and the process
    ends at once with ``code`` (issue 36)."""
    import atexit
    import os
    import sys

    others = [t for t in threading.enumerate()
              if t is not threading.current_thread() and not t.daemon and t.is_alive()]
    if not others:
        raise SystemExit(code)
    names = ", ".join(sorted({t.name for t in others}))[:200]
    with contextlib.suppress(BaseException):
        sys.stderr.write(f"humanoid-twin: {len(others)} thread(s) started by user code still running "
                         f"after the run ({names}): not waited for, the process ends\n")
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(BaseException):
            if stream is not None:
                stream.flush()
    with contextlib.suppress(BaseException):
        atexit._run_exitfuncs()
    os._exit(code)


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


def on_hard_exit(fn: Callable[[], object]) -> None:
    """Run ``fn()`` in :func:`hard_exit` (the CLI removes its temporary files there)."""
    _cleanups.append(fn)


def hard_exit(code: int, message: str) -> None:
    """The last resort for user code that swallows every exception the run raises to end it
    (``except BaseException: pass`` in a loop): one line on stderr, the registered clean-ups,
    and the process ends with ``code`` at once (``os._exit``: no ``finally`` of the stuck code).
    May be called from another thread than the main one (the signals' grace)."""
    import os
    import sys

    with contextlib.suppress(BaseException):
        sys.stderr.write(message.rstrip("\n") + "\n")
        sys.stderr.flush()
    for fn in _cleanups:
        with contextlib.suppress(BaseException):
            fn()
    os._exit(code)
