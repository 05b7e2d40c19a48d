"""What a twin recording holds, as one declarative table of scalar columns.

Each :class:`Column` says what is recorded (``names``: one series per value), where (``path``: the
rerun entity), in which unit, with which colours, and how it is sampled (``read``: a function of
the :class:`Tick`, returning ``len(names)`` floats). The recorder derives everything from this
one table: the static series styles, the buffer layout (one block of buffer columns per
``Column``), the per-tick row and the ``send_columns`` batches. Adding a series is adding one
``Column``; nothing else has to be kept in the same order.

A :class:`ColumnGroup` reads several consecutive columns of the table in one call (a board's
servos, a foot, the robot's balance): the recorder calls its ``read`` once per row for all of
them, each of its columns' own ``read`` takes its slice of it.

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
from humanoid_twin.hardware import (
    FOOT_OF_SCU,
    IMU_SCU,
    N_SERVOS,
    PWM_PERIOD_US,
    SERVO_JOINTS,
    imu_from_counts,
)
from humanoid_twin.plant import FOOT_BODIES, SERVO_SIGN
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

__all__ = ["Column", "ColumnGroup", "Tick", "twin_columns", "RGB"]

RGB = tuple[int, int, int]

# Colours of the series, the same meaning everywhere in the viewer.
GREY: RGB = (120, 120, 120)
BLUE: RGB = (31, 119, 180)
PURPLE: RGB = (148, 103, 189)
ORANGE: RGB = (255, 127, 14)
GREEN: RGB = (44, 160, 44)
RED: RGB = (214, 39, 40)
PINK: RGB = (227, 119, 194)
CYAN: RGB = (23, 190, 207)
YELLOW: RGB = (230, 230, 70)
TAN: RGB = (196, 156, 148)
NEUTRAL: RGB = (200, 205, 215)       # a plot of one quantity (its title names it)
# orange is always a firmware value and green the ground truth (joint measured/true, CoP firmware/
# truth, velocities), in the plots and in the foot views beside them; no other series uses them
POSITION_COLOURS: tuple[RGB, ...] = (GREY, BLUE, PURPLE, ORANGE, GREEN)   # POSITION_SERIES order
SENSOR_COLOURS: tuple[RGB, ...] = (RED, CYAN, PINK, YELLOW)               # SENSOR_NAMES order (FL FR RL RR)
CURRENT_COLOURS: tuple[RGB, ...] = (BLUE, PURPLE, TAN)                    # servo 1, 2, 3 of a board
COUNTER_COLOURS: tuple[RGB, ...] = (BLUE, PURPLE, RED, TAN)               # several counts in one plot

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


class ColumnGroup:
    """Consecutive columns of the table read together: ``read(tick)`` returns the values of all
    of them, flat, in the order they were added with :meth:`column`; all share one ``every``.

    The recorder calls ``read`` once per row for the whole group (one Python call instead of
    one per column); each column's own ``read`` calls it and takes its slice (for a reader of
    that one column alone).
    """

    __slots__ = ("read", "every", "columns", "width")

    def __init__(self, read: Callable[[Tick], Sequence[float]], every: int = 1) -> None:
        self.read = read
        self.every = every
        self.columns: list[Column] = []
        self.width = 0

    def column(self, path: str, names: tuple[str, ...], unit: str, colors: tuple[RGB, ...] | None = None,
               sparse: bool = False) -> Column:
        """Add the group's next column (its values follow the previous column's in ``read``)."""
        start = self.width
        self.width += len(names)
        col = Column(path, names, unit, _GroupSlice(self, start, self.width), colors, sparse, self.every)
        self.columns.append(col)
        return col


class _GroupSlice:
    """One column's ``read`` in a :class:`ColumnGroup`: its slice of the group's values."""

    __slots__ = ("group", "start", "stop")

    def __init__(self, group: ColumnGroup, start: int, stop: int) -> None:
        self.group = group
        self.start = start
        self.stop = stop

    def __call__(self, t: Tick) -> Sequence[float]:
        return list(self.group.read(t))[self.start:self.stop]


def group_reader(cols: Sequence[Column], k: int) -> tuple[Callable[[Tick], Sequence[float]], int]:
    """The reader of ``cols[k:]``'s first values: the whole group's ``read`` when ``cols[k]`` opens
    a :class:`ColumnGroup` whose columns all follow it in ``cols``, else ``cols[k].read``; and how
    many columns of ``cols`` it reads."""
    r = cols[k].read
    if isinstance(r, _GroupSlice) and r.start == 0:
        group = r.group
        m = len(group.columns)
        if len(cols) - k >= m and all(a is b for a, b in zip(cols[k:k + m], group.columns, strict=True)):
            return group.read, m
    return r, 1


class Tick:
    """What every reader of one sample shares: the time, the ground truth (read once), the
    true servo angles and their finite-difference speed (``true_deg`` / ``true_vel``, keyed by
    ``(scu, servo)``; as lists in :func:`servo_keys` order: ``true`` / ``vel``), and the per-tick
    rates' bases."""

    __slots__ = ("twin", "now_us", "dt_us", "truth", "true", "vel", "per_s", "_signs", "_dicts")

    def __init__(self, twin: Any) -> None:
        self.twin = twin
        self.now_us = twin.clock.now_us
        self.dt_us = 0
        self.truth: Any = None
        self.true: list[float] = []
        self.vel: list[float] = []
        self.per_s = 0.0
        self._signs: Sequence[tuple[tuple[int, int], str, int]] = ()
        self._dicts: tuple[dict[tuple[int, int], float], dict[tuple[int, int], float]] | None = None

    def _by_key(self) -> tuple[dict[tuple[int, int], float], dict[tuple[int, int], float]]:
        if self._dicts is None:
            keys = [key for key, _, _ in self._signs]
            self._dicts = (dict(zip(keys, self.true, strict=True)), dict(zip(keys, self.vel, strict=True)))
        return self._dicts

    @property
    def true_deg(self) -> dict[tuple[int, int], float]:
        """True shaft angle (servo frame, degrees) of each recorded servo, by ``(scu, servo)``."""
        return self._by_key()[0]

    @property
    def true_vel(self) -> dict[tuple[int, int], float]:
        """Its change since the previous sample, per PWM period (0 at the first sample)."""
        return self._by_key()[1]


