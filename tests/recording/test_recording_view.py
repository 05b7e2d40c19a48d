"""What the recording's view shows (docs/recording.md, "Blueprint"): a robot that falls has a
"fell" line in the event log at the instant it fell; every plot of one quantity has a bright
colour of its own (not light grey) and every series a visible line width; the 3D eye frames a
fallen robot too. The pictures of these: docs/img (taken with
scripts/screenshot_viewer.py, looked at by eye)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import humanoid_twin
from humanoid_twin.protocol.wire import SCUS
from humanoid_twin.recording.columns import twin_columns
from humanoid_twin.recording.paths import CAN, ROBOT, SUPERVISOR


def _events(path: Path) -> list[tuple[float, str, str]]:
    """``(t_s, level, text)`` of every event line of a recording, in time order."""
    from rerun.chunk import RrdReader

    out = []
    for c in RrdReader(path).stream():
        if c.entity_path.lstrip("/") != f"{SUPERVISOR}/events":
            continue
        rb = c.to_record_batch()
        names = rb.schema.names
        t = rb.column(names.index("sim_time")).cast("int64").to_pylist()
        text = rb.column(next(i for i, n in enumerate(names) if n.endswith(":text"))).to_pylist()
        level = rb.column(next(i for i, n in enumerate(names) if n.endswith(":level"))).to_pylist()
        out += [(ti / 1e9, lv[0], tx[0]) for ti, lv, tx in zip(t, level, text, strict=True)]
    return sorted(out)


def test_a_fall_is_a_line_of_the_event_log_at_its_instant(tmp_path: Path) -> None:
    out = tmp_path / "shoved.rrd"
    with humanoid_twin.open("stand", out=out) as run:
        run.drive()                                 # the stand's balance gains
        run.step(0.3)
        run.twin.plant.set_trunk_force(20.0)        # a forward shove they do not hold
        run.step(0.2)
        run.twin.plant.set_trunk_force(0.0)
        while not run.read()["fell"] and run.now_s < run.boot_s + 4:
            run.step(0.1)
        fell_at = run.read()["fell_at_s"]
        run.step(1.0)                               # lying still
        _, bodies, _ = run.twin.plant.body_poses()
    assert fell_at is not None, "the shove did not topple the robot"
    # the default 3D eye still has the fallen robot in view: every body within 25 deg of its axis
    # (rerun's 3D view opens with a vertical field of view of ~55 deg)
    from humanoid_twin.recording import blueprint

    eye, target = np.array(blueprint.EYE_POSITION), np.array(blueprint.EYE_TARGET)
    axis = (target - eye) / np.linalg.norm(target - eye)
    rays = bodies - eye
    off_axis = np.degrees(np.arccos(rays @ axis / np.linalg.norm(rays, axis=1)))
    assert off_axis.max() < 25, f"a body of the fallen robot is {off_axis.max():.0f} deg off the eye's axis"
    fell = [(t, lv, tx) for t, lv, tx in _events(out) if tx.startswith("fell")]
    assert len(fell) == 1, _events(out)
    t, level, text = fell[0]
    assert t == pytest.approx(fell_at, abs=0.021) and level == "ERROR"
    assert re.fullmatch(r"fell: trunk \d+ deg, \d+ mm high", text), text


def test_a_run_that_stands_has_no_fell_line(tmp_path: Path) -> None:
    out = tmp_path / "stand.rrd"
    with humanoid_twin.open("stand", out=out) as run:
        run.step(0.5)
    assert [e for e in _events(out) if "fell" in e[2]] == []
    assert any("mode -> ready" in e[2] for e in _events(out))


def test_every_plot_of_one_quantity_has_a_colour_of_its_own_and_no_grey() -> None:
    from humanoid_twin.twin import Twin

    with Twin(seed=0) as twin:
        columns = twin_columns(twin, SCUS)
    # the Balance tab's plots and the bus rates: one series each, alone in their plot
    alone = (f"{CAN}/frames_per_s", f"{CAN}/load_percent")
    single = {c.path: c.colors[0] for c in columns
              if c.colors is not None and len(c.names) == 1 and (c.path.startswith(ROBOT) or c.path in alone)}
    assert f"{ROBOT}/trunk_tilt_deg" in single and len(single) == 8, single
    for path, (r, g, b) in single.items():
        assert max(r, g, b) - min(r, g, b) >= 80, f"{path}: {(r, g, b)} is a grey"
    balance = [p for p in single if p.startswith(ROBOT) and not p.endswith("/fell")]
    assert len({single[p] for p in balance}) == len(balance), "two Balance plots share a colour"
