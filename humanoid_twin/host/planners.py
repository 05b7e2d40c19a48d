"""Motion planners of the legs (seed 000 table 22, fig. 21): ``flexao``, ``inclinar``,
``levantar_perna``.

Each returns ``(pos_apply, k, t)`` with the shapes of table 23:

- ``pos_apply``: ``(N_SCU, N_SERVOS, N_MOTIONS)`` = ``(8, 3, M)``, the final position of every
  servo at the end of each motion, as *leg angles* in degrees (joint frame of the MuJoCo model,
  0 = vertical posture; ``exe_traj`` turns them into servo angles with ``adaptate``, ``correct``,
  ``limit``).
- ``k``: ``(8, 3, M, 4)``, per servo and motion ``[KI, KP, KD, control type]`` (bytes; gains in
  the Slave's fixed point, docs/firmware.md; control type of seed 000 table 9).
- ``t``: ``(M,)``, the duration of each motion in seconds (the movement period, sent in 20 ms
  ticks).

Joint signs (humanoid_twin/models/humanoid.xml and its README.md): every axis follows the world
at the stand pose, x forward, y left, z up, the same for both legs. Pitch about +y: positive hip
pitch swings the leg backward, positive knee flexes the knee, positive ankle pitch turns the toes down. Roll
about +x: positive hip roll swings the leg to the robot's right (over a planted foot: the trunk
moves left), positive ankle roll raises the foot's left edge (over a planted foot: the shank
leans left). Only SCUs 1-4 (legs and hips) move; boards 5-8 stay
at 0 with NO_CONTROL (``exe_traj`` drives the leg SCUs by default).

The gains are kept in one place, :data:`GAINS` (the balance numbers are tuned in
docs/balance.md when that work lands).
"""

from __future__ import annotations

import math
import operator
from typing import Any

import numpy as np

from humanoid_twin.clock import US_PER_S
from humanoid_twin.hardware import LEG_SCUS, N_SERVOS, PWM_PERIOD_US
from humanoid_twin.protocol.wire import N_SCU, ControlType, s8

__all__ = [
    "GAINS",
    "LEG_SCUS",
    "SHIFT_DEG",
    "TORSO_LEAN_DEG",
    "R_LEG",
    "L_LEG",
    "R_HIP",
    "L_HIP",
    "ANKLE_ROLL",
    "ANKLE_PITCH",
    "KNEE",
    "HIP_ROLL",
    "HIP_PITCH",
    "HIP_YAW",
    "MAX_PERIOD_S",
    "flexao",
    "inclinar",
    "levantar_perna",
    "empty_plan",
    "leg_pose",
    "control_row",
    "with_control",
]

# Rows of pos_apply / k (SCU - 1) and columns (servo index) of the leg and hip boards
# (hardware.SERVO_JOINTS).
R_LEG, L_LEG, R_HIP, L_HIP = 0, 1, 2, 3
ANKLE_ROLL, ANKLE_PITCH, KNEE = 0, 1, 2
HIP_ROLL, HIP_PITCH, HIP_YAW = 0, 1, 2

TICK_S = PWM_PERIOD_US / US_PER_S
MAX_PERIOD_S = 255 * TICK_S          # the movement period travels as one byte of 20 ms ticks