def _finite(x: float) -> float:
    return x if math.isfinite(x) else _NAN


def _board_columns(scu: int, slave: Any, first: int) -> list[Column]:
    """The columns of board ``scu``; ``first``: its servo 0's place in the tick's ``true`` list."""
    base = scu_path(scu)

    def servos(t: Tick) -> Sequence[float]:
        act = slave.actuators.servo
        traj = slave.traj.position
        commanded = slave.commanded
        sensed = slave.sensors.servo
        true = t.true
        vel = t.vel
        out: list[float] = []
        for i in range(N_SERVOS):
            s = sensed[i]
            k = first + i
            out += (act[i].ref, traj[i], commanded[i], s.pos, true[k],   # position (POSITION_SERIES)
                    s.vel, vel[k],                                       # velocity
                    s.current)                                           # current
        return out

    servo = ColumnGroup(servos)
    for i in range(N_SERVOS):
        sp = servo_path(scu, i)
        servo.column(f"{sp}/position", POSITION_SERIES, "deg (servo frame)", POSITION_COLOURS)
        servo.column(f"{sp}/velocity", ("measured", "true"), "deg per PWM period", (ORANGE, GREEN))
        servo.column(f"{sp}/current", (f"{SERVO_JOINTS[scu][i]} ({i + 1})",), "ADC 0..100",
                     (CURRENT_COLOURS[i],))

    def flags(t: Tick) -> Sequence[float]:
        st = slave.sensors.sysStatus
        return (st.pwm, st.calib, slave.deadline_violations)

    counters = ColumnGroup(flags, every=COUNTER_EVERY)
    counters.column(f"{base}/status", ("pwm", "calibrated"), "flag", (BLUE, PURPLE))
    counters.column(f"{base}/deadline_violations", ("deadline violations",), "count", (RED,))
    # the last pass's time at the board's clock (the PIC18 cycle table) against its 20 ms
    budget_ms = PWM_PERIOD_US / 1000.0
    task = Column(f"{base}/task_ms", ("task time", "budget"), "ms",
                  lambda t: (slave.task_us / 1000.0, budget_ms), (BLUE, RED))
    cols = [*servo.columns, *counters.columns, task]
    if scu == IMU_SCU:
        cols += _imu_columns(base, slave)
    foot = FOOT_OF_SCU.get(scu)
    if foot is None:
        return cols

    f = FOOT_BODIES.index(foot)

    def feet(t: Tick) -> Sequence[float]:
        truth = t.truth.plain()
        if slave.cop_loaded:
            fx, fy = slave.cop_x, slave.cop_y
        else:
            fx = fy = _NAN
        c = truth.foot_cop_mm[f]
        tx, ty = (_NAN, _NAN) if c is None else c
        return [*slave.sensors.special, *truth.pad_forces_n[4 * f:4 * f + 4], fx, tx, fy, ty]

    group = ColumnGroup(feet)
    group.column(f"{base}/force/adc", SENSOR_NAMES, "8-bit ADC", SENSOR_COLOURS)
    group.column(f"{base}/force/newton", SENSOR_NAMES, "N", SENSOR_COLOURS)
    for axis in ("x", "y"):
        group.column(f"{base}/cop/{axis}/firmware", ("firmware",), "mm", (ORANGE,), True)
        group.column(f"{base}/cop/{axis}/truth", ("truth",), "mm", (GREEN,), True)
    return cols + group.columns


