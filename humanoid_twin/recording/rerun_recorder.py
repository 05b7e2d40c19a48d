"""Record a running twin to a rerun ``.rrd`` file, in buffered columns.

    with Twin(seed=0) as twin, Recorder("run.rrd", twin) as rec:
        ...                                   # drive the twin; rec samples every 20 ms
    # the file is complete here, even if the block raised

The recorder registers :meth:`Recorder.sample` on the twin's clock (``twin.every(period_us,
...)``, first at the current instant). Each sample writes one row of plain floats into
preallocated numpy arrays; every ``chunk_s`` of simulated time (and at :meth:`Recorder.flush` /
:meth:`Recorder.close`) the rows are sent with ``rr.send_columns`` on the duration timeline
``sim_time``, one call per entity per chunk, never one ``rr.log`` per value (docs/recording.md).
Static content (robot geometry, platform, floor, foot outlines, sensor positions, series names
and colours) and the default blueprint are sent once, at construction. What is recorded where:
docs/recording.md.

With ``stream_to`` (a viewer's gRPC URL, ``rerun+http://127.0.0.1:9876/proxy``) the same data
also goes live to that viewer, beside the file (``path`` None: to the viewer only): ``serve
--viewer`` / ``--connect`` (docs/serve.md).

The recorder only reads: the Slave databases and firmware state, the Master and bus counters,
and the plant's ground truth (``truth()``, ``body_poses()``, ``servo_angle_deg``). It never calls
the plant's sensor-reading methods (they draw noise), so a recorded run is the same run as an
unrecorded one.
"""

from __future__ import annotations

import atexit
import contextlib
import math
import os
import pathlib
import struct
import sys
import threading
import time
import uuid
from collections.abc import Iterable, Sequence
from itertools import chain
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

# rerun warns once per file that it is streamed without its footer index (on purpose here: the
# close rewrites it with one); keep that line out of the user's terminal unless RUST_LOG is set.
os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd::file_sink=error")
import rerun as rr  # noqa: E402

from humanoid_twin import signals
from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import FOOT_OF_SCU, N_SPECIAL_SENSORS, PWM_PERIOD_US
from humanoid_twin.plant.plant import WXYZ_TO_XYZW
from humanoid_twin.protocol.wire import SCUS
from humanoid_twin.recording.blueprint import default_blueprint, log_keys, log_params
from humanoid_twin.recording.columns import (
    BLUE,
    RED,
    SERIES_WIDTH,
    Column,
    ColumnGroup,
    Tick,
    group_reader,
    master_groups,
    servo_signs,
    start_tick,
    twin_columns,
)
from humanoid_twin.recording.geometry import log_static
from humanoid_twin.recording.paths import BODIES, SUPERVISOR, WORLD, foot_view_path, scu_path

if TYPE_CHECKING:
    from humanoid_twin.plant.truth import GroundTruth
    from humanoid_twin.twin import Twin

__all__ = ["Recorder", "RecorderError", "TIMELINE", "Column", "compact_for", "SHORT_RECORDING_S"]

TIMELINE = "sim_time"

# Sensor loads in the foot view: circle radius (mm) = base + per_newton * F, capped.
_LOAD_RADIUS_BASE_MM = 2.0
_LOAD_RADIUS_MM_PER_N = 1.5
_LOAD_RADIUS_MAX_MM = 30.0
# Largest buffer (rows per chunk): 10 000 rows x ~270 columns x 8 bytes = ~22 MB.
_MAX_CHUNK_ROWS = 10_000
# Simulated seconds per chunk: each entity's rows go to rerun in one send_columns call per chunk
# (a fixed cost per entity and call: one chunk of 30 s sends a 30 s run in ~35 ms, three of 10 s
# in ~50 ms; the buffers hold one chunk, 5.5 MB at 30 s: docs/recording.md).
DEFAULT_CHUNK_S = 30.0
# Height (m) of the CoP point and support polygon above the platform surface, so they show.
_ON_FLOOR_M = 0.001
_NO_COP = (math.nan, math.nan)        # a row's CoP while airborne (no point drawn)
# Recordings up to this many simulated seconds keep rerun's footer index in memory to the end and
# get their footer written by rerun at close (the index grows ~0.04 MB per simulated second with
# 10 s chunks, less with the default 30 s ones: a few MB at most); longer (or open-ended) ones
# stream without it, for flat memory, and are compacted at close (about 1 s per simulated minute).
# compact_for() decides.
SHORT_RECORDING_S = 120.0
# rerun's TextLog levels accepted by log_event
LEVELS = ("TRACE", "DEBUG", "INFO", "WARN", "ERROR", "CRITICAL")


def compact_for(expected_s: float | None) -> bool:
    """The ``compact`` to give a :class:`Recorder` for a run of ``expected_s`` simulated seconds
    (None: unknown or open-ended, as ``serve``): False up to :data:`SHORT_RECORDING_S`."""
    return expected_s is None or expected_s > SHORT_RECORDING_S


