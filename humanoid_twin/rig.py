"""The twin with its instruments, assembled once: :class:`Rig` (``run``, ``serve``, the balance
study and the tests' booted-twin fixture all build their twin here).

A rig is the :class:`~humanoid_twin.twin.Twin` and what a run puts on it, always in this order:

1. the twin (seed, CAN interface, supervisor thresholds), then the ``on_twin`` hook (the live
   viewer attaches there);
2. the firmware laws (``--law``) on every Slave;
3. the rerun recorder (``--out FILE.rrd``; live to a viewer too with ``serve --viewer`` /
   ``--connect``: ``live``), then the CAN log (``--can-log FILE``), then the
   serial log (``--serial-log FILE``: every RS-232 byte, recording/serial_log.py; its header records
   :meth:`RigOptions.replay_meta`, and the tilt's start once known, so that its replay rebuilds
   this rig: :meth:`RigOptions.from_replay_meta`);
4. the ground-truth monitor, then the boards' report (task load, deadline misses, the IMU);
5. the faults (``--fault``), their start and end told to the recording;
6. the progress hook (every 0.1 s of virtual time).

The platform's tilt (``--tilt``) starts when the boot ends: :meth:`boot` (``run``) or, when a
client boots the robot (``serve``), the Master's supervisor entering ``ready``
(:meth:`tilt_after_ready`). :meth:`close` (or leaving the ``with`` block) closes the outputs and
the twin in the reverse order, each even when an earlier one failed, so a failed run never leaves
a file open; the first error is raised once all are closed.

    with Rig(RigOptions(seed=0, tilt=10.0)) as rig:
        H = rig.boot()                  # time advances here: power_on, the Slaves calibrate
        rig.sleep(3.0)                  # and here: the host waits on the twin's clock
        print(rig.monitor.fell)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from humanoid_twin.board_report import BoardReport
from humanoid_twin.controllers import install_laws, law_reference
from humanoid_twin.cycles import DEFAULT_PIC_MHZ
from humanoid_twin.faults import FaultInjector, FaultSpec
from humanoid_twin.host import drivers
from humanoid_twin.host.motion import power_on
from humanoid_twin.host.timebase import sleep as host_sleep
from humanoid_twin.master.supervisor import ESTOP, READY, SAFE, SupervisorConfig
from humanoid_twin.monitor import CONTROLLERS_START_S, Monitor
from humanoid_twin.twin import Twin

if TYPE_CHECKING:
    from humanoid_twin.interfaces import HostPort
    from humanoid_twin.recording.can_log import CanLog
    from humanoid_twin.recording.rerun_recorder import Recorder
    from humanoid_twin.recording.serial_log import SerialLog

__all__ = ["Rig", "RigOptions", "ScenarioError", "BootError", "boot", "tilt_profile", "BOOT_TIMEOUT_S",
           "TILT_RATE_DEG_S", "PROGRESS_PERIOD_US"]

BOOT_TIMEOUT_S = 5.0
TILT_RATE_DEG_S = 1.0       # "the floor platform tilts slowly": 1 degree per second
PROGRESS_PERIOD_US = 100_000
LIVE_CHUNK_S = 1.0          # a live viewer gets the recording's rows this often (simulated s)


@dataclass(kw_only=True)
class RigOptions:
    """What a rig puts on the twin (``run`` and ``serve`` share these options)."""

    seed: int = 0
    # python-can interface of the CAN wire: the project's own "humanoid_twin" (frames delivered in
    # virtual time only to the nodes whose slide-23 filters take them), or "virtual" / "socketcan"
    can_interface: str = "humanoid_twin"
    can_channel: str | None = None
    # injected faults (humanoid_twin/faults.py) and the supervisor's thresholds (docs/supervisor.md)
    faults: tuple[FaultSpec, ...] = ()
    supervisor: SupervisorConfig | None = None
    # firmware laws per control type ((type name or number, law class or "module:Class"), ...):
    # humanoid_twin/controllers.py, docs/controllers.md
    laws: tuple[tuple[int | str, Any], ...] = ()
    tilt: float = 0.0
    # the Slave boards' PIC18 clock, MHz (``--pic-mhz``; the cycle table: humanoid_twin/cycles.py)
    pic_mhz: float = DEFAULT_PIC_MHZ
    # the outputs: a rerun recording (.rrd) and a CAN log (format by suffix); ``can_log_name``:
    # the log's final file name, when ``can_log`` is a temporary one
    out: Path | None = None
    can_log: Path | None = None
    can_log_name: str | None = None
    # the RS-232 log (humanoid_twin/recording/serial_log.py), replayable into a rig of the same options
    serial_log: Path | None = None
    # a rerun viewer's gRPC URL (rerun+http://127.0.0.1:PORT/proxy): the recording streams there
    # live, in chunks of LIVE_CHUNK_S simulated seconds (beside ``out``, or alone)
    live: str | None = None
    # The ground-truth monitor behind fell / trunk tilt / CoP margin / CoP error. Off only for
    # scripts/bench.py, which times the twin itself (like recording, it is instrumentation).
    monitor: bool = True
    # the robot's named parameters (humanoid_twin/params.py, docs/parameters.md): name -> value,
    # the ones that differ from their defaults (empty: today's twin); ``--params`` / ``--set``
    params: Mapping[str, float] = field(default_factory=dict)

    def replay_meta(self) -> dict[str, Any]:
        """What a replay of this rig's RS-232 traffic needs to build the same twin (the serial
        log's header): the seed, the CAN wire, the faults (their texts), the supervisor's
        thresholds, the laws (``module:Class``), the tilt and the boards' clock. The outputs and
        the monitor are not in it: they observe, they do not change what the twin answers."""
        import dataclasses

        meta: dict[str, Any] = {"seed": self.seed}
        if self.can_interface != "humanoid_twin" or self.can_channel is not None:
            meta.update(can_interface=self.can_interface, can_channel=self.can_channel)
        if self.faults:
            meta["faults"] = [spec.text for spec in self.faults]
        if self.supervisor is not None:
            meta["supervisor"] = dataclasses.asdict(self.supervisor)
        if self.laws:
            meta["laws"] = [[ctype, law_reference(law)] for ctype, law in self.laws]
        if self.tilt:
            meta["tilt"] = self.tilt
        if self.pic_mhz != DEFAULT_PIC_MHZ:
            meta["pic_mhz"] = self.pic_mhz
        if self.params:
            from humanoid_twin.params import non_defaults

            meta["params"] = non_defaults(self.params)
        return meta

    @classmethod
    def from_replay_meta(cls, meta: dict[str, Any]) -> RigOptions:
        """The options :meth:`replay_meta` recorded (no outputs, no monitor); ``ValueError`` when
        the meta cannot be read back (a fault text or a threshold that no longer parses)."""
        from humanoid_twin.faults import FaultSpecError, parse_fault

        try:
            faults = tuple(parse_fault(text) for text in meta.get("faults", ()))
            sup = meta.get("supervisor")
            return cls(seed=int(meta.get("seed", 0)),
                       can_interface=meta.get("can_interface", "humanoid_twin"),
                       can_channel=meta.get("can_channel"), faults=faults,
                       supervisor=None if sup is None else SupervisorConfig(**sup),
                       laws=tuple((ctype, ref) for ctype, ref in meta.get("laws", ())),
                       tilt=float(meta.get("tilt", 0.0)),
                       pic_mhz=float(meta.get("pic_mhz", DEFAULT_PIC_MHZ)), monitor=False,
                       params=_meta_params(meta.get("params", {})))
        except (FaultSpecError, TypeError, ValueError) as exc:
            raise ValueError(f"the options in its meta cannot be read back: {exc}") from None


def _meta_params(values: Any) -> dict[str, float]:
    """A log's recorded parameters, checked against this version's registry (``ParamError``, a
    ``ValueError``, when one is unknown or out of bounds)."""
    from humanoid_twin.params import ParamError, registry

    if not isinstance(values, dict):
        raise ParamError(f"params must be a table of name -> value, got {values!r}")
    return registry().check(values)


class ScenarioError(RuntimeError):
    """A run could not go on (the twin did not boot, a request failed ...); ``humanoid_twin.scenarios``
    re-exports it."""


class BootError(ScenarioError):
    """:func:`boot` failed; ``port`` is the host end of the link, open (the run may go on)."""

    def __init__(self, message: str, port: HostPort) -> None:
        super().__init__(message)
        self.port = port


def boot(twin: Twin, timeout: float = BOOT_TIMEOUT_S) -> Any:
    """The one boot sequence: open the host end of the twin's RS-232 link and ``power_on`` every
    board (positions 0, movement period, PWM on; the Slaves calibrate). Returns the open port.
    Attach whatever observes the run (monitor, recorder, CAN log, faults) before calling it.
    :class:`BootError` (with the port) if a request fails."""
    H = twin.open_port()
    try:
        power_on(H, timeout=timeout)
    except drivers.CommError as exc:
        raise BootError(f"the twin did not boot: {exc}", H) from exc
    return H


def tilt_profile(
    target_deg: float, start_s: float, rate_deg_s: float = TILT_RATE_DEG_S
) -> Callable[[float], float]:
    """Platform pitch vs time: flat until ``start_s``, then a ramp at ``rate_deg_s`` to ``target_deg``."""
    import math

    def profile(t: float) -> float:
        if t <= start_s or target_deg == 0:
            return 0.0
        ramp = (t - start_s) * rate_deg_s
        return math.copysign(min(abs(target_deg), ramp), target_deg)

    return profile


class Rig:
    """The twin and its instruments, assembled in the module's fixed order: ``Rig(opts)``.

    ``expected_s``: how long the run lasts at most (None: open-ended, as ``serve``), which sizes
    the recording's compaction. ``on_twin(twin)``: called once the twin is built, before anything
    is written. ``on_progress(t_s, end_s)``: every 0.1 s of virtual time (``end_s``: :attr:`end_s`,
    None until the run's end is known).

    Attributes: ``twin``, ``monitor`` (attached when ``opts.monitor``), ``report`` (the boards'
    task load, deadline misses and IMU error: humanoid_twin/board_report.py), ``injector``,
    ``recorder``, ``canlog`` and ``seriallog`` (None when not asked for), ``H`` (the host's port once
    :meth:`boot` ran), ``boot_s``, ``boot_error`` (why the boot failed, when the run went on: None
    when it worked), ``host_error`` (a request that failed while the run went on), ``end_s``.
    """

    def __init__(self, opts: RigOptions | None = None, *, expected_s: float | None = None,
                 on_twin: Callable[[Twin], None] | None = None,
                 on_progress: Callable[[float, float | None], None] | None = None) -> None:
        opts = opts if opts is not None else RigOptions()
        self.opts = opts
        self.recorder: Recorder | None = None
        self.canlog: CanLog | None = None
        self.seriallog: SerialLog | None = None
        self.H: HostPort = None  # type: ignore[assignment]  # the host end, from boot on
        self.boot_s: float | None = None
        self.boot_error: str | None = None
        self.host_error: str | None = None
        self.end_s: float | None = None
        self.twin = Twin(seed=opts.seed, can_interface=opts.can_interface, can_channel=opts.can_channel,
                         supervisor=opts.supervisor, pic_mhz=opts.pic_mhz, params=opts.params)
        try:
            self._assemble(opts, expected_s, on_twin, on_progress)
        except BaseException:
            self.close()
            raise

    def _assemble(self, opts: RigOptions, expected_s: float | None, on_twin: Callable[[Twin], None] | None,
                  on_progress: Callable[[float, float | None], None] | None) -> None:
        twin = self.twin
        if on_twin is not None:
            on_twin(twin)
        self.injector = FaultInjector(twin, opts.faults, opts.seed)
        if opts.laws:
            install_laws(twin, opts.laws)      # LawError: a law that cannot be made for every board
        if opts.out is not None or opts.live is not None:
            from humanoid_twin.recording import Recorder, compact_for

            live: dict[str, Any] = ({} if opts.live is None
                                    else {"stream_to": opts.live, "chunk_s": LIVE_CHUNK_S})
            self.recorder = Recorder(opts.out, twin, compact=compact_for(expected_s), **live)
        if opts.can_log is not None:
            from humanoid_twin.recording import CanLog

            self.canlog = CanLog(opts.can_log, twin.network, name=opts.can_log_name, params=twin.params)
        if opts.serial_log is not None:
            from humanoid_twin.recording.serial_log import SerialLog

            self.seriallog = SerialLog(opts.serial_log, twin.link, meta=opts.replay_meta())
        self.monitor = Monitor(twin)
        if opts.monitor:
            self.monitor.attach()
        self.report = BoardReport(twin, imu=opts.monitor)     # task load, deadline misses, the IMU
        if self.recorder is not None:
            rec = self.recorder
            self.injector.listeners.append(
                lambda t, what, spec: rec.log_event(t, f"injected {spec.text}: {what}", "WARN"))
        self.injector.install()
        if on_progress is not None:
            twin.every(PROGRESS_PERIOD_US, lambda: on_progress(twin.now_s, self.end_s))

    # -- the run ---------------------------------------------------------------------------------
    @property
    def now_s(self) -> float:
        """The twin's virtual time (s)."""
        return self.twin.now_s

    def stopped(self) -> bool:
        """The Master's supervisor is in ``safe`` or ``estop``."""
        return self.twin.the_master().supervisor.mode in (SAFE, ESTOP)

    def tolerates(self) -> bool:
        """A failed host request is part of what the run shows (the summary's ``host_error``)
        rather than the end of it: the supervisor stopped the robot, or faults are injected."""
        return self.stopped() or bool(self.opts.faults)

    def boot(self) -> Any:
        """Boot the twin (:func:`boot`; time advances here) and start the platform's tilt from
        the boot's end; the monitor's extremes over the motion alone start
        :data:`~humanoid_twin.monitor.CONTROLLERS_START_S` later. A failed boot the run
        tolerates (:meth:`tolerates`) is kept in :attr:`boot_error` and :attr:`host_error` (no
        motion follows it); otherwise :class:`BootError`. Returns the host's port ``H``."""
        try:
            self.H = boot(self.twin)
        except BootError as exc:
            if not self.tolerates():
                raise
            self.H = exc.port
            self.boot_error = str(exc.__cause__)
            self.host_error = f"boot: {exc.__cause__}"   # the supervisor stopped the boot: the run goes on
        self.boot_s = self.twin.now_s
        if self.boot_error is None:
            self.monitor.start_motion(self.boot_s + CONTROLLERS_START_S)
        self.start_tilt(self.boot_s)
        return self.H

    def start_tilt(self, at_s: float) -> None:
        """The platform tilts from ``at_s`` (virtual s) at :data:`TILT_RATE_DEG_S` to ``opts.tilt``."""
        if self.opts.tilt:
            self.twin.plant.set_tilt_profile(tilt_profile(self.opts.tilt, at_s))
            if self.seriallog is not None:
                self.seriallog.note({"tilt_from_s": at_s})     # what its replay starts the tilt at

    def tilt_after_ready(self) -> None:
        """The platform tilts from the moment the Master's supervisor first enters ``ready`` (a
        client booted the robot: ``serve``)."""
        if not self.opts.tilt:
            return
        sup = self.twin.the_master().supervisor
        started = [False]

        def on_mode(kind: str, t_us: int, value: Any) -> None:
            if kind == "mode" and value == READY and not started[0]:
                started[0] = True
                self.boot_s = t_us / 1e6
                self.start_tilt(self.boot_s)

        sup.listeners.append(on_mode)

    def sleep(self, seconds: float) -> None:
        """The host waits ``seconds`` on the twin's clock (time advances here)."""
        if seconds > 0:
            host_sleep(self.H, seconds)

    def sleep_until(self, t_s: float) -> None:
        """The host waits until virtual time ``t_s`` (nothing when it is past)."""
        self.sleep(t_s - self.twin.now_s)

    def log_event(self, text: str, level: str = "INFO") -> None:
        """A line in the recording's event log at the current time (nothing without ``--out``)."""
        if self.recorder is not None:
            self.recorder.log_event(self.twin.clock.now_us, text, level)

    # -- the end ---------------------------------------------------------------------------------
    def close(self) -> None:
        """Close the outputs and the twin in the reverse of their assembly, each even when an
        earlier one failed; the first error is raised once all are closed. No user code runs from
        here (humanoid_twin/signals.user_code_done: a signal's grace ends)."""
        from humanoid_twin import signals

        signals.user_code_done()
        first: BaseException | None = None
        for thing in (self.seriallog, self.canlog, self.recorder, self.twin):
            if thing is None:
                continue
            try:
                thing.close()
            except BaseException as exc:    # noqa: BLE001 - raised again below, after the others
                first = first or exc
        if first is not None:
            raise first

    def __enter__(self) -> Rig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
