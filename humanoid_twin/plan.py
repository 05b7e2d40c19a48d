"""What a scenario asks of the robot: its :class:`Plan` (the planners' ``pos_apply``, ``k``, ``t``
of seed 000 table 23, and which leg carries the robot), and the stand's leader/follower gains
that ``--control reaction|balance`` puts on a plan in double support (docs/balance.md 2.2).

Below the scenarios (``humanoid_twin/scenarios.py`` builds plans, ``humanoid_twin/summary.py``
reads them): both import it, neither imports the other for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humanoid_twin.host.planners import control_row, with_control
from humanoid_twin.protocol.wire import ControlType

__all__ = ["Plan", "STAND_CONTROL", "STAND_GAINS", "STAND_LEAD_KP", "STAND_FOLLOW_KP", "STAND_KD"]

# ``stand``: the vertical posture, both feet down, BALANCE_CONTROL on the leg boards and
# LOCOMOTION_CONTROL on the hips. In double support the two legs must not run the same law
# (they fight through the pelvis, docs/balance.md): the right leg leads (its foot front joint
# moves the mass centre to put its CoP on the foot centre, KP 1, KD 2: gain 1/4) and the left
# leg follows (KP -8, KD 2: its foot front joint turns the foot to centre its own CoP, 8 times as
# fast); foot lateral and knee gains 0 (the lateral CoP of a foot in double support is an internal
# force; a knee bent on one leg only twists the pelvis). Rows: servos 1-3, (KI, KP, KD) bytes.
# Measured (scripts/balance_study.py, docs/balance.md): largest platform tilt held 36 deg toes up,
# 37 toes down, against 13 / 12 deg with the controllers off; BALANCE holds from gain 1/8 to 1/2.
STAND_CONTROL = {1: ControlType.BALANCE_CONTROL, 2: ControlType.BALANCE_CONTROL,
                 3: ControlType.LOCOMOTION_CONTROL, 4: ControlType.LOCOMOTION_CONTROL}
STAND_LEAD_KP, STAND_FOLLOW_KP, STAND_KD = 1, -8, 2
STAND_GAINS: dict[int, tuple[tuple[int, int, int], ...]] = {
    1: ((0, 0, 0), (0, STAND_LEAD_KP, STAND_KD), (0, 0, 0)),
    2: ((0, 0, 0), (0, STAND_FOLLOW_KP, STAND_KD), (0, 0, 0)),
}

_BALANCE_TYPES = (ControlType.REACTION_CONTROL, ControlType.BALANCE_CONTROL)


@dataclass
class Plan:
    """What a scenario asks of the robot: the planner's ``pos_apply``, ``k``, ``t`` (table 23)."""

    pos_apply: np.ndarray
    k: np.ndarray
    t: np.ndarray
    # per motion, the leg board (SCU 1 or 2) that carries the robot, and whether it carries it
    # alone (the other foot up); None: both feet down all along, the right leg leads (stand)
    lead: tuple[int, ...] | None = None
    single: tuple[bool, ...] | None = None

    def with_control(self, ctype: int, split: bool = False) -> Plan:
        """The same motions with every leg and hip board (SCU 1-4) on control type ``ctype``
        (and that type's default gains): ``--control``. ``split`` (the scenarios that keep both
        feet down, ``Scenario.double_support``: stand, flexao, inclinar): for REACTION and BALANCE
        the two legs get the leader/follower pair of :data:`STAND_GAINS` instead of the same law,
        which would make them fight through the pelvis (docs/balance.md 2.2). A plan with
        ``lead``/``single`` (levantar_perna) keeps its own division of labour instead: REACTION or
        BALANCE (with the law's single-support gains, ``planners.GAINS``) on the support leg
        where it carries the robot alone, every other board and motion as planned
        (docs/balance.md 4 has what the other splits measured)."""
        if split and self.single is not None and self.lead is not None and ctype in _BALANCE_TYPES:
            k = np.array(self.k, dtype=float, copy=True)
            for m, alone in enumerate(self.single):
                if alone:
                    k[self.lead[m] - 1, :, m] = control_row(ctype)
            return Plan(self.pos_apply, k, self.t, self.lead, self.single)
        k = with_control(self.k, ctype)
        if split and ctype in _BALANCE_TYPES:
            for scu, gains in STAND_GAINS.items():
                k[scu - 1] = control_row(ctype, gains)[:, None, :]
        return Plan(self.pos_apply, k, self.t, self.lead, self.single)
