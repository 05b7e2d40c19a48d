"""``humanoid-twin calibrate``: fit the twin's named parameters to robot CAN logs.

The residual is ``compare``'s (humanoid_twin/compare/core.py): for every value of every Sensors
frame of every training log, (twin - log) divided by the signal's quantum (1 degree, one count),
over the chosen signal groups; its length is fixed by the logs (a frame the twin did not send
holds the twin's last value). The fit is a bounded least-squares problem on it, solved with
MuJoCo's system-identification toolbox (``mujoco.sysid``: its ``Parameter``/``ParameterDict``
hold the unknowns and their bounds, ``optimize`` runs MuJoCo's bounded Levenberg-Marquardt
``mujoco.minimize.least_squares``, ``calculate_intervals`` gives the 95 % intervals from the
Jacobian). Where ``mujoco.sysid`` would roll the MuJoCo model out itself, the twin's rollout is
used instead: firmware, buses and plant, one :func:`~humanoid_twin.compare.core.compare_log` per
log and evaluation (in-process, no interpreter start), and the Jacobian's finite differences
are evaluated in parallel (local processes, or Ray with ``--backend ray``), with steps of a few
percent of each parameter (the measurements are whole degrees and counts: an infinitesimal step
changes nothing). docs/calibration.md says where and why.

A parameter the logs do not determine (its 95 % interval, widened for the averaged residuals'
correlation, wider than +-25 % of its value or than half its bounds; its Jacobian column near
zero; its value not the bottom of a valley of the residual, one and two steps either side; the
floor's friction from logs in which no foot slides) is ``identifiable: false``: its
value stays where the fit started, it is not written to ``--out``, and the output names the
motion that would determine it.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from humanoid_twin.compare.core import CompareOptions, CompareResult, compare_log
from humanoid_twin.compare.fitparams import Unknown
from humanoid_twin.compare.robot_log import RobotLog
from humanoid_twin.compare.signals import GROUPS, SIGNALS

__all__ = ["FitProblem", "FitResult", "fit", "motion_for", "shown", "DEFAULT_GROUPS", "REL_STEP",
           "BOUND_STEP", "ZERO_COLUMN", "REL_CI", "VALLEY_RISE"]

DEFAULT_GROUPS: tuple[str, ...] = ("position_deg", "current", "force_counts", "imu_counts")
REL_STEP = 0.1           # finite-difference step: 10 % of the value ...
BOUND_STEP = 0.005       # ... and at least 0.5 % of the parameter's range
MU_FACTOR = 10.0         # the LM regulariser's growth after a step that did not reduce the residual
ZERO_COLUMN = 1e-9       # a Jacobian column below this norm (quanta per unit) determines nothing
REL_CI = 0.25            # a 95 % interval wider than +-25 % of the value determines nothing
VALLEY_RISE = 1.1        # the residual 1 and 2 steps either side of the value: at least 10 % above it

# the motion that determines a kind of parameter (Param.kind of humanoid_twin/params.py)
MOTIONS: dict[str, str] = {
    "servo": "steps and chirps of that joint under load (the excite scenario: run excite)",
    "pot": "a pose measured by another reference: the boards' calibration takes a potentiometer's "
           "offset into b (seed 000 calibration), so only a joint moved with PWM off or against a stop "
           "shows it",
    "fsr": "the weight shifted onto that foot and off it (excite's weight shift, inclinar)",
    "floor": "a motion in which a foot slips (the platform tilted past the friction cone: "
             "run stand --tilt 30)",
    "body": "motions that load the joints below that body (flexao, excite's weight shift, levantar_perna)",
    "imu": "the trunk held still at known angles (run stand, or excite's weight shift)",
    "pic_mhz": "a control law whose cycles come close to the 2 ms PWM window (docs/firmware.md)",
}


def motion_for(name: str) -> str:
    """The kind of motion that determines parameter ``name``."""
    head = name.split(".", 1)[0]
    return MOTIONS.get(head, "a motion in which this parameter changes the measured signals")


def shown(name: str, slip_mm: float) -> bool:
    """Whether the training logs show what parameter ``name`` acts through: the floor's friction
    acts on the robot's signals through a foot that slides (``slip_mm``: the largest slide of
    the twin's feet over the training logs at the fitted values, at least ``SLIP_HELD_MM``, a
    run's "slid"); without a slide, the twin's friction still moves its pads' forces (MuJoCo's
    pyramidal friction cone) and would stand in for another parameter's error
    (docs/calibration.md, "Identifiable")."""
    from humanoid_twin.summary import SLIP_HELD_MM

    if name.split(".", 1)[0] == "floor":
        return slip_mm >= SLIP_HELD_MM
    return True


# -- one evaluation: the twin against every log ----------------------------------------------------
@dataclass
class FitProblem:
    """What an evaluation needs: the logs, the unknowns, the fixed values, the twin's options."""

    logs: list[RobotLog]
    unknowns: list[Unknown]
    base: dict[str, float] = field(default_factory=dict)
    seed: int = 0
    support: str = "floor"
    groups: tuple[str, ...] = DEFAULT_GROUPS
    window: int = 1          # frames each signal's residual is averaged over (--smooth)
    phases: str = "log"      # the Slaves' phases (CompareOptions.phases)

    def values(self, x: Sequence[float] | np.ndarray) -> dict[str, float]:
        """The parameters of point ``x``: the fixed ones, then each unknown's names."""
        out = dict(self.base)
        for u, v in zip(self.unknowns, x, strict=True):
            for name in u.names:
                out[name] = float(v)
        return out

    def run(self, x: Sequence[float] | np.ndarray,
            logs: Sequence[RobotLog] | None = None) -> list[CompareResult]:
        opts = CompareOptions(seed=self.seed, support=self.support, params=self.values(x), phases=self.phases)
        return [compare_log(log, opts) for log in (self.logs if logs is None else logs)]

    def residual(self, x: Sequence[float] | np.ndarray) -> np.ndarray:
        """The stacked residual of every log at ``x`` (quanta)."""
        return np.concatenate([r.residual_vector(self.groups, self.window) for r in self.run(x)])