def _imu_columns(base: str, slave: Any) -> list[Column]:
    """The body board's inclinometer and gyroscope (its sensor database, decoded) beside the
    trunk's true attitude and rates (docs/firmware.md, "Trunk inertial sensors")."""
    def imu(t: Tick) -> Sequence[float]:
        m = imu_from_counts(slave.sensors.special)
        true = t.twin.plant.trunk_attitude_deg()
        return (m[0], true[0], m[1], true[1], m[2], true[2], m[3], true[3])

    group = ColumnGroup(imu)
    for what, unit in (("roll", "deg"), ("pitch", "deg"), ("roll_rate", "deg/s"), ("pitch_rate", "deg/s")):
        sensor = "gyroscope" if what.endswith("rate") else "inclinometer"
        group.column(f"{base}/imu/{what}", (sensor, "truth"), unit, (ORANGE, GREEN))
    return group.columns


def _robot_columns() -> list[Column]:
    def balance(t: Tick) -> Sequence[float]:
        truth = t.truth
        return (truth.trunk_tilt_deg, truth.com[2] * 1000.0, _finite(truth.cop_margin_mm), truth.fell,
                truth.total_normal_force_n, t.twin.plant.tilt_deg)

    group = ColumnGroup(balance)
    group.column(f"{ROBOT}/trunk_tilt_deg", ("trunk tilt",), "deg", (NEUTRAL,))
    group.column(f"{ROBOT}/com_height_mm", ("CoM height",), "mm", (NEUTRAL,))
    group.column(f"{ROBOT}/cop_margin_mm", ("CoP margin",), "mm", (NEUTRAL,), sparse=True)
    group.column(f"{ROBOT}/fell", ("fell",), "flag", (RED,))
    group.column(f"{ROBOT}/total_force_n", ("total normal force",), "N", (NEUTRAL,))
    group.column(f"{ROBOT}/platform_tilt_deg", ("platform tilt",), "deg", (NEUTRAL,))
    return group.columns


class _BusRates:
    """CAN frames/s and bus load over the last tick (keeps the previous counters)."""

    def __init__(self, twin: Any) -> None:
        self.net = twin.network
        self.frames = self.net.frames_sent
        self.busy = getattr(self.net, "busy_us", 0)
        self.at: int | None = None
        self.last: tuple[float, float] = (0.0, 0.0)

    def read(self, t: Tick) -> Sequence[float]:
        if t.now_us == self.at:        # read again in the same tick (a column's own read)
            return self.last
        frames = self.net.frames_sent
        busy = getattr(self.net, "busy_us", 0)
        rate = (frames - self.frames) * t.per_s
        load = 100.0 * (busy - self.busy) / t.dt_us if t.dt_us > 0 else 0.0
        self.frames, self.busy = frames, busy
        self.at, self.last = t.now_us, (rate, load)
        return self.last


