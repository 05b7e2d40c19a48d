"""The default layout a twin recording opens with (``rerun.blueprint``, rerun-sdk 0.41).

Left: the robot in 3D (bodies, platform, floor, ground-truth CoP, support polygon, CoM) over the
two foot views (outline, sensors with their loads, firmware vs ground-truth CoP). Right, in
tabs: the leg joints (reference / trajectory / measured / true per joint), currents, force
sensors, CoP and balance, bus counters, and the upper-body boards.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import rerun as rr
import rerun.blueprint as rrb
from rerun.blueprint.encodings import TextLogColumn, TextLogColumnKind

from humanoid_twin.hardware import FOOT_OF_SCU, IMU_SCU, LEG_SCUS, N_SERVOS, SERVO_JOINTS
from humanoid_twin.protocol.wire import SCUS
from humanoid_twin.recording.paths import (
    CAN,
    FEET,
    KEYS,
    ROBOT,
    SERIAL,
    SUPERVISOR,
    WORLD,
    foot_side,
    scu_path,
    servo_path,
)

__all__ = ["default_blueprint", "log_keys", "LEG_SCUS"]



# The 3D eye: framed on the robot (about 0.5 m tall, standing at the origin, facing +x), seen from
# its front right and above, instead of rerun's default framing of the whole floor; far enough
# that a robot that falls, whichever way (its 0.5 m along the floor around its feet), stays whole
# in the picture: the eye at (0.70, -0.60, 0.45) looking at the hips lost a fallen robot at the
# edge of the view, and rerun's tracking of the trunk (EyeControls3D.tracking_entity) kept the
# eye at its height while the trunk fell, looking at the robot's side from the floor.
EYE_POSITION = (1.00, -0.85, 0.75)
EYE_TARGET = (0.05, 0.0, 0.12)
# Legends: in the top-left corner of a plot with several series; none on a plot with one (its
# title names it) nor on the joint plots, whose five series are named once, in a key line above
# their grid (five-entry legends covered the first seconds of every joint plot).
_LEGEND = rrb.PlotLegend(corner="LeftTop", visible=True)
_NO_LEGEND = rrb.PlotLegend(visible=False)
# Fixed y ranges where rerun's own would show a single tick label: a flag from 0 to 1, the
# supervisor's modes 0-4 (a user can still zoom out).
_FLAG_RANGE = (-0.1, 1.1)
_MODE_RANGE = (-0.5, 4.5)
# the event log: time, level, text (every event is on one entity: its path says nothing)
_LOG_COLUMNS = rrb.TextLogColumns(text_log_columns=[
    TextLogColumn(TextLogColumnKind.LogLevel), TextLogColumn(TextLogColumnKind.Body),
    TextLogColumn(TextLogColumnKind.EntityPath, visible=False)])
JOINT_KEY = f"{KEYS}/joints"
JOINT_KEY_TEXT = ("Each plot: one joint, degrees (servo frame). **grey** reference (the Master's target), "
                  "**blue** trajectory (this tick's set-point), **purple** commanded (the PWM's position), "
                  "**orange** measured (the firmware's potentiometer), **green** true (the plant). "
                  "Hover a curve for its value.")


def _plot(name: str, origin: str, *, legend: bool = True, y_range: tuple[float, float] | None = None,
          **kw: Any) -> rrb.TimeSeriesView:
    axis = None if y_range is None else rrb.ScalarAxis(range=y_range)
    return rrb.TimeSeriesView(name=name, origin=origin, plot_legend=_LEGEND if legend else _NO_LEGEND,
                              axis_y=axis, **kw)


def _joint_title(scu: int, i: int) -> str:
    return f"{SERVO_JOINTS[scu][i]} (SCU {scu} servo {i + 1}), deg"


def _joint_grid(scus: Sequence[int], name: str) -> rrb.Vertical:
    views = [
        _plot(_joint_title(scu, i), f"{servo_path(scu, i)}/position", legend=False)
        for scu in scus
        for i in range(N_SERVOS)
    ]
    key = rrb.TextDocumentView(origin=JOINT_KEY, titlebar=False, name="key")
    rows = -(-len(views) // 2)
    return rrb.Vertical(key, rrb.Grid(*views, grid_columns=2), row_shares=[1, 6 * rows], name=name)


def log_keys(rec: rr.RecordingStream) -> None:
    """The static texts the blueprint shows (the joint tabs' colour key), into recording ``rec``."""
    rec.log(JOINT_KEY, rr.TextDocument(JOINT_KEY_TEXT, media_type=rr.MediaType.MARKDOWN), static=True)


PARAMS = "params"       # the run's non-default named parameters (docs/parameters.md), a text document


def params_markdown(params: Mapping[str, float]) -> str:
    """The Parameters tab's text: the non-default parameters, one row each."""
    from humanoid_twin.params import params_digest, registry

    reg = registry()
    lines = [f"Parameters that differ from their defaults (docs/parameters.md); digest "
             f"`{params_digest(params)}`.", "", "| name | value | default | unit |", "|---|---|---|---|"]
    for name, v in params.items():
        p = reg.get(name)
        lines.append(f"| `{name}` | {v:g} | {p.default:g} | {p.unit} |")
    return "\n".join(lines) + "\n"


def log_params(rec: rr.RecordingStream, params: Mapping[str, float]) -> None:
    """The run's non-default parameters into recording ``rec``: a recording property ``params``
    (name -> value; rerun's recording properties) and the Parameters tab's static text."""
    from humanoid_twin.params import params_digest

    rec.send_property(PARAMS, rr.AnyValues(**{name: float(v) for name, v in params.items()},  # type: ignore[arg-type]  # rerun's **kwargs of any value
                                           params_digest=params_digest(params)))
    rec.log(PARAMS, rr.TextDocument(params_markdown(params), media_type=rr.MediaType.MARKDOWN), static=True)


def default_blueprint(
    scus: Sequence[int] = SCUS, master_entities: Sequence[str] = (), params: bool = False,
    active_tab: str | None = None,
) -> rrb.Blueprint:
    """The blueprint sent with every recording (see docs/recording.md, "Blueprint");
    ``master_entities``: the ``master/...`` counter entities, one plot each; ``params``: a
    Parameters tab (a run with non-default parameters, :func:`log_params`); ``active_tab``: the
    name of the tab shown first (default the first, the right leg's joints)."""
    feet = [s for s in scus if s in FOOT_OF_SCU]
    tabs = _tabs(scus, feet, master_entities, params)
    return rrb.Blueprint(
        rrb.Horizontal(_robot_views(feet), rrb.Tabs(*tabs, active_tab=_tab_index(tabs, active_tab)),
                       column_shares=[2, 3]),
        rrb.TimePanel(timeline="sim_time", state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )


def _robot_views(feet: Sequence[int]) -> rrb.Container | rrb.View:
    """The left of the window: the robot in 3-D, each foot's CoP under it."""
    robot_3d = rrb.Spatial3DView(
        name="Robot", origin=WORLD,
        eye_controls=rrb.EyeControls3D(position=EYE_POSITION, look_target=EYE_TARGET, eye_up=(0.0, 0.0, 1.0)),
    )
    foot_views = [
        rrb.Spatial2DView(name=f"{foot_side(s).capitalize()} foot CoP (mm)", origin=f"{FEET}/{foot_side(s)}")
        for s in feet
    ]
    return rrb.Vertical(robot_3d, rrb.Horizontal(*foot_views), row_shares=[3, 2]) if foot_views else robot_3d


def _currents_tab(scus: Sequence[int]) -> rrb.Grid:
    """Each board's servo currents."""
    return rrb.Grid(
        *[
            _plot(
                name=f"{scu_path(s).split('/')[1]} current (0..100)",
                origin=scu_path(s),
                contents=[f"{servo_path(s, i)}/current" for i in range(N_SERVOS)],
            )
            for s in scus
        ],
        grid_columns=2,
        name="Currents",
    )


def _forces_tab(feet: Sequence[int]) -> rrb.Grid:
    """Each foot's force sensors, as the firmware reads them and as the plant applies them."""
    return rrb.Grid(
        *[
            _plot(
                name=f"{foot_side(s)} foot sensors, firmware 8-bit", origin=f"{scu_path(s)}/force/adc"
            )
            for s in feet
        ],
        *[
            _plot(
                name=f"{foot_side(s)} foot sensors, plant (N)", origin=f"{scu_path(s)}/force/newton"
            )
            for s in feet
        ],
        grid_columns=2,
        name="Force sensors",
    )


def _cop_tab(feet: Sequence[int]) -> rrb.Grid:
    """Each foot's CoP, firmware against truth."""
    # the CoP plots get a tab of their own: taller plots, readable ticks on a few mm of motion
    return rrb.Grid(
        *[
            _plot(
                name=f"{foot_side(s)} CoP {axis} (mm, {'right' if axis == 'x' else 'forward'} +): "
                     "firmware vs truth",
                origin=f"{scu_path(s)}/cop/{axis}",
            )
            for s in feet
            for axis in ("x", "y")
        ],
        grid_columns=2,
        name="CoP",
    )


def _balance_tab() -> rrb.Grid:
    """The robot's balance: CoP margin, trunk tilt, CoM height, the fall, the platform."""
    return rrb.Grid(
        _plot(name="CoP margin (mm)", origin=f"{ROBOT}/cop_margin_mm", legend=False),
        _plot(name="trunk tilt (deg)", origin=f"{ROBOT}/trunk_tilt_deg", legend=False),
        _plot(name="CoM height (mm)", origin=f"{ROBOT}/com_height_mm", legend=False),
        _plot(name="fell (0 no, 1 yes)", origin=f"{ROBOT}/fell", legend=False, y_range=_FLAG_RANGE),
        _plot(name="platform tilt (deg, toes up +)", origin=f"{ROBOT}/platform_tilt_deg", legend=False),
        _plot(name="total normal force (N)", origin=f"{ROBOT}/total_force_n", legend=False),
        grid_columns=2,
        name="Balance",
    )


def _counters_tab(master_entities: Sequence[str]) -> rrb.Grid:
    """The CAN wire's and the serial cable's counters, the Master's."""
    return rrb.Grid(
        _plot(name="CAN frames/s", origin=f"{CAN}/frames_per_s", legend=False),
        _plot(name="CAN bus load (%)", origin=f"{CAN}/load_percent", legend=False),
        _plot(
            name="CAN errors", origin=CAN, contents=[f"{CAN}/error_frames", f"{CAN}/frames_dropped"]
        ),
        _plot(name="Master CAN controller (state, TEC, REC)", origin=f"{CAN}/master_controller"),
        _plot(name="serial bytes (cable)", origin=SERIAL),
        *[
            _plot(name=f"Master {p.split('/', 1)[1].replace('_', ' ')} (count)", origin=p)
            for p in master_entities
        ],
        grid_columns=2,
        name="Counters",
    )


def _boards_tab(scus: Sequence[int]) -> rrb.Grid:
    """Each board's status and task time; the body board's IMU against truth."""
    return rrb.Grid(
        *[
            _plot(
                name=f"{scu_path(s).split('/')[1]}: PWM, calibrated, deadline violations",
                origin=scu_path(s),
                contents=[f"{scu_path(s)}/status", f"{scu_path(s)}/deadline_violations"],
            )
            for s in scus
        ],
        *[
            _plot(name=f"{scu_path(s).split('/')[1]}: task time per tick vs its 20 ms budget (ms)",
                  origin=f"{scu_path(s)}/task_ms")
            for s in scus
        ],
        *[
            _plot(name=f"trunk {what.replace('_', ' ')}: body board sensor vs truth",
                  origin=f"{scu_path(IMU_SCU)}/imu/{what}")
            for what in ("roll", "pitch", "roll_rate", "pitch_rate") if IMU_SCU in scus
        ],
        grid_columns=2,
        name="Boards",
    )


def _supervisor_tab() -> rrb.Horizontal:
    """The supervisor's mode beside its events."""
    # the events beside the plot: a log's lines are short, a full-width table left most of it empty
    return rrb.Horizontal(
        _plot("Supervisor mode and faults latched", f"{SUPERVISOR}/mode", y_range=_MODE_RANGE),
        rrb.TextLogView(name="Events: modes, faults, injections, the fall", origin=f"{SUPERVISOR}/events",
                        columns=_LOG_COLUMNS),
        column_shares=[1, 1],       # [3, 2] cut the longer lines (a fall's) at the window's edge
        name="Supervisor",
    )


def _tabs(scus: Sequence[int], feet: Sequence[int], master_entities: Sequence[str], params: bool
          ) -> list[rrb.Container]:
    """The tabs, in order: the legs' joints, the currents, the feet's (forces, CoP, balance), the
    counters, the supervisor, the boards, the upper body's joints, the parameters."""
    legs = [s for s in LEG_SCUS if s in scus]
    upper = [s for s in scus if s not in LEG_SCUS]
    tabs: list[rrb.Container] = []
    # one tab per leg (its hip board and its leg board: 6 joints, 3 rows), so each plot is tall
    # enough for its legend to name all five series beside the curves
    for side, pair in (("Right leg joints", (3, 1)), ("Left leg joints", (4, 2))):
        mine = [s for s in pair if s in legs]
        if mine:
            tabs.append(_joint_grid(mine, side))
    tabs += [_currents_tab(scus)]
    if feet:
        tabs += [_forces_tab(feet), _cop_tab(feet), _balance_tab()]
    tabs += [_counters_tab(master_entities), _supervisor_tab(), _boards_tab(scus)]
    if upper:
        tabs.append(_joint_grid(upper, "Upper body"))
    if params:
        tabs.append(rrb.TextDocumentView(origin=PARAMS, name="Parameters"))  # type: ignore[arg-type]  # a view is a tab too
    return tabs


def _tab_index(tabs: Sequence[rrb.Container], name: str | None) -> int | None:
    """The index of the tab called ``name`` (rerun names only views, not containers, as tabs)."""
    if name is None:
        return None
    names = [str(t.name) for t in tabs]
    if name not in names:
        raise ValueError(f"no tab {name!r} (the tabs: {', '.join(names)})")
    return names.index(name)
