"""``humanoid-twin run``: a scenario headless against the in-process twin. Its inputs are checked
first (cli/run_checks.py: one line, exit 2), its outputs created under temporary names
(cli/checked_outputs.py), the run watched (a progress bar, MuJoCo's viewer), then reported: the
outputs renamed, the summary on stdout, the exit code (docs/scenarios.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from humanoid_twin.cli.checked_outputs import CheckedOutputs
from humanoid_twin.cli.messages import one_line, stop_reason
from humanoid_twin.cli.options import run_options, usage_error
from humanoid_twin.cli.run_checks import check_run_inputs

EXIT_SUPERVISOR = 3     # the run ended with the supervisor in safe or estop (docs/supervisor.md)


def cmd_run(args: argparse.Namespace) -> int:
    """``humanoid-twin run``: ``--wall-timeout`` is armed from its first line (importing, planning
    and sizing the scenario included: a user's loop there ends in one line, exit 1)."""
    from humanoid_twin import signals
    from humanoid_twin.scenarios import WallTimeoutExpired, arm_wall_timeout, disarm_wall_timeout

    signals.user_code_runs()        # the scenario, laws and controller are imported next
    try:
        arm_wall_timeout(args.wall_timeout)
        return _check_and_run(args)
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


def _check_and_run(args: argparse.Namespace) -> int:
    """Every input checked, the outputs created (their disk space sized by the run's length), the
    run; whatever was not committed is removed."""
    from humanoid_twin import signals

    controllers = check_run_inputs(args)
    if args.viewer:
        from humanoid_twin.cli.live_viewer import LiveViewerError, check_display

        try:
            check_display()
        except LiveViewerError as exc:
            raise usage_error(str(exc)) from None
    from humanoid_twin.scenarios import ScenarioError, ScenarioInputError, expected_run_s, recording_name

    try:    # what sizes the outputs' disk space: a user's motion_s, called (and checked) again
        expected_s = expected_run_s(args.scenario, args.duration, args.T, args.motion, args.perna, args.tilt)
    except ScenarioInputError as exc:
        raise usage_error(str(exc)) from None
    except ScenarioError as exc:
        sys.stderr.write(f"humanoid-twin: {one_line(str(exc))}\n")
        return 1
    # --out was checked with the other inputs; the default name ends in .rrd
    out = None if args.no_record else (args.out or Path(recording_name(args.scenario)))
    outputs = CheckedOutputs()
    signals.on_hard_exit(outputs.discard)     # --wall-timeout against code that swallows the stop
    try:
        files = outputs.open_all(out, args, expected_s)
        return _run(args, run_options(args, controllers, files), outputs)
    finally:
        outputs.discard()       # whatever was not committed


class _Watchers:
    """What watches a run: the progress bar on stderr, MuJoCo's live viewer (each optional)."""

    def __init__(self, args: argparse.Namespace, opts: Any) -> None:
        self.bar: Any = None
        self.live: Any = None
        self.viewer_errors: tuple[type[Exception], ...] = ()
        if opts.progress:
            from humanoid_twin.cli.progress import RunProgress

            self.bar = RunProgress(args.scenario, sys.stderr, duration_s=args.duration)
        if args.viewer:
            from humanoid_twin.cli.live_viewer import LiveViewer, LiveViewerError

            self.live, self.viewer_errors = LiveViewer(), (LiveViewerError,)

    def callbacks(self) -> dict[str, Any]:
        """The run's ``on_progress``, ``on_twin`` and ``on_boot`` (None where nothing watches)."""
        bar = self.bar
        return {"on_progress": None if bar is None else bar.update,
                "on_twin": None if self.live is None else self.live.attach,
                "on_boot": None if bar is None else bar.boot_ended}

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        if self.live is not None:
            self.live.close()


def _run(args: argparse.Namespace, opts: Any, outputs: CheckedOutputs) -> int:
    """The run, watched; a failure is one line and its exit code, a result is reported."""
    from humanoid_twin import signals
    from humanoid_twin.recording.readback import RrdReadError
    from humanoid_twin.scenarios import ScenarioError, ScenarioInputError, disarm_wall_timeout, run

    watchers = _Watchers(args, opts)
    try:
        try:
            summary = run(opts, **watchers.callbacks())
        finally:
            disarm_wall_timeout()        # the run is over: what is left is the CLI's own work
    except ScenarioInputError as exc:
        raise usage_error(str(exc)) from None
    except ScenarioError as exc:
        sys.stderr.write(f"humanoid-twin: {one_line(outputs.final_names(str(exc)))}\n")
        return 1
    except watchers.viewer_errors as exc:        # the window could not open (nothing written yet)
        raise usage_error(str(exc)) from None
    except KeyboardInterrupt as exc:
        # SIGINT / SIGTERM (humanoid_twin/signals.py, installed by main): the run closed its files
        # on the way out, each complete before the signal was let through: what was recorded is
        # kept (valid files)
        signals.user_code_done()
        outputs.commit()
        sys.stderr.write(f"humanoid-twin: {stop_reason(exc)}{outputs.kept()}\n")
        return signals.exit_code(exc)
    except (OSError, RrdReadError) as exc:
        # a full disk (or a file-size limit) while writing: one line, nothing replaced
        sys.stderr.write(outputs.write_failed(exc))
        return 1
    finally:
        watchers.close()
    return _report(args, summary, outputs)


def _report(args: argparse.Namespace, summary: dict, outputs: CheckedOutputs) -> int:
    """A finished run: its outputs renamed (not a diverged one's), its warnings and the summary
    printed; the exit code."""
    if summary.get("outcome") == "diverged":
        # not a result: no output replaced, the summary printed for the record, one line, exit 1
        sys.stderr.write(f"humanoid-twin: the simulation diverged ({summary.get('diverged')}): the run "
                         "ended there; its outputs are not written\n")
        outputs.discard()
        print_summary(summary, args.json, args.stdout)
        return 1
    if summary.get("boot_s") is None:
        sys.stderr.write(f"humanoid-twin: warning: the run ended at {summary['duration_s']:g} s (--duration) "
                         "before the boot did (~2.65 s, longer under faults): the scenario's program did "
                         "not run\n")
    _commit(args, summary, outputs)
    for fault in summary.get("law_faults", ()):
        sys.stderr.write(f"humanoid-twin: control law {fault['law']} stopped on SCU {fault['scu']} at "
                         f"t={fault['t_s']} s: {fault['reason']}\n")
    print_summary(summary, args.json, args.stdout)
    return EXIT_SUPERVISOR if summary.get("mode") in ("safe", "estop") else 0


def _commit(args: argparse.Namespace, summary: dict, outputs: CheckedOutputs) -> None:
    """The outputs renamed to their final names, which the summary names; the recording's lines
    (the default name written or replaced, a recording kept uncompacted)."""
    final = outputs.final
    replaced = "out" in final and final["out"].exists()
    outputs.commit()
    if "out" in final:
        summary["recording"] = str(final["out"])
        if args.out is None:      # the default name: say which file was written (and replaced)
            sys.stderr.write(f"humanoid-twin: wrote {final['out']}"
                             + (" (replacing the earlier one; --out FILE.rrd picks another)"
                                if replaced else "")
                             + "\n")
        if summary.get("recording_compacted") is False:
            sys.stderr.write(f"humanoid-twin: warning: {final['out']} kept as recorded, not "
                             f"compacted: {outputs.final_names(summary.get('recording_note', ''))}\n")
    if "can_log" in final:
        summary["can_log"] = str(final["can_log"])
    if "serial_log" in final:
        summary["serial_log"] = str(final["serial_log"])


def summary_table(summary: dict) -> str:
    """The human summary: one ``key  value`` line per key, plain values (docs/scenarios.md)."""
    from humanoid_twin.summary import plain_value

    width = max(len(k) for k in summary)
    return "".join(f"{key:<{width}}  {plain_value(value)}\n" for key, value in summary.items())


def print_summary(summary: dict, as_json: bool, out: Any) -> None:
    """``--json``: the JSON object alone on stdout (for machines); otherwise the human table.
    ``out``: the command's stdout (cli/streams.py; None: the process has none)."""
    if out is None:
        return
    out.write(json.dumps(summary, sort_keys=False) + "\n" if as_json else summary_table(summary))
    out.flush()
