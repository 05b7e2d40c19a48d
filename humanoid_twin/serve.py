"""``humanoid-twin serve``: the twin in real time behind a pty or a TCP port.

The first line on stdout is the port to open; any program that speaks the RS-232 bytes of
SPEC.md section 2 drives the twin from there, as it would drive the robot.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from humanoid_twin.clock import RealTimePacer
from humanoid_twin.faults import FaultInjector, FaultSpec
from humanoid_twin.master.supervisor import SupervisorConfig
from humanoid_twin.twin import Twin

POLL_S = 0.0005


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
) -> int:
    """Serve until ``should_stop()`` (or ``max_seconds`` of wall time); returns an exit code."""
    from humanoid_twin.bus.bridges import PtyBridge, TcpBridge

    twin = Twin(seed=seed, can_interface=can_interface, can_channel=can_channel, supervisor=supervisor)
    FaultInjector(twin, faults, seed).install()     # --fault: a client can practise recovery
    bridge = TcpBridge(twin.link, host=host, port=tcp_port) if tcp_port is not None else PtyBridge(twin.link)
    try:
        if tilt:
            from humanoid_twin.scenarios import tilt_profile

            twin.plant.set_tilt_profile(tilt_profile(tilt, 0.0))
        print(bridge.port_name, flush=True)
        pacer = RealTimePacer(twin.clock)
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
