"""Record a running twin to a rerun ``.rrd`` file, in buffered columns.

    with Twin(seed=0) as twin, Recorder("run.rrd", twin) as rec:
        ...                                   # drive the twin; rec samples every 20 ms
    # the file is complete here, even if the block raised

The recorder registers :meth:`Recorder.sample` on the twin's clock (``twin.every(period_us,
...)``, first at the current instant). Each sample writes one row of plain floats into
preallocated numpy arrays; every ``chunk_s`` of simulated time (and at :meth:`Recorder.flush` /
:meth:`Recorder.close`) the rows are sent with ``rr.send_columns`` on the duration timeline
``sim_time``, one call per entity per chunk, never one ``rr.log`` per value (SPEC.md section 1).
Static content (robot geometry, platform, floor, foot outlines, sensor positions, series names
and colours) and the default blueprint are sent once, at construction. What is recorded where:
docs/recording.md.

The recorder only reads: the Slave databases and firmware state, the Master and bus counters,
and the plant's ground truth (``truth()``, ``body_poses()``, ``servo_angle_deg``). It never calls
the plant's sensor-reading methods (they draw noise), so a recorded run is the same run as an
unrecorded one.
"""

from __future__ import annotations

import atexit
import math
import pathlib
import time
import uuid
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa
import rerun as rr

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import (
    FOOT_LENGTH_MM,
    FOOT_OF_SCU,
    FOOT_WIDTH_MM,
    FORCE_SENSOR_XY_MM,
    N_SCU,
    N_SERVOS,
    N_SPECIAL_SENSORS,
    PWM_PERIOD_US,
    SERVO_JOINTS,
)
from humanoid_twin.plant import SERVO_SIGN
from humanoid_twin.protocol.rs232 import SUPERVISOR_MODES
from humanoid_twin.recording.blueprint import default_blueprint
from humanoid_twin.recording.paths import (
    BODIES,
    CAN,
    MASTER,
    POSITION_SERIES,
    ROBOT,
    SENSOR_NAMES,
    SERIAL,
    SUPERVISOR_EVENTS,
    SUPERVISOR_MODE,
    WORLD,
    foot_view_path,
    scu_path,
    servo_path,
)

__all__ = ["Recorder", "RecorderError", "TIMELINE"]

TIMELINE = "sim_time"

# Colours of the series (RGB), the same meaning everywhere in the viewer.
_GREY = (120, 120, 120)
_BLUE = (31, 119, 180)
_PURPLE = (148, 103, 189)
_ORANGE = (255, 127, 14)
_GREEN = (44, 160, 44)
_RED = (214, 39, 40)
_POSITION_COLOURS = (_GREY, _BLUE, _PURPLE, _ORANGE, _GREEN)     # POSITION_SERIES order
_SENSOR_COLOURS = (_RED, _BLUE, _ORANGE, _GREEN)                  # SENSOR_NAMES order
_SENSOR_LABELS = ("FL", "FR", "RL", "RR")

# Sensor loads in the foot view: circle radius (mm) = base + per_newton * F, capped.
_LOAD_RADIUS_BASE_MM = 2.0
_LOAD_RADIUS_MM_PER_N = 1.5
_LOAD_RADIUS_MAX_MM = 30.0
# Master.stats() keys with these prefixes share one entity (one series per key): master/can, ...
_MASTER_GROUPS = ("serial_frames_", "serial_bytes_", "can_")
# Largest buffer (rows per chunk): 10 000 rows x ~270 columns x 8 bytes = ~22 MB.
_MAX_CHUNK_ROWS = 10_000
# An infinite MuJoCo plane (size 0) is drawn as a square of this half size (m).
_FLOOR_HALF_M = 1.5
# Height (m) of the CoP point and support polygon above the platform surface, so they show.
_ON_FLOOR_M = 0.001


class RecorderError(RuntimeError):
    """The recorder cannot record this twin (a missing interface) or this file."""


@dataclass(frozen=True)
class _Series:
    """One ``Scalars`` entity: ``width`` consecutive columns of the value buffer."""

    path: str
    col: int
    width: int
    names: tuple[str, ...]
    colors: tuple[tuple[int, int, int], ...] | None = None
    sparse: bool = False          # NaN = no value in that row (width 1 only)


