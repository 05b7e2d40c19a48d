"""A run's summary (``humanoid-twin run``'s table, ``--json``'s object, a sweep's row): built here
from the :class:`~humanoid_twin.rig.Rig` once the run is over. :data:`SUMMARY_KEYS` lists every
key, in order, with its meaning; docs/scenarios.md's table is generated from it."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from humanoid_twin.cycles import DEFAULT_PIC_MHZ
from humanoid_twin.faults import FaultSpec
from humanoid_twin.monitor import CONTROLLERS_START_S
from humanoid_twin.params import params_digest
from humanoid_twin.plan import Plan
from humanoid_twin.protocol.wire import SCUS, ControlType
from humanoid_twin.twin import Twin

if TYPE_CHECKING:
    from humanoid_twin.rig import Rig

__all__ = ["SUMMARY_KEYS", "SUMMARY_SUBKEYS", "summary_keys_markdown", "build_summary", "outcome",
           "SLIP_HELD_MM", "NO_SUPPORT_MARGIN_MM", "FOOT_SCUS", "plain_value", "table_cells", "table_columns"]

FOOT_SCUS = (1, 2)      # the leg boards (foot lateral, foot front, knee): the summary's ``control``


def build_summary(rig: Rig, scenario: str, plan: Plan, *, completed: bool, wall_s: float,
                  host_calls: int | None = None) -> dict[str, Any]:
    """The summary of the run ``scenario`` (its name as the user gave it) on ``rig``, whose plan
    was ``plan``: every key of :data:`SUMMARY_KEYS` that applies, in that order."""
    twin, opts = rig.twin, rig.opts
    sup = twin.the_master().supervisor
    summary: dict[str, Any] = {
        "scenario": scenario,
        "duration_s": round(twin.now_s, 6),
        **_balance(rig.monitor),
        **_run_facts(rig, plan, completed=completed, wall_s=wall_s),
    }
    if twin.params:     # the named parameters that differ from their defaults (none: every default)
        summary["params"] = dict(twin.params)
        summary["params_digest"] = params_digest(twin.params)
    summary |= {
        "mode": sup.mode_name,
        **rig.report.summary(),
        "faults": [f.as_dict() for f in sup.faults],
        # the faults that started (one whose T0 lies beyond the run's end is listed apart)
        "injected": [s.as_dict() for s in opts.faults if _started(s, rig)],
    }
    return summary | _what_went_wrong(rig, host_calls)


def _balance(monitor: Any) -> dict[str, Any]:
    """What the monitor saw of the robot: the fall, the trunk's tilt, the slide, the outcome, the
    CoP's margin (over the whole run, and over the motion alone)."""
    motion = monitor.motion if monitor.motion is not None and monitor.motion.samples else None
    return {
        "fell": monitor.fell,
        "fell_at_s": monitor.fell_at_s,
        "trunk_tilt_max_deg": round(monitor.trunk_tilt_max_deg, 3),
        "trunk_tilt_max_at_s": _time(monitor.trunk_tilt_max_at_s),
        "trunk_tilt_max_motion_deg": None if motion is None else round(motion.trunk_tilt_max_deg, 3),
        "trunk_tilt_max_motion_at_s": None if motion is None else _time(motion.trunk_tilt_max_at_s),
        "slip_mm": round(monitor.slip_mm, 1),
        "slip_mm_at_s": _time(monitor.slip_mm_at_s),
        "outcome": "diverged" if monitor.diverged is not None else outcome(monitor.fell, monitor.slip_mm),
        "cop_margin_min_mm": _finite(monitor.cop_margin_min_mm),
        "cop_margin_min_at_s": _time(monitor.cop_margin_min_at_s),
        "cop_margin_min_motion_mm": None if motion is None else _finite(motion.cop_margin_min_mm),
        "cop_margin_min_motion_at_s": None if motion is None else _time(motion.cop_margin_min_at_s),
        "cop_error_rms_mm": _round(monitor.cop_error_rms_mm),
    }


def _run_facts(rig: Rig, plan: Plan, *, completed: bool, wall_s: float) -> dict[str, Any]:
    """How the run went (its speed, the frames, the boot) and what it was given (tilt, control,
    seed)."""
    twin, opts = rig.twin, rig.opts
    return {
        "wall_s": round(wall_s, 3),
        "rtf": round(twin.now_s / wall_s, 3) if wall_s > 0 else None,
        "can_frames": twin.network.frames_sent,
        "serial_frames": twin.the_master().stats()["serial_frames_received"],
        "boot_s": None if rig.boot_s is None else round(rig.boot_s, 3),
        "booted": rig.boot_error is None,
        "completed": completed,
        "tilt_deg": opts.tilt,
        "control": _control_label(plan),
        "control_law": _law_label(twin, plan),
        "seed": opts.seed,
    }


