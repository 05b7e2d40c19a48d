"""recording: what the twin did, for people and tools (docs/recording.md).

- :class:`Recorder`: a rerun ``.rrd`` recording of a running twin (buffered columns on the
  ``sim_time`` timeline, robot in 3D, joints, currents, force sensors, CoP, counters, and a
  default blueprint). ``humanoid-twin view FILE.rrd`` or ``rerun FILE.rrd`` opens it.
- :class:`CanLog`: the CAN traffic in python-can's log formats (by suffix), virtual timestamps.
- Read-back: :func:`read_rrd_entities`, :func:`read_rrd_rows`, :func:`read_rrd_scalars`,
  :func:`rrd_has_blueprint` (rerun's own loader), :func:`verify_rrd` (``rerun rrd verify``);
  :func:`read_can_log`, :func:`decode_can_log`
  (python-can + the project's DBC).

What is recorded where: docs/recording.md.
"""

from typing import TYPE_CHECKING, Any

from humanoid_twin.recording.can_log import (
    CanLog,
    CanLogError,
    DecodedFrame,
    check_log_path,
    decode_can_log,
    read_can_log,
)
from humanoid_twin.recording.readback import (
    RrdReadError,
    read_rrd_entities,
    read_rrd_rows,
    read_rrd_scalars,
    rrd_has_blueprint,
    verify_rrd,
)

if TYPE_CHECKING:
    from humanoid_twin.recording.rerun_recorder import (
        SHORT_RECORDING_S,
        TIMELINE,
        Recorder,
        RecorderError,
        compact_for,
    )

# The recorder's names come from rerun_recorder on first use: importing it imports rerun and
# pyarrow (about a second of CPU), which a CAN log, a read-back or a path table does not need.
_RECORDER_NAMES = frozenset({"SHORT_RECORDING_S", "TIMELINE", "Recorder", "RecorderError", "compact_for"})


def __getattr__(name: str) -> Any:
    if name in _RECORDER_NAMES:
        from humanoid_twin.recording import rerun_recorder

        return getattr(rerun_recorder, name)
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
    "RrdReadError",
    "read_rrd_entities",
    "read_rrd_rows",
    "read_rrd_scalars",
    "rrd_has_blueprint",
    "verify_rrd",
]
