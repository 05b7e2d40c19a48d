#!/usr/bin/env python3
"""Generate ``humanoid_twin/protocol/humanoid_twin.dbc`` with the cantools API.

The DBC describes the Master <-> Slave CAN traffic of seed 002 slides 18-20 (docs/protocol.md section 2):
for each slave k = 1..8, ``Actuation1_S<k>`` / ``Actuation2_S<k>`` from MASTER to SCU<k> and
``Sensors1_S<k>`` / ``Sensors2_S<k>`` back. Identifiers come from ``canframes.can_id``; signal
ranges are the ranges the codecs in ``humanoid_twin.protocol.canframes`` accept.

    python scripts/make_dbc.py            # (re)write the shipped file
    python scripts/make_dbc.py --check    # exit 1 if the shipped file is not what this generates
"""

from __future__ import annotations

import argparse
import sys
from collections import OrderedDict
from pathlib import Path

from cantools.database import conversion
from cantools.database.can import Database, Message, Node, Signal

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # generate from this checkout, installed or not
    sys.path.insert(0, str(REPO))

from humanoid_twin.hardware import (  # noqa: E402
    FORCE_SENSOR_LABELS,
    FORCE_SENSOR_NAMES,
    IMU_GYRO_DPS_PER_COUNT,
    IMU_INCL_DEG_PER_COUNT,
    IMU_SCU,
    IMU_SENSOR_NAMES,
    IMU_ZERO_COUNT,
    SCU_NAMES,
)
from humanoid_twin.protocol import canframes as cf  # noqa: E402
from humanoid_twin.protocol import wire  # noqa: E402
from humanoid_twin.protocol.wire import SCUS, ControlType, ErrorState  # noqa: E402

DBC_PATH = REPO / "humanoid_twin" / "protocol" / cf.DBC_RESOURCE

# The Master's time-triggered schedule (seed 000 section 2, docs/master.md): 1 ms per Slave, each
# Slave's two actuation packets once per 8 ms round, its two sensor packets answering them; the
# DBC's GenMsgCycleTime of every message
CYCLE_MS = 8

# Section names as in seed 002 slide 19 ("Right Leg" ...), from the boards' names.
SECTIONS = {k: SCU_NAMES[k].replace("_", " ").title() for k in SCUS}

CONTROL_CHOICES = OrderedDict((int(t), t.name) for t in ControlType)
CAN_STATE_CHOICES = OrderedDict((int(e), e.label) for e in ErrorState)
# The four force sensors of a foot, in the order of Sensors 2 bytes 4-7 (Data1..4 of slide 20):
# seed 000 table 12's order, front-left, front-right, rear-left, rear-right (hardware.py).
FORCE_NAMES = dict(zip(FORCE_SENSOR_LABELS, FORCE_SENSOR_NAMES, strict=True))


def _bit(mask: int) -> int:
    """The bit number of a one-bit mask (0x40 -> 6)."""
    return mask.bit_length() - 1


def _sig(
    name: str,
    byte: int,
    *,
    bit: int = 0,
    length: int = 8,
    signed: bool = False,
    unit: str | None = None,
    minimum: int | None = None,
    maximum: int | None = None,
    choices: OrderedDict | None = None,
    comment: str | None = None,
    receiver: str,
    scale: float = 1,
    offset: float = 0,
) -> Signal:
    """A signal of ``length`` bits starting at bit ``bit`` of payload byte ``byte`` (0-based);
    physical value = ``scale * raw + offset``."""
    if minimum is None:
        minimum = scale * (-(1 << (length - 1)) if signed else 0) + offset
    if maximum is None:
        maximum = scale * ((1 << (length - 1)) - 1 if signed else (1 << length) - 1) + offset
    return Signal(
        name=name,
        start=8 * byte + bit,
        length=length,
        byte_order="little_endian",
        is_signed=signed,
        conversion=conversion.BaseConversion.factory(scale=scale, offset=offset, choices=choices),
        minimum=minimum,
        maximum=maximum,
        unit=unit,
        comment=comment,
        receivers=[receiver],
    )


def _sflags(receiver: str) -> list[Signal]:
    return [
        _sig(
            "SFlagsSource", 0, bit=cf.SFLAGS_SOURCE_SHIFT, length=8 - cf.SFLAGS_SOURCE_SHIFT,
            comment="SFlags bits 7-4: source address", receiver=receiver
        ),
        _sig("SFlagsIndex", 0, bit=_bit(cf.SFLAGS_INDEX), length=1, comment="SFlags bit 3: packet index",
             receiver=receiver),
    ]


