"""Trajectory sampling of one control unit (seed 000 table 21): ``predict_trajectory``,
``sample_traj``, ``sample_traj3``.

The ideal trajectory is the Slave's (module TRAJECTORY): a cubic from ``pos0`` to ``posF`` with
zero velocity at both ends, ``theta(tau) = pos0 + (posF - pos0) (3 tau^2 - 2 tau^3)``,
``tau = t / T``, then ``posF``.

``sample_traj``/``sample_traj3`` work on servo angles directly (degrees on the wire, no
``adaptate``): they are bench tools for one board's servos.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from humanoid_twin.hardware import N_SERVOS
from humanoid_twin.host import timebase
from humanoid_twin.host.drivers import ErrorCode, raise_for_error, readjoint
from humanoid_twin.host.motion import apply_joint, period_ticks, send_gains
from humanoid_twin.host.planners import TICK_S, control_row
from humanoid_twin.protocol.rs232 import PARAM_CURRENT, PARAM_POSITION, PARAM_VELOCITY
from humanoid_twin.protocol.wire import ControlType, check_scu, int_in_range

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort

__all__ = [
    "TEST_SCU",
    "predict_trajectory",
    "cubic",
    "sample_traj",
    "sample_traj3",
    "SAMPLE_TRAJ_COLUMNS",
    "SAMPLE_TRAJ3_COLUMNS",
]

# The "slave unit under test" that the MATLAB routines fixed inside the script: SCU 6 (right
# arm), whose servos move without disturbing the stance. Pass ``scu=`` for another board.
TEST_SCU = 6

SAMPLE_TRAJ_COLUMNS = ("time", "position", "velocity", "current", "posT", "velT")
SAMPLE_TRAJ3_COLUMNS = ("time",) + tuple(
    f"{name}{i}" for name in ("position", "posT", "velocity", "velT", "current") for i in (1, 2, 3)
)


def cubic(t: Any, T: float, pos0: Any, posF: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration at times ``t`` of the cubic from ``pos0`` (t = 0) to
    ``posF`` (t = ``T``) with zero end velocities, ``posF`` after ``T``. Units: degrees and
    ``t``'s unit. ``t`` (n,), ``pos0``/``posF`` scalars or (k,) -> arrays (n,) or (n, k)."""
    tt = np.asarray(t, dtype=float)
    p0 = np.asarray(pos0, dtype=float)
    d = np.asarray(posF, dtype=float) - p0
    tau = np.clip(tt / T, 0.0, 1.0)
    moving = (tt >= 0) & (tt <= T)
    if p0.ndim:
        tau = tau[:, None]
        moving = moving[:, None]
    pos = p0 + d * (3 * tau**2 - 2 * tau**3)
    vel = np.where(moving, d * (6 * tau - 6 * tau**2) / T, 0.0)
    acc = np.where(moving, d * (6 - 12 * tau) / T**2, 0.0)
    return pos, vel, acc


