"""A robot's CAN log, read for ``compare`` and ``calibrate``: the Master's frames that drive the
twin, the Slaves' Sensors frames it is compared with, and what else the bus carried (counted).

``read_robot_log(path)`` reads any log python-can reads (``can.LogReader``: ``.blf .asc .log
.csv .trc .db .mf4``, optionally ``.gz``) and sorts what it finds:

- **Master frames**: Actuation 1 and 2 to each SCU (identifiers ``canframes.ACTUATION_IDS``),
  8 data bytes, decodable with the project's codecs (``canframes.unpack_actuation1/2``);
- **Sensors frames**: Sensors 1 and 2 of each SCU (``canframes.SENSOR_IDS``), decodable with
  ``canframes.unpack_sensors1/2``;
- **foreign frames**: anything else (another ID, an extended ID, a remote frame, a payload the
  codecs refuse): counted, never sent to the twin, never compared;
- **error frames**: counted.

Time: every frame's instant is in integer microseconds from the start (SOF) of the log's first
Master frame, so an adapter's clock (seconds since 1970, or since it was plugged in) and the
twin's virtual clock line up: the first Master frame starts at the twin's instant 0, as the
twin's own Master sends its first frame at power-on. The shift is ``clock_offset_s``. The
frame's length on the wire (``bus.frames.frame_bits``) gives its start from the logged instant
(python-can adapters, and the twin's own logs, stamp a frame at its end).

Bad input (:class:`RobotLogError`, a ``ValueError``; the CLI's exit 2): a file python-can cannot
read, a log without one Master frame, a log with none of the robot's identifiers.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass, field
from typing import NamedTuple

from humanoid_twin.bus.frames import frame_bits
from humanoid_twin.clock import US_PER_S
from humanoid_twin.protocol import canframes
from humanoid_twin.protocol.canframes import CAN_BITRATE, PAYLOAD_LEN, PayloadError
from humanoid_twin.protocol.wire import STATUS_CALIB

__all__ = ["LogFrame", "RobotLog", "RobotLogError", "read_robot_log", "robot_log_from_messages",
           "ACTUATION_OF", "SENSORS_OF"]

# identifier -> (scu, packet index) of the robot's frames (the codecs' tables, inverted once)
ACTUATION_OF: dict[int, tuple[int, int]] = {
    arb: (scu, idx) for scu, ids in canframes.ACTUATION_IDS.items() for idx, arb in enumerate(ids)}
SENSORS_OF: dict[int, tuple[int, int]] = {
    arb: (scu, idx) for scu, ids in canframes.SENSOR_IDS.items() for idx, arb in enumerate(ids)}
_BIT_US = US_PER_S // CAN_BITRATE       # 1 us per bit at 1 Mbit/s
_EOF_TO_END_BITS = 3                    # a frame is stamped 3 bits (its IFS) before its last bit


class RobotLogError(ValueError):
    """A file that is not a usable CAN log of the robot (one line for the user)."""


class LogFrame(NamedTuple):
    """One of the robot's frames in a log: ``t_us`` (logged instant, us from the first Master
    frame's start), ``arbitration_id``, ``data`` (8 bytes)."""

    t_us: int
    arbitration_id: int
    data: bytes


@dataclass
class RobotLog:
    """What :func:`read_robot_log` found in a log, in time order."""

    path: str
    master: list[LogFrame] = field(default_factory=list)      # Actuation 1/2 to SCU 1..8
    sensors: list[LogFrame] = field(default_factory=list)     # Sensors 1/2 of SCU 1..8
    frames_total: int = 0
    frames_foreign: int = 0          # not the robot's (other IDs, extended, remote, bad payloads)
    error_frames: int = 0
    clock_offset_s: float = 0.0      # the logged time of the twin's instant 0

    @property
    def started_after_boot(self) -> bool:
        """Whether the log begins after the boot: its first Sensors 1 frame says its Slave is
        calibrated (Status bit 6)."""
        first = next((f for f in self.sensors if SENSORS_OF[f.arbitration_id][1] == 0), None)
        return first is not None and bool(first.data[7] & STATUS_CALIB)

    def shifted(self, dt_us: int) -> RobotLog:
        """The same log ``dt_us`` later on the twin's clock."""
        return RobotLog(self.path, [f._replace(t_us=f.t_us + dt_us) for f in self.master],
                        [f._replace(t_us=f.t_us + dt_us) for f in self.sensors], self.frames_total,
                        self.frames_foreign, self.error_frames, self.clock_offset_s - dt_us / US_PER_S)

    @property
    def duration_us(self) -> int:
        """The last frame's instant."""
        last = [f.t_us for f in (self.master[-1:] + self.sensors[-1:])]
        return max(last) if last else 0

    def master_start_us(self, frame: LogFrame) -> int:
        """The instant a Master frame started on the wire (its logged instant minus its length)."""
        return frame.t_us - (frame_bits(frame.arbitration_id, frame.data) - _EOF_TO_END_BITS) * _BIT_US


