"""A firmware control law plug-in: a CoP law with a damping term, for BALANCE_CONTROL.

    humanoid-twin run stand --tilt 20 --law balance=examples.cop_pd_law:CopPD

(from the repository root). Each leg board runs it every 20 ms tick, in integers, as the PIC
would: on the foot front joint (servo 1) ``v = KP * (e + 4 * (e - e_prev)) / 2^KD`` with
``e = CoP_ref - CoP`` (mm, forward) and the gain bytes the host sends (``stand`` sends the
leader KP 1 / follower KP -8 pair, KD 2: docs/balance.md). The derivative term damps the body's
rocking on the servos. Foot lateral and knee do nothing (double support, docs/balance.md 2.2).
docs/controllers.md explains the interface.
"""

from __future__ import annotations

from humanoid_twin.slave.laws import VELOCITY, ControlLaw, LawInputs, balance_gain_bytes, shr

D_WEIGHT = 4        # ticks: the derivative term's weight against the proportional one


class CopPD(ControlLaw):
    name = "cop_pd"
    output = VELOCITY           # 1/65536 degree per tick, added to the trajectory reference
    needs_foot = True           # on boards without a foot the servos follow their trajectory

    def __init__(self) -> None:
        self.e_prev: int | None = None

    def start(self, servo: int, inputs: LawInputs) -> None:
        self.e_prev = None

    def step(self, inputs: LawInputs) -> list[int]:
        out = [0, 0, 0]
        if inputs.cop_mm is None or 1 not in inputs.servos:      # foot in the air: hold
            self.e_prev = None
            return out
        e = inputs.cop_error_mm[1]
        d = 0 if self.e_prev is None else e - self.e_prev
        self.e_prev = e
        kp, shift = balance_gain_bytes(inputs.gains[1][1], inputs.gains[1][2])
        # same direction convention as the built-in REACTION law: -sign * KP * e, KP/256 deg/tick/mm
        out[1] = shr((-inputs.signs[1] * kp * (e + D_WEIGHT * d)) << 8, shift)
        return out
