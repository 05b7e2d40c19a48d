"""``humanoid-twin``: run a scenario headless, serve the twin to any serial client, view a recording.

The command line is a contract (scripts and CI depend on it; docs/scenarios.md):

    humanoid-twin run SCENARIO [--duration S] [--T S] [--motion DEG] [--perna 1|2] [--out FILE.rrd]
                               [--can-log FILE] [--serial-log FILE]
                               [--control none|locomotion|reaction|balance] [--tilt DEG] [--seed N] [--json]
    humanoid-twin serve [--pty | --tcp PORT] [--host 127.0.0.1] [--out FILE.rrd] [--can-log FILE]
                        [--serial-log FILE] [--viewer | --connect [ADDR]]
                        [--law ...] [--fault ...] [--tilt DEG] [--seed N]
    humanoid-twin view FILE.rrd
    humanoid-twin replay FILE [--out FILE.rrd] [--can-log FILE] [--seed N] [--law ...] [--wall-timeout S]
                         [--json]

SCENARIO: a built-in one, or the user's (FILE.py:NAME, MODULE:NAME, an entry point's name).
The options ``run`` and ``serve`` share are defined and checked once (cli/options.py).

A bad flag, an unknown scenario or an unwritable output path: one line on stderr, exit code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from humanoid_twin.cli.argtypes import (
    degrees_90,
    non_negative_seconds,
    positive_seconds,
    speed_factor,
    tcp_port,
    wall_seconds,
)
from humanoid_twin.cli.options import (
    add_host_controller_options,
    add_rig_options,
    cannot_write_in,
    check_rig_inputs,
    load_scenario_arg,
    rig_fields,
    run_options,
    scenario_arg,
)
from humanoid_twin.cli.options import usage_error as _usage_error
from humanoid_twin.outputs import (  # noqa: F401 - temp_name, remove_stale_partials: their home was here
    NAME_MAX,
    PARTIAL_PREFIX,
    Outputs,
    remove_stale_partials,
    temp_name,
)

if TYPE_CHECKING:
    from typing import TextIO

    from humanoid_twin.scenarios import RunOptions

EXIT_SUPERVISOR = 3     # the run ended with the supervisor in safe or estop (docs/supervisor.md)


class _Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (``humanoid-twin: error: ...``) and exit 2. The top
    parser's ``run_parser`` is its ``run`` subcommand (a sweep's columns are its options)."""

    run_parser: argparse.ArgumentParser | None = None

    def error(self, message: str) -> None:  # type: ignore[override]  # raises: exit 2
        raise _usage_error(message)


EXAMPLES = """\
examples:
  humanoid-twin run flexao                        squat; writes flexao.rrd, prints a summary
  humanoid-twin view flexao.rrd                   open it in the rerun viewer (--web: no display)
  humanoid-twin run levantar_perna --perna 2      lift the left leg
  humanoid-twin run inclinar --motion -15 --T 2   lean 15 deg to the right, in 2 s
  humanoid-twin run stand --tilt 20 --json        tilt the platform 20 deg toes up; JSON summary
  humanoid-twin run flexao --viewer --no-record   watch it live in MuJoCo's viewer
  humanoid-twin serve --tcp 5000                  the robot's serial port on socket://127.0.0.1:5000
  humanoid-twin sweep stand --param tilt=10,20,30 --out tilt.csv

more: the project's README.md and docs/ (docs/scenarios.md: what a run does, the summary's keys)"""


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("humanoid-twin")
    except PackageNotFoundError:     # a source tree on sys.path, not installed
        from humanoid_twin import __version__

        return __version__


def core_kind() -> str:
    """Which core runs, for ``--version``: ``compiled`` or ``python`` (humanoid_twin/core.py)."""
    from humanoid_twin.core import core_kind as kind

    return kind()


