"""A user scenario: push recovery. The robot stands on its balance controllers (the ``stand``
scenario's plan) and the experiment shoves its trunk, forward then backward, harder each time,
1.5 s apart, each shove 100 ms long, until the robot falls or the shoves run out.

None of the built-in scenarios does this (``--fault push:N@T0`` is one shove); here the
scenario's own program (:meth:`PushRecovery.drive`) does it, with the plant's public door for an
external force (``Plant.set_trunk_force``) and the twin's clock (``rig.sleep``). Each shove is a
line in the recording's event log; the summary's ``fell_at_s`` says which shove was too much.

    humanoid-twin run examples/push_recovery.py:push_recovery --out push.rrd
    humanoid-twin run examples/push_recovery.py:gentle --json --no-record
    humanoid-twin sweep examples/push_recovery.py:push_recovery --param seed=0,1 --out pushes.csv

docs/scenarios.md ("Your own scenario") explains the API.
"""

from __future__ import annotations

from dataclasses import dataclass

from humanoid_twin.rig import Rig
from humanoid_twin.scenarios import REGISTRY, Plan, Scenario, hold

PUSH_S = 0.1            # each shove lasts 100 ms


@dataclass(frozen=True)
class PushRecovery(Scenario):
    """``stand``, then shoves of ``forces_n`` newtons (+ forward, - backward), ``every_s`` apart."""

    forces_n: tuple[float, ...] = (10.0, -10.0, 20.0, -20.0, 30.0, -30.0)
    every_s: float = 1.5

    def motion_s(self, plan: Plan) -> float:
        """The program's length: one period per shove (the run then settles 2 s more)."""
        return len(self.forces_n) * self.every_s

    def drive(self, rig: Rig, plan: Plan) -> None:
        hold(rig.H, plan)                          # the stand's balance gains on the leg boards
        plant = rig.twin.plant
        for force in self.forces_n:
            rig.sleep(self.every_s - PUSH_S)       # time advances here: the robot stands
            if rig.monitor.fell:
                break                              # the last shove was too much: the run says when
            rig.log_event(f"push {force:+g} N for {PUSH_S * 1000:g} ms")
            plant.set_trunk_force(force)
            rig.sleep(PUSH_S)                      # time advances here: the shove
            plant.set_trunk_force(0.0)


_stand = REGISTRY["stand"]

# the scenario objects the CLI loads (FILE.py:NAME): built from stand's plan and flags
push_recovery = PushRecovery("push_recovery", _stand.factory, moves=False, double_support=True,
                             doc="stand, then shoves of growing force until the robot falls")
gentle = PushRecovery("gentle", _stand.factory, moves=False, double_support=True, forces_n=(5.0, -5.0),
                      doc="stand, then two 5 N shoves")