def _what_went_wrong(rig: Rig, host_calls: int | None) -> dict[str, Any]:
    """The keys present only when they say something: faults that never started, a divergence, the
    host controller's error, the control laws that stopped; the host controller's calls."""
    twin, monitor = rig.twin, rig.monitor
    keys: dict[str, Any] = {}
    not_started = [s.as_dict() for s in rig.opts.faults if not _started(s, rig)]
    if not_started:
        keys["injected_not_started"] = not_started
    if monitor.diverged is not None:
        keys["diverged"] = f"t={monitor.diverged_at_s:.3f} s: {monitor.diverged}"
    if rig.host_error is not None:
        keys["host_error"] = rig.host_error
    law_faults = [sl.servo.law_fault for sl in twin.slaves.values() if sl.servo.law_fault is not None]
    if law_faults:
        keys["law_faults"] = [f.as_dict() for f in law_faults]
    if host_calls is not None:
        keys["host_controller_calls"] = host_calls
    return keys


def note_recording(summary: dict[str, Any], rig: Rig) -> None:
    """After the rig closed: when the compaction of its recording failed (no room for its copy, a
    signal), the file is kept as recorded and the summary says why."""
    if rig.recorder is not None and rig.recorder.compaction_error is not None:
        summary["recording_compacted"] = False
        summary["recording_note"] = rig.recorder.compaction_error


def _started(spec: FaultSpec, rig: Rig) -> bool:
    return any(s is spec for s in rig.injector.started)


# a foot that moved less than this along the platform held its place: a foot rolling onto an edge
# of its pads moves its sole origin a few mm without sliding (levantar_perna --perna 2: 7.1 mm)
SLIP_HELD_MM = 10.0


def outcome(fell: bool, slip_mm: float) -> str:
    """The run in one word: ``fell`` (the plant's fall test, against the platform), ``slid`` (did
    not fall, but a foot moved ``SLIP_HELD_MM`` or more along the platform), or ``held``."""
    if fell:
        return "fell"
    return "slid" if slip_mm >= SLIP_HELD_MM else "held"