def _scenario_lines() -> str:
    """One line per registered scenario (its docstring's first line), then its defaults."""
    from humanoid_twin.scenarios import DEFAULT_MOTION_DEG, DEFAULT_T_S, REGISTRY

    width = max(len(name) for name in REGISTRY)
    lines = ["scenarios:"]
    for name, spec in REGISTRY.items():
        lines.append(f"  {name:<{width}}  {spec.doc}")
        if name in DEFAULT_MOTION_DEG:
            lines.append(f"  {'':<{width}}  defaults: --T {DEFAULT_T_S:g} s, --motion "
                         f"{DEFAULT_MOTION_DEG[name]:g} deg")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    """The CLI's argument parser (exposed for the docs and the tests)."""
    from humanoid_twin.scenarios import CONTROL_CHOICES, DEFAULT_MOTION_DEG, DEFAULT_T_S, SCENARIOS

    raw = argparse.RawDescriptionHelpFormatter
    parser = _Parser(
        prog="humanoid-twin",
        description="Digital twin of the University of Aveiro humanoid's legs and its 2006 control system\n"
        "(PC -> RS-232 -> Master -> CAN -> 8 Slaves -> servos, on a MuJoCo robot).\n\n" + _scenario_lines(),
        epilog=EXAMPLES, formatter_class=raw,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()} (core: {core_kind()})")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser, metavar="COMMAND")

    run = sub.add_parser(
        "run",
        help="run a scenario headless, write a rerun recording, print a summary",
        description="Run a scenario headless against the in-process twin (host -> RS-232 -> Master -> "
        "CAN ->\nSlaves -> MuJoCo) and write a rerun recording. Progress on stderr, the summary on "
        "stdout.\n\n" + _scenario_lines(),
        epilog=EXAMPLES, formatter_class=raw,
    )
    run.add_argument("scenario", type=scenario_arg, metavar="SCENARIO",
                     help=f"one of: {', '.join(SCENARIOS)} (see above); or your own: FILE.py:NAME, "
                     "MODULE:NAME, or an entry point of group humanoid_twin.scenarios (docs/scenarios.md)")
    run.add_argument("--duration", type=positive_seconds, metavar="S", help="simulated seconds (default: "
                     "boot ~2.7 s + the motion + 2 s of settling)")
    run.add_argument("--T", type=positive_seconds, metavar="S", help="the planner's movement period in "
                     "seconds (seed 000 table 22; levantar_perna: each of its 5 steps). "
                     f"Default: {DEFAULT_T_S:g} s")
    per = ", ".join(f"{name} {deg:g}" for name, deg in DEFAULT_MOTION_DEG.items())
    run.add_argument("--motion", type=degrees_90, metavar="DEG", help="the planner's angle in degrees "
                     f"(what it bends: see the scenarios above). Default: {per}")
    run.add_argument("--perna", type=int, default=1, choices=(1, 2), help="levantar_perna: the leg to "
                     "lift, 1 the right (default), 2 the left (seed 000 table 22)")
    add_rig_options(run, out_help="rerun recording to write (default: SCENARIO.rrd; a scenario of "
                    "yours: its name.rrd)")
    run.add_argument("--no-record", action="store_true", help="do not write a recording")
    run.add_argument("--control", choices=tuple(CONTROL_CHOICES), help="override the control type the "
                     "planner sets")
    run.add_argument("--json", action="store_true", help="print the summary as one JSON object, alone "
                     "on stdout (instead of the table)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    run.add_argument("--wall-timeout", type=wall_seconds, metavar="S",
                     help="end the run after S seconds of wall time (one line, exit 1, files closed, "
                     "nothing replaced); default: no limit")
    run.add_argument("--viewer", action="store_true", help="watch the run live in MuJoCo's own viewer, "
                     "paced to real time (needs a display)")
    add_host_controller_options(run)     # --host-controller, --host-period-ms (docs/controllers.md)

    serve = sub.add_parser(
        "serve",
        help="serve the twin in real time on a pty or TCP port for any serial client",
        description="Run the twin in real time. The first line on stdout is the port to open "
        "(a pty path, or socket://HOST:PORT with --tcp). Runs until killed (Ctrl-C, SIGTERM); "
        "--out, --can-log and --serial-log are complete files then (docs/serve.md).",
    )
    where = serve.add_mutually_exclusive_group()
    where.add_argument("--pty", action="store_true", help="serve on a pseudo-terminal (default)")
    where.add_argument("--tcp", type=tcp_port, metavar="PORT", help="serve on TCP PORT (0: any free port)")
    serve.add_argument("--host", default="127.0.0.1", help="address to bind with --tcp (default 127.0.0.1; "
                       "::1 for IPv6 loopback)")
    serve.add_argument("--allow-remote", action="store_true",
                       help="allow a --host that is not loopback (the protocol has no authentication: "
                       "anyone on the network could drive the robot)")
    serve.add_argument("--idle-timeout", type=non_negative_seconds, default=600.0, metavar="S",
                       help="disconnect a TCP client that sent nothing for S wall seconds, so that a "
                       "silent client cannot hold the port (default 600; 0: never)")
    serve.add_argument("--speed", type=speed_factor, default=1.0, metavar="X", help="run X times faster "
                       "than real time (0.5: half as fast; default 1, as the robot); 0.01..100")
    add_rig_options(serve, out_help="rerun recording of the whole serve run (default: none)")
    live = serve.add_mutually_exclusive_group()
    live.add_argument("--viewer", action="store_true", help="watch the run live in rerun's native viewer "
                      "(started here, its server on a free loopback port; needs a display)")
    live.add_argument("--connect", nargs="?", const="127.0.0.1:9876", metavar="ADDR",
                      help="stream the recording live to a rerun viewer already listening at ADDR "
                      "(HOST:PORT on loopback, default 127.0.0.1:9876: `rerun --bind 127.0.0.1`)")

    from humanoid_twin.cli.sweep import add_sweep_parser

    add_sweep_parser(sub)   # its other options are run's (main passes them through)
    from humanoid_twin.cli.params import add_params_parser

    add_params_parser(sub)  # humanoid-twin params [show FILE | diff A B] (docs/parameters.md)

    from humanoid_twin.cli.compare import add_compare_parsers

    add_compare_parsers(sub)    # compare, calibrate (cli/compare.py)

    from humanoid_twin.cli.replay import add_replay_parser

    add_replay_parser(sub)

    view = sub.add_parser("view", help="open a recording in the rerun viewer",
                          description="Open FILE.rrd in the rerun viewer (same as `rerun FILE.rrd`).")
    view.add_argument("file", type=Path, help="the .rrd recording")
    view.add_argument("--web", action="store_true",
                      help="serve rerun's web viewer on 127.0.0.1 and print its URL (no display needed)")
    view.add_argument("--port", type=int, default=9090, help="HTTP port of --web (default 9090)")
    parser.run_parser = run
    return parser