class RecorderError(RuntimeError):
    """The recorder cannot record this twin (a missing interface) or this file."""


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


def _chunk_s(period_us: int, chunk_s: float | None) -> float:
    """``chunk_s`` checked (default: :data:`DEFAULT_CHUNK_S`, or fewer seconds at a short
    ``period_us``, itself checked)."""
    if isinstance(period_us, bool) or not isinstance(period_us, int) or period_us <= 0:
        raise ValueError(f"period_us must be a positive int of microseconds, got {period_us!r}")
    if chunk_s is None:     # the default: DEFAULT_CHUNK_S, or fewer seconds at a short period
        chunk_s = min(DEFAULT_CHUNK_S, _MAX_CHUNK_ROWS * period_us / US_PER_S)
    if isinstance(chunk_s, bool) or not isinstance(chunk_s, (int, float)) or not (
        math.isfinite(chunk_s) and chunk_s > 0
    ):
        raise ValueError(f"chunk_s must be a positive number of simulated seconds, got {chunk_s!r}")
    return chunk_s


def _chunk_rows(period_us: int, chunk_s: float) -> int:
    """The rows a chunk of ``chunk_s`` buffers, one per ``period_us``: at most :data:`_MAX_CHUNK_ROWS`."""
    rows = max(1, round(chunk_s * US_PER_S / period_us))
    if rows > _MAX_CHUNK_ROWS:
        raise ValueError(
            f"chunk_s={chunk_s} s at period_us={period_us} buffers {rows} rows; at most "
            f"{_MAX_CHUNK_ROWS} (memory): use a smaller chunk_s"
        )
    return rows


def _checked_scus(twin: Any, scus: Iterable[int]) -> tuple[int, ...]:
    """``twin`` is a Twin and ``scus`` some of its boards, each once."""
    for attr in ("clock", "plant", "network", "link", "master", "slaves", "every"):
        if not hasattr(twin, attr):
            raise RecorderError(f"Recorder needs a Twin (with .{attr}), got {type(twin).__name__}")
    boards = tuple(scus)
    if not boards:
        raise ValueError("scus: record at least one board")
    for s in boards:
        if s not in twin.slaves:
            raise ValueError(f"SCU {s!r} is not a board of this twin (it has {sorted(twin.slaves)})")
    if len(set(boards)) != len(boards):
        raise ValueError(f"scus has duplicates: {boards}")
    return boards


def _check_columns(columns: Sequence[Column]) -> None:
    """Each column records its own path; a sparse column has one series."""
    seen: set[str] = set()
    for c in columns:
        if c.path in seen:
            raise ValueError(f"two columns record {c.path!r}")
        if c.sparse and c.width != 1:
            raise ValueError(f"column {c.path!r}: sparse columns have one series")
        seen.add(c.path)