# Gains per control type: rows servo 1..3, columns (KI, KP, KD), raw bytes of the CAN packets.
# LOCOMOTION (incremental PID of fig. 8 on the measured servo position, Q4.4 bytes = gain x 16,
# docs/firmware.md): KI 1 (1/16 per tick), KP 0, KD 0. The PID's output *is* the servo command
# and the hobby servo already follows its command, so this outer loop acts as an integrator
# behind 3-5 ticks of measurement delay (pot sampling, filters, servo speed). Measured in the
# twin (seed 0), trunk tilt max: flexao 20 deg in 1 s: KI 1 -> 1.5 deg, KI 2 -> 1.6, KI 3 -> 9,
# KI 4 -> 14-26, KI 8 + KP 8 -> oscillates and falls; flexao 25 deg in 1 s: KI 1 -> 2.1, KI 2 ->
# 7.9 (rocks on the toes). KP and KD only add phase lag here (KI 2 + KP 2 -> 4.3 deg). Final
# error 0 deg (NO_CONTROL keeps the pot calibration error, ~1 deg); the price is a lag behind
# the cubic during the motion (~16 deg on a 40 deg knee motion in 1 s, ~8 deg in 2 s).
# BALANCE (Jacobian-transpose CoP law on foot lateral, foot front and knee) and REACTION
# (proportional CoP law on the two foot joints): the firmware reads KP as a signed byte and KD as
# the gain's binary exponent, gain = KP / 2^KD, on a CoP low-passed over 8 ticks (docs/balance.md).
# These defaults are for the leg that carries the robot alone (single support): KP 1, KD 1 on the
# three joints (BALANCE: 0.18 deg/s per mm of CoP error at the straight leg). Measured in the twin
# (levantar_perna knee 40 deg, T 1 s, BALANCE on the support leg in the hold, seeds 0-1, both
# legs): no fall, CoP margin min 1.5-10.6 mm over the whole run (the smallest in the return to
# double support), trunk tilt max 1.3-2.5 deg; with the lean cut to 13 deg the law keeps the
# one-leg stance (margin 3.4-10 mm) where the same plan without it (LOCOMOTION in the hold) tips
# the support foot onto its edge in 3 runs of 4 (tests/firmware/slave/test_balance.py). KP 2, KD 0 rocks the
# robot on the foot edges. Both legs on the same law in double support fight each other
# (docs/balance.md): a stand uses a leader/follower pair (scenarios.STAND_GAINS);
# ``--control balance|reaction`` keeps that split (scenarios.Plan.with_control): on levantar_perna
# it puts the law, with these gains, on the support leg in single support only.
GAINS: dict[ControlType, tuple[tuple[int, int, int], ...]] = {
    ControlType.NO_CONTROL: ((0, 0, 0),) * 3,
    ControlType.LOCOMOTION_CONTROL: ((1, 0, 0),) * 3,
    ControlType.REACTION_CONTROL: ((0, 1, 1), (0, 1, 1), (0, 0, 0)),
    ControlType.BALANCE_CONTROL: ((0, 1, 1),) * 3,
}

# levantar_perna: lateral lean of both legs (ankle roll, hip roll opposite) and of the upper
# torso (torso roll, SCU 5) toward the support leg before the other foot leaves the floor.
# Measured in the twin (seed 0, knee 50 deg, T 1 s): the robot's mass centre moves 2.2 mm per
# degree of leg lean (inclinar 20 -> 45 mm, 24 -> 55 mm = over the support foot's centre, hips
# 110 mm apart). In single support the support hip's roll servo carries everything above it
# (trunk, arms, head and the raised leg, ~3.6 kg) at ~75 mm: ~2.7 N.m, over the HS-805BB's
# 2.42 N.m stall, so with the legs alone the hip sags 5 deg and the robot falls sideways when the
# leg comes down. Leaning the upper torso 20 deg toward the support leg moves that load over the
# hip: legs 18 deg + torso 20 deg -> trunk tilt max 2.9 deg, CoP margin min 5 mm, no fall
# (LOCOMOTION everywhere); legs 22 + torso 0 -> falls; 15/22 -> tilt 2.2, margin 4 mm.
SHIFT_DEG = 18.0
TORSO_LEAN_DEG = 20.0
BODY = 4                  # row of SCU 5 (body): servo 1 torso roll, 2 torso pitch, 3 bench servo
TORSO_ROLL = 0
SHIFT = 0                 # levantar_perna's motion indices: the weight shift (double support)
LIFT = 1                  # ... the lift (the foot leaves the floor)
HOLD = 2                  # ... the hold (single support)
LOWER = 3                 # ... the lower (single support until the foot touches)
RETURN = 4                # ... the return to the vertical posture
REST = 5                  # ... the rest: the vertical posture again, open loop
# levantar_perna's balance (docs/balance.md 4, issue 12). Measured over seeds 0-9, perna 1 and 2
# (T 1 s, knee 40 deg; scripts/levantar_margins.py), each addition against the plan without it:
# - BALANCE on the support leg in the hold *and* the lower (the foot is still up);
# - the weight shift over SHIFT_PERIODS x T: the lift starts once the legs' PIDs have caught up
#   with the lean (in T they lag ~3 deg and the lifting foot bounces on its inner edge);
# - the foot lateral joint of the leg that comes down turns compliant (REACTION with a negative
#   gain, LANDING_GAINS: it turns the foot to bring its own CoP to the foot centre, as the stand's
#   follower does in pitch) during the lower and the return: the foot lands and stays flat
#   instead of rocking the robot onto its inner edge while the support leg hands the weight over;
# - the return over RETURN_PERIODS x T;
# - a last motion REST (T) at the vertical posture with NO_CONTROL on the leg and hip boards: the
#   servos get the plan's positions again, the PIDs' integral corrections from single support are
#   dropped, and the feet sit flat as after the boot (with LOCOMOTION there, whole-degree
#   leftovers keep the feet on their inner edges; a compliant roll left on rocks the robot
#   fore-aft).
# Smallest CoP margin over the 20 runs: 10.2 mm (all 20 >= 10 mm), against 6.8 mm (13 of 20) with
# BALANCE in hold + lower and a return over 2 T alone.
BALANCE_MOTIONS = (HOLD, LOWER)
LANDING_MOTIONS = (LOWER, RETURN)
LANDING_GAINS = ((0, -8, 2), (0, 0, 0), (0, 0, 0))     # foot lateral: KP -8, KD 2 (gain -2)
SHIFT_PERIODS = 2
RETURN_PERIODS = 3