def _check_path(path: str | pathlib.Path) -> pathlib.Path:
    p = pathlib.Path(path)
    if p.suffix.lower() != ".rrd":
        raise ValueError(f"recording path {str(p)!r} must end in .rrd (rerun's file format)")
    parent = p.parent
    if not parent.is_dir():
        raise FileNotFoundError(
            f"cannot write the recording {str(p)!r}: directory {str(parent)!r} does not exist"
        )
    if p.is_dir():
        raise IsADirectoryError(f"cannot write the recording {str(p)!r}: it is a directory")
    try:  # probe writability now, not in the middle of a run
        with open(p, "ab"):
            pass
    except OSError as exc:
        raise OSError(exc.errno, f"cannot write the recording {str(p)!r}: {exc.strerror or exc}") from exc
    return p


class Recorder:
    """Buffered rerun recording of a :class:`~humanoid_twin.twin.Twin` (docs/recording.md).

    ``path``: the ``.rrd`` file (checked writable here, before the run). ``period_us``: sampling
    period on the virtual clock (default one PWM period, 20 ms). ``app_id``: rerun application
    id (the viewer keys blueprints by it). ``chunk_s``: simulated seconds per ``send_columns``
    chunk. ``scus``: the boards recorded (default all 8). ``blueprint``: send the default layout.

    Counters: ``samples`` (rows taken), ``chunks_sent``, ``wall_s`` (wall time spent in the
    recorder: set-up, sampling, sending, closing), :meth:`cost_per_sim_s`.
    """

    def __init__(
        self,
        path: str | pathlib.Path,
        twin: Any,
        period_us: int = PWM_PERIOD_US,
        app_id: str = "humanoid_twin",
        *,
        chunk_s: float = 2.0,
        scus: Iterable[int] = range(1, N_SCU + 1),
        blueprint: bool = True,
    ) -> None:
        t_start = time.perf_counter()
        if isinstance(period_us, bool) or not isinstance(period_us, int) or period_us <= 0:
            raise ValueError(f"period_us must be a positive int of microseconds, got {period_us!r}")
        if isinstance(chunk_s, bool) or not isinstance(chunk_s, (int, float)) or not (
            math.isfinite(chunk_s) and chunk_s > 0
        ):
            raise ValueError(f"chunk_s must be a positive number of simulated seconds, got {chunk_s!r}")
        if not isinstance(app_id, str) or not app_id:
            raise ValueError(f"app_id must be a non-empty string, got {app_id!r}")
        for attr in ("clock", "plant", "network", "link", "master", "slaves", "every"):
            if not hasattr(twin, attr):
                raise RecorderError(f"Recorder needs a Twin (with .{attr}), got {type(twin).__name__}")
        self.scus: tuple[int, ...] = tuple(scus)
        if not self.scus:
            raise ValueError("scus: record at least one board")
        for s in self.scus:
            if s not in twin.slaves:
                raise ValueError(f"SCU {s!r} is not a board of this twin (it has {sorted(twin.slaves)})")
        if len(set(self.scus)) != len(self.scus):
            raise ValueError(f"scus has duplicates: {self.scus}")
        rows = max(1, round(chunk_s * US_PER_S / period_us))
        if rows > _MAX_CHUNK_ROWS:
            raise ValueError(
                f"chunk_s={chunk_s} s at period_us={period_us} buffers {rows} rows; at most "
                f"{_MAX_CHUNK_ROWS} (memory): use a smaller chunk_s"
            )
        self.twin = twin
        self._rows = rows
        self.period_us = period_us
        self.app_id = app_id
        self.samples = 0
        self.chunks_sent = 0
        self.wall_s = 0.0
        self._closed = False
        self._t0_us = twin.clock.now_us
        self._n = 0

        self._layout()
        self._alloc()
        self.path = _check_path(path)          # the last check, the first thing created
        self.rec = rr.RecordingStream(app_id, recording_id=uuid.uuid4())
        bp = default_blueprint(self.scus, [p for p, _ in self._master_groups]) if blueprint else None
        try:
            self.rec.save(self.path, default_blueprint=bp)
        except RuntimeError as exc:
            raise OSError(f"cannot write the recording {str(self.path)!r}: {exc}") from exc
        atexit.register(self.close)
        try:
            self._log_static()
        except BaseException:
            self.close()
            raise
        twin.every(period_us, self.sample, twin.clock.now_us)
        # the supervisor (docs/supervisor.md): its mode as a series, its faults as text events
        self._sup = getattr(twin.master, "supervisor", None)
        self._last_mode: int | None = None
        if self._sup is not None:
            self.mode(self._sup.mode)
            self._sup.listeners.append(self._on_supervisor)
        self.wall_s += time.perf_counter() - t_start

    # -- events on sim_time (docs/supervisor.md) ----------------------------------------------------
    def event(self, text: str, level: str = "INFO", t_us: int | None = None) -> None:
        """A text event on ``sim_time`` (``supervisor/events``): a fault, a mode change, an
        injected fault. ``t_us``: virtual time (default now)."""
        if self._closed:
            return
        t = self.twin.clock.now_us if t_us is None else t_us
        self.rec.set_time(TIMELINE, duration=np.timedelta64(t, "us"))
        self.rec.log(SUPERVISOR_EVENTS, rr.TextLog(text, level=level))

    def mode(self, mode: int, t_us: int | None = None) -> None:
        """One point of the ``supervisor/mode`` series (0 standby .. 4 estop) at ``t_us``."""
        if self._closed:
            return
        t = self.twin.clock.now_us if t_us is None else t_us
        self._last_mode = mode
        self.rec.set_time(TIMELINE, duration=np.timedelta64(t, "us"))
        self.rec.log(SUPERVISOR_MODE, rr.Scalars(float(mode)))

    def _on_supervisor(self, kind: str, t_us: int, value: Any) -> None:
        if kind == "mode":
            prev = self._last_mode
            if prev is not None and t_us > 0:
                self.mode(prev, t_us - 1)          # a step, not a ramp, in the plot
            self.mode(value, t_us)
            self.event(f"mode {SUPERVISOR_MODES.get(value, value)}", "INFO", t_us)
        else:
            self.event(f"fault {value.name} (code {value.code}) node {value.node}", "ERROR", t_us)

    # -- layout --------------------------------------------------------------------------------------
    def _layout(self) -> None:
        """The scalar entities, in the exact order :meth:`sample` appends their values."""
        twin = self.twin
        plant = twin.plant
        for attr in ("truth", "body_poses", "geometry", "servo_angle_deg", "advance_to", "tilt_deg"):
            if not hasattr(plant, attr):
                raise RecorderError(f"the twin's plant has no {attr}(): cannot record ground truth")
        self._slaves = [(s, twin.slaves[s]) for s in self.scus]
        self._feet = [s for s in self.scus if s in FOOT_OF_SCU]
        self._master_keys: list[str] = []
        self._master_groups: list[tuple[str, list[str]]] = []   # (entity, stats keys)
        for k, v in twin.master.stats().items():
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            self._master_keys.append(k)
            group = next((g for g in _MASTER_GROUPS if k.startswith(g)), k)
            for path, keys in self._master_groups:
                if path == f"{MASTER}/{group.rstrip('_')}":
                    keys.append(k)
                    break
            else:
                self._master_groups.append((f"{MASTER}/{group.rstrip('_')}", [k]))
        series: list[_Series] = []
        col = 0

        def add(path: str, names: Sequence[str], colors: Sequence[tuple[int, int, int]] | None = None,
                sparse: bool = False) -> None:
            nonlocal col
            series.append(_Series(path, col, len(names), tuple(names),
                                  tuple(colors) if colors is not None else None, sparse))
            col += len(names)

        for scu, _ in self._slaves:
            base = scu_path(scu)
            for i in range(N_SERVOS):
                sp = servo_path(scu, i)
                add(f"{sp}/position", POSITION_SERIES, _POSITION_COLOURS)
                add(f"{sp}/velocity", ("measured", "true"), (_ORANGE, _GREEN))
                add(f"{sp}/current", (f"{SERVO_JOINTS[scu][i]} ({i + 1})",))
            add(f"{base}/status", ("pwm", "calibrated"))
            add(f"{base}/deadline_violations", ("deadline violations",))
            if scu in FOOT_OF_SCU:
                add(f"{base}/force/adc", SENSOR_NAMES, _SENSOR_COLOURS)
                add(f"{base}/force/newton", SENSOR_NAMES, _SENSOR_COLOURS)
                for axis in ("x", "y"):
                    add(f"{base}/cop/{axis}/firmware", ("firmware",), (_ORANGE,), sparse=True)
                    add(f"{base}/cop/{axis}/truth", ("truth",), (_GREEN,), sparse=True)
        add(f"{ROBOT}/trunk_tilt_deg", ("trunk tilt",))
        add(f"{ROBOT}/com_height_mm", ("CoM height",))
        add(f"{ROBOT}/cop_margin_mm", ("CoP margin",), sparse=True)
        add(f"{ROBOT}/fell", ("fell",), (_RED,))
        add(f"{ROBOT}/total_force_n", ("total normal force",))
        add(f"{ROBOT}/platform_tilt_deg", ("platform tilt",))
        add(f"{CAN}/frames", ("frames",))
        add(f"{CAN}/frames_per_s", ("frames/s",))
        add(f"{CAN}/load_percent", ("bus load",))
        add(f"{CAN}/error_frames", ("error frames",), (_RED,))
        add(f"{CAN}/frames_dropped", ("frames dropped",), (_ORANGE,))
        add(f"{CAN}/master_controller", ("state (0 active, 1 passive, 2 off)", "TEC", "REC"))
        add(f"{SERIAL}/bytes", ("to device", "to host"))
        for path, keys in self._master_groups:
            add(path, keys)
        self._master_order = [k for _, keys in self._master_groups for k in keys]
        self._series = series
        self._ncols = col
        self._col = {s.path: s.col for s in series}
        # true shaft angle in the servo frame from the ground truth's joint angles (one truth()
        # per sample instead of 24 servo_angle_deg calls); checked against servo_angle_deg here
        truth = plant.truth()
        self._servo_signs: list[tuple[str, int]] = []
        for scu, _ in self._slaves:
            for i in range(N_SERVOS):
                joint = SERVO_JOINTS[scu][i]
                sign = SERVO_SIGN[joint]
                if abs(sign * truth.joint_angles_deg[joint] - plant.servo_angle_deg(scu, i)) > 1e-9:
                    raise RecorderError(f"plant servo sign table disagrees with servo_angle_deg for {joint}")
                self._servo_signs.append((joint, sign))
        names, _, _ = plant.body_poses()
        self._body_names: tuple[str, ...] = tuple(names)
        self._platform = self._body_names.index("platform") if "platform" in self._body_names else None
        # state for rates and finite differences
        self._prev_true = [0.0] * (len(self._slaves) * N_SERVOS)
        self._prev_frames = twin.network.frames_sent
        self._prev_busy = getattr(twin.network, "busy_us", 0)
        self._prev_t_us: int | None = None

    def _alloc(self) -> None:
        rows, nb = self._rows, len(self._body_names)
        self._t = np.zeros(rows, dtype=np.int64)
        self._vals = np.zeros((rows, self._ncols), dtype=np.float64)
        self._pos = np.zeros((rows, nb, 3), dtype=np.float64)
        self._quat = np.zeros((rows, nb, 4), dtype=np.float64)
        self._com = np.zeros((rows, 3), dtype=np.float64)
        self._cop3 = np.full((rows, 2), np.nan)
        self._poly: list[np.ndarray | None] = [None] * rows

    # -- static content ------------------------------------------------------------------------------
    def _log_static(self) -> None:
        rec = self.rec
        rec.log(WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._log_geometry()
        for s in self._series:
            kw: dict[str, Any] = {"names": list(s.names)}
            if s.colors is not None:
                kw["colors"] = list(s.colors)
            rec.log(s.path, rr.SeriesLines(**kw), static=True)
        for scu in self._feet:
            self._log_foot_static(scu)

    def _log_foot_static(self, scu: int) -> None:
        """Foot outline and sensors in the 2D foot view (mm; drawn with forward up)."""
        rec = self.rec
        v = foot_view_path(scu)
        hl, hw = FOOT_LENGTH_MM / 2, FOOT_WIDTH_MM / 2
        outline = _view_xy([[-hw, -hl], [hw, -hl], [hw, hl], [-hw, hl], [-hw, -hl]])
        rec.log(f"{v}/outline", rr.LineStrips2D([outline], colors=[(200, 200, 200)]), static=True)
        rec.log(f"{v}/forward", rr.Arrows2D(origins=[[0.0, 0.0]], vectors=[[0.0, -0.8 * hl]],
                                            colors=[(90, 90, 90)], labels=["forward"]), static=True)
        xy = _view_xy(FORCE_SENSOR_XY_MM)
        rec.log(f"{v}/sensors", rr.Points2D(xy, radii=[3.0] * 4, colors=list(_SENSOR_COLOURS),
                                            labels=list(_SENSOR_LABELS), show_labels=True), static=True)
        rec.log(f"{v}/loads", rr.Points2D(xy, colors=[(*c, 90) for c in _SENSOR_COLOURS]), static=True)
        rec.log(f"{v}/cop/firmware", rr.Points2D([[0.0, 0.0]], radii=[4.0], colors=[_ORANGE],
                                                 labels=["firmware"]), static=True)
        rec.log(f"{v}/cop/truth", rr.Points2D([[0.0, 0.0]], radii=[3.0], colors=[_GREEN],
                                              labels=["truth"]), static=True)

    def _log_geometry(self) -> None:
        """Static shapes: one entity per body under world/bodies, shapes in the body frame; the
        world body's planes as the floor."""
        rec = self.rec
        per_body: dict[str, dict[str, list]] = {}
        floor: list = []
        for g in self.twin.plant.geometry():
            kind = str(g.type).lower()
            if kind == "plane":
                floor.append(g)
            else:
                per_body.setdefault(g.body, {}).setdefault(kind, []).append(g)
        known = set(self._body_names)
        for body, kinds in per_body.items():
            base = f"{BODIES}/{body}" if body in known else f"{WORLD}/static/{body}"
            for kind, gs in kinds.items():
                arch = _shapes(kind, gs)
                if arch is not None:
                    rec.log(f"{base}/{_KIND_ENTITY[kind]}", arch, static=True)
        for k, g in enumerate(floor):
            hx = g.size[0] if g.size[0] > 0 else _FLOOR_HALF_M
            hy = g.size[1] if g.size[1] > 0 else _FLOOR_HALF_M
            centre = np.asarray(g.pos, dtype=float) - [0.0, 0.0, 0.0005]
            rec.log(f"{WORLD}/floor/{k}", rr.Boxes3D(half_sizes=[[hx, hy, 0.0005]], centers=[centre],
                                                     colors=[_rgba(g)], fill_mode="solid"), static=True)

    # -- sampling ------------------------------------------------------------------------------------
    def sample(self) -> None:
        """Take one row now (registered on the clock every ``period_us``). A no-op once closed."""
        if self._closed:
            return
        twin = self.twin
        plant = twin.plant
        now = twin.clock.now_us
        plant.advance_to(now)        # physics due anyway (lazy stepping): not the recorder's cost
        w0 = time.perf_counter()
        i = self._n
        self._t[i] = now
        prev_t = self._prev_t_us
        dt_us = now - prev_t if prev_t is not None else 0
        per_tick = PWM_PERIOD_US / dt_us if dt_us > 0 else 0.0
        per_s = US_PER_S / dt_us if dt_us > 0 else 0.0
        truth = plant.truth()
        pads_n = truth.pad_forces_n
        cops = truth.foot_cop_mm
        nan = math.nan

        vals: list[float] = []
        ap = vals.append
        prev_true = self._prev_true
        joints = truth.joint_angles_deg
        signs = self._servo_signs
        j = 0
        for scu, slv in self._slaves:
            sens = slv.sensors.servo
            act = slv.actuators.servo
            tpos = slv.traj.position
            cmd = slv.commanded
            for k in range(N_SERVOS):
                s = sens[k]
                joint, sign = signs[j]
                true = sign * joints[joint]       # servo frame = SERVO_SIGN * joint frame
                vals += (act[k].ref, tpos[k], cmd[k], s.pos, true,
                         s.vel, (true - prev_true[j]) * per_tick, s.current)
                prev_true[j] = true
                j += 1
            st = slv.sensors.sysStatus
            vals += (st.pwm, st.calib, slv.deadline_violations)
            foot = FOOT_OF_SCU.get(scu)
            if foot is not None:
                vals += slv.sensors.special
                vals += pads_n[foot].tolist()
                cop = cops[foot]
                if slv.cop_loaded:
                    ap(slv.cop_x)
                else:
                    ap(nan)
                ap(nan if cop is None else cop[0])
                ap(slv.cop_y if slv.cop_loaded else nan)
                ap(nan if cop is None else cop[1])
        com = truth.com
        margin = truth.cop_margin_mm
        vals += (truth.trunk_tilt_deg, com[2] * 1000.0, margin if math.isfinite(margin) else nan,
                 truth.fell, truth.total_normal_force_n, plant.tilt_deg)
        net = twin.network
        frames = net.frames_sent
        busy = getattr(net, "busy_us", 0)
        ctl = twin.master.controller
        link = twin.link
        vals += (frames, (frames - self._prev_frames) * per_s, 100.0 * (busy - self._prev_busy) / dt_us
                 if dt_us > 0 else 0.0, net.error_frames, net.frames_dropped,
                 ctl.error_state_code, ctl.tec, ctl.rec, link.bytes_to_device, link.bytes_to_host)
        if self._master_keys:
            ms = twin.master.stats()
            for key in self._master_order:
                ap(ms.get(key, nan))
        self._prev_frames = frames
        self._prev_busy = busy
        self._prev_t_us = now
        if len(vals) != self._ncols:
            raise RecorderError(f"recorder bug: sampled {len(vals)} values for {self._ncols} columns")
        self._vals[i] = vals

        _, pos, quat = plant.body_poses()
        self._pos[i] = pos
        self._quat[i] = quat
        self._com[i] = com
        cw = truth.cop_world_xy
        if cw is None:
            self._cop3[i] = nan
        else:
            self._cop3[i] = cw
        self._poly[i] = truth.support_polygon_xy
        self._n = i + 1
        self.samples += 1
        self.wall_s += time.perf_counter() - w0
        if self._n == self._rows:
            self.flush()

    # -- sending -------------------------------------------------------------------------------------
    def flush(self) -> None:
        """Send the buffered rows (one ``send_columns`` per entity) and empty the buffer."""
        n = self._n
        if n == 0 or self._closed:
            return
        w0 = time.perf_counter()
        self._n = 0       # a failure below loses this chunk, never duplicates it
        rec = self.rec
        idx = [rr.TimeColumn(TIMELINE, duration=self._t[:n].astype("timedelta64[us]"))]
        vals = self._vals[:n]
        # Scalars and transforms go as ready arrow arrays (``rr.ComponentColumn`` over the
        # archetype's own descriptor): the same data as ``rr.Scalars.columns(...)`` /
        # ``rr.Transform3D.columns(...)``, at a third of their Python cost per call.
        for s in self._series:
            if s.width == 1:
                col = vals[:, s.col]
                if s.sparse:
                    ok = ~np.isnan(col)
                    if not ok.all():  # rows without a value: empty rows, a gap in the plot
                        offsets = np.zeros(n + 1, dtype=np.int32)
                        np.cumsum(ok, out=offsets[1:])
                        rec.send_columns(s.path, indexes=idx, columns=[
                            rr.ComponentColumn(_D_SCALARS, _Arrow(pa.array(col[ok])), offsets=offsets)])
                        continue
                data = pa.array(col)
            else:
                data = pa.array(vals[:, s.col:s.col + s.width].ravel())
            rec.send_columns(s.path, indexes=idx, columns=[
                rr.ComponentColumn(_D_SCALARS, _Arrow(data), offsets=_offsets(n, s.width))])
        unit = _offsets(n, 1)
        for b, name in enumerate(self._body_names):
            rec.send_columns(f"{BODIES}/{name}", indexes=idx, columns=[
                rr.ComponentColumn(_D_TRANSLATION, _Arrow(_vec_array(self._pos[:n, b], _VEC3)), offsets=unit),
                rr.ComponentColumn(_D_QUATERNION, _Arrow(_vec_array(self._quat[:n, b], _VEC4)), offsets=unit),
            ])
        self._send_feet(idx, vals)
        self._send_world(idx, n)
        self.chunks_sent += 1
        self.wall_s += time.perf_counter() - w0

    def _send_feet(self, idx: list, vals: np.ndarray) -> None:
        rec = self.rec
        col = self._col
        for scu in self._feet:
            base = scu_path(scu)
            v = foot_view_path(scu)
            for who in ("firmware", "truth"):
                x = vals[:, col[f"{base}/cop/x/{who}"]]
                y = vals[:, col[f"{base}/cop/y/{who}"]]
                ok = ~(np.isnan(x) | np.isnan(y))
                offsets = np.zeros(len(ok) + 1, dtype=np.int32)
                np.cumsum(ok, out=offsets[1:])
                pts = np.column_stack([x[ok], -y[ok]])        # drawn with forward up
                rec.send_columns(f"{v}/cop/{who}", indexes=idx, columns=[
                    rr.ComponentColumn(_D_POSITIONS2D, _Arrow(_vec_array(pts, _VEC2)), offsets=offsets)])
            k0 = col[f"{base}/force/newton"]
            forces = vals[:, k0:k0 + N_SPECIAL_SENSORS]
            radii = np.clip(_LOAD_RADIUS_BASE_MM + _LOAD_RADIUS_MM_PER_N * forces, 0.0, _LOAD_RADIUS_MAX_MM)
            rec.send_columns(f"{v}/loads", indexes=idx, columns=[rr.ComponentColumn(
                _D_RADII2D, _Arrow(pa.array(radii.astype(np.float32).ravel())),
                offsets=_offsets(len(forces), N_SPECIAL_SENSORS))])

    def _send_world(self, idx: list, n: int) -> None:
        rec = self.rec
        unit = _offsets(n, 1)
        com = self._com[:n]
        ground = com.copy()
        ground[:, 2] = self._platform_z(np.arange(n), com[:, :2])
        cop = self._cop3[:n]
        ok = ~np.isnan(cop[:, 0])
        cop_offsets = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(ok, out=cop_offsets[1:])
        cop_pts = np.column_stack([cop[ok], self._platform_z(np.flatnonzero(ok), cop[ok])])
        for path, pts, offsets in ((f"{WORLD}/com", com, unit), (f"{WORLD}/com_ground", ground, unit),
                                   (f"{WORLD}/cop", cop_pts, cop_offsets)):
            rec.send_columns(path, indexes=idx, columns=[
                rr.ComponentColumn(_D_POSITIONS3D, _Arrow(_vec_array(pts, _VEC3)), offsets=offsets)])
        # support polygon: one closed line strip per row (none when nothing touches)
        polys: list[np.ndarray] = []
        rows_of: list[np.ndarray] = []
        strip_offsets = np.zeros(n + 1, dtype=np.int32)
        for r, poly in enumerate(self._poly[:n]):
            if poly is not None and len(poly) >= 2:
                p = np.asarray(poly, dtype=float)[:, :2]
                if len(p) > 2:
                    p = np.vstack([p, p[:1]])     # closed outline
                polys.append(p)
                rows_of.append(np.full(len(p), r))
            strip_offsets[r + 1] = len(polys)
        if polys:
            xy = np.concatenate(polys)
            xyz = np.column_stack([xy, self._platform_z(np.concatenate(rows_of), xy)])
        else:
            xyz = np.zeros((0, 3))
        point_offsets = np.zeros(len(polys) + 1, dtype=np.int32)
        np.cumsum([len(p) for p in polys], out=point_offsets[1:])
        strips = pa.ListArray.from_arrays(pa.array(point_offsets), _vec_array(xyz, _VEC3), type=_STRIP3)
        rec.send_columns(f"{WORLD}/support_polygon", indexes=idx, columns=[
            rr.ComponentColumn(_D_STRIPS3D, _Arrow(strips), offsets=strip_offsets)])

    def _platform_z(self, rows: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """Height (m) of the platform's top surface under world points ``xy`` at buffered rows
        ``rows`` (+1 mm so the drawing shows), from the platform body's recorded pose."""
        if self._platform is None or len(rows) == 0:
            return np.full(len(rows), _ON_FLOOR_M)
        p0 = self._pos[rows, self._platform]
        q = self._quat[rows, self._platform]
        x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        nx = 2 * (x * z + y * w)          # third column of the rotation matrix: the surface normal
        ny = 2 * (y * z - x * w)
        nz = 1 - 2 * (x * x + y * y)
        return p0[:, 2] - (nx * (xy[:, 0] - p0[:, 0]) + ny * (xy[:, 1] - p0[:, 1])) / nz + _ON_FLOOR_M

    # -- life cycle ----------------------------------------------------------------------------------
    def close(self) -> None:
        """Send what is buffered, flush rerun and finalise the file. Idempotent; also run at
        interpreter exit (``atexit``), so an interrupted program leaves a readable file."""
        if self._closed:
            return
        w0 = time.perf_counter()
        if self._sup is not None:
            self.mode(self._sup.mode)              # the series reaches the end of the run
            if self._on_supervisor in self._sup.listeners:
                self._sup.listeners.remove(self._on_supervisor)
        try:
            self.flush()
        finally:
            self._closed = True
            atexit.unregister(self.close)
            try:
                self.rec.flush()
            finally:
                self.rec.disconnect()
                self.wall_s += time.perf_counter() - w0

    @property
    def closed(self) -> bool:
        """True once :meth:`close` ran."""
        return self._closed

    def cost_per_sim_s(self) -> float:
        """Wall seconds the recorder spent per simulated second recorded so far."""
        sim = (self.twin.clock.now_us - self._t0_us) / US_PER_S
        return self.wall_s / sim if sim > 0 else 0.0

    @property
    def entities(self) -> list[str]:
        """Every entity path this recorder writes on the ``sim_time`` timeline (one row per
        sample each)."""
        out = [s.path for s in self._series] + [f"{BODIES}/{b}" for b in self._body_names]
        for scu in self._feet:
            v = foot_view_path(scu)
            out += [f"{v}/cop/firmware", f"{v}/cop/truth", f"{v}/loads"]
        out += [f"{WORLD}/com", f"{WORLD}/com_ground", f"{WORLD}/cop", f"{WORLD}/support_polygon"]
        return out

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"Recorder({str(self.path)!r}, {state}, samples={self.samples}, chunks={self.chunks_sent})"


# -- helpers -----------------------------------------------------------------------------------------
_D_SCALARS = rr.Scalars.descriptor_scalars()
_D_TRANSLATION = rr.Transform3D.descriptor_translation()
_D_QUATERNION = rr.Transform3D.descriptor_quaternion()
# rerun's own arrow types for Vec3D / Quaternion (fixed-size lists of non-null float32)
_D_POSITIONS2D = rr.Points2D.descriptor_positions()
_D_RADII2D = rr.Points2D.descriptor_radii()
_D_POSITIONS3D = rr.Points3D.descriptor_positions()
_D_STRIPS3D = rr.LineStrips3D.descriptor_strips()
_VEC2 = pa.list_(pa.field("item", pa.float32(), nullable=False), 2)
_VEC3 = pa.list_(pa.field("item", pa.float32(), nullable=False), 3)
_VEC4 = pa.list_(pa.field("item", pa.float32(), nullable=False), 4)
_STRIP3 = pa.list_(pa.field("item", _VEC3, nullable=False))


class _Arrow:
    """A ready pyarrow array as a rerun ``ComponentBatchLike``."""

    __slots__ = ("array",)

    def __init__(self, array: pa.Array) -> None:
        self.array = array

    def as_arrow_array(self) -> pa.Array:
        return self.array


def _vec_array(x: np.ndarray, arrow_type: pa.DataType) -> pa.Array:
    values = pa.array(np.ascontiguousarray(x, dtype=np.float32).ravel())
    return pa.FixedSizeListArray.from_arrays(values, type=arrow_type)


_OFFSETS: dict[tuple[int, int], np.ndarray] = {}


def _offsets(n: int, width: int) -> np.ndarray:
    """Row offsets of ``n`` rows of ``width`` values each (cached)."""
    o = _OFFSETS.get((n, width))
    if o is None:
        o = _OFFSETS[(n, width)] = np.arange(0, n * width + 1, width, dtype=np.int32)
    return o


_KIND_ENTITY = {"box": "boxes", "capsule": "capsules", "sphere": "spheres", "ellipsoid": "ellipsoids",
                "cylinder": "cylinders"}


def _view_xy(xy: Iterable[Sequence[float]]) -> list[list[float]]:
    """Foot frame (x right, y forward, mm) -> 2D view (x right, y down): forward is drawn up."""
    return [[float(p[0]), -float(p[1])] for p in xy]


def _rgba(g: Any) -> list[int]:
    """MuJoCo rgba (0..1 floats) -> 8-bit RGBA."""
    return [max(0, min(255, round(float(v) * 255))) for v in g.rgba]


def _rotate_xyzw(q: Sequence[float], v: Sequence[float]) -> np.ndarray:
    """Rotate ``v`` by the unit quaternion ``q`` (x, y, z, w)."""
    x, y, z, w = (float(c) for c in q)
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return r @ np.asarray(v, dtype=float)


def _shapes(kind: str, gs: list) -> Any:
    """One rerun archetype for the geoms of one kind of one body (poses in the body frame)."""
    pos = np.array([g.pos for g in gs], dtype=float)
    quats = [list(g.quat_xyzw) for g in gs]
    sizes = [np.asarray(g.size, dtype=float) for g in gs]
    colors = [_rgba(g) for g in gs]
    common: dict[str, Any] = {"quaternions": quats, "colors": colors}
    if kind == "box":
        return rr.Boxes3D(half_sizes=[s[:3] for s in sizes], centers=pos, fill_mode="solid", **common)
    if kind == "sphere":
        radii = [[s[0]] * 3 for s in sizes]
        return rr.Ellipsoids3D(half_sizes=radii, centers=pos, fill_mode="solid", **common)
    if kind == "ellipsoid":
        return rr.Ellipsoids3D(half_sizes=[s[:3] for s in sizes], centers=pos, fill_mode="solid", **common)
    if kind == "capsule":
        # MuJoCo: centred on pos along local z, radius size[0], half-length size[1];
        # rerun: starts at the translation and runs ``length`` along local +z.
        starts = [p - _rotate_xyzw(q, (0.0, 0.0, s[1])) for p, q, s in zip(pos, quats, sizes, strict=True)]
        return rr.Capsules3D(lengths=[2 * s[1] for s in sizes], radii=[s[0] for s in sizes],
                             translations=starts, **common)
    if kind == "cylinder":
        return rr.Cylinders3D(lengths=[2 * s[1] for s in sizes], radii=[s[0] for s in sizes], centers=pos,
                              fill_mode="solid", **common)
    return None
