"""Issue 37, points 3 and 4: the summary says when, and a failed boot is reported as one.

- each extreme comes with the simulated time of the sample that reached it, and the balance
  metrics are also given over the motion alone (from ``monitor.CONTROLLERS_START_S`` after the
  boot): on ``stand`` the whole run's CoP margin is the controllers' start-up swing (34.748 mm at
  4.20 s, whatever the tilt), the motion's is not;
- ``run stand --pic-mhz 0.5`` (boards too slow to calibrate) printed "booted by 5.1 s simulated"
  and ``completed: yes`` while its ``host_error`` said no board reported PWM on.
"""

from __future__ import annotations

import json
from pathlib import Path

from helpers import cli

from humanoid_twin.monitor import CONTROLLERS_START_S


def test_each_extreme_says_when_and_the_motion_leaves_the_start_up_out(tmp_path: Path) -> None:
    r = cli("run", "stand", "--tilt", "10", "--duration", "8", "--no-record", "--no-progress", "--json",
            cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    # the whole run's low is the controllers' start-up swing, 1.55 s after the boot
    assert s["cop_margin_min_mm"] == 34.748 and s["cop_margin_min_at_s"] == 4.2
    assert s["boot_s"] < s["cop_margin_min_at_s"] < s["boot_s"] + CONTROLLERS_START_S
    # over the motion alone: after the start-up, a higher low, at a time within the window
    assert s["cop_margin_min_motion_mm"] > s["cop_margin_min_mm"] + 3
    assert s["boot_s"] + CONTROLLERS_START_S <= s["cop_margin_min_motion_at_s"] <= s["duration_s"]
    assert 0 < s["trunk_tilt_max_motion_deg"] <= s["trunk_tilt_max_deg"]
    assert s["boot_s"] + CONTROLLERS_START_S <= s["trunk_tilt_max_motion_at_s"] <= s["duration_s"]
    assert 0 < s["trunk_tilt_max_at_s"] <= s["duration_s"]
    assert s["slip_mm"] > 0 and 0 < s["slip_mm_at_s"] <= s["duration_s"]
    assert s["booted"] is True and s["completed"] is True


def test_a_failed_boot_is_reported_as_a_failed_boot(tmp_path: Path) -> None:
    r = cli("run", "stand", "--pic-mhz", "0.5", "--no-record", cwd=tmp_path)     # progress on, in a log
    table = r.stdout
    r_json = cli("run", "stand", "--pic-mhz", "0.5", "--no-record", "--no-progress", "--json", cwd=tmp_path)
    assert r.returncode == 3 and r_json.returncode == 3, r.stderr       # the supervisor ended safe
    assert "booted by" not in r.stderr
    (line,) = [ln for ln in r.stderr.splitlines() if "boot FAILED" in ln]
    assert "did not report PWM on" in line and "the scenario does not run" in line
    rows = dict(ln.split(None, 1) for ln in table.splitlines())
    assert rows["booted"] == "no" and rows["completed"] == "no"
    s = json.loads(r_json.stdout)
    assert s["booted"] is False and s["completed"] is False and s["host_error"].startswith("boot: ")
    assert s["cop_margin_min_motion_mm"] is None and s["trunk_tilt_max_motion_deg"] is None
