"""The host's pure parts (humanoid_twin.host): planners (seed 000 tables 22-23), the robot tables
and adaptate/correct/limit (table 26), calccop and cop_graphs (table 27), predict_trajectory
(table 21), argument checks. No twin here: tests/host/test_host_drivers.py runs the host on it."""

from __future__ import annotations

import json
import math

import mujoco
import numpy as np
import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_twin import hardware
from humanoid_twin.host import (
    GAINS,
    CopData,
    adaptate,
    calccop,
    cop_graphs,
    correct,
    exe_traj,
    flexao,
    inclinar,
    levantar_perna,
    limit,
    load_tables,
    predict_trajectory,
    sensor_loads,
    servo_command,
    timebase,
)
from humanoid_twin.host import drivers as drv
from humanoid_twin.host.planners import ANKLE_PITCH, ANKLE_ROLL, HIP_PITCH, HIP_ROLL, HIP_YAW, KNEE
from humanoid_twin.host.tables import TABLES_PATH, TablesError
from humanoid_twin.plant import DEFAULT_MODEL
from humanoid_twin.protocol.wire import ControlType

R_LEG, L_LEG, R_HIP, L_HIP = 0, 1, 2, 3
LOCO, BAL = int(ControlType.LOCOMOTION_CONTROL), int(ControlType.BALANCE_CONTROL)
REACT, OPEN = int(ControlType.REACTION_CONTROL), int(ControlType.NO_CONTROL)


def leg(pos: np.ndarray, side: int, m: int) -> dict[str, float]:
    """The leg's joint angles of motion m (side 0 right, 1 left)."""
    lg, hp = (R_LEG, R_HIP) if side == 0 else (L_LEG, L_HIP)
    return {
        "ankle_roll": pos[lg, ANKLE_ROLL, m],
        "ankle_pitch": pos[lg, ANKLE_PITCH, m],
        "knee": pos[lg, KNEE, m],
        "hip_roll": pos[hp, HIP_ROLL, m],
        "hip_pitch": pos[hp, HIP_PITCH, m],
        "hip_yaw": pos[hp, HIP_YAW, m],
    }


def ankle_to_hip_xz(j: dict[str, float]) -> tuple[float, float]:
    """Sagittal position of the hip over a flat foot's ankle (mm), table 13 links, model signs:
    pitch about +y, a link's up-vector at world pitch phi is (sin phi, cos phi)."""
    L = hardware.LINK_LENGTH_MM
    phi_thigh = j["hip_pitch"]                       # trunk upright: world pitch of the thigh
    phi_shank = j["hip_pitch"] + j["knee"]
    x = L * math.sin(math.radians(-phi_shank)) + L * math.sin(math.radians(-phi_thigh))
    z = L * math.cos(math.radians(phi_shank)) + L * math.cos(math.radians(phi_thigh))
    return x, z


# --- shapes (table 23) --------------------------------------------------------------------------

@pytest.mark.parametrize(
    "plan, n_motions",
    [(flexao(1.0, 20), 1), (inclinar(1.5, -10), 1), (levantar_perna(1.0, 40, 1), 6),
     (levantar_perna(1.0, 40, 2), 6), (levantar_perna(1.0, 40, 0), 3), (levantar_perna(1.0, 40, 7), 3)],
)
def test_planner_shapes_are_those_of_table_23(plan, n_motions):
    pos, k, t = plan
    assert pos.shape == (8, 3, n_motions)
    assert k.shape == (8, 3, n_motions, 4)
    assert t.shape == (n_motions,)
    assert np.all(np.isfinite(pos)) and np.all(t > 0)
    # only the legs, hips and (levantar_perna) the torso roll move; the arms and head stay at 0
    assert np.all(pos[5:] == 0) and np.all(pos[4, 1:] == 0)
    assert set(np.unique(k[..., 3])) <= {0, 1, 2, 3}
    assert np.all((k[..., :3] >= 0) & (k[..., :3] <= 255))


# --- flexao -------------------------------------------------------------------------------------

