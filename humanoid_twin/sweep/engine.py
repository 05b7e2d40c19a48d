"""Grid points, the task that runs one, and the two backends (local process pool, Ray)."""

from __future__ import annotations

import itertools
import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from humanoid_twin import signals
from humanoid_twin.sweep.params import flag, run_arg
from humanoid_twin.sweep.table import SweepError, cells, read_table, table_format, write_table

if TYPE_CHECKING:
    from tqdm import tqdm

BACKENDS = ("local", "ray")
DEFAULT_TIMEOUT_S = 900.0
MAX_POINTS = 100_000         # runs in one sweep (a larger grid is a usage error, not a MemoryError)
STOP_GRACE_S = 2.0           # SIGTERM to the runs in flight, then SIGKILL after this
KILL_MARGIN_S = 15.0         # a run past --timeout + this (it did not end itself) is killed
# columns a re-run may change (timing); every other cell is the same whatever the backend and --jobs
TIMING_COLUMNS = ("wall_s", "rtf")

Task = Callable[["Point"], dict[str, Any]]


def typed_value(text: Any) -> Any:
    """A parameter value as the table stores it: an int, else a float, else the text."""
    if not isinstance(text, str):
        return text
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def key_value(value: Any) -> str:
    """The same parameter value read back from CSV (text) or Parquet/JSON (typed) gives one key."""
    v = typed_value(value)
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, int | float):
        return repr(float(v))
    return "" if v is None else str(v)


@dataclass(frozen=True)
class Point:
    """One run of a sweep: its place in the grid, its parameters (name -> value) and its seed."""

    index: int
    params: tuple[tuple[str, Any], ...]
    seed: int = 0

    def key(self) -> tuple:
        """What identifies this run in a table (so a re-run can skip it)."""
        return tuple((n, key_value(v)) for n, v in self.params) + (("seed", key_value(self.seed)),)

    def row_prefix(self) -> dict[str, Any]:
        return {**{n: typed_value(v) for n, v in self.params}, "seed": self.seed}

    def label(self) -> str:
        return "_".join(f"{n}={v}" for n, v in self.params) + f"_seed={self.seed}"


def grid(params: dict[str, Sequence[Any]], seeds: Iterable[int] = (0,),
         draws: Sequence[tuple[tuple[str, Any], ...]] = ()) -> list[Point]:
    """Every combination of ``params`` values (first name outermost), times each sample of
    ``draws`` (``--randomize``'s robots, humanoid_twin/sweep/params.py: its values after the grid's
    in a point's parameters; none: one sample of nothing), times ``seeds``."""
    names = list(params)
    seeds = list(seeds)
    points: list[Point] = []
    for values in itertools.product(*(params[n] for n in names)):
        for draw in draws or [()]:
            for seed in seeds:
                points.append(Point(len(points), (*zip(names, values, strict=True), *draw), seed))
    return points


def row_key(row: dict[str, Any], names: Sequence[str]) -> tuple | None:
    """The :meth:`Point.key` of a table row, or None when the row lacks one of ``names``."""
    if any(n not in row for n in names) or "seed" not in row:
        return None
    return tuple((n, key_value(row[n])) for n in names) + (("seed", key_value(row["seed"])),)


