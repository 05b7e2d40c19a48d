"""``humanoid-twin run --viewer``: watch a run live in MuJoCo's own passive viewer.

The viewer (the plant's window, ``Plant.open_viewer``) shows the twin's MuJoCo model and data. The
run is paced to real time by the clock's :class:`~humanoid_twin.clock.RealTimePacer` (the twin
normally runs faster than that) and the window is refreshed every 20 ms of simulated time.
Closing the window does not stop the run: it finishes headless, unpaced. Without a display (no
``DISPLAY`` / ``WAYLAND_DISPLAY``, or a display MuJoCo cannot open) the CLI says so in one line
and exits with code 2 before anything is written.
"""

from __future__ import annotations

import os
import sys
from typing import TYPE_CHECKING

from humanoid_twin.clock import RealTimePacer
from humanoid_twin.plant import ViewerWindow, ViewerWindowError

if TYPE_CHECKING:
    from humanoid_twin.twin import Twin

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
        self.window: ViewerWindow | None = None
        self._pacer: RealTimePacer | None = None

    def attach(self, twin: Twin) -> None:
        """Open the window on ``twin.plant`` and refresh it every :data:`FRAME_US` of its clock."""
        try:
            self.window = twin.plant.open_viewer()
        except ViewerWindowError as exc:
            raise LiveViewerError(str(exc)) from exc
        self._pacer = RealTimePacer(twin.clock)
        self._pacer.start()
        twin.every(FRAME_US, self._frame)

    def _frame(self) -> None:
        window = self.window
        if window is None or not window.is_open():      # the window was closed: run on, headless
            return
        assert self._pacer is not None
        self._pacer.wait()                              # real time: the twin runs faster
        window.draw()                                   # the physics due up to now, then draw it

    def close(self) -> None:
        """Close the window and wait for the viewer's thread to finish."""
        if self.window is not None:
            self.window.close()
            self.window = None


__all__ = ["FRAME_US", "LiveViewer", "LiveViewerError", "check_display"]
