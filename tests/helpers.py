"""What several test files share that is not a fixture (the fixtures are in tests/conftest.py):
the repository's root, the command line in a child process (and its signals), the head of a plain
pyserial client, and a wait on the Master's supervisor.

The test files sit in folders by what they test (tests/protocol, tests/bus, tests/firmware, ...);
pytest puts ``tests/`` on ``sys.path`` for its root conftest.py, so every test file imports this
module as ``helpers``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
"""The repository's root (the folder above ``tests/``)."""

CLI = [sys.executable, "-m", "humanoid_twin.cli.main"]
"""``humanoid-twin`` as a child process of this interpreter (the package under test, whatever
``PYTHONPATH`` points at)."""


def default_signals() -> None:
    """A child's ``preexec_fn``: SIGINT and SIGTERM back to their default actions, so that a test
    that signals a child does not depend on how pytest itself was started (a background job
    ignores SIGINT, and its children inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def cli(*args: str, cwd: str | Path | None = None, timeout: float = 300,
        env: Mapping[str, str] | None = None,
        preexec_fn: Callable[[], Any] | None = None) -> subprocess.CompletedProcess:
    """``humanoid-twin ARGS`` in a child process (in ``cwd``; ``env`` added to this process's
    environment), its output captured as text; raises ``subprocess.TimeoutExpired`` after
    ``timeout`` seconds."""
    return subprocess.run([*CLI, *args], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=None if env is None else {**os.environ, **env}, preexec_fn=preexec_fn)


# The head of a plain pyserial client, a user's own program that uses no project code: its imports
# and the RS-232 frame of docs/protocol.md written out by hand (start byte, OpCode, three data
# bytes, the XOR of all five). A test adds its port and its requests below it.
PYSERIAL_FRAME = """
import json, sys, time
import serial


def frame(op, scu, param, d1=0, d2=0, d3=0):
    b = [0xFF, (op << 6) | (scu << 2) | param, d1 & 0xFF, d2 & 0xFF, d3 & 0xFF]
    x = 0
    for v in b:
        x ^= v
    return bytes(b + [x])
"""


def wait_for_mode(robot: Any, mode_name: str, timeout_s: float) -> str:
    """Poll a :class:`~humanoid_twin.host.drivers.HumanoidClient` every 50 ms until its Master's
    supervisor reports ``mode_name`` or ``timeout_s`` wall seconds pass; the mode it reported last."""
    deadline = time.monotonic() + timeout_s
    while (name := robot.supervisor().mode_name) != mode_name and time.monotonic() < deadline:
        time.sleep(0.05)
    return name