def _sflags1_supervisor() -> list[Signal]:
    """Sensors 1 SFlags bits 2-0, zero in seed 002 slide 20: the Slave's supervisor flags
    (docs/supervisor.md, ``canframes.SFLAGS_WATCHDOG`` / ``SFLAGS_CAN_STATE``)."""
    return [
        _sig("Watchdog", 0, bit=_bit(cf.SFLAGS_WATCHDOG), length=1, receiver="MASTER",
             comment="SFlags bit 2: CAN watchdog, no actuation for 5 ticks, holding the last reference"),
        _sig("CanState", 0, bit=0, length=cf.SFLAGS_CAN_STATE.bit_length(), receiver="MASTER",
             maximum=int(ErrorState.BUS_OFF), choices=CAN_STATE_CHOICES,
             comment="SFlags bits 1-0: the Slave's CAN error state since its last tick"),
    ]


def _imu_signals() -> list[Signal]:
    """Sensors 2 Data1..4 of the body board: its inclinometer and gyroscope (docs/firmware.md,
    "Trunk inertial sensors"), physical units from the 8-bit counts (hardware.py)."""
    out = []
    for i, name in enumerate(IMU_SENSOR_NAMES):
        incl = i < 2
        scale = IMU_INCL_DEG_PER_COUNT if incl else IMU_GYRO_DPS_PER_COUNT
        axis = "roll (about the trunk's x, forward)" if i % 2 == 0 else "pitch (about the trunk's y, left)"
        what = "inclinometer" if incl else "gyroscope"
        out.append(_sig(name, 4 + i, unit="deg" if incl else "deg/s", receiver="MASTER", scale=scale,
                        offset=-IMU_ZERO_COUNT * scale,
                        comment=f"Data{i + 1}: trunk {what}, {axis}; 8-bit ADC count, {IMU_ZERO_COUNT} = 0"))
    return out


