"""``humanoid-twin serve``: the twin in real time behind a pty or a TCP port.

The first line on stdout is the port to open; any program that speaks the RS-232 bytes of
docs/protocol.md drives the twin from there, as it would drive the robot. One client at a time;
every client starts on a clean line; connects and leaves are logged on stderr (docs/serve.md).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from humanoid_twin.clock import RealTimePacer
from humanoid_twin.cycles import DEFAULT_PIC_MHZ
from humanoid_twin.faults import FaultInjector, FaultSpec
from humanoid_twin.master.supervisor import SupervisorConfig
from humanoid_twin.twin import Twin

POLL_S = 0.0005
DEFAULT_IDLE_TIMEOUT_S = 600.0


class ServeError(OSError):
    """``serve`` cannot listen where it was asked to (address in use, not an address here ...)."""


def _log(text: str) -> None:
    sys.stderr.write(f"humanoid-twin serve: {text}\n")
    sys.stderr.flush()


def serve(
    *,
    tcp_port: int | None = None,
    host: str = "127.0.0.1",
    seed: int = 0,
    tilt: float = 0.0,
    can_interface: str = "humanoid_twin",
    can_channel: str | None = None,
    should_stop: Callable[[], bool] = lambda: False,
    max_seconds: float | None = None,
    faults: tuple[FaultSpec, ...] = (),
    supervisor: SupervisorConfig | None = None,
    idle_timeout_s: float | None = DEFAULT_IDLE_TIMEOUT_S,
    log: Callable[[str], None] = _log,
    speed: float = 1.0,
    pic_mhz: float = DEFAULT_PIC_MHZ,
) -> int:
    """Serve until ``should_stop()`` (or ``max_seconds`` of wall time); returns an exit code.

    Raises :class:`ServeError` if the TCP address cannot be listened on (before the twin boots).
    """
    from humanoid_twin.bus.bridges import PtyBridge, TcpBridge
    from humanoid_twin.master.usart import FRAME_GAP_US, PROCESS_US

    twin = Twin(seed=seed, can_interface=can_interface, can_channel=can_channel, supervisor=supervisor,
                pic_mhz=pic_mhz)
    # Between two clients the line stays quiet longer than the Master's break-off gap and its
    # answer delay, and each client starts with the Master's receiver reset: no spliced frames,
    # no answer to somebody else's bytes.
    options = dict(log=log, on_session=twin.master.usart.usartResetRxBuff, idle_timeout_s=idle_timeout_s,
                   quiet_us=FRAME_GAP_US + PROCESS_US + 1_000)
    try:
        if tcp_port is not None:
            bridge = TcpBridge(twin.link, host=host, port=tcp_port, **options)
        else:
            bridge = PtyBridge(twin.link, **options)
    except OSError as exc:
        twin.close()
        where = f"{host} port {tcp_port}" if tcp_port is not None else "a pty"
        raise ServeError(exc.errno, f"cannot listen on {where}: {exc.strerror or exc}") from exc
    FaultInjector(twin, faults, seed).install()     # --fault: a client can practise recovery
    try:
        if tilt:
            from humanoid_twin.scenarios import tilt_profile

            twin.plant.set_tilt_profile(tilt_profile(tilt, 0.0))
        print(bridge.port_name, flush=True)
        idle = f"idle timeout {idle_timeout_s:g} s" if idle_timeout_s else "no idle timeout"
        pace = "" if speed == 1.0 else f", {speed:g}x real time"
        log(f"serving on {bridge.port_name}: one client at a time, {idle}{pace}")
        pacer = RealTimePacer(twin.clock, speed=speed)     # --speed: virtual seconds per wall second
        pacer.start()
        wall0 = time.monotonic()
        lag_warned = False
        while not should_stop():
            if max_seconds is not None and time.monotonic() - wall0 > max_seconds:
                break
            bridge.poll()
            lag = twin.run_realtime_step(pacer, max_step_us=1_000)
            bridge.poll()
            if lag > 0.5 and not lag_warned:
                sys.stderr.write(f"humanoid-twin serve: running {lag:.2f} s behind real time\n")
                lag_warned = True
            if lag == 0:
                time.sleep(POLL_S)
        return 0
    finally:
        bridge.close()
        twin.close()