class Recorder:
    """Buffered rerun recording of a :class:`~humanoid_twin.twin.Twin` (docs/recording.md).

    ``path``: the ``.rrd`` file (checked writable here, before the run). ``period_us``: sampling
    period on the virtual clock (default one PWM period, 20 ms). ``app_id``: rerun application
    id (the viewer keys blueprints by it). ``chunk_s``: simulated seconds per ``send_columns``
    chunk (default :data:`DEFAULT_CHUNK_S`, 30 s, or the 10 000 rows of a shorter period; at most
    10 000 rows). ``scus``: the boards recorded (default all 8). ``blueprint``: send the default layout.
    ``columns``: extra :class:`Column` s (recording/columns.py) sampled with the others.
    ``compact``: stream without rerun's in-memory footer index (flat memory) and rewrite the file
    compacted at :meth:`close` (default); False: rerun writes the final file directly.
    ``stream_to``: a rerun gRPC URL (``rerun+http://HOST:PORT/proxy``) to stream the recording to
    as well, live (a viewer listening there); ``path`` may then be None (no file).

    Counters: ``samples`` (rows taken), ``chunks_sent``, ``wall_s`` (wall time spent in the
    recorder: set-up, sampling, sending, closing; the compaction at close apart, in ``compact_s``),
    :meth:`cost_per_sim_s`.
    """

    def __init__(
        self,
        path: str | pathlib.Path | None,
        twin: Twin,
        period_us: int = PWM_PERIOD_US,
        app_id: str = "humanoid_twin",
        *,
        chunk_s: float | None = None,
        scus: Iterable[int] = SCUS,
        blueprint: bool = True,
        columns: Sequence[Column] = (),
        compact: bool = True,
        stream_to: str | None = None,
    ) -> None:
        t_start = time.perf_counter()
        chunk_s = _chunk_s(period_us, chunk_s)
        if not isinstance(app_id, str) or not app_id:
            raise ValueError(f"app_id must be a non-empty string, got {app_id!r}")
        self.scus: tuple[int, ...] = _checked_scus(twin, scus)
        rows = _chunk_rows(period_us, chunk_s)
        self.twin = twin
        self._rows = rows
        self.period_us = period_us
        self.app_id = app_id
        self.samples = 0
        self.chunks_sent = 0
        self.wall_s = 0.0
        self._closed = False
        self._sending = False
        self.size_before_compaction: int | None = None
        self.compaction_error: str | None = None   # why the compaction at close kept the file as is
        self.compact_s = 0.0          # wall time of the compaction at close (not in wall_s)
        self._t0_us = twin.clock.now_us
        self._n = 0
        self._fell_logged = False

        self._layout((*_supervisor_columns(twin), *columns))
        self._alloc()
        self._open(path, stream_to, compact, blueprint)
        atexit.register(self.close)
        try:
            self._log_static()
        except BaseException:
            self.close()
            raise
        sup = getattr(twin.master, "supervisor", None)
        if sup is not None and hasattr(sup, "listeners"):
            sup.listeners.append(self._on_supervisor)
        twin.every(period_us, self.sample, twin.clock.now_us)
        self.wall_s += time.perf_counter() - t_start

    def _open(self, path: str | pathlib.Path | None, stream_to: str | None, compact: bool,
              blueprint: bool) -> None:
        """The recording stream and its sinks: the file ``path`` (checked: the last check, the
        first thing created), a viewer at ``stream_to``; the default blueprint."""
        if path is None and stream_to is None:
            raise ValueError("a recorder writes a file, streams to a viewer (stream_to), or both")
        self.stream_to = stream_to
        self.compact = compact and path is not None
        self.path = None if path is None else _check_path(path)   # the last check, the first thing created
        self.rec = rr.RecordingStream(self.app_id, recording_id=uuid.uuid4())
        self.params: dict[str, float] = dict(getattr(self.twin, "params", None) or {})   # non-default ones
        bp = default_blueprint(self.scus, self._master_paths, params=bool(self.params)) if blueprint else None
        try:
            # compact: no footer while recording (rerun's file sink keeps the footer's index of
            # every chunk in memory until the end: RSS grew ~0.13 MB per simulated second with
            # it); the compaction at close writes the file again, compacted, with its footer.
            sinks: list[Any] = [] if self.path is None else [rr.FileSink(self.path, write_footer=not compact)]
            if stream_to is not None:
                sinks.append(rr.GrpcSink(stream_to))
            self.rec.set_sinks(*sinks, default_blueprint=bp)
        except RuntimeError as exc:
            raise OSError(f"cannot write the recording {str(self.path or stream_to)!r}: {exc}") from exc

    # -- layout --------------------------------------------------------------------------------------
    def _layout(self, extra: Sequence[Column]) -> None:
        """The buffer layout, derived from the column table: one block of ``width`` buffer
        columns per :class:`Column`, in table order."""
        twin = self.twin
        plant = twin.plant
        for attr in ("truth", "body_poses", "body_pose_views", "geometry", "servo_angle_deg", "tilt_deg"):
            if not hasattr(plant, attr):
                raise RecorderError(f"the twin's plant has no {attr}(): cannot record ground truth")
        self._feet = [s for s in self.scus if s in FOOT_OF_SCU]
        self._master_paths = [p for p, _ in master_groups(twin)]
        self.columns: tuple[Column, ...] = (*twin_columns(twin, self.scus), *extra)
        _check_columns(self.columns)
        # the recorded values: one block of ``width`` columns per Column, grouped by ``every`` (in
        # table order within a group); ``_col``: each Column's first
        self._buffer_order = sorted(self.columns, key=lambda c: c.every)
        self._col: dict[str, int] = {}
        col = 0
        for c in self._buffer_order:
            self._col[c.path] = col
            col += c.width
        self._ncols = col
        # the buffer, in the same order, by reader: a group read once a row for all its columns
        # (recording/columns.py); a batch group's raw values there, its columns derived from
        # them at chunk time (``_batch``); the other values as recorded (``_plain_*``: where)
        # (read, batch group or None, every, buffer column, buffer width, integers first) per
        # reader; a group's integers (``ColumnGroup.ints``) are stored as int64 (``_int_cols``)
        self._readers: list[tuple[Any, ColumnGroup | None, int, int, int, int]] = []
        self._batch: list[tuple[ColumnGroup, int, int]] = []     # (group, buffer column, values column)
        self._plan_buffer()
        self._batch_state: dict[ColumnGroup, Any] = {}
        # the readers of a row, by the set of Column.every values that divide its sample number
        # (a column written every k-th sample is only read then): built once per set, found by
        # the sample number modulo the everys' least common multiple
        self._row_readers: dict[int, list[tuple[list, struct.Struct, int, int]]] = {}
        self._runs_by_due: dict[frozenset[int], list[tuple[list, struct.Struct, int, int]]] = {}
        self._everys = sorted({c.every for c in self.columns})
        self._cycle = math.lcm(*self._everys)
        try:
            self._signs = servo_signs(twin, self.scus)
        except ValueError as exc:
            raise RecorderError(str(exc)) from None
        self._pose_sources(plant)
        self._tick: Tick | None = None

    def _plan_buffer(self) -> None:
        """Each reader's place in the buffer (``_readers``, ``_batch``), the plain values' source
        and destination columns, the integer columns; the buffer's width."""
        src: list[int] = []
        dst: list[int] = []
        ints: list[int] = []
        b = k = 0
        order = self._buffer_order
        while k < len(order):
            read, m, group = group_reader(order, k)
            batch = group if group is not None and group.finish is not None else None
            f0 = self._col[order[k].path]
            width = sum(c.width for c in order[k:k + m])
            if batch is not None:
                self._batch.append((batch, b, f0))
                bw = batch.raw_width
            else:
                src += range(b, b + width)
                dst += range(f0, f0 + width)
                bw = width
            n_int = 0 if group is None else group.ints
            if not 0 <= n_int <= bw:
                raise ValueError(f"column {order[k].path!r}: its group's ints ({n_int}) must be 0..{bw}")
            ints += range(b, b + n_int)
            self._readers.append((read, batch, order[k].every, b, bw, n_int))
            b += bw
            k += m
        self._nbuf = b
        self._int_cols = np.array(ints, dtype=np.intp)
        self._plain_src = np.array(src, dtype=np.intp)
        self._plain_dst = np.array(dst, dtype=np.intp)

    def _pose_sources(self, plant: Any) -> None:
        """The bodies' names and their poses' views, copied into the buffer at each sample, after
        truth() has synced the plant (as flat memoryviews: a row's copy is a slice assignment)."""
        names, _, _ = plant.body_poses()
        self._body_names: tuple[str, ...] = tuple(names)
        self._poses = plant.body_pose_views()
        if not all(v.dtype == np.float64 and v.flags.c_contiguous for v in self._poses):
            raise RecorderError("the plant's body pose views are not contiguous float64: cannot record them")
        self._pose_src = tuple(memoryview(v).cast("B").cast("d") for v in self._poses)
        self._platform = self._body_names.index("platform") if "platform" in self._body_names else None

    def _runs_due(self, k: int) -> list[tuple[list, struct.Struct, int, int]]:
        """The runs of sample number ``k`` (:meth:`_readers_for`), kept by ``k`` modulo the
        cycle when it is short, by the set of ``every`` values due in any case."""
        due = frozenset(e for e in self._everys if k % e == 0)
        runs = self._runs_by_due.get(due)
        if runs is None:
            runs = self._runs_by_due[due] = self._readers_for(due)
        if self._cycle <= _MAX_CHUNK_ROWS:
            self._row_readers[k % self._cycle] = runs
        return runs

    def _readers_for(self, due: frozenset[int]) -> list[tuple[list, struct.Struct, int, int]]:
        """The runs of buffer columns written on a row whose sample number the ``every`` values
        ``due`` divide: for each, its readers (``(read, batch group or None)``: a group read once
        for all its columns), the packer of its values, its offset in the row (bytes) and its
        width."""
        runs: list[tuple[list, struct.Struct, int, int]] = []
        start = end = -1
        readers: list[tuple[Any, ColumnGroup | None]] = []
        fmt = ""
        for read, batch, every, at, width, n_int in self._readers:
            if every not in due:
                continue
            if at != end:           # not contiguous with the run before: a new run
                if readers:
                    runs.append((readers, _packer(fmt, end - start), start * _F64, end - start))
                readers, start, fmt = [], at, ""
            readers.append((read, batch))
            fmt += f"{n_int}q{width - n_int}d"
            end = at + width
        if readers:
            runs.append((readers, _packer(fmt, end - start), start * _F64, end - start))
        return runs

    def _alloc(self) -> None:
        rows, nb = self._rows, len(self._body_names)
        self._t = np.zeros(rows, dtype=np.int64)
        self._t_items = memoryview(self._t)  # type: ignore[arg-type]  # numpy arrays are buffers
        self._k0 = 0          # the sample number of the buffer's first row (then one more a row)
        self._buf = np.zeros((rows, self._nbuf), dtype=np.float64)
        self._buf_bytes = memoryview(self._buf).cast("B")  # type: ignore[arg-type]  # the rows, packed in place (an array is a buffer)
        self._pos = np.zeros((rows, nb, 3), dtype=np.float64)
        self._quat = np.zeros((rows, nb, 4), dtype=np.float64)  # MuJoCo's order (w, x, y, z)
        # flat views of them, one row a slice
        self._pose_dst = tuple(memoryview(a).cast("B").cast("d") for a in (self._pos, self._quat))  # type: ignore[arg-type]  # as above
        self._pose_len = (nb * 3, nb * 4)
        self._com: list[Sequence[float]] = [()] * rows      # each row's CoM (x y z)
        self._cop: list[Sequence[float] | None] = [None] * rows    # its CoP (x y), None airborne
        self._poly: list[Sequence[Sequence[float]]] = [()] * rows      # each row's hull points

    # -- static content ------------------------------------------------------------------------------
    def _log_static(self) -> None:
        rec = self.rec
        log_static(rec, self.twin.plant, self._body_names, self._feet)
        log_keys(rec)
        if self.params:
            log_params(rec, self.params)
        styles: dict[tuple, rr.SeriesLines] = {}     # one archetype per style (many columns share one)
        for c in self.columns:
            key: tuple | None = (c.names, c.colors)
            try:
                style = styles.get(key)  # type: ignore[arg-type]  # None is a key too
            except TypeError:       # a user's column given lists (unhashable): an archetype of its own
                key = style = None
            if style is None:
                kw: dict[str, Any] = {"names": list(c.names), "widths": [SERIES_WIDTH] * len(c.names)}
                if c.colors is not None:
                    kw["colors"] = list(c.colors)
                style = rr.SeriesLines(**kw)
                if key is not None:
                    styles[key] = style
            rec.log(c.path, style, static=True)

    # -- sampling ------------------------------------------------------------------------------------
    def sample(self) -> None:
        """Take one row now (registered on the clock every ``period_us``): every column of the
        table read once, plus the bodies' poses. A no-op once closed."""
        if self._closed:
            return
        w0 = time.perf_counter()
        i = self._n
        k = self.samples
        if i == 0:
            self._k0 = k
        tick = self._tick = start_tick(self.twin, self._tick, self._signs)
        self._t_items[i] = tick.now_us
        runs = self._row_readers.get(k % self._cycle)
        if runs is None:
            runs = self._runs_due(k)
        raw = tick.raw
        row = i * self._nbuf * _F64
        for readers, packer, offset, width in runs:
            vals: list[float] = []
            ext = vals.extend
            for read, batch in readers:
                v = read(tick)
                if batch is not None:
                    raw[batch] = v
                ext(v)
            if len(vals) != width:
                raise RecorderError(f"recorder bug: sampled {len(vals)} values for {width} columns")
            try:
                packer.pack_into(self._buf_bytes, row + offset, *vals)
            except struct.error as exc:     # a value a group declared an int is not one
                raise RecorderError(f"cannot record this row's values: {exc}") from None

        truth = tick.truth
        if truth.fell and not self._fell_logged:      # the first row that sees the robot fallen
            self._log_fell(tick.now_us, truth)
        pos, quat = self._pose_dst
        npos, nquat = self._pose_len
        pos[i * npos:(i + 1) * npos], quat[i * nquat:(i + 1) * nquat] = self._pose_src
        self._com[i] = truth.com  # type: ignore[call-overload]  # an array of 3
        plain = truth.plain()
        self._cop[i] = plain.cop_world_xy
        self._poly[i] = plain.support_polygon_xy
        self._n = i + 1
        self.samples += 1
        self.wall_s += time.perf_counter() - w0
        if self._n == self._rows:
            self.flush()

    # -- events (the supervisor's hook) ---------------------------------------------------------------
    def log_event(self, t_us: int, text: str, level: str = "INFO") -> None:
        """Record a text event at simulated time ``t_us`` on ``supervisor/events`` (a rerun
        ``TextLog``; ``level`` one of TRACE DEBUG INFO WARN ERROR CRITICAL). Shown in the
        default blueprint's "Supervisor" tab. A no-op once closed."""
        if level not in LEVELS:
            raise ValueError(f"level must be one of {LEVELS}, got {level!r}")
        if self._closed:
            return
        rec = self.rec
        rec.set_time(TIMELINE, duration=np.timedelta64(int(t_us), "us"))
        rec.log(f"{SUPERVISOR}/events", rr.TextLog(str(text), level=level))
        rec.reset_time()

    def _log_fell(self, t_us: int, truth: GroundTruth) -> None:
        """The robot's fall as an event (once a recording): when, and how it lies."""
        self._fell_logged = True
        tilt, height_mm = truth.trunk_tilt_deg, truth.trunk_height_m * 1000
        self.log_event(t_us, f"fell: trunk {tilt:.0f} deg, {height_mm:.0f} mm high", "ERROR")

    def _on_supervisor(self, kind: str, t_us: int, value: Any) -> None:
        """The Master supervisor's listener: every mode change and fault as an event."""
        if kind == "mode":
            sup = self.twin.the_master().supervisor
            self.log_event(t_us, f"mode -> {sup.mode_name}", "WARN" if sup.mode_name in ("safe", "estop")
                           else "INFO")
        elif kind == "fault":
            name = getattr(value, "name", str(value))
            self.log_event(t_us, f"fault {name} (node {getattr(value, 'node', '?')})", "ERROR")

    # -- sending -------------------------------------------------------------------------------------
    def flush(self) -> None:
        """Send the buffered rows (one ``send_columns`` per entity) and empty the buffer."""
        n = self._n
        if n == 0 or self._closed:
            return
        w0 = time.perf_counter()
        self._n = 0       # a failure below loses this chunk, never duplicates it
        self._sending = True
        try:
            self._send(n)
        finally:
            self._sending = False
        self.chunks_sent += 1
        self.wall_s += time.perf_counter() - w0

    def _send(self, n: int) -> None:
        rec = self.rec
        t = self._t[:n]
        idx = [rr.TimeColumn(TIMELINE, duration=t.astype("timedelta64[us]"))]
        vals = self._values(n)
        # Scalars and transforms go as ready arrow arrays (``rr.ComponentColumn`` over the
        # archetype's own descriptor): the same data as ``rr.Scalars.columns(...)`` /
        # ``rr.Transform3D.columns(...)``, at a third of their Python cost per call. A column's
        # rows are contiguous in ``vals``: one series is given to arrow as it is (no copy).
        subsets: dict[int, tuple[list, slice, int]] = {1: (idx, slice(None), n)}
        for s in self.columns:
            c0 = self._col[s.path]
            sub = subsets.get(s.every)
            if sub is None:       # the rows of a column written every k-th sample
                rows = self._rows_every(s.every, n)
                sub = subsets[s.every] = (
                    [rr.TimeColumn(TIMELINE, duration=t[rows].astype("timedelta64[us]"))], rows,
                    len(range(n)[rows]))
            idx_s, rows, m = sub
            if m == 0:
                continue
            if s.width == 1:
                col = np.ascontiguousarray(vals[c0, rows])
                if s.sparse:
                    ok = ~np.isnan(col)
                    if not ok.all():  # rows without a value: empty rows, a gap in the plot
                        offsets = np.zeros(m + 1, dtype=np.int32)
                        np.cumsum(ok, out=offsets[1:])
                        rec.send_columns(s.path, indexes=idx_s, columns=[
                            rr.ComponentColumn(_D_SCALARS, _Arrow(pa.array(col[ok])), offsets=offsets)])
                        continue
                data = pa.array(col)
            else:             # row by row: the row's values side by side
                data = pa.array(vals[c0:c0 + s.width, rows].T.ravel())
            rec.send_columns(s.path, indexes=idx_s, columns=[
                rr.ComponentColumn(_D_SCALARS, _Arrow(data), offsets=_offsets(m, s.width))])
        unit = _offsets(n, 1)
        quat = self._quat[:n][:, :, WXYZ_TO_XYZW]
        # by body, each body's rows contiguous, as rerun's float32
        pos32 = np.ascontiguousarray(self._pos[:n].transpose(1, 0, 2), dtype=np.float32)
        quat32 = np.ascontiguousarray(quat.transpose(1, 0, 2), dtype=np.float32)
        for b, name in enumerate(self._body_names):
            rec.send_columns(f"{BODIES}/{name}", indexes=idx, columns=[
                rr.ComponentColumn(_D_TRANSLATION, _Arrow(_vec_array(pos32[b], _VEC3)), offsets=unit),
                rr.ComponentColumn(_D_QUATERNION, _Arrow(_vec_array(quat32[b], _VEC4)), offsets=unit),
            ])
        self._send_feet(idx, vals)
        self._send_world(idx, n, quat)

    def _rows_every(self, every: int, n: int) -> slice:
        """The rows of the ``n`` buffered ones whose sample number ``every`` divides."""
        return slice((-self._k0) % every, n, every)

    def _values(self, n: int) -> np.ndarray:
        """The recorded values of the ``n`` buffered rows, ``(columns, n)`` (a column's rows
        contiguous): the buffer's, and the batch groups' columns derived from their raw values
        (recording/columns.py), for the rows each is written on."""
        t = self._t[:n]
        buf = self._buf[:n]
        if len(self._int_cols):       # the integers' columns hold int64s: as float64
            buf = buf.copy()
            buf[:, self._int_cols] = self._buf[:n].view(np.int64)[:, self._int_cols]
        vals = np.empty((self._ncols, n))
        vals[self._plain_dst] = buf[:, self._plain_src].T
        for group, b0, f0 in self._batch:
            rows = slice(None) if group.every == 1 else self._rows_every(group.every, n)
            if not len(range(n)[rows]):
                continue
            raw = buf[rows, b0:b0 + group.raw_width]
            out, state = group.finish(t[rows], raw, self._batch_state.get(group))  # type: ignore[misc]  # a batch group has finish
            vals[f0:f0 + group.width, rows] = out.T
            self._batch_state[group] = state
        return vals

    def _send_feet(self, idx: list, vals: np.ndarray) -> None:
        rec = self.rec
        col = self._col
        for scu in self._feet:
            base = scu_path(scu)
            v = foot_view_path(scu)
            for who in ("firmware", "truth"):
                x = vals[col[f"{base}/cop/x/{who}"]]
                y = vals[col[f"{base}/cop/y/{who}"]]
                ok = ~(np.isnan(x) | np.isnan(y))
                offsets = np.zeros(len(ok) + 1, dtype=np.int32)
                np.cumsum(ok, out=offsets[1:])
                pts = np.column_stack([x[ok], -y[ok]])        # drawn with forward up
                rec.send_columns(f"{v}/cop/{who}", indexes=idx, columns=[
                    rr.ComponentColumn(_D_POSITIONS2D, _Arrow(_vec_array(pts, _VEC2)), offsets=offsets)])
            k0 = col[f"{base}/force/newton"]
            forces = vals[k0:k0 + N_SPECIAL_SENSORS].T
            radii = np.clip(_LOAD_RADIUS_BASE_MM + _LOAD_RADIUS_MM_PER_N * forces, 0.0, _LOAD_RADIUS_MAX_MM)
            rec.send_columns(f"{v}/loads", indexes=idx, columns=[rr.ComponentColumn(
                _D_RADII2D, _Arrow(pa.array(radii.astype(np.float32).ravel())),
                offsets=_offsets(len(forces), N_SPECIAL_SENSORS))])

    def _send_world(self, idx: list, n: int, quat: np.ndarray) -> None:
        rec = self.rec
        unit = _offsets(n, 1)
        com = np.array(self._com[:n], dtype=np.float64).reshape(n, 3)
        ground = com.copy()
        ground[:, 2] = self._platform_z(np.arange(n), com[:, :2], quat)
        cop = np.array([_NO_COP if c is None else c for c in self._cop[:n]], dtype=np.float64).reshape(n, 2)
        ok = ~np.isnan(cop[:, 0])
        cop_offsets = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(ok, out=cop_offsets[1:])
        cop_pts = np.column_stack([cop[ok], self._platform_z(np.flatnonzero(ok), cop[ok], quat)])
        for path, pts, offsets in ((f"{WORLD}/com", com, unit), (f"{WORLD}/com_ground", ground, unit),
                                   (f"{WORLD}/cop", cop_pts, cop_offsets)):
            rec.send_columns(path, indexes=idx, columns=[
                rr.ComponentColumn(_D_POSITIONS3D, _Arrow(_vec_array(pts, _VEC3)), offsets=offsets)])
        # support polygon: one line strip per row with 2 points or more (closed with more than
        # 2), none for the others; all rows at once
        polys = self._poly[:n]
        k = np.fromiter(map(len, polys), dtype=np.intp, count=n)    # each row's hull points
        has = k >= 2
        m = np.where(has, k + (k > 2), 0)                           # its strip's points
        strip_offsets = np.zeros(n + 1, dtype=np.int32)
        np.cumsum(has, out=strip_offsets[1:])
        total = int(m.sum())
        if total:
            # every row's points, (x, y) each, read as one stream of floats
            hulls = np.fromiter(chain.from_iterable(chain.from_iterable(polys)), dtype=float,
                                count=2 * int(k.sum())).reshape(-1, 2)
            first = np.cumsum(k) - k                                # each row's first point in them
            row = np.repeat(np.arange(n), m)                        # the row of each strip point
            j = np.arange(total) - np.repeat(np.cumsum(m) - m, m)   # its place in its strip
            xy = hulls[first[row] + np.where(j < k[row], j, 0)]     # past the hull: its first point
            xyz = np.column_stack([xy, self._platform_z(row, xy, quat)])
        else:
            xyz = np.zeros((0, 3))
        point_offsets = np.zeros(int(has.sum()) + 1, dtype=np.int32)
        np.cumsum(m[has], out=point_offsets[1:])
        strips = pa.ListArray.from_arrays(pa.array(point_offsets), _vec_array(xyz, _VEC3), type=_STRIP3)
        rec.send_columns(f"{WORLD}/support_polygon", indexes=idx, columns=[
            rr.ComponentColumn(_D_STRIPS3D, _Arrow(strips), offsets=strip_offsets)])

    def _platform_z(self, rows: np.ndarray, xy: np.ndarray, quat: np.ndarray) -> np.ndarray:
        """Height (m) of the platform's top surface under world points ``xy`` at buffered rows
        ``rows`` (+1 mm so the drawing shows), from the platform body's recorded pose (``quat``:
        the buffered quaternions, x y z w)."""
        if self._platform is None or len(rows) == 0:
            return np.full(len(rows), _ON_FLOOR_M)
        p0 = self._pos[rows, self._platform]
        q = quat[rows, self._platform]
        x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        nx = 2 * (x * z + y * w)          # third column of the rotation matrix: the surface normal
        ny = 2 * (y * z - x * w)
        nz = 1 - 2 * (x * x + y * y)
        return p0[:, 2] - (nx * (xy[:, 0] - p0[:, 0]) + ny * (xy[:, 1] - p0[:, 1])) / nz + _ON_FLOOR_M

    # -- life cycle ----------------------------------------------------------------------------------
    def close(self, timeout_s: float = 10.0) -> None:
        """Send what is buffered, flush rerun (waiting at most ``timeout_s``) and finalise the
        file: with ``compact`` (the default) rewrite it with rerun's own ``rrd optimize`` (fewer,
        larger chunks, about 30 % smaller, rerun's footer index written; about 1 s per simulated
        minute), through a temporary file renamed over it.

        Idempotent, and safe to call from a signal handler or a ``finally`` at any point of a run
        (also when the handler interrupted a :meth:`sample` or :meth:`flush`: the rows being sent
        then are written, the half-taken row is dropped). Also run at interpreter exit
        (``atexit``), so an interrupted program leaves a file ``rerun rrd verify`` accepts."""
        if self._closed:
            return
        # the last writes and the compaction are not cut in the middle by SIGINT / SIGTERM: a
        # signal waits for the file to be complete, and stops a compaction under way (the file
        # then stays as recorded), humanoid_twin/signals.py
        with signals.deferred():
            self._close(timeout_s)

    def _close(self, timeout_s: float) -> None:
        w0 = time.perf_counter()
        interrupted_send = self._sending
        try:
            if not interrupted_send:
                self.flush()
        finally:
            self._closed = True
            atexit.unregister(self.close)
            writer_failed = False
            try:
                try:
                    self.rec.flush(timeout_sec=timeout_s)
                except RuntimeError as exc:   # rerun's file writer failed (a full disk, EFBIG)
                    writer_failed = True
                    raise OSError(f"cannot write the recording {str(self.path)!r}: {exc}") from exc
            finally:
                if writer_failed:
                    # with its writer thread gone, rerun's disconnect (and its own shutdown at
                    # interpreter exit) can wait for it forever (seen under load): the disconnect
                    # bounded, rerun's exit handler dropped; the file is lost anyway
                    rr.unregister_shutdown()
                    t = threading.Thread(target=self.rec.disconnect, daemon=True)
                    t.start()
                    t.join(timeout_s)
                else:
                    self.rec.disconnect()
                self.wall_s += time.perf_counter() - w0
                if self.compact and not writer_failed:
                    self._compact()

    def _compact(self) -> None:
        """Compact the closed file. A first SIGINT/SIGTERM lets it finish (about 1 s per
        simulated minute: the file then has rerun's footer and passes ``rerun rrd verify``); a
        second one stops it. A compaction that fails or is stopped (no room for its copy, rerun
        failing, two signals) keeps the file as recorded: complete, readable by rerun and its
        viewer, without the footer index (``compaction_error`` says why; docs/recording.md)."""
        from humanoid_twin.recording.readback import RrdReadError, compact_rrd

        told = [False]

        def stop() -> bool:
            n = signals.pending()
            if n == 1 and not told[0]:
                told[0] = True
                with contextlib.suppress(OSError):
                    sys.stderr.write("humanoid-twin: finishing the recording's compaction (a second "
                                     "signal stops it and keeps the recording uncompacted)\n")
            return n >= 2

        w1 = time.perf_counter()
        try:
            self.size_before_compaction, _ = compact_rrd(self.path, should_stop=stop)  # type: ignore[arg-type]  # a file recording
        except (RrdReadError, OSError) as exc:
            self.compaction_error = " ".join(str(exc).split())[:300]
        self.compact_s = time.perf_counter() - w1

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
        out = [c.path for c in self.columns] + [f"{BODIES}/{b}" for b in self._body_names]
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


