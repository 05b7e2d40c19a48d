"""``humanoid-twin replay FILE``: a serial log replayed headless into the twin its meta describes,
checked, and re-recorded on request (humanoid_twin/replay.py; docs/buses.md, "Replay").

Exit codes: 0 every answer of the twin matches the log; 1 they differ (the first difference on
stderr; the outputs asked for are written all the same: they show what the twin does now); 2 bad
input (one line on stderr, before anything is written: not a serial log, records that contradict
each other, a meta that cannot rebuild the twin, a law the log names and the command line does
not; a replay past ``--wall-timeout``: its outputs discarded); 130/143 SIGINT/SIGTERM (what was
recorded is kept, as ``run`` does).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from humanoid_twin.cli.argtypes import wall_seconds
from humanoid_twin.cli.checked_outputs import CheckedOutputs
from humanoid_twin.cli.messages import stop_reason
from humanoid_twin.cli.options import (
    add_law_option,
    check_recording_outputs,
    load_controllers,
    usage_error,
)
from humanoid_twin.seeds import SEED_MAX

EXIT_DIFFER = 1


def add_replay_parser(sub: argparse._SubParsersAction[Any]) -> None:
    """The ``replay`` command's parser, on ``humanoid-twin``'s sub-parsers."""
    from humanoid_twin.replay import REPLAY_CAN_INTERFACES

    p = sub.add_parser(
        "replay", help="replay a serial log into the twin it describes; check the answers; re-record it",
        description="Feed the host's bytes of a serial log (--serial-log of run or serve) at their virtual "
        "instants into a fresh twin built with the options its header records, and compare the twin's "
        "answers with the log's, byte for byte and microsecond for microsecond: exit 0 when they all "
        "match, 1 and the first difference when not, 2 when the file cannot be replayed (docs/buses.md).")
    p.add_argument("file", type=Path, metavar="FILE", help="the serial log")
    p.add_argument("--out", type=Path, metavar="FILE.rrd", help="record the replay (a rerun recording, as "
                   "run)")
    p.add_argument("--can-log", type=Path, metavar="FILE", help="CAN log of the replay to write; format by "
                   "suffix (.asc .blf .log .csv .trc ...), python-can writers")
    p.add_argument("--seed", type=int, help="the twin's seed (default: the log's)")
    p.add_argument("--can-interface", choices=REPLAY_CAN_INTERFACES,
                   help="the CAN wire's python-can interface (default: the log's; a log of a socketcan run "
                   "needs one: a replay opens no system CAN interface)")
    add_law_option(p, help_more="; a law the log names runs only when named here the same (a log is "
                   "data: its replay imports no code the command line does not name)")
    p.add_argument("--json", action="store_true", help="print the result as one JSON object, alone on stdout")
    p.add_argument("--wall-timeout", type=wall_seconds, metavar="S",
                   help="end the replay after S seconds of wall time, counted from the start (one line, "
                   "exit 1, nothing replaced); default: no limit (a log spans one simulated day at most)")
    p.set_defaults(serial_log=None)      # the outputs' shared code knows a run's three


def _check_not_the_log(args: argparse.Namespace) -> None:
    """An output is not the log being replayed (``--can-log run.log`` of ``run.log``: the CAN log
    would be renamed over it at the end)."""
    import os

    for flag, path in (("--out", args.out), ("--can-log", args.can_log)):
        if path is None:
            continue
        same = path.expanduser().resolve() == args.file.expanduser().resolve()
        if not same and path.exists() and args.file.exists():
            try:
                same = os.path.samefile(path, args.file)
            except OSError:
                pass
        if same:
            raise usage_error(f"{flag} {path} is the log being replayed: name another file")


def replay_command(args: argparse.Namespace) -> int:
    """``humanoid-twin replay``: every input checked (one line, exit 2) before the outputs
    (cli/checked_outputs.py: under temporary names) are created; the replay; the outputs renamed."""
    from humanoid_twin import signals
    from humanoid_twin.clock import US_PER_S
    from humanoid_twin.recording.readback import RrdReadError
    from humanoid_twin.replay import ReplayError, ReplayTimeoutError

    t0 = time.monotonic()
    info, laws = _check_replay_inputs(args)
    outputs = CheckedOutputs()
    signals.on_hard_exit(outputs.discard)
    try:
        files = outputs.open_all(args.out, args, info.end_us / US_PER_S)
        try:
            res = _replay(args, info, laws, files, t0)
        except ReplayError as exc:
            raise usage_error(outputs.final_names(str(exc))) from None
        except ReplayTimeoutError as exc:        # the outputs are discarded: nothing replaced
            sys.stderr.write(f"humanoid-twin replay: {args.file}: {exc} (--wall-timeout)\n")
            return 1
        except KeyboardInterrupt as exc:         # SIGINT / SIGTERM: the files closed whole, kept
            outputs.commit()
            sys.stderr.write(f"humanoid-twin replay: {stop_reason(exc)}{outputs.kept()}\n")
            return signals.exit_code(exc)
        except (OSError, RrdReadError) as exc:
            text = " ".join(outputs.final_names(str(exc)).split())[:500]
            sys.stderr.write(f"humanoid-twin replay: error: cannot write the outputs: {text}; no file "
                             "replaced\n")
            return 1
        outputs.commit()
    finally:
        outputs.discard()
    return _report(args, res, outputs)


def _check_replay_inputs(args: argparse.Namespace) -> tuple[Any, Any]:
    """The options, the outputs' names and the log (a twin its meta can rebuild, the laws it names
    given the same here): one line, exit 2. Returns the log's description and the laws."""
    from humanoid_twin.replay import ReplayError, check_log, replay_options

    if args.seed is not None and not 0 <= args.seed <= SEED_MAX:
        raise usage_error(f"--seed {args.seed}: must be 0..{SEED_MAX}")
    check_recording_outputs(args)
    _check_not_the_log(args)
    laws = load_controllers(args)["laws"]
    try:
        info = check_log(args.file)
        replay_options(args.file, info, seed=args.seed, laws=laws, can_interface=args.can_interface)
    except ReplayError as exc:
        raise usage_error(str(exc)) from None
    return info, laws


def _replay(args: argparse.Namespace, info: Any, laws: Any, files: dict[str, Any], t0: float) -> Any:
    """The replay into ``files`` (the outputs' temporary names), its ``--wall-timeout`` counted
    from ``t0`` (the command's start); its result."""
    from humanoid_twin.replay import replay

    return replay(args.file, args.seed, laws=laws, can_interface=args.can_interface, out=files["out"],
                  can_log=files["can_log"], can_log_name=files["can_log_name"], info=info,
                  wall_timeout=None if args.wall_timeout is None
                  else max(0.0, args.wall_timeout - (time.monotonic() - t0)))


def _report(args: argparse.Namespace, res: Any, outputs: CheckedOutputs) -> int:
    """The files written, the result (``--json``: one JSON object), the first difference; the exit
    code."""
    written = {key: str(path) for key, path in outputs.final.items()}
    for path in written.values():
        sys.stderr.write(f"humanoid-twin replay: wrote {path}\n")
    if args.json:
        sys.stdout.write(json.dumps({"file": str(args.file), **res.as_dict(), **written}) + "\n")
    if res.difference is not None:
        sys.stderr.write(f"humanoid-twin replay: {args.file}: the twin's answers differ: {res.difference}\n")
        return EXIT_DIFFER
    if not args.json:
        sys.stdout.write(f"{args.file}: replayed {res.host_bytes} host bytes over {res.end_s:.3f} simulated "
                         f"s; the twin's {res.twin_bytes} answer bytes match the log\n")
    return 0
