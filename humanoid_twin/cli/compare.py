"""``humanoid-twin compare LOG`` and ``humanoid-twin calibrate LOG...`` (docs/calibration.md).

    humanoid-twin compare LOG [--seed N] [--support floor|stand] [--phases log|seed] [--out F.rrd] [--json]
    humanoid-twin calibrate LOG [LOG ...] --fit NAMES [--tie NAMES] [--validate LOG ...]
                            --out FILE.toml [--report FILE.html|.rrd] [--jobs N]
                            [--backend local|ray] [--json]

Both check their inputs first (one line, exit 2: a file that is not a CAN log, a log with no
Master frame or none of the robot's frames, an unknown parameter, an unwritable output) and
write their outputs under temporary names renamed at the end: a failed run replaces nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from humanoid_twin.cli.options import usage_error

__all__ = ["add_compare_parsers", "cmd_compare", "cmd_calibrate"]


def add_compare_parsers(sub: argparse._SubParsersAction[Any]) -> None:
    """The ``compare`` and ``calibrate`` subcommands (registered by cli/main.py)."""
    from humanoid_twin.compare.core import SUPPORTS

    cmp = sub.add_parser(
        "compare", help="drive the twin with a robot's CAN log and compare their sensor frames",
        description="The log's Master frames drive the twin's eight Slaves at their logged instants; "
        "each Sensors frame is compared with the log's frame of the same SCU, packet and round "
        "(docs/calibration.md).")
    cmp.add_argument("log", type=Path, help="a CAN log python-can reads (.blf .asc .log .csv .trc ...)")
    _twin_options(cmp, SUPPORTS)
    cmp.add_argument("--out", type=Path,
                     help="a rerun recording (.rrd): the twin's and the log's signals overlaid")
    cmp.add_argument("--json", action="store_true", help="print one JSON object on stdout")

    cal = sub.add_parser(
        "calibrate", help="fit the twin's parameters to robot CAN logs (bounded least squares)",
        description="Fit the named parameters so that the twin's Sensors frames match the logs' "
        "(each signal divided by its quantum); write the result as a params file (docs/calibration.md).")
    cal.add_argument("logs", type=Path, nargs="+", metavar="LOG", help="training CAN logs")
    cal.add_argument("--fit", required=True,
                     help="comma-separated parameter names or globs (each match fitted)")
    cal.add_argument("--tie", default="", help="comma-separated names or globs fitted as one shared value")
    cal.add_argument("--validate", type=Path, nargs="+", default=[], metavar="LOG",
                     help="validation logs (never fitted on)")
    cal.add_argument("--out", type=Path, required=True, help="the fitted parameters (.toml, a params file)")
    cal.add_argument("--report", type=Path, help="a report of every signal before and after (.html or .rrd)")
    cal.add_argument("--jobs", type=int, default=0, help="parallel rollouts (default: the cores)")
    cal.add_argument("--backend", choices=("local", "ray"), default="local",
                     help="where rollouts run: local processes (default) or a Ray cluster")
    cal.add_argument("--max-evaluations", type=int, default=200,
                     help="the fit's budget of evaluations (about: whole iterations; default 200)")
    cal.add_argument("--scan", type=int, default=0, metavar="K",
                     help="first try each parameter alone at K Jacobian steps (10 %% of its value) either "
                     "side of its start and start from the best (default 0: no scan; servo gains: 2)")
    cal.add_argument("--signals", default="position_deg,current,force_counts,imu_counts",
                     help="signal groups in the residual (default: all but speed)")
    cal.add_argument("--smooth", type=float, default=1.0, metavar="S",
                     help="each signal's residual averaged over S seconds of frames (default 1; 0: raw)")
    _twin_options(cal, SUPPORTS)
    cal.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _twin_options(p: argparse.ArgumentParser, supports: tuple[str, ...]) -> None:
    p.add_argument("--seed", type=int, default=0, help="the twin's seed (default 0)")
    p.add_argument("--support", choices=supports, default="floor",
                   help="floor: on its feet (default); stand: the trunk held in the air")
    p.add_argument("--phases", choices=("log", "seed"), default="log",
                   help="the Slaves' PWM phases: log (default: the seed's unless the log's silent rounds "
                   "contradict them, then read from the log) or seed (the seed's, always)")
    from humanoid_twin.cli.params import add_params_options

    add_params_options(p)       # --params FILE.toml, --set NAME=VALUE (docs/parameters.md)


def _read_log(path: Path) -> Any:
    from humanoid_twin.compare.robot_log import RobotLogError, read_robot_log

    try:
        return read_robot_log(path)
    except RobotLogError as exc:
        raise usage_error(str(exc)) from None


def twin_params(args: argparse.Namespace) -> dict[str, float]:
    """``--params FILE`` then each ``--set``, checked (one line, exit 2 on a bad one)."""
    from humanoid_twin.cli.params import params_from_args

    return params_from_args(args)


def _check_out(path: Path, what: str, suffixes: tuple[str, ...]) -> None:
    from humanoid_twin.cli.checked_outputs import check_writable

    if path.suffix.lower() not in suffixes:
        raise usage_error(f"{what} {path}: the file must end in {' or '.join(suffixes)}")
    check_writable(path, what)


def _commit(tmp: Path, final: Path) -> None:
    import os

    from humanoid_twin import signals

    with signals.deferred():
        os.replace(tmp, final)


def _temp(path: Path) -> Path:
    from humanoid_twin.outputs import temp_name

    return temp_name(path.expanduser())


def cmd_compare(args: argparse.Namespace) -> int:
    """``humanoid-twin compare``."""
    from humanoid_twin.compare.core import CompareOptions, compare_log

    if args.out is not None:
        _check_out(args.out, "--out", (".rrd",))
    params = twin_params(args)
    log = _read_log(args.log)
    opts = CompareOptions(seed=args.seed, support=args.support, params=params, phases=args.phases)
    result = compare_log(log, opts)
    if args.out is not None:
        from humanoid_twin.compare.overlay import write_overlay

        tmp = _temp(args.out)
        try:
            write_overlay(tmp, {"": result.series})
            _commit(tmp, args.out)
        finally:
            tmp.unlink(missing_ok=True)
    d = result.as_dict()
    if params:
        d["params"] = dict(params)
    if args.json:
        sys.stdout.write(json.dumps(d) + "\n")
    else:
        sys.stdout.write(compare_table(d))
    return 0


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.3f}"


def compare_table(d: dict[str, Any]) -> str:
    """The people's view of a comparison: frames, then RMS / largest difference per group and
    the five signals furthest from the log."""
    lines = [f"log: {d['log']}",
             f"frames compared {d['frames_compared']}, missing in the twin {d['frames_missing']['twin']}, "
             f"missing in the log {d['frames_missing']['log']}, warm-up {d['frames_warmup']}, "
             f"foreign {d['frames_foreign']}, error frames {d['error_frames']}",
             f"{'group':<14} {'rms':>9} {'max':>9}"]
    from_log = [f"SCU {scu} {p['us']} us" for scu, p in d.get("phases", {}).items() if p["from"] == "log"]
    if from_log:
        lines.insert(2, "Slaves' phases read from the log (the seed's contradict it): " + ", ".join(from_log))
    for g, v in d["rms"].items():
        lines.append(f"{g:<14} {_fmt(v):>9} {_fmt(d['max_abs'][g]):>9}")
    worst = sorted(((s["rms"] or 0.0, n) for n, s in d["signals"].items()), reverse=True)[:5]
    if worst and worst[0][0] > 0:
        lines.append("furthest: " + ", ".join(f"{n} {r:.3f}" for r, n in worst if r > 0))
    return "\n".join(lines) + "\n"


def cmd_calibrate(args: argparse.Namespace) -> int:
    """``humanoid-twin calibrate``: every input checked first, then the fit, then the outputs."""
    import os

    from humanoid_twin.compare.calibrate import FitProblem, fit, groups_arg, write_params_toml
    from humanoid_twin.compare.fitparams import ParamError, expand_fit

    _check_out(args.out, "--out", (".toml",))
    if args.report is not None:
        _check_out(args.report, "--report", (".html", ".rrd"))
    if args.jobs < 0:
        raise usage_error(f"--jobs {args.jobs}: must be 0 (the cores) or more")
    if not 0 <= args.smooth <= 60:
        raise usage_error(f"--smooth {args.smooth}: must be 0..60 s")
    if not 0 <= args.scan <= 10:
        raise usage_error(f"--scan {args.scan}: must be 0..10")
    if args.max_evaluations < 1:
        raise usage_error(f"--max-evaluations {args.max_evaluations}: must be 1 or more")
    try:
        groups = groups_arg(args.signals)
    except ValueError as exc:
        raise usage_error(str(exc)) from None
    if args.backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise usage_error("--backend ray needs Ray: pip install 'humanoid-twin[ray]'") from None
    from humanoid_twin.plant.sysid import SysidMissingError, toolbox

    try:
        toolbox()
    except SysidMissingError as exc:
        raise usage_error(str(exc).split(" (")[0]) from None
    base = twin_params(args)
    try:
        unknowns = expand_fit(args.fit, args.tie, base)
    except ParamError as exc:
        raise usage_error(str(exc)) from None
    fitted_names = {n for u in unknowns for n in u.names}
    logs = [_read_log(p) for p in args.logs]
    validate = [_read_log(p) for p in args.validate]
    jobs = args.jobs or os.cpu_count() or 1
    from humanoid_twin.master.pic import ROUND_US

    problem = FitProblem(logs=logs, unknowns=unknowns, seed=args.seed, support=args.support, groups=groups,
                         phases=args.phases,
                         base={k: v for k, v in base.items() if k not in fitted_names},
                         window=max(1, round(args.smooth * 1e6 / ROUND_US)))
    result = fit(problem, validate=validate, jobs=jobs, backend=args.backend,
                 max_evaluations=args.max_evaluations, scan=args.scan,
                 progress=lambda text: print(text, file=sys.stderr))
    d = result.as_dict()
    header = (f"humanoid-twin calibrate: {', '.join(str(p) for p in args.logs)} (seed {args.seed}, "
              f"support {args.support})\nresidual {d['residual_before']:.4f} -> {d['residual_after']:.4f} "
              "quanta RMS; parameters not identified are left out")
    temps = []
    try:
        tmp = _temp(args.out)
        temps.append((tmp, args.out))
        write_params_toml(tmp, result.values, header)
        if args.report is not None:
            rtmp = _temp(args.report)
            temps.append((rtmp, args.report))
            if args.report.suffix.lower() == ".rrd":
                from humanoid_twin.compare.overlay import write_overlay

                runs = {}
                for tag, pairs in (("training", zip(result.before, result.after, strict=True)),
                                   ("validation", zip(result.val_before, result.val_after, strict=True))):
                    for i, (b, a) in enumerate(pairs):
                        runs[f"before/{tag}{i}"] = b.series
                        runs[f"after/{tag}{i}"] = a.series
                write_overlay(rtmp, runs)
            else:
                from humanoid_twin.compare.report import write_report

                write_report(rtmp, result.fitted, d, list(zip(result.before, result.after, strict=True)),
                             list(zip(result.val_before, result.val_after, strict=True)))
        for t, final in temps:
            _commit(t, final)
    finally:
        for t, _ in temps:
            t.unlink(missing_ok=True)
    d["out"] = str(args.out)
    if args.report is not None:
        d["report"] = str(args.report)
    if args.json:
        sys.stdout.write(json.dumps(d) + "\n")
    else:
        sys.stdout.write(calibrate_table(d))
    return 0


def calibrate_table(d: dict[str, Any]) -> str:
    """The people's view of a fit."""
    lines = [f"{'parameter':<28} {'start':>10} {'fitted':>10}  95 % interval"]
    for name, e in d["fitted"].items():
        ci = "-" if e["ci95"] is None else f"{e['ci95'][0]:.4g} .. {e['ci95'][1]:.4g}"
        lines.append(f"{name:<28} {e['start']:>10.4g} {e['value']:>10.4g}  {ci}")
        if not e["identifiable"]:
            lines.append(f"  not identifiable from these logs: needs {e['needs']}")
    lines.append(f"residual {d['residual_before']:.4f} -> {d['residual_after']:.4f} quanta RMS "
                 f"({d['evaluations']} evaluations, {d['wall_s']:.1f} s)")
    if d["validation_before"] is not None:
        lines.append(f"validation {d['validation_before']:.4f} -> {d['validation_after']:.4f}")
    lines.append(f"wrote {d['out']}" + (f" and {d['report']}" if "report" in d else ""))
    return "\n".join(lines) + "\n"
