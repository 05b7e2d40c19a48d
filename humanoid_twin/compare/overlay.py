"""``compare --out F.rrd``: the twin's and the log's signals overlaid on ``sim_time`` in rerun.

Each compared signal is one entity ``compare/GROUP/NAME`` with two series, ``twin`` and ``log``
(at the log's instants of the paired frames, the twin's clock), so the viewer draws them on one
plot; ``compare/GROUP/NAME/diff`` is their difference. ``calibrate --report F.rrd`` writes the
same overlay for each log before and after the fit (``before/``, ``after/``).
"""

from __future__ import annotations

import pathlib
import uuid
from collections.abc import Mapping

import numpy as np

from humanoid_twin.compare.signals import SIGNALS
from humanoid_twin.recording.rerun_recorder import TIMELINE

__all__ = ["write_overlay"]


def write_overlay(path: str | pathlib.Path,
                  runs: Mapping[str, Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]]]) -> None:
    """Write ``runs`` (prefix -> a compare result's ``series``) to a rerun recording at ``path``."""
    import rerun as rr

    rec = rr.RecordingStream("humanoid_twin_compare", recording_id=uuid.uuid4())
    rec.set_sinks(rr.FileSink(str(path)))
    try:
        for prefix, series in runs.items():
            for s in SIGNALS:
                t, twin, log = series[s.name]
                if not t.size:
                    continue
                base = f"{prefix}/{s.group}/{s.name}" if prefix else f"compare/{s.group}/{s.name}"
                idx = [rr.TimeColumn(TIMELINE, duration=t.astype("timedelta64[us]"))]
                for who, v in (("twin", twin), ("log", log), ("diff", twin - log)):
                    rec.send_columns(f"{base}/{who}", indexes=idx, columns=rr.Scalars.columns(scalars=v))
    finally:
        rec.flush()
        rec.disconnect()
