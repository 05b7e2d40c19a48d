"""``humanoid-twin sweep``: argument checks (all before anything is written) and the command."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from humanoid_twin.cli.argtypes import count, wall_seconds
from humanoid_twin.cli.options import SEED_MAX, cannot_write_in, scenario_arg
from humanoid_twin.sweep.engine import (
    BACKENDS,
    DEFAULT_TIMEOUT_S,
    MAX_POINTS,
    RunCli,
    check_backend,
    flag,
    grid,
    key_value,
    run_sweep,
)
from humanoid_twin.sweep.params import is_set_name, run_arg
from humanoid_twin.sweep.table import SweepError, read_table, table_format

# run options a sweep sets itself, or that would make every run write the same file
NOT_PARAMS = {"command", "scenario", "out", "no_record", "can_log", "serial_log", "json", "no_progress"}


def add_sweep_parser(sub: argparse._SubParsersAction[Any]) -> argparse.ArgumentParser:
    """The ``sweep`` subcommand (``sub``: the CLI's subparsers). Options it does not know are
    ``run``'s, given to every run."""
    p = sub.add_parser(
        "sweep",
        allow_abbrev=False,   # --seed (run's) must not be read as --seeds (sweep's)
        help="run a grid of runs in parallel (this machine or a Ray cluster) into one table",
        description="Run SCENARIO for every combination of the --param values times seeds 0..N-1, "
        "in parallel, into one table (one row per run: the parameters, seed, every key of "
        "`run --json`, error). Any other `run` option (e.g. --duration 3 --tilt 5) applies to "
        "every run. See docs/sweeps.md.",
    )
    p.add_argument("scenario", type=scenario_arg, metavar="SCENARIO",
                   help="the scenario to run: a built-in one, FILE.py:NAME or MODULE:NAME (as run's)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=V1,V2,...",
                   help="a run option (its flag without dashes: tilt, T, motion, perna, control, fault, "
                   "seed ...), a named parameter (humanoid-twin params; a glob sets every match) or "
                   "scenario.FIELD (a scenario of yours' own field), and its values; repeat for a grid")
    p.add_argument("--randomize", action="append", default=[], metavar="NAME=uniform(A,B)|normal(MU,SIGMA)",
                   help="draw a named parameter for each of --samples runs (seeded; docs/parameters.md); "
                   "repeatable")
    p.add_argument("--samples", type=count, metavar="N", help="--randomize: how many robots to draw")
    p.add_argument("--seeds", type=count, default=1, metavar="N", help="seeds 0..N-1 (default 1)")
    p.add_argument("--jobs", type=count, metavar="N", help="runs at a time (default: the cores here; "
                   "ray: the CPUs of the local Ray)")
    p.add_argument("--backend", choices=BACKENDS, default="local",
                   help="local (default): a process per run here; ray: a Ray cluster (the ray extra)")
    p.add_argument("--address", help="ray: the cluster to join (e.g. HOST:6379 or auto; "
                   "default: start a local Ray)")
    p.add_argument("--out", type=Path, required=True, metavar="FILE.csv|FILE.parquet",
                   help="the table; runs already in it are skipped (runs with an error run again)")
    p.add_argument("--recordings", type=Path, metavar="DIR", help="write one .rrd per run into DIR "
                   "(default: no recordings)")
    p.add_argument("--timeout", type=wall_seconds, default=DEFAULT_TIMEOUT_S, metavar="S",
                   help=f"a run taking longer is stopped and is a row with an error (default "
                   f"{DEFAULT_TIMEOUT_S:g} s)")
    p.add_argument("--plot", type=Path, metavar="FILE.png", help="plot --metric against --x")
    p.add_argument("--metric", metavar="KEY", help="--plot: the column on the y axis (e.g. "
                   "cop_margin_min_mm)")
    p.add_argument("--x", metavar="PARAM", help="--plot: the parameter on the x axis")
    p.add_argument("--no-progress", action="store_true", help="no progress on stderr")
    return p


def _writable_dir(path: Path, what: str) -> None:
    """``path`` may be written (its directory exists and is writable; an existing ``path`` is a
    regular file, or a link to one: :func:`humanoid_twin.containment.output_target`)."""
    from humanoid_twin.containment import OutputPathError, output_target

    try:
        parent = output_target(path, what).parent
    except OutputPathError as exc:
        raise SweepError(str(exc)) from None
    if not parent.is_dir():
        raise SweepError(f"{what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise SweepError(f"{what} {path} is not writable")
    why = cannot_write_in(parent)
    if why is not None:
        raise SweepError(f"{what} {path}: cannot write in {parent}: {why}")


def parse_params(specs: list[str]) -> dict[str, list[str]]:
    """``["tilt=0,5", "T=1"]`` -> ``{"tilt": ["0", "5"], "T": ["1"]}``; :class:`SweepError` on a
    malformed spec or a name given twice."""
    params: dict[str, list[str]] = {}
    for spec in specs:
        name, eq, values = spec.partition("=")
        name = name.strip().lstrip("-")
        vals = [v.strip() for v in values.split(",")]
        if not eq or not name or any(v == "" for v in vals):
            raise SweepError(f"--param {spec!r}: expected NAME=V1,V2,... (no empty values)")
        if name in params:
            raise SweepError(f"--param {name} given twice")
        if len(set(vals)) != len(vals):
            raise SweepError(f"--param {spec!r}: a value is repeated")
        typed = [key_value(v) for v in vals]     # 10 and 10.0 are one grid point (issue 24)
        if len(set(typed)) != len(typed):
            dup = next(v for i, v in enumerate(vals) if typed[i] in typed[:i])
            raise SweepError(f"--param {spec!r}: a value is repeated ({dup} is the same value as an "
                             "earlier one: the same run twice)")
        params[name] = vals
    return params


def plan_sweep(args: argparse.Namespace, parser: argparse.ArgumentParser
               ) -> tuple[dict[str, list[str]], Sequence[int], RunCli]:
    """Check every input of ``sweep`` (``parser``: the CLI's, whose ``run`` checks each value);
    returns the grid, the seeds and the task. Raises :class:`SweepError` (or exits 2 through the
    parser) before anything is written."""
    run_args = list(args.run_args)
    label = _resolve_scenario(args)       # the table's scenario: the reference as the user gave it
    base, given = _check_run_args(args, parser, run_args)
    params, seeds = _grid(args)
    args.draws = _randomize(args)          # --randomize ... --samples N: the drawn values
    for name, values in params.items():
        _check_param(args, parser, run_args, name, values, base, given)
    _check_size(args, params, seeds)
    _check_every_point(args, parser, run_args, params, seeds)
    _check_table(args.out)
    _check_where(args)
    _check_plot(args, params)
    recordings = None if args.recordings is None else str(args.recordings)
    return params, seeds, RunCli(args.scenario, tuple(run_args), recordings, args.timeout, label=label)


def _resolve_scenario(args: argparse.Namespace) -> str:
    """A user's file (``FILE.py:NAME``) made absolute in ``args.scenario``: found by every run,
    whatever its cwd. Returns the scenario as the user gave it (the table's)."""
    from humanoid_twin.scenarios import split_reference

    label = args.scenario
    where, name = split_reference(args.scenario)
    if where.endswith(".py"):
        args.scenario = f"{Path(where).expanduser().resolve()}:{name}"
    return label


def _check_run_args(args: argparse.Namespace, parser: argparse.ArgumentParser, run_args: list[str]
                    ) -> tuple[dict[str, Any], dict[str, Any]]:
    """The run options given for every run parsed by ``run``'s parser; those a sweep sets itself
    refused. Returns ``run``'s defaults and the values given."""
    base = vars(parser.parse_args(["run", args.scenario, "--no-record"]))
    given = vars(parser.parse_args(["run", args.scenario, "--no-record", *run_args]))
    if given["can_log"] is not None:
        raise SweepError("--can-log is per run: use --recordings DIR for one recording per run")
    if given["serial_log"] is not None:
        raise SweepError("--serial-log is per run: run the one you want to log with `run --serial-log FILE`")
    if given["out"] is not None:
        raise SweepError("--out is the sweep's table; use --recordings DIR for the runs' recordings")
    if given["seed"] != base["seed"] or any(a.startswith("--seed") for a in run_args):
        raise SweepError("--seed: use --seeds N (seeds 0..N-1) or --param seed=S1,S2,...")
    return base, given


def _grid(args: argparse.Namespace) -> tuple[dict[str, list[str]], Sequence[int]]:
    """The ``--param`` s (by column name) and the seeds (``--seeds N`` or ``--param seed=...``)."""
    # a parameter's column is named as the option's dest (pic_mhz): --param pic-mhz or pic_mhz
    params = {n.replace("-", "_"): v for n, v in parse_params(args.param).items()}
    if len(params) != len(args.param):
        raise SweepError("a --param is given twice (pic-mhz and pic_mhz are one option)")
    # a range, not a list: --seeds 100000000 is refused by the size check at once (a list of them
    # took 15 s and 4 GB first)
    seeds: Sequence[int] = range(args.seeds)
    if "seed" in params:
        if args.seeds != 1:
            raise SweepError("give either --seeds N or --param seed=..., not both")
        try:
            seeds = [int(v) for v in params.pop("seed")]
        except ValueError:
            raise SweepError("--param seed: seeds are whole numbers") from None
    return params, seeds


def _check_param(args: argparse.Namespace, parser: argparse.ArgumentParser, run_args: list[str], name: str,
                 values: list[str], base: dict[str, Any], given: dict[str, Any]) -> None:
    """One ``--param``: a named parameter or a scenario's field (``--set NAME=V``), or a run option
    a sweep can vary, not also given as a run option, each value through ``run``'s own checks."""
    if is_set_name(name):              # a named parameter or a scenario's field: --set NAME=V
        _check_set_param(name, values)
        return
    if name not in base or name in NOT_PARAMS:
        options = sorted(d.replace("_", "-") for d in base if d not in NOT_PARAMS)
        raise SweepError(f"--param {flag(name)[2:]}: not a run option a sweep can vary (choose from "
                         f"{' '.join(options)}){_did_you_mean(flag(name)[2:], options)}")
    if given[name] != base[name]:
        raise SweepError(f"{flag(name)} is given both as a run option and as --param {flag(name)[2:]}")
    for v in values:      # run's own checks, one line and exit 2 on a bad value
        parser.parse_args(["run", args.scenario, "--no-record", *run_args, f"{flag(name)}={v}"])


def _check_size(args: argparse.Namespace, params: dict[str, list[str]], seeds: Sequence[int]) -> None:
    """At most :data:`MAX_POINTS` runs; every seed in range."""
    n_points = len(seeds) * max(1, len(args.draws))
    for values in params.values():
        n_points *= len(values)
    if n_points > MAX_POINTS:
        raise SweepError(f"{n_points} runs: a sweep runs at most {MAX_POINTS} (split it)")
    if any(not 0 <= sd <= SEED_MAX for sd in seeds):
        raise SweepError(f"--param seed: seeds are 0..{SEED_MAX}")


def _check_table(out: Path) -> None:
    """``--out``: a table's format, in a writable place; an existing file is a sweep table."""
    table_format(out)
    _writable_dir(out, "--out")
    if out.exists():
        try:
            rows = read_table(out)
        except Exception as exc:  # noqa: BLE001 - whatever the reader says, it is not a table
            raise SweepError(f"--out {out} exists and is not a sweep table ({exc})") from None
        _check_is_sweep_table(out, rows)


def _check_where(args: argparse.Namespace) -> None:
    """Where the runs run (``--backend``, a Ray cluster's ``--address``) and where their
    recordings go (``--recordings DIR``: a directory, or one that can be made, writable)."""
    check_backend(args.backend)
    if args.address is not None and args.backend != "ray":
        raise SweepError("--address is for --backend ray")
    if args.backend == "ray" and args.address is not None:
        check_ray_address(args.address)
    if args.recordings is None:
        return
    if args.recordings.exists() and not args.recordings.is_dir():
        raise SweepError(f"--recordings {args.recordings} is not a directory")
    where = args.recordings if args.recordings.exists() else args.recordings.resolve().parent
    while not where.exists():
        where = where.parent
    if not os.access(where, os.W_OK):
        raise SweepError(f"--recordings {args.recordings} is not writable")
    why = cannot_write_in(where)
    if why is not None:
        raise SweepError(f"--recordings {args.recordings}: cannot write in {where}: {why}")


def _check_plot(args: argparse.Namespace, params: dict[str, list[str]]) -> None:
    """``--plot FILE.png`` with ``--metric KEY`` and ``--x PARAM`` (a parameter of this sweep;
    ``args.x`` made its column's name), or none of the three."""
    if args.plot is None:
        if args.metric is not None or args.x is not None:
            raise SweepError("--metric and --x go with --plot FILE.png")
        return
    if args.plot.suffix.lower() != ".png":
        raise SweepError(f"--plot {args.plot}: a plot ends in .png")
    _writable_dir(args.plot, "--plot")
    if args.metric is None or args.x is None:
        raise SweepError("--plot needs --metric KEY and --x PARAM")
    args.x = args.x.replace("-", "_")     # the column's name (--x pic-mhz: pic_mhz)
    if args.x not in params and args.x != "seed" and not any(r.split("=")[0].strip() == args.x
                                                              for r in args.randomize):
        given = " ".join(params) or "it has no --param"
        raise SweepError(f"--x {args.x}: not a --param of this sweep ({given})")


def _did_you_mean(name: str, choices: list[str]) -> str:
    import difflib

    close = difflib.get_close_matches(name, choices, n=1)
    return f"; did you mean {close[0]}?" if close else ""


def option_kind(action: argparse.Action) -> str:
    """The kind of a ``run`` option's values in a table (``int``, ``float``, ``string``): what its
    own type makes of a value (``1``); text for a list (``--fault``) or a type that refuses it."""
    if action.type is None or isinstance(action, argparse._AppendAction):
        return "string"
    try:
        value = action.type("1")  # type: ignore[operator]  # a run option's type is a callable
    except (argparse.ArgumentTypeError, TypeError, ValueError):
        return "string"
    if isinstance(value, bool):
        return "bool"
    return "int" if isinstance(value, int) else "float" if isinstance(value, float) else "string"


def known_columns(parser: argparse.ArgumentParser, params: dict[str, list[str]]) -> dict[str, str | None]:
    """Every column a sweep table can have, and its kind where an option gives it: every run option
    a sweep can vary (this sweep's ``params`` first), ``seed``, every summary column
    (``humanoid_twin.summary.table_columns``), ``error`` (:func:`~humanoid_twin.sweep.engine.run_sweep`'s
    ``known``: a Parquet table carries them all), and every named parameter of the robot (a column
    of its own when a sweep varies it, ``params_NAME`` when a run set it)."""
    from humanoid_twin.params import registry
    from humanoid_twin.summary import table_columns

    run = parser.run_parser  # type: ignore[attr-defined]  # set by the CLI's parser
    options = {a.dest: option_kind(a) for a in run._actions     # argparse has no public list of them
               if a.option_strings and a.dest not in NOT_PARAMS and a.dest != "help"
               and a.nargs != 0}
    known: dict[str, str | None] = {name: options.get(name) for name in params}
    known.update({name: kind for name, kind in options.items() if name not in known and name != "seed"})
    # every named parameter of the robot, as a --param column and as a run's params_NAME
    names = registry().names()
    known.update({name: "float" for name in names if name not in known})
    known["seed"] = "int"
    known.update({c: None for c in table_columns() if c not in known})
    known.update({f"params_{name}": "float" for name in names})
    known["error"] = "string"
    return known


def _check_every_point(args: argparse.Namespace, parser: argparse.ArgumentParser, run_args: list[str],
                       params: dict[str, list[str]], seeds: Sequence[int]) -> None:
    """Every grid point through ``run``'s own checks (the planners' limits, the platform's tilt,
    --duration, the faults' composition, a loadable --law / --host-controller ...) before any
    run starts: one line, exit 2 (issue 24). A seed is checked once, on the first point."""
    import itertools

    from humanoid_twin.cli.run_checks import check_run_inputs
    from humanoid_twin.scenarios import arm_wall_timeout, disarm_wall_timeout

    names = list(params)
    loaded: set[tuple] = set()
    drawn = [run_arg(n, v) for n, v in (args.draws[0] if args.draws else ())]   # the first robot drawn
    for i, values in enumerate(itertools.product(*(params[n] for n in names))):
        for seed in seeds if i == 0 else seeds[:1]:
            argv = ["run", args.scenario, "--no-record", *run_args, *drawn,
                    *(run_arg(n, v) for n, v in zip(names, values, strict=True)), f"--seed={seed}"]
            ns = parser.parse_args(argv)
            key = (tuple(ns.law), ns.host_controller)
            # each point's check (a user's scenario imported, planned and sized here) within
            # --timeout, as each run is (its --wall-timeout is armed from its first line)
            try:
                arm_wall_timeout(args.timeout)
                check_run_inputs(ns, load=key not in loaded)    # a --law / --host-controller loaded once
            finally:
                disarm_wall_timeout()
            loaded.add(key)


def _check_set_param(name: str, values: list[str]) -> None:
    """A ``--param`` that is a named parameter: its name (or glob) and every value checked
    (``scenario.FIELD``: checked with each grid point, by run's own checks)."""
    from humanoid_twin.params import ParamError, registry
    from humanoid_twin.sweep.params import SCENARIO_PREFIX

    if name.startswith(SCENARIO_PREFIX):
        return
    try:
        for v in values:
            registry().check({name: v})
    except ParamError as exc:
        raise SweepError(f"--param {name}: {exc}") from None


def _randomize(args: argparse.Namespace) -> list[tuple[tuple[str, float], ...]]:
    """``--randomize`` with ``--samples N``: the N drawn robots (sweep/params.py)."""
    from humanoid_twin.sweep.params import draw_samples, parse_randomize

    if not args.randomize:
        if args.samples is not None:
            raise SweepError("--samples N goes with --randomize NAME=uniform(A,B)|normal(MU,SIGMA)")
        return []
    if args.samples is None:
        raise SweepError("--randomize needs --samples N (how many robots to draw)")
    randomized = parse_randomize(args.randomize)
    clash = [r.name for r in randomized if r.name in parse_params(args.param)]
    if clash:
        raise SweepError(f"{clash[0]} is given both as --param and as --randomize")
    return draw_samples(randomized, args.samples)


def _check_is_sweep_table(path: Path, rows: list[dict[str, Any]]) -> None:
    """An existing ``--out`` is only rewritten when it is a sweep table: every row has ``seed``
    and ``error`` columns (docs/sweeps.md)."""
    if table_format(path) == "csv":
        import csv

        with open(path, newline="") as f:
            header = next(csv.reader(f), [])
    else:
        header = list(rows[0]) if rows else []
        if not rows:
            import pyarrow.parquet as pq

            header = pq.read_schema(path).names
    if "seed" not in header or "error" not in header:
        raise SweepError(f"--out {path} exists and is not a sweep table (no seed and error columns): "
                         "not rewritten")


def check_ray_address(address: str) -> None:
    """``auto``, or ``HOST:PORT`` where something answers within 5 s (a Ray cluster's GCS):
    :class:`SweepError` at once otherwise, instead of Ray retrying for minutes (issue 24)."""
    import socket

    if address in ("auto", "local"):
        return
    text = address.removeprefix("ray://")
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isascii() or not port.isdigit() or not 0 < int(port) < 65536:
        raise SweepError(f"--address {address!r}: expected HOST:PORT (e.g. 10.0.0.5:6379) or auto")
    try:
        with socket.create_connection((host, int(port)), timeout=5.0):
            pass
    except (OSError, UnicodeError) as exc:
        raise SweepError(f"--address {address}: no Ray cluster answers there "
                         f"({getattr(exc, 'strerror', None) or exc})") from None


def sweep_command(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    """``humanoid-twin sweep`` (``args.run_args``: the options for every run)."""
    from humanoid_twin import signals
    from humanoid_twin.scenarios import WallTimeoutExpired

    signals.user_code_runs()        # the checks import the user's scenario, laws, controller
    try:
        params, seeds, task = plan_sweep(args, parser)
    except SweepError as exc:
        sys.stderr.write(f"humanoid-twin: error: {exc}\n")
        return 2
    except WallTimeoutExpired:
        sys.stderr.write(f"humanoid-twin: checking a grid point took more than {args.timeout:g} wall seconds "
                         f"(--timeout): loading, planning or sizing {args.scenario} does not end; no run "
                         "started\n")
        return 1
    finally:
        signals.user_code_done()    # the runs' own code runs in their own processes
    if args.recordings is not None:
        args.recordings.mkdir(parents=True, exist_ok=True)
    points = grid(params, seeds, args.draws)  # type: ignore[arg-type]  # the grid x the drawn robots x the seeds (values as text)
    progress = None if args.no_progress else sys.stderr
    if progress is not None:
        _announce(args, task, len(points), progress)

    try:
        # SIGINT / SIGTERM (humanoid_twin/signals.py): the runs in flight are stopped within ~2 s,
        # the table keeps every finished run, exit 130 / 143
        rows = run_sweep(points, task, args.out, jobs=args.jobs, backend=args.backend,
                         address=args.address, progress=progress, known=known_columns(parser, params))
    except KeyboardInterrupt as exc:
        why = "terminated (SIGTERM)" if isinstance(exc, signals.Terminated) else "interrupted"
        sys.stderr.write(f"humanoid-twin: {why}; {args.out} keeps every finished run (the same command "
                         "resumes)\n")
        return signals.exit_code(exc)
    except SweepError as exc:
        sys.stderr.write(f"humanoid-twin: error: {exc}\n")
        return 2
    failed = sum(bool(r.get("error")) for r in rows)
    _say(args, f"{args.out}: {_runs(len(rows))}, {failed} failed")
    if args.plot is not None and not _plot(args, rows, list(params), task):
        return 2
    return exit_code(failed)


def _announce(args: argparse.Namespace, task: RunCli, n_runs: int, progress: Any) -> None:
    """The sweep's first progress line: how many runs of what, where, into which table."""
    where = args.address or "a local Ray" if args.backend == "ray" else "this machine"
    progress.write(f"sweep: {_runs(n_runs)} of {task.label or args.scenario} on {where}"
                   f"{f' ({args.jobs} jobs)' if args.jobs else ''} into {args.out}\n")


def _plot(args: argparse.Namespace, rows: list[dict[str, Any]], names: list[str], task: RunCli) -> bool:
    """``--plot``: the table's ``--metric`` against ``--x`` (sweep/plot.py); False when the plot
    cannot be drawn (one line said)."""
    from humanoid_twin.sweep.plot import plot_sweep

    title = f"sweep {task.label or args.scenario}: {args.metric} against {args.x}"
    try:
        plot_sweep(rows, args.x, args.metric, args.plot, names + ["seed"], title=title)
    except SweepError as exc:
        sys.stderr.write(f"humanoid-twin: error: {exc}\n")
        return False
    _say(args, f"{args.plot}: {args.metric} against {args.x}")
    return True


def _say(args: argparse.Namespace, line: str) -> None:
    """One line on the command's stdout (cli/streams.py), if it has one."""
    out = getattr(args, "stdout", sys.stdout)
    if out is not None:
        out.write(line + "\n")
        out.flush()


def _runs(n: int) -> str:
    return f"{n} run" if n == 1 else f"{n} runs"


EXIT_FAILED_BASE = 100     # a sweep with failed runs exits 100 + their number (199: 99 or more)


def exit_code(failed: int) -> int:
    """The sweep's exit code (docs/sweeps.md): 0 when every run worked, else 100 + the number of
    runs whose row has an error, at most 199; their errors are in the table's ``error`` column."""
    if failed:
        sys.stderr.write(f"humanoid-twin: {failed} run(s) failed: see the error column of the table\n")
    return EXIT_FAILED_BASE + min(failed, 99) if failed else 0
