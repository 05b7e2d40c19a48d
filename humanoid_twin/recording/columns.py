"""What a twin recording holds, as one declarative table of scalar columns.

Each :class:`Column` says what is recorded (``names``: one series per value), where (``path``: the
rerun entity), in which unit, with which colours, and how it is sampled (``read``: a function of
the :class:`Tick`, returning ``len(names)`` floats). The recorder derives everything from this
one table: the static series styles, the buffer layout (one block of buffer columns per
``Column``), the per-tick row and the ``send_columns`` batches. Adding a series is adding one
``Column``; nothing else has to be kept in the same order.

A :class:`ColumnGroup` reads several consecutive columns of the table in one call (the boards'
servos and feet, the robot's balance): the recorder calls its ``read`` once per row for all of
them, each of its columns' own ``read`` takes its slice of it. A group with a ``finish`` reads
only raw values per row (a board's firmware values and true joint angles, the bus counters) and
derives its columns from them in numpy, a chunk of rows at a time (the true servo angles and
speeds, the bus rates): the same numbers, computed once per chunk instead of once per row.

The readers only read: Slave databases and firmware state, Master and bus counters, and the
plant's ground truth (one ``truth()`` per tick, shared through the :class:`Tick`). They never
call the plant's sensor-reading methods (those draw noise), so a recorded run is the same run
as an unrecorded one. docs/recording.md lists the table.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from operator import itemgetter
from typing import TYPE_CHECKING, Any

import numpy as np

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

if TYPE_CHECKING:
    from humanoid_twin.plant.truth import GroundTruth
    from humanoid_twin.slave.slave import Slave
    from humanoid_twin.twin import Twin

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
# A plot of one quantity (its title names it) gets a bright colour of its own, none of the
# colours above: in light grey (200, 205, 215) its curve read as one more grid line beside the
# white time cursor, and every such plot looked the same
SKY: RGB = (86, 180, 233)
GOLD: RGB = (235, 185, 40)
VIOLET: RGB = (175, 125, 255)
TEAL: RGB = (40, 200, 165)
ROSE: RGB = (245, 105, 150)
# every series' line width (points): rerun's default, 0.75, was a hairline on a 1600-point window
SERIES_WIDTH = 1.5
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


# ``finish(t_us, raw, state) -> (values, state)``: a batch group's columns for rows of raw values
# taken at times ``t_us`` (int64, increasing), ``state``: what the previous call left (None at the
# first rows)
Finish = Callable[[np.ndarray, np.ndarray, Any], tuple[np.ndarray, Any]]


class ColumnGroup:
    """Consecutive columns of the table read together: ``read(tick)`` returns the values of all
    of them, flat, in the order they were added with :meth:`column`; all share one ``every``.

    The recorder calls ``read`` once per row for the whole group (one Python call instead of
    one per column); each column's own ``read`` calls it and takes its slice (for a reader of
    that one column alone).

    ``ints``: how many of the first values ``read`` returns are always ``int`` (or ``bool``):
    the recorder stores those as 64-bit integers (cheaper per row than a float from an int).

    With ``finish`` (a batch group), ``read(tick)`` returns ``raw_width`` raw values instead, and
    ``finish(t_us, raw, state)`` derives the columns' values from rows of them (numpy arrays:
    the rows' times and raw values), returning them ``(rows, width)`` and the state the next
    rows continue from (None before the first row): differences between rows (speeds, rates)
    are computed a chunk at a time.
    """

    __slots__ = ("read", "every", "columns", "width", "finish", "raw_width", "ints")

    def __init__(self, read: Callable[[Tick], Sequence[float]], every: int = 1, *,
                 finish: Finish | None = None, raw_width: int = 0, ints: int = 0) -> None:
        self.read = read
        self.every = every
        self.columns: list[Column] = []
        self.width = 0
        self.finish = finish
        self.raw_width = raw_width
        self.ints = ints

    def column(self, path: str, names: tuple[str, ...], unit: str, colors: tuple[RGB, ...] | None = None,
               sparse: bool = False) -> Column:
        """Add the group's next column (its values follow the previous column's in ``read``)."""
        start = self.width
        self.width += len(names)
        col = Column(path, names, unit, _GroupSlice(self, start, self.width), colors, sparse, self.every)
        self.columns.append(col)
        return col

    def values(self, t: Tick) -> list[float]:
        """The values of all the group's columns at tick ``t`` (a batch group: from the raw
        values the recorder took at ``t`` and at the sample before, as in the recording)."""
        if self.finish is None:
            return list(self.read(t))
        raw = t.raw.get(self)
        if raw is None:
            raw = self.read(t)
        prev = t.prev
        state = None
        if prev is not None and self in prev.raw:     # the state the sample before left
            _, state = self.finish(np.array([prev.now_us], dtype=np.int64),
                                   np.array([prev.raw[self]], dtype=np.float64), _prev_state(prev, self))
        out, _ = self.finish(np.array([t.now_us], dtype=np.int64), np.array([raw], dtype=np.float64), state)
        return out[0].tolist()


def _prev_state(t: Tick, group: ColumnGroup) -> Any:
    """The state before ``t``'s row of a batch group, from the raw values of the tick before."""
    prev = t.prev
    if prev is None or group not in prev.raw:
        return None
    _, state = group.finish(np.array([prev.now_us], dtype=np.int64),  # type: ignore[misc]  # a batch group has finish
                            np.array([prev.raw[group]], dtype=np.float64), None)
    return state


