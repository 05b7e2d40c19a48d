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

This module is the entry point: the signal handlers, the command's stdout, and each command handed
to its module (the parser: cli/parser.py; run: cli/run.py, its checks cli/run_checks.py; serve:
cli/serve.py; the outputs' checks and temporary names: cli/checked_outputs.py; sweep, params,
compare, calibrate, replay, view: cli/NAME.py).

A bad flag, an unknown scenario or an unwritable output path: one line on stderr, exit code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
from collections.abc import Callable

# Each command's function (it takes the parsed arguments, returns the exit code), imported when run
COMMANDS = {
    "run": "humanoid_twin.cli.run:cmd_run",
    "serve": "humanoid_twin.cli.serve:cmd_serve",
    "view": "humanoid_twin.cli.view:cmd_view",
    "params": "humanoid_twin.cli.params:cmd_params",      # docs/parameters.md
    "compare": "humanoid_twin.cli.compare:cmd_compare",
    "calibrate": "humanoid_twin.cli.compare:cmd_calibrate",
    "replay": "humanoid_twin.cli.replay:replay_command",
}


def build_parser() -> argparse.ArgumentParser:
    """The CLI's argument parser (cli/parser.py; exposed for the docs and the tests). Imported
    when called: the signal handlers come first (:func:`main`)."""
    from humanoid_twin.cli.parser import build_parser as build

    return build()


def _handler(command: str, parser: argparse.ArgumentParser) -> Callable[[argparse.Namespace], int]:
    """The function of ``command``; ``sweep`` is handed the parser, whose ``run`` checks each value
    (humanoid_twin/sweep/, docs/sweeps.md)."""
    if command == "sweep":
        from humanoid_twin.cli.sweep import sweep_command

        return lambda args: sweep_command(args, parser)
    module, _, name = COMMANDS[command].partition(":")
    return getattr(importlib.import_module(module), name)


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
        handler = _handler(args.command, parser)
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
    from humanoid_twin.cli.messages import stop_reason

    signals.user_code_done()
    with contextlib.suppress(OSError):
        sys.stderr.write(f"humanoid-twin: {stop_reason(exc)}\n")
    return signals.exit_code(exc)


if __name__ == "__main__":
    raise SystemExit(main())
