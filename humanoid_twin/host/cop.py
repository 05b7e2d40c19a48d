"""Reaction forces and centre of pressure on the host (seed 000 table 27): ``calccop``,
``cop_acquire``, ``cop_graphs``, ``cop_realtime``.

Readings. ``readspecial`` gives each force sensor as the Slave's 8-bit *result*
``Sensor(7 bit) + offset``, where the calibration set ``offset = 128 - mean`` (seed 000, SERVO
``calibration`` and ``sampleExtraSensors``): a reading of 128 is the load the sensor carried when
the Slave calibrated, and one count is one 7-bit ADC step (2 x ``FORCE_N_PER_COUNT`` = 0.4 N).
The host cannot see that calibration load, so it takes it from the tables file
(``force_calib_load``, 7-bit counts; default: the robot standing on both feet, its weight shared
by the 8 sensors, 15.3 counts = 6.1 N). The weight of each sensor in the CoP is then its load
in 7-bit counts, ``w = max(reading - 128 + force_calib_load, 0)``, and
``CoP = sum(w_i p_i) / sum(w_i)`` with the table 12 sensor positions
(``hardware.FORCE_SENSOR_XY_MM``, foot frame: x to the robot's right, y forward, mm). Under
:data:`COP_MIN_LOAD` counts in all (3.2 N, the firmware's ``calcCoP`` threshold) the foot is
unloaded and the CoP is NaN.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from humanoid_twin.hardware import (
    COP_MIN_LOAD,
    FOOT_LENGTH_MM,
    FOOT_OF_SCU,
    FOOT_WIDTH_MM,
    FORCE_CALIBRATION_VALUE,
    FORCE_N_PER_COUNT,
    FORCE_SENSOR_NAMES,
    FORCE_SENSOR_XY_MM,
    N_SPECIAL_SENSORS,
)
from humanoid_twin.host import timebase
from humanoid_twin.host.drivers import ErrorCode, readjoint, readspecial
from humanoid_twin.host.planners import TICK_S
from humanoid_twin.host.tables import RobotTables, default_tables
from humanoid_twin.protocol.rs232 import PARAM_CURRENT, PARAM_POSITION
from humanoid_twin.protocol.wire import check_scu, int_in_range

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort

__all__ = [
    "COP_MIN_LOAD",
    "N_PER_COUNT7",
    "SENSOR_NAMES",
    "CopData",
    "sensor_loads",
    "calccop",
    "cop_acquire",
    "cop_graphs",
    "cop_realtime",
]

N_PER_COUNT7 = 2 * FORCE_N_PER_COUNT      # one 7-bit count in newtons
SENSOR_NAMES = FORCE_SENSOR_NAMES
_SENSOR_XY = np.asarray(FORCE_SENSOR_XY_MM, dtype=float)   # (4, 2)


class CopData(NamedTuple):
    """The variables of ``cop_acquire`` (table 27): ``reaction`` 4 x TIME (readings, 128 =
    calibration load), ``CoP`` 2 x TIME (mm, foot frame; NaN when unloaded), ``servo`` 3 x TIME
    (degrees), ``current`` 3 x TIME (0..100), ``time`` (TIME,) seconds; ``scu`` the board."""

    reaction: np.ndarray
    CoP: np.ndarray
    servo: np.ndarray
    current: np.ndarray
    time: np.ndarray
    scu: int = 1

    def save(self, path: str | Path) -> Path:
        """Store in a ``.npz`` file (the MATLAB workspace file that ``cop_graphs`` reads)."""
        p = Path(path)
        np.savez(p, reaction=self.reaction, CoP=self.CoP, servo=self.servo, current=self.current,
                 time=self.time, scu=self.scu)
        return p if p.suffix == ".npz" else p.with_name(p.name + ".npz")

    @classmethod
    def load(cls, path: str | Path) -> CopData:
        """Read a file written by :meth:`save`."""
        with np.load(Path(path)) as z:
            return cls(z["reaction"], z["CoP"], z["servo"], z["current"], z["time"], int(z["scu"]))


def _calib_load(calib_load: Any, tables: RobotTables | None) -> np.ndarray:
    if calib_load is None:
        calib_load = (tables or default_tables()).force_calib_load
    arr = np.asarray(calib_load, dtype=float)
    if arr.shape not in ((), (N_SPECIAL_SENSORS,)) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"calib_load must be a count >= 0 or 4 of them, got {calib_load!r}")
    return arr


def sensor_loads(react: Any, calib_load: Any = None, *, tables: RobotTables | None = None) -> np.ndarray:
    """Each sensor's load in 7-bit counts, ``max(reading - 128 + calib_load, 0)`` (multiply by
    :data:`N_PER_COUNT7` for newtons). ``react``: (4,) or (4, TIME)."""
    r = np.asarray(react, dtype=float)
    if r.ndim not in (1, 2) or r.shape[0] != N_SPECIAL_SENSORS:
        raise ValueError(f"react must hold the 4 force readings (4 or 4 x TIME), got shape {r.shape}")
    load = _calib_load(calib_load, tables)
    if r.ndim == 2 and load.ndim == 1:
        load = load[:, None]
    return np.maximum(r - FORCE_CALIBRATION_VALUE + load, 0.0)


def calccop(react: Any, calib_load: Any = None, *, tables: RobotTables | None = None) -> np.ndarray:
    """``CoP = calccop(react)`` (table 27): the centre of pressure ``(x, y)`` in mm (foot frame,
    x to the robot's right, y forward) from the 4 force readings (table 12 order: front-left,
    front-right, rear-left, rear-right). ``react`` (4,) -> (2,); (4, TIME) -> (2, TIME). NaN
    where the foot carries less than :data:`COP_MIN_LOAD` counts. ``calib_load``: 7-bit counts
    each sensor carried at calibration (default: the tables file)."""
    w = sensor_loads(react, calib_load, tables=tables)
    total = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        cop = np.tensordot(_SENSOR_XY.T, w, axes=([1], [0])) / total
    return np.where(total >= COP_MIN_LOAD, cop, np.nan)


def _scu(scu: Any) -> int:
    s = check_scu(scu, "scu")
    if s not in FOOT_OF_SCU:
        raise ValueError(f"SCU {s} has no force-sensing foot (feet: {sorted(FOOT_OF_SCU)})")
    return s


def _sample(H: HostPort, s: int) -> tuple[list[float], list[float], list[float]]:
    r = readspecial(H, s)
    react = list(r.special) if r.error == ErrorCode.OK else [math.nan] * 4  # type: ignore[arg-type]  # answered (error OK)
    p = readjoint(H, s, PARAM_POSITION)
    pos = list(p.servos) if p.error == ErrorCode.OK else [math.nan] * 3  # type: ignore[arg-type]  # answered (error OK)
    c = readjoint(H, s, PARAM_CURRENT)
    cur = list(c.servos) if c.error == ErrorCode.OK else [math.nan] * 3  # type: ignore[arg-type]  # answered (error OK)
    return react, pos, cur  # type: ignore[return-value]  # ints widen to floats


def _check_time(name: str, v: Any, positive: bool = True) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be seconds, got {v!r}") from None
    if not math.isfinite(f) or f < 0 or (positive and f == 0):
        raise ValueError(f"{name} must be {'> 0' if positive else '>= 0'} s, got {v!r}")
    return f


def _loop(H: HostPort, s: int, maxtime: float, dt: float, on_sample: Any = None) -> CopData:
    react, pos, cur, tt = [], [], [], []
    t0 = timebase.now(H)
    t_end = t0 + maxtime
    i = 0
    while timebase.now(H) < t_end:
        ts = timebase.now(H) - t0
        r, p, c = _sample(H, s)
        tt.append(ts)
        react.append(r)
        pos.append(p)
        cur.append(c)
        if on_sample is not None:
            on_sample(ts, r, p, c)
        i += 1
        if dt > 0:
            wait = min(t0 + i * dt, t_end) - timebase.now(H)
            if wait > 0:
                timebase.sleep(H, wait)
    reaction = np.asarray(react, dtype=float).reshape(-1, 4).T
    return CopData(reaction, calccop(reaction), np.asarray(pos, dtype=float).reshape(-1, 3).T,
                   np.asarray(cur, dtype=float).reshape(-1, 3).T, np.asarray(tt, dtype=float), s)


def cop_acquire(H: HostPort, maxtime: float, scu: int = 1, *, dt: float = TICK_S) -> CopData:
    """``cop_acquire`` (table 27): sample the foot of ``scu`` (1 right leg, 2 left leg) every
    ``dt`` s for ``maxtime`` s on the time base: force readings, CoP, the board's 3 servo
    positions and currents. Failed reads leave NaN."""
    return _loop(H, _scu(scu), _check_time("maxtime", maxtime), _check_time("dt", dt, positive=False))


def _foot_outline() -> np.ndarray:
    hx, hy = FOOT_WIDTH_MM / 2, FOOT_LENGTH_MM / 2
    return np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy], [-hx, -hy]])


def cop_graphs(data: CopData | str | Path, path: str | Path, *, title: str | None = None) -> Path:
    """``cop_graphs`` (table 27): a PNG of a ``cop_acquire`` result (or its ``.npz`` file):
    the CoP trace over the foot outline and its sensors (coloured by time), the 4 sensor loads
    (N) against time, the 3 servo positions and currents against time. Returns the path."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    d = CopData.load(data) if isinstance(data, str | Path) else data
    out = Path(path)
    side = {1: "right", 2: "left"}.get(d.scu, str(d.scu))
    fig = plt.figure(figsize=(12, 7.5), layout="constrained")
    gs = fig.add_gridspec(3, 2, width_ratios=[1, 1.6])
    ax_foot = fig.add_subplot(gs[:, 0])
    ax_f = fig.add_subplot(gs[0, 1])
    ax_p = fig.add_subplot(gs[1, 1], sharex=ax_f)
    ax_c = fig.add_subplot(gs[2, 1], sharex=ax_f)

    outline = _foot_outline()
    ax_foot.fill(outline[:, 0], outline[:, 1], color="0.92", ec="0.3", lw=1.5, label="sole 80 x 200 mm")
    ax_foot.scatter(_SENSOR_XY[:, 0], _SENSOR_XY[:, 1], s=120, marker="s", c="tab:orange",
                    ec="k", zorder=3, label="force sensors")
    for (x, y), name in zip(_SENSOR_XY, SENSOR_NAMES, strict=True):
        ax_foot.annotate(name, (x, y), textcoords="offset points", xytext=(0, 10 if y > 0 else -16),
                         ha="center", fontsize=8)
    cop = d.CoP
    ok = np.all(np.isfinite(cop), axis=0) if cop.size else np.zeros(0, bool)
    if np.any(ok):
        ax_foot.plot(cop[0, ok], cop[1, ok], "-", color="0.5", lw=0.8, zorder=4)
        sc = ax_foot.scatter(cop[0, ok], cop[1, ok], c=d.time[ok], cmap="viridis", s=14, zorder=5)
        fig.colorbar(sc, ax=ax_foot, label="time (s)", shrink=0.6)
        ax_foot.scatter(cop[0, ok][-1:], cop[1, ok][-1:], marker="x", c="r", s=80, zorder=6, label="last CoP")
    else:
        ax_foot.text(0, 0, "foot unloaded:\nno CoP", ha="center", va="center", color="tab:red")
    ax_foot.axhline(0, color="0.7", lw=0.5)
    ax_foot.axvline(0, color="0.7", lw=0.5)
    ax_foot.set_aspect("equal")
    ax_foot.set_xlim(-FOOT_WIDTH_MM * 0.9, FOOT_WIDTH_MM * 0.9)
    ax_foot.set_ylim(-FOOT_LENGTH_MM * 0.62, FOOT_LENGTH_MM * 0.62)
    ax_foot.set_xlabel("x (mm, to the robot's right)")
    ax_foot.set_ylabel("y (mm, forward)")
    ax_foot.set_title(f"CoP, {side} foot (SCU {d.scu})")
    ax_foot.legend(loc="lower center", fontsize=8)

    loads = sensor_loads(d.reaction) * N_PER_COUNT7 if d.reaction.size else d.reaction
    for i, name in enumerate(SENSOR_NAMES):
        if loads.size:
            ax_f.plot(d.time, loads[i], label=name)
    ax_f.set_ylabel("sensor load (N)")
    ax_f.legend(fontsize=8, ncol=4, loc="upper left")
    ax_f.set_title("reaction forces")
    for i in range(3):
        if d.servo.size:
            ax_p.plot(d.time, d.servo[i], label=f"servo {i + 1}")
            ax_c.plot(d.time, d.current[i], label=f"servo {i + 1}")
    ax_p.set_ylabel("position (deg)")
    ax_p.legend(fontsize=8, ncol=3, loc="upper left")
    ax_c.set_ylabel("current (0..100)")
    ax_c.set_xlabel("time (s)")
    ax_c.legend(fontsize=8, ncol=3, loc="upper left")
    for ax in (ax_f, ax_p, ax_c):
        ax.grid(alpha=0.3)
    fig.suptitle(title or f"cop_acquire: {len(d.time)} samples, {d.time[-1] if len(d.time) else 0:.2f} s")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out