@pytest.mark.parametrize("motion", [0.0, 5.0, 20.0, 33.3, 45.0])
def test_flexao_knee_is_twice_the_ankle_and_the_feet_stay_flat(motion):
    pos, k, t = flexao(2.0, motion)
    assert t[0] == 2.0
    for side in (0, 1):
        j = leg(pos, side, 0)
        assert j["ankle_pitch"] == -motion
        assert j["knee"] == 2 * motion
        assert j["hip_pitch"] == -motion
        assert j["ankle_roll"] == j["hip_roll"] == j["hip_yaw"] == 0
        # trunk upright -> foot flat: the pitch angles along the chain sum to zero
        assert j["hip_pitch"] + j["knee"] + j["ankle_pitch"] == pytest.approx(0.0)
        # equal links: the hip stays straight above the ankle, lowered by 2 L (1 - cos motion)
        x, z = ankle_to_hip_xz(j)
        assert x == pytest.approx(0.0, abs=1e-9)
        assert z == pytest.approx(2 * 95.0 * math.cos(math.radians(motion)))
    assert np.all(k[:4, :, 0, 3] == LOCO)
    assert np.all(k[:4, :, 0, :3] == np.asarray(GAINS[ControlType.LOCOMOTION_CONTROL]))


def test_flexao_rejects_what_the_knee_cannot_do():
    with pytest.raises(ValueError, match="motion"):
        flexao(1.0, 46)
    with pytest.raises(ValueError, match="motion"):
        flexao(1.0, -5)
    with pytest.raises(ValueError, match="T"):
        flexao(0.0, 10)
    with pytest.raises(ValueError, match="255 ticks"):
        flexao(6.0, 10)
    with pytest.raises(ValueError, match="motion"):
        flexao(1.0, float("nan"))


# --- inclinar -----------------------------------------------------------------------------------

@pytest.mark.parametrize("motion", [-30.0, -7.5, 0.0, 12.0, 30.0])
def test_inclinar_moves_foot_lateral_by_motion_and_hip_roll_opposite(motion):
    pos, k, _ = inclinar(1.0, motion)
    for side in (0, 1):
        j = leg(pos, side, 0)
        assert j["ankle_roll"] == motion
        assert j["hip_roll"] == -motion
        assert j["ankle_roll"] + j["hip_roll"] == 0     # trunk upright, feet flat
        assert j["ankle_pitch"] == j["knee"] == j["hip_pitch"] == j["hip_yaw"] == 0
    # both legs identical: they stay parallel
    assert np.array_equal(pos[R_LEG], pos[L_LEG]) and np.array_equal(pos[R_HIP], pos[L_HIP])
    assert np.all(k[:4, :, 0, 3] == LOCO)
    with pytest.raises(ValueError, match="motion"):
        inclinar(1.0, 31)


# --- levantar_perna -----------------------------------------------------------------------------

@pytest.mark.parametrize("perna, lifted, support", [(1, 0, L_LEG), (2, 1, R_LEG)])
def test_levantar_perna_shifts_then_lifts_one_leg_with_balance_on_the_support_leg(perna, lifted, support):
    motion, shift = 50.0, 12.0
    pos, k, t = levantar_perna(1.5, motion, perna, shift=shift)
    # the shift takes 2 T, the return 3 T, the other motions T (docs/balance.md 4)
    assert t.tolist() == [3.0, 1.5, 1.5, 1.5, 4.5, 1.5]
    lean = shift if perna == 1 else -shift      # + = toward the left leg
    other = 1 - lifted
    for m in range(4):
        for side in (0, 1):
            j = leg(pos, side, m)
            assert j["ankle_roll"] == lean and j["hip_roll"] == -lean
    # shift: no flexion yet
    for side in (0, 1):
        assert leg(pos, side, 0)["knee"] == 0
    # lift and hold: the lifted knee at motion, foot parallel to the floor, the support leg straight
    for m in (1, 2):
        j = leg(pos, lifted, m)
        assert j["knee"] == motion
        assert j["hip_pitch"] + j["knee"] + j["ankle_pitch"] == 0
        assert leg(pos, other, m)["knee"] == 0
    # lower = the shift pose; return and rest = vertical
    assert np.array_equal(pos[:, :, 3], pos[:, :, 0])
    assert np.all(pos[:, :, 4:] == 0)
    # the upper torso leans toward the support leg (torso roll about +x: negative = top to the left)
    assert np.all(pos[4, 0, :4] == (-20.0 if perna == 1 else 20.0)) and np.all(pos[4, 1:, :] == 0)
    assert np.all(pos[4, 0, 4:] == 0)
    # control: balance on the support leg's board during the hold and the lower (single support);
    # the lifted leg's foot lateral joint compliant (REACTION, negative KP) in the lower and the
    # return; open loop on the legs and hips in the rest; locomotion otherwise
    lifted_row = R_LEG if lifted == 0 else L_LEG
    for m in range(6):
        for row in (R_LEG, L_LEG, R_HIP, L_HIP, 4):
            for servo in range(3):
                want = LOCO
                if row == support and m in (2, 3):
                    want = BAL
                elif m == 5 and row != 4:
                    want = OPEN
                elif row == lifted_row and servo == ANKLE_ROLL and m in (3, 4):
                    want = REACT
                assert k[row, servo, m, 3] == want, (row, servo, m)
    assert np.all(k[support, :, 2, :3] == np.asarray(GAINS[ControlType.BALANCE_CONTROL]))
    assert k[lifted_row, ANKLE_ROLL, 3, :3].tolist() == [0, 256 - 8, 2]     # KP -8 as a signed byte, KD 2


