"""The signals ``compare`` reads from the Sensors frames, named once from the robot's wiring.

Every signal is one field of a Sensors packet of one SCU, decoded with the project's codecs
(``protocol/canframes.py``: ``unpack_sensors1`` / ``unpack_sensors2``), in the packet's own unit
(the wire's integers), and belongs to a group:

=============  ==============================  ========================  ==================
group          field                           name                      quantum (unit)
=============  ==============================  ========================  ==================
position_deg   Sensors 1 Pos1..3               the joint (``r_knee``)    1 degree
speed          Sensors 1 Speed1..3             ``JOINT.speed``           1 degree / 20 ms
current        Sensors 2 Curr1..3              ``JOINT.current``         1 (0..100)
force_counts   Sensors 2 Data1..4, feet        the pad (``r_foot_fl``)   1 count
imu_counts     Sensors 2 Data1..4, body board  ``imu.IncRoll`` ...       1 count
=============  ==============================  ========================  ==================

Joint names: ``hardware.SERVO_JOINTS`` (SCU x servo); pads: the foot of ``hardware.FOOT_OF_SCU``
and ``hardware.FORCE_SENSOR_LABELS`` (table 12 order, as the model's sites ``r_foot_fl`` ...);
the body board's sensors: ``hardware.IMU_SENSOR_NAMES``. The quantum is what ``calibrate``
divides each residual by (one step of the measurement: docs/calibration.md).
"""

from __future__ import annotations

from typing import NamedTuple

from humanoid_twin import hardware
from humanoid_twin.protocol import canframes

__all__ = ["Signal", "SIGNALS", "GROUPS", "GROUP_UNITS", "QUANTUM", "decode_packet"]


class Signal(NamedTuple):
    """One compared signal: ``name``, ``group``, the SCU and packet index it comes in, and the
    position of its value in :func:`decode_packet`'s tuple."""

    name: str
    group: str
    scu: int
    packet: int
    field: int


GROUPS: tuple[str, ...] = ("position_deg", "speed", "current", "force_counts", "imu_counts")
GROUP_UNITS: dict[str, str] = {
    "position_deg": "deg", "speed": "deg/20ms", "current": "0..100", "force_counts": "counts",
    "imu_counts": "counts"}
QUANTUM: dict[str, float] = {group: 1.0 for group in GROUPS}   # one step of each wire integer


def _signals() -> tuple[Signal, ...]:
    out: list[Signal] = []
    for scu, joints in hardware.SERVO_JOINTS.items():
        for i, joint in enumerate(joints):
            out.append(Signal(joint, "position_deg", scu, 0, i))
            out.append(Signal(f"{joint}.speed", "speed", scu, 0, 3 + i))
            out.append(Signal(f"{joint}.current", "current", scu, 1, i))
        if scu in hardware.FOOT_OF_SCU:
            foot = hardware.FOOT_OF_SCU[scu]
            for k, label in enumerate(hardware.FORCE_SENSOR_LABELS):
                out.append(Signal(f"{foot}_{label.lower()}", "force_counts", scu, 1, 3 + k))
        if scu == hardware.IMU_SCU:
            for k, label in enumerate(hardware.IMU_SENSOR_NAMES):
                out.append(Signal(f"imu.{label}", "imu_counts", scu, 1, 3 + k))
    return tuple(out)


SIGNALS: tuple[Signal, ...] = _signals()


def decode_packet(packet: int, data: bytes) -> tuple[tuple[int, ...], int]:
    """A Sensors packet's values in :class:`Signal` field order, and its Status byte (packet 0;
    -1 for packet 1): ``(pos1, pos2, pos3, speed1, speed2, speed3)`` or ``(curr1, curr2, curr3,
    data1, data2, data3, data4)``."""
    if packet == 0:
        _, _, pos, speed, status = canframes.unpack_sensors1(data)
        return (*pos, *speed), status
    _, _, curr, data4 = canframes.unpack_sensors2(data)
    return (*curr, *data4), -1
