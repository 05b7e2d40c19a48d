"""Read a twin recording (``.rrd``) back with rerun's own loader (``rerun.chunk.RrdReader``).

For tests and for users who want numbers out of a recording without the viewer. Entity paths
are returned without the leading ``/`` (as the recorder names them: ``scu/1_right_leg/...``).
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import time
import uuid
from collections import defaultdict
from collections.abc import Callable

import numpy as np

__all__ = [
    "RrdReadError",
    "read_rrd_entities",
    "read_rrd_rows",
    "read_rrd_scalars",
    "rrd_has_blueprint",
    "verify_rrd",
]


class RrdReadError(ValueError):
    """A file that is not a readable rerun recording, or a missing entity."""


def _reader(path: str | pathlib.Path):  # noqa: ANN202 - rerun type, imported lazily
    p = pathlib.Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording {str(p)!r} does not exist")
    from rerun.chunk import RrdReader

    try:
        return RrdReader(p)
    except Exception as exc:  # rerun raises its own ValueError/IOError flavours
        raise RrdReadError(f"{str(p)!r} is not a readable rerun recording: {exc}") from exc


def _chunks(path: str | pathlib.Path) -> list:
    reader = _reader(path)
    try:
        return list(reader.stream())
    except Exception as exc:
        raise RrdReadError(f"{str(path)!r}: cannot read the recording's chunks: {exc}") from exc


def _name(entity_path: str) -> str:
    return entity_path.lstrip("/")


def read_rrd_entities(path: str | pathlib.Path) -> set[str]:
    """Every entity path that holds data (static or on a timeline) in the file's recording."""
    return {_name(c.entity_path) for c in _chunks(path) if not _name(c.entity_path).startswith("__")}


def read_rrd_rows(path: str | pathlib.Path, timeline: str = "sim_time") -> dict[str, int]:
    """Number of rows per entity on ``timeline`` (static data not counted)."""
    rows: dict[str, int] = defaultdict(int)
    for c in _chunks(path):
        if not c.is_static and timeline in c.timeline_names:
            rows[_name(c.entity_path)] += c.num_rows
    return dict(rows)


def rrd_has_blueprint(path: str | pathlib.Path) -> bool:
    """True when the file carries a blueprint (the default layout the viewer opens with)."""
    return bool(_reader(path).blueprints())


def read_rrd_scalars(
    path: str | pathlib.Path, entity: str, timeline: str = "sim_time"
) -> tuple[np.ndarray, np.ndarray]:
    """``(t_s, values)`` of a ``Scalars`` entity: times in seconds (sorted) and values, shape
    ``(rows,)`` for one series or ``(rows, k)`` for ``k`` series per row."""
    want = "/" + entity.lstrip("/")
    times: list[np.ndarray] = []
    values: list[list[list[float]]] = []
    for c in _chunks(path):
        if c.entity_path != want or c.is_static:
            continue
        rb = c.to_record_batch()
        names = rb.schema.names
        if timeline not in names or "Scalars:scalars" not in names:
            continue
        t = rb.column(names.index(timeline)).cast("int64").to_numpy(zero_copy_only=False)
        times.append(t.astype(np.float64) / 1e9)
        values.extend(rb.column(names.index("Scalars:scalars")).to_pylist())
    if not times:
        raise RrdReadError(f"{str(path)!r}: no scalars for entity {entity!r} on timeline {timeline!r}")
    t_all = np.concatenate(times)
    order = np.argsort(t_all, kind="stable")
    width = max(len(v) for v in values)
    arr = np.full((len(values), width), np.nan)
    for i, v in enumerate(values):
        arr[i, : len(v)] = v
    arr = arr[order]
    return t_all[order], (arr[:, 0] if width == 1 else arr)


def rerun_executable() -> pathlib.Path:
    """The ``rerun`` executable shipped with rerun-sdk (the ``rerun_cli`` package)."""
    override = os.environ.get("RERUN_CLI_PATH")
    if override:
        return pathlib.Path(override)
    import rerun_cli

    exe = pathlib.Path(rerun_cli.__file__).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if not exe.is_file():
        raise RrdReadError(f"the rerun executable is not installed with rerun-sdk (looked for {exe})")
    return exe


def verify_rrd(path: str | pathlib.Path, timeout_s: float = 120.0, check_footers: bool = True) -> None:
    """Check with rerun's own ``rerun rrd verify`` that every column of the file deserialises as
    its declared component type (what the viewer will do). ``RrdReadError`` with rerun's message
    otherwise. ``check_footers=False``: a file without rerun's footer index is accepted (a long
    recording whose compaction failed or was stopped, docs/recording.md)."""
    p = pathlib.Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"recording {str(p)!r} does not exist")
    res = subprocess.run(
        [str(rerun_executable()), "rrd", "verify", f"--check-footers={str(check_footers).lower()}", str(p)],
        capture_output=True, text=True, timeout=timeout_s)
    if res.returncode != 0:
        raise RrdReadError(f"rerun rrd verify {str(p)!r} failed: {(res.stderr or res.stdout).strip()}")


def compact_rrd(path: str | pathlib.Path, timeout_s: float = 600.0,
                should_stop: Callable[[], bool] | None = None) -> tuple[int, int]:
    """Rewrite ``path`` with rerun's own ``rerun rrd optimize`` (chunks merged into fewer, larger
    ones: the viewer loads it faster and it is smaller). Written to a temporary file beside it and
    renamed over it only when rerun succeeded, so the original survives any failure (then
    ``RrdReadError``), a timeout, and ``should_stop()`` turning true (polled every 50 ms: rerun is
    stopped, ``RrdReadError``). Returns the sizes (bytes) before and after."""
    p = pathlib.Path(path)
    before = p.stat().st_size
    # a short name whatever the recording's (a 255-byte name must still be compacted)
    tmp = p.with_name(f".compact-{os.getpid()}-{uuid.uuid4().hex[:8]}.rrd")
    try:
        with subprocess.Popen([str(rerun_executable()), "rrd", "optimize", str(p), "-o", str(tmp)],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) as proc:
            deadline = time.monotonic() + timeout_s
            try:
                while proc.poll() is None:
                    if should_stop is not None and should_stop():
                        raise RrdReadError(f"rerun rrd optimize {str(p)!r}: stopped by a signal")
                    if time.monotonic() > deadline:
                        raise RrdReadError(f"rerun rrd optimize {str(p)!r}: no result in {timeout_s:g} s")
                    time.sleep(0.05)
            except BaseException:
                proc.kill()
                proc.wait()
                raise
            out = proc.stdout.read() if proc.stdout is not None else ""
        if proc.returncode != 0 or not tmp.is_file():
            last = out.strip().splitlines()[-1] if out.strip() else f"exit {proc.returncode}"
            raise RrdReadError(f"rerun rrd optimize {str(p)!r} failed: {last}")
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)
    return before, p.stat().st_size
