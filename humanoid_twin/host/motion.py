"""Execution of coordinated motions (seed 000 tables 24-26): ``exe_traj``, ``recycle``,
``controller``, ``controller_off``, and ``power_on`` (PWM on + the Slaves' calibration).

Every routine speaks only through the drivers (:mod:`humanoid_twin.host.drivers`) and measures
and waits time through :mod:`humanoid_twin.host.timebase`, so it runs unchanged on a real port,
a pty, a TCP socket or the in-process ``twin://`` port. A request that still fails after its
retries raises a :class:`~humanoid_twin.host.drivers.CommError` subclass; a sensor read that
fails while sampling leaves NaN in its place (and a ``RuntimeWarning`` says how many).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from humanoid_twin.hardware import N_SERVOS
from humanoid_twin.host import timebase
from humanoid_twin.host.drivers import (
    STATUS_CALIB,
    STATUS_PWM,
    ErrorCode,
    Timeout,
    applycontrol,
    applyjoint,
    raise_for_error,
    readjoint,
)
from humanoid_twin.host.planners import GAINS, LEG_SCUS, MAX_PERIOD_S, TICK_S, control_row
from humanoid_twin.host.tables import RobotTables, adaptate, correct, default_tables, limit
from humanoid_twin.protocol.rs232 import (
    PARAM_CONTROLON,
    PARAM_CURRENT,
    PARAM_KD,
    PARAM_KI,
    PARAM_KP,
    PARAM_POSITION,
    PARAM_SPECIAL,
    PARAM_VELOCITY,
)
from humanoid_twin.protocol.wire import N_SCU, SCUS, ControlType, check_scu, int_in_range

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort

__all__ = [
    "ALL_SCUS",
    "TrajData",
    "exe_traj",
    "servo_command",
    "recycle",
    "controller",
    "controller_off",
    "power_on",
    "period_ticks",
    "send_gains",
    "apply_joint",
]

ALL_SCUS: tuple[int, ...] = SCUS


class TrajData(NamedTuple):
    """``[tt, position, velocity, current] = exe_traj(...)`` (table 25).

    ``tt``: (TIME,) seconds from the start of ``exe_traj``; ``position``, ``velocity``,
    ``current``: (N_TEST, N_SERVOS, TIME) for the SCUs driven, in the order of ``scus``.
    Positions: measured servo angles (degrees, servo frame); velocities: degrees per second
    (the Slave's mean velocity, degrees per 20 ms tick, x 50); currents: 0..100. NaN where a read
    failed.
    """

    tt: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    current: np.ndarray


def _scus(scus: Iterable[int]) -> tuple[int, ...]:
    out = []
    for s in scus:
        out.append(check_scu(s, "SCU addresses"))
    if not out:
        raise ValueError("no SCU to drive")
    if len(set(out)) != len(out):
        raise ValueError(f"SCU addresses repeat: {out}")
    return tuple(out)


def period_ticks(seconds: float) -> int:
    """A movement period in seconds as 20 ms ticks (the APPLY_JOINT VELOCITY byte), 0..255."""
    try:
        s = float(seconds)
    except (TypeError, ValueError):
        raise ValueError(f"a period must be a number of seconds, got {seconds!r}") from None
    if not math.isfinite(s) or s < 0:
        raise ValueError(f"a period must be >= 0 s, got {seconds!r}")
    ticks = round(s / TICK_S)
    if ticks > 255:
        raise ValueError(f"period {s} s = {ticks} ticks: at most 255 ({MAX_PERIOD_S:.2f} s) fit the byte")
    return ticks


def servo_command(scu: int, leg_angles: Any, tables: RobotTables | None = None) -> list[int]:
    """Leg angles of one SCU -> the whole servo degrees sent: ``limit(correct(adaptate(..)))``,
    rounded (seed 000 table 26, the chain ``exe_traj`` applies)."""
    t = tables or default_tables()
    servo = limit(scu, correct(scu, adaptate(scu, leg_angles, t), t), t)
    return [int(v) for v in np.rint(servo)]


def apply_joint(H: HostPort, scu: int, param: int, data: Sequence[int], what: str) -> None:
    """``applyjoint(H, scu_id, param, servos)`` (seed 000 table 20) that raises instead of
    returning an error code: a request that still fails after its retries raises the
    :class:`~humanoid_twin.host.drivers.CommError` subclass of its error, its message starting
    ``"<what> (SCU <scu>)"``. The motion and trajectory routines move the servos through it."""
    raise_for_error(applyjoint(H, scu, param, data), f"{what} (SCU {scu})", H)


def _control(H: HostPort, scu: int, param: int, data: Sequence[int], what: str) -> None:
    raise_for_error(applycontrol(H, scu, param, data), f"{what} (SCU {scu})", H)


def send_gains(H: HostPort, scu: int, k_scu: Any) -> None:
    """``applycontrol`` KI, KP, KD and CONTROLON for one SCU from ``k_scu`` (3 x 4: rows
    servos, columns KI KP KD control type)."""
    arr = np.asarray(k_scu)
    if arr.shape != (N_SERVOS, 4):
        raise ValueError(f"gains of one SCU must be 3 x 4 (KI KP KD type per servo), got {arr.shape}")
    for col, param, what in ((0, PARAM_KI, "KI"), (1, PARAM_KP, "KP"), (2, PARAM_KD, "KD"),
                             (3, PARAM_CONTROLON, "control type")):
        _control(H, scu, param, [int(v) for v in arr[:, col]], f"set {what}")


class _Sampler:
    """Reads position, velocity and current of the SCUs driven, into growing lists."""

    def __init__(self, H: HostPort, scus: tuple[int, ...]) -> None:
        self.H = H
        self.scus = scus
        self.tt: list[float] = []
        self.rows: list[np.ndarray] = []
        self.failed = 0

    def sample(self, t0: float) -> None:
        H = self.H
        row = np.full((3, len(self.scus), N_SERVOS), np.nan)
        self.tt.append(timebase.now(H) - t0)
        for j, scu in enumerate(self.scus):
            for q, param in enumerate((PARAM_POSITION, PARAM_VELOCITY, PARAM_CURRENT)):
                r = readjoint(H, scu, param)
                if r.error == ErrorCode.OK:
                    row[q, j] = r.servos
                else:
                    self.failed += 1
        self.rows.append(row)

    def run_until(self, t_end: float, t0: float, dt: float) -> None:
        """Sample until ``t_end`` (time base), a sweep starting ``dt`` s after the previous one's
        start (back to back when a sweep takes longer, or ``dt`` = 0)."""
        H = self.H
        while True:
            now = timebase.now(H)
            if now >= t_end:
                return
            if dt > 0 and self.tt:
                wait = min(t0 + self.tt[-1] + dt, t_end) - now
                if wait > 0:
                    timebase.sleep(H, wait)
                    if timebase.now(H) >= t_end:
                        return
            self.sample(t0)

    def result(self) -> TrajData:
        if self.failed:
            warnings.warn(f"exe_traj: {self.failed} sensor reads failed (NaN in the result)",
                          RuntimeWarning, stacklevel=3)
        n = len(self.tt)
        if n == 0:
            empty = np.zeros((len(self.scus), N_SERVOS, 0))
            return TrajData(np.zeros(0), empty, empty.copy(), empty.copy())
        data = np.stack(self.rows, axis=-1)           # (3, N_TEST, N_SERVOS, TIME)
        return TrajData(np.asarray(self.tt), data[0], data[1] / TICK_S, data[2])


def exe_traj(
    H: HostPort,
    t: Any,
    pos_apply: Any,
    Textra: float,
    k: Any = None,
    *,
    scus: Iterable[int] | None = None,
    dt: float = TICK_S,
    tables: RobotTables | None = None,
) -> TrajData:
    """``[tt, position, velocity, current] = exe_traj(H, t, pos_apply, Textra)`` (tables 24-25).

    For each motion ``m``: send the gains and control types ``k[:, :, m, :]`` (``applycontrol``
    KI, KP, KD, CONTROLON; only when they changed since the last motion; ``k=None`` sends none),
    the period ``t[m]`` (``applyjoint`` VELOCITY, ``round(t[m] / 0.02)`` ticks), the positions
    ``limit(correct(adaptate(pos_apply[:, :, m])))`` (``applyjoint`` POSITION), then sample the
    position, velocity and current of every SCU in ``scus`` every ``dt`` seconds (0 = as fast as
    the link allows) until ``t[m]`` seconds have passed on the time base since the motion was
    sent (``t[m] + Textra`` for the last motion).

    ``scus`` (the N_TEST units): by default the SCUs in use, the legs and hips (1-4) plus any
    other board the plan moves or sets gains for (e.g. SCU 5's torso roll in
    ``levantar_perna``), in address order.
    """
    tt_in, pos, kk = _check_plan(t, pos_apply, k)
    n_m = tt_in.shape[0]
    scus_t = _scus(_driven(pos, kk) if scus is None else scus)
    if np.any(~np.isfinite(pos[[s - 1 for s in scus_t]])):
        raise ValueError("pos_apply has non-finite values for the SCUs driven")
    ticks, textra = _check_times(tt_in, Textra, dt)
    tab = tables or default_tables()
    commands = [[servo_command(s, pos[s - 1, :, m], tab) for s in scus_t] for m in range(n_m)]

    sampler = _Sampler(H, scus_t)
    t0 = timebase.now(H)
    sent = _Sent()
    for m in range(n_m):
        if kk is not None:
            sent.gains(H, scus_t, kk[:, :, m, :])
        sent.period(H, scus_t, ticks[m])
        t_start = timebase.now(H)
        for j, s in enumerate(scus_t):
            apply_joint(H, s, PARAM_POSITION, commands[m][j], "set positions")
        t_end = t_start + tt_in[m] + (textra if m == n_m - 1 else 0.0)
        sampler.run_until(t_end, t0, dt)
    return sampler.result()


def _check_plan(t: Any, pos_apply: Any, k: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """``exe_traj``'s plan as arrays, their shapes checked: the motions' durations, the positions
    (N_SCU x N_SERVOS x N_MOTIONS; one motion's N_SCU x N_SERVOS too), the gains (or None)."""
    tt_in = np.atleast_1d(np.asarray(t, dtype=float))
    if tt_in.ndim != 1:
        raise ValueError(f"t must be a vector of motion durations, got shape {tt_in.shape}")
    n_m = tt_in.shape[0]
    pos = np.asarray(pos_apply, dtype=float)
    if pos.ndim == 2:
        pos = pos[:, :, None]
    if pos.shape != (N_SCU, N_SERVOS, n_m):
        raise ValueError(
            f"pos_apply must be {N_SCU} x {N_SERVOS} x N_MOTIONS with N_MOTIONS = len(t) = {n_m}, "
            f"got shape {pos.shape}"
        )
    kk = None
    if k is not None:
        kk = np.asarray(k)
        if kk.shape != (N_SCU, N_SERVOS, n_m, 4):
            raise ValueError(f"k must be {N_SCU} x {N_SERVOS} x {n_m} x 4, got shape {kk.shape}")
    return tt_in, pos, kk


def _check_times(tt_in: np.ndarray, Textra: Any, dt: float) -> tuple[list[int], float]:
    """Each motion's period in ticks of 20 ms (a positive duration that fits the byte), ``Textra``
    and ``dt`` (>= 0 s); returns the periods and ``Textra``."""
    ticks = [period_ticks(v) for v in tt_in]
    if any(v <= 0 for v in tt_in):
        raise ValueError(f"every motion needs a positive duration, got t = {tt_in.tolist()}")
    textra = float(Textra)
    if not math.isfinite(textra) or textra < 0:
        raise ValueError(f"Textra must be >= 0 s, got {Textra!r}")
    if not (math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be >= 0 s, got {dt!r}")
    return ticks, textra


def _driven(pos: np.ndarray, kk: np.ndarray | None) -> list[int]:
    """The SCUs in use: the legs and hips, and every other board the plan moves or sets gains for."""
    used = {s for s in SCUS if np.any(pos[s - 1] != 0)}
    if kk is not None:
        used |= {s for s in SCUS if np.any(kk[s - 1] != 0)}
    return sorted(used | set(LEG_SCUS))


class _Sent:
    """What ``exe_traj`` last sent each SCU (its gains, its period): sent again only when changed."""

    def __init__(self) -> None:
        self.k: dict[int, np.ndarray] = {}
        self.ticks: dict[int, int] = {}

    def gains(self, H: Any, scus: Sequence[int], k_m: np.ndarray) -> None:
        """One motion's gains and control types (N_SCU x N_SERVOS x 4) to each of ``scus``."""
        for s in scus:
            ks = k_m[s - 1]
            if s not in self.k or not np.array_equal(self.k[s], ks):
                send_gains(H, s, ks)
                self.k[s] = ks

    def period(self, H: Any, scus: Sequence[int], ticks: int) -> None:
        """One motion's period (ticks of 20 ms) to each of ``scus``."""
        for s in scus:
            if self.ticks.get(s) != ticks:
                apply_joint(H, s, PARAM_VELOCITY, [ticks] * 3, "set period")
                self.ticks[s] = ticks


def recycle(
    H: HostPort,
    speed: int,
    correct_flag: bool,
    *,
    scus: Iterable[int] = LEG_SCUS,
    wait: bool = True,
    tables: RobotTables | None = None,
) -> list[list[int]]:
    """``recycle(H, speed, correct_flag)`` (table 24): bring the leg joints back to the vertical
    posture in ``speed`` ticks of 20 ms (0 = at once), with the ``calib`` correction when
    ``correct_flag`` is set, then (``wait=True``) wait ``speed`` ticks on the time base.

    Returns the servo positions sent, per SCU in ``scus`` order.
    """
    scus_t = _scus(scus)
    sp = int_in_range("speed", speed, 0, 255, "ticks of 20 ms")
    tab = tables or default_tables()
    sent = []
    for s in scus_t:
        servo = adaptate(s, np.zeros(N_SERVOS), tab)
        if correct_flag:
            servo = correct(s, servo, tab)
        sent.append([int(v) for v in np.rint(limit(s, servo, tab))])
    for s in scus_t:
        apply_joint(H, s, PARAM_VELOCITY, [sp] * 3, "recycle period")
    for s, cmd in zip(scus_t, sent, strict=True):
        apply_joint(H, s, PARAM_POSITION, cmd, "recycle positions")
    if wait and sp:
        timebase.sleep(H, sp * TICK_S)
    return sent


def _gains_array(k: Any, n_scus: int) -> np.ndarray:
    """KI KP KD as (n_scus, 3 servos, 3) from a triple, a 3 x 3 (per servo) or an 8 x 3 x 3."""
    arr = np.asarray(k)
    if arr.shape == (3,):
        arr = np.broadcast_to(arr, (N_SERVOS, 3))
    if arr.shape == (N_SERVOS, 3):
        return np.broadcast_to(arr, (n_scus, N_SERVOS, 3))
    if arr.shape == (N_SCU, N_SERVOS, 3):
        return arr
    raise ValueError(f"k must be (KI, KP, KD), 3 x 3 per servo or 8 x 3 x 3 per SCU, got shape {arr.shape}")


def controller(
    H: HostPort,
    k: Any = None,
    control: int | ControlType = ControlType.LOCOMOTION_CONTROL,
    *,
    scus: Iterable[int] = LEG_SCUS,
) -> None:
    """``controller`` (table 26): set the PID gains and switch the controllers on, on every SCU in
    ``scus``. ``k``: (KI, KP, KD) for all servos, 3 x 3 per servo, or 8 x 3 x 3 per SCU (row
    ``scu - 1``); default :data:`~humanoid_twin.host.planners.GAINS` of ``control``."""
    scus_t = _scus(scus)
    ctype = ControlType(int(control))
    per_scu = k is not None and np.asarray(k).shape == (N_SCU, N_SERVOS, 3)
    gains = _gains_array(GAINS[ctype] if k is None else k, N_SCU if per_scu else len(scus_t))
    for j, s in enumerate(scus_t):
        g = gains[s - 1] if per_scu else gains[j]
        send_gains(H, s, control_row(ctype, g))


def controller_off(H: HostPort, *, scus: Iterable[int] = ALL_SCUS) -> None:
    """``controller_off`` (table 26): NO_CONTROL (open loop) on every servo of ``scus``."""
    for s in _scus(scus):
        _control(H, s, PARAM_CONTROLON, [0, 0, 0], "controller off")


def power_on(
    H: HostPort,
    scus: Iterable[int] = ALL_SCUS,
    *,
    calibrate: bool = False,
    wait: bool = True,
    timeout: float = 5.0,
    poll: float = 0.1,
    tables: RobotTables | None = None,
) -> dict[int, int]:
    """Switch the servos' PWM on (``applyjoint`` SPECIAL ``[1, calibrate, 0]``), after sending the
    vertical posture (period 0) as the first actuation, which the Slave's ``calibration`` moves to
    and measures (seed 000 SERVO; a Slave keeps its PWM off until this). With ``wait``, poll
    every ``poll`` s until each Slave reports PWM on and calibration done (status bits 7 and 6),
    raising :class:`~humanoid_twin.host.drivers.Timeout` after ``timeout`` s.

    Returns the last status byte of each SCU.
    """
    scus_t = _scus(scus)
    tab = tables or default_tables()
    for s in scus_t:
        apply_joint(H, s, PARAM_VELOCITY, [0, 0, 0], "power on period")
        apply_joint(H, s, PARAM_POSITION, servo_command(s, np.zeros(N_SERVOS), tab), "power on positions")
        apply_joint(H, s, PARAM_SPECIAL, [1, int(bool(calibrate)), 0], "PWM on")
    status = {s: 0 for s in scus_t}
    if not wait:
        return status
    want = STATUS_PWM | STATUS_CALIB
    t_end = timebase.now(H) + timeout
    pending = set(scus_t)
    # A recalibration is done only once the Slave has been seen *not* calibrated since the
    # request (its first answers still carry the old "calibrated" bit, docs/master.md).
    seen_running: set[int] = set() if calibrate else set(scus_t)
    while True:
        for s in sorted(pending):
            r = readjoint(H, s, PARAM_POSITION)
            if r.error != ErrorCode.OK:
                continue
            status[s] = r.state  # type: ignore[assignment]  # an answer's state (error OK)
            if not r.state & STATUS_CALIB:  # type: ignore[operator]  # as above
                seen_running.add(s)
            elif r.state & want == want and s in seen_running:  # type: ignore[operator]  # as above
                pending.discard(s)
        if not pending:
            return status
        if timebase.now(H) >= t_end:
            late = sorted(pending)
            raise Timeout(
                f"power_on: SCUs {late} did not report PWM on + calibrated within {timeout} s "
                f"(status {[hex(status[s]) for s in late]})",
                ErrorCode.TIMEOUT,
            )
        timebase.sleep(H, poll)