def _is_robot_payload(arb: int, data: bytes) -> bool:
    """Whether ``data`` decodes with the project's codecs for identifier ``arb``."""
    if len(data) != PAYLOAD_LEN:
        return False
    try:
        if arb in ACTUATION_OF:
            if ACTUATION_OF[arb][1] == 0:
                canframes.unpack_actuation1(data)
            else:
                canframes.unpack_actuation2(data)
        else:
            scu, idx = SENSORS_OF[arb]
            src = canframes.unpack_sensors1(data)[0] if idx == 0 else canframes.unpack_sensors2(data)[0]
            if src != scu:
                return False
    except (PayloadError, ValueError):
        return False
    return True


def robot_log_from_messages(messages: list, path: str = "<messages>") -> RobotLog:
    """Sort python-can messages (anything with ``timestamp``, ``arbitration_id``, ``data``,
    ``is_error_frame`` ...) into a :class:`RobotLog` (see the module's docstring)."""
    log = RobotLog(path=str(path))
    raw: list[tuple[float, int, bytes, bool]] = []
    for msg in messages:
        log.frames_total += 1
        if getattr(msg, "is_error_frame", False):
            log.error_frames += 1
            continue
        arb = msg.arbitration_id
        data = bytes(msg.data)
        if (getattr(msg, "is_extended_id", False) or getattr(msg, "is_remote_frame", False)
                or getattr(msg, "is_fd", False) or (arb not in ACTUATION_OF and arb not in SENSORS_OF)
                or not _is_robot_payload(arb, data)):
            log.frames_foreign += 1
            continue
        raw.append((float(msg.timestamp), arb, data, arb in ACTUATION_OF))
    if not raw:
        raise RobotLogError(f"CAN log {path}: none of the robot's frames (Actuation/Sensors of SCU 1..8) "
                            f"in {log.frames_total} frames")
    raw.sort(key=lambda r: r[0])      # an adapter may write a few out of order: stable sort
    first_master = next((r for r in raw if r[3]), None)
    if first_master is None:
        raise RobotLogError(f"CAN log {path}: no Master frame (Actuation 1/2) among its "
                            f"{len(raw)} Sensors frames: the twin has nothing to drive it with")
    # the first Master frame starts at the twin's instant 0 (the logged instant is its end)
    t0, arb0, data0, _ = first_master
    start_offset_us = (frame_bits(arb0, data0) - _EOF_TO_END_BITS) * _BIT_US
    log.clock_offset_s = t0 - start_offset_us / US_PER_S
    for ts, arb, data, is_master in raw:
        t_us = round((ts - t0) * US_PER_S) + start_offset_us
        if t_us < 0:         # a Slave's frame logged before the first Master frame: answers nothing
            log.frames_foreign += 1
            continue
        (log.master if is_master else log.sensors).append(LogFrame(t_us, arb, data))
    return log


def read_robot_log(path: str | pathlib.Path) -> RobotLog:
    """Read a CAN log with python-can and sort it (:func:`robot_log_from_messages`).
    :class:`RobotLogError` when python-can cannot read it or it is not the robot's."""
    import can

    p = pathlib.Path(path)
    if not p.is_file():
        raise RobotLogError(f"CAN log {p}: no such file")
    from humanoid_twin.recording.can_log import _reader_suffixes, log_suffix

    suffix = log_suffix(p)
    if suffix not in _reader_suffixes():
        raise RobotLogError(f"CAN log {p}: python-can does not read {suffix or '(no suffix)'!r} files; "
                            f"it reads {', '.join(_reader_suffixes())}")
    try:
        with can.LogReader(p) as reader:
            messages = list(reader)
    except Exception as exc:    # noqa: BLE001 - each python-can reader fails its own way on a bad file
        why = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise RobotLogError(f"CAN log {p}: not a readable {suffix} CAN log ({why})") from None
    return robot_log_from_messages(messages, str(p))