def predict_trajectory(
    pos0: Any, posF: Any, n_samples: int, ratio: float, *, dt: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``[posT, velT, accT] = predict_trajectory(pos0, posF, n_samples, ratio)`` (table 21).

    ``n_samples`` samples, ``dt`` apart; the motion takes the first fraction ``ratio`` (0..1] of
    the sampled interval, ``T = ratio (n_samples - 1) dt``, and holds ``posF`` after it. So
    ``posT[0] = pos0``, ``velT[0] = 0``, and when ``ratio = 1``, ``posT[-1] = posF`` and
    ``velT[-1] = 0``. Velocities per ``dt`` unit (per sample by default; pass ``dt=0.02`` for
    degrees per second at the 20 ms tick). ``pos0``/``posF`` scalars or vectors (one column per
    servo).
    """
    n = int_in_range("n_samples", n_samples, 2, None, "samples")
    r = float(ratio)
    if not (math.isfinite(r) and 0 < r <= 1):
        raise ValueError(f"ratio must be in (0, 1], got {ratio!r}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be > 0, got {dt!r}")
    p0 = np.asarray(pos0, dtype=float)
    pF = np.asarray(posF, dtype=float)
    if p0.shape != pF.shape or p0.ndim > 1:
        raise ValueError(f"pos0 and posF must be scalars or equal-length vectors, got {p0.shape}, {pF.shape}")
    t = np.arange(n) * dt
    T = r * (n - 1) * dt
    return cubic(t, T, p0, pF)


def _three(name: str, v: Any) -> np.ndarray:
    arr = np.asarray(v, dtype=float)
    if arr.shape != (N_SERVOS,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite servo angles [servo1, servo2, servo3], got {v!r}")
    return arr


def sample_traj3(
    H: HostPort,
    T: float,
    pos0: Any,
    posF: Any,
    k: Any,
    *,
    scu: int = TEST_SCU,
    Textra: float = 0.5,
    settle: float = 1.0,
    dt: float = TICK_S,
    control: int | ControlType = ControlType.LOCOMOTION_CONTROL,
) -> np.ndarray:
    """``array = sample_traj3(H, T, pos0, posF, k)`` (table 21): move the 3 servos of ``scu`` from
    ``pos0`` to ``posF`` (servo degrees) in ``T`` s and sample them.

    ``k``: 3 x 3, rows servos 1..3, columns KI, KP, KD (bytes); ``control`` the control type
    (LOCOMOTION_CONTROL). First the servos go to ``pos0`` over ``settle`` s and wait there
    ``settle`` s; then ``posF`` is sent with period ``T`` and the servos are sampled every ``dt``
    s for ``T + Textra`` s.

    Returns ``array`` (TIME x 16), columns ``[time position(3) posT(3) velocity(3) velT(3)
    current(3)]`` (:data:`SAMPLE_TRAJ3_COLUMNS`): time in s from the start of the motion,
    positions in degrees, velocities in degrees per second, currents 0..100; ``posT``/``velT``
    the ideal cubic at the sample times.
    """
    s = check_scu(scu, "scu")
    p0 = _three("pos0", pos0)
    pF = _three("posF", posF)
    gains = np.asarray(k, dtype=float)
    if gains.shape != (N_SERVOS, 3):
        raise ValueError(f"k must be 3 x 3 (rows servos, columns KI KP KD), got shape {gains.shape}")
    ticks = period_ticks(T)
    if ticks == 0:
        raise ValueError(f"T must be at least one 20 ms tick, got {T!r}")
    T = ticks * TICK_S
    settle_ticks = period_ticks(settle)
    if not (math.isfinite(Textra) and Textra >= 0):
        raise ValueError(f"Textra must be >= 0 s, got {Textra!r}")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be > 0 s, got {dt!r}")
    send_gains(H, s, control_row(control, gains))
    # to pos0 and rest there
    apply_joint(H, s, PARAM_VELOCITY, [settle_ticks] * 3, "sample_traj period")
    apply_joint(H, s, PARAM_POSITION, [int(v) for v in np.rint(p0)], "sample_traj pos0")
    timebase.sleep(H, 2 * settle_ticks * TICK_S)
    # the motion
    apply_joint(H, s, PARAM_VELOCITY, [ticks] * 3, "sample_traj period")
    t0 = timebase.now(H)
    apply_joint(H, s, PARAM_POSITION, [int(v) for v in np.rint(pF)], "sample_traj posF")
    rows: list[list[float]] = []
    t_end = t0 + T + Textra
    i = 0
    while timebase.now(H) < t_end:
        ts = timebase.now(H) - t0
        vals = []
        for param in (PARAM_POSITION, PARAM_VELOCITY, PARAM_CURRENT):
            r = readjoint(H, s, param)
            vals.append(list(r.servos) if r.error == ErrorCode.OK else [math.nan] * 3)  # type: ignore[arg-type]  # answered (error OK)
        rows.append([ts, *vals[0], *vals[1], *vals[2]])
        i += 1
        wait = min(t0 + i * dt, t_end) - timebase.now(H)
        if wait > 0:
            timebase.sleep(H, wait)
    data = np.asarray(rows, dtype=float).reshape(-1, 10)
    tt = data[:, 0]
    posT, velT, _ = cubic(tt, T, np.rint(p0), np.rint(pF))
    return np.column_stack([tt, data[:, 1:4], posT, data[:, 4:7] / TICK_S, velT, data[:, 7:10]])


def sample_traj(
    H: HostPort,
    T: float,
    pos0: float,
    posF: float,
    k: Any,
    *,
    scu: int = TEST_SCU,
    Textra: float = 0.5,
    settle: float = 1.0,
    dt: float = TICK_S,
    control: int | ControlType = ControlType.LOCOMOTION_CONTROL,
) -> np.ndarray:
    """``array = sample_traj(H, T, pos0, posF, k)`` (table 21): as :func:`sample_traj3` for the
    first servo of ``scu`` only (``k = [KI, KP, KD]``); servos 2 and 3 hold the positions they
    have when it starts.

    Returns ``array`` (TIME x 6), columns ``[time position velocity current posT velT]``
    (:data:`SAMPLE_TRAJ_COLUMNS`, the manual's order).
    """
    s = check_scu(scu, "scu")
    kk = np.asarray(k, dtype=float)
    if kk.shape != (3,):
        raise ValueError(f"k must be [KI, KP, KD], got {k!r}")
    r = readjoint(H, s, PARAM_POSITION)
    raise_for_error(r, f"sample_traj: read positions (SCU {s})")
    hold = np.asarray(r.servos[1:], dtype=float)  # type: ignore[index]  # raise_for_error above
    p0 = np.concatenate([[float(pos0)], hold])
    pF = np.concatenate([[float(posF)], hold])
    arr3 = sample_traj3(H, T, p0, pF, np.tile(kk, (N_SERVOS, 1)), scu=s, Textra=Textra, settle=settle, dt=dt,
                        control=control)
    # arr3 columns: 0 time, 1-3 position, 4-6 posT, 7-9 velocity, 10-12 velT, 13-15 current
    return arr3[:, [0, 1, 7, 13, 4, 10]]