_WORKER: FitProblem | None = None


def _init_worker(problem: FitProblem) -> None:
    global _WORKER
    _WORKER = problem
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _worker_residual(x: Sequence[float]) -> np.ndarray:
    assert _WORKER is not None
    return _WORKER.residual(x)


class _Evaluator:
    """Residuals at one or several points: in-process (``jobs`` 1), local processes, or Ray."""

    def __init__(self, problem: FitProblem, jobs: int, backend: str,
                 progress: Callable[[str], None]) -> None:
        self.problem = problem
        self.jobs = max(1, jobs)
        self.backend = backend
        self.progress = progress
        self.evaluations = 0
        self.best = math.inf
        self.best_x: np.ndarray | None = None      # the point of the lowest residual evaluated
        self._pool: Any = None
        self._ray_actors: list[Any] = []
        if self.jobs > 1 and backend == "local":
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            ctx = multiprocessing.get_context("fork" if sys.platform.startswith("linux") else "spawn")
            self._pool = ProcessPoolExecutor(self.jobs, mp_context=ctx, initializer=_init_worker,
                                             initargs=(problem,))
        elif backend == "ray":
            import ray

            if not ray.is_initialized():
                ray.init(num_cpus=self.jobs, include_dashboard=False, log_to_driver=False,
                         configure_logging=False)
            actor = ray.remote(_RayWorker)
            self._ray_actors = [actor.remote(problem) for _ in range(self.jobs)]

    def many(self, xs: Sequence[np.ndarray]) -> list[np.ndarray]:
        if self._pool is not None and len(xs) > 1:
            out = list(self._pool.map(_worker_residual, [np.asarray(x, float) for x in xs]))
        elif self._ray_actors:
            import ray

            refs = [self._ray_actors[i % len(self._ray_actors)].residual.remote(np.asarray(x, float))
                    for i, x in enumerate(xs)]
            out = ray.get(refs)
        else:
            out = [self.problem.residual(x) for x in xs]
        for x, r in zip(xs, out, strict=True):
            self.evaluations += 1
            cost = float(np.sqrt(np.mean(r * r))) if r.size else 0.0
            if cost < self.best:
                self.best = cost
                self.best_x = np.array(x, dtype=float)
            self.progress(f"calibrate: evaluation {self.evaluations}: residual {cost:.4f} "
                          f"(best {self.best:.4f}) quanta RMS")
        return out

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
        if self._ray_actors:
            import ray

            for a in self._ray_actors:
                ray.kill(a)
            self._ray_actors = []


