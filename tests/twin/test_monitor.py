"""The public ground-truth monitor (humanoid_twin/monitor.py): what a user's controller and the
run summary read."""

from __future__ import annotations

import math

from humanoid_twin import scenarios
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.monitor import Monitor
from humanoid_twin.scenarios import boot
from humanoid_twin.twin import Twin


def test_monitor_sees_a_limp_robot_fall_and_a_booted_one_stand():
    assert scenarios.Monitor is Monitor          # the old import path keeps working
    with Twin(seed=0) as twin:                   # never booted: the platform tips it over
        mon = Monitor(twin)
        mon.attach()
        twin.plant.set_tilt_profile(scenarios.tilt_profile(40.0, 0.0, rate_deg_s=40.0))
        twin.run_for(1.5)
        assert mon.fell and mon.fell_at_s is not None and mon.fell_at_s <= 1.5
        assert mon.samples == 75 and mon.last is not None
    with Twin(seed=0) as twin:
        mon = Monitor(twin)
        mon.attach()
        H = boot(twin)
        mon2 = Monitor(twin, start_s=twin.now_s)
        mon2.attach()
        host_sleep(H, 0.5)
        assert not mon2.fell and not mon.fell
        assert 20.0 < mon2.cop_margin_min_mm < 80.0 and math.isfinite(mon2.cop_margin_min_mm)
        assert mon2.cop_error_rms_mm is not None and mon2.cop_error_rms_mm < 4.0
        assert mon2.last.cop_world_xy is not None and twin.now_s - 0.02 <= mon2.last.t_s <= twin.now_s
