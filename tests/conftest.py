"""Shared fixtures: a twin and a booted twin (assembled and booted by a
:class:`~humanoid_twin.rig.Rig`, as every run is), and ``humanoid-twin serve`` in a child process.

Tests that attach an observer (a monitor, a CAN log, faults, supervisor listeners) before the
boot build their twin themselves and call :func:`humanoid_twin.rig.boot` on it, or give a
:class:`~humanoid_twin.rig.Rig` the options that attach it.
"""

from __future__ import annotations

import gc
import json
import select
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from humanoid_twin.rig import Rig, RigOptions
from humanoid_twin.twin import Twin

# Everything imported so far (pytest, numpy, MuJoCo, python-can, the package) lives as long as the
# process: out of the collector's sight, so that its full passes while the test files are imported
# and run do not walk it again each time (a sixth of the fast subset's collection, 0.5 s of CPU).
gc.freeze()

# The files that keep one pytest-xdist worker longest, longest first (the CPU each takes on its own,
# children included). The whole suite runs with `-n auto --dist loadfile --no-loadscope-reorder`
# (README, .ci/run): whole files go to the workers in collection order, so these start first and
# the short files fill in around them; no long file is left to run alone at the end (xdist's default
# order, by number of tests, put the one-test files such as the wheel install last).
LONGEST_FIRST = (
    "project/test_docs.py",
    "project/test_install.py",
    "golden/test_golden.py",
    "calibration/test_calibrate.py",
    "firmware/slave/test_balance.py",
    "sweep/test_sweep.py",
    "firmware/test_cycles.py",
    "serve/test_serve_abuse.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The files of :data:`LONGEST_FIRST` first, in its order; the others after them, in the order
    collected (the sort is stable, and keeps the order of the tests within a file)."""
    tests = Path(__file__).parent
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.relative_to(tests).as_posix(), len(rank)))


@pytest.fixture
def twin() -> Iterator[Twin]:
    """A fresh twin, seed 0, not booted (Slaves with PWM off); closed after the test."""
    tw = Twin(seed=0)
    yield tw
    tw.close()


@pytest.fixture
def booted_twin() -> Iterator[tuple[Twin, Any]]:
    """``(twin, H)``: the seed-0 twin of a :class:`~humanoid_twin.rig.Rig` (no instruments) after
    :meth:`~humanoid_twin.rig.Rig.boot` (PWM on, every Slave calibrated) and the host end ``H``
    of its RS-232 link; closed after the test."""
    with Rig(RigOptions(seed=0, monitor=False)) as rig:
        yield rig.twin, rig.boot()


class ServeStarter:
    """``proc, port = serve(*args)`` starts ``humanoid-twin serve ARGS`` and returns once it has
    printed its port (30 s at most); ``serve.client(code, port)`` runs a client program against
    it; ``serve.stop(proc)`` stops it (SIGTERM, then kill). Every child still running when the
    test ends is stopped."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def __call__(self, *args: str) -> tuple[subprocess.Popen, str]:
        proc = subprocess.Popen([sys.executable, "-m", "humanoid_twin.cli.main", "serve", *args],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.procs.append(proc)
        ready, _, _ = select.select([proc.stdout], [], [], 30)
        if not ready:
            self.stop(proc)
            raise AssertionError("serve printed no port in 30 s")
        return proc, proc.stdout.readline().strip()

    @staticmethod
    def client(code: str, port: str, timeout: float = 60) -> dict:
        """Run the client program ``code`` (dedented) in a child process with serve's ``port``
        as its argument; what it printed last, a JSON object."""
        r = subprocess.run([sys.executable, "-c", textwrap.dedent(code), port], capture_output=True,
                           text=True, timeout=timeout)
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout.strip().splitlines()[-1])

    @staticmethod
    def stop(proc: subprocess.Popen) -> None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


@pytest.fixture
def serve() -> Iterator[ServeStarter]:
    """A :class:`ServeStarter`: ``humanoid-twin serve`` in child processes, stopped after the test."""
    starter = ServeStarter()
    yield starter
    for proc in starter.procs:
        if proc.poll() is None:
            starter.stop(proc)