class _RayWorker:
    def __init__(self, problem: FitProblem) -> None:
        self.problem = problem

    def residual(self, x: np.ndarray) -> np.ndarray:
        return self.problem.residual(x)


def _steps(unknowns: Sequence[Unknown], x: np.ndarray) -> np.ndarray:
    return np.array([max(REL_STEP * abs(v), BOUND_STEP * (u.hi - u.lo))
                     for u, v in zip(unknowns, x, strict=True)])


def _jacobian(ev: _Evaluator, unknowns: Sequence[Unknown], x: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Forward differences (backward at an upper bound), every column in parallel."""
    h = _steps(unknowns, x)
    pts = []
    signed = []
    for i, u in enumerate(unknowns):
        step = h[i] if x[i] + h[i] <= u.hi else -h[i]
        p = x.copy()
        p[i] += step
        pts.append(p)
        signed.append(step)
    cols = ev.many(pts)
    J = np.empty((r.size, len(unknowns)))
    for i, (c, step) in enumerate(zip(cols, signed, strict=True)):
        J[:, i] = (c - r) / step
    return J


def _central_jacobian(ev: _Evaluator, unknowns: Sequence[Unknown], x: np.ndarray,
                      r: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[list[float]]]:
    """The Jacobian at the optimum by central differences (one side at a bound), every probe in
    parallel, and for each column the variance of what a straight line through its three points
    does not explain (the twin's jitter under that parameter: a quantised reading or a contact
    that flips, mean square per value; 0 where a side is missing), and each column's residual RMS
    at its probes (those within the bounds, for :func:`_valleys`)."""
    h = _steps(unknowns, x)
    pts: list[np.ndarray] = []
    sides: list[tuple[float, float]] = []
    for i, u in enumerate(unknowns):
        up = min(x[i] + h[i], u.hi)
        down = max(x[i] - h[i], u.lo)
        sides.append((up, down))
        for v in (up, down):
            p = x.copy()
            p[i] = v
            pts.append(p)
    cols = ev.many(pts)
    J = np.empty((r.size, len(unknowns)))
    jitter = np.zeros(len(unknowns))
    probes: list[list[float]] = []
    for i, (up, down) in enumerate(sides):
        r_up, r_down = cols[2 * i], cols[2 * i + 1]
        probes.append([_rms(c) for c, v in ((r_up, up), (r_down, down)) if v != x[i]])
        J[:, i] = (r_up - r_down) / (up - down) if up > down else 0.0
        a, b = up - x[i], x[i] - down
        if a > 0 and b > 0 and r.size:
            # the straight line through the outer points misses the middle one by ``miss``: the
            # least-squares line's residuals through the three (one degree of freedom) sum to
            # 2/3 of its square (equal steps)
            miss = (b * r_up + a * r_down) / (a + b) - r
            jitter[i] = float(np.mean(miss * miss)) * 2.0 / 3.0
    return J, jitter, probes


def _valleys(ev: _Evaluator, unknowns: Sequence[Unknown], x: np.ndarray, r: np.ndarray,
             near: list[list[float]]) -> list[bool]:
    """Whether each unknown's value is the bottom of a valley of the residual: its RMS at one
    (``near``, the central Jacobian's probes) and two Jacobian steps either side, within the
    bounds, at least :data:`VALLEY_RISE` times the value's. The residual is not smooth (a reading
    or a pad's share of the load flips as a parameter moves): where a parameter's effect is
    smaller than those jumps, the fit stops at a jump, and the Jacobian there, hence the interval,
    says nothing; the profile shows it (docs/calibration.md, "Identifiable")."""
    h = _steps(unknowns, x)
    pts: list[np.ndarray] = []
    owner: list[int] = []
    for i, u in enumerate(unknowns):
        for v in (min(x[i] + 2 * h[i], u.hi), max(x[i] - 2 * h[i], u.lo)):
            if v != x[i]:
                p = x.copy()
                p[i] = v
                pts.append(p)
                owner.append(i)
    far: list[list[float]] = [[] for _ in unknowns]
    for i, c in zip(owner, ev.many(pts), strict=True):
        far[i].append(_rms(c))
    floor = _rms(r) * VALLEY_RISE
    return [all(v > floor for v in near[i] + far[i]) for i in range(len(unknowns))]


def _windows(results: Sequence[CompareResult], groups: Sequence[str], window: int) -> float:
    """The independent pieces of information in the residual: one per averaging window of each
    log, all its signals together (a contact that flips moves every force and current at once;
    the average of a window shares its frames): the residual's values / (signals x window)."""
    out = 0.0
    for r in results:
        n = r.residual_vector(groups, window).size
        signals = sum(1 for s in SIGNALS if s.group in groups and r.residuals[s.name].size)
        out += n / max(1, signals * max(1, window))
    return out


def _intervals(sysid: Any, r: np.ndarray, J: np.ndarray, jitter: np.ndarray, n_eff: float) -> np.ndarray:
    """95 % half-widths: ``mujoco.sysid.calculate_intervals`` (the variance times the inverse of
    JᵀJ, by its eigen-decomposition) with an honest variance for each parameter: the larger of
    the residual's and that parameter's jitter, times n / ``n_eff`` (the residual's values are
    not independent: ``_windows``), and Student's quantile on ``n_eff`` - p degrees of freedom."""
    from scipy.special import stdtrit

    n, p = r.size, J.shape[1]
    if n <= p:
        return np.full(p, math.inf)
    # the toolbox's half-widths for a unit variance (its residual's mean square: 1)
    _, unit = sysid.calculate_intervals([np.full(n, math.sqrt((n - p) / n))], J)
    s2 = np.maximum(float(r @ r) / (n - p), np.asarray(jitter, dtype=float)) * n / max(n_eff, 1e-9)
    dof = max(n_eff - p, 1.0)
    return np.asarray(unit, dtype=float) * np.sqrt(s2) * float(stdtrit(dof, 0.975) / stdtrit(n - p, 0.975))


# -- the fit ------------------------------------------------------------------------------------
@dataclass
class FitResult:
    """What ``calibrate`` reports (``as_dict``: the ``--json`` object, outputs aside)."""

    fitted: dict[str, dict[str, Any]]
    values: dict[str, float]              # the params file: fixed values and identified ones
    residual_before: float
    residual_after: float
    validation_before: float | None
    validation_after: float | None
    evaluations: int
    wall_s: float
    before: list[CompareResult]
    after: list[CompareResult]
    val_before: list[CompareResult]
    val_after: list[CompareResult]

    def as_dict(self) -> dict[str, Any]:
        return {"fitted": self.fitted, "params": self.values, "residual_before": self.residual_before,
                "residual_after": self.residual_after, "validation_before": self.validation_before,
                "validation_after": self.validation_after, "evaluations": self.evaluations,
                "wall_s": round(self.wall_s, 3)}


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(r * r))) if r.size else 0.0


