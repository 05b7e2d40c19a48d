"""``humanoid-twin compare``: a robot's CAN log drives the twin's Slaves; their answers are compared.

The log stands in for the Master (:class:`LogPlayer`): the twin is built without its Master
board (``Twin(master=False)``), and a node on the wire, with the Master's acceptance filters
(seed 002 slide 23), puts each of the log's Master frames (Actuation 1 and 2 to each SCU) on the
wire at the instant it started on the robot's bus. The eight Slaves, the wire and the plant run
as always, and answer with their Sensors frames.

Pairing: a Slave answers each actuation packet with the Sensors packet of the same index
(slide 29), so a Sensors frame belongs to the *round* of the last actuation packet of its index
to its SCU. Both the log's frames and the twin's are keyed ``(scu, packet, round)``, the round
counted from the actuation packets each side carried: the same key is the same question asked of
the robot and of the twin, whatever the clocks. A key on one side only is a frame missing on the
other (the robot's Slave stayed silent, a frame lost, a log cut short).

A log that begins after the boot (its first Sensors frame says its Slave is calibrated) is
preceded on the twin by a *pre-roll* of :data:`PREROLL_US`: the log's first Actuation 1 and 2 of
each SCU, repeated on the Master's schedule (seed 002 slide 27), so that the twin's Slaves move to
the log's first positions and calibrate there, as the robot's did at its boot, before the log's
first frame. The twin's frames of the pre-roll are not compared. A round in which the twin's
board still calibrates while the robot's did not is counted (``frames_warmup``) and left out.

The Slaves' PWM phases decide which actuation packets they leave unanswered: with
``CompareOptions.phases`` "log" (the default) a Slave whose seeded phase the log's silences
contradict starts at the phase read from the log instead (humanoid_twin/compare/phases.py).
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from humanoid_twin.clock import US_PER_S
from humanoid_twin.compare.robot_log import ACTUATION_OF, SENSORS_OF, LogFrame, RobotLog
from humanoid_twin.compare.signals import GROUP_UNITS, GROUPS, QUANTUM, SIGNALS, Signal, decode_packet
from humanoid_twin.hardware import PWM_PERIOD_US
from humanoid_twin.master.pic import ROUND_US, SLAVE_PERIOD_US, TIMER_PERIOD_US
from humanoid_twin.protocol import canframes
from humanoid_twin.protocol.wire import STATUS_CALIB

if TYPE_CHECKING:
    import can

    from humanoid_twin.twin import Twin

__all__ = ["CompareOptions", "CompareResult", "LogPlayer", "PHASES", "SUPPORTS", "compare_frames", "run_twin",
           "compare_log", "key_frames", "twin_phases"]

SUPPORTS = ("floor", "stand")
PHASES = ("log", "seed")
# a log that starts after the boot: the twin's boot on the log's first actuation, before it
# (the Slaves' calibration, 100 + 25 PWM periods, then a margin), whole rounds of the schedule
PREROLL_US = 375 * ROUND_US
TAIL_US = 2_000          # the twin runs this long past the log's last frame (the last answers)

Key = tuple[int, int, int]        # (scu, packet index, round)


@dataclass(kw_only=True)
class CompareOptions:
    """How the twin is built for a comparison: the seed, the robot's support (``floor``: on its
    feet; ``stand``: the trunk held in the air, as on a test stand) and the parameters
    (name -> value, humanoid_twin/params.py; empty: the defaults)."""

    seed: int = 0
    support: str = "floor"
    params: Mapping[str, float] = field(default_factory=dict)
    # the Slaves' PWM phases: "log" (the seed's, unless the log contradicts them: then the
    # phases read from the log, humanoid_twin/compare/phases.py) or "seed" (the seed's, always)
    phases: str = "log"


@dataclass
class SignalStats:
    """One signal's differences (twin - log), in the signal's unit."""

    name: str
    group: str
    n: int
    rms: float | None
    max_abs: float | None

    def as_dict(self) -> dict[str, Any]:
        return {"group": self.group, "unit": GROUP_UNITS[self.group], "n": self.n, "rms": self.rms,
                "max_abs": self.max_abs}


@dataclass
class CompareResult:
    """What ``compare`` reports (``as_dict``: the ``--json`` object)."""

    log: str
    frames_log: int                   # the log's Sensors frames
    frames_twin: int                  # the twin's Sensors frames
    frames_compared: int
    frames_missing: dict[str, int]    # {"twin": keys only in the log, "log": keys only in the twin}
    frames_warmup: int
    frames_foreign: int
    error_frames: int
    master_frames: int
    status_mismatches: int
    started_after_boot: bool
    clock_offset_s: float
    rms: dict[str, float | None]
    max_abs: dict[str, float | None]
    signals: dict[str, SignalStats]
    series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]   # name -> (t_us, twin, log)
    # per signal, one value per log frame: (twin - log) / quantum (calibrate); 0 for a warm-up
    # round, the twin's last value held for a frame it did not send
    residuals: dict[str, np.ndarray]
    options: CompareOptions
    wall_s: float = 0.0
    # per SCU: the PWM phase the twin's Slave ran at (us) and where it came from ("seed"/"log")
    phases: dict[int, tuple[int, str]] = field(default_factory=dict)
    slip_mm: float = 0.0              # the largest distance a foot of the twin slid (monitor.SoleSlide)

    def as_dict(self) -> dict[str, Any]:
        return {
            "log": self.log,
            "seed": self.options.seed,
            "support": self.options.support,
            "frames_compared": self.frames_compared,
            "frames_missing": self.frames_missing,
            "frames_warmup": self.frames_warmup,
            "frames_foreign": self.frames_foreign,
            "error_frames": self.error_frames,
            "frames_log": self.frames_log,
            "frames_twin": self.frames_twin,
            "master_frames": self.master_frames,
            "status_mismatches": self.status_mismatches,
            "started_after_boot": self.started_after_boot,
            "clock_offset_s": self.clock_offset_s,
            "phases": {str(scu): {"us": p, "from": src} for scu, (p, src) in sorted(self.phases.items())},
            "rms": self.rms,
            "max_abs": self.max_abs,
            "signals": {name: s.as_dict() for name, s in self.signals.items()},
            "wall_s": round(self.wall_s, 3),
        }

    def residual_vector(self, groups: Iterable[str] | None = None, window: int = 1) -> np.ndarray:
        """The residuals of the signals of ``groups`` (all), one signal after the other, each
        averaged over ``window`` consecutive frames (1: as they are) ."""
        keep = set(GROUPS if groups is None else groups)
        parts = []
        for s in SIGNALS:
            if s.group not in keep:
                continue
            r = self.residuals[s.name]
            if window > 1 and r.size >= window:
                c = np.cumsum(np.concatenate(([0.0], r)))
                r = (c[window:] - c[:-window]) / window
            parts.append(r)
        return np.concatenate(parts) if parts else np.zeros(0)

    def residual_norm(self, groups: Iterable[str] | None = None, window: int = 1) -> float:
        """The RMS of :meth:`residual_vector`."""
        r = self.residual_vector(groups, window)
        return float(np.sqrt(np.mean(r * r))) if r.size else 0.0


class LogPlayer:
    """The log's Master frames on the twin's wire, each at the instant it started on the robot's
    bus: a node with the Master's acceptance filters (slide 23) in the Master's place."""

    NODE = "log-player"

    def __init__(self, twin: Twin, log: RobotLog, preroll: list[LogFrame] | None = None) -> None:
        self.clock = twin.clock
        self.ctrl = twin.network.attach(self.NODE, canframes.master_filters(), None)
        self.frames = list(preroll or ()) + log.master
        self.starts = [f.t_us for f in preroll or ()] + [log.master_start_us(f) for f in log.master]
        self.sent = 0
        self.refused = 0
        self._i = 0
        if self.frames:
            self.clock.schedule(max(0, self.starts[0]), self._send)

    def _send(self) -> None:
        i = self._i
        f = self.frames[i]
        frame = self.ctrl.load_tx(None, f.arbitration_id, f.data)
        if self.ctrl.send(frame):
            self.sent += 1
        else:
            self.refused += 1
        i += 1
        self._i = i
        if i < len(self.frames):
            now = self.clock.now_us
            self.clock.schedule(max(now, self.starts[i]), self._send)


class _Collector:
    """A wire listener keeping the robot's frames the twin's wire carried (us, id, data)."""

    def __init__(self) -> None:
        self.frames: list[LogFrame] = []

    def on_message_received(self, msg: can.Message) -> None:
        arb = msg.arbitration_id
        if arb in SENSORS_OF or arb in ACTUATION_OF:
            self.frames.append(LogFrame(round(msg.timestamp * US_PER_S), arb, bytes(msg.data)))

    def stop(self) -> None:
        pass


def key_frames(frames: Iterable[LogFrame]) -> tuple[dict[Key, LogFrame], int]:
    """The Sensors frames of a time-ordered stream (actuation and sensors frames) by
    ``(scu, packet, round)`` (the round: how many actuation packets of that index the SCU had
    got, minus one). Returns the keyed frames and the count of duplicates (a second answer in
    one round: the first is kept)."""
    rounds: dict[tuple[int, int], int] = {}
    out: dict[Key, LogFrame] = {}
    dup = 0
    for f in frames:
        arb = f.arbitration_id
        act = ACTUATION_OF.get(arb)
        if act is not None:
            rounds[act] = rounds.get(act, 0) + 1
            continue
        scu, idx = SENSORS_OF[arb]
        key = (scu, idx, rounds.get((scu, idx), 0) - 1)
        if key in out:
            dup += 1
        else:
            out[key] = f
    return out, dup


def preroll_frames(log: RobotLog) -> list[LogFrame]:
    """The pre-roll before a log that starts after the boot: each SCU's first Actuation 1 and 2
    of the log, on the Master's schedule (slot 0 and slot 2 of its millisecond) from the twin's
    instant 0 to :data:`PREROLL_US`; ``t_us`` here is each frame's start (TXREQ)."""
    first: dict[int, LogFrame] = {}
    for f in log.master:
        first.setdefault(f.arbitration_id, f)
    out: list[LogFrame] = []
    for t in range(0, PREROLL_US, ROUND_US):
        for scu, ids in canframes.ACTUATION_IDS.items():
            for idx, arb in enumerate(ids):
                f = first.get(arb)  # type: ignore[assignment]  # every actuation id is in the log's first frames
                if f is not None:
                    slot_us = t + (scu - 1) * SLAVE_PERIOD_US + 2 * idx * TIMER_PERIOD_US
                    out.append(LogFrame(slot_us, arb, f.data))
    return out


