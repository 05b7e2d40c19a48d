"""Every value of a ``run`` checked before anything runs or is written: the command ``run`` and
each grid point of a ``sweep`` (cli/sweep.py) go through the same checks."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from humanoid_twin.cli.messages import one_line
from humanoid_twin.cli.options import check_rig_inputs, load_scenario_arg, usage_error


def check_run_inputs(args: argparse.Namespace, load: bool = True) -> dict[str, Any]:
    """Every value of ``run`` checked before anything runs or is written (one line, exit 2): its
    own, the scenario (loaded: a user's is imported here) and its planner's limits, then what it
    shares with ``serve`` (:func:`~humanoid_twin.cli.options.check_rig_inputs`). Returns the
    loaded controllers; ``load`` False: the ``--law`` s and ``--host-controller`` are not imported
    again (a sweep's later grid points)."""
    _check_run_options(args)
    _check_scenario(args)
    return check_rig_inputs(args, load=load)


def _check_run_options(args: argparse.Namespace) -> None:
    """``run``'s own options: --no-record against --out, --duration within its bounds."""
    from humanoid_twin.scenarios import BOOT_MIN_S, MAX_DURATION_S

    if args.no_record and args.out is not None:
        raise usage_error(f"--no-record and --out {args.out} contradict each other: drop one")
    if args.duration is not None and args.duration > MAX_DURATION_S:
        raise usage_error(f"--duration {args.duration:g}: at most {MAX_DURATION_S:g} simulated seconds")
    if args.duration is not None and args.duration < BOOT_MIN_S:
        raise usage_error(f"--duration {args.duration:g} is shorter than the boot (the Slaves calibrate for "
                          f"{BOOT_MIN_S:g} s; the boot takes ~2.65 simulated seconds): give at least that")


def _check_scenario(args: argparse.Namespace) -> None:
    """The scenario loaded (a user's is imported here), planned and sized with the run's values."""
    from humanoid_twin.cli.params import scenario_with_fields
    from humanoid_twin.scenarios import ScenarioError, ScenarioInputError, scenario_motion_s, scenario_plan

    spec = scenario_with_fields(load_scenario_arg(args.scenario), args)    # --set scenario.FIELD=V
    try:   # the planners' own limits (T fits one byte of 20 ms ticks, each joint's range ...), and
        # the scenario's length (motion_s, checked like --duration: it sizes the outputs' disk space)
        scenario_motion_s(spec, scenario_plan(spec, args.scenario, args.T, args.motion, args.perna),
                          args.scenario)
    except ScenarioInputError as exc:
        raise usage_error(str(exc)) from None
    except ScenarioError as exc:       # the user's own code raised (its plan, its motion_s)
        sys.stderr.write(f"humanoid-twin: {one_line(str(exc))}\n")
        raise SystemExit(1) from None
