"""``humanoid-twin run --viewer``: watch a run live in MuJoCo's own passive viewer.

The viewer (``mujoco.viewer.launch_passive``) shows the twin's MuJoCo model and data. The run is
paced to real time (the twin normally runs faster than that) and the window is refreshed every
20 ms of simulated time. Closing the window does not stop the run: it finishes headless, unpaced.
Without a display (no ``DISPLAY`` / ``WAYLAND_DISPLAY``, or a display MuJoCo cannot open) the CLI
says so in one line and exits with code 2 before anything is written.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import Any

from humanoid_twin.clock import US_PER_S

FRAME_US = 20_000          # one refresh per 20 ms of simulated time (50 frames per simulated second)


class LiveViewerError(RuntimeError):
    """No display, or MuJoCo's viewer could not open a window."""


def check_display() -> None:
    """Raise :class:`LiveViewerError` when no display is available (checked before the run)."""
    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if sys.platform.startswith("linux") and not display:
        raise LiveViewerError("--viewer needs a display (DISPLAY is not set); without one, record the run "
                              "and open it with `humanoid-twin view FILE.rrd --web`")


class LiveViewer:
    """MuJoCo's passive viewer on a twin's plant, paced to real time."""

    def __init__(self) -> None:
        self.handle: Any = None
        self._threads: list[threading.Thread] = []
        self._twin: Any = None
        self._wall0 = 0.0
        self._sim0_us = 0

    def attach(self, twin: Any) -> None:
        """Open the window on ``twin.plant`` and refresh it every :data:`FRAME_US` of its clock."""
        import mujoco.viewer

        plant = twin.plant
        before = set(threading.enumerate())
        try:
            self.handle = mujoco.viewer.launch_passive(plant.model, plant.data)
        except Exception as exc:  # GLFW without a usable display raises here
            raise LiveViewerError(f"MuJoCo's viewer could not open a window: {exc}") from exc
        # the viewer's (daemon) thread: joined at close, so that the interpreter does not exit
        # while it still tears the window down (a segfault in GLFW otherwise)
        self._threads = [t for t in threading.enumerate() if t not in before]
        self._twin = twin
        self._wall0 = time.perf_counter()
        self._sim0_us = twin.clock.now_us
        twin.every(FRAME_US, self._frame)

    def _frame(self) -> None:
        handle = self.handle
        if handle is None or not handle.is_running():      # the window was closed: run on, headless
            return
        twin = self._twin
        now_us = twin.clock.now_us
        twin.plant.advance_to(now_us)                      # the physics due up to now, then draw it
        ahead = (now_us - self._sim0_us) / US_PER_S - (time.perf_counter() - self._wall0)
        if ahead > 0:
            time.sleep(ahead)                              # real time: the twin runs faster
        handle.sync()

    def close(self) -> None:
        """Close the window and wait for the viewer's thread to finish."""
        if self.handle is not None:
            self.handle.close()
            self.handle = None
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._threads = []


__all__ = ["FRAME_US", "LiveViewer", "LiveViewerError", "check_display"]