MIN_FREE_BYTES = 8 * 2**20  # a run's outputs need at least this much free disk besides their own size
EXIT_INTERRUPTED = 130      # SIGINT (Ctrl-C)
EXIT_TERMINATED = 143       # SIGTERM (timeout, CI runners, docker stop)

# What a run writes, per simulated second, measured on stand and flexao (docs/scenarios.md,
# "Disk space"): the recording streams 186-215 kB/s (220 000 bound); the CAN wire carries 3 800
# frames/s (4 000 bound) and each python-can format costs (bytes per frame, measured x 1.25):
RRD_BYTES_PER_S = 220_000
CAN_FRAMES_PER_S = 4_000
CAN_LOG_BYTES_PER_FRAME = {".asc": 78, ".blf": 7, ".csv": 44, ".log": 52, ".trc": 92, ".txt": 150,
                           ".db": 41}
CAN_LOG_BYTES_PER_FRAME_OTHER = 150     # a format not measured (.mf4 ...): the largest
CAN_LOG_BYTES_PER_FRAME_GZ = 8          # any format + .gz (measured .asc.gz: 3.2)


def _check_writable(path: Path, what: str) -> Path:
    """``path`` may be written by a run (one line, exit 2 otherwise); returns the file it names
    (through symbolic links: :func:`humanoid_twin.containment.output_target`, which also refuses
    a FIFO or a device)."""
    from humanoid_twin.containment import OutputPathError, output_target

    try:
        target = output_target(path, what)
    except OutputPathError as exc:
        raise _usage_error(str(exc)) from None
    parent = target.parent
    if not parent.is_dir():
        raise _usage_error(f"{what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK) or (target.exists() and not os.access(target, os.W_OK)):
        raise _usage_error(f"{what} {path} is not writable")
    why = cannot_write_in(parent)
    if why is not None:
        raise _usage_error(f"{what} {path}: cannot write in {parent}: {why}")
    if len(os.fsencode(target.name)) > NAME_MAX:
        raise _usage_error(f"{what}: the file name is longer than {NAME_MAX} bytes")
    return target


def output_bytes(kind: str, path: Path, expected_s: float) -> int:
    """What a run of ``expected_s`` simulated seconds writes to ``path`` at most (bytes): a
    recording (``kind`` "out"), twice over when it is compacted at the end (the compaction writes
    a copy before it replaces the file), or a CAN log in its format."""
    if kind == "out":
        from humanoid_twin.recording import compact_for

        return round(expected_s * RRD_BYTES_PER_S * (2 if compact_for(expected_s) else 1))
    if kind == "serial_log":
        from humanoid_twin.bus.serial_log import max_bytes_per_s

        return round(expected_s * max_bytes_per_s())     # measured flexao: 18 400 bytes/s
    suffix = path.suffix.lower()
    if suffix == ".gz":
        per_frame = CAN_LOG_BYTES_PER_FRAME_GZ
    else:
        per_frame = CAN_LOG_BYTES_PER_FRAME.get(suffix, CAN_LOG_BYTES_PER_FRAME_OTHER)
    return round(expected_s * CAN_FRAMES_PER_S * per_frame)


class _Outputs(Outputs):
    """The run's files are written under temporary names next to their final ones and renamed at
    the end (humanoid_twin/outputs.py): a failed run never replaces an existing file. Each temporary
    file is created up front (an unwritable place is found before the run: exit 2), once the free
    space of every disk has been checked against what the run will write there
    (:func:`output_bytes`)."""

    def check_space(self, wanted: dict[str, tuple[Path, str]], expected_s: float) -> None:
        """Every disk has room for what the run writes on it, plus :data:`MIN_FREE_BYTES` (an
        open-ended run, ``serve``: ``expected_s`` 0, that margin only)."""
        need: dict[int, list] = {}
        for key, (path, what) in wanted.items():
            parent = _check_writable(path, what).parent
            dev = os.stat(parent).st_dev
            entry = need.setdefault(dev, [parent, 0, []])
            entry[1] += output_bytes(key, path, expected_s)
            entry[2].append(f"{what} {path}")
        for parent, total, whats in need.values():
            free = shutil.disk_usage(parent).free
            if free < total + MIN_FREE_BYTES:
                raise _usage_error(
                    f"{' and '.join(whats)}: a {expected_s:g} s run writes about "
                    f"{(total + MIN_FREE_BYTES) / 2**20:.0f} MB there, only {free / 2**20:.0f} MB free "
                    "(docs/scenarios.md, \"Disk space\")")

    def open_all(self, out: Path | None, args: argparse.Namespace, expected_s: float) -> dict[str, Any]:
        """The outputs of a ``run`` or ``serve`` (the recording ``out``, ``args``' ``--can-log`` and
        ``--serial-log``): their disks' space checked (:meth:`check_space`), each created under its
        temporary name. Returns the :class:`~humanoid_twin.rig.RigOptions` output fields: the
        temporary names, and the CAN log's final name (``can_log_name``, its header)."""
        finals = {"out": out, "can_log": args.can_log, "serial_log": args.serial_log}
        wanted = {k: (p, what) for (k, p), what in zip(finals.items(), ("--out", "--can-log", "--serial-log"),
                                                      strict=True) if p is not None}
        self.check_space(wanted, expected_s)
        files: dict[str, Any] = {k: self.add(k, *wanted[k]) if k in wanted else None for k in finals}
        files["can_log_name"] = None if args.can_log is None else args.can_log.name
        return files

    def add(self, key: str, path: Path, what: str) -> Path:  # type: ignore[override]  # what: names it in the message
        """As :meth:`Outputs.add`, checked first as the CLI checks an output (one line, exit 2)."""
        _check_writable(path.expanduser(), what)
        try:
            return super().add(key, path)
        except OSError as exc:
            self.discard()
            raise _usage_error(f"{what} {path}: cannot write there: {exc.strerror or exc}") from None


def check_run_inputs(args: argparse.Namespace, load: bool = True) -> dict[str, Any]:
    """Every value of ``run`` checked before anything runs or is written (one line, exit 2): its
    own, the scenario (loaded: a user's is imported here) and its planner's limits, then what it
    shares with ``serve`` (:func:`~humanoid_twin.cli.options.check_rig_inputs`). Returns the
    loaded controllers; ``load`` False: the ``--law`` s and ``--host-controller`` are not imported
    again (a sweep's later grid points)."""
    from humanoid_twin.scenarios import (
        BOOT_MIN_S,
        MAX_DURATION_S,
        ScenarioError,
        ScenarioInputError,
        scenario_motion_s,
        scenario_plan,
    )

    if args.no_record and args.out is not None:
        raise _usage_error(f"--no-record and --out {args.out} contradict each other: drop one")
    if args.duration is not None and args.duration > MAX_DURATION_S:
        raise _usage_error(f"--duration {args.duration:g}: at most {MAX_DURATION_S:g} simulated seconds")
    if args.duration is not None and args.duration < BOOT_MIN_S:
        raise _usage_error(f"--duration {args.duration:g} is shorter than the boot (the Slaves calibrate for "
                           f"{BOOT_MIN_S:g} s; the boot takes ~2.65 simulated seconds): give at least that")
    from humanoid_twin.cli.params import scenario_with_fields

    spec = scenario_with_fields(load_scenario_arg(args.scenario), args)    # --set scenario.FIELD=V
    try:   # the planners' own limits (T fits one byte of 20 ms ticks, each joint's range ...), and
        # the scenario's length (motion_s, checked like --duration: it sizes the outputs' disk space)
        scenario_motion_s(spec, scenario_plan(spec, args.scenario, args.T, args.motion, args.perna),
                          args.scenario)
    except ScenarioInputError as exc:
        raise _usage_error(str(exc)) from None
    except ScenarioError as exc:       # the user's own code raised (its plan, its motion_s)
        sys.stderr.write(f"humanoid-twin: {_one_line(str(exc))}\n")
        raise SystemExit(1) from None
    return check_rig_inputs(args, load=load)


def cmd_run(args: argparse.Namespace) -> int:
    """``humanoid-twin run``: ``--wall-timeout`` is armed from its first line (importing, planning
    and sizing the scenario included: a user's loop there ends in one line, exit 1)."""
    from humanoid_twin import signals
    from humanoid_twin.scenarios import WallTimeoutExpired, arm_wall_timeout, disarm_wall_timeout

    signals.user_code_runs()        # the scenario, laws and controller are imported next
    try:
        arm_wall_timeout(args.wall_timeout)
        return _cmd_run(args)
    except (WallTimeoutExpired, Exception) as exc:
        # outside the simulation (scenarios.run reports its own); an alarm that landed in the
        # import of an extension module comes out of it as an ImportError caused by it
        if not any(isinstance(e, WallTimeoutExpired) for e in _causes(exc)):
            raise
        sys.stderr.write(f"humanoid-twin: the run took more than {args.wall_timeout:g} wall seconds "
                         "(--wall-timeout): stopped while loading, planning or sizing the scenario\n")
        return 1
    finally:
        disarm_wall_timeout()


def _causes(exc: BaseException, limit: int = 20) -> list[BaseException]:
    """``exc`` and the exceptions it was raised from or during, nearest first (at most ``limit``)."""
    out: list[BaseException] = []
    cur: BaseException | None = exc
    while cur is not None and len(out) < limit:
        out.append(cur)
        cur = cur.__cause__ or cur.__context__
    return out


def _cmd_run(args: argparse.Namespace) -> int:
    from humanoid_twin import signals

    controllers = check_run_inputs(args)
    if args.viewer:
        from humanoid_twin.cli.live_viewer import LiveViewerError, check_display

        try:
            check_display()
        except LiveViewerError as exc:
            raise _usage_error(str(exc)) from None
    from humanoid_twin.scenarios import ScenarioError, ScenarioInputError, expected_run_s, recording_name

    try:    # what sizes the outputs' disk space: a user's motion_s, called (and checked) again
        expected_s = expected_run_s(args.scenario, args.duration, args.T, args.motion, args.perna, args.tilt)
    except ScenarioInputError as exc:
        raise _usage_error(str(exc)) from None
    except ScenarioError as exc:
        sys.stderr.write(f"humanoid-twin: {_one_line(str(exc))}\n")
        return 1
    # --out was checked with the other inputs; the default name ends in .rrd
    out = None if args.no_record else (args.out or Path(recording_name(args.scenario)))
    outputs = _Outputs()
    signals.on_hard_exit(outputs.discard)     # --wall-timeout against code that swallows the stop
    try:
        files = outputs.open_all(out, args, expected_s)
        return _run(args, run_options(args, controllers, files), outputs)
    finally:
        outputs.discard()       # whatever was not committed


def _run(args: argparse.Namespace, opts: RunOptions, outputs: _Outputs) -> int:
    from humanoid_twin import signals
    from humanoid_twin.recording.readback import RrdReadError
    from humanoid_twin.scenarios import ScenarioError, ScenarioInputError, disarm_wall_timeout, run

    bar = None
    if opts.progress:
        from humanoid_twin.cli.progress import RunProgress

        bar = RunProgress(args.scenario, sys.stderr, duration_s=args.duration)
    live = None
    viewer_errors: tuple[type[Exception], ...] = ()
    if args.viewer:
        from humanoid_twin.cli.live_viewer import LiveViewer, LiveViewerError

        live, viewer_errors = LiveViewer(), (LiveViewerError,)
    try:
        try:
            summary = run(opts, on_progress=None if bar is None else bar.update,
                          on_twin=None if live is None else live.attach,
                          on_boot=None if bar is None else bar.boot_ended)
        finally:
            disarm_wall_timeout()        # the run is over: what is left is the CLI's own work
    except ScenarioInputError as exc:
        raise _usage_error(str(exc)) from None
    except ScenarioError as exc:
        sys.stderr.write(f"humanoid-twin: {_one_line(outputs.final_names(str(exc)))}\n")
        return 1
    except viewer_errors as exc:        # the window could not open (nothing written yet)
        raise _usage_error(str(exc)) from None
    except KeyboardInterrupt as exc:
        # SIGINT / SIGTERM (humanoid_twin/signals.py, installed by main): the run closed its files
        # on the way out, each complete before the signal was let through: what was recorded is
        # kept (valid files)
        signals.user_code_done()
        outputs.commit()
        kept = " ".join(str(p) for p in outputs.final.values())
        why = "terminated (SIGTERM)" if isinstance(exc, signals.Terminated) else "interrupted"
        sys.stderr.write(f"humanoid-twin: {why}" + (f"; recorded so far: {kept}" if kept else "") + "\n")
        return signals.exit_code(exc)
    except (OSError, RrdReadError) as exc:
        # a full disk (or a file-size limit) while writing: one line, nothing replaced
        sys.stderr.write(f"humanoid-twin: error: cannot write the outputs: "
                         f"{_one_line(outputs.final_names(str(exc)))}; no file replaced\n")
        return 1
    finally:
        if bar is not None:
            bar.close()
        if live is not None:
            live.close()
    if summary.get("outcome") == "diverged":
        # not a result: no output replaced, the summary printed for the record, one line, exit 1
        sys.stderr.write(f"humanoid-twin: the simulation diverged ({summary.get('diverged')}): the run "
                         "ended there; its outputs are not written\n")
        outputs.discard()
        _print_summary(summary, args.json, args.stdout)
        return 1
    if summary.get("boot_s") is None:
        sys.stderr.write(f"humanoid-twin: warning: the run ended at {summary['duration_s']:g} s (--duration) "
                         "before the boot did (~2.65 s, longer under faults): the scenario's program did "
                         "not run\n")
    replaced = "out" in outputs.final and outputs.final["out"].exists()
    outputs.commit()
    if "out" in outputs.final:
        summary["recording"] = str(outputs.final["out"])
        if args.out is None:      # the default name: say which file was written (and replaced)
            sys.stderr.write(f"humanoid-twin: wrote {outputs.final['out']}"
                             + (" (replacing the earlier one; --out FILE.rrd picks another)"
                                if replaced else "")
                             + "\n")
        if summary.get("recording_compacted") is False:
            sys.stderr.write(f"humanoid-twin: warning: {outputs.final['out']} kept as recorded, not "
                             f"compacted: {outputs.final_names(summary.get('recording_note', ''))}\n")
    if "can_log" in outputs.final:
        summary["can_log"] = str(outputs.final["can_log"])
    if "serial_log" in outputs.final:
        summary["serial_log"] = str(outputs.final["serial_log"])
    for fault in summary.get("law_faults", ()):
        sys.stderr.write(f"humanoid-twin: control law {fault['law']} stopped on SCU {fault['scu']} at "
                         f"t={fault['t_s']} s: {fault['reason']}\n")
    _print_summary(summary, args.json, args.stdout)
    return EXIT_SUPERVISOR if summary.get("mode") in ("safe", "estop") else 0


def _one_line(text: str, limit: int = 500) -> str:
    """``text`` on one line, at most ``limit`` characters (an error message from anywhere)."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def summary_table(summary: dict) -> str:
    """The human summary: one ``key  value`` line per key, plain values (docs/scenarios.md)."""
    from humanoid_twin.summary import plain_value

    width = max(len(k) for k in summary)
    return "".join(f"{key:<{width}}  {plain_value(value)}\n" for key, value in summary.items())


def _print_summary(summary: dict, as_json: bool, out: TextIO | None) -> None:
    """``--json``: the JSON object alone on stdout (for machines); otherwise the human table.
    ``out``: the command's stdout (cli/streams.py; None: the process has none)."""
    if out is None:
        return
    out.write(json.dumps(summary, sort_keys=False) + "\n" if as_json else summary_table(summary))
    out.flush()


def cmd_serve(args: argparse.Namespace) -> int:
    """``humanoid-twin serve``: real-time pacing, the port on the first stdout line; ``--out``,
    ``--can-log`` and ``--serial-log`` written under temporary names and renamed when serve ends
    (Ctrl-C, SIGTERM)."""
    from humanoid_twin import signals
    from humanoid_twin.recording.readback import RrdReadError
    from humanoid_twin.recording.viewer import ViewerError, live_url, spawn_live_viewer
    from humanoid_twin.serve import ServeError, ServeOptions, serve
    from humanoid_twin.slave.laws import LawError

    signals.user_code_runs()        # the laws are imported here
    controllers = check_rig_inputs(args)        # the same checks as run's (cli/options.py)
    signals.user_code_done()        # (the viewer may take its time to start: not user code)
    if args.tcp is not None:
        _check_bind(args.host, args.tcp)
        _check_remote(args.host, args.allow_remote)
    try:
        live = live_url(args.connect) if args.connect is not None else None
    except ViewerError as exc:
        raise _usage_error(str(exc)) from None
    stop: dict[str, int | None] = {"signal": None}

    def _stop(signum: int, frame: object) -> None:
        stop["signal"] = stop["signal"] or signum
        signals.stop_requested(signum)     # a law that never returns: the process ends anyway

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    outputs = _Outputs()
    signals.on_hard_exit(outputs.discard)     # a law that holds a signal back: nothing left behind
    try:
        files = outputs.open_all(args.out, args, 0.0)     # open-ended: the free-space margin only
        if args.viewer:             # the last check, the first thing started: the viewer's window
            try:
                live = spawn_live_viewer()[1]
            except ViewerError as exc:
                raise _usage_error(str(exc)) from None
        opts = ServeOptions(**rig_fields(args, controllers), **files, live=live,
                            tcp_port=args.tcp, host=args.host, idle_timeout_s=args.idle_timeout or None,
                            speed=args.speed)
        signals.user_code_runs()    # the laws run in the twin from here to the rig's close
        if stop["signal"] is not None:      # a signal meanwhile: its grace starts now
            signals.stop_requested(stop["signal"])
        try:
            code = serve(opts, should_stop=lambda: stop["signal"] is not None,
                         announce=lambda line: _say(args.stdout, line))
        except (ServeError, LawError) as exc:     # LawError: a law that cannot be made for every board
            raise _usage_error(str(exc)) from None
        except (OSError, RrdReadError) as exc:
            sys.stderr.write(f"humanoid-twin: error: cannot write the outputs: "
                             f"{_one_line(outputs.final_names(str(exc)))}; no file replaced\n")
            return 1
        outputs.commit()
        for path in outputs.final.values():
            sys.stderr.write(f"humanoid-twin serve: wrote {path}\n")
    finally:
        outputs.discard()
    # ended by a signal: 130 (SIGINT) or 143 (SIGTERM), as run (issue 24; it was 0)
    return 128 + stop["signal"] if stop["signal"] is not None else code


def _say(out: TextIO | None, line: str) -> None:
    """One line on the command's stdout (cli/streams.py; None: the process has none)."""
    if out is not None:
        out.write(line + "\n")
        out.flush()


def _check_remote(host: str, allow: bool) -> None:
    """``--host`` is a loopback address unless ``--allow-remote`` (the protocol has no
    authentication: anyone who reaches the port can drive, e-stop or reset the robot)."""
    import ipaddress
    import socket

    try:
        infos = socket.getaddrinfo(host, None, 0, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
        addrs = {info[4][0] for info in infos}
    except (socket.gaierror, UnicodeError) as exc:
        raise _usage_error(f"--host {host}: not an address or a known host name ({exc})") from None
    remote = [a for a in addrs if not ipaddress.ip_address(a.split("%")[0]).is_loopback]  # type: ignore[union-attr]  # an IP family's address is a str
    if not remote:
        return
    if not allow:
        raise _usage_error(f"--host {host} is reachable from other machines and the robot's protocol has "
                           "no authentication: add --allow-remote if that is what you want (docs/serve.md)")
    sys.stderr.write(f"humanoid-twin serve: warning: listening on {host}, reachable from the network; the "
                     "protocol has no authentication: anyone who reaches this port can drive, e-stop or "
                     "reset the robot\n")


def _check_bind(host: str, port: int) -> None:
    """The TCP address is one this machine can listen on, before the twin boots (exit 2 otherwise)."""
    import socket

    try:
        infos = socket.getaddrinfo(host, port, 0, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        raise _usage_error(f"--host {host}: not an address or a known host name ({exc})") from None
    family, _, _, _, addr = infos[0]
    try:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(addr)
            s.listen(1)
    except OSError as exc:
        raise _usage_error(f"--host {host} --tcp {port}: cannot listen: {exc.strerror or exc}") from None


def cmd_view(args: argparse.Namespace) -> int:
    """``humanoid-twin view FILE.rrd``: the rerun viewer shipped with rerun-sdk."""
    if not args.file.is_file():
        raise _usage_error(f"no such recording: {args.file}")
    from humanoid_twin.recording.viewer import ViewerError, view

    if not 0 < args.port < 65536:
        raise _usage_error(f"--port {args.port}: must be 1..65535")
    try:
        return view(args.file, web=args.web, web_port=args.port)
    except ViewerError as exc:
        raise _usage_error(str(exc)) from None


def cmd_sweep(args: argparse.Namespace) -> int:
    """``humanoid-twin sweep``: a grid of runs into one table (humanoid_twin/sweep/, docs/sweeps.md)."""
    from humanoid_twin.cli.sweep import sweep_command

    return sweep_command(args, build_parser())


def _cmd_compare(args: argparse.Namespace) -> int:
    from humanoid_twin.cli.compare import cmd_compare

    return cmd_compare(args)


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from humanoid_twin.cli.compare import cmd_calibrate

    return cmd_calibrate(args)


def cmd_params(args: argparse.Namespace) -> int:
    """``humanoid-twin params``: the named parameters (cli/params.py, docs/parameters.md)."""
    from humanoid_twin.cli.params import cmd_params as params_command

    return params_command(args)


def cmd_replay(args: argparse.Namespace) -> int:
    """``humanoid-twin replay``: a serial log into the twin it describes (cli/replay.py)."""
    from humanoid_twin.cli.replay import replay_command

    return replay_command(args, _Outputs())


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``humanoid-twin`` console script.

    Its first instruction installs the signal handlers (humanoid_twin/signals.py): from there to
    the last rename, SIGINT exits 130 and SIGTERM 143 with one line, never a traceback. ``run``,
    ``serve`` and ``sweep`` keep stdout for their own output (cli/streams.py: what user code
    prints goes to stderr). ``argv`` None (the console script): the process ends here, also when
    threads started by user code are still running (:func:`humanoid_twin.signals.end_process`)."""
    from humanoid_twin import signals

    signals.install()
    code = 1
    try:
        code = _command(argv)
    finally:
        signals.restore(exiting=code if argv is None else None)   # argv None: about to exit
    if argv is None:
        signals.end_process(code)
    return code


def _command(argv: list[str] | None) -> int:
    from humanoid_twin import signals
    from humanoid_twin.cli.streams import command_streams

    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
        if extra and args.command != "sweep":     # sweep gives run's options it does not know to every run
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
        args.run_args = extra
        handler = {"run": cmd_run, "serve": cmd_serve, "view": cmd_view, "sweep": cmd_sweep,
                   "params": cmd_params, "compare": _cmd_compare, "calibrate": _cmd_calibrate,
                   "replay": cmd_replay}[args.command]
        if args.command not in ("run", "serve", "sweep"):   # no user code's prints to keep off stdout
            return handler(args)
        with command_streams() as out:
            args.stdout = out
            return handler(args)
    except Exception as exc:
        # a signal that landed in an extension module's import comes out wrapped (ImportError)
        cause = signals.signal_cause(exc)
        if cause is None:
            raise
        return _signalled(cause)
    except KeyboardInterrupt as exc:
        return _signalled(exc)


def _signalled(exc: BaseException) -> int:
    """One line for SIGINT / SIGTERM, and the exit code (130 / 143)."""
    from humanoid_twin import signals

    signals.user_code_done()
    why = "terminated (SIGTERM)" if isinstance(exc, signals.Terminated) else "interrupted"
    with contextlib.suppress(OSError):
        sys.stderr.write(f"humanoid-twin: {why}\n")
    return signals.exit_code(exc)


if __name__ == "__main__":
    raise SystemExit(main())
