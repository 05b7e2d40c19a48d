"""What a new user meets first (issue 11): --version, a --help that teaches, progress that reads
well on a terminal and in a log, and nothing left in the user's folder."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import struct
import subprocess
import sys
import termios

import pytest
from helpers import CLI, cli

from humanoid_twin.cli.progress import RunProgress
from humanoid_twin.scenarios import DEFAULT_MOTION_DEG, SCENARIOS


def test_version():
    r = cli("--version")
    assert r.returncode == 0
    name, version, core = r.stdout.strip().split(maxsplit=2)
    assert name == "humanoid-twin" and version[0].isdigit()
    assert core in ("(core: compiled)", "(core: python)")   # which core runs (docs/architecture.md)


def test_run_help_explains_each_scenario_its_defaults_and_gives_examples():
    out = cli("run", "--help").stdout
    lines = out.splitlines()
    for name in SCENARIOS:                    # one line per scenario, in English
        assert any(ln.split()[:1] == [name] and len(ln.split()) > 3 for ln in lines), name
    assert "squat" in out and "lateral lean" in out and "lift a leg" in out
    assert "--perna 1 the right, 2 the left" in out
    for name, deg in DEFAULT_MOTION_DEG.items():
        assert f"--motion {deg:g} deg" in out, name
    assert "Default: 1 s" in out
    assert "examples:" in out and "humanoid-twin run levantar_perna --perna 2" in out


def test_progress_in_a_log_is_plain_lines_with_the_boot_and_wall_time(tmp_path):
    # stderr is a pipe here (as in CI or `2> run.log`): no carriage return, a line per ~10 %
    r = cli("run", "flexao", "--no-record", cwd=str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert "\r" not in r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("flexao: ")]
    assert "booting" in lines[0] and "booted by" in lines[1]
    assert lines[-1].startswith("flexao: 100%") and "wall" in lines[-1]
    assert any("ETA" in ln and "real time" in ln for ln in lines)
    assert 6 <= len(lines) <= 14, lines
    assert list(tmp_path.iterdir()) == []      # nothing written into the cwd (no MUJOCO_LOG.TXT)


def test_progress_on_a_terminal_is_a_redrawn_bar_with_a_boot_phase():
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    os.set_blocking(master, False)
    with os.fdopen(slave, "w") as tty:
        bar = RunProgress("flexao", tty)
        assert bar.tty
        for i in range(27):
            bar.update(i / 10, None)
        for i in range(27, 58):
            bar.update(i / 10, 5.7)
        bar.close()
        tty.flush()
    out = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except (BlockingIOError, OSError):
            break
        if not chunk:
            break
        out += chunk
    os.close(master)
    text = out.decode()
    assert "flexao: boot:" in text and "s simulated" in text and "wall" in text
    assert "\r" in text and "\n" not in text.replace("\r\n", "")   # redrawn in place, no log lines
    assert "/5.7 s simulated" in text


def test_mujoco_warnings_go_to_stderr_not_to_a_log_file_in_the_cwd(tmp_path):
    code = ("import math, mujoco; from humanoid_twin.plant import Plant; p = Plant(); "
            "p.data.qpos[0] = math.nan; mujoco.mj_step(p.model, p.data)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "humanoid-twin: MuJoCo warning:" in r.stderr and "QPOS" in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_run_viewer_without_a_display_is_one_line_and_exit_2_before_anything_is_written(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([*CLI, "run", "stand", "--viewer"], capture_output=True, text=True, timeout=60,
                       cwd=tmp_path, env=env)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "--viewer needs a display" in r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs xvfb-run (a virtual X display)")
def test_run_viewer_watches_the_run_paced_to_real_time_on_a_virtual_display(tmp_path):
    r = subprocess.run(["xvfb-run", "-a", *CLI, "run", "stand", "--duration", "3", "--viewer", "--no-record",
                        "--json", "--no-progress"], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0, r.stderr          # the window opened, the run ended, the viewer closed
    summary = json.loads(r.stdout.splitlines()[-1])
    assert summary["fell"] is False
    assert summary["rtf"] <= 1.05               # paced: never faster than real time (headless: ~3x)