def messages_for(k: int) -> list[Message]:
    """The four messages exchanged with slave ``k`` (seed 002 slide 20)."""
    scu = f"SCU{k}"
    act1 = [
        *(
            _sig(
                f"Ref{i}",
                i - 1,
                signed=True,
                unit="deg",
                comment=f"reference position, servo {i}",
                receiver=scu,
            )
            for i in (1, 2, 3)
        ),
        *(
            _sig(
                f"Speed{i}",
                2 + i,
                unit="tick",
                comment=f"movement period in 20 ms ticks, servo {i}",
                receiver=scu,
            )
            for i in (1, 2, 3)
        ),
        *(
            _sig(
                f"Type{i}",
                6,
                bit=wire.CONTROL_TYPE_BITS * (i - 1),
                length=wire.CONTROL_TYPE_BITS,
                choices=CONTROL_CHOICES,
                comment=f"Control bits {2 * i - 1}-{2 * i - 2}: control type of servo {i}",
                receiver=scu,
            )
            for i in (1, 2, 3)
        ),
        _sig("Calib", 6, bit=_bit(wire.CONTROL_CALIB), length=1,
             comment="Control bit 6: calibration requested", receiver=scu),
        _sig("PWM", 6, bit=_bit(wire.CONTROL_PWM), length=1, comment="Control bit 7: PWM on", receiver=scu),
        _sig("KD3", 7, comment="KD gain, servo 3", receiver=scu),
    ]
    act2 = [
        *(_sig(f"KI{i}", i - 1, comment=f"KI gain, servo {i}", receiver=scu) for i in (1, 2, 3)),
        *(_sig(f"KP{i}", 2 + i, comment=f"KP gain, servo {i}", receiver=scu) for i in (1, 2, 3)),
        _sig("KD1", 6, comment="KD gain, servo 1", receiver=scu),
        _sig("KD2", 7, comment="KD gain, servo 2", receiver=scu),
    ]
    sen1 = [
        *_sflags("MASTER"),
        *_sflags1_supervisor(),
        *(
            _sig(
                f"Pos{i}",
                i,
                signed=True,
                unit="deg",
                comment=f"measured position, servo {i}",
                receiver="MASTER",
            )
            for i in (1, 2, 3)
        ),
        *(
            _sig(
                f"Speed{i}",
                3 + i,
                signed=True,
                unit="deg/tick",
                comment=f"mean velocity (degrees per 20 ms tick), servo {i}",
                receiver="MASTER",
            )
            for i in (1, 2, 3)
        ),
        *(
            _sig(
                f"Fin{i}",
                7,
                bit=_bit(wire.STATUS_FINISHED[i - 1]),
                length=1,
                comment=f"Status bit {i - 1}: motion of servo {i} finished",
                receiver="MASTER",
            )
            for i in (1, 2, 3)
        ),
        *(
            _sig(name, 7, bit=_bit(mask), length=1, comment=f"Status bit {_bit(mask)}: {what}",
                 receiver="MASTER")
            for name, mask, what in (
                ("FinOne", wire.STATUS_ONE_FINISHED, "one motion finished"),
                ("FinAll", wire.STATUS_ALL_FINISHED, "all motions finished"),
                ("Deadline", wire.STATUS_DEADLINE, "deadline violated"),
                ("Calib", wire.STATUS_CALIB, "calibration complete"),
                ("PWM", wire.STATUS_PWM, "PWM on"),
            )
        ),
    ]
    sen2 = [
        *_sflags("MASTER"),
        _sig("LawStopped", 0, bit=_bit(cf.SFLAGS2_LAW), length=1, receiver="MASTER",
             comment="SFlags bit 2: a control law of this Slave was stopped (docs/controllers.md)"),
        *(
            _sig(
                f"Curr{i}",
                i,
                maximum=cf.CURRENT_MAX,
                unit="%",
                comment=f"current 0..100, servo {i}",
                receiver="MASTER",
            )
            for i in (1, 2, 3)
        ),
        *(_imu_signals() if k == IMU_SCU else (
            _sig(name, 4 + i, unit="count", receiver="MASTER",
                 comment=f"Data{i + 1}: {where} foot force sensor (seed 000 table 12), 8-bit ADC counts; "
                 "0 on boards without a foot")
            for i, (name, where) in enumerate(FORCE_NAMES.items())
        )),
    ]
    a1, a2 = cf.ACTUATION_IDS[k]
    s1, s2 = cf.SENSOR_IDS[k]
    section = SECTIONS[k]
    return [
        Message(
            a1,
            f"Actuation1_S{k}",
            8,
            act1,
            senders=["MASTER"],
            cycle_time=CYCLE_MS,
            comment=f"Actuation 1 (index 0), Master -> slave {k} ({section})",
        ),
        Message(
            a2,
            f"Actuation2_S{k}",
            8,
            act2,
            senders=["MASTER"],
            cycle_time=CYCLE_MS,
            comment=f"Actuation 2 (index 1), Master -> slave {k} ({section})",
        ),
        Message(
            s1,
            f"Sensors1_S{k}",
            8,
            sen1,
            senders=[scu],
            cycle_time=CYCLE_MS,
            comment=f"Sensors 1 (index 0), slave {k} ({section}) -> Master",
        ),
        Message(
            s2,
            f"Sensors2_S{k}",
            8,
            sen2,
            senders=[scu],
            cycle_time=CYCLE_MS,
            comment=f"Sensors 2 (index 1), slave {k} ({section}) -> Master",
        ),
    ]


def build_database() -> Database:
    """The whole DBC as a cantools database."""
    nodes = [Node("MASTER", comment="Master unit (address 0): RS-232 <-> CAN distributer")]
    nodes += [
        Node(f"SCU{k}", comment=f"Slave {k}: {SECTIONS[k]} (address {k}, {SCU_NAMES[k]})")
        for k in SCUS
    ]
    messages = [m for k in SCUS for m in messages_for(k)]
    return Database(messages=messages, nodes=nodes, version="1.0")


def dbc_text() -> str:
    """The DBC file content this script writes."""
    return build_database().as_dbc_string().replace("\r\n", "\n")  # LF: clean git diffs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--check", action="store_true", help="compare with the shipped file instead of writing"
    )
    parser.add_argument("--out", type=Path, default=DBC_PATH, help=f"output file (default {DBC_PATH})")
    args = parser.parse_args(argv)
    text = dbc_text()
    if args.check:
        current = args.out.read_bytes().decode("utf-8") if args.out.exists() else ""
        if current != text:
            print(f"{args.out} is out of date: run scripts/make_dbc.py", file=sys.stderr)
            return 1
        print(f"{args.out} is up to date")
        return 0
    args.out.write_bytes(text.encode("utf-8"))
    print(f"wrote {args.out} ({len(build_database().messages)} messages)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
