"""Issue 36, points 1, 2, 4, 5, 6, 15, 19, 20: what users bring stays contained.

User code (a scenario's ``drive``, its module, a law, a host controller) that prints, closes the
streams, starts threads, swallows ``BaseException`` or ends the process; output paths that name a
FIFO, a device or a symbolic link; ``serve --connect`` to a port that is not a rerun viewer.
Every test talks to loopback only and ends by itself (each subprocess has a timeout).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest
from helpers import CLI, default_signals

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)

GRACE_S = 2.0               # humanoid_twin/signals.GRACE_S, as a user measures it (from outside)
SLACK_S = 3.0               # a loaded machine: the process's own closing, the interpreter's exit

SCENARIOS = '''
import os
import sys
import threading
import time
from dataclasses import dataclass

from humanoid_twin.scenarios import REGISTRY, Scenario, hold


@dataclass(frozen=True)
class Hostile(Scenario):
    mode: str = ""

    def motion_s(self, plan):
        return 1.0

    def drive(self, rig, plan):
        hold(rig.H, plan)
        getattr(self, self.mode)(rig)
        rig.sleep(1.0)

    def noisy(self, rig):              # every way to write to stdout, then both streams closed
        print("no newline", end="")
        sys.stdout.write("{\\"not\\": \\"the summary\\"}\\n")
        sys.__stdout__.write("through sys.__stdout__\\n")
        sys.__stdout__.flush()
        os.write(1, b"through file descriptor 1\\n")
        for i in range(200):
            print("line", i)
        sys.stdout.close()
        sys.stderr.close()

    def closes_fds(self, rig):
        print("bye", end="")
        os.close(1)
        os.close(2)

    def thread(self, rig):             # a thread that outlives the run
        print("a thread starts", end="")
        threading.Thread(target=time.sleep, args=(3600,), name="user-sleeper").start()

    def waits_at_exit(self, rig):      # the interpreter's shutdown never ends by itself
        import atexit

        atexit.register(time.sleep, 3600)

    def loop(self, rig):               # deaf to every exception
        sys.stderr.write("LOOPING\\n")
        while True:
            try:
                time.sleep(0.05)
            except BaseException:
                pass

    def once(self, rig):               # swallows the first exception, then goes on with the twin
        sys.stderr.write("LOOPING\\n")
        try:
            time.sleep(60)
        except BaseException:
            pass
        rig.sleep(30.0)

    def exits(self, rig):              # ends the process at once: nothing of the run's can follow
        rig.sleep(0.5)
        os._exit(0)


def make(mode):
    return Hostile(mode, REGISTRY["stand"].factory, moves=False, double_support=True, mode=mode)


noisy, closes_fds, thread, waits_at_exit = (make(m) for m in ("noisy", "closes_fds", "thread",
                                                              "waits_at_exit"))
loop, once, exits = make("loop"), make("once"), make("exits")
'''

LOOPING_MODULE = '''
import sys
import time

from humanoid_twin.scenarios import REGISTRY

sys.stderr.write("LOOPING\\n")
while True:
    try:
        time.sleep(0.05)
    except BaseException:
        pass
stand = REGISTRY["stand"]
'''

LAWS = '''
import sys
import time

from humanoid_twin.slave.laws import ControlLaw


class Loop(ControlLaw):
    cycles = 1600

    def step(self, inputs):
        sys.stderr.write("LOOPING\\n")
        while True:
            try:
                time.sleep(0.05)
            except BaseException:
                pass
'''


@pytest.fixture
def user(tmp_path: Path) -> Path:
    (tmp_path / "hostile.py").write_text(SCENARIOS)
    (tmp_path / "looping_module.py").write_text(LOOPING_MODULE)
    (tmp_path / "looping_law.py").write_text(LAWS)
    return tmp_path


def _run(cwd: Path, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, "run", *args, "--no-progress"], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, preexec_fn=default_signals)


def _partials(where: Path) -> list[str]:
    return sorted(p.name for p in where.iterdir() if p.name.startswith(".partial-"))


# -- stdout is the command's (points 2, 15, 19) ------------------------------------------------------
@pytest.mark.parametrize("mode", ["noisy", "closes_fds"])
def test_json_stdout_is_the_summary_alone_whatever_user_code_does_to_the_streams(user: Path,
                                                                                 mode: str) -> None:
    old = user / "x.rrd"
    old.write_bytes(b"the old recording")
    res = _run(user, f"hostile.py:{mode}", "--duration", "4", "--json", "--out", "x.rrd")
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("\n") == 1, res.stdout[:500]
    summary = json.loads(res.stdout)
    assert summary["scenario"] == f"hostile.py:{mode}" and summary["recording"] == "x.rrd"
    assert "Traceback" not in res.stderr
    if mode == "noisy":             # what the code printed is on stderr, in the order it was written
        for text in ("no newline", '{"not": "the summary"}', "through sys.__stdout__",
                     "through file descriptor 1", "line 199"):
            assert text in res.stderr
    assert old.stat().st_size > 10_000 and _partials(user) == []


def test_a_sweep_keeps_runs_whose_code_prints_without_newline_and_leaves_a_thread(user: Path) -> None:
    t0 = time.monotonic()
    res = subprocess.run([*CLI, "sweep", "hostile.py:thread", "--param", "seed=0,1", "--duration", "4.5",
                          "--jobs", "1", "--timeout", "30", "--out", "t.csv", "--no-progress"], cwd=user,
                         capture_output=True, text=True, timeout=150, preexec_fn=default_signals)
    assert res.returncode == 0, res.stderr
    assert time.monotonic() - t0 < 30          # before: each run killed at --timeout + 15 s
    import csv

    rows = list(csv.DictReader((user / "t.csv").open()))
    assert [r["error"] for r in rows] == ["", ""] and [r["completed"] for r in rows] == ["true", "true"]
    assert res.stdout == "t.csv: 2 runs, 0 failed\n"


# -- threads and the interpreter's shutdown after the summary (points 2, 6) -------------------------
def test_a_user_thread_does_not_keep_a_finished_run_alive(user: Path) -> None:
    res = _run(user, "hostile.py:thread", "--duration", "4.5", "--json", "--no-record", timeout=60)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["completed"] is True
    assert "1 thread(s) started by user code still running after the run (user-sleeper)" in res.stderr


def test_after_the_summary_a_signal_ends_a_process_that_user_code_holds(user: Path) -> None:
    proc = subprocess.Popen([*CLI, "run", "hostile.py:waits_at_exit", "--duration", "4.5", "--json",
                             "--no-record", "--no-progress"], cwd=user, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    try:
        line = proc.stdout.readline()          # the summary: the run is over
        assert json.loads(line)["completed"] is True
        time.sleep(1.0)
        assert proc.poll() is None             # its atexit function holds the interpreter
        proc.send_signal(signal.SIGTERM)
        proc.wait(SLACK_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0                # the run was done: its own exit code


# -- signals that user code swallows (point 4) ------------------------------------------------------
def _signal_when_looping(cwd: Path, args: list[str], sig: int) -> tuple[int, float, str]:
    """Start ``run ARGS``, send ``sig`` once the user code loops; (exit code, seconds from the
    signal to the exit, stderr)."""
    proc = subprocess.Popen([*CLI, "run", *args, "--no-progress"], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    try:
        first = proc.stderr.readline()
        while first and "LOOPING" not in first:
            first = proc.stderr.readline()
        assert "LOOPING" in first, "the user code never ran"
        time.sleep(0.3)
        t0 = time.monotonic()
        proc.send_signal(sig)
        proc.wait(GRACE_S + SLACK_S + 5)
        elapsed = time.monotonic() - t0
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, elapsed, err


@pytest.mark.parametrize("where,args,sig", [
    ("drive", ["hostile.py:loop"], signal.SIGTERM),
    ("drive", ["hostile.py:loop"], signal.SIGINT),
    ("import", ["looping_module.py:stand"], signal.SIGTERM),
    ("law", ["stand", "--law", "balance=looping_law:Loop"], signal.SIGTERM),
])
def test_a_signal_ends_a_run_whose_user_code_swallows_it(user: Path, where: str, args: list[str],
                                                        sig: int) -> None:
    (user / "x.rrd").write_bytes(b"the old recording")
    code, elapsed, err = _signal_when_looping(user, [*args, "--out", "x.rrd", "--json"], sig)
    assert code == (143 if sig == signal.SIGTERM else 130), err
    assert GRACE_S - 0.2 < elapsed < GRACE_S + SLACK_S, (where, elapsed)
    lines = [ln for ln in err.splitlines() if ln and "LOOPING" not in ln and "declares no cost" not in ln]
    assert len(lines) == 1 and "user code held the stop back for 2 s" in lines[0], err
    assert (user / "x.rrd").read_bytes() == b"the old recording" and _partials(user) == []


def test_a_signal_swallowed_once_is_raised_again_where_the_twin_goes_on(user: Path) -> None:
    code, elapsed, err = _signal_when_looping(user, ["hostile.py:once", "--out", "x.rrd", "--json"],
                                              signal.SIGTERM)
    assert code == 143 and elapsed < GRACE_S + SLACK_S, err
    assert "terminated (SIGTERM); recorded so far: x.rrd" in err    # the files closed as for any signal
    assert (user / "x.rrd").stat().st_size > 10_000 and _partials(user) == []


# -- os._exit in user code (point 20): nothing to do then, the next start cleans up -----------------
def test_a_run_ended_by_os_exit_leaves_no_partial_file_at_the_next_start(user: Path) -> None:
    (user / "x.rrd").write_bytes(b"the old recording")
    res = _run(user, "hostile.py:exits", "--out", "x.rrd", "--json")
    assert res.returncode == 0 and res.stdout == ""        # what is left: no summary, no error
    left = _partials(user)
    assert len(left) == 1 and left[0].endswith("-x.rrd")
    alive = user / f".partial-{os.getpid()}-x.rrd"        # a run still going (this process): kept
    alive.write_bytes(b"")
    res = _run(user, "stand", "--duration", "3", "--out", "x.rrd", "--json")
    assert res.returncode == 0, res.stderr
    assert _partials(user) == [alive.name]


# -- output paths (point 1) -------------------------------------------------------------------------
def _null_device(tmp_path: Path) -> Path:
    """A character device the test may lose: as root (who could replace the system's /dev/null if
    the twin regressed: it did, issue 36), a null device node of the test's own; otherwise
    /dev/null itself, which a user other than root cannot replace."""
    if os.geteuid() != 0:
        return Path("/dev/null")
    import stat

    node = tmp_path / "dev" / "null"
    node.parent.mkdir()
    os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    return node


@pytest.mark.parametrize("option,make,kind", [
    ("--can-log", "fifo", "a FIFO"),
    ("--serial-log", "device", "a character device"),
    ("--out", "link to a device", "a character device (through a link: "),
])
def test_an_output_that_is_not_a_regular_file_is_refused_never_replaced(tmp_path: Path, option: str,
                                                                        make: str, kind: str) -> None:
    work = tmp_path / "work"
    work.mkdir()
    device = _null_device(tmp_path)
    if make == "fifo":
        target = work / "bus.asc"
        os.mkfifo(target)
    elif make == "device":
        target = device
    else:
        target = work / "x.rrd"
        target.symlink_to(device)
    res = _run(work, "stand", "--duration", "3", option, str(target), timeout=60)
    assert res.returncode == 2 and res.stdout == "", res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and f"is {kind}" in res.stderr, res.stderr
    if make == "fifo":
        assert target.is_fifo()
    if make.startswith("link"):
        assert target.is_symlink() and os.readlink(target) == str(device)
    assert device.is_char_device()
    assert [p.name for p in work.iterdir()] == ([target.name] if target.parent == work else [])


def test_an_output_through_a_symlink_replaces_its_target_and_keeps_the_link(tmp_path: Path) -> None:
    (tmp_path / "real").mkdir()
    real = tmp_path / "real" / "bus.asc"
    real.write_text("the old log")
    link = tmp_path / "bus.asc"
    link.symlink_to(real)
    res = _run(tmp_path, "stand", "--duration", "3", "--no-record", "--can-log", "bus.asc", "--json",
               timeout=60)
    assert res.returncode == 0, res.stderr
    assert link.is_symlink() and link.resolve() == real
    assert real.stat().st_size > 10_000 and json.loads(res.stdout)["can_log"] == "bus.asc"
    assert _partials(tmp_path) == [] and _partials(real.parent) == []


def test_a_sweep_table_that_is_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    table = tmp_path / "t.csv"
    os.mkfifo(table)
    res = subprocess.run([*CLI, "sweep", "stand", "--param", "seed=0", "--out", str(table)],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert res.returncode == 2 and "is a FIFO" in res.stderr, res.stderr
    assert table.is_fifo()


# -- serve --connect to something that is not a viewer (point 5) ------------------------------------
class _Listener:
    """A loopback TCP server that accepts and then says ``reply`` (or nothing) and holds on."""

    def __init__(self, reply: bytes) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.reply, self.conns, self.done = reply, [], False
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while not self.done:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                continue
            self.conns.append(conn)
            if self.reply:
                conn.sendall(self.reply)

    def close(self) -> None:
        self.done = True
        self.thread.join(5)
        for c in self.conns:
            c.close()
        self.sock.close()


@pytest.mark.parametrize("reply", [b"", b"HTTP/1.0 200 OK\r\n\r\nhello"])
def test_serve_connect_to_a_port_that_is_not_a_rerun_viewer_is_exit_2_at_once(tmp_path: Path,
                                                                            reply: bytes) -> None:
    listener = _Listener(reply)
    try:
        res = subprocess.run([*CLI, "serve", "--tcp", "0", "--connect", f"127.0.0.1:{listener.port}",
                              "--out", "s.rrd"], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    finally:
        listener.close()
    assert res.returncode == 2 and res.stdout == "", res.stderr     # before: hung, no port, deaf to SIGTERM
    assert len(res.stderr.strip().splitlines()) == 1 and "not a rerun viewer" in res.stderr, res.stderr
    assert list(tmp_path.iterdir()) == []