def _bus_columns(twin: Any) -> list[Column]:
    net = twin.network
    ctl = twin.master.controller
    link = twin.link
    rates = ColumnGroup(_BusRates(twin).read)
    counters = ColumnGroup(lambda t: (net.error_frames, net.frames_dropped, ctl.error_state_code, ctl.tec,
                                      ctl.rec, link.bytes_to_device, link.bytes_to_host), every=COUNTER_EVERY)
    return [
        Column(f"{CAN}/frames", ("frames",), "count", lambda t: (net.frames_sent,), every=COUNTER_EVERY),
        rates.column(f"{CAN}/frames_per_s", ("frames/s",), "1/s", (NEUTRAL,)),
        rates.column(f"{CAN}/load_percent", ("bus load",), "%", (NEUTRAL,)),
        counters.column(f"{CAN}/error_frames", ("error frames",), "count", (RED,)),
        counters.column(f"{CAN}/frames_dropped", ("frames dropped",), "count", (TAN,)),
        counters.column(f"{CAN}/master_controller", ("state (0 active, 1 passive, 2 off)", "TEC", "REC"),
                        "code / count", COUNTER_COLOURS[:3]),
        counters.column(f"{SERIAL}/bytes", ("to device", "to host"), "bytes", COUNTER_COLOURS[:2]),
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
    keys = [k for _, ks in groups for k in ks]

    def stats(t: Tick) -> Sequence[float]:          # one Master.stats() per row for all its columns
        st = master.stats()
        return [st.get(k, _NAN) for k in keys]

    group = ColumnGroup(stats, every=COUNTER_EVERY)
    return [group.column(path, tuple(ks), "count",
                         tuple(COUNTER_COLOURS[i % len(COUNTER_COLOURS)] for i in range(len(ks))))
            for path, ks in groups]


def twin_columns(twin: Any, scus: Sequence[int]) -> list[Column]:
    """The recording's column table for ``twin`` (boards ``scus``), in recording order."""
    cols: list[Column] = []
    first = {key: k for k, key in enumerate(servo_keys(scus))}
    for scu in scus:
        cols += _board_columns(scu, twin.slaves[scu], first[(scu, 0)])
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
    for scu, i in servo_keys(scus):
        joint = SERVO_JOINTS[scu][i]
        sign = SERVO_SIGN[joint]
        if abs(sign * truth.joint_angles_deg[joint] - plant.servo_angle_deg(scu, i)) > 1e-9:
            raise ValueError(f"plant servo sign table disagrees with servo_angle_deg for {joint}")
        out.append(((scu, i), joint, sign))
    return out


def servo_keys(scus: Sequence[int]) -> list[tuple[int, int]]:
    """``(scu, servo)`` of every recorded servo, in the order of the tick's ``true`` / ``vel``."""
    return [(scu, i) for scu in scus for i in range(N_SERVOS)]


def start_tick(twin: Any, prev: Tick | None, signs: Sequence[tuple[tuple[int, int], str, int]]) -> Tick:
    """The shared state of a sample taken now (``prev``: the previous sample's, for rates)."""
    t = Tick(twin)
    t.truth = truth = twin.plant.truth()
    t._signs = signs
    joints = truth.joint_angles_deg
    t.true = true = [sign * joints[joint] for _, joint, sign in signs]
    if prev is None:
        t.vel = [0.0] * len(true)
        return t
    t.dt_us = dt = t.now_us - prev.now_us
    per_tick = PWM_PERIOD_US / dt if dt > 0 else 0.0
    t.per_s = US_PER_S / dt if dt > 0 else 0.0
    t.vel = [(deg - before) * per_tick for deg, before in zip(true, prev.true, strict=True)]
    return t