@pytest.mark.parametrize("perna", [0, 3, -1, 1.5, None, "both"])
def test_levantar_perna_with_any_other_value_moves_both_legs(perna):
    pos, k, t = levantar_perna(1.0, 40, perna)
    assert pos.shape[2] == 3
    for side in (0, 1):
        assert leg(pos, side, 0)["knee"] == 40
        assert leg(pos, side, 0)["ankle_roll"] == 0
    assert np.all(pos[:, :, 2] == 0)
    assert np.all(k[:4, :, :, 3] == LOCO)


def test_levantar_perna_rejects_a_knee_beyond_its_range():
    with pytest.raises(ValueError, match="motion"):
        levantar_perna(1.0, 95, 1)
    with pytest.raises(ValueError, match="shift"):
        levantar_perna(1.0, 40, 1, shift=40)


# --- robot tables, adaptate, correct, limit -----------------------------------------------------

def raw_tables() -> dict[str, np.ndarray]:
    doc = json.loads(TABLES_PATH.read_text())
    return {name: np.array(doc[name]["values"], dtype=float)
            for name in ("signal", "offset", "calib", "lim_min", "lim_max")}


def test_table_signs_agree_with_the_plants_servo_mounting():
    from humanoid_twin.plant import SERVO_SIGN_BY_SCU

    signal = raw_tables()["signal"]
    for scu in range(1, 9):
        assert tuple(signal[scu - 1]) == SERVO_SIGN_BY_SCU[scu], f"SCU {scu}"


def test_table_limits_lie_inside_the_models_joint_ranges():
    model = mujoco.MjModel.from_xml_path(str(DEFAULT_MODEL))
    t = raw_tables()
    for scu, joints in hardware.SERVO_JOINTS.items():
        for i, name in enumerate(joints):
            lo, hi = np.degrees(model.joint(name).range)
            # servo limits -> joint limits (joint = signal * servo)
            a, b = sorted((t["lim_min"][scu - 1, i] * t["signal"][scu - 1, i],
                           t["lim_max"][scu - 1, i] * t["signal"][scu - 1, i]))
            assert lo - 1e-6 <= a and b <= hi + 1e-6, (name, (a, b), (lo, hi))


@pytest.mark.parametrize("plan", [flexao(1, 45), inclinar(1, 30), inclinar(1, -30), levantar_perna(1, 90, 1),
                                  levantar_perna(1, 90, 2), levantar_perna(1, 90, 0)])
def test_the_planners_extreme_poses_are_not_clipped_by_limit(plan):
    pos, _, _ = plan
    for m in range(pos.shape[2]):
        for scu in (1, 2, 3, 4):
            servo = correct(scu, adaptate(scu, pos[scu - 1, :, m]))
            assert np.array_equal(limit(scu, servo), servo), (scu, m)


@settings(max_examples=60, deadline=None)
@given(scu=st.integers(1, 8), p=st.lists(st.floats(-120, 120), min_size=3, max_size=3))
def test_adaptate_correct_limit_follow_the_json_tables(scu, p):
    t = raw_tables()
    r = scu - 1
    a = adaptate(scu, p)
    assert np.allclose(a, np.array(p) * t["signal"][r] + t["offset"][r])
    c = correct(scu, a)
    assert np.allclose(c, a + t["calib"][r])
    lim = limit(scu, c)
    assert np.all(lim >= t["lim_min"][r]) and np.all(lim <= t["lim_max"][r])
    inside = (c >= t["lim_min"][r]) & (c <= t["lim_max"][r])
    assert np.array_equal(lim[inside], c[inside])