class _GroupSlice:
    """One column's ``read`` in a :class:`ColumnGroup`: its slice of the group's values."""

    __slots__ = ("group", "start", "stop")

    def __init__(self, group: ColumnGroup, start: int, stop: int) -> None:
        self.group = group
        self.start = start
        self.stop = stop

    def __call__(self, t: Tick) -> Sequence[float]:
        return self.group.values(t)[self.start:self.stop]


def group_reader(cols: Sequence[Column], k: int) -> tuple[Callable[[Tick], Sequence[float]], int,
                                                         ColumnGroup | None]:
    """The reader of ``cols[k:]``'s first values: the whole group's ``read`` when ``cols[k]`` opens
    a :class:`ColumnGroup` whose columns all follow it in ``cols``, else ``cols[k].read``; how
    many columns of ``cols`` it reads; and the group (None for one column's own ``read``). A
    batch group's columns (``finish``) apart in ``cols`` are a ``ValueError``: they are derived
    together, from one raw block a row."""
    r = cols[k].read
    if isinstance(r, _GroupSlice):
        group = r.group
        m = len(group.columns)
        if r.start == 0 and len(cols) - k >= m and all(
                a is b for a, b in zip(cols[k:k + m], group.columns, strict=True)):
            return group.read, m, group
        if group.finish is not None:
            raise ValueError(f"column {cols[k].path!r}: the columns of a batch group (finish=) must "
                             f"be given together, in the group's order, with one every")
    return r, 1, None


class Tick:
    """What every reader of one sample shares: the time, the ground truth (read once), the
    true servo angles and their finite-difference speed (``true_deg`` / ``true_vel``, keyed by
    ``(scu, servo)``; as lists in :func:`servo_keys` order: ``true`` / ``vel``; computed on
    first read), and the per-tick rates' bases. ``prev``: the sample before (None at the first;
    a tick keeps the one before it only while it is one of the last two), ``raw``: the raw
    values of the batch groups read at this sample (by group)."""

    __slots__ = ("twin", "now_us", "dt_us", "truth", "per_s", "prev", "raw", "_signs", "_true", "_vel",
                 "_dicts")

    def __init__(self, twin: Twin) -> None:
        self.twin = twin
        self.now_us = twin.clock.now_us
        self.dt_us = 0
        self.truth: GroundTruth = None  # type: ignore[assignment]  # sampled by start_tick, before any read
        self.per_s = 0.0
        self.prev: Tick | None = None
        self.raw: dict[ColumnGroup, Sequence[float]] = {}
        self._signs: Sequence[tuple[tuple[int, int], str, int]] = ()
        self._true: list[float] | None = None
        self._vel: list[float] | None = None
        self._dicts: tuple[dict[tuple[int, int], float], dict[tuple[int, int], float]] | None = None

    @property
    def true(self) -> list[float]:
        """True shaft angle (servo frame, degrees) of each recorded servo, :func:`servo_keys` order."""
        if self._true is None:
            joints = self.truth.joint_angles_deg
            self._true = [sign * joints[joint] for _, joint, sign in self._signs]
        return self._true

    @property
    def vel(self) -> list[float]:
        """Their change since the previous sample, per PWM period (0 at the first sample)."""
        if self._vel is None:
            prev = self.prev
            if prev is None:
                self._vel = [0.0] * len(self.true)
            else:
                dt = self.dt_us
                per_tick = PWM_PERIOD_US / dt if dt > 0 else 0.0
                self._vel = [(deg - before) * per_tick
                             for deg, before in zip(self.true, prev.true, strict=True)]
        return self._vel

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