def _supervisor_columns(twin: Twin) -> list[Column]:
    """``supervisor/mode``: the Master supervisor's mode number and faults latched (when the
    twin's Master has a supervisor, docs/supervisor.md)."""
    sup = getattr(twin.master, "supervisor", None)
    if sup is None or not hasattr(sup, "read"):
        return []

    def read(t: Tick) -> Sequence[float]:
        mode, _code, _node, nfaults = sup.read()
        return (mode, nfaults)

    return [Column(f"{SUPERVISOR}/mode", ("mode (0 standby 1 self_check 2 ready 3 safe 4 estop)",
                                          "faults latched"), "code / count", read, (BLUE, RED))]


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
_F64 = 8              # bytes of a float64 (the buffer's rows are packed with struct)


def _packer(fmt: str, width: int) -> struct.Struct:
    """The packer of a run of ``width`` values of struct format ``fmt`` (``q`` and ``d`` items,
    native: 8 bytes each, no padding)."""
    p = struct.Struct(fmt)
    if p.size != width * _F64:
        raise RecorderError(f"recorder bug: format {fmt!r} packs {p.size} bytes for {width} values")
    return p


def _offsets(n: int, width: int) -> np.ndarray:
    """Row offsets of ``n`` rows of ``width`` values each (cached)."""
    o = _OFFSETS.get((n, width))
    if o is None:
        o = _OFFSETS[(n, width)] = np.arange(0, n * width + 1, width, dtype=np.int32)
    return o