def test_an_edited_tables_file_changes_adaptate_correct_limit(tmp_path):
    doc = json.loads(TABLES_PATH.read_text())
    doc["offset"]["values"][0] = [5, -3, 2]
    doc["calib"]["values"][0] = [1, 1, -1]
    doc["lim_max"]["values"][0] = [10, 45, 60]
    path = tmp_path / "tables.json"
    path.write_text(json.dumps(doc))
    tab = load_tables(path)
    assert adaptate(1, [10, 20, 30], tab).tolist() == [15, 17, 32]
    assert correct(1, [15, 17, 32], tab).tolist() == [16, 18, 31]
    assert limit(1, [16, 18, 70], tab).tolist() == [10, 18, 60]
    # the whole chain as exe_traj sends it
    assert servo_command(1, [10, 20, 30], tab) == [10, 18, 31]
    # mirrored servo: left ankle roll +10 (leg) -> servo -10
    assert servo_command(2, [10, 0, 0]) == [-10, 0, 0]


def test_broken_tables_files_are_refused_with_the_reason(tmp_path):
    doc = json.loads(TABLES_PATH.read_text())
    bad = json.loads(json.dumps(doc))
    bad["signal"]["values"][3][1] = 0
    p = tmp_path / "a.json"
    p.write_text(json.dumps(bad))
    with pytest.raises(TablesError, match="signal"):
        load_tables(p)
    bad = json.loads(json.dumps(doc))
    bad["lim_min"]["values"][0][0] = 50
    p.write_text(json.dumps(bad))
    with pytest.raises(TablesError, match="lim_min > lim_max for SCU 1 servo 1"):
        load_tables(p)
    bad = json.loads(json.dumps(doc))
    del bad["calib"]
    p.write_text(json.dumps(bad))
    with pytest.raises(TablesError, match="calib"):
        load_tables(p)
    bad = json.loads(json.dumps(doc))
    bad["offset"]["values"] = bad["offset"]["values"][:7]
    p.write_text(json.dumps(bad))
    with pytest.raises(TablesError, match="8 x 3"):
        load_tables(p)
    p.write_text("{ not json")
    with pytest.raises(TablesError, match="JSON"):
        load_tables(p)


def test_adaptate_refuses_a_wrong_scu_or_vector():
    with pytest.raises(ValueError, match="scuid"):
        adaptate(0, [0, 0, 0])
    with pytest.raises(ValueError, match="scuid"):
        limit(9, [0, 0, 0])
    with pytest.raises(ValueError, match="3 servos"):
        correct(1, [0, 0])
    with pytest.raises(ValueError, match="NaN"):
        adaptate(1, [0, float("nan"), 0])


# --- calccop ------------------------------------------------------------------------------------

XY = np.asarray(hardware.FORCE_SENSOR_XY_MM)


def readings(load7: np.ndarray, calib_load: float) -> np.ndarray:
    """What readspecial shows for sensor loads ``load7`` (7-bit counts) after a calibration at
    ``calib_load`` counts each: 7-bit value + (128 - calib_load)."""
    return np.asarray(load7, dtype=float) + 128 - calib_load


def test_calccop_at_the_calibration_load_is_the_sensors_centroid():
    assert np.allclose(calccop([128, 128, 128, 128]), XY.mean(axis=0))


@pytest.mark.parametrize("i", range(4))
def test_calccop_with_one_loaded_sensor_is_that_sensor(i):
    load = np.zeros(4)
    load[i] = 30
    assert np.allclose(calccop(readings(load, 15.3), 15.3), XY[i])


def test_calccop_weights_the_sensors_by_their_loads():
    load = np.array([10.0, 30.0, 0.0, 20.0])
    want = (load[:, None] * XY).sum(axis=0) / load.sum()
    assert np.allclose(calccop(readings(load, 12.0), 12.0), want)
    # per-sensor calibration loads
    cal = np.array([10.0, 14.0, 16.0, 20.0])
    assert np.allclose(calccop(load + 128 - cal, cal), want)