class _Boards:
    """The recorded boards' every-sample columns as one batch group (one read a row for all of
    them): per row, each board's firmware values (reference, trajectory, commanded, measured
    position and speed, current: each for its three servos; the task time), all integers, then
    the boards' other values (the IMU's, the foot's: ``add``) and the true joint angles of every
    board (unsigned, as the truth has them); at chunk time, the recorded layout, with the true
    angles in the servo frame and their finite-difference speed."""

    FIRMWARE = 6 * N_SERVOS + 1          # a board's firmware values a row

    def __init__(self) -> None:
        if N_SERVOS != 3:
            raise RuntimeError(f"the recorder reads a board's 3 servos unrolled, the hardware has {N_SERVOS}")
        self.slaves: list[Any] = []
        self.parts: list[tuple[Callable[[Tick], Sequence[float]], int, int]] = []   # (read, width, out)
        self.joint_names: list[str] = []
        self.signs: list[float] = []
        self.width = 0
        self.joints: Callable[[dict], Sequence[float]] = lambda d: ()    # set by seal()
        self._layout: tuple | None = None
        self._out: list[tuple[int, int]] = []      # each board's first output column and its task's

    def add_board(self, scu: int, slave: Slave) -> None:
        """Board ``scu``'s servos and task time (its columns: the servos' position, velocity and
        current, then the task time's two)."""
        joints = SERVO_JOINTS[scu]
        self.joint_names += joints
        self.signs += [SERVO_SIGN[j] for j in joints]
        self.slaves.append(slave)
        per = len(POSITION_SERIES) + 3
        self._out.append((self.width, self.width + N_SERVOS * per))
        self.width += N_SERVOS * per + 2
        self._layout = None

    def add(self, part: Callable[[Tick], Sequence[float]], width: int) -> None:
        """Values read per row after the firmware's, recorded as read (the last board's columns)."""
        self.parts.append((part, width, self.width))
        self.width += width
        self._layout = None

    @property
    def ints(self) -> int:
        """The integer raw values a row (first): the boards' firmware values."""
        return self.FIRMWARE * len(self.slaves)

    @property
    def raw_width(self) -> int:
        """Raw values a row: the firmware's, the parts', the joints'."""
        return self.ints + sum(w for _, w, _ in self.parts) + len(self.joint_names)

    def read(self, t: Tick) -> list[float]:
        row: list[float] = []
        for slave in self.slaves:
            a0, a1, a2 = slave.actuators.servo          # the board's three servos, unrolled
            s0, s1, s2 = slave.sensors.servo
            row += (a0.ref, a1.ref, a2.ref, *slave.traj.position, *slave.commanded,
                    s0.pos, s1.pos, s2.pos, s0.vel, s1.vel, s2.vel, s0.current, s1.current, s2.current,
                    slave.task_us)
        for part, _, _ in self.parts:
            row += part(t)
        row += self.joints(t.truth.joint_angles_deg)
        return row

    def _index(self) -> tuple:
        """raw -> out: the columns copied as read; the true angles' (servo frame) and their
        speeds'; the task times' (raw us -> ms)."""
        if self._layout is None:
            n = N_SERVOS
            per = len(POSITION_SERIES) + 3
            src: list[int] = []
            dst: list[int] = []
            true_dst: list[int] = []
            task_src: list[int] = []
            task_dst: list[int] = []
            for b, (o, task) in enumerate(self._out):
                r = b * self.FIRMWARE
                for i in range(n):       # raw: ref, traj, commanded, pos, vel, current (n each)
                    s = o + i * per      # out: position (ref traj commanded pos true), velocity
                    src += [r + i, r + n + i, r + 2 * n + i, r + 3 * n + i, r + 4 * n + i, r + 5 * n + i]
                    dst += [s, s + 1, s + 2, s + 3, s + 5, s + 7]    # (measured true), current
                    true_dst.append(s + 4)
                task_src.append(r + 6 * n)
                task_dst.append(task)
            r = self.ints
            for _, width, out in self.parts:
                src += range(r, r + width)
                dst += range(out, out + width)
                r += width
            true_dst_a = np.array(true_dst)
            self._layout = (np.array(src), np.array(dst), r, np.array(self.signs), true_dst_a, true_dst_a + 2,
                            np.array(task_src), np.array(task_dst))
        return self._layout

    def finish(self, t: np.ndarray, raw: np.ndarray, state: Any) -> tuple[np.ndarray, Any]:
        src, dst, joints, signs, true_dst, speed_dst, task_src, task_dst = self._index()
        n = len(t)
        out = np.empty((n, self.width))
        out[:, dst] = raw[:, src]
        true = raw[:, joints:] * signs          # the servo frame
        out[:, true_dst] = true
        # the speed: (true - true before) * PWM period / dt, 0 at the first sample
        t0, before = (t[0], true[0]) if state is None else state
        dt = np.diff(t, prepend=t0)
        per_tick = np.zeros(n)
        np.divide(PWM_PERIOD_US, dt, out=per_tick, where=dt > 0)
        speed = (true - np.vstack([before, true[:-1]])) * per_tick[:, None]
        if state is None:
            speed[0] = 0.0
        out[:, speed_dst] = speed
        out[:, task_dst] = raw[:, task_src] / 1000.0      # the last pass's time, ms
        out[:, task_dst + 1] = PWM_PERIOD_US / 1000.0     # its budget
        return out, (t[-1], true[-1].copy())

    def seal(self, truth: GroundTruth) -> None:
        """The joints' reader, once every board is added, keyed by the names of ``truth``'s own
        joint table (the same keys, found by identity)."""
        keys = {k: k for k in truth.joint_angles_deg}
        self.joints = itemgetter(*[keys.get(j, j) for j in self.joint_names])