@dataclass(frozen=True)
class RunCli:
    """Runs one point as ``humanoid-twin run SCENARIO ... --json`` in its own process (the CLI's own
    code path; a crash or a hang is that point's error). ``run_args`` apply to every run;
    ``recordings``: a folder for one ``.rrd`` per run (default: no recording); ``label``: the
    scenario as the row's ``scenario`` names it (default ``scenario``: the sweep makes a user's
    file absolute for its runs, and keeps the reference the user gave for the table)."""

    scenario: str
    run_args: tuple[str, ...] = ()
    recordings: str | None = None
    timeout: float | None = DEFAULT_TIMEOUT_S
    label: str | None = None

    def argv(self, point: Point) -> list[str]:
        argv = [sys.executable, "-m", "humanoid_twin.cli.main", "run", self.scenario, *self.run_args]
        argv += [run_arg(name, value) for name, value in point.params]   # --set NAME=V: a named parameter
        argv += [f"--seed={point.seed}", "--json", "--no-progress"]
        if self.timeout is not None:     # the run ends itself, files closed (run --wall-timeout)
            argv.append(f"--wall-timeout={self.timeout:g}")
        if self.recordings is None:
            argv.append("--no-record")
        else:
            from humanoid_twin.scenarios import recording_name

            argv.append(f"--out={Path(self.recordings) / recording_name(self.scenario, point.label())}")
        return argv

    def __call__(self, point: Point) -> dict[str, Any]:
        backstop = None if self.timeout is None else self.timeout + KILL_MARGIN_S
        try:
            proc = subprocess.run(self.argv(point), capture_output=True, text=True, timeout=backstop,
                                  stdin=subprocess.DEVNULL, preexec_fn=_die_with_parent)
        except subprocess.TimeoutExpired:
            raise RuntimeError(self._timeout_message()) from None
        return self.summary(proc.returncode, proc.stdout, proc.stderr)

    def _timeout_message(self) -> str:
        return f"timeout: the run took more than {self.timeout:g} s"

    def summary(self, returncode: int, stdout: str, stderr: str) -> dict[str, Any]:
        """The ``run --json`` summary of a finished run; RuntimeError (its row's error) otherwise."""
        # exit 0: done; exit 3: the supervisor ended the run in a safe state, a result like any other
        summary: Any = _last_json(stdout) if returncode in (0, 3) else _NO_JSON
        if summary is not _NO_JSON:
            if self.label is not None and isinstance(summary, dict) and "scenario" in summary:
                summary["scenario"] = self.label
            return summary
        raise RuntimeError(self._failure(returncode, stderr))

    def _failure(self, returncode: int, stderr: str) -> str:
        """The error cell of a run that gave no summary: the whole of its stderr (a traceback's
        every line), one line per cell: lines joined by " | "."""
        err = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
        if returncode == 1 and err and "(--wall-timeout)" in err[-1]:
            return self._timeout_message()
        if returncode in (0, 3):    # a run prints its summary last: its process ended before (os._exit)
            why = "ended without its summary (its process ended early: os._exit in user code?)"
            return f"exit {returncode}: {why}" + (f": {' | '.join(err)}" if err else "")
        return f"exit {returncode}: {' | '.join(err) if err else 'no message'}"


_NO_JSON = object()


def _last_json(stdout: str) -> Any:
    """The JSON value of the last non-blank line of ``stdout`` (:data:`_NO_JSON`: none, or not JSON)."""
    lines = [ln for ln in stdout.splitlines() if ln.strip()]
    if not lines:
        return _NO_JSON
    try:
        return json.loads(lines[-1])
    except json.JSONDecodeError:
        return _NO_JSON


