"""examples/octave/twin_client.m drives ``humanoid-twin serve``'s pty from GNU Octave, with the
serialport API and with the older serial / fopen / fwrite / fread pair (issue 27).

Runs only where ``octave-cli`` and Octave's instrument-control package are installed (Debian,
Ubuntu: ``apt install octave octave-instrument-control``); skipped with the reason otherwise.
"""

from __future__ import annotations

import functools
import shutil
import subprocess
import sys
import time

import pytest
from helpers import REPO

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

EXAMPLE_DIR = REPO / "examples" / "octave"
INSTALL = "Debian, Ubuntu: apt install octave octave-instrument-control"


@functools.cache
def octave_missing() -> str | None:
    """Why the example cannot run here, or None."""
    if not sys.platform.startswith("linux"):
        return "the example opens the twin's pty (Linux)"
    octave = shutil.which("octave-cli")
    if octave is None:
        return f"octave-cli is not installed ({INSTALL})"
    try:
        r = subprocess.run([octave, "--no-gui", "-q", "--eval", "pkg load instrument-control"],
                           capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return "octave-cli did not load instrument-control within 120 s"
    if r.returncode != 0:
        return f"Octave's instrument-control package is not installed ({INSTALL}): {r.stderr.strip()[:200]}"
    return None


def run_example(port: str, api: str) -> subprocess.CompletedProcess:
    call = f"addpath('{EXAMPLE_DIR}'); twin_client('{port}', '{api}')"
    return subprocess.run(["octave-cli", "--no-gui", "-q", "--eval", call],
                          capture_output=True, text=True, timeout=120)


def test_the_octave_client_gets_its_answers_with_both_apis(serve) -> None:
    reason = octave_missing()
    if reason:
        pytest.skip(reason)
    proc, port = serve()
    assert port.startswith("/dev/")
    for api in ("serialport", "serial"):
        r = run_example(port, api)
        assert r.returncode == 0, r.stdout + r.stderr
        lines = r.stdout.splitlines()
        assert lines[0] == f"{port} ({api} API): 115200 baud, 8 data bits, parity even, 1 stop bit"
        assert lines[1] == "test message: FA F9 F8 F7 F6 F5"
        assert lines[2] == "PWM on, SCU 1: FB 07 01 00 00 FD"              # the request echoed
        assert lines[3].startswith("joint positions, SCU 1: FD ")
        assert lines[4].startswith("supervisor: FD ") and " -> mode " in lines[4]
        time.sleep(0.2)                       # serve sees the port closed: the next run is a new client
    serve.stop(proc)
    log = proc.stderr.read()
    assert log.count("connected (session") == 2 and log.count("closed the port") == 2, log