def _merged(log: RobotLog) -> list[LogFrame]:
    return sorted(log.master + log.sensors, key=lambda f: f.t_us)


def _hold_support(twin: Twin, support: str) -> None:
    if support == "stand":
        twin.plant.hold_trunk()


def twin_phases(log: RobotLog, opts: CompareOptions) -> dict[int, tuple[int, str]]:
    """The Slaves' phases a comparison runs with (``opts.phases``): SCU -> (us, "seed" or "log")."""
    from humanoid_twin.compare.phases import phases_for
    from humanoid_twin.twin import seed_phases

    own = seed_phases(opts.seed)
    if opts.phases == "seed":
        return {scu: (p, "seed") for scu, p in own.items()}
    return phases_for(log, own)


def run_twin(log: RobotLog, opts: CompareOptions, phases: Mapping[int, int] | None = None,
             slide: Any = None) -> list[LogFrame]:
    """Drive a twin (no Master; :class:`LogPlayer` in its place) with the log's Master frames up
    to the log's end (after a pre-roll when the log starts after the boot: the log is then
    :meth:`RobotLog.shifted` by :data:`PREROLL_US`); the robot's frames its wire carried from the
    log's start, in time order. ``phases``: the Slaves' phases (SCU -> us; the seed's otherwise);
    ``slide``: a :class:`humanoid_twin.monitor.SoleSlide` fed the twin's soles every PWM period
    (how far the twin's feet slid: ``calibrate`` asks it of the floor's friction)."""
    from humanoid_twin.twin import Twin

    kwargs: dict[str, Any] = {}
    if opts.params:
        kwargs["params"] = dict(opts.params)
    twin = Twin(seed=opts.seed, master=False, phases_us=phases, **kwargs)
    try:
        _hold_support(twin, opts.support)
        collector = _Collector()
        twin.network.add_listener(collector)  # type: ignore[arg-type]  # a listener by duck typing
        preroll = preroll_frames(log) if log.started_after_boot else []
        if preroll:
            log = log.shifted(PREROLL_US)
        LogPlayer(twin, log, preroll)
        if slide is not None:
            plant = twin.plant
            twin.every(PWM_PERIOD_US, lambda: slide.add(plant.soles_on_surface_mm()),
                       PREROLL_US if preroll else 0)
        twin.advance_to(log.duration_us + TAIL_US)
        if preroll:
            return [f._replace(t_us=f.t_us - PREROLL_US) for f in collector.frames if f.t_us >= PREROLL_US]
        return collector.frames
    finally:
        twin.close()


