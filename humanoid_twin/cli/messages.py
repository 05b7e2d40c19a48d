"""The commands' own lines: a usage error (one line, exit 2), an error message on one line, a line
on the command's stdout, why a signal stopped a command (the exit codes: humanoid_twin/signals.py)."""

from __future__ import annotations

import sys
from typing import Any

EXIT_USAGE = 2


def usage_error(message: str) -> SystemExit:
    """``humanoid-twin: error: MESSAGE`` on stderr; the ``SystemExit`` (exit 2) to raise."""
    sys.stderr.write(f"humanoid-twin: error: {message}\n")
    return SystemExit(EXIT_USAGE)


def one_line(text: str, limit: int = 500) -> str:
    """``text`` on one line, at most ``limit`` characters (an error message from anywhere)."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def say(out: Any, line: str) -> None:
    """One line on the command's stdout (cli/streams.py; None: the process has none)."""
    if out is not None:
        out.write(line + "\n")
        out.flush()


def stop_reason(exc: BaseException) -> str:
    """What a SIGINT / SIGTERM (``exc``, humanoid_twin/signals.py) did to a command, for its line."""
    from humanoid_twin import signals

    return "terminated (SIGTERM)" if isinstance(exc, signals.Terminated) else "interrupted"
