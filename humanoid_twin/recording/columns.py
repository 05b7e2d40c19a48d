"""What a twin recording holds, as one declarative table of scalar columns.

Each :class:`Column` says what is recorded (``names``: one series per value), where (``path``: the
rerun entity), in which unit, with which colours, and how it is sampled (``read``: a function of
the :class:`Tick`, returning ``len(names)`` floats). The recorder derives everything from this
one table: the static series styles, the buffer layout (one block of buffer columns per
``Column``, in table order), the per-tick row and the ``send_columns`` batches. Adding a series is
adding one ``Column``; nothing else has to be kept in the same order.

The readers only read: Slave databases and firmware state, Master and bus counters, and the
plant's ground truth (one ``truth()`` per tick, shared through the :class:`Tick`). They never
call the plant's sensor-reading methods (those draw noise), so a recorded run is the same run
as an unrecorded one. docs/recording.md lists the table.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import FOOT_OF_SCU, N_SERVOS, PWM_PERIOD_US, SERVO_JOINTS
from humanoid_twin.plant import SERVO_SIGN
from humanoid_twin.recording.paths import (
    CAN,
    MASTER,
    POSITION_SERIES,
    ROBOT,
    SENSOR_NAMES,
    SERIAL,
    scu_path,
    servo_path,
)

__all__ = ["Column", "Tick", "twin_columns", "RGB"]

RGB = tuple[int, int, int]

# Colours of the series, the same meaning everywhere in the viewer.
GREY: RGB = (120, 120, 120)
BLUE: RGB = (31, 119, 180)
PURPLE: RGB = (148, 103, 189)
ORANGE: RGB = (255, 127, 14)
GREEN: RGB = (44, 160, 44)
RED: RGB = (214, 39, 40)
POSITION_COLOURS: tuple[RGB, ...] = (GREY, BLUE, PURPLE, ORANGE, GREEN)   # POSITION_SERIES order
SENSOR_COLOURS: tuple[RGB, ...] = (RED, BLUE, ORANGE, GREEN)               # SENSOR_NAMES order

# Master.stats() keys with these prefixes share one entity (one series per key): master/can, ...
_MASTER_GROUPS = ("serial_frames_", "serial_bytes_", "can_")
_NAN = math.nan
# Slow counters and flags (cumulative counts, PWM/calibrated, controller state) are written every
# 5th sample (10 Hz at the default 20 ms): they change rarely, and a per-tick copy only costs file.
COUNTER_EVERY = 5


@dataclass(frozen=True)
class Column:
    """One ``Scalars`` entity of the recording and how to sample it.

    ``path``: entity path; ``names``: the series (one value each per tick); ``unit``: of every
    value; ``read(tick)``: the values now, ``len(names)`` floats; ``colors``: one per series or
    None (rerun's palette); ``sparse``: NaN means "no value this tick" (a gap, width 1 only);
    ``every``: read and written every ``every``-th sample only (slow counters and flags,
    COUNTER_EVERY).
    """

    path: str
    names: tuple[str, ...]
    unit: str
    read: Callable[[Tick], Sequence[float]]
    colors: tuple[RGB, ...] | None = None
    sparse: bool = False
    every: int = 1

    def __post_init__(self) -> None:
        if self.every < 1:
            raise ValueError(f"column {self.path!r}: every must be >= 1, got {self.every!r}")

    @property
    def width(self) -> int:
        return len(self.names)


class Tick:
    """What every reader of one sample shares: the time, the ground truth (read once), the
    true servo angles and their finite-difference speed, and the per-tick rates' bases."""

    __slots__ = ("twin", "now_us", "dt_us", "truth", "true_deg", "true_vel", "per_s")

    def __init__(self, twin: Any) -> None:
        self.twin = twin
        self.now_us = twin.clock.now_us
        self.dt_us = 0
        self.truth: Any = None
        self.true_deg: dict[tuple[int, int], float] = {}
        self.true_vel: dict[tuple[int, int], float] = {}
        self.per_s = 0.0


def _finite(x: float) -> float:
    return x if math.isfinite(x) else _NAN


def _servo_columns(scu: int, slave: Any) -> list[Column]:
    cols: list[Column] = []
    for i in range(N_SERVOS):
        sp = servo_path(scu, i)
        key = (scu, i)

        def position(t: Tick, slv: Any = slave, i: int = i, key: tuple[int, int] = key) -> Sequence[float]:
            return (slv.actuators.servo[i].ref, slv.traj.position[i], slv.commanded[i],
                    slv.sensors.servo[i].pos, t.true_deg[key])

        def velocity(t: Tick, slv: Any = slave, i: int = i, key: tuple[int, int] = key) -> Sequence[float]:
            return (slv.sensors.servo[i].vel, t.true_vel[key])

        def current(t: Tick, slv: Any = slave, i: int = i) -> Sequence[float]:
            return (slv.sensors.servo[i].current,)

        cols += [
            Column(f"{sp}/position", POSITION_SERIES, "deg (servo frame)", position, POSITION_COLOURS),
            Column(f"{sp}/velocity", ("measured", "true"), "deg per PWM period", velocity, (ORANGE, GREEN)),
            Column(f"{sp}/current", (f"{SERVO_JOINTS[scu][i]} ({i + 1})",), "ADC 0..100", current),
        ]
    return cols


def _board_columns(scu: int, slave: Any) -> list[Column]:
    base = scu_path(scu)

    def status(t: Tick, slv: Any = slave) -> Sequence[float]:
        st = slv.sensors.sysStatus
        return (st.pwm, st.calib)

    cols = [
        *_servo_columns(scu, slave),
        Column(f"{base}/status", ("pwm", "calibrated"), "flag", status, every=COUNTER_EVERY),
        Column(f"{base}/deadline_violations", ("deadline violations",), "count",
               lambda t, slv=slave: (slv.deadline_violations,), every=COUNTER_EVERY),
    ]
    foot = FOOT_OF_SCU.get(scu)
    if foot is None:
        return cols

    def cop(axis: int, who: str) -> Callable[[Tick], Sequence[float]]:
        if who == "firmware":
            def read(t: Tick, slv: Any = slave) -> Sequence[float]:
                if not slv.cop_loaded:
                    return (_NAN,)
                return (slv.cop_x if axis == 0 else slv.cop_y,)
        else:
            def read(t: Tick) -> Sequence[float]:
                c = t.truth.foot_cop_mm[foot]
                return (_NAN if c is None else c[axis],)
        return read

    cols += [
        Column(f"{base}/force/adc", SENSOR_NAMES, "8-bit ADC", lambda t, slv=slave: slv.sensors.special,
               SENSOR_COLOURS),
        Column(f"{base}/force/newton", SENSOR_NAMES, "N",
               lambda t: t.truth.pad_forces_n[foot].tolist(), SENSOR_COLOURS),
    ]
    for a, axis in enumerate(("x", "y")):
        cols += [
            Column(f"{base}/cop/{axis}/firmware", ("firmware",), "mm", cop(a, "firmware"), (ORANGE,), True),
            Column(f"{base}/cop/{axis}/truth", ("truth",), "mm", cop(a, "truth"), (GREEN,), True),
        ]
    return cols


def _robot_columns() -> list[Column]:
    return [
        Column(f"{ROBOT}/trunk_tilt_deg", ("trunk tilt",), "deg", lambda t: (t.truth.trunk_tilt_deg,)),
        Column(f"{ROBOT}/com_height_mm", ("CoM height",), "mm", lambda t: (t.truth.com[2] * 1000.0,)),
        Column(f"{ROBOT}/cop_margin_mm", ("CoP margin",), "mm",
               lambda t: (_finite(t.truth.cop_margin_mm),), sparse=True),
        Column(f"{ROBOT}/fell", ("fell",), "flag", lambda t: (t.truth.fell,), (RED,)),
        Column(f"{ROBOT}/total_force_n", ("total normal force",), "N",
               lambda t: (t.truth.total_normal_force_n,)),
        Column(f"{ROBOT}/platform_tilt_deg", ("platform tilt",), "deg", lambda t: (t.twin.plant.tilt_deg,)),
    ]


class _BusRates:
    """CAN frames/s and bus load over the last tick (keeps the previous counters)."""

    def __init__(self, twin: Any) -> None:
        self.net = twin.network
        self.frames = self.net.frames_sent
        self.busy = getattr(self.net, "busy_us", 0)

    def read(self, t: Tick) -> Sequence[float]:
        frames = self.net.frames_sent
        busy = getattr(self.net, "busy_us", 0)
        rate = (frames - self.frames) * t.per_s
        load = 100.0 * (busy - self.busy) / t.dt_us if t.dt_us > 0 else 0.0
        self.frames, self.busy = frames, busy
        return (rate, load)


def _bus_columns(twin: Any) -> list[Column]:
    net = twin.network
    ctl = twin.master.controller
    link = twin.link
    rates = _BusRates(twin)
    last = {"rate": (0.0, 0.0)}

    def frames_per_s(t: Tick) -> Sequence[float]:
        last["rate"] = rates.read(t)
        return (last["rate"][0],)

    return [
        Column(f"{CAN}/frames", ("frames",), "count", lambda t: (net.frames_sent,), every=COUNTER_EVERY),
        Column(f"{CAN}/frames_per_s", ("frames/s",), "1/s", frames_per_s),
        Column(f"{CAN}/load_percent", ("bus load",), "%", lambda t: (last["rate"][1],)),
        Column(f"{CAN}/error_frames", ("error frames",), "count", lambda t: (net.error_frames,), (RED,),
               every=COUNTER_EVERY),
        Column(f"{CAN}/frames_dropped", ("frames dropped",), "count",
               lambda t: (net.frames_dropped,), (ORANGE,), every=COUNTER_EVERY),
        Column(f"{CAN}/master_controller", ("state (0 active, 1 passive, 2 off)", "TEC", "REC"),
               "code / count", lambda t: (ctl.error_state_code, ctl.tec, ctl.rec), every=COUNTER_EVERY),
        Column(f"{SERIAL}/bytes", ("to device", "to host"), "bytes",
               lambda t: (link.bytes_to_device, link.bytes_to_host), every=COUNTER_EVERY),
    ]


def master_groups(twin: Any) -> list[tuple[str, list[str]]]:
    """The ``master/...`` entities and the numeric ``Master.stats()`` keys each plots."""
    groups: list[tuple[str, list[str]]] = []
    for k, v in twin.master.stats().items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        group = next((g for g in _MASTER_GROUPS if k.startswith(g)), k)
        path = f"{MASTER}/{group.rstrip('_')}"
        for p, keys in groups:
            if p == path:
                keys.append(k)
                break
        else:
            groups.append((path, [k]))
    return groups


def _master_columns(twin: Any, groups: list[tuple[str, list[str]]]) -> list[Column]:
    master = twin.master
    cache: dict[str, Any] = {"at": None, "stats": {}}

    def stats(t: Tick) -> dict[str, Any]:
        if cache["at"] != t.now_us:          # one Master.stats() per tick for all its columns
            cache["at"], cache["stats"] = t.now_us, master.stats()
        return cache["stats"]

    return [
        Column(path, tuple(keys), "count", lambda t, keys=tuple(keys): [stats(t).get(k, _NAN) for k in keys],
               every=COUNTER_EVERY)
        for path, keys in groups
    ]


def twin_columns(twin: Any, scus: Sequence[int]) -> list[Column]:
    """The recording's column table for ``twin`` (boards ``scus``), in recording order."""
    cols: list[Column] = []
    for scu in scus:
        cols += _board_columns(scu, twin.slaves[scu])
    cols += _robot_columns()
    cols += _bus_columns(twin)
    cols += _master_columns(twin, master_groups(twin))
    return cols


def servo_signs(twin: Any, scus: Sequence[int]) -> list[tuple[tuple[int, int], str, int]]:
    """((scu, servo), joint, sign) for every recorded servo: the true shaft angle in the servo
    frame is ``sign * truth.joint_angles_deg[joint]`` (checked against the plant's own
    ``servo_angle_deg`` here, once)."""
    plant = twin.plant
    truth = plant.truth()
    out = []
    for scu in scus:
        for i in range(N_SERVOS):
            joint = SERVO_JOINTS[scu][i]
            sign = SERVO_SIGN[joint]
            if abs(sign * truth.joint_angles_deg[joint] - plant.servo_angle_deg(scu, i)) > 1e-9:
                raise ValueError(f"plant servo sign table disagrees with servo_angle_deg for {joint}")
            out.append(((scu, i), joint, sign))
    return out


def start_tick(twin: Any, prev: Tick | None, signs: Sequence[tuple[tuple[int, int], str, int]]) -> Tick:
    """The shared state of a sample taken now (``prev``: the previous sample's, for rates)."""
    t = Tick(twin)
    t.truth = truth = twin.plant.truth()
    t.dt_us = t.now_us - prev.now_us if prev is not None else 0
    per_tick = PWM_PERIOD_US / t.dt_us if t.dt_us > 0 else 0.0
    t.per_s = US_PER_S / t.dt_us if t.dt_us > 0 else 0.0
    joints = truth.joint_angles_deg
    for key, joint, sign in signs:
        true = sign * joints[joint]
        t.true_deg[key] = true
        t.true_vel[key] = (true - prev.true_deg[key]) * per_tick if prev is not None else 0.0
    return t