# Every key a run's summary may hold, in the order the summary gives them, with what it means:
# docs/scenarios.md's table is generated from this (scripts/gen_docs.py; a test fails when they
# drift, another when a run's summary holds a key that is not here).
SUMMARY_KEYS: dict[str, str] = {
    "scenario": "the scenario run",
    "duration_s": "simulated seconds run (boot included)",
    "fell": "the plant's fall test at any 20 ms sample, against the platform the feet stand on: the "
            "trunk origin less than 0.12 m above the platform's plane, or the trunk more than 45 deg "
            "from both the vertical and the platform's normal (humanoid_twin/models/README.md section 9)",
    "fell_at_s": "the first sample that saw the robot fallen (none: it did not fall)",
    "trunk_tilt_max_deg": "largest angle between the trunk's z axis and the vertical",
    "trunk_tilt_max_at_s": "when (simulated s from power-on) `trunk_tilt_max_deg` was first reached",
    "trunk_tilt_max_motion_deg": "`trunk_tilt_max_deg` over the motion alone: the samples from "
                                 f"{CONTROLLERS_START_S:g} s after the boot's end (the controllers' start: "
                                 "docs/scenarios.md, \"When\") to the run's end; none when the boot "
                                 "failed or the run ended before",
    "trunk_tilt_max_motion_at_s": "when `trunk_tilt_max_motion_deg` was first reached",
    "slip_mm": "the largest distance a sole moved along the platform's surface while standing on it "
               "(since the run began, or since that foot was last set down): feet sliding down a "
               "tilted platform, not a fall",
    "slip_mm_at_s": "when the sole's slide reached `slip_mm` (none: no sole moved)",
    "outcome": "the run in one word: `fell`; `slid` (not fallen, but `slip_mm` reached 10 mm: a foot "
               "rolling onto an edge of its pads moves a few mm without sliding); `held`; `diverged` (the "
               "simulation blew up, see `diverged`: the run ended there, exit code 1; not a result)",
    "cop_margin_min_mm": "smallest signed distance of the ground-truth CoP (MuJoCo contact forces) inside "
                         "the support polygon (hull of the foot pads in contact), sampled every 20 ms; "
                         "negative when outside; **-1000** when at some sample no pad touched the "
                         "platform (the robot in the air or lying)",
    "cop_margin_min_at_s": "when `cop_margin_min_mm` was first reached",
    "cop_margin_min_motion_mm": "`cop_margin_min_mm` over the motion alone (as "
                                "`trunk_tilt_max_motion_deg`): what a sweep over the tilt should plot",
    "cop_margin_min_motion_at_s": "when `cop_margin_min_motion_mm` was first reached",
    "cop_error_rms_mm": "RMS distance between each leg board's firmware CoP (`calcCoP`, 7-bit forces, "
                        "integer mm) and the contact-force CoP of its foot, compared right after the "
                        "board's own 20 ms tick, while the foot is loaded and the board calibrated",
    "wall_s": "wall time of the run (simulation, host and recording)",
    "rtf": "real-time factor: simulated / wall seconds",
    "can_frames": "frames on the CAN wire",
    "serial_frames": "RS-232 requests the Master received",
    "boot_s": "when the boot ended (virtual seconds); none when the run ended before it did (faults "
              "stretched the boot past `--duration`)",
    "booted": "true when every board reported PWM on and calibrated (the boot worked); false: the "
              "boot failed (`host_error` says why) and the scenario's program did not run",
    "completed": "false when the run's end (`--duration`, or the default one) cut the boot or the "
                 "scenario's program before its end, the boot failed, or the simulation diverged; else true",
    "tilt_deg": "the platform's tilt asked for (`--tilt`)",
    "control": "the control type(s) the leg boards (SCU 1-2) ran, `+` between them: the scenario's "
               "own (`stand`: `balance`) or `--control`'s",
    "control_law": "the law that ran each of those types on the leg boards, `type=Class` (built-in), "
                   "or `type=module:Class` (a `--law` plug-in, docs/controllers.md)",
    "seed": "the run's seed",
    "params": "only when a named parameter differs from its default (`--params FILE.toml`, `--set "
              "NAME=VALUE`, docs/parameters.md): those parameters, name -> value",
    "params_digest": "only with `params`: 16 hex digits of SHA-256 of them (sorted JSON); two runs "
                     "with the same digest ran with the same numbers",
    "mode": "the Master supervisor's mode at the end (`ready`; `safe` or `estop`: exit code 3; "
            "docs/supervisor.md)",
    "task_load_max": "`{\"slaves\": F, \"master\": F}`: the largest fraction of its 20 ms period "
                     "any Slave's pass of the main loop used, its interrupts included, and the largest "
                     "fraction of its 250 us slot the Master's timer interrupt used (the Slaves at "
                     f"`--pic-mhz`, the Master always at {DEFAULT_PIC_MHZ:g} MHz; the PIC18 cycle table, "
                     "docs/firmware.md); above 1: the work overran",
    "deadline_misses": "per board (`master`, `1`..`8`): the Slave's passes that set `deadlineError` (a pass "
                       "past its 20 ms period, or a late start injected by `--fault deadline`), the "
                       "Master's 250 us slots whose interrupt work overran",
    "imu_tilt_error_rms_deg": "RMS difference between the trunk tilt the body board's inclinometer gives "
                              "(`readspecial(H, 5)`, docs/firmware.md) and the true tilt, after each of "
                              "that board's ticks once calibrated",
    "faults": "the faults the supervisor latched: name, node, time, detail each",
    "injected": "the `--fault` specs injected that started (docs/supervisor.md)",
    "injected_not_started": "only when some `--fault` starts beyond the run's end: those specs",
    "diverged": "only when the simulation diverged (MuJoCo's instability warning: a NaN, an infinite or a "
                "huge value in the state, which MuJoCo then resets; or a non-finite state): when and why",
    "host_error": "only when a host request failed while the supervisor was stopped or faults were "
                  "injected: that request's error (the run went on)",
    "law_faults": "only when a control law raised or returned a bad value: which law, board, time "
                  "and why (the board fell back to holding; docs/controllers.md)",
    "host_controller_calls": "only with `--host-controller`: how many times its `step` was called",
    "recording": "the `.rrd` written (the CLI)",
    "can_log": "the CAN log written (the CLI)",
    "serial_log": "the serial log written (the CLI; replay: docs/buses.md)",
    "recording_compacted": "only when the compaction of a long recording failed: `false`, the file "
                           "kept as recorded (docs/recording.md)",
    "recording_note": "only with `recording_compacted`: why the compaction failed",
}


