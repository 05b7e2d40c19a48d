"""The CLI contract (docs/scenarios.md, README): commands, help, errors with exit code 2, the JSON summary."""

from __future__ import annotations

import json
import os

import pytest
from helpers import cli

SUMMARY_KEYS = {"scenario", "duration_s", "fell", "trunk_tilt_max_deg", "cop_margin_min_mm",
                "cop_error_rms_mm", "wall_s", "rtf", "can_frames", "serial_frames"}


@pytest.mark.parametrize("cmd", [[], ["run"], ["serve"], ["view"]])
def test_help_on_every_command(cmd):
    r = cli(*cmd, "--help")
    assert r.returncode == 0
    assert "usage: humanoid-twin" in r.stdout


@pytest.mark.parametrize(
    "args, message",
    [
        (["run", "stand", "--bogus"], "unrecognized arguments: --bogus"),
        (["run", "walk"], "invalid choice: 'walk'"),
        (["run", "stand", "--duration", "-1"], "--duration"),
        (["run", "stand", "--tilt", "95"], "--tilt"),
        (["run", "stand", "--control", "pid"], "invalid choice: 'pid'"),
        (["run", "stand", "--out", "/nonexistent-dir/x.rrd"], "does not exist"),
        (["run", "stand", "--out", "x.txt"], "must end in .rrd"),
        (["run", "stand", "--can-log", "frames.xyz", "--no-record"], "unknown format '.xyz'"),
        (["serve", "--pty", "--tcp", "5000"], "not allowed with argument"),
        (["view", "missing.rrd"], "no such recording"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(args, message, tmp_path):
    r = cli(*args, cwd=str(tmp_path))
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("humanoid-twin")]
    assert len(lines) == 1 and message in lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_unwritable_output_path_is_refused(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):   # root ignores permissions: use a file as the "directory"
            target = tmp_path / "a-file"
            target.write_text("x")
            out = target / "run.rrd"
        else:
            out = locked / "run.rrd"
        r = cli("run", "stand", "--out", str(out), cwd=str(tmp_path))
    finally:
        locked.chmod(0o700)
    assert r.returncode == 2
    assert r.stderr.startswith("humanoid-twin: error: --out")


def test_run_prints_a_summary_and_json_last_line(tmp_path):
    out = tmp_path / "stand.rrd"
    r = cli("run", "stand", "--duration", "3.5", "--out", str(out), "--json", "--seed", "3",
            cwd=str(tmp_path))
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    assert SUMMARY_KEYS <= summary.keys()
    assert summary["scenario"] == "stand" and summary["seed"] == 3
    assert summary["duration_s"] == pytest.approx(3.5, abs=0.01)
    assert summary["fell"] is False
    assert summary["can_frames"] > 10_000          # 4000 frames per simulated second, minus silences
    assert summary["serial_frames"] > 8 * 3         # the boot alone: 3 requests per board
    assert 0 < summary["cop_error_rms_mm"] < 2.0
    assert summary["cop_margin_min_mm"] > 20        # standing still: the CoP is well inside both feet
    assert out.is_file() and out.stat().st_size > 10_000
    assert "%" in r.stderr                          # the progress bar went to stderr, not stdout


def test_default_recording_is_named_after_the_scenario(tmp_path):
    r = cli("run", "stand", "--duration", "3", "--no-progress", cwd=str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "stand.rrd").is_file()


@pytest.mark.parametrize("scenario", ["flexao", "inclinar", "levantar_perna"])
def test_each_motion_runs_headless_from_the_cli(scenario, tmp_path):
    r = cli("run", scenario, "--no-record", "--json", "--no-progress", cwd=str(tmp_path))
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout.strip().splitlines()[-1])
    assert s["scenario"] == scenario and s["fell"] is False
    assert s["cop_margin_min_mm"] > 0                  # the CoP stayed inside the support polygon
    assert s["duration_s"] > s["boot_s"] + 1.0          # the motion ran after the boot
    assert s["serial_frames"] > 8 * 3 + 4 * 5          # boot + the motion's requests


def test_python_cans_virtual_interface_gives_the_same_run(tmp_path):
    runs = [json.loads(cli("run", "stand", "--duration", "3.2", "--no-record", "--json", "--no-progress",
                           *extra, cwd=str(tmp_path)).stdout.strip().splitlines()[-1])
            for extra in ([], ["--can-interface", "virtual"])]
    for key in ("can_frames", "serial_frames", "cop_error_rms_mm", "cop_margin_min_mm", "trunk_tilt_max_deg"):
        assert runs[0][key] == runs[1][key], key
