"""The Slave firmware's modules on their own (seed 000 section 3): TRAJECTORY, MyMATHS, DATA, SERVO,
PIC2 arithmetic, GLOBAL, and the CAN module's packet intake. Pure and fast: no plant, no bus."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanoid_twin import hardware
from humanoid_twin.clock import Clock
from humanoid_twin.protocol.canframes import control_byte, pack_actuation1, pack_actuation2
from humanoid_twin.slave import data, mymaths
from humanoid_twin.slave.can import SlaveCan
from humanoid_twin.slave.database import Global
from humanoid_twin.slave.pic2 import (
    current_from_pulse,
    force_result,
    limitPosition,
    median3,
    position_from_adc,
)
from humanoid_twin.slave.servo import (
    BALANCE_CONTROL,
    LOCOMOTION_CONTROL,
    NO_CONTROL,
    REACTION_CONTROL,
    VELOCITY_LIMIT_Q8,
    Calibration,
    ServoControl,
    calibration_b,
    force_offset,
)
from humanoid_twin.slave.slave import LEG_SIGNS
from humanoid_twin.slave.trajectory import FREE_TRAJECT, NORMAL_TRAJECT, Trajectory

# ---------------------------------------------------------------------------------------------
# TRAJECTORY (tables 6-7)


def run_ticks(tr: Trajectory, refs, periods, types, n: int) -> list[list[int]]:
    out = []
    for _ in range(n):
        tr.trajectory(refs, periods, types, tr.position)
        out.append(list(tr.position))
    return out


def test_cubic_coefficients_have_zero_end_velocities_and_reach_the_end():
    tr = Trajectory()
    tr.calcTrajectory(0, start=10, theta_final=70, period=100, control_type=0)
    a0, a1, a2, a3 = tr.traject[0].coef
    assert tr.traject[0].type == NORMAL_TRAJECT
    assert (a0, a1) == (10.0, 0.0)
    assert a2 == pytest.approx(3 * 60 / 100**2)
    assert a3 == pytest.approx(-2 * 60 / 100**3)

    def vel(t: float) -> float:
        return a1 + 2 * a2 * t + 3 * a3 * t * t

    assert vel(0) == 0.0
    assert vel(100) == pytest.approx(0.0, abs=1e-12)
    assert a0 + a1 * 100 + a2 * 100**2 + a3 * 100**3 == pytest.approx(70.0)


def test_trajectory_reaches_the_final_position_exactly_at_period_ticks():
    tr = Trajectory()
    tr.initTrajectory((10, 0, -5))
    out = run_ticks(tr, (70, 0, -5), (100, 0, 0), (0, 0, 0), 99)
    assert not tr.done(0) and tr.theoretical(0, 99) < 70   # 99 ticks: not there yet
    out += run_ticks(tr, (70, 0, -5), (100, 0, 0), (0, 0, 0), 21)
    servo0 = [o[0] for o in out]
    assert tr.traject[0].time == 100 and servo0[99] == 70  # the 100th tick outputs theta_final
    assert all(p == 70 for p in servo0[99:])
    assert servo0 == sorted(servo0)                       # monotonic, no overshoot
    assert servo0[49] == 40                               # half time = half way (symmetric cubic)
    # slow start and slow end: small steps at both ends, the largest in the middle
    steps = np.diff([10] + servo0[:100])
    assert steps[0] <= 1 and steps[-1] <= 1 and steps.max() >= 0.9 * 1.5 * 60 / 100
    assert tr.done(0) and tr.done(1) and tr.done(2)


def test_free_trajectory_applies_the_final_position_at_once():
    tr = Trajectory()
    restarted = tr.trajectory((45, -30, 0), (0, 0, 0), (0, 0, 0), tr.position)
    assert restarted == 0b011                              # servo 3's ref (0) did not change
    assert tr.position == [45, -30, 0]
    assert tr.traject[0].type == FREE_TRAJECT and tr.done(0)


def test_a_new_reference_interrupts_the_trajectory_from_the_commanded_position():
    tr = Trajectory()
    out = run_ticks(tr, (70, 0, 0), (100, 0, 0), (0, 0, 0), 50)
    here = out[-1][0]
    assert here == 35                                      # from 0, half way to 70
    mask = tr.trajectory((-20, 0, 0), (50, 0, 0), (0, 0, 0), tr.position)
    assert mask == 0b001
    assert tr.traject[0].coef[0] == here                   # starts where the servo is commanded
    assert abs(tr.position[0] - here) <= 1                 # no jump
    rest = run_ticks(tr, (-20, 0, 0), (50, 0, 0), (0, 0, 0), 60)
    assert [o[0] for o in rest][48] == -20 and not tr.traject[0].time < 50


def test_a_new_control_type_restarts_but_a_new_period_alone_does_not():
    tr = Trajectory()
    run_ticks(tr, (30, 0, 0), (10, 0, 0), (0, 0, 0), 20)
    assert tr.trajectory((30, 0, 0), (99, 0, 0), (0, 0, 0), tr.position) == 0      # period only
    assert tr.trajectory((30, 0, 0), (99, 0, 0), (0, 1, 0), tr.position) == 0b010  # type of servo 2
    assert tr.traject[1].control_type == 1


def test_trajectory_limits_references_and_rejects_bad_periods():
    tr = Trajectory()
    tr.trajectory((127, -128, 0), (0, 0, 0), (0, 0, 0), tr.position)
    assert tr.position[:2] == [90, -90]
    with pytest.raises(ValueError, match="period"):
        tr.calcTrajectory(0, 0, 10, -1, 0)
    with pytest.raises(ValueError, match="period"):
        tr.calcTrajectory(0, 0, 10, 70000, 0)


# ---------------------------------------------------------------------------------------------
# MyMATHS (table 15)

TABLE_15 = {0: 0, 1: 1, 2: 3, 3: 5, 4: 6, 5: 8, 81: 98, 82: 99, 83: 99, 89: 99, 90: 100}


@pytest.mark.parametrize("deg,value", sorted(TABLE_15.items()))
def test_sine_table_matches_every_entry_of_table_15(deg, value):
    assert mymaths.seno(deg) == value
    assert mymaths.SINE_TABLE[deg] == value


def test_sine_table_is_the_truncated_sine_at_every_degree():
    for d in range(91):
        v = mymaths.SINE_TABLE[d]
        exact = 100 * math.sin(math.radians(d))
        assert v <= exact + 1e-9 < v + 1, d
    assert mymaths.seno(30) == 50                           # exact values stay exact


def test_sine_folding_signs_and_cosine():
    for t in range(-720, 721):
        s = mymaths.seno(t)
        assert -100 <= s <= 100
        assert mymaths.seno(-t) == -s or s == 0 and mymaths.seno(-t) == 0
        assert mymaths.seno(180 - t) == s
        assert mymaths.seno(t + 360) == s
        assert mymaths.coseno(t) == mymaths.seno(90 - t)
        assert abs(s - 100 * math.sin(math.radians(t))) < 1.0 + 1e-9
    assert [mymaths.coseno(t) for t in (0, 60, 90, 180, 270, -60)] == [100, 50, 0, -100, 0, 50]
    assert mymaths.seno(-90) == -100 and mymaths.seno(270) == -100 and mymaths.seno(-1) == -1
    assert mymaths.abs(-32768) == 32768 and mymaths.abs(5) == 5


# ---------------------------------------------------------------------------------------------
# DATA: calcCoP (table 12)


def test_cop_equal_loads_is_the_centroid_of_the_sensors():
    cx = sum(x for x, _ in hardware.FORCE_SENSOR_XY_MM) / 4      # -0.375 mm
    cy = sum(y for _, y in hardware.FORCE_SENSOR_XY_MM) / 4      # -0.25 mm
    x, y, loaded = data.calcCoP([30, 30, 30, 30])
    assert loaded and (x, y) == (round(cx), round(cy)) == (0, 0)


@pytest.mark.parametrize(
    "k,expected", [(0, (-33, 62)), (1, (32, 62)), (2, (-35, -63)), (3, (34, -63))]
)
def test_cop_one_loaded_sensor_is_its_coordinates(k, expected):
    f = [0, 0, 0, 0]
    f[k] = 40
    x, y, loaded = data.calcCoP(f)
    sx, sy = hardware.FORCE_SENSOR_XY_MM[k]
    assert loaded and (x, y) == expected
    assert abs(x - sx) <= 0.5 and abs(y - sy) <= 0.5              # halves rounded away from zero


def test_cop_hand_computed_and_unloaded_foot():
    # x = (30*-32.5 + 10*32 + 20*34)/60 = 0.4167 -> 0;  y = (30*62 + 10*62 - 20*62.5)/60 = 20.5 -> 21
    assert data.calcCoP([30, 10, 0, 20]) == (0, 21, True)
    assert data.calcCoP([2, 2, 1, 2]) == (0, 0, False)              # 7 counts < COP_MIN_LOAD
    assert data.calcCoP([0, 0, 0, 0]) == (0, 0, False)


@given(st.lists(st.integers(0, 127), min_size=4, max_size=4))
@settings(max_examples=200, deadline=None)
def test_cop_integer_arithmetic_within_half_a_millimetre_of_the_exact_cop(f):
    x, y, loaded = data.calcCoP(f)
    if sum(f) < data.COP_MIN_LOAD:
        assert not loaded
        return
    fx = sum(fi * p[0] for fi, p in zip(f, hardware.FORCE_SENSOR_XY_MM, strict=True)) / sum(f)
    fy = sum(fi * p[1] for fi, p in zip(f, hardware.FORCE_SENSOR_XY_MM, strict=True)) / sum(f)
    assert loaded and abs(x - fx) <= 0.5 + 1e-9 and abs(y - fy) <= 0.5 + 1e-9


# ---------------------------------------------------------------------------------------------
# DATA: jacobianMatrix (table 13) vs finite differences


def _rot_x(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def leg_mass_centre(a: float, b: float, c: float) -> np.ndarray:
    """Independent forward kinematics (rotation matrices, radians): links of table 13 from the
    ankle, roll about +y (forward), pitch and knee about +x (right), masses M1 = M2."""
    L, R, M = hardware.LINK_LENGTH_MM, hardware.LINK_COM_MM, hardware.LINK_MASS_KG
    up = np.array([0.0, 0.0, 1.0])
    base = _rot_y(a) @ _rot_x(b)
    lower = base @ (up * (L - R))
    upper = base @ (up * L + _rot_x(c) @ (up * (L - R)))
    return (M * lower + M * upper) / (2 * M)


def test_mass_centre_closed_form_matches_rotation_matrices():
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.uniform(-80, 80, 3)
        ref = leg_mass_centre(*np.radians(q))
        assert np.allclose(data.mass_centre_mm(*q), ref, atol=1e-9)
    assert np.allclose(data.mass_centre_mm(0, 0, 0), [0, 0, 95.5])


@pytest.mark.parametrize("signs", [(1, 1, 1), (-1, 1, 1)])
@pytest.mark.parametrize("q", [(0, 0, 0), (10, -20, 30), (-25, 15, -40), (5, 45, 60), (-60, -30, 10)])
def test_jacobian_matches_finite_differences_of_the_leg_kinematics(q, signs):
    J = np.array(data.jacobianMatrix(*q, signs=signs), dtype=float) / 1000.0   # mm/rad
    h = 1e-6
    fd = np.zeros((3, 3))
    for j in range(3):
        qp = np.radians(np.array(q, dtype=float) * signs)
        qm = qp.copy()
        qp[j] += signs[j] * h
        qm[j] -= signs[j] * h
        fd[:, j] = (leg_mass_centre(*qp) - leg_mass_centre(*qm)) / (2 * h)
    # integer sine table (truncated, x100) and C division: about 1 % of the 95.5 mm lever
    assert np.allclose(J, fd, atol=2.0), (J, fd)


# ---------------------------------------------------------------------------------------------
# SERVO: calibration, PID, balance laws, applyVelocity


def test_calibration_b_and_force_offsets():
    assert calibration_b(10, 25 * 470) == 4 * 10 + 470
    assert calibration_b(-5, 25 * 470 + 10) == -20 + 470           # mean 470.4 -> 470
    assert calibration_b(0, 25 * 470 + 13) == 471                  # mean 470.52 -> 471
    assert position_from_adc(calibration_b(10, 25 * 470), 470) == 10
    assert force_offset(25 * 20) == 108
    assert force_result(2 * 20 + 1, force_offset(25 * 20)) == 128  # calibration load reads 128
    with pytest.raises(ValueError):
        calibration_b(0, 0, 0)


def test_calibration_state_machine_counts_ticks_like_the_manual():
    cal = Calibration()
    assert cal.state == Calibration.WAIT and not cal.step([0] * 3, [0] * 4)
    cal.start([10, -20, 120])
    assert cal.pos_master == [10, -20, 90]
    # 100 ticks of settling: whatever is measured then is ignored
    assert not any(cal.step([999, 999, 999], [127] * 4) for _ in range(100))
    results = [cal.step([470, 600, 512], [20, 30, 40, 50]) for _ in range(25)]
    assert results == [False] * 24 + [True]
    assert cal.done and cal.runs == 1
    assert cal.b_q == [40 + 470, -80 + 600, 360 + 512]
    assert cal.offsets == [108, 98, 88, 78]
    assert [position_from_adc(b, a) for b, a in zip(cal.b_q, [470, 600, 512], strict=True)] == [10, -20, 90]


def make_servo(kp=(0, 0, 0), ki=(0, 0, 0), kd=(0, 0, 0), foot=True, signs=(1, 1, 1)) -> ServoControl:
    g = Global()
    for i in range(3):
        c = g.actuators.control[i]
        c.kp, c.ki, c.kd = kp[i], ki[i], kd[i]
    return ServoControl(g.actuators, foot, signs)


def test_incremental_pid_against_hand_computed_steps():
    sc = make_servo(kp=(16, 0, 0), ki=(8, 0, 0), kd=(4, 0, 0))    # Kp 1.0, Ki 0.5, Kd 0.25
    sc.reset([0, 0, 0])
    types = [LOCOMOTION_CONTROL, NO_CONTROL, NO_CONTROL]
    Kp, Ki, Kd = 1.0, 0.5, 0.25
    u, e1, e2 = 0.0, None, None
    measured_seq = [0, 5, 1, 14, 12, 10]
    for m in measured_seq:
        sc.servoRequest(0, 10)
        e = 10 - m
        if e1 is None:
            e1 = e2 = e                                             # bumpless first step
        u = u + Kp * (e - e1) + Ki * e + Kd * (e - 2 * e1 + e2)
        e2, e1 = e1, e
        sc.controller([m, 0, 0], 0, 0, False, types)
        assert sc.law(LOCOMOTION_CONTROL).u16[0] == round(16 * u)
        assert sc.output[0] == math.floor(u + 0.5)
    assert sc.law(LOCOMOTION_CONTROL).e1[0] == 0 and sc.law(LOCOMOTION_CONTROL).e2[0] == -2


def test_pid_with_integral_gain_converges_on_a_lagging_servo():
    sc = make_servo(kp=(8, 0, 0), ki=(6, 0, 0))
    sc.reset([0, 0, 0])
    measured = 0.0
    for _ in range(60):
        sc.servoRequest(0, 30)
        sc.controller([round(measured), 0, 0], 0, 0, False, [1, 0, 0])
        measured += 0.5 * (sc.output[0] - 2 - measured)              # a servo 2 deg short, lagging
    assert abs(round(measured) - 30) <= 1                            # the integral removes the offset
    assert sc.output[0] > 30


def test_apply_velocity_limiter_and_slow_velocities_accumulate():
    sc = make_servo()
    sc.reset([10, 0, 0])
    sc.applyVelocity(0, 10_000)
    assert sc.last_v[0] == VELOCITY_LIMIT_Q8 and sc.output[0] == 11     # 1 degree per tick at most
    sc.applyVelocity(0, -10_000)
    assert sc.output[0] == 10
    outs = []
    for _ in range(64):
        sc.applyVelocity(0, 2)                                          # 1/128 degree per tick
        outs.append(sc.output[0])
    assert outs[:63] == [10] * 63 and outs[63] == 11
    for _ in range(500):
        sc.applyVelocity(0, 10_000)
    assert sc.output[0] == 90                                            # held within -90..90
    sc.applyVelocity(0, -256)
    assert sc.output[0] == 89                                            # no wind-up past the limit


def test_reaction_control_moves_the_foot_joints_toward_the_cop_reference():
    sc = make_servo(kp=(8, 8, 8))
    sc.reset([0, 0, 0])
    types = [REACTION_CONTROL] * 3
    # CoP 10 mm to the left and 20 mm behind the reference: e = (+10, +20)
    sc.controller([0, 0, 0], -10, -20, True, types)
    assert sc.last_v[0] == 8 * 10 and sc.last_v[1] == -8 * 20 and sc.output[2] == 0
    for _ in range(9):
        sc.controller([0, 0, 0], -10, -20, True, types)
    assert sc.output[:2] == [round(10 * 80 / 256), -round(10 * 160 / 256)]   # integrated: 3, -6
    # the velocity sign is the lever's sign: moving by it shifts the leg mass centre toward +x/+y
    J = data.jacobianMatrix(0, 0, 0)
    assert sc.last_v[0] * J[0][0] > 0 and sc.last_v[1] * J[1][1] > 0
    # mirrored mounting flips the servo direction
    sm = make_servo(kp=(8, 8, 8), signs=(-1, 1, 1))
    sm.reset([0, 0, 0])
    sm.controller([0, 0, 0], -10, -20, True, types)
    assert sm.last_v[0] == -8 * 10
    # an unloaded foot does not act
    sc2 = make_servo(kp=(64, 64, 64))
    sc2.reset([0, 0, 0])
    for _ in range(10):
        sc2.controller([0, 0, 0], -10, -20, False, types)
    assert sc2.output == [0, 0, 0]


def test_jacobian_control_is_j_transpose_e_and_agrees_with_reaction_at_the_straight_leg():
    sc = make_servo(kp=(100, 100, 100))
    sc.reset([0, 0, 0])
    sc.controller([0, 0, 0], -10, -20, True, [BALANCE_CONTROL] * 3)
    J = data.jacobianMatrix(0, 0, 0)
    ex, ey = 10, 20
    for j in range(3):
        jte = J[0][j] * ex + J[1][j] * ey
        expected = int(100 * jte / 65536)
        assert sc.last_v[j] == max(-VELOCITY_LIMIT_Q8, min(VELOCITY_LIMIT_Q8, expected))
    assert sc.last_v[0] > 0 and sc.last_v[1] < 0 and sc.last_v[2] < 0


def test_boards_without_a_foot_run_balance_types_open_loop():
    sc = make_servo(kp=(100, 100, 100), foot=False)
    sc.reset([0, 0, 0])
    for i, r in enumerate((20, -15, 5)):
        sc.servoRequest(i, r)
    sc.controller([0, 0, 0], -30, -30, True, [REACTION_CONTROL, BALANCE_CONTROL, BALANCE_CONTROL])
    assert sc.output == [20, -15, 5]


def test_leg_signs_are_a_mirror_pair():
    r, left = LEG_SIGNS[1], LEG_SIGNS[2]
    assert r[0] == -left[0] and r[1:] == left[1:]


# ---------------------------------------------------------------------------------------------
# PIC2 arithmetic


def test_position_current_force_and_limit_arithmetic():
    b = hardware.POT_B_NOMINAL_DEG * hardware.POT_COUNTS_PER_DEG
    assert position_from_adc(b, 512) == 0
    assert position_from_adc(b, 512 - 40) == 10
    assert position_from_adc(b, 512 + 6) == -1                      # -1.5 deg -> -1 (halves up)
    assert position_from_adc(b, 512 - 6) == 2                       # 1.5 deg -> 2
    assert position_from_adc(b + 100, 0) == 127                     # int8 clamp
    assert current_from_pulse(0) == 0 and current_from_pulse(505) == 50
    assert current_from_pulse(5000) == 100
    assert force_result(255, 128) == 255 and force_result(0, -5) == 0 and force_result(101, 10) == 60
    assert [limitPosition(p) for p in (-128, -90, 0, 90, 127)] == [-90, -90, 0, 90, 90]


def test_median_of_three():
    import itertools

    for a, b, c in itertools.product(range(-2, 3), repeat=3):
        assert median3(a, b, c) == sorted((a, b, c))[1]


# ---------------------------------------------------------------------------------------------
# GLOBAL and the CAN module's packet intake (receiveCanMessage)


def test_database_init_functions():
    g = Global()
    g.actuators.servo[1].ref = 40
    g.actuators.servo[1].speed = 9
    g.actuators.control[2].kp = 7
    g.sensors.servo[0].pos = 12
    g.sensors.sysStatus.calib = True
    g.reinitServo()
    assert (g.actuators.servo[1].ref, g.actuators.servo[1].speed) == (0, 0)
    assert g.actuators.control[2].kp == 7
    g.initSensors()
    assert g.sensors.servo[0].pos == 0 and not g.sensors.sysStatus.calib
    g.initGlobal()
    assert g.actuators.control[2].kp == 0


def test_receive_can_message_fills_the_actuator_database_and_latches_calib_requests():
    g = Global()
    sc = SlaveCan(3, Clock(), g, 0)
    p1 = pack_actuation1((10, -20, 30), (100, 0, 5), control_byte(True, False, (1, 2, 3)), 9)
    p2 = pack_actuation2((1, 2, 3), (4, 5, 6), 7, 8)
    assert sc.receiveCanMessage(0, p1) and sc.receiveCanMessage(1, p2)
    a = g.actuators
    assert [s.ref for s in a.servo] == [10, -20, 30]
    assert [s.speed for s in a.servo] == [100, 0, 5]
    assert [c.type for c in a.control] == [1, 2, 3]
    assert [(c.ki, c.kp, c.kd) for c in a.control] == [(1, 4, 7), (2, 5, 8), (3, 6, 9)]
    assert a.sysStatus.pwm and not a.sysStatus.calib and not sc.calib_request
    # a calibration request 0 -> 1 is latched, and the next answer already says "not calibrated"
    g.sensors.sysStatus.calib = True
    sc.prepareSensorPackets()
    assert sc.payload[0][7] & 0x40
    sc.receiveCanMessage(0, pack_actuation1((0, 0, 0), (0, 0, 0), control_byte(True, True, (0, 0, 0)), 0))
    assert sc.calib_request and not sc.payload[0][7] & 0x40
    sc.calib_request = False
    sc.receiveCanMessage(0, pack_actuation1((0, 0, 0), (0, 0, 0), control_byte(True, True, (0, 0, 0)), 0))
    assert not sc.calib_request                                     # 1 -> 1 is no new request
    # a malformed packet changes nothing and is counted
    assert not sc.receiveCanMessage(0, b"\x01\x02\x03")
    assert sc.rx_errors == 1 and [s.ref for s in a.servo] == [0, 0, 0]


def test_slave_rejects_bad_addresses_and_phases():
    from humanoid_twin.slave import Slave

    for bad in (0, 9, "1", True, 1.0):
        with pytest.raises(ValueError, match="SCU address"):
            Slave(bad, Clock(), None, None, phase_us=0)
    with pytest.raises(ValueError, match="phase_us"):
        Slave(1, Clock(), None, None, phase_us=-5)