def _period(T: Any) -> float:
    try:
        v = float(T)
    except (TypeError, ValueError):
        raise ValueError(f"T must be a duration in seconds, got {T!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"T must be a positive duration in seconds, got {T!r}")
    if round(v / TICK_S) > 255:
        raise ValueError(f"T = {v} s is longer than {MAX_PERIOD_S:.2f} s (255 ticks of 20 ms, one byte)")
    return v


def _angle(name: str, value: Any, lo: float, hi: float, why: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an angle in degrees, got {value!r}") from None
    if not math.isfinite(v) or not lo <= v <= hi:
        raise ValueError(f"{name} must be {lo:g}..{hi:g} degrees ({why}), got {value!r}")
    return v


def empty_plan(n_motions: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``pos_apply`` zeros ``(8, 3, M)``, ``k`` with NO_CONTROL and zero gains ``(8, 3, M, 4)``,
    ``t`` zeros ``(M,)``."""
    m = operator.index(n_motions)
    if m < 1:
        raise ValueError(f"a plan needs at least one motion, got {m}")
    return np.zeros((N_SCU, N_SERVOS, m)), np.zeros((N_SCU, N_SERVOS, m, 4)), np.zeros(m)


def control_row(ctype: int | ControlType, gains: Any = None) -> np.ndarray:
    """One board's ``k`` entries for one motion (table 23): 3 x 4, rows servos 1-3, columns
    ``[KI, KP, KD, control type]``. ``gains``: (KI, KP, KD) per servo (3 x 3) or one triple for
    all three; default :data:`GAINS` of ``ctype``. A negative gain (a signed KP) is stored as its
    two's complement byte; ``ValueError`` outside -128..255. The one place a k row is built."""
    ctype = ControlType(int(ctype))
    g = np.broadcast_to(np.asarray(GAINS[ctype] if gains is None else gains), (N_SERVOS, 3))
    if np.any(g < -128) or np.any(g > 255):
        raise ValueError(f"gains must be bytes (-128..255), got {g.tolist()}")
    row = np.empty((N_SERVOS, 4))
    row[:, :3] = [[s8(v) if v < 0 else v for v in r] for r in np.asarray(g, dtype=np.int64).tolist()]
    row[:, 3] = int(ctype)
    return row


def with_control(k: np.ndarray, ctype: int | ControlType, scus: tuple[int, ...] = LEG_SCUS) -> np.ndarray:
    """A copy of ``k`` (8 x 3 x M x 4) with the boards ``scus`` on control type ``ctype`` and its
    :data:`GAINS` in every motion (``humanoid-twin run --control``)."""
    out = np.array(k, dtype=float, copy=True)
    row = control_row(ctype)
    for scu in scus:
        out[scu - 1] = row[:, None, :]
    return out


def _set_k(k: np.ndarray, row: int, m: int, ctype: ControlType) -> None:
    k[row, :, m] = control_row(ctype)


def leg_pose(
    pos: np.ndarray,
    m: int,
    side: int,
    *,
    hip_roll: float = 0.0,
    hip_pitch: float = 0.0,
    knee: float = 0.0,
    ankle_pitch: float = 0.0,
    ankle_roll: float = 0.0,
) -> None:
    """Write one leg's joint angles (degrees) into ``pos[:, :, m]``; ``side`` 0 right, 1 left."""
    leg, hip = (R_LEG, R_HIP) if side == 0 else (L_LEG, L_HIP)
    pos[leg, ANKLE_ROLL, m] = ankle_roll
    pos[leg, ANKLE_PITCH, m] = ankle_pitch
    pos[leg, KNEE, m] = knee
    pos[hip, HIP_ROLL, m] = hip_roll
    pos[hip, HIP_PITCH, m] = hip_pitch
    pos[hip, HIP_YAW, m] = 0.0


def flexao(T: float, motion: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``[pos_apply, k, t] = flexao(T, motion)`` (table 22): both legs bend, in one motion of ``T`` s.

    ``motion`` = the ankle's bend (degrees, 0..45). Both legs: ankle pitch ``-motion`` (the shank
    leans forward over the flat foot), knee ``+2 motion``, hip pitch ``-motion`` (the thigh leans
    back by the same angle): the feet stay flat, the trunk upright, and the hips stay straight
    above the ankles (equal link lengths, table 13), so the mass centre does not move fore-aft.
    LOCOMOTION_CONTROL on the legs and hips.
    """
    T = _period(T)
    a = _angle("motion", motion, 0.0, 45.0, "the knee bends 2 x motion, up to 90")
    pos, k, t = empty_plan(1)
    for side in (0, 1):
        leg_pose(pos, 0, side, hip_pitch=-a, knee=2 * a, ankle_pitch=-a)
    for row in (R_LEG, L_LEG, R_HIP, L_HIP):
        _set_k(k, row, 0, ControlType.LOCOMOTION_CONTROL)
    t[0] = T
    return pos, k, t


def inclinar(T: float, motion: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``[pos_apply, k, t] = inclinar(T, motion)`` (table 22): both legs lean sideways, one motion.

    ``motion`` = the foot lateral joint's angle (degrees, -30..30): ankle roll ``+motion`` and hip
    roll ``-motion`` on both legs, so the legs stay parallel, the feet flat and the trunk upright
    while the hips move sideways by 190 mm x sin(motion). Positive: the robot leans to its left.
    LOCOMOTION_CONTROL on the legs and hips.
    """
    T = _period(T)
    a = _angle("motion", motion, -30.0, 30.0, "the roll joints' structure limit")
    pos, k, t = empty_plan(1)
    for side in (0, 1):
        leg_pose(pos, 0, side, hip_roll=-a, ankle_roll=a)
    for row in (R_LEG, L_LEG, R_HIP, L_HIP):
        _set_k(k, row, 0, ControlType.LOCOMOTION_CONTROL)
    t[0] = T
    return pos, k, t


def levantar_perna(
    T: float, motion: float, perna: Any, *, shift: float = SHIFT_DEG, torso: float = TORSO_LEAN_DEG
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``[pos_apply, k, t] = levantar_perna(T, motion, perna)`` (table 22): lift a leg until its
    knee is at ``motion`` degrees (0..90). ``perna`` 1 = right leg, 2 = left leg, any other value =
    both legs (the manual's rule).

    One leg, 6 motions (``T`` seconds each unless said):

    1. shift (:data:`SHIFT_PERIODS` x ``T``): both legs lean ``shift`` degrees toward the support
       leg (as ``inclinar``: ankle roll ``+-shift``, hip roll opposite) and the upper torso leans
       ``torso`` degrees the same way (torso roll, SCU 5 servo 1: ``-torso`` for the left support
       leg), putting the mass centre over the support foot and the upper body's load over the
       support hip;
    2. lift: the raised leg flexes: hip pitch ``-motion/2``, knee ``motion``, ankle pitch
       ``-motion/2`` (foot parallel to the floor, straight under the hip, raised by
       ``2 x 95 mm x (1 - cos(motion/2))``);
    3. hold: the same pose for another ``T``;
    4. lower: back to the shift pose;
    5. return: vertical posture, in :data:`RETURN_PERIODS` x ``T``;
    6. rest: the vertical posture, open loop (NO_CONTROL on SCUs 1-4).

    (A period is at most 5.1 s, one byte of 20 ms ticks.) Control: LOCOMOTION_CONTROL on SCUs 1-5,
    except the support leg's board (foot lateral, foot front, knee), which runs BALANCE_CONTROL
    during the hold and the lower (single support: the other foot is up, so the support foot's
    CoP is the robot's), the foot lateral joint of the lifted leg, which complies with the floor
    during the lower and the return (REACTION_CONTROL, :data:`LANDING_GAINS`), and the rest
    (NO_CONTROL on the legs and hips). docs/balance.md section 4 has the measurements.

    Both legs: 3 motions (both legs flex as in step 2, hold, return), LOCOMOTION_CONTROL on the
    legs and hips.
    """
    T = _period(T)
    a = _angle("motion", motion, 0.0, 90.0, "the knee's range")
    s = _angle("shift", shift, 0.0, 30.0, "the roll joints' structure limit")
    tr = _angle("torso", torso, 0.0, 30.0, "the torso roll's structure limit")
    flex = {"hip_pitch": -a / 2, "knee": a, "ankle_pitch": -a / 2}
    if perna in (1, 2) and not isinstance(perna, bool):
        return _lift_one_leg(0 if perna == 1 else 1, T, flex, s, tr)     # side index: 0 right, 1 left
    return _flex_both_legs(T, flex)


def _lift_one_leg(lifted: int, T: float, flex: dict[str, float], s: float, tr: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``levantar_perna``'s 6 motions lifting leg ``lifted`` (0 right, 1 left): the poses (the
    shift ``s`` and torso lean ``tr`` toward the support leg, the lifted leg flexed by ``flex``),
    the control types, the periods."""
    pos, k, t = empty_plan(6)
    sign = 1.0 if lifted == 0 else -1.0      # + = toward the left leg
    for m in (SHIFT, LIFT, HOLD, LOWER):
        for side in (0, 1):
            extra = flex if (side == lifted and m in (LIFT, HOLD)) else {}
            leg_pose(pos, m, side, hip_roll=-sign * s, ankle_roll=sign * s, **extra)
        pos[BODY, TORSO_ROLL, m] = -sign * tr   # roll about +x: negative leans the top left
    _lift_controls(k, lifted)
    t[:] = T
    t[SHIFT] = min(SHIFT_PERIODS * T, MAX_PERIOD_S)
    t[RETURN] = min(RETURN_PERIODS * T, MAX_PERIOD_S)
    return pos, k, t


def _lift_controls(k: np.ndarray, lifted: int) -> None:
    """The control types of the 6 motions lifting leg ``lifted``: LOCOMOTION_CONTROL, BALANCE_CONTROL
    on the support leg's board while the other foot is up, NO_CONTROL on the legs and hips at rest,
    REACTION_CONTROL on the lifted foot's lateral joint as it lands."""
    support_row = L_LEG if lifted == 0 else R_LEG
    lifted_row = R_LEG if lifted == 0 else L_LEG
    for m in range(6):
        for row in (R_LEG, L_LEG, R_HIP, L_HIP, BODY):
            ctype = ControlType.LOCOMOTION_CONTROL
            if row == support_row and m in BALANCE_MOTIONS:
                ctype = ControlType.BALANCE_CONTROL
            elif m == REST and row != BODY:
                ctype = ControlType.NO_CONTROL
            _set_k(k, row, m, ctype)
    landing = control_row(ControlType.REACTION_CONTROL, LANDING_GAINS)[ANKLE_ROLL]
    for m in LANDING_MOTIONS:
        k[lifted_row, ANKLE_ROLL, m] = landing


def _flex_both_legs(T: float, flex: dict[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``levantar_perna`` of both legs: 3 motions (flex, hold, return), LOCOMOTION_CONTROL."""
    pos, k, t = empty_plan(3)
    for side in (0, 1):
        for m in (0, 1):
            leg_pose(pos, m, side, **flex)
    for m in range(3):
        for row in (R_LEG, L_LEG, R_HIP, L_HIP):
            _set_k(k, row, m, ControlType.LOCOMOTION_CONTROL)
    t[:] = T
    return pos, k, t
