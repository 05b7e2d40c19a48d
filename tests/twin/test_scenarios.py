"""The scenario registry (humanoid_twin/scenarios.py): one factory per scenario, one boot sequence,
one function that builds a k row."""

from __future__ import annotations

import numpy as np
import pytest

from humanoid_twin import scenarios
from humanoid_twin.host.planners import GAINS, control_row, empty_plan, leg_pose
from humanoid_twin.protocol.wire import ControlType
from humanoid_twin.scenarios import REGISTRY, SCENARIOS, Plan, RunOptions, ScenarioError, run


def test_the_cli_choices_are_the_registry_with_stand_first():
    assert SCENARIOS == ("stand", "flexao", "inclinar", "levantar_perna", "excite") == tuple(REGISTRY)
    assert not REGISTRY["stand"].moves and all(REGISTRY[n].moves for n in SCENARIOS[1:])
    with pytest.raises(ScenarioError, match="unknown scenario 'walk'.*stand, flexao"):
        scenarios.plan("walk")


def test_control_row_is_gains_then_type_with_signed_kp_as_a_byte():
    row = control_row(ControlType.BALANCE_CONTROL, ((0, 0, 0), (0, -8, 2), (0, 0, 0)))
    assert row.tolist() == [[0, 0, 0, 3], [0, 248, 2, 3], [0, 0, 0, 3]]
    assert control_row(ControlType.LOCOMOTION_CONTROL)[:, :3].tolist() == [list(g) for g in
                                                                          GAINS[ControlType.LOCOMOTION_CONTROL]]
    with pytest.raises(ValueError, match="gains must be bytes"):
        control_row(1, (0, 300, 0))


def test_a_scenario_added_in_one_place_runs_end_to_end(monkeypatch):
    """A new scenario is one registered factory: run() and plan() find it, it moves the robot."""
    monkeypatch.setattr(scenarios, "REGISTRY", dict(REGISTRY))

    @scenarios.scenario("crouch")
    def _crouch(T, motion, perna) -> Plan:
        """both knees bend 30 degrees"""
        pos, k, t = empty_plan(1)
        for side in (0, 1):
            leg_pose(pos, 0, side, hip_pitch=-15.0, knee=30.0, ankle_pitch=-15.0)
        for row in range(4):
            k[row, :, 0] = control_row(ControlType.LOCOMOTION_CONTROL)
        t[0] = 0.5 if T is None else T
        return Plan(pos, k, t)

    assert scenarios.load_scenario("crouch").doc == "both knees bend 30 degrees"
    s = run(RunOptions("crouch", progress=False))
    assert s["scenario"] == "crouch" and not s["fell"]
    # boot + the 0.5 s motion + the settling time: the motion's duration came from the plan
    assert s["duration_s"] == pytest.approx(s["boot_s"] + 0.5 + scenarios.SETTLE_S, abs=0.05)
    assert np.isfinite(s["trunk_tilt_max_deg"])


def test_a_duration_inside_the_motion_cuts_it_and_says_so():
    """``--duration`` shorter than boot + motion stops the run at that instant (completed false);
    without it the motion runs to its end (completed true)."""
    cut = run(RunOptions(scenario="flexao", duration=3.2, seed=0))
    assert cut["duration_s"] == 3.2 and cut["completed"] is False and not cut["fell"]
    whole = run(RunOptions(scenario="stand", duration=3.2, seed=0))
    assert whole["duration_s"] == 3.2 and whole["completed"] is True