def cop_realtime(
    H: HostPort,
    scu: int = 1,
    duration: float = 10.0,
    *,
    mode: str = "spawn",
    path: str | Path | None = None,
    url: str | None = None,
    dt: float = TICK_S,
    chunk: int = 10,
) -> CopData:
    """``cop_realtime`` (table 27): the CoP of a foot on a drawing of the foot, live, in rerun.

    ``mode``: ``"spawn"`` (start a viewer, ``rr.spawn``), ``"connect"`` (stream to a running
    viewer at ``url``, ``rr.connect_grpc``; default URL of rerun) or ``"save"`` (headless: write
    ``path``, an ``.rrd`` file to open with ``humanoid-twin view``). Samples the foot of ``scu``
    every ``dt`` s for ``duration`` s (time base) and sends them to rerun in chunks of ``chunk``
    samples (columns, not one ``rr.log`` per value). Entities: ``foot/outline``,
    ``foot/sensors``, ``foot/cop`` (2D), ``forces/<sensor>`` (N), ``servo/position/<i>``,
    ``servo/current/<i>``, on the timeline ``time`` (seconds on the time base). Returns the
    samples as :func:`cop_acquire` does.
    """
    import rerun as rr

    s = _scu(scu)
    duration = _check_time("duration", duration)
    dt = _check_time("dt", dt, positive=False)
    chunk = int_in_range("chunk", chunk, 1, None, "samples")
    rec = rr.RecordingStream("humanoid_twin_cop_realtime")
    if mode == "spawn":
        rec.spawn()
    elif mode == "connect":
        if url is None:
            rec.connect_grpc()
        else:
            rec.connect_grpc(url)
    elif mode == "save":
        if path is None:
            raise ValueError("mode='save' needs path= (an .rrd file)")
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        rec.save(str(path))
    else:
        raise ValueError(f"mode must be 'spawn', 'connect' or 'save', got {mode!r}")

    rec.log("foot/outline", rr.LineStrips2D([_foot_outline()], colors=[[90, 90, 90]]), static=True)
    rec.log("foot/sensors", rr.Points2D(_SENSOR_XY, labels=list(SENSOR_NAMES), radii=4.0,
                                        colors=[[255, 150, 30]]), static=True)
    buf: list[tuple[float, list[float], list[float], list[float]]] = []

    def flush() -> None:
        if not buf:
            return
        t = np.array([b[0] for b in buf])
        react = np.array([b[1] for b in buf], dtype=float).T
        pos = np.array([b[2] for b in buf], dtype=float).T
        cur = np.array([b[3] for b in buf], dtype=float).T
        idx = [rr.TimeColumn("time", duration=t)]
        cop = calccop(react)
        ok = np.all(np.isfinite(cop), axis=0)
        if np.any(ok):
            pts = rr.Points2D.columns(positions=cop[:, ok].T).partition([1] * int(ok.sum()))
            rr.send_columns("foot/cop", indexes=[rr.TimeColumn("time", duration=t[ok])], columns=pts,
                            recording=rec)
        loads = sensor_loads(react) * N_PER_COUNT7
        for i, name in enumerate(SENSOR_NAMES):
            rr.send_columns(f"forces/{name}", indexes=idx, columns=rr.Scalars.columns(scalars=loads[i]),
                            recording=rec)
        for i in range(3):
            for name, values in (("position", pos[i]), ("current", cur[i])):
                cols = rr.Scalars.columns(scalars=values)
                rr.send_columns(f"servo/{name}/{i + 1}", indexes=idx, columns=cols, recording=rec)
        buf.clear()

    def on_sample(ts: float, r: list[float], p: list[float], c: list[float]) -> None:
        buf.append((ts, r, p, c))
        if len(buf) >= chunk:
            flush()

    try:
        data = _loop(H, s, duration, dt, on_sample)
    finally:
        flush()
        rec.flush()
        if mode == "save":
            rec.disconnect()
    return data