def _die_with_parent() -> None:
    """In a run's process, before it starts: SIGTERM when the sweep dies, whatever kills it (Linux
    ``PR_SET_PDEATHSIG``; elsewhere nothing), so no run outlives its sweep (issue 24)."""
    import signal as _signal

    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(_signal.SIGTERM), 0, 0, 0)      # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _local_cli(task: RunCli, points: list[Point], jobs: int) -> Iterable[dict[str, Any]]:
    """The local backend for ``run`` processes: ``jobs`` of them at a time, started here (no pool
    of workers in between), so that stopping the sweep stops them: when the sweep ends for any
    reason (SIGINT, SIGTERM, an error) each run in flight gets SIGTERM (it closes its files and
    ends) and SIGKILL :data:`STOP_GRACE_S` later; a sweep killed hard takes them with it
    (:func:`_die_with_parent`). A run past ``--timeout`` ends itself (``run --wall-timeout``);
    one that does not is killed :data:`KILL_MARGIN_S` later."""
    import tempfile

    todo = list(reversed(points))
    running: dict[subprocess.Popen, tuple[Point, float, Any, Any]] = {}
    try:
        while todo or running:
            while todo and len(running) < jobs:
                p = todo.pop()
                out, err = tempfile.TemporaryFile("w+"), tempfile.TemporaryFile("w+")
                # a SIGINT/SIGTERM during the fork would be raised in the interpreter's at-fork
                # callbacks, which print and drop exceptions (the signal lost, the sweep going
                # on): held back until the run is started and in ``running``, then delivered
                with signals.deferred():
                    proc = subprocess.Popen(task.argv(p), stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                            text=True, preexec_fn=_die_with_parent)
                    running[proc] = (p, time.monotonic(), out, err)
            time.sleep(0.02)
            for proc, (p, t0, out, err) in list(running.items()):
                late = task.timeout is not None and time.monotonic() - t0 > task.timeout + KILL_MARGIN_S
                if proc.poll() is None and not late:
                    continue
                if late:
                    proc.kill()
                    proc.wait()
                del running[proc]
                row = p.row_prefix()
                try:
                    if late:
                        raise RuntimeError(task._timeout_message())
                    out.seek(0)
                    err.seek(0)
                    summary = task.summary(proc.returncode, out.read(), err.read())
                    for k, v in cells(summary).items():
                        row.setdefault(k, v)
                    row["error"] = ""
                except RuntimeError as exc:
                    row["error"] = f"RuntimeError: {exc}".replace("\n", " ")
                out.close()
                err.close()
                yield row
    finally:
        _stop_all(running)


def _stop_all(running: dict[subprocess.Popen, Any]) -> None:
    for proc in running:
        if proc.poll() is None:
            proc.terminate()
    deadline = time.monotonic() + STOP_GRACE_S
    for proc, (_, _, out, err) in running.items():
        try:
            proc.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        out.close()
        err.close()


def run_point(task: Task, point: Point) -> dict[str, Any]:
    """The table row of one point: its parameters, ``seed``, the task's summary and ``error``
    (empty when the run worked). Never raises: a failed run is a row."""
    row = point.row_prefix()
    try:
        summary = task(point)
        error = ""
    except Exception as exc:  # noqa: BLE001 - any failure of a run is that run's row
        summary = {}
        error = f"{type(exc).__name__}: {exc}".replace("\n", " ")
    for k, v in cells(summary).items():
        row.setdefault(k, v)
    row["error"] = error
    return row