def _norm(results: Sequence[CompareResult], groups: Sequence[str], window: int = 1) -> float:
    return _rms(np.concatenate([r.residual_vector(groups, window) for r in results]))


def _scan(ev: _Evaluator, unknowns: Sequence[Unknown], x0: np.ndarray, r0: np.ndarray,
          steps: int) -> np.ndarray:
    """The fit's start after a coarse scan: each unknown alone at ``steps`` Jacobian steps
    (:data:`REL_STEP` of its value) on either side of ``x0``, within its bounds, every point in
    parallel; each takes its best value (the residual is not one smooth valley: a local fit
    from the default can stop in another, docs/calibration.md)."""
    h = _steps(unknowns, x0)
    pts: list[np.ndarray] = []
    owner: list[int] = []
    for i, u in enumerate(unknowns):
        for k in [*range(-steps, 0), *range(1, steps + 1)]:
            v = min(max(x0[i] + k * h[i], u.lo), u.hi)
            if v != x0[i]:
                p = x0.copy()
                p[i] = v
                pts.append(p)
                owner.append(i)
    x = x0.copy()
    best = [_rms(r0)] * len(unknowns)
    for i, p, r in zip(owner, pts, ev.many(pts), strict=True):
        if _rms(r) < best[i]:
            best[i] = _rms(r)
            x[i] = p[i]
    return x


