"""Module TRAJECTORY of the Slave firmware (seed 000 section 3, tables 6-7).

Velocity control of the servos by position trajectories: each new final position is reached along
a third-degree polynomial ``theta = a0 + a1 t + a2 t^2 + a3 t^3`` of ``period`` PWM ticks (20 ms),
with zero velocity at both ends (``a1 = 0``, ``a2 = 3 d / T^2``, ``a3 = -2 d / T^3``, ``d`` = the
travel), so that velocity and acceleration have no Dirac-like steps. ``period == 0`` is a *free
traject*: the final position is applied at once.

Whenever the Master asks for a final position or a control type different from ``theta_final`` /
``control_type``, the running trajectory is interrupted and a new one is computed from the current
commanded position (``calcTrajectory``). The coefficients are ``double`` in the manual, so floats
here; the position handed to the controller is rounded to whole int8 degrees.

Time convention (docs/firmware.md, "TRAJECTORY"): ``calcTrajectory`` sets ``time = 0`` at the tick
the new reference is seen; every ``executeTrajectory`` call (one per tick, the same tick first)
advances ``time`` by one and outputs ``theta(time)``, so the final value is output at the
``period``-th tick, and held from then on.
"""

from __future__ import annotations

from collections.abc import Sequence

from humanoid_twin.hardware import N_SERVOS
from humanoid_twin.slave.pic2 import limitPosition

__all__ = ["FREE_TRAJECT", "NORMAL_TRAJECT", "StructTrajectory", "Trajectory", "round_deg"]

FREE_TRAJECT = 0      # enum_trajectType: the final position is applied directly
NORMAL_TRAJECT = 1    # the cubic polynomial over ``period`` ticks

_MAX_PERIOD = 0xFFFF  # ``word period``


def round_deg(x: float) -> int:
    """Round a position in degrees to the nearest whole degree (halves away from zero)."""
    return int(x + 0.5) if x >= 0.0 else -int(0.5 - x)


class StructTrajectory:
    """``struct_trajectory`` (seed 000, TRAJECTORY): the data of one servo's trajectory."""

    __slots__ = ("type", "coef", "period", "time", "theta_final", "control_type")

    def __init__(self) -> None:
        self.type: int = FREE_TRAJECT
        self.coef: list[float] = [0.0, 0.0, 0.0, 0.0]   # a0, a1, a2, a3 (degrees, ticks)
        self.period: int = 0                             # duration in ticks
        self.time: int = 0                               # ticks elapsed
        self.theta_final: int = 0                        # final position (int8 degrees)
        self.control_type: int = 0                       # controller in use (table 9)

    def __repr__(self) -> str:
        kind = "free" if self.type == FREE_TRAJECT else "normal"
        return (
            f"StructTrajectory({kind}, theta_final={self.theta_final}, period={self.period}, "
            f"time={self.time}, control_type={self.control_type}, coef={self.coef})"
        )


class Trajectory:
    """The TRAJECTORY module of one Slave: ``traject[N_SERVOS]`` and its functions."""

    __slots__ = ("traject", "position")

    def __init__(self) -> None:
        self.traject: list[StructTrajectory] = [StructTrajectory() for _ in range(N_SERVOS)]
        self.position: list[int] = [0] * N_SERVOS      # last output of executeTrajectory
        self.initTrajectory()

    def initTrajectory(
        self, positions: Sequence[int] = (0, 0, 0), control_types: Sequence[int] = (0, 0, 0)
    ) -> None:
        """``initTrajectory`` (table 6): every servo at rest at ``positions`` (a finished free
        traject), with the given control types."""
        for i in range(N_SERVOS):
            p = limitPosition(int(positions[i]))
            t = self.traject[i]
            t.type = FREE_TRAJECT
            t.coef[0] = float(p)
            t.coef[1] = t.coef[2] = t.coef[3] = 0.0
            t.period = 0
            t.time = 0
            t.theta_final = p
            t.control_type = int(control_types[i])
            self.position[i] = p

    def calcTrajectory(self, i: int, start: int, theta_final: int, period: int, control_type: int) -> None:
        """``calcTrajectory`` (table 7): a new trajectory of servo ``i`` from ``start`` to
        ``theta_final`` over ``period`` ticks (0 = free traject). Raises ``ValueError`` for a
        period outside 0..65535 (``word``)."""
        if not 0 <= period <= _MAX_PERIOD:
            raise ValueError(f"trajectory period must be 0..{_MAX_PERIOD} ticks, got {period!r}")
        t = self.traject[i]
        t.theta_final = theta_final
        t.control_type = control_type
        t.period = period
        t.time = 0
        c = t.coef
        c[0] = float(start)
        c[1] = 0.0
        if period == 0:
            t.type = FREE_TRAJECT
            c[2] = c[3] = 0.0
        else:
            t.type = NORMAL_TRAJECT
            d = float(theta_final - start)
            c[2] = 3.0 * d / (period * period)
            c[3] = -2.0 * d / (period * period * period)

    def executeTrajectory(self, i: int) -> int:
        """``executeTrajectory`` (table 7): one tick of servo ``i``'s trajectory; returns (and
        stores in ``position[i]``) the position to command, in whole degrees."""
        t = self.traject[i]
        if t.type == FREE_TRAJECT:
            p = t.theta_final
        else:
            if t.time < t.period:
                t.time += 1
            tt = t.time
            if tt >= t.period:
                p = t.theta_final
            else:
                c0, c1, c2, c3 = t.coef
                p = round_deg(c0 + tt * (c1 + tt * (c2 + tt * c3)))
        self.position[i] = p
        return p

    def trajectory(
        self, refs: Sequence[int], periods: Sequence[int], types: Sequence[int], start: Sequence[int]
    ) -> int:
        """``trajectory`` (table 6): one tick for all servos. A reference or control type that
        differs from the running trajectory's interrupts it and starts a new one from ``start``
        (the current commanded positions). Returns a bit mask of the servos restarted (bit i =
        servo i). The outputs are in ``position``."""
        restarted = 0
        traject = self.traject
        for i in range(N_SERVOS):
            ref = limitPosition(refs[i])
            t = traject[i]
            if ref != t.theta_final or types[i] != t.control_type:
                self.calcTrajectory(i, start[i], ref, periods[i], types[i])
                restarted |= 1 << i
            self.executeTrajectory(i)
        return restarted

    def done(self, i: int) -> bool:
        """Whether servo ``i``'s trajectory has output its final position."""
        t = self.traject[i]
        return t.type == FREE_TRAJECT or t.time >= t.period

    def theoretical(self, i: int, tick: float) -> float:
        """The polynomial of servo ``i`` at ``tick`` ticks after its start, unrounded (for tests
        and recording of the planned trajectory)."""
        t = self.traject[i]
        if t.type == FREE_TRAJECT or tick >= t.period:
            return float(t.theta_final)
        c = t.coef
        return c[0] + tick * (c[1] + tick * (c[2] + tick * c[3]))
