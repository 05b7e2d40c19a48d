"""The plant's physics time kept up with the twin's clock: the base of the plant's classes
(``PhysicsTime`` <- ``BoardIO`` (sensors.py) <- ``Plant`` (plant.py), one chain because the
compiled core makes each an extension type, which has one base).

Part of the compiled core (stepping.pxd): every read the boards make first runs the physics due
up to the clock's now (``_sync``) in one ``mj_step(..., nstep=k)`` call (``advance_to``), so a
board's read stays one C call into the plant. ``Plant`` sets the fields (the MuJoCo model and
data, the time step, the bound clock, the tilt profile) and documents them.
"""

from __future__ import annotations

import time

import mujoco

__all__ = ["PhysicsTime", "PlantError", "PlantInputError"]


class PlantError(Exception):
    """The model cannot be loaded or does not match what the boards expect."""


class PlantInputError(PlantError, ValueError):
    """A caller passed an invalid argument (SCU address, pulse width, tilt, ...)."""


class PhysicsTime:
    """Physics time ``t_us`` following the clock bound to the plant: each read first runs the
    physics due up to the clock's now (``_sync``), in this one place."""

    def _sync(self) -> None:
        """Run the physics due up to the bound clock's now (nothing without a clock)."""
        c = self._clock
        if c is not None:
            now = c.now_us
            if now - self.t_us >= self.timestep_us:
                self.advance_to(now)

    def advance_to(self, t_us: int) -> None:
        """Run the physics steps due up to ``t_us`` (never past it) in one ``mj_step`` call.

        The platform tilt profile, if any, is evaluated on a fixed 10 ms grid of physics time
        (the tilt of ``[g, g + 10 ms)`` is ``fn(g)``), so where the callers split the stepping
        (a recorder, a monitor) does not change the physics.
        """
        due = t_us - self.t_us
        if due < 0:
            raise PlantInputError(f"cannot advance the plant backwards: {t_us} us < {self.t_us} us")
        k = due // self.timestep_us
        if k <= 0:
            return
        w0 = time.perf_counter_ns()
        if self._tilt_profile is None:
            mujoco.mj_step(self.model, self.data, nstep=k)
            self.t_us += k * self.timestep_us
        else:
            self._advance_with_profile(k)
        self.step_ns_total += time.perf_counter_ns() - w0
