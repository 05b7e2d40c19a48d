"""Recording: rerun .rrd of a running twin, CAN logs, read-back (real rerun, python-can, MuJoCo).

One driven run (module fixture, 3 s of virtual time) is recorded to an .rrd and an .asc CAN log:
every board gets PWM on at 0 degrees over RS-232, calibrates (~2.5 s), then both legs bend the
knee 10 degrees. The files are read back with rerun's own loader and python-can's LogReader.
"""

from __future__ import annotations

import math
import pathlib

import can
import numpy as np
import pytest

from humanoid_twin import recording
from humanoid_twin.hardware import N_SERVOS
from humanoid_twin.protocol import canframes, rs232
from humanoid_twin.protocol.wire import N_SCU
from humanoid_twin.recording import (
    CanLog,
    CanLogError,
    RrdReadError,
    check_log_path,
    decode_can_log,
    read_can_log,
    read_rrd_entities,
    read_rrd_rows,
    read_rrd_scalars,
    rrd_has_blueprint,
    verify_rrd,
)
from humanoid_twin.recording.columns import Column, ColumnGroup
from humanoid_twin.twin import Twin

DURATION_US = 3_000_000
PERIOD_US = 20_000
ROWS = DURATION_US // PERIOD_US + 1        # samples at 0, 20 ms, ..., 3.0 s
KNEE_DEG = 10
# the digest of the driven run's recording (test_recorded_content_is_pinned)
RECORDED_CONTENT_SHA256 = "407c2385dd6ee42bc3e54fb34c2759580f76b1665f1f611cf5a84d49fa5d33ba"


def _request(port, op: int, scu: int, param: int, d1: int = 0, d2: int = 0, d3: int = 0) -> bytes:
    port.write(rs232.encode_request(op, scu, param, d1, d2, d3))
    answer = port.read(6)
    assert answer[:1] == bytes([rs232.MESSAGE_SUCCESS]), answer.hex()
    return answer


def _power_up(twin: Twin) -> None:
    """Every board: positions 0, PWM on (starts its calibration)."""
    port = twin.open_port()
    for scu in range(1, N_SCU + 1):
        _request(port, rs232.Op.APPLY_JOINT, scu, rs232.PARAM_POSITION, 0, 0, 0)
        _request(port, rs232.Op.APPLY_JOINT, scu, rs232.PARAM_SPECIAL, 1, 0, 0)
    return port