def _board_columns(scu: int, slave: Slave, rows: _Boards, group: ColumnGroup) -> list[Column]:
    """The columns of board ``scu``, its every-sample ones added to the boards' batch group
    ``group`` (of ``rows``)."""
    base = scu_path(scu)
    rows.add_board(scu, slave)
    first = len(group.columns)
    for i in range(N_SERVOS):
        sp = servo_path(scu, i)
        group.column(f"{sp}/position", POSITION_SERIES, "deg (servo frame)", POSITION_COLOURS)
        group.column(f"{sp}/velocity", ("measured", "true"), "deg per PWM period", (ORANGE, GREEN))
        group.column(f"{sp}/current", (f"{SERVO_JOINTS[scu][i]} ({i + 1})",), "ADC 0..100",
                     (CURRENT_COLOURS[i],))

    def flags(t: Tick) -> Sequence[float]:
        st = slave.sensors.sysStatus
        return (st.pwm, st.calib, slave.deadline_violations)

    counters = ColumnGroup(flags, every=COUNTER_EVERY, ints=3)
    counters.column(f"{base}/status", ("pwm", "calibrated"), "flag", (BLUE, PURPLE))
    counters.column(f"{base}/deadline_violations", ("deadline violations",), "count", (RED,))
    # the last pass's time at the board's clock (the PIC18 cycle table) against its 20 ms
    # (one group with the servos: read in the same row, their columns follow in the buffer)
    task = group.column(f"{base}/task_ms", ("task time", "budget"), "ms", (BLUE, RED))
    cols = [*group.columns[first:-1], *counters.columns, task]
    if scu == IMU_SCU:
        cols += _imu_columns(base, slave, group, rows)
    foot = FOOT_OF_SCU.get(scu)
    if foot is None:
        return cols

    f = FOOT_BODIES.index(foot)

    def feet(t: Tick) -> Sequence[float]:
        truth = t.truth.plain()
        if slave.cop_loaded:
            fx, fy = slave.cop_x, slave.cop_y
        else:
            fx = fy = _NAN  # type: ignore[assignment]  # NaN when unloaded
        c = truth.foot_cop_mm[f]
        tx, ty = (_NAN, _NAN) if c is None else c
        return [*slave.sensors.special, *truth.pad_forces_n[4 * f:4 * f + 4], fx, tx, fy, ty]

    rows.add(feet, 12)
    first = len(group.columns)
    group.column(f"{base}/force/adc", SENSOR_NAMES, "8-bit ADC", SENSOR_COLOURS)
    group.column(f"{base}/force/newton", SENSOR_NAMES, "N", SENSOR_COLOURS)
    for axis in ("x", "y"):
        group.column(f"{base}/cop/{axis}/firmware", ("firmware",), "mm", (ORANGE,), True)
        group.column(f"{base}/cop/{axis}/truth", ("truth",), "mm", (GREEN,), True)
    return cols + group.columns[first:]