def test_calccop_of_an_unloaded_foot_is_nan_and_works_on_columns():
    unloaded = readings(np.zeros(4), 15.3)
    assert np.all(np.isnan(calccop(unloaded)))
    cols = np.stack([unloaded, [128] * 4, readings([0, 0, 0, 40], 15.3)], axis=1)
    cop = calccop(cols)
    assert cop.shape == (2, 3)
    assert np.all(np.isnan(cop[:, 0]))
    assert np.allclose(cop[:, 1], XY.mean(axis=0))
    assert np.allclose(cop[:, 2], XY[3])
    assert np.allclose(sensor_loads([128] * 4), 15.3)


def test_calccop_agrees_with_the_slaves_calcCoP():
    from humanoid_twin.slave.data import calcCoP

    rng = np.random.default_rng(3)
    for _ in range(50):
        force7 = rng.integers(0, 40, size=4)
        if force7.sum() < 8:
            continue
        x, y, loaded = calcCoP([int(v) for v in force7])
        host = calccop(readings(force7, 15), 15)
        assert loaded
        assert abs(host[0] - x) <= 0.5 + 1e-9 and abs(host[1] - y) <= 0.5 + 1e-9


def test_calccop_refuses_other_than_four_readings():
    with pytest.raises(ValueError, match="4 force readings"):
        calccop([128, 128, 128])
    with pytest.raises(ValueError, match="calib_load"):
        calccop([128] * 4, -1)


# --- cop_graphs ---------------------------------------------------------------------------------

def synthetic_cop(n: int = 150) -> CopData:
    t = np.arange(n) * 0.02
    s, c = np.sin(t), np.cos(2 * t)
    load = np.stack([20 + 10 * s, 20 - 10 * s, 15 + 5 * c, 15 - 5 * c])
    react = load + 128 - 15.3
    react[:, :5] = 110                      # the foot in the air for the first samples
    servo = np.stack([5 * np.sin(t), -10 + 0 * t, 20 * np.cos(t)])
    cur = np.stack([10 + 0 * t, 20 + 5 * np.sin(t), 30 + 0 * t])
    return CopData(react, calccop(react), servo, cur, t, 1)