def _drive(twin: Twin) -> None:
    port = _power_up(twin)
    twin.advance_to(2_600_000)
    for scu in (1, 2):   # knee 10 degrees in 10 ticks (0.2 s)
        _request(port, rs232.Op.APPLY_JOINT, scu, rs232.PARAM_VELOCITY, 10, 10, 10)
        _request(port, rs232.Op.APPLY_JOINT, scu, rs232.PARAM_POSITION, 0, 0, KNEE_DEG)
    twin.advance_to(DURATION_US)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The recorded run: (rrd path, asc path, recorder, can log, facts taken from the live twin)."""
    d = tmp_path_factory.mktemp("rec")
    rrd, asc = d / "run.rrd", d / "run.asc"
    with Twin(seed=0) as twin:
        with recording.Recorder(rrd, twin, chunk_s=2.0) as rec, CanLog(asc, twin.network) as log:
            _drive(twin)
            facts = {
                "knee_true": [twin.plant.servo_angle_deg(scu, 2) for scu in (1, 2)],
                "knee_measured": [twin.slaves[scu].sensors.servo[2].pos for scu in (1, 2)],
                "frames_sent": twin.network.frames_sent,
                "qpos": twin.plant.data.qpos.copy(),
                "sim_s": twin.now_s,
            }
        facts["rec_cost"] = rec.cost_per_sim_s()
    return rrd, asc, rec, log, facts


# --- the .rrd --------------------------------------------------------------------------------


def test_rrd_holds_every_entity_with_one_row_per_sample(run):
    rrd, _, rec, _, _ = run
    assert rec.samples == ROWS and rec.closed
    rows = read_rrd_rows(rrd)
    assert set(rec.entities) <= set(rows), sorted(set(rec.entities) - set(rows))
    every = {c.path: c.every for c in rec.columns}          # slow counters: every k-th sample
    assert set(every.values()) == {1, 5}
    wrong = {e: rows[e] for e in rec.entities if rows[e] != -(-ROWS // every.get(e, 1))}
    assert not wrong, wrong
    # static content: robot geometry per body, platform, floor, foot outline and sensors
    entities = read_rrd_entities(rrd)
    for e in ("world/bodies/trunk/boxes", "world/bodies/r_knee_link/boxes", "world/bodies/platform/boxes",
              "world/bodies/l_foot/spheres", "world/floor/0", "feet/right/outline", "feet/left/sensors"):
        assert e in entities, e
    for scu in range(1, N_SCU + 1):
        for i in range(1, N_SERVOS + 1):
            assert any(e.startswith(f"scu/{scu}_") and e.endswith(f"servo{i}/position") for e in entities)
    assert rrd_has_blueprint(rrd)


def test_extra_columns_are_recorded_and_slow_ones_read_only_on_their_rows(tmp_path):
    # a user's own series (Recorder(columns=...)): one every sample, one every 5th sample whose
    # reader (as an expensive one would be) is called only on the rows it is written on
    fast_calls: list[int] = []
    slow_calls: list[int] = []

    def fast(t):
        fast_calls.append(t.now_us)
        return (t.now_us / 1000.0,)

    def slow(t):
        slow_calls.append(t.now_us)
        return (float(len(slow_calls)), -1.0)

    def since(t, raw, state):       # a batch group's finish: ms since its row before (0 at the first)
        before = np.concatenate(([t[0] if state is None else state], t[:-1]))
        return ((t - before) / 1000.0)[:, None], t[-1]

    batch = ColumnGroup(lambda t: (t.now_us,), every=5, finish=since, raw_width=1)
    extra = [Column("user/fast", ("t ms",), "ms", fast),
             Column("user/slow", ("calls", "minus one"), "count", slow, every=5),
             batch.column("user/since", ("ms since",), "ms")]
    rrd = tmp_path / "extra.rrd"
    with Twin(seed=0) as twin, recording.Recorder(rrd, twin, columns=extra, chunk_s=0.3) as rec:
        twin.advance_to(1_000_000)
    assert rec.samples == 51                            # 0, 20 ms, ..., 1 s
    assert len(fast_calls) == 51
    assert slow_calls == list(range(0, 1_000_001, 100_000))     # 11 reads, every 100 ms
    t, v = read_rrd_scalars(rrd, "user/fast")
    assert np.allclose(v, t * 1000.0) and len(t) == 51
    t, v = read_rrd_scalars(rrd, "user/slow")
    assert np.allclose(t, np.arange(11) * 0.1)
    assert v[:, 0].tolist() == list(range(1, 12)) and set(v[:, 1]) == {-1.0}
    t, v = read_rrd_scalars(rrd, "user/since")      # derived per chunk (3 rows a chunk), every 5th row
    assert np.allclose(t, np.arange(11) * 0.1) and v.tolist() == [0.0] + [100.0] * 10


def test_a_batch_group_split_in_the_column_list_is_refused(tmp_path):
    """A batch group's columns are derived together from one raw block a row: given apart
    (another column between them) they could not be, and the recorder says so at once."""
    def twice(t, raw, state):
        return np.hstack([raw, raw]), state

    batch = ColumnGroup(lambda t: (t.now_us,), finish=twice, raw_width=1)
    a = batch.column("user/a", ("a",), "us")
    b = batch.column("user/b", ("b",), "us")
    other = Column("user/other", ("x",), "us", lambda t: (1.0,))
    with Twin(seed=0) as twin:
        with pytest.raises(ValueError, match="must be given together"):
            recording.Recorder(tmp_path / "split.rrd", twin, columns=[a, other, b])
    assert not (tmp_path / "split.rrd").exists()


def test_a_column_group_is_read_once_a_row_and_each_column_alone_reads_its_slice(tmp_path):
    calls: list[int] = []

    def read(t):
        calls.append(t.now_us)
        return (t.now_us / 1000.0, 1.0, 2.0, -t.now_us / 1000.0)

    group = ColumnGroup(read)
    a = group.column("user/a", ("t ms",), "ms")
    b = group.column("user/b", ("one", "two"), "count")
    c = group.column("user/c", ("minus t ms",), "ms")
    rrd = tmp_path / "group.rrd"
    with Twin(seed=0) as twin, recording.Recorder(rrd, twin, columns=group.columns, chunk_s=0.3) as rec:
        twin.advance_to(200_000)
        tick = rec._tick
        assert list(b.read(tick)) == [1.0, 2.0] and list(c.read(tick)) == [-200.0]
        del calls[-2:]                                  # the two reads of the line above
    assert calls == list(range(0, 200_001, 20_000))     # once a row for its three columns
    assert [col.every for col in (a, b, c)] == [1, 1, 1]
    t, v = read_rrd_scalars(rrd, "user/a")
    assert np.allclose(v, t * 1000.0) and len(t) == 11
    _, v = read_rrd_scalars(rrd, "user/b")
    assert v.tolist() == [[1.0, 2.0]] * 11
    t, v = read_rrd_scalars(rrd, "user/c")
    assert np.allclose(v, -t * 1000.0)


def test_support_polygon_strips_of_every_size(tmp_path):
    # rows with 0, 1, 2 and 4 hull points: no strip, no strip, an open segment, a closed outline
    from rerun.chunk import RrdReader

    rrd = tmp_path / "poly.rrd"
    hulls = [np.zeros((0, 2)), np.array([[0.1, 0.0]]), np.array([[0.0, 0.0], [0.1, 0.0]]),
             np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.05], [0.0, 0.05]])]
    with Twin(seed=0) as twin, recording.Recorder(rrd, twin, chunk_s=10.0) as rec:
        twin.advance_to(60_000)                         # rows at 0, 20, 40, 60 ms
        assert rec._n == 4
        rec._poly[:4] = hulls
    strips = {}
    for chunk in RrdReader(rrd).stream():
        if chunk.entity_path == "/world/support_polygon" and not chunk.is_static:
            rb = chunk.to_record_batch()
            times = rb.column(rb.schema.names.index("sim_time")).cast("int64").to_pylist()
            rows = rb.column(rb.schema.names.index("LineStrips3D:strips")).to_pylist()
            strips.update(zip(times, rows, strict=True))
    got = [strips[t * 1_000_000] for t in (0, 20, 40, 60)]
    assert got[0] == [] and got[1] == []
    assert [[p[:2] for p in s] for s in got[2]] == [[pytest.approx([0.0, 0.0]), pytest.approx([0.1, 0.0])]]
    assert len(got[3]) == 1 and len(got[3][0]) == 5 and got[3][0][0] == got[3][0][4]


def test_rrd_passes_rerun_s_own_verification(run, tmp_path):
    verify_rrd(run[0])      # every column deserialises as its component type (as the viewer does)
    import pyarrow as pa
    import rerun as rr

    bad = tmp_path / "bad.rrd"
    rec = rr.RecordingStream("bad")
    rec.save(bad)

    class F64:
        def as_arrow_array(self) -> pa.Array:
            return pa.array([1.0, 2.0])

    rec.send_columns("x", indexes=[rr.TimeColumn("sim_time", duration=[0.0, 1.0])],
                     columns=[rr.ComponentColumn(rr.Transform3D.descriptor_translation(), F64())])
    rec.disconnect()
    with pytest.raises(RrdReadError, match="Vec3D"):
        verify_rrd(bad)


def _content_digest(path: pathlib.Path) -> str:
    """SHA-256 of everything a recording holds on ``sim_time`` and statically: per entity and
    component, its rows (time, value) in time order, whatever the chunks (rerun's own reader)."""
    import hashlib
    import json

    from rerun.chunk import RrdReader

    cells: dict[str, list] = {}
    for c in RrdReader(path).stream():
        if c.entity_path.startswith("/__"):
            continue
        rb = c.to_record_batch()
        names = rb.schema.names
        t = (rb.column(names.index("sim_time")).cast("int64").to_pylist() if "sim_time" in names
             else [-1] * rb.num_rows)
        for k, name in enumerate(names):
            if ":" in name:
                cells.setdefault(f"{c.entity_path} {name} {c.is_static}", []).extend(
                    zip(t, rb.column(k).to_pylist(), strict=True))
    for rows in cells.values():
        rows.sort(key=lambda r: (r[0], json.dumps(r[1])))
    return hashlib.sha256(json.dumps(cells, sort_keys=True).encode()).hexdigest()


def test_recorded_content_is_pinned(run):
    """Every value the driven run's recording holds (joints, true angles and their speeds, feet,
    CoPs, bus rates across the chunk boundary, counters, poses, world points, static content),
    bitwise: the recorder's sampling and chunking may change, what it records may not unnoticed.
    A deliberate change of the recording updates this digest (and says so in docs/recording.md)."""
    assert _content_digest(run[0]) == RECORDED_CONTENT_SHA256


def test_the_content_does_not_depend_on_where_the_chunks_cut(tmp_path):
    """The same 1 s run recorded in chunks of 7 rows (their first sample numbers not multiples
    of the slow columns' 5: the rows those are written on found per chunk) and in one chunk
    holds the same values, bitwise."""
    digests = []
    for chunk_s in (0.14, 30.0):
        rrd = tmp_path / f"chunks{chunk_s}.rrd"
        with Twin(seed=0) as twin, recording.Recorder(rrd, twin, chunk_s=chunk_s) as rec:
            twin.advance_to(1_000_000)
        digests.append(_content_digest(rrd))
        assert rec.chunks_sent == (8 if chunk_s < 1 else 1)     # 51 rows
    assert digests[0] == digests[1]


def test_a_user_column_may_give_its_names_and_colours_as_lists(tmp_path):
    """Lists where the table has tuples (a user's column): recorded like the others."""
    col = Column("user/listed", ["a", "b"], "u", lambda t: (1.0, 2.0), colors=[[255, 0, 0], [0, 255, 0]])
    rrd = tmp_path / "listed.rrd"
    with Twin(seed=0) as twin, recording.Recorder(rrd, twin, columns=[col], chunk_s=0.3):
        twin.advance_to(100_000)
    t, v = read_rrd_scalars(rrd, "user/listed")
    assert len(t) == 6 and v.tolist() == [[1.0, 2.0]] * 6


def test_a_derived_column_read_alone_gives_its_recorded_last_row(run):
    """A column of a batch group read alone (its own ``read`` on the last sample's tick) gives
    what the recording holds for that row: the true angle and its speed, the task time, the
    bus rates, derived from the raw values taken then."""
    from humanoid_twin.recording.paths import scu_path, servo_path

    rrd, _, rec, _, _ = run
    cols = {c.path: c for c in rec.columns}
    for path in (f"{servo_path(1, 2)}/position", f"{servo_path(1, 2)}/velocity", f"{scu_path(2)}/task_ms",
                 f"{scu_path(5)}/imu/roll", "bus/can/frames_per_s", "bus/can/load_percent"):
        _, v = read_rrd_scalars(rrd, path)
        assert np.atleast_1d(v[-1]).tolist() == list(cols[path].read(rec._tick)), path


def test_bus_rates_computed_per_chunk_are_the_per_row_rates(twin):
    """The bus rates are derived a chunk at a time: whatever the chunk boundaries, and with rows
    taken twice at one instant (a repeat keeps its rates; the next ones run from the instant's
    first row), they are what a per-row reader keeps (the previous counters, rate = frames
    since / dt, load = 100 * busy us since / dt)."""
    from humanoid_twin.recording.columns import _BusRates

    t = np.array([0, 20_000, 40_000, 40_000, 60_000, 100_000, 100_000, 100_000, 120_000], dtype=np.int64)
    raw = np.array([[5, 0], [60, 700], [100, 900], [130, 950], [190, 1300], [250, 2000], [260, 2100],
                    [270, 2200], [330, 2500]], dtype=np.float64)
    want, at, base = [], None, None
    for k in range(len(t)):              # the per-row reader
        if k == 0:
            want.append((0.0, 0.0))
        elif t[k] == at:
            want.append(want[-1])
            continue
        else:
            dt = int(t[k] - at)
            want.append(((raw[k, 0] - base[0]) * (1_000_000 / dt), 100.0 * (raw[k, 1] - base[1]) / dt))
        at, base = t[k], raw[k]
    rates = _BusRates(twin)
    for cuts in ([9], [1, 8], [3, 6], [4, 5], [6, 3], [2, 2, 2, 3]):
        got, state, k = [], None, 0
        for m in cuts:
            out, state = rates.finish(t[k:k + m], raw[k:k + m], state)
            got += [tuple(r) for r in out.tolist()]
            k += m
        assert got == want, cuts


def test_rrd_rows_are_on_sim_time_and_sent_in_chunks(run):
    rrd, _, rec, _, _ = run
    t, _ = read_rrd_scalars(rrd, "robot/trunk_tilt_deg")
    np.testing.assert_allclose(t, np.arange(ROWS) * PERIOD_US / 1e6, atol=1e-9)
    # 151 rows in 2 s chunks of 100 rows: two send_columns per entity, not one log per value
    assert rec.chunks_sent == 2


def test_rrd_joint_series_are_what_the_boards_and_plant_had(run):
    rrd, _, _, _, facts = run
    for k, scu in enumerate((1, 2)):
        name = "scu/1_right_leg" if scu == 1 else "scu/2_left_leg"
        t, pos = read_rrd_scalars(rrd, f"{name}/servo3/position")
        assert pos.shape == (ROWS, 5)       # reference, trajectory, commanded, measured, true
        ref, traj, _cmd, meas, true = pos.T
        assert ref[-1] == KNEE_DEG and ref[0] == 0
        assert traj[-1] == KNEE_DEG         # the 0.2 s cubic reached its end
        assert true[-1] == pytest.approx(facts["knee_true"][k], abs=1e-5)
        assert meas[-1] == facts["knee_measured"][k]
        assert np.all(meas == np.round(meas))   # firmware positions are whole degrees
        assert abs(true[-1] - KNEE_DEG) < 3.0   # the knee really moved
        assert np.all(np.abs(true[t < 2.5]) < 3.0)


def test_rrd_forces_cop_and_balance_are_consistent(run):
    rrd, _, _, _, _ = run
    _, total = read_rrd_scalars(rrd, "robot/total_force_n")
    _, fr = read_rrd_scalars(rrd, "scu/1_right_leg/force/newton")
    _, fl = read_rrd_scalars(rrd, "scu/2_left_leg/force/newton")
    np.testing.assert_allclose(fr.sum(axis=1) + fl.sum(axis=1), total, atol=1e-4)
    assert total[50] == pytest.approx(5.0 * 9.81, rel=0.05)     # standing at t = 1 s
    _, adc = read_rrd_scalars(rrd, "scu/1_right_leg/force/adc")
    assert adc.shape == (ROWS, 4) and np.all(adc == np.round(adc)) and adc.max() <= 255
    _, fell = read_rrd_scalars(rrd, "robot/fell")
    assert not fell.any()
    # CoP of the right foot: firmware (whole mm) vs ground truth, both in the foot frame
    t_fw, fw = read_rrd_scalars(rrd, "scu/1_right_leg/cop/y/firmware")
    t_tr, tr = read_rrd_scalars(rrd, "scu/1_right_leg/cop/y/truth")
    assert len(t_fw) == len(t_tr) == ROWS
    both = ~np.isnan(fw) & ~np.isnan(tr)
    still = both & (t_fw > 1.0) & (t_fw < 2.5)                   # standing still
    assert still.sum() > 50
    assert np.all(np.abs(fw[still] - tr[still]) < 3.0)
    # the knee bend rocks the robot: both see the CoP swing (the firmware's up to a tick late)
    moving = both & (t_fw > 2.6)
    assert np.ptp(tr[moving]) > 30.0
    assert np.corrcoef(fw[moving], tr[moving])[0, 1] > 0.8
    assert math.isnan(tr[0])                                     # t = 0: pads not loaded yet


def test_rrd_foot_view_draws_the_cop_with_forward_up(run):
    rrd, _, _, _, _ = run
    from rerun.chunk import RrdReader

    _, y_truth = read_rrd_scalars(rrd, "scu/1_right_leg/cop/y/truth")
    points = []
    for c in RrdReader(rrd).stream():
        if c.entity_path == "/feet/right/cop/truth" and not c.is_static:
            points += c.to_record_batch().to_pydict()["Points2D:positions"]
    assert len(points) == ROWS
    for p, y in zip(points, y_truth, strict=True):
        if math.isnan(y):
            assert p == []                 # unloaded foot: no point
        else:
            assert p[0][1] == pytest.approx(-y, abs=1e-3)


def test_rrd_counters(run):
    rrd, _, _, _, facts = run
    _, frames = read_rrd_scalars(rrd, "bus/can/frames")
    assert np.all(np.diff(frames) >= 0) and frames[-1] == facts["frames_sent"]
    _, rate = read_rrd_scalars(rrd, "bus/can/frames_per_s")
    # seed 002 slide 27: 2 actuation packets per slave per 8 ms (2000/s) plus the answers
    assert 2000 <= np.median(rate[1:]) <= 4000
    _, serial = read_rrd_scalars(rrd, "bus/serial/bytes")
    assert serial[-1, 0] == 6 * (2 * N_SCU + 4)      # every request byte the host wrote
    _, rounds = read_rrd_scalars(rrd, "master/rounds")
    assert rounds[-1] == pytest.approx(facts["sim_s"] / 0.008, abs=2)


def test_recording_does_not_change_the_run(run, tmp_path):
    """The recorder only observes: the same inputs give the same physics without it."""
    _, _, _, _, facts = run
    with Twin(seed=0) as twin:
        _drive(twin)
        np.testing.assert_array_equal(twin.plant.data.qpos, facts["qpos"])
        assert twin.network.frames_sent == facts["frames_sent"]


def test_recorder_cost_is_small(run):
    _, _, _, _, facts = run
    # measured ~0.02-0.03 s of wall per simulated second here (docs/recording.md); the bound is
    # loose for a shared machine, but a per-value rr.log design (~270 values x 50 Hz x 70 us
    # = 0.9 s/s) cannot pass it
    assert facts["rec_cost"] < 0.25


# --- robustness ----------------------------------------------------------------------------


def test_interrupted_run_leaves_a_readable_file(tmp_path):
    path = tmp_path / "interrupted.rrd"
    with Twin(seed=1) as twin:
        with pytest.raises(RuntimeError, match="boom"):
            with recording.Recorder(path, twin, chunk_s=0.2) as rec:
                twin.run_for(0.5)
                raise RuntimeError("boom")
        assert rec.closed
        twin.run_for(0.1)                  # the clock still calls sample(): a no-op now
        rec.close()                        # idempotent
    rows = read_rrd_rows(path)
    assert rows["robot/trunk_tilt_deg"] == 26 == rec.samples     # 0..0.5 s, incl. the partial chunk
    assert rrd_has_blueprint(path)


def test_ctrl_c_inside_the_clock_leaves_a_readable_file(tmp_path):
    path = tmp_path / "ctrlc.rrd"

    def interrupt() -> None:
        raise KeyboardInterrupt

    with Twin(seed=2) as twin:
        with pytest.raises(KeyboardInterrupt):
            with recording.Recorder(path, twin) as rec:
                twin.clock.schedule(310_000, interrupt)
                twin.run_for(1.0)
    t, _ = read_rrd_scalars(path, "scu/1_right_leg/servo1/position")
    assert len(t) == rec.samples == 16 and t[-1] == pytest.approx(0.3)


def test_real_ctrl_c_and_forgotten_close_leave_readable_files(tmp_path):
    """A separate process records without ``with``/``close`` and gets a real SIGINT mid-run: the
    uncaught KeyboardInterrupt ends the interpreter, ``atexit`` closes the recorder."""
    import signal
    import subprocess
    import sys

    path = tmp_path / "sigint.rrd"
    script = (
        "import sys\n"
        "from humanoid_twin.twin import Twin\n"
        "from humanoid_twin.recording import Recorder\n"
        "twin = Twin(seed=0)\n"
        f"rec = Recorder({str(path)!r}, twin, chunk_s=0.5)\n"
        "twin.run_for(0.3)\n"
        "print('ready', flush=True)\n"
        "while True:\n"
        "    twin.run_for(0.1)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True,  # default SIGINT in the child even when pytest runs with it ignored
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert proc.stdout.readline().strip() == "ready"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert "KeyboardInterrupt" in err
    verify_rrd(path)
    t, _ = read_rrd_scalars(path, "robot/trunk_tilt_deg")
    assert len(t) >= 16 and np.all(np.diff(t) == pytest.approx(0.02))     # every row up to the stop


def test_recorder_rejects_bad_input(tmp_path, twin):
    with pytest.raises(ValueError, match=r"\.rrd"):
        recording.Recorder(tmp_path / "run.txt", twin)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        recording.Recorder(tmp_path / "missing" / "run.rrd", twin)
    with pytest.raises(ValueError, match="period_us"):
        recording.Recorder(tmp_path / "run.rrd", twin, period_us=0)
    with pytest.raises(ValueError, match="SCU 9"):
        recording.Recorder(tmp_path / "run.rrd", twin, scus=[1, 9])
    with pytest.raises(ValueError, match="chunk_s"):
        recording.Recorder(tmp_path / "run.rrd", twin, chunk_s=float("nan"))
    with pytest.raises(ValueError, match="smaller chunk_s"):
        recording.Recorder(tmp_path / "run.rrd", twin, chunk_s=3600)
    assert not (tmp_path / "run.rrd").exists()      # nothing created by a refused recorder


def test_the_default_chunk_fits_a_short_sampling_period(tmp_path, twin):
    """The default chunk is 30 simulated s, or the most rows a chunk may hold at a short period
    (a 2 ms period would need 15 000 rows for 30 s; an explicit chunk_s that long is refused)."""
    with recording.Recorder(tmp_path / "fast.rrd", twin, period_us=2_000) as rec:
        twin.run_for(0.1)
    assert rec.samples >= 50
    with pytest.raises(ValueError, match="smaller chunk_s"):
        recording.Recorder(tmp_path / "slow.rrd", twin, period_us=2_000, chunk_s=30.0)
    with pytest.raises(FileNotFoundError):
        read_rrd_entities(tmp_path / "nothing.rrd")
    junk = tmp_path / "junk.rrd"
    junk.write_bytes(b"not a recording")
    with pytest.raises(RrdReadError):
        read_rrd_entities(junk)


def test_recorder_subset_of_boards(tmp_path):
    path = tmp_path / "legs.rrd"
    with Twin(seed=0) as twin, recording.Recorder(path, twin, scus=(1, 2), period_us=40_000) as rec:
        twin.run_for(0.4)
    rows = read_rrd_rows(path)
    assert rows["scu/1_right_leg/servo1/position"] == 11 == rec.samples
    assert not any(e.startswith("scu/3_") for e in rows)


# --- CAN logs --------------------------------------------------------------------------------


def test_can_log_has_all_slaves_with_virtual_timestamps(run):
    _, asc, _, log, facts = run
    msgs = read_can_log(asc)
    assert len(msgs) == log.frames == facts["frames_sent"]
    times = np.array([m.timestamp for m in msgs])
    assert np.all(np.diff(times) > 0)                 # one wire: strictly increasing
    assert 0.0 <= times[0] < 0.01 and times[-1] <= facts["sim_s"]
    ids = {m.arbitration_id for m in msgs}
    for scu in range(1, N_SCU + 1):
        assert set(canframes.ACTUATION_IDS[scu]) <= ids
        assert set(canframes.SENSOR_IDS[scu]) <= ids


def test_can_log_decodes_with_the_dbc(run):
    _, asc, _, _, _ = run
    frames = list(decode_can_log(asc))
    late = [f for f in frames if f.name == "Actuation1_S1" and f.timestamp > 2.7]
    assert late and all(f.signals["Ref3"] == KNEE_DEG and f.signals["PWM"] == 1 for f in late)
    sensors = [f for f in frames if f.op == canframes.OP_SENSORS]
    assert {f.src for f in sensors} == set(range(1, N_SCU + 1))
    assert all(f.dst == 0 for f in sensors)


@pytest.mark.parametrize("suffix", [".asc", ".log", ".blf", ".csv", ".trc", ".db", ".asc.gz"])
def test_can_log_formats(tmp_path, suffix):
    path = tmp_path / f"bus{suffix}"
    with Twin(seed=0) as twin:
        twin.run_for(0.0105)                  # start logging mid-run, not at t = 0
        ref = can.BufferedReader()
        twin.network.add_listener(ref)
        with CanLog(path, twin.network) as log:
            twin.run_for(0.05)
        twin.run_for(0.01)                    # after close: nothing more is written
    first = []
    while (m := ref.get_message(0)) is not None and m.timestamp <= 0.0605:
        first.append(m)
    assert first[0].timestamp > 0.0105
    msgs = read_can_log(path)
    assert len(msgs) == log.frames == len(first) > 0
    # the same virtual times in every format (to the format's resolution)
    np.testing.assert_allclose([m.timestamp for m in msgs], [m.timestamp for m in first], atol=1e-5)
    assert [m.arbitration_id for m in msgs] == [m.arbitration_id for m in first]
    assert [bytes(m.data) for m in msgs] == [bytes(m.data) for m in first]


def test_can_log_rejects_bad_paths(tmp_path, twin):
    with pytest.raises(CanLogError, match="unknown format '.foo'"):
        CanLog(tmp_path / "bus.foo", twin.network)
    with pytest.raises(CanLogError, match="no suffix"):
        CanLog(tmp_path / "bus", twin.network)
    with pytest.raises(OSError, match="cannot write the CAN log"):
        CanLog(tmp_path / "missing" / "bus.asc", twin.network)
    (tmp_path / "ro").mkdir()
    (tmp_path / "ro" / "bus.asc").mkdir()      # a directory where the file should go
    with pytest.raises(IsADirectoryError):
        CanLog(tmp_path / "ro" / "bus.asc", twin.network)
    assert check_log_path(tmp_path / "bus.blf.gz") == ".blf"
    assert not (tmp_path / "bus.blf.gz").exists()     # checking creates nothing
    with pytest.raises(CanLogError, match="unknown format"):
        check_log_path("bus.mp3")
    with pytest.raises(CanLogError, match="cannot read"):
        read_can_log(tmp_path / "bus.txt")


def test_columns_have_rerun_s_own_arrow_types(run, tmp_path):
    """The recorder sends ready arrow arrays; they must be exactly what rerun's archetype helpers
    make (or the viewer would not draw them)."""
    import rerun as rr
    from rerun.chunk import RrdReader

    def types(path: pathlib.Path, entities: dict[str, str]) -> dict[str, str]:
        out = {}
        for c in RrdReader(path).stream():
            name = c.entity_path.lstrip("/")
            if name in entities and not c.is_static:
                rb = c.to_record_batch()
                out[entities[name]] = {f.name: str(f.type) for f in rb.schema if ":" in f.name}
        return out

    rrd = run[0]
    ours = types(rrd, {"scu/1_right_leg/servo1/position": "scalars", "world/bodies/trunk": "transform",
                       "feet/right/cop/truth": "points2d", "feet/right/loads": "radii",
                       "world/com": "points3d", "world/support_polygon": "strips"})
    ref_path = tmp_path / "ref.rrd"
    rec = rr.RecordingStream("ref")
    rec.save(ref_path)
    t = [rr.TimeColumn("sim_time", duration=[0.0, 0.02])]
    rec.send_columns("a", indexes=t, columns=rr.Scalars.columns(scalars=[[1.0, 2.0], [3.0, 4.0]]))
    rec.send_columns("b", indexes=t, columns=rr.Transform3D.columns(
        translation=[[0, 0, 0], [1, 1, 1]], quaternion=[[0, 0, 0, 1], [0, 0, 0, 1]]))
    rec.send_columns("c", indexes=t, columns=rr.Points2D.columns(positions=[[1, 2], [3, 4]]))
    rec.send_columns("d", indexes=t, columns=rr.Points2D.columns(radii=[1.0, 2.0]))
    rec.send_columns("e", indexes=t, columns=rr.Points3D.columns(positions=[[1, 2, 3], [3, 4, 5]]))
    rec.send_columns("f", indexes=t, columns=rr.LineStrips3D.columns(
        strips=[[[0, 0, 0], [1, 0, 0]], [[0, 0, 0], [0, 1, 0]]]))
    rec.disconnect()
    ref = types(ref_path, {"a": "scalars", "b": "transform", "c": "points2d", "d": "radii",
                           "e": "points3d", "f": "strips"})
    assert ours == ref


def test_can_log_txt_is_refused_before_anything_is_written(tmp_path, twin):
    """Issue 25: ``.txt`` (python-can's Printer) could be written but not read back: refused."""
    with pytest.raises(CanLogError, match="cannot read it back"):
        CanLog(tmp_path / "bus.txt", twin.network)
    assert not (tmp_path / "bus.txt").exists()


def test_trc_header_names_the_file_not_a_temporary_absolute_path(tmp_path):
    path = tmp_path / ".partial-1-bus.trc"
    with Twin(seed=0) as twin, CanLog(path, twin.network, name="bus.trc"):
        twin.run_for(0.02)
    text = path.read_text()
    assert "bus.trc" in text and str(tmp_path) not in text and ".partial" not in text


def test_a_converted_log_keeps_the_virtual_times(tmp_path):
    """python-can's logconvert shifts ASC/BLF times by the first frame's; convert_can_log does not."""
    from humanoid_twin.recording.can_log import convert_can_log

    with Twin(seed=0) as twin:
        twin.run_for(0.05)
        with CanLog(tmp_path / "bus.db", twin.network):    # the log starts 50 ms into the run
            twin.run_for(0.05)
    src = read_can_log(tmp_path / "bus.db")
    assert src[0].timestamp > 0.04
    for suffix in (".asc", ".blf"):
        assert convert_can_log(tmp_path / "bus.db", tmp_path / f"bus{suffix}") == len(src)
        back = read_can_log(tmp_path / f"bus{suffix}")
        assert [m.timestamp for m in back] == pytest.approx([m.timestamp for m in src], abs=1e-6)


def test_the_dbc_gives_every_frame_its_8_ms_cycle():
    from humanoid_twin.protocol.canframes import load_dbc

    assert {m.cycle_time for m in load_dbc().messages} == {8}
