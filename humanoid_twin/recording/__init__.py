"""recording: what the twin did, for people and tools (docs/recording.md).

- :class:`Recorder`: a rerun ``.rrd`` recording of a running twin (buffered columns on the
  ``sim_time`` timeline, robot in 3D, joints, currents, force sensors, CoP, counters, and a
  default blueprint). ``humanoid-twin view FILE.rrd`` or ``rerun FILE.rrd`` opens it.
- :class:`CanLog`: the CAN traffic in python-can's log formats (by suffix), virtual timestamps.
- :class:`SerialLog`: the RS-232 traffic, byte for byte (``serial_log.py``; :func:`read_log`).
  The CAN and serial logs are the run logs beside the recording; they load without rerun (the
  rerun-based names below are imported on first use).
- Read-back: :func:`read_rrd_entities`, :func:`read_rrd_rows`, :func:`read_rrd_scalars`,
  :func:`rrd_has_blueprint` (rerun's own loader), :func:`verify_rrd` (``rerun rrd verify``);
  :func:`read_can_log`, :func:`decode_can_log`
  (python-can + the project's DBC).

What is recorded where: docs/recording.md.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from humanoid_twin.recording.can_log import (
    CanLog,
    CanLogError,
    DecodedFrame,
    check_log_path,
    decode_can_log,
    read_can_log,
)
from humanoid_twin.recording.serial_log import SerialLog, SerialLogError, read_log

if TYPE_CHECKING:
    from humanoid_twin.recording.readback import (
        RrdReadError,
        read_rrd_entities,
        read_rrd_rows,
        read_rrd_scalars,
        rrd_has_blueprint,
        verify_rrd,
    )
    from humanoid_twin.recording.rerun_recorder import (
        SHORT_RECORDING_S,
        TIMELINE,
        Recorder,
        RecorderError,
        compact_for,
    )

# the rerun-based names load rerun on first use: the run logs alone (a --no-record run's CAN or
# serial log, a replay) do not pay for importing rerun
_LAZY = {
    **dict.fromkeys(("RrdReadError", "read_rrd_entities", "read_rrd_rows", "read_rrd_scalars",
                     "rrd_has_blueprint", "verify_rrd"), "readback"),
    **dict.fromkeys(("SHORT_RECORDING_S", "TIMELINE", "Recorder", "RecorderError", "compact_for"),
                    "rerun_recorder"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "Recorder",
    "RecorderError",
    "TIMELINE",
    "SHORT_RECORDING_S",
    "compact_for",
    "CanLog",
    "CanLogError",
    "DecodedFrame",
    "check_log_path",
    "read_can_log",
    "decode_can_log",
    "SerialLog",
    "SerialLogError",
    "read_log",
    "RrdReadError",
    "read_rrd_entities",
    "read_rrd_rows",
    "read_rrd_scalars",
    "rrd_has_blueprint",
    "verify_rrd",
]
