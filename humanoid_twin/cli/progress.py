"""Progress of ``humanoid-twin run`` on stderr, driven by virtual time.

Two phases: the boot (its length is not known in advance: the Slaves calibrate, ~2.65 s of virtual
time), then the run up to its end time. On a terminal: a tqdm bar (tqdm's own throttling, at most
~10 redraws a second), simulated seconds done / total, wall time elapsed and remaining (ETA) and the
real-time factor (simulated seconds per wall second). On anything else (a CI log, a file, a pipe):
one plain line when the boot starts and ends, at every 10 % of the run and at the end, never a
carriage return. A run asked for a ``--duration`` within the boot's bound (``BOOT_TIMEOUT_S``, 5 s)
gets no "booting" line: it is over in about a second of wall time, and a duration that turns out
shorter than this seed's boot (2.5-2.65 s) is then reported in one line, the error alone.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    from tqdm import tqdm

TICK_S = 0.1      # the run calls update() every 0.1 s of virtual time (scenarios.run)
_BAR_FORMAT = ("{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.1f} s simulated "
               "[{elapsed}<{remaining} wall, {rate_fmt}]")
_BOOT_FORMAT = "{desc}: {n:.1f} s simulated [{elapsed} wall]"


class RunProgress:
    """``update(t_s, end_s)``: ``end_s`` None while booting, else the run's end time (s)."""

    def __init__(self, label: str, stream: TextIO, duration_s: float | None = None) -> None:
        from humanoid_twin.scenarios import BOOT_TIMEOUT_S

        self.label = label
        self._boot_line = duration_s is None or duration_s > BOOT_TIMEOUT_S
        self.stream = stream
        self.tty = bool(getattr(stream, "isatty", lambda: False)())
        self._t0 = time.perf_counter()
        self._bar: tqdm[Any] | None = None
        self._boot_bar: tqdm[Any] | None = None
        self._boot_end_s: float | None = None
        self._next_pct = 10
        self._last: tuple[float, float | None] | None = None
        self._boot_error: str | None = None

    def boot_ended(self, t_s: float, error: str | None) -> None:
        """The boot is over at ``t_s`` (``scenarios.run``'s ``on_boot``): ``error`` None when it
        worked, else why it failed; the next :meth:`update` says which."""
        self._boot_error = error

    def update(self, t_s: float, end_s: float | None) -> None:
        """Virtual time ``t_s`` reached (called every 0.1 s of virtual time)."""
        first = self._last is None
        self._last = (t_s, end_s)
        if end_s is None:
            if first and not self.tty and self._boot_line:
                self._line("booting (the Slaves calibrate their servos, ~2.7 s simulated)")
            if self.tty:
                if self._boot_bar is None:
                    self._boot_bar = self._tqdm(None, f"{self.label}: boot", _BOOT_FORMAT)
                self._boot_bar.update(t_s - self._boot_bar.n)
            return
        if self._boot_end_s is None:
            self._boot_done(t_s, end_s)
        if self.tty:
            if self._bar is None:
                self._bar = self._tqdm(end_s, self.label, _BAR_FORMAT, initial=t_s)  # after the boot
            self._bar.update(min(t_s, end_s) - self._bar.n)
            return
        t_s = min(t_s, end_s)
        pct = 100.0 * t_s / end_s if end_s > 0 else 100.0
        if pct + 1e-9 >= self._next_pct:
            self._next_pct = 10 * int(pct // 10) + 10
            self._line(f"{pct:3.0f}% {t_s:.1f}/{end_s:.1f} s simulated, " + self._times(t_s, end_s))

    def close(self) -> None:
        """Close the bars (a terminal) or write the last line, where the run stopped (otherwise)."""
        for bar in (self._boot_bar, self._bar):
            if bar is not None:
                bar.close()
        self._boot_bar = self._bar = None
        if not self.tty and self._last is not None and self._last[1] is not None:
            t_s, end_s = self._last
            if self._next_pct <= 100:          # the 100 % line was not written yet
                if t_s + TICK_S >= end_s - 1e-9:  # type: ignore[operator]  # the last tick before the end: the run got there (set with _last)
                    t_s = end_s  # type: ignore[assignment]  # as above
                pct = 100.0 * t_s / end_s if end_s > 0 else 100.0  # type: ignore[operator]  # as above
                self._line(f"{pct:3.0f}% {t_s:.1f}/{end_s:.1f} s simulated, "
                           f"{time.perf_counter() - self._t0:.1f} s wall")
            self._next_pct = 110

    def _boot_done(self, t_s: float, end_s: float) -> None:
        self._boot_end_s = t_s
        if self._boot_bar is not None:
            self._boot_bar.close()
            self._boot_bar = None
        if self._boot_error is not None:          # on a terminal too: it is what the run shows
            if self.tty:
                from tqdm import tqdm

                tqdm.write(f"{self.label}: {self._boot_failed(t_s, end_s)}", file=self.stream)
            else:
                self._line(self._boot_failed(t_s, end_s))
        if not self.tty:
            pct = 100.0 * t_s / end_s if end_s > 0 else 100.0
            self._next_pct = 10 * int(pct // 10) + 10
            if self._boot_error is None:
                self._line(f"booted by {t_s:.1f} s simulated ({time.perf_counter() - self._t0:.1f} s wall); "
                           f"the run ends at {end_s:.1f} s")

    def _boot_failed(self, t_s: float, end_s: float) -> str:
        return (f"the boot FAILED by {t_s:.1f} s simulated: {self._boot_error}; the scenario does not run, "
                f"the twin runs on to {end_s:.1f} s (the summary's booted: no)")

    def _times(self, t_s: float, end_s: float) -> str:
        wall = time.perf_counter() - self._t0
        rate = t_s / wall if wall > 0 else float("inf")
        eta = (end_s - t_s) / rate if rate > 0 else float("nan")
        return f"{wall:.1f} s wall, ETA {eta:.1f} s ({rate:.1f}x real time)"

    def _line(self, text: str) -> None:
        self.stream.write(f"{self.label}: {text}\n")
        self.stream.flush()

    def _tqdm(self, total: float | None, desc: str, fmt: str, initial: float = 0.0) -> tqdm[Any]:
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, file=self.stream, unit="s", initial=initial,
                    bar_format=fmt, leave=False, dynamic_ncols=True)