def _imu_columns(base: str, slave: Slave, group: ColumnGroup, rows: _Boards) -> list[Column]:
    """The body board's inclinometer and gyroscope (its sensor database, decoded) beside the
    trunk's true attitude and rates (docs/firmware.md, "Trunk inertial sensors"): read with the
    board's servos (``group``)."""
    def imu(t: Tick) -> Sequence[float]:
        m = imu_from_counts(slave.sensors.special)
        true = t.twin.plant.trunk_attitude_deg()
        return (m[0], true[0], m[1], true[1], m[2], true[2], m[3], true[3])

    rows.add(imu, 8)
    first = len(group.columns)
    for what, unit in (("roll", "deg"), ("pitch", "deg"), ("roll_rate", "deg/s"), ("pitch_rate", "deg/s")):
        sensor = "gyroscope" if what.endswith("rate") else "inclinometer"
        group.column(f"{base}/imu/{what}", (sensor, "truth"), unit, (ORANGE, GREEN))
    return group.columns[first:]


def _robot_columns() -> list[Column]:
    def balance(t: Tick) -> Sequence[float]:
        truth = t.truth
        return (truth.trunk_tilt_deg, truth.com[2] * 1000.0, _finite(truth.cop_margin_mm), truth.fell,
                truth.total_normal_force_n, t.twin.plant.tilt_deg)

    group = ColumnGroup(balance)
    group.column(f"{ROBOT}/trunk_tilt_deg", ("trunk tilt",), "deg", (SKY,))
    group.column(f"{ROBOT}/com_height_mm", ("CoM height",), "mm", (GOLD,))
    group.column(f"{ROBOT}/cop_margin_mm", ("CoP margin",), "mm", (VIOLET,), sparse=True)
    group.column(f"{ROBOT}/fell", ("fell",), "flag", (RED,))
    group.column(f"{ROBOT}/total_force_n", ("total normal force",), "N", (TEAL,))
    group.column(f"{ROBOT}/platform_tilt_deg", ("platform tilt",), "deg", (ROSE,))
    return group.columns


class _BusRates:
    """CAN frames/s and bus load since the sample before, as a batch group: the counters are
    read per row, the rates computed a chunk at a time. A row taken at the same instant as the
    one before repeats its rates (and the next rates run from the first row of that instant)."""

    raw_width = 2

    def __init__(self, twin: Twin) -> None:
        self.net = twin.network

    def read(self, t: Tick) -> Sequence[float]:
        net = self.net
        return (net.frames_sent, getattr(net, "busy_us", 0))

    def finish(self, t: np.ndarray, raw: np.ndarray, state: Any) -> tuple[np.ndarray, Any]:
        if state is None:       # the first row: no rates (0), the next ones run from it
            state = (t[0], raw[0, 0], raw[0, 1], 0.0, 0.0)
        at, frames, busy, rate0, load0 = state
        new = t != np.concatenate(([at], t[:-1]))      # the first row of its instant
        idx = np.flatnonzero(new)
        dt = np.diff(t[idx], prepend=at)
        rate = np.diff(raw[idx, 0], prepend=frames) * (US_PER_S / dt)
        load = 100.0 * np.diff(raw[idx, 1], prepend=busy) / dt
        last = np.full(len(t), -1)                          # each row's instant's first row in idx
        last[idx] = np.arange(len(idx))
        last = np.maximum.accumulate(last) + 1
        out = np.column_stack([np.concatenate(([rate0], rate))[last], np.concatenate(([load0], load))[last]])
        if len(idx):
            k = idx[-1]
            state = (t[k], raw[k, 0], raw[k, 1], rate[-1], load[-1])
        return out, state