@dataclass
class Progress:
    """Runs done / total, failures, ETA on ``stream``: a tqdm bar on a terminal, else a plain
    line every ~10 % (no carriage returns in a log). ``label`` and ``unit`` name the job and
    what it counts (a sweep's runs; ``scripts/compare_laws.py``'s tasks)."""

    total: int
    stream: TextIO | None = None
    label: str = "sweep"
    unit: str = "run"
    done: int = 0
    failed: int = 0
    _t0: float = field(default_factory=time.perf_counter)
    _bar: tqdm[Any] | None = None
    _next_pct: int = 10

    def __post_init__(self) -> None:
        if self.stream is not None and self.total and self.stream.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, unit=self.unit, desc=self.label, file=self.stream)

    def update(self, row: dict[str, Any]) -> None:
        self.done += 1
        self.failed += bool(row.get("error"))
        if self._bar is not None:
            self._bar.set_postfix_str(f"{self.failed} failed", refresh=False)
            self._bar.update(1)
        elif self.stream is not None and (100 * self.done >= self._next_pct * self.total
                                          or self.done == self.total):
            self._next_pct = 10 * (100 * self.done // self.total // 10) + 10
            self.stream.write(self.line() + "\n")
            self.stream.flush()

    def line(self) -> str:
        elapsed = time.perf_counter() - self._t0
        eta = elapsed / self.done * (self.total - self.done) if self.done else math.nan
        return (f"{self.label}: {self.done}/{self.total} {self.unit}s done, {self.failed} failed, "
                f"{elapsed:.0f} s elapsed, ETA {eta:.0f} s")

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def _local(task: Task, points: list[Point], jobs: int) -> Iterable[dict[str, Any]]:
    """One process per run, ``jobs`` at a time; a worker that dies is its run's error."""
    from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    todo = list(reversed(points))
    while todo:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            running: dict[Future[dict[str, Any]], Point] = {}
            broken = False
            while (todo or running) and not broken:
                while todo and len(running) < jobs:
                    p = todo.pop()
                    running[pool.submit(run_point, task, p)] = p
                finished, _ = wait(running, return_when=FIRST_COMPLETED)
                for fut in finished:
                    p = running.pop(fut)
                    try:
                        yield fut.result()
                    except BrokenProcessPool as exc:
                        broken = True
                        row = p.row_prefix()
                        row["error"] = f"BrokenProcessPool: the worker process died ({exc})"
                        yield row
            # a dead worker breaks the pool: the runs in flight are errors, the rest go on in a new pool
            for fut, p in running.items():
                row = p.row_prefix()
                row["error"] = "BrokenProcessPool: a worker process died during this run"
                fut.cancel()
                yield row


LOOPBACK = "127.0.0.1"


def _loopback_ray() -> dict[str, Any]:
    """What keeps a local Ray (no ``--address``) on the loopback interface, as every other server
    of the project: Ray binds its GCS, raylet and workers to the node's network address unless
    told that this is not a cluster (its ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0``, read by Ray's
    own processes, which inherit it) and given 127.0.0.1 as the node's address. Returns the
    ``ray.init`` arguments."""
    os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
    from ray._private import ray_constants

    ray_constants.ENABLE_RAY_CLUSTER = False      # read at its import: this process may have it
    return {"_node_ip_address": LOOPBACK, "dashboard_host": LOOPBACK}


def _ray(task: Task, points: list[Point], jobs: int | None, address: str | None
         ) -> Iterable[dict[str, Any]]:
    """One Ray task (1 CPU) per run; ``address`` joins a cluster, None starts a local Ray."""
    import ray

    started = False
    if not ray.is_initialized():
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False,
                                  "logging_level": "ERROR"}
        if address is None:
            kwargs["num_cpus"] = jobs or os.cpu_count() or 1
            kwargs.update(_loopback_ray())
        try:
            ray.init(address=address, **kwargs)
        except Exception as exc:  # noqa: BLE001 - Ray's own flavours: no cluster, a bad address ...
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0][:200]
            raise SweepError(f"--backend ray{f' --address {address}' if address else ''}: cannot join "
                             f"a Ray cluster: {type(exc).__name__}: {first}") from None
        started = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=1)(run_point)
        refs = {remote.remote(task, p): p for p in points}
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                try:
                    yield ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - a worker that died is its run's error
                    row = refs[ref].row_prefix()
                    row["error"] = f"{type(exc).__name__}: {exc}".splitlines()[0]
                    yield row
    finally:
        if started:
            ray.shutdown()


def check_backend(backend: str) -> None:
    """:class:`SweepError` when ``backend`` is unknown or its package is missing."""
    if backend not in BACKENDS:
        raise SweepError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    if backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise SweepError("the ray backend needs Ray: pip install 'humanoid-twin[ray]'") from None


def run_sweep(points: Sequence[Point], task: Task, out: Path, *, jobs: int | None = None,
              backend: str = "local", address: str | None = None, progress: TextIO | None = None,
              known: dict[str, str | None] | None = None) -> list[dict[str, Any]]:
    """Run every point of ``points`` not already in ``out`` (rows with an ``error`` are run again),
    rewriting ``out`` atomically after each finished run; returns the rows of ``points`` in their
    order (those read from ``out`` and the new ones).

    ``known``: every column a table of this kind can have (name -> its kind, ``int``, ``float``,
    ``bool``, ``string``, or None: what its name or values say): a Parquet ``out`` carries each,
    empty where this sweep has none, so that a folder of sweeps over different parameters reads
    back whole as one dataset (docs/sweeps.md); a CSV ``out`` only the columns of its rows."""
    table_format(out)
    check_backend(backend)
    names = [n for n, _ in points[0].params] if points else []
    kept, todo = _plan_runs(points, names, read_table(out) if out.exists() else [])
    jobs = jobs or os.cpu_count() or 1
    bar = Progress(len(todo), progress)
    if progress is not None and len(todo) < len(points):
        progress.write(f"sweep: {len(points) - len(todo)} of {len(points)} runs already in {out}, "
                       f"{len(todo)} to run\n")
    table = _Table(out, kept, known)
    try:
        if todo:
            index = {p.key(): p.index for p in todo}
            for row in _start(task, todo, jobs, backend, address):
                table.add(index[row_key(row, names)], row)  # type: ignore[index]  # a row's key
                bar.update(row)
        elif not out.exists():
            table.write()
    finally:
        bar.close()
    return table.rows_of(points, names)