def _calibrated(status: int) -> bool:
    return bool(status & STATUS_CALIB)


def compare_frames(log: RobotLog, twin_frames: Sequence[LogFrame], opts: CompareOptions,
                   wall_s: float = 0.0) -> CompareResult:
    """Pair the log's Sensors frames with the twin's and compute the statistics."""
    log_keyed, _ = key_frames(_merged(log))
    twin_keyed, _ = key_frames(twin_frames)
    started_after_boot = log.started_after_boot
    # per (scu, round): the twin still calibrating while the robot was not (warm-up)
    warm: set[tuple[int, int]] = set()
    status_mismatches = 0
    for key, lf in log_keyed.items():
        scu, idx, rnd = key
        tf = twin_keyed.get(key)
        if idx == 0 and tf is not None:
            ls = decode_packet(0, lf.data)[1]
            ts = decode_packet(0, tf.data)[1]
            if ls != ts:
                status_mismatches += 1
            if _calibrated(ls) and not _calibrated(ts):
                warm.add((scu, rnd))
    by_packet: dict[tuple[int, int], list[Signal]] = {}
    for s in SIGNALS:
        by_packet.setdefault((s.scu, s.packet), []).append(s)
    values: dict[str, tuple[list[int], list[int], list[int]]] = {s.name: ([], [], []) for s in SIGNALS}
    held: dict[str, int] = {}
    res: dict[str, list[float]] = {s.name: [] for s in SIGNALS}
    compared = warmup = missing_twin = 0
    for key in sorted(log_keyed, key=lambda k: (log_keyed[k].t_us, k)):
        scu, idx, rnd = key
        lf = log_keyed[key]
        tf = twin_keyed.get(key)
        sigs = by_packet.get((scu, idx), ())
        if (scu, rnd) in warm:
            warmup += 1
            for s in sigs:      # not compared; the residual keeps its length (one per log value)
                res[s.name].append(0.0)
            continue
        lv = decode_packet(idx, lf.data)[0]
        if tf is None:
            missing_twin += 1
            for s in sigs:      # the residual keeps its length: the twin's last value holds
                twin_v = held.get(s.name, lv[s.field])
                res[s.name].append((twin_v - lv[s.field]) / QUANTUM[s.group])
            continue
        compared += 1
        tv = decode_packet(idx, tf.data)[0]
        for s in sigs:
            t, a, b = values[s.name]
            t.append(lf.t_us)
            a.append(tv[s.field])
            b.append(lv[s.field])
            held[s.name] = tv[s.field]
            res[s.name].append((tv[s.field] - lv[s.field]) / QUANTUM[s.group])
    missing_log = sum(1 for k in twin_keyed if k not in log_keyed and (k[0], k[2]) not in warm)
    signals: dict[str, SignalStats] = {}
    series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    sq: dict[str, list[np.ndarray]] = {g: [] for g in GROUPS}
    for s in SIGNALS:
        t, a, b = values[s.name]
        ta = np.asarray(t, dtype=np.int64)
        aa = np.asarray(a, dtype=float)
        ba = np.asarray(b, dtype=float)
        series[s.name] = (ta, aa, ba)
        d = aa - ba
        sq[s.group].append(d)
        if d.size:
            signals[s.name] = SignalStats(s.name, s.group, int(d.size), float(np.sqrt(np.mean(d * d))),
                                          float(np.max(np.abs(d))))
        else:
            signals[s.name] = SignalStats(s.name, s.group, 0, None, None)
    rms: dict[str, float | None] = {}
    max_abs: dict[str, float | None] = {}
    for g in GROUPS:
        d = np.concatenate(sq[g]) if sq[g] else np.zeros(0)
        rms[g] = float(np.sqrt(np.mean(d * d))) if d.size else None
        max_abs[g] = float(np.max(np.abs(d))) if d.size else None
    twin_sensors = sum(1 for f in twin_frames if f.arbitration_id in SENSORS_OF)
    return CompareResult(
        log=log.path, frames_log=len(log.sensors), frames_twin=twin_sensors, frames_compared=compared,
        frames_missing={"twin": missing_twin, "log": missing_log}, frames_warmup=warmup,
        frames_foreign=log.frames_foreign, error_frames=log.error_frames, master_frames=len(log.master),
        status_mismatches=status_mismatches, started_after_boot=started_after_boot,
        clock_offset_s=log.clock_offset_s, rms=rms, max_abs=max_abs, signals=signals, series=series,
        residuals={name: np.asarray(v, dtype=float) for name, v in res.items()},
        options=opts, wall_s=wall_s)


def compare_log(log: RobotLog, opts: CompareOptions | None = None) -> CompareResult:
    """Run the twin against ``log`` (:func:`run_twin`) and compare (:func:`compare_frames`)."""
    opts = opts if opts is not None else CompareOptions()
    if opts.support not in SUPPORTS:
        raise ValueError(f"support must be one of {', '.join(SUPPORTS)}, got {opts.support!r}")
    if opts.phases not in PHASES:
        raise ValueError(f"phases must be one of {', '.join(PHASES)}, got {opts.phases!r}")
    t0 = time.perf_counter()
    phases = twin_phases(log, opts)
    from humanoid_twin.monitor import SoleSlide

    slide = SoleSlide()
    frames = run_twin(log, opts, {scu: p for scu, (p, _) in phases.items()}, slide)
    result = compare_frames(log, frames, opts, time.perf_counter() - t0)
    result.phases = phases
    result.slip_mm = slide.slip_mm
    return result


def finite_or_none(x: float | None) -> float | None:
    """``x`` when finite (JSON has no NaN)."""
    return x if x is not None and math.isfinite(x) else None
