"""The plant (issue 2): the MuJoCo model and what the boards see of it. Real MuJoCo, no mocks."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from humanoid_twin import hardware as H  # noqa: N812
from humanoid_twin.plant import (
    DEFAULT_MODEL,
    SERVO_SIGN,
    SERVO_SIGN_BY_SCU,
    Plant,
    PlantError,
    PlantInputError,
)
from humanoid_twin.plant import constants as C  # noqa: N812
from humanoid_twin.plant.geometry import convex_hull, signed_distance

WEIGHT_N = H.ROBOT_MASS_KG * 9.81
TABLE12 = np.array(H.FORCE_SENSOR_XY_MM)
TICK = H.PWM_PERIOD_US


# --- helpers ---------------------------------------------------------------------------------------
class Driver:
    """Drives every servo through set_pwm with joint-frame angles, one PWM period at a time."""

    def __init__(self, plant: Plant) -> None:
        self.p = plant
        self.cur: dict[str, float] = {}
        self.apply()

    def apply(self) -> None:
        for scu, joints in H.SERVO_JOINTS.items():
            deg = [round(SERVO_SIGN[j] * self.cur.get(j, 0.0)) for j in joints]
            self.p.set_pwm(scu, [H.pulse_from_deg(d) for d in deg])

    def ramp(self, target: dict[str, float], seconds: float) -> None:
        """Move linearly to ``target`` (joint degrees; joints not named go to 0)."""
        start = dict(self.cur)
        n = round(seconds * 1e6 / TICK)
        names = set(start) | set(target)
        for k in range(1, n + 1):
            for j in names:
                a, b = start.get(j, 0.0), target.get(j, 0.0)
                self.cur[j] = a + (b - a) * k / n
            self.apply()
            self.wait(TICK)

    def wait(self, us: int) -> None:
        self.p.advance_to(self.p.t_us + us)


def sensor_cop_mm(adc: list[int]) -> np.ndarray:
    """CoP in the foot frame from the four dequantised ADC values and the table 12 geometry."""
    f = np.array(adc, dtype=float) * H.FORCE_N_PER_COUNT
    return f @ TABLE12 / f.sum()


def sensor_newtons(plant: Plant, scu: int) -> float:
    return sum(plant.read_force_adc(scu)) * H.FORCE_N_PER_COUNT


@pytest.fixture()
def standing() -> tuple[Plant, Driver]:
    plant = Plant(seed=1)
    drv = Driver(plant)
    drv.wait(300_000)
    return plant, drv


# --- the model -------------------------------------------------------------------------------------
def test_model_compiles_without_warnings_and_runs_clean() -> None:
    caught: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(caught.append)
    try:
        model = mujoco.MjModel.from_xml_path(str(DEFAULT_MODEL))
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
        mujoco.mj_step(model, data, nstep=1000)
    finally:
        mujoco.set_mju_user_warning(previous)
    assert caught == []
    assert [w.number for w in data.warning] == [0] * len(data.warning)
    assert Plant().load_warnings == []


def test_every_servo_is_a_joint_with_its_actuator() -> None:
    # as compiled (a Plant zeroes the kp of its PWM-off servos)
    m = mujoco.MjModel.from_xml_path(str(DEFAULT_MODEL))
    for joints in H.SERVO_JOINTS.values():
        for j in joints:
            a = m.actuator(f"{j}_act")
            assert a.trnid[0] == m.joint(j).id
            assert a.forcerange[1] == pytest.approx(C.SERVO_STALL_TORQUE_NM, rel=1e-3)
            assert a.gainprm[0] == pytest.approx(C.SERVO_KP_NM_PER_RAD, rel=1e-3)
            assert m.joint(j).damping[0] == pytest.approx(C.SERVO_DAMPING_NMS, rel=1e-3)
            assert m.joint(j).frictionloss[0] == pytest.approx(C.SERVO_FRICTION_NM)
            assert np.degrees(m.joint(j).range) == pytest.approx([-90, 90], abs=1e-3)
    assert m.nu == 24 and m.njnt == 25        # 24 servo joints + the free root


def test_masses_and_leg_links_match_table_13() -> None:
    p = Plant()
    m, d = p.model, p.data
    assert m.body("trunk").subtreemass[0] == pytest.approx(H.ROBOT_MASS_KG, abs=1e-9)
    for side in "rl":
        upper, lower = m.body(f"{side}_hip_pitch_link"), m.body(f"{side}_knee_link")
        assert upper.mass[0] == pytest.approx(H.LINK_MASS_KG)
        assert lower.mass[0] == pytest.approx(H.LINK_MASS_KG)
        hip = d.xanchor[m.joint(f"{side}_hip_pitch").id]
        knee = d.xanchor[m.joint(f"{side}_knee").id]
        ankle = d.xanchor[m.joint(f"{side}_ankle_pitch").id]
        assert np.linalg.norm(knee - hip) * 1000 == pytest.approx(H.LINK_LENGTH_MM, abs=1e-6)
        assert np.linalg.norm(ankle - knee) * 1000 == pytest.approx(H.LINK_LENGTH_MM, abs=1e-6)
        # centre of mass 47 mm from the proximal joint, on the link's axis
        assert np.linalg.norm(d.xipos[upper.id] - hip) * 1000 == pytest.approx(H.LINK_COM_MM, abs=1e-6)
        assert np.linalg.norm(d.xipos[lower.id] - knee) * 1000 == pytest.approx(H.LINK_COM_MM, abs=1e-6)
        assert d.xipos[upper.id][2] < hip[2] and d.xipos[lower.id][2] < knee[2]
    # about 60 cm tall: the top of the highest visual box (boxes are axis-aligned at the stand pose)
    top = max(d.geom_xpos[g][2] + m.geom_size[g][2]
              for g in range(m.ngeom) if m.geom_group[g] == 2 and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX)
    assert top * 1000 == pytest.approx(H.ROBOT_HEIGHT_MM, abs=5)


def test_force_sensor_pads_sit_at_table_12() -> None:
    p = Plant()
    m, d = p.model, p.data
    for side in ("r", "l"):
        for k, suffix in enumerate(("fl", "fr", "rl", "rr")):
            pad = d.geom_xpos[m.geom(f"{side}_foot_pad_{suffix}").id]
            assert p.world_to_foot_frame(side, pad) == pytest.approx(TABLE12[k], abs=1e-6)
            site = d.site_xpos[m.site(f"{side}_foot_{suffix}").id]
            assert site == pytest.approx(pad, abs=1e-9)
            # pad bottom on the platform at the stand pose: not penetrating, not floating
            assert pad[2] - m.geom(f"{side}_foot_pad_{suffix}").size[0] == pytest.approx(0.0, abs=1e-9)
        # the pads span the 20 x 8 cm foot print
        corners = [p.foot_frame_to_world(side, xy) for xy in TABLE12]
        assert all(abs(c[0]) < H.FOOT_LENGTH_MM / 2000 for c in corners)


# --- standing and the force sensors ------------------------------------------------------------------
def test_stands_10_s_with_servos_holding(standing) -> None:
    p, drv = standing
    p.reset()
    drv.apply()
    com0 = p.truth().com.copy()
    heights = []
    for _ in range(10):
        drv.wait(1_000_000)
        heights.append(p.truth().com[2])
    tr = p.truth()
    assert max(abs(h - com0[2]) for h in heights) < 0.005
    assert np.linalg.norm(tr.com[:2] - com0[:2]) < 0.005
    assert not tr.fell and tr.trunk_tilt_deg < 1.0
    assert tr.t_s == 10.0


def test_limp_robot_collapses(standing) -> None:
    """Counter-check of the above: with bent knees and PWM off, the servos give way."""
    p, drv = standing
    drv.ramp({"r_knee": 30, "l_knee": 30, "r_hip_pitch": -15, "l_hip_pitch": -15,
              "r_ankle_pitch": -15, "l_ankle_pitch": -15}, 0.5)
    drv.wait(500_000)
    crouched = p.truth().com[2]
    assert crouched > 0.2 and not p.truth().fell
    for scu in range(1, 9):
        p.set_pwm(scu, [None, None, None])
    drv.wait(2_000_000)
    assert p.truth().com[2] < crouched - 0.05


def test_force_sensors_add_up_to_the_weight(standing) -> None:
    p, _ = standing
    total = sensor_newtons(p, 1) + sensor_newtons(p, 2)
    assert total == pytest.approx(WEIGHT_N, rel=0.03)
    assert p.truth().total_normal_force_n == pytest.approx(WEIGHT_N, rel=1e-3)
    # roughly half on each foot, and every sensor loaded
    assert sensor_newtons(p, 1) == pytest.approx(WEIGHT_N / 2, rel=0.1)
    assert min(p.read_force_adc(1) + p.read_force_adc(2)) > 20
    # boards without a foot read nothing
    assert all(p.read_force_adc(scu) == [0, 0, 0, 0] for scu in range(3, 9))


@pytest.mark.parametrize("lift_side", ["r", "l"])
def test_lifting_one_foot_moves_the_whole_load_to_the_other(standing, lift_side) -> None:
    p, drv = standing
    s = 1 if lift_side == "r" else -1          # lean toward the stance foot: +y for a right lift
    lean = {"r_ankle_roll": 15 * s, "l_ankle_roll": 15 * s, "r_hip_roll": -15 * s, "l_hip_roll": -15 * s,
            "torso_roll": -20 * s}
    drv.ramp(lean, 2.0)
    leg = lift_side
    lifted = dict(lean, **{f"{leg}_hip_pitch": -30, f"{leg}_knee": 60, f"{leg}_ankle_pitch": -30})
    drv.ramp(lifted, 1.0)
    drv.wait(1_000_000)
    lift_scu, stance_scu = (1, 2) if lift_side == "r" else (2, 1)
    assert p.read_force_adc(lift_scu) == [0, 0, 0, 0]
    assert sensor_newtons(p, stance_scu) == pytest.approx(WEIGHT_N, rel=0.03)
    tr = p.truth()
    assert tr.foot_cop_mm[f"{lift_side}_foot"] is None and not tr.fell
    assert p.foot_cop_mm(f"{lift_side}_foot") is None and p.foot_cop_xy_mm(f"{lift_side}_foot") is None
    assert len(tr.support_polygon_xy) == 4 and tr.cop_margin_mm > 0


@pytest.mark.parametrize(("pose", "axis", "direction"), [
    ({"r_ankle_pitch": -4, "l_ankle_pitch": -4}, 1, +1),                         # lean forward
    ({"r_ankle_pitch": 4, "l_ankle_pitch": 4}, 1, -1),                           # lean back
    ({"r_ankle_roll": -4, "l_ankle_roll": -4, "r_hip_roll": 4, "l_hip_roll": 4}, 0, +1),   # to the right
    ({"r_ankle_roll": 4, "l_ankle_roll": 4, "r_hip_roll": -4, "l_hip_roll": -4}, 0, -1),   # to the left
])
def test_sensor_cop_equals_contact_cop_within_2_mm(standing, pose, axis, direction) -> None:
    p, drv = standing
    drv.ramp(pose, 1.0)
    drv.wait(500_000)
    for _ in range(5):                       # five single readings, 20 ms apart, each within 2 mm
        drv.wait(TICK)
        tr = p.truth()
        for scu, foot in H.FOOT_OF_SCU.items():
            truth = tr.foot_cop_mm[foot]
            # the per-foot calls give the truth's numbers, as an array and as two floats
            assert p.foot_cop_mm(foot).tolist() == truth.tolist() == list(p.foot_cop_xy_mm(foot))
            assert np.linalg.norm(sensor_cop_mm(p.read_force_adc(scu)) - truth) < 2.0
            assert truth[axis] * direction > 3.0       # the lean really moved the CoP


# --- the servo -----------------------------------------------------------------------------------------
def test_servo_step_response_reaches_the_no_load_speed(standing) -> None:
    p, _ = standing
    dof = p.model.joint("body_spare").dofadr[0]
    p.set_pwm(5, [1500, 1500, H.pulse_from_deg(60)])
    speeds = []
    for _ in range(300):
        p.advance_to(p.t_us + 1000)
        speeds.append(abs(p.data.qvel[dof]))
    assert max(speeds) == pytest.approx(C.SERVO_NO_LOAD_SPEED_RAD_S, rel=0.10)
    assert p.servo_angle_deg(5, 2) == pytest.approx(60, abs=1.0)
    # 60 degrees at 7.48 rad/s take 0.14 s: half-way (30 degrees) after about 0.07 s + the spin-up
    t_half = next(k for k, _ in enumerate(speeds) if sum(speeds[: k + 1]) * 1e-3 > math.radians(30))
    assert 0.06 < t_half / 1000 < 0.12


def test_servo_holds_its_stall_torque_and_slips_beyond(standing) -> None:
    p, _ = standing
    a = p.model.actuator("body_spare_act").id
    stall = C.SERVO_STALL_TORQUE_NM
    for k in range(1, 21):                                      # load it slowly up to 95 % of stall
        p.set_external_torque("body_spare", 0.95 * stall * k / 20)
        p.advance_to(p.t_us + 25_000)
    p.advance_to(p.t_us + 300_000)
    held = p.servo_angle_deg(5, 2)
    p.advance_to(p.t_us + 500_000)
    assert abs(p.servo_angle_deg(5, 2) - held) < 0.2           # holds still
    assert abs(held) < C.SERVO_SATURATION_ERROR_DEG + 0.3       # deflected by ~ torque / kp
    assert abs(p.data.actuator_force[a]) == pytest.approx(0.95 * stall, rel=0.05)
    p.set_external_torque("body_spare", 1.25 * stall)
    p.advance_to(p.t_us + 300_000)
    assert abs(p.data.actuator_force[a]) == pytest.approx(stall, rel=1e-5)   # saturated at stall
    assert abs(p.servo_angle_deg(5, 2)) > 20                                  # back-driven


def test_current_reading_rises_with_load(standing) -> None:
    p, _ = standing
    idle = p.read_servos(5)[1][2]
    p.set_external_torque("body_spare", 1.0)
    p.advance_to(p.t_us + 300_000)
    loaded = p.read_servos(5)[1][2]
    p.set_external_torque("body_spare", 2.0)
    p.advance_to(p.t_us + 300_000)
    heavier = p.read_servos(5)[1][2]
    assert idle <= C.CURRENT_IDLE_US + 10
    assert idle < loaded < heavier <= H.CURRENT_PULSE_FULL_US
    assert heavier == pytest.approx(C.CURRENT_IDLE_US + 1000 * 2.0 / C.SERVO_STALL_TORQUE_NM, abs=15)
    # moving unloaded at the no-load speed draws little current (back-EMF), stalled draws full
    p.set_external_torque("body_spare", 0.0)
    p.set_pwm(5, [1500, 1500, H.pulse_from_deg(-80)])
    p.advance_to(p.t_us + 100_000)
    assert p.read_servos(5)[1][2] < 200
    # stalled by a load beyond its stall torque: full current
    p.set_external_torque("body_spare", 5.0)
    p.advance_to(p.t_us + 300_000)
    assert p.read_servos(5)[1][2] == H.CURRENT_PULSE_FULL_US


def test_pwm_off_makes_a_servo_limp(standing) -> None:
    p, _ = standing
    p.set_pwm(5, [1500, 1500, None])
    assert not p.servo_powered(5, 2) and p.servo_powered(5, 1)
    p.set_external_torque("body_spare", 0.5)      # above its gear friction
    p.advance_to(p.t_us + 500_000)
    assert abs(p.servo_angle_deg(5, 2)) > 20      # (0.5 - 0.2 friction) / damping = 1 rad/s
    assert p.data.actuator_force[p.model.actuator("body_spare_act").id] == 0.0
    assert p.read_servos(5)[1][2] == 0
    p.set_external_torque("body_spare", 0.0)
    p.set_pwm(5, [1500, 1500, 1500])              # on again: back to 0
    p.advance_to(p.t_us + 500_000)
    assert p.servo_angle_deg(5, 2) == pytest.approx(0, abs=1.0)


def test_potentiometer_follows_the_calibration_law(standing) -> None:
    p, drv = standing
    drv.ramp({"r_knee": 30, "l_knee": 30, "r_hip_pitch": -15, "l_hip_pitch": -15,
              "r_ankle_pitch": -15, "l_ankle_pitch": -15, "l_hip_roll": 5, "l_ankle_roll": 5}, 0.5)
    drv.wait(500_000)
    for scu in range(1, 9):
        samples = np.array([p.read_servos(scu)[0] for _ in range(200)], dtype=float)
        for i in range(3):
            b = p.pot_b_true_deg[scu][i]
            assert abs(b - H.POT_B_NOMINAL_DEG) <= C.POT_OFFSET_RANGE_DEG
            expected = (b - p.servo_angle_deg(scu, i)) * H.POT_COUNTS_PER_DEG
            assert samples[:, i].mean() == pytest.approx(expected, abs=0.2)
            assert 0.3 < samples[:, i].std() < 0.8              # noise std 0.5 count
            # pos = b - m * ADC recovers the true angle (what the firmware computes)
            est = b - samples[:, i].mean() / H.POT_COUNTS_PER_DEG
            assert est == pytest.approx(p.servo_angle_deg(scu, i), abs=0.1)
    # the left roll servos are mirrored: the joints moved toward +5, the servos read the opposite
    joints = p.truth().joint_angles_deg
    assert joints["l_hip_roll"] > 2 and joints["l_ankle_roll"] > 2
    assert p.servo_angle_deg(4, 0) == pytest.approx(-joints["l_hip_roll"])
    assert p.servo_angle_deg(2, 0) == pytest.approx(-joints["l_ankle_roll"])
    assert p.servo_angle_deg(1, 2) == pytest.approx(joints["r_knee"])


def test_runs_are_deterministic_per_seed() -> None:
    def run(seed: int) -> list:
        p = Plant(seed=seed)
        drv = Driver(p)
        out = []
        for _ in range(10):
            drv.wait(TICK)
            out.append((p.read_servos(1), p.read_force_adc(1), p.read_force_adc(2)))
        return out + [p.pot_b_true_deg]

    assert run(3) == run(3)
    assert run(3) != run(4)


def test_readings_are_plain_ints_in_range(standing) -> None:
    p, _ = standing
    adc, cur = p.read_servos(1)
    forces = p.read_force_adc(1)
    assert all(type(v) is int for v in adc + cur + forces)
    assert all(0 <= v <= H.POT_ADC_MAX for v in adc)
    assert all(0 <= v <= H.CURRENT_PULSE_FULL_US for v in cur)
    assert all(0 <= v <= H.FORCE_ADC_MAX for v in forces)


# --- the platform ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("tilt", [10.0, -10.0])
def test_tilting_the_platform_moves_the_cop_to_the_low_edge(standing, tilt) -> None:
    p, drv = standing
    before = {f: p.truth().foot_cop_mm[f][1] for f in ("r_foot", "l_foot")}
    p.set_tilt_profile(lambda t: max(-10.0, min(10.0, (t - 0.3) * tilt / 2.0)))   # 5 deg/s ramp
    drv.wait(3_000_000)
    assert p.tilt_deg == pytest.approx(tilt)
    toe = p.foot_frame_to_world("r", (0.0, 100.0))
    assert toe[2] * tilt > 0                      # toes up for positive tilt
    tr = p.truth()
    assert not tr.fell
    for scu, foot in H.FOOT_OF_SCU.items():
        moved = tr.foot_cop_mm[foot][1] - before[foot]
        assert moved * tilt < -20                  # toward the low edge by more than 2 cm
        adc = p.read_force_adc(scu)
        front, rear = adc[0] + adc[1], adc[2] + adc[3]
        assert (rear - front) * tilt > 0
    p.set_tilt_deg(0.0)
    assert p.tilt_deg == 0.0


# --- ground truth and frames ---------------------------------------------------------------------------
def test_ground_truth_and_drawing_helpers(standing) -> None:
    p, _ = standing
    tr = p.truth()
    assert tr.cop_world_xy is not None and np.linalg.norm(tr.cop_world_xy) < 0.005
    # the support polygon is the hull of the 8 pads; the CoP (centre) is 62 mm from its front edge
    assert 4 <= len(tr.support_polygon_xy) <= 8
    assert np.abs(tr.support_polygon_xy[:, 0]).max() == pytest.approx(0.0625, abs=1e-3)
    assert tr.cop_margin_mm == pytest.approx(62.0, abs=1.0)
    pads = sum(tr.pad_forces_n["r_foot"]) + sum(tr.pad_forces_n["l_foot"])
    assert pads == pytest.approx(WEIGHT_N, rel=1e-3)
    # the pad forces are the normal components of mj_contactForce over the pad contacts
    m, d = p.model, p.data
    f6, ref = np.zeros(6), {"r_foot": np.zeros(4), "l_foot": np.zeros(4)}
    for c in range(d.ncon):
        name = m.geom(d.contact.geom[c][0]).name or m.geom(d.contact.geom[c][1]).name
        mujoco.mj_contactForce(m, d, c, f6)
        foot, suffix = name[:6], name[-2:]
        ref[foot][("fl", "fr", "rl", "rr").index(suffix)] += f6[0]
    for foot in ref:
        assert tr.pad_forces_n[foot] == pytest.approx(ref[foot], rel=1e-9)
    names, pos, quat = p.body_poses()
    assert len(names) == len(pos) == len(quat) == p.model.nbody - 1 and "r_foot" in names
    assert quat[names.index("trunk")] == pytest.approx([0, 0, 0, 1], abs=1e-3)     # xyzw
    geoms = p.geometry()
    assert {"platform", "floor"} <= {g.name for g in geoms}
    assert sum(g.name.startswith("r_foot_pad") for g in geoms) == 4
    assert all(len(g.quat_xyzw) == 4 and len(g.rgba) == 4 for g in geoms)
    xy = (10.0, -20.0)
    assert p.world_to_foot_frame("l", p.foot_frame_to_world("l", xy)) == pytest.approx(xy, abs=1e-9)


def test_fell_is_reported_when_the_robot_falls() -> None:
    p = Plant()
    drv = Driver(p)
    drv.ramp({"r_ankle_pitch": -40, "l_ankle_pitch": -40}, 0.3)     # throw itself forward
    drv.wait(2_000_000)
    tr = p.truth()
    assert tr.fell and tr.trunk_tilt_deg > 45


def test_convex_hull_and_signed_distance() -> None:
    square = convex_hull([(0, 0), (1, 0), (1, 1), (0, 1), (0.5, 0.5), (0.5, 0)])
    assert len(square) == 4
    assert signed_distance((0.5, 0.5), square) == pytest.approx(0.5)
    assert signed_distance((0.5, 0.9), square) == pytest.approx(0.1)
    assert signed_distance((2.0, 0.5), square) == pytest.approx(-1.0)
    assert signed_distance((2.0, 2.0), square) == pytest.approx(-math.sqrt(2))
    assert signed_distance((0.5, 0.0), square) == pytest.approx(0.0)
    assert signed_distance((0, 1), convex_hull([(0, 0), (0, 2)])) == pytest.approx(0.0)
    assert signed_distance((1, 1), convex_hull([(0, 0)])) == pytest.approx(-math.sqrt(2))
    assert signed_distance((0, 0), []) == -math.inf


# --- time and bad input --------------------------------------------------------------------------------
def test_advance_to_never_passes_the_requested_time() -> None:
    p = Plant()
    assert p.timestep_us == 1000
    p.advance_to(1500)
    assert p.t_us == 1000 and p.data.time == pytest.approx(0.001)
    p.advance_to(1999)
    assert p.t_us == 1000
    p.advance_to(20_000)
    assert p.t_us == 20_000 and p.data.time == pytest.approx(0.02)
    with pytest.raises(PlantInputError, match="backwards"):
        p.advance_to(10_000)
    p.reset()
    assert p.t_us == 0 and p.truth().t_s == 0.0


def test_sign_table() -> None:
    assert SERVO_SIGN["l_hip_roll"] == SERVO_SIGN["l_ankle_roll"] == SERVO_SIGN["l_hip_yaw"] == -1
    assert SERVO_SIGN["r_hip_roll"] == SERVO_SIGN["l_knee"] == SERVO_SIGN["l_hip_pitch"] == 1
    assert SERVO_SIGN_BY_SCU[2] == (-1, 1, 1) and SERVO_SIGN_BY_SCU[1] == (1, 1, 1)
    assert len(SERVO_SIGN) == 24
    assert Plant.scu_joint_names(1) == ("r_ankle_roll", "r_ankle_pitch", "r_knee")


def test_bad_input_gets_clear_errors(tmp_path) -> None:
    p = Plant()
    with pytest.raises(PlantInputError, match="SCU"):
        p.set_pwm(9, [1500, 1500, 1500])
    with pytest.raises(PlantInputError, match="SCU"):
        p.read_servos(0)
    with pytest.raises(PlantInputError, match="SCU"):
        p.read_force_adc(-1)
    for foot in ("r", "left", None, ["r_foot"]):
        with pytest.raises(PlantInputError, match="unknown foot"):
            p.foot_cop_mm(foot)
        with pytest.raises(PlantInputError, match="unknown foot"):
            p.foot_cop_xy_mm(foot)
    with pytest.raises(PlantInputError, match="600..2400"):
        p.set_pwm(1, [1500, 2500, 1500])
    with pytest.raises(PlantInputError, match="pulse"):
        p.set_pwm(1, [1500, "1500", 1500])
    with pytest.raises(PlantInputError, match="3 pulses"):
        p.set_pwm(1, [1500, 1500])
    with pytest.raises(PlantInputError, match="3 pulses"):
        p.set_pwm(1, 1500)
    with pytest.raises(PlantInputError, match="servo index"):
        p.servo_angle_deg(1, 3)
    with pytest.raises(PlantInputError, match="tilt"):
        p.set_tilt_deg(float("nan"))
    with pytest.raises(PlantInputError, match="keyframe"):
        p.reset("sit")
    with pytest.raises(PlantInputError, match="foot side"):
        p.foot_frame_to_world("middle", (0, 0))
    with pytest.raises(PlantInputError, match="joint"):
        p.set_external_torque("tail", 1.0)
    # a rejected call changes nothing
    assert p.data.ctrl[p.model.actuator("r_ankle_pitch_act").id] == 0.0
    missing = tmp_path / "nope.xml"
    with pytest.raises(PlantError, match="nope.xml"):
        Plant(missing)
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody><body><geom type='box'/></worldbody></mujoco>")
    with pytest.raises(PlantError, match="broken.xml"):
        Plant(broken)
    other = tmp_path / "other.xml"
    other.write_text("<mujoco><worldbody><geom type='plane' size='1 1 1'/></worldbody></mujoco>")
    with pytest.raises(PlantError, match="no joint named"):
        Plant(other)


# --- the ground truth: the figures of its instant, read then or later --------------------------------
def _truth_fields(tr) -> list:
    return [tr.t_s, tr.com, tr.trunk_tilt_deg, tr.trunk_height_m, tr.joint_angles_deg, tr.pad_forces_n,
            tr.foot_cop_mm, tr.cop_world_xy, tr.support_polygon_xy, tr.cop_margin_mm,
            tr.total_normal_force_n, tr.fell]


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (a is None) == (b is None) and np.array_equal(a, b)
    return a == b


def test_truth_read_later_is_that_of_its_instant() -> None:
    # the per-foot fields are derived on first read, from what the plant copied at the sample:
    # a truth read after the plant moved on says what a truth read at once said
    plants = [Plant(seed=1), Plant(seed=1)]
    for p in plants:
        Driver(p).ramp({"r_knee": 20.0, "r_hip_pitch": -10.0, "r_ankle_pitch": -10.0}, 0.4)
    late, now = plants[0].truth(), plants[1].truth()
    expected = _truth_fields(now)
    for p in plants:
        Driver(p).ramp({"l_hip_roll": 8.0}, 0.3)
    assert all(_same(a, b) for a, b in zip(_truth_fields(late), expected, strict=True))
    assert not _same(plants[0].truth().com, late.com)           # the plant did move on
    assert late.foot_cop_mm["r_foot"] is not None and late.support_polygon_xy.shape[1] == 2
    with pytest.raises(AttributeError):
        late.fell = True                                        # read-only, as a frozen record
    assert "GroundTruth(t_s=" in repr(late)


def test_body_pose_views_follow_the_plant(standing) -> None:
    p, drv = standing
    names, pos, quat = p.body_poses()
    vpos, vquat = p.body_pose_views()
    assert np.array_equal(vpos, pos) and np.array_equal(vquat[:, [1, 2, 3, 0]], quat)
    drv.ramp({"r_knee": 15.0}, 0.2)
    _, pos2, quat2 = p.body_poses()
    assert np.array_equal(vpos, pos2) and np.array_equal(vquat[:, [1, 2, 3, 0]], quat2)
    assert not np.array_equal(pos, pos2)                        # body_poses copies, the views follow


def _place_robot_on_platform(p: Plant, tilt_deg: float, along_m: float, lying: bool = False) -> None:
    """Tilt the platform and put the robot (keyframe posture) ``along_m`` along its surface (negative:
    down the slope of a toes-up tilt), turned with the platform (feet flat on it), or lying on it."""
    import mujoco

    p.set_tilt_deg(tilt_deg)
    th = math.radians(tilt_deg)
    d = p.data
    x0, z0 = float(d.qpos[0]), float(d.qpos[2])
    half = -th / 2                 # the platform's own rotation (toes up = about -y)
    if lying:      # trunk along the surface (its z axis down the slope), 5 cm above it
        x0, z0 = 0.0, 0.05
        half = -(th + math.pi / 2) / 2
    d.qpos[3:7] = (math.cos(half), 0.0, math.sin(half), 0.0)
    # the point (x0, z0) of the level platform's frame, carried onto the tilted one and moved along it
    d.qpos[0] = (x0 + along_m) * math.cos(th) - z0 * math.sin(th)
    d.qpos[2] = (x0 + along_m) * math.sin(th) + z0 * math.cos(th)
    d.qvel[:] = 0
    mujoco.mj_forward(p.model, d)


def test_feet_slid_down_a_tilted_platform_is_not_a_fall_and_is_measured_as_slip() -> None:
    """Issue 25: the fall test compared the trunk's height above the *world* floor with 0.12 m, so a
    robot standing upright whose feet had slid 0.4 m down a 30 deg platform was 'fallen'."""
    p = Plant()
    soles0 = p.soles_on_surface_mm()
    _place_robot_on_platform(p, 30.0, -0.4)
    tr = p.truth()
    assert tr.trunk_height_m < C.FELL_HEIGHT_M          # what the old, world-height test tripped on
    assert not tr.fell
    slid = p.soles_on_surface_mm()
    for (x, y, h), (x0, y0, h0) in zip(slid, soles0, strict=True):
        assert x - x0 == pytest.approx(-400.0, abs=5.0) and y == pytest.approx(y0, abs=1.0)
        assert h == pytest.approx(h0, abs=1.0) and abs(h0) < 5.0       # on the surface
    # tilting the platform under a robot that stays put on it moves no sole along the surface
    q = Plant()
    _place_robot_on_platform(q, 20.0, 0.0)
    for (x, y, _), (x0, y0, _) in zip(q.soles_on_surface_mm(), soles0, strict=True):
        assert math.hypot(x - x0, y - y0) < 1.0


def test_a_robot_lying_on_a_tilted_platform_has_fallen() -> None:
    p = Plant()
    _place_robot_on_platform(p, 30.0, 0.0, lying=True)
    tr = p.truth()
    assert tr.fell and tr.trunk_tilt_deg == pytest.approx(120.0)    # lying along it, head down the slope


def test_the_sensor_front_end_rounds_as_python_does():
    """The boards' ADC rounding (plant/sensors.py, C doubles in the compiled core) is Python's
    round: to nearest, ties to even, also next to the ties and for negative values."""
    import math
    import random

    from humanoid_twin.plant.sensors import round_half_even

    values = [k / 2 for k in range(-41, 42)]                          # every tie in -20.5..20.5
    values += [math.nextafter(v, d) for v in values for d in (-math.inf, math.inf)]
    values += [0.0, -0.0, 0.49999999999999994, -0.49999999999999994, 1023.5, 254.5, 1e15 + 0.5]
    rng = random.Random(7)
    values += [rng.uniform(-1100.0, 1100.0) for _ in range(20_000)]
    assert [round_half_even(v) for v in values] == [round(v) for v in values]