def _plan_runs(points: Sequence[Point], names: list[str], old: list[dict[str, Any]]
               ) -> tuple[list[dict[str, Any]], list[Point]]:
    """The rows of the table ``old`` that this sweep keeps (in the table's order: the finished
    runs, and the rows of other grids) and the points it runs (not in it, or with an error)."""
    old_by_key = {}
    for row in old:
        k = row_key(row, names)
        if k is not None and not row.get("error"):
            old_by_key[k] = row
    wanted = {p.key() for p in points}
    # rows of the table that this sweep does not run again, in the table's order
    kept = [r for r in old if row_key(r, names) not in wanted or row_key(r, names) in old_by_key]
    todo = [p for p in points if p.key() not in old_by_key]
    return kept, todo


def _start(task: Task, todo: list[Point], jobs: int, backend: str, address: str | None
           ) -> Iterable[dict[str, Any]]:
    """The rows of the runs of ``todo`` as they finish, on ``backend``."""
    if backend != "local":
        return _ray(task, todo, jobs, address)
    if isinstance(task, RunCli):
        return _local_cli(task, todo, jobs)
    return _local(task, todo, jobs)


class _Table:
    """The sweep's table ``out``, rewritten atomically after each finished run: the rows kept
    from it, then the new ones in grid order (the same table whatever order the runs finish in).
    ``known``: see :func:`run_sweep` (a Parquet table carries every column it names)."""

    def __init__(self, out: Path, kept: list[dict[str, Any]], known: dict[str, str | None] | None) -> None:
        self.out, self.kept, self.known = out, kept, known
        self.new: dict[int, dict[str, Any]] = {}
        self.parquet = table_format(out) == "parquet"
        self.kinds = {c: k for c, k in (known or {}).items() if k is not None}

    def add(self, index: int, row: dict[str, Any]) -> None:
        """The row of grid point ``index``, written."""
        self.new[index] = row
        self.write()

    def write(self) -> None:
        # columns from the rows in grid order: the same table whatever order the runs finish in
        rows = self.kept + [self.new[i] for i in sorted(self.new)]
        columns = _columns(rows)
        if self.parquet and self.known:
            columns += [c for c in self.known if c not in columns]
        write_table(self.out, rows, _ordered(columns), self.kinds if self.parquet else None)

    def rows_of(self, points: Sequence[Point], names: list[str]) -> list[dict[str, Any]]:
        """The rows of ``points``, in their order (kept or new)."""
        by_key = {row_key(r, names): r for r in self.kept}
        by_key.update({row_key(r, names): r for r in self.new.values()})
        return [by_key[p.key()] for p in points]


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    cols: list[str] = []
    seen: set[str] = set()
    for row in rows:
        for c in row:
            if c not in seen:
                seen.add(c)
                cols.append(c)
    return cols


def _ordered(columns: list[str]) -> list[str]:
    """``error`` last."""
    return [c for c in columns if c != "error"] + (["error"] if "error" in columns else [])


__all__ = ["Point", "RunCli", "SweepError", "grid", "run_sweep", "run_point", "typed_value", "BACKENDS",
           "TIMING_COLUMNS", "check_backend", "flag", "key_value", "row_key"]
