"""The ``humanoid-twin`` command line's parser: the commands and their options (``run``, ``serve``
and ``view`` here; ``sweep``, ``params``, ``compare``, ``calibrate`` and ``replay`` from their own
modules; the options ``run`` and ``serve`` share: cli/options.py). A bad flag is one line on
stderr and exit 2."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

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
    scenario_arg,
    usage_error,
)


class Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (``humanoid-twin: error: ...``) and exit 2. The top
    parser's ``run_parser`` is its ``run`` subcommand (a sweep's columns are its options)."""

    run_parser: argparse.ArgumentParser | None = None

    def error(self, message: str) -> None:  # type: ignore[override]
        raise usage_error(message)


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
    parser = Parser(
        prog="humanoid-twin",
        description="Digital twin of the University of Aveiro humanoid's legs and its 2006 control system\n"
        "(PC -> RS-232 -> Master -> CAN -> 8 Slaves -> servos, on a MuJoCo robot).\n\n" + _scenario_lines(),
        epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()} (core: {core_kind()})")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser, metavar="COMMAND")

    run = _add_run_parser(sub)
    _add_serve_parser(sub)
    from humanoid_twin.cli.sweep import add_sweep_parser

    add_sweep_parser(sub)   # its other options are run's (main passes them through)
    from humanoid_twin.cli.params import add_params_parser

    add_params_parser(sub)  # humanoid-twin params [show FILE | diff A B] (docs/parameters.md)

    from humanoid_twin.cli.compare import add_compare_parsers

    add_compare_parsers(sub)    # compare, calibrate (cli/compare.py)

    from humanoid_twin.cli.replay import add_replay_parser

    add_replay_parser(sub)

    _add_view_parser(sub)
    parser.run_parser = run
    return parser


def _add_run_parser(sub: Any) -> argparse.ArgumentParser:
    """The ``run`` command (``sub``: the CLI's subparsers)."""
    from humanoid_twin.scenarios import CONTROL_CHOICES, DEFAULT_MOTION_DEG, DEFAULT_T_S, SCENARIOS

    raw = argparse.RawDescriptionHelpFormatter
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

    return run


def _add_serve_parser(sub: Any) -> None:
    """The ``serve`` command (``sub``: the CLI's subparsers)."""
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


def _add_view_parser(sub: Any) -> None:
    """The ``view`` command (``sub``: the CLI's subparsers)."""
    view = sub.add_parser("view", help="open a recording in the rerun viewer",
                          description="Open FILE.rrd in the rerun viewer (same as `rerun FILE.rrd`).")
    view.add_argument("file", type=Path, help="the .rrd recording")
    view.add_argument("--web", action="store_true",
                      help="serve rerun's web viewer on 127.0.0.1 and print its URL (no display needed)")
    view.add_argument("--port", type=int, default=9090, help="HTTP port of --web (default 9090)")