def test_cop_graphs_writes_a_png_with_the_four_panels(tmp_path):
    data = synthetic_cop()
    out = cop_graphs(data, tmp_path / "cop.png")
    raw = out.read_bytes()
    assert raw[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.image as mpimg

    img = mpimg.imread(out)
    assert img.shape[0] >= 600 and img.shape[1] >= 1000
    # not a blank canvas: many distinct colours (foot, sensors, the time-coloured CoP, curves)
    assert len(np.unique(img.reshape(-1, img.shape[2])[:, :3].round(2), axis=0)) > 50


def test_cop_data_round_trips_through_its_file_and_graphs_from_it(tmp_path):
    data = synthetic_cop(40)
    path = data.save(tmp_path / "run.npz")
    back = CopData.load(path)
    for a, b in zip(data, back, strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
    assert cop_graphs(path, tmp_path / "from_file.png").stat().st_size > 20_000


# --- predict_trajectory -------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(p0=st.floats(-90, 90), pf=st.floats(-90, 90), n=st.integers(2, 300))
def test_predict_trajectory_starts_and_ends_at_rest_on_the_endpoints(p0, pf, n):
    pos, vel, acc = predict_trajectory(p0, pf, n, 1.0)
    assert pos.shape == vel.shape == acc.shape == (n,)
    assert pos[0] == pytest.approx(p0) and pos[-1] == pytest.approx(pf)
    assert vel[0] == pytest.approx(0.0, abs=1e-12) and vel[-1] == pytest.approx(0.0, abs=1e-12)
    lo, hi = min(p0, pf), max(p0, pf)
    assert np.all(pos >= lo - 1e-9) and np.all(pos <= hi + 1e-9)


def test_predict_trajectory_ratio_and_units():
    pos, vel, acc = predict_trajectory([0, 10, 0], [30, 10, -60], 101, 0.5, dt=0.02)
    assert pos.shape == (101, 3)
    # motion over the first half (1 s), then posF held
    assert np.allclose(pos[50:], [30, 10, -60]) and np.allclose(vel[50:], 0)
    # peak velocity of the cubic = 1.5 * distance / T, at mid-motion
    assert vel[25, 0] == pytest.approx(1.5 * 30 / 1.0)
    assert vel[25, 2] == pytest.approx(1.5 * -60 / 1.0)
    assert acc[0, 0] == pytest.approx(6 * 30 / 1.0**2)
    # velocity is the derivative of position
    assert np.allclose(np.gradient(pos[:51, 0], 0.02)[5:45], vel[5:45, 0], atol=0.1)
    with pytest.raises(ValueError, match="ratio"):
        predict_trajectory(0, 1, 10, 0)
    with pytest.raises(ValueError, match="n_samples"):
        predict_trajectory(0, 1, 1, 1)
    with pytest.raises(ValueError, match="same|equal"):
        predict_trajectory([0, 1], [0, 1, 2], 10, 1)


# --- driver and executor argument checks (no answer needed) --------------------------------------

def test_drivers_refuse_what_the_frame_cannot_carry_before_sending():
    port = serial.serial_for_url("loop://", timeout=0.01)
    with pytest.raises(ValueError, match="whole number"):
        drv.applyjoint(port, 1, 0, [10.5, 0, 0])
    with pytest.raises(ValueError, match="int8"):
        drv.applyjoint(port, 1, 0, [200, 0, 0])
    with pytest.raises(ValueError, match="3 values"):
        drv.applyjoint(port, 1, 0, [1, 2])
    with pytest.raises(ValueError, match="byte"):
        drv.applyjoint(port, 1, 1, [256, 0, 0])
    with pytest.raises(ValueError, match="scu_id"):
        drv.readjoint(port, 16, 0)
    with pytest.raises(ValueError, match="readspecial"):
        drv.readjoint(port, 1, 3)
    with pytest.raises(ValueError, match="max_tries"):
        drv.calibcom(port, max_tries=0)
    assert port.in_waiting == 0           # nothing was written
    # a whole-valued float is a whole number
    r = drv.applyjoint(port, 1, 0, [10.0, np.int8(-3), np.float64(0)], max_tries=1)
    assert r.rx[:5] == bytes([0xFF, 0x04, 10, 0xFD, 0])


def test_retries_are_counted_and_reported_on_a_line_that_echoes():
    """pyserial's loop:// returns the request itself: first byte FF, never an answer."""
    port = serial.serial_for_url("loop://", timeout=0.01)
    r = drv.readjoint(port, 2, 0, max_tries=4)
    assert r.error == drv.ErrorCode.UNEXPECTED_RESPONSE and r.tries == 4 and r.servos is None
    assert "after 4 tries" in r.errorstr and r.rx[0] == 0xFF
    with pytest.raises(drv.BadFrame, match="wrong first byte"):
        drv.raise_for_error(r)
    port.close()
    r = drv.calibcom(port, max_tries=2)
    assert r.error == drv.ErrorCode.PORT_ERROR and r.tries == 2 and not r.ok


def test_every_error_code_has_a_text_and_an_exception():
    for code in drv.ErrorCode:
        assert drv.ERROR_TEXT[code]
    assert drv.ERROR_TEXT[drv.ErrorCode.OK] == "ok"


def test_gate_numbers_map_to_platform_ports():
    assert drv.gate_to_port(1, "linux") == "/dev/ttyS0"
    assert drv.gate_to_port(3, "win32") == "COM3"
    with pytest.raises(ValueError):
        drv.gate_to_port(0)
    with pytest.raises(drv.PortError, match="cannot open"):
        drv.initcom("/dev/does-not-exist-humanoid")


def test_the_wall_clock_time_base_for_ordinary_ports():
    port = serial.serial_for_url("loop://")
    t0 = timebase.now(port)
    timebase.sleep(port, 0.01)
    assert 0.009 <= timebase.now(port) - t0 < 1.0
    with pytest.raises(ValueError):
        timebase.sleep(port, -1)


def test_exe_traj_checks_its_arguments_before_talking_to_the_robot():
    pos, k, t = levantar_perna(1.0, 40, 1)
    with pytest.raises(ValueError, match="N_MOTIONS"):
        exe_traj(None, t[:3], pos, 0.5, k)
    with pytest.raises(ValueError, match="k must be"):
        exe_traj(None, t, pos, 0.5, k[:, :, :2])
    with pytest.raises(ValueError, match="255"):
        exe_traj(None, t * 10, pos, 0.5, k)
    with pytest.raises(ValueError, match="Textra"):
        exe_traj(None, t, pos, -1, k)
    with pytest.raises(ValueError, match="SCU"):
        exe_traj(None, t, pos, 0.5, k, scus=[1, 9])