# the keys whose value is a dict, and that dict's keys: a sweep's table gives each its own column,
# ``KEY_SUB`` (``task_load_max_slaves``, ``deadline_misses_3``: humanoid_twin/board_report.py)
SUMMARY_SUBKEYS: dict[str, tuple[str, ...]] = {
    "task_load_max": ("slaves", "master"),
    "deadline_misses": ("master", *(str(scu) for scu in SCUS)),
}


def plain_value(value: object) -> str:
    """A summary value as a person reads it (the run's table, a sweep table's list cells): ``-``
    for none, ``yes``/``no``, lists one item after another, ``; `` between them (a dict as
    ``key=value`` pairs), no Python reprs."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, dict):
        return " ".join(f"{k}={plain_value(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return "; ".join(plain_value(v) for v in value) if value else "-"
    return str(value)


def table_cells(summary: dict[str, Any]) -> dict[str, Any]:
    """A run's summary as the cells of a table row (a sweep's): a dict of numbers becomes one
    column per key (:data:`SUMMARY_SUBKEYS`: ``task_load_max_slaves`` ...), a list the words of
    the run's own table (:func:`plain_value`; an empty one, none), every other value as it is;
    no JSON text in a cell."""
    cells: dict[str, Any] = {}
    for key, value in summary.items():
        if isinstance(value, dict):
            for sub, v in value.items():
                cells[f"{key}_{sub}"] = plain_value(v) if isinstance(v, list | tuple | dict) else v
        elif isinstance(value, list | tuple):
            cells[key] = plain_value(value) if value else None
        else:
            cells[key] = value
    return cells


def table_columns() -> list[str]:
    """Every column :func:`table_cells` can give, in the summary's order."""
    cols: list[str] = []
    for key in SUMMARY_KEYS:
        cols += [f"{key}_{sub}" for sub in SUMMARY_SUBKEYS[key]] if key in SUMMARY_SUBKEYS else [key]
    return cols


def summary_keys_markdown() -> str:
    """docs/scenarios.md's table of the summary's keys, from :data:`SUMMARY_KEYS`."""
    lines = ["| key | meaning |", "|---|---|"]
    lines += [f"| `{key}` | {meaning} |" for key, meaning in SUMMARY_KEYS.items()]
    return "\n".join(lines) + "\n"


def _leg_control_types(the_plan: Plan) -> list[ControlType]:
    """The control types the leg boards (SCU 1, 2) run over the plan's motions, in type order."""
    types = {int(v) for v in np.asarray(the_plan.k)[[scu - 1 for scu in FOOT_SCUS], :, :, 3].ravel()}
    return [ControlType(t) for t in sorted(types)]


def _control_label(the_plan: Plan) -> str:
    """``control`` of the summary: the leg boards' control types, ``+`` between them (``stand``:
    ``balance``, the scenario's default; ``--control`` replaces them)."""
    return "+".join(t.label for t in _leg_control_types(the_plan))


def _law_label(twin: Twin, the_plan: Plan) -> str:
    """``control_law`` of the summary: which law class ran each of those types on the leg boards
    (``balance=JacobianLaw``; a ``--law`` plug-in by its module and class)."""
    servo = twin.slaves[FOOT_SCUS[0]].servo
    parts = []
    for t in _leg_control_types(the_plan):
        law = servo.law(int(t))
        cls = type(law)
        name = cls.__qualname__
        if cls.__module__ != "humanoid_twin.slave.laws":
            name = f"{cls.__module__}:{name}"
        parts.append(f"{t.label}={name}")
    return " ".join(parts)


def _round(x: float | None) -> float | None:
    return None if x is None else round(x, 3)


def _time(t_s: float | None) -> float | None:
    """A sample's simulated time (s), to the microsecond of the clock."""
    return None if t_s is None else round(t_s, 6)


# cop_margin_min_mm when no foot pad touched the platform at some sample (airborne or fallen):
# the CoP is then outside any support polygon, by more than any foot length.
NO_SUPPORT_MARGIN_MM = -1000.0


def _finite(x: float) -> float | None:
    if math.isinf(x):
        return None if x > 0 else NO_SUPPORT_MARGIN_MM
    return round(max(x, NO_SUPPORT_MARGIN_MM), 3)