def fit(problem: FitProblem, *, validate: Sequence[RobotLog] = (), jobs: int = 1, backend: str = "local",
        max_evaluations: int = 200, progress: Callable[[str], None] | None = None,
        scan: int = 0) -> FitResult:
    """Fit ``problem``'s unknowns (see the module's docstring); ``validate``: logs kept apart;
    ``scan``: a coarse scan of each unknown first (:func:`_scan`, ``--scan``)."""
    from humanoid_twin.plant.sysid import toolbox

    sysid = toolbox()
    say = progress or (lambda text: None)
    t0 = time.perf_counter()
    unknowns = problem.unknowns
    params = sysid.ParameterDict({u.label: sysid.Parameter(u.label, u.default, u.lo, u.hi) for u in unknowns})
    x0 = params.as_vector()
    ev = _Evaluator(problem, jobs, backend, say)
    try:
        before = problem.run(x0)
        r0 = np.concatenate([r.residual_vector(problem.groups, problem.window) for r in before])
        ev.evaluations += len(problem.logs) and 1
        say(f"calibrate: start: residual {_rms(r0):.4f} quanta RMS over {r0.size} values, "
            f"{len(unknowns)} unknowns")
        budget = {"left": max_evaluations}

        def residual_fn(x: np.ndarray, _params: Any) -> tuple[list[np.ndarray], None, None]:
            x = np.asarray(x, dtype=float)
            cols = x.reshape(len(unknowns), -1)
            outs = ev.many([cols[:, k] for k in range(cols.shape[1])])
            budget["left"] -= len(outs)
            return [np.stack(outs, axis=1) if x.ndim == 2 else outs[0]], None, None

        def jacobian(x: np.ndarray, r: np.ndarray) -> np.ndarray:
            xv = np.asarray(x, dtype=float).reshape(-1)
            budget["left"] -= len(unknowns)
            return _jacobian(ev, unknowns, xv, np.asarray(r, dtype=float).reshape(-1))

        ev.best, ev.best_x = _rms(r0), x0.copy()
        if scan > 0:
            start = _scan(ev, unknowns, x0, r0, scan)
            budget["left"] -= 2 * scan * len(unknowns)
            params.update_from_vector(start)
        max_iters = max(1, budget["left"] // (len(unknowns) + 2))
        opt, _ = _optimize(sysid, params, residual_fn, jacobian, max_iters, _steps(unknowns, x0))
        x = np.clip(opt.as_vector(), [u.lo for u in unknowns], [u.hi for u in unknowns])
        after = problem.run(x)
        r1 = np.concatenate([r.residual_vector(problem.groups, problem.window) for r in after])
        ev.evaluations += 1
        if ev.best_x is not None and ev.best < _rms(r1):
            # a point evaluated on the way (a scan's, a Jacobian's probe) is better than where the
            # optimiser stopped: the residual's jumps misled it; the best point is the result
            x = np.clip(ev.best_x, [u.lo for u in unknowns], [u.hi for u in unknowns])
            after = problem.run(x)
            r1 = np.concatenate([r.residual_vector(problem.groups, problem.window) for r in after])
            ev.evaluations += 1
        J, jitter, near = _central_jacobian(ev, unknowns, x, r1)
        half = _intervals(sysid, r1, J, jitter, _windows(after, problem.groups, problem.window))
        valley = _valleys(ev, unknowns, x, r1, near)
    finally:
        ev.close()
    fitted: dict[str, dict[str, Any]] = {}
    values = dict(problem.base)
    col_norm = np.linalg.norm(J, axis=0) if J.size else np.zeros(len(unknowns))
    slip_mm = max((r.slip_mm for r in after), default=0.0)
    for i, u in enumerate(unknowns):
        hw = float(half[i]) if i < len(half) else math.inf
        ok = (math.isfinite(hw) and col_norm[i] > ZERO_COLUMN and 2 * hw <= (u.hi - u.lo) / 2
              and hw <= REL_CI * abs(float(x[i])) and valley[i] and shown(u.names[0], slip_mm))
        entry: dict[str, Any] = {"value": float(x[i]) if ok else u.default, "start": u.default,
                                 "ci95": [float(x[i]) - hw, float(x[i]) + hw] if ok else None,
                                 "identifiable": bool(ok)}
        if len(u.names) > 1:
            entry["tied"] = list(u.names)
        if not ok:
            entry["needs"] = motion_for(u.names[0])
        else:
            for name in u.names:
                values[name] = float(x[i])
        fitted[u.label] = entry
    # the unidentified keep their start: the after-fit residual is that of the values written
    if any(not e["identifiable"] for e in fitted.values()):
        x_written = np.array([e["value"] for e in fitted.values()])
        after = problem.run(x_written)
    val_before = problem.run(x0, validate) if validate else []
    val_after = problem.run(np.array([e["value"] for e in fitted.values()]), validate) if validate else []
    g, w = problem.groups, problem.window
    return FitResult(fitted=fitted, values=values, residual_before=_norm(before, g, w),
                     residual_after=_norm(after, g, w),
                     validation_before=_norm(val_before, g, w) if validate else None,
                     validation_after=_norm(val_after, g, w) if validate else None,
                     evaluations=ev.evaluations, wall_s=time.perf_counter() - t0, before=before, after=after,
                     val_before=val_before, val_after=val_after)


def _optimize(sysid: Any, params: Any, residual_fn: Callable, jacobian: Callable, max_iters: int,
              scale: np.ndarray) -> tuple[Any, Any]:
    """``mujoco.sysid.optimize`` with MuJoCo's bounded least squares, the twin's Jacobian."""
    return sysid.optimize(params, residual_fn, optimizer="mujoco", verbose=False, jacobian=jacobian,
                          max_iters=max_iters, x_scale=scale, output=sys.stderr, mu_factor=MU_FACTOR)


def groups_arg(text: str) -> tuple[str, ...]:
    """``--signals`` (comma-separated group names)."""
    out = tuple(t.strip() for t in text.split(",") if t.strip())
    bad = [g for g in out if g not in GROUPS]
    if bad or not out:
        raise ValueError(f"--signals {text!r}: groups are {', '.join(GROUPS)}")
    return out


def write_params_toml(path: Any, values: Mapping[str, float], header: str) -> None:
    """A params file: one ``"name" = value`` line per parameter, after ``# header`` lines."""
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f'"{name}" = {float(v)!r}' for name, v in values.items()]
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