def _bus_columns(twin: Twin) -> list[Column]:
    net = twin.network
    ctl = twin.the_master().controller
    link = twin.link
    bus = _BusRates(twin)
    rates = ColumnGroup(bus.read, finish=bus.finish, raw_width=bus.raw_width, ints=bus.raw_width)
    counters = ColumnGroup(lambda t: (net.error_frames, net.frames_dropped, ctl.error_state_code, ctl.tec,
                                      ctl.rec, link.bytes_to_device, link.bytes_to_host), every=COUNTER_EVERY,
                           ints=7)
    return [
        Column(f"{CAN}/frames", ("frames",), "count", lambda t: (net.frames_sent,), every=COUNTER_EVERY),
        rates.column(f"{CAN}/frames_per_s", ("frames/s",), "1/s", (SKY,)),
        rates.column(f"{CAN}/load_percent", ("bus load",), "%", (GOLD,)),
        counters.column(f"{CAN}/error_frames", ("error frames",), "count", (RED,)),
        counters.column(f"{CAN}/frames_dropped", ("frames dropped",), "count", (TAN,)),
        counters.column(f"{CAN}/master_controller", ("state (0 active, 1 passive, 2 off)", "TEC", "REC"),
                        "code / count", COUNTER_COLOURS[:3]),
        counters.column(f"{SERIAL}/bytes", ("to device", "to host"), "bytes", COUNTER_COLOURS[:2]),
    ]


def master_groups(twin: Twin) -> list[tuple[str, list[str]]]:
    """The ``master/...`` entities and the numeric ``Master.stats()`` keys each plots."""
    groups: list[tuple[str, list[str]]] = []
    for k, v in twin.the_master().stats().items():
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


def _master_columns(twin: Twin, groups: list[tuple[str, list[str]]]) -> list[Column]:
    master = twin.the_master()
    keys = [k for _, ks in groups for k in ks]

    def stats(t: Tick) -> Sequence[float]:          # one Master.stats() per row for all its columns
        st = master.stats()
        return [st.get(k, _NAN) for k in keys]

    group = ColumnGroup(stats, every=COUNTER_EVERY)
    return [group.column(path, tuple(ks), "count",
                         tuple(COUNTER_COLOURS[i % len(COUNTER_COLOURS)] for i in range(len(ks))))
            for path, ks in groups]


def twin_columns(twin: Twin, scus: Sequence[int]) -> list[Column]:
    """The recording's column table for ``twin`` (boards ``scus``), in recording order."""
    cols: list[Column] = []
    rows = _Boards()
    boards = ColumnGroup(rows.read, finish=rows.finish)
    for scu in scus:
        cols += _board_columns(scu, twin.slaves[scu], rows, boards)
    rows.seal(twin.plant.truth())
    boards.raw_width = rows.raw_width
    boards.ints = rows.ints
    cols += _robot_columns()
    cols += _bus_columns(twin)
    cols += _master_columns(twin, master_groups(twin))
    return cols


def servo_signs(twin: Twin, scus: Sequence[int]) -> list[tuple[tuple[int, int], str, int]]:
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


def start_tick(twin: Twin, prev: Tick | None, signs: Sequence[tuple[tuple[int, int], str, int]]) -> Tick:
    """The shared state of a sample taken now (``prev``: the previous sample's, for rates)."""
    t = Tick(twin)
    t.truth = twin.plant.truth()
    t._signs = signs
    if prev is None:
        return t
    before = prev.prev
    if before is not None:
        before.prev = None         # a tick keeps its predecessor while it is one of the last two
    t.prev = prev
    t.dt_us = dt = t.now_us - prev.now_us
    t.per_s = US_PER_S / dt if dt > 0 else 0.0
    return t
