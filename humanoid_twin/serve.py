"""``humanoid-twin serve``: the twin in real time behind a pty or a TCP port.

The first line on stdout is the port to open; any program that speaks the RS-232 bytes of
docs/protocol.md drives the twin from there, as it would drive the robot. One client at a time;
every client starts on a clean line; connects and leaves are logged on stderr (docs/serve.md).

The twin and its instruments are a :class:`~humanoid_twin.rig.Rig`, assembled as for ``run``
(laws, faults, recording, CAN log, serial log; the recording also live to a rerun viewer with
``RigOptions.live``); the platform's tilt starts once a client has booted the
robot (the Master's supervisor enters ``ready``), as ``run``'s starts after its boot.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from humanoid_twin import signals
from humanoid_twin.clock import RealTimePacer
from humanoid_twin.rig import Rig, RigOptions

if TYPE_CHECKING:
    from humanoid_twin.bus.bridges import PtyBridge, TcpBridge

POLL_S = 0.0005
DEFAULT_IDLE_TIMEOUT_S = 600.0


class ServeError(OSError):
    """``serve`` cannot listen where it was asked to (address in use, not an address here ...)."""


@dataclass(kw_only=True)
class ServeOptions(RigOptions):
    """The ``humanoid-twin serve`` options (docs/serve.md): the rig's, and where and how to serve.
    ``tcp_port`` None: a pty. ``speed``: virtual seconds per wall second. ``max_seconds``: wall
    seconds to serve at most (None: until stopped)."""

    tcp_port: int | None = None
    host: str = "127.0.0.1"
    idle_timeout_s: float | None = DEFAULT_IDLE_TIMEOUT_S
    speed: float = 1.0
    max_seconds: float | None = None
    monitor: bool = False      # nobody reads a ground-truth summary of a serve run


def _log(text: str) -> None:
    sys.stderr.write(f"humanoid-twin serve: {text}\n")
    sys.stderr.flush()


def _announce(line: str) -> None:
    print(line, flush=True)


def serve(opts: ServeOptions | None = None, *, should_stop: Callable[[], bool] = lambda: False,
          log: Callable[[str], None] = _log, announce: Callable[[str], None] = _announce) -> int:
    """Serve until ``should_stop()`` (or ``opts.max_seconds`` of wall time); returns an exit code.
    The rig's outputs are complete files when it returns, whatever ended it. ``announce(port)``
    prints the port's name, the first line on stdout (default: ``print``; the CLI gives its own
    stdout, cli/streams.py).

    Raises :class:`ServeError` if the TCP address cannot be listened on (before the twin boots).
    """
    from humanoid_twin.bus.bridges import PtyBridge, TcpBridge
    from humanoid_twin.master.usart import FRAME_GAP_US, PROCESS_US

    opts = opts if opts is not None else ServeOptions()
    with Rig(opts) as rig:
        rig.tilt_after_ready()
        twin = rig.twin
        # Between two clients the line stays quiet longer than the Master's break-off gap and its
        # answer delay, and each client starts with the Master's receiver reset: no spliced frames,
        # no answer to somebody else's bytes.
        options: dict[str, Any] = dict(log=log, on_session=twin.the_master().reset_receiver,
                                       idle_timeout_s=opts.idle_timeout_s,
                                       quiet_us=FRAME_GAP_US + PROCESS_US + 1_000)
        try:
            if opts.tcp_port is not None:
                bridge = TcpBridge(twin.link, host=opts.host, port=opts.tcp_port, **options)
            else:
                bridge = PtyBridge(twin.link, **options)  # type: ignore[assignment]  # either bridge
        except OSError as exc:
            where = f"{opts.host} port {opts.tcp_port}" if opts.tcp_port is not None else "a pty"
            raise ServeError(exc.errno, f"cannot listen on {where}: {exc.strerror or exc}") from exc
        try:
            return _serve_loop(rig, bridge, opts, should_stop, log, announce)
        finally:
            bridge.close()


def _serve_loop(rig: Rig, bridge: PtyBridge | TcpBridge, opts: ServeOptions, should_stop: Callable[[], bool],
                log: Callable[[str], None], announce: Callable[[str], None]) -> int:
    twin = rig.twin
    announce(bridge.port_name)
    idle = f"idle timeout {opts.idle_timeout_s:g} s" if opts.idle_timeout_s else "no idle timeout"
    pace = "" if opts.speed == 1.0 else f", {opts.speed:g}x real time"
    log(f"serving on {bridge.port_name}: one client at a time, {idle}{pace}")
    pacer = RealTimePacer(twin.clock, speed=opts.speed)     # --speed: virtual seconds per wall second
    pacer.start()
    wall0 = time.monotonic()
    lag_warned = False
    try:
        while not should_stop():
            if opts.max_seconds is not None and time.monotonic() - wall0 > opts.max_seconds:
                break
            bridge.poll()
            lag = twin.run_realtime_step(pacer, max_step_us=1_000)    # time advances here: toward wall time
            bridge.poll()
            if lag > 0.5 and not lag_warned:
                sys.stderr.write(f"humanoid-twin serve: running {lag:.2f} s behind real time\n")
                lag_warned = True
            if lag == 0:
                time.sleep(POLL_S)
    except KeyboardInterrupt as exc:
        # The stop that arrived after should_stop() was asked, raised where the twin was asked to
        # go on (Twin.advance_to: humanoid_twin/signals.check): the session ends as if the loop
        # had seen it, its outputs complete. (It raised out of serve: the CLI then discarded the
        # session's files, exit 143 with no serial log, when SIGTERM came during a poll.)
        if not (signals.is_signal(exc) and should_stop()):
            raise
    return 0
