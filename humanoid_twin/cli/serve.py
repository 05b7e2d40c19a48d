"""``humanoid-twin serve``: the twin in real time on a pty or a TCP port (docs/serve.md). Its
inputs are checked first (the rig's as ``run``'s, the address it listens on: one line, exit 2), its
outputs created under temporary names and renamed when it ends (Ctrl-C, SIGTERM)."""

from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

from humanoid_twin.cli.checked_outputs import CheckedOutputs
from humanoid_twin.cli.messages import say
from humanoid_twin.cli.options import check_rig_inputs, rig_fields, usage_error


def cmd_serve(args: argparse.Namespace) -> int:
    """``humanoid-twin serve``: real-time pacing, the port on the first stdout line; ``--out``,
    ``--can-log`` and ``--serial-log`` written under temporary names and renamed when serve ends
    (Ctrl-C, SIGTERM)."""
    from humanoid_twin import signals

    controllers, live = _check_serve_inputs(args)
    stop: dict[str, int | None] = {"signal": None}

    def _stop(signum: int, frame: object) -> None:
        stop["signal"] = stop["signal"] or signum
        signals.stop_requested(signum)     # a law that never returns: the process ends anyway

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    outputs = CheckedOutputs()
    signals.on_hard_exit(outputs.discard)     # a law that holds a signal back: nothing left behind
    try:
        files = outputs.open_all(args.out, args, 0.0)     # open-ended: the free-space margin only
        if args.viewer:             # the last check, the first thing started: the viewer's window
            live = _spawn_viewer()
        code = _serve(args, controllers, files, live, stop, outputs)
    finally:
        outputs.discard()
    # ended by a signal: 130 (SIGINT) or 143 (SIGTERM), as run (issue 24; it was 0)
    return 128 + stop["signal"] if stop["signal"] is not None else code


def _check_serve_inputs(args: argparse.Namespace) -> tuple[dict[str, Any], str | None]:
    """The rig's inputs (the same checks as run's, cli/options.py; the laws imported here), the
    address to listen on, the viewer to stream to (``--connect``). Returns the loaded controllers
    and the viewer's URL (None: none)."""
    from humanoid_twin import signals
    from humanoid_twin.recording.viewer import ViewerError, live_url

    signals.user_code_runs()        # the laws are imported here
    controllers = check_rig_inputs(args)        # the same checks as run's (cli/options.py)
    signals.user_code_done()        # (the viewer may take its time to start: not user code)
    if args.tcp is not None:
        _check_bind(args.host, args.tcp)
        _check_remote(args.host, args.allow_remote)
    try:
        live = live_url(args.connect) if args.connect is not None else None
    except ViewerError as exc:
        raise usage_error(str(exc)) from None
    return controllers, live


def _spawn_viewer() -> str:
    """rerun's native viewer started (``--viewer``); the URL to stream to."""
    from humanoid_twin.recording.viewer import ViewerError, spawn_live_viewer

    try:
        return spawn_live_viewer()[1]
    except ViewerError as exc:
        raise usage_error(str(exc)) from None


def _serve(args: argparse.Namespace, controllers: dict[str, Any], files: dict[str, Any], live: str | None,
           stop: dict[str, int | None], outputs: CheckedOutputs) -> int:
    """Serve until a signal (``stop``); the outputs renamed to their final names. The exit code."""
    from humanoid_twin import signals
    from humanoid_twin.controllers import LawError
    from humanoid_twin.recording.readback import RrdReadError
    from humanoid_twin.serve import ServeError, ServeOptions, serve

    opts = ServeOptions(**rig_fields(args, controllers), **files, live=live,
                        tcp_port=args.tcp, host=args.host, idle_timeout_s=args.idle_timeout or None,
                        speed=args.speed)
    signals.user_code_runs()    # the laws run in the twin from here to the rig's close
    if stop["signal"] is not None:      # a signal meanwhile: its grace starts now
        signals.stop_requested(stop["signal"])
    try:
        code = serve(opts, should_stop=lambda: stop["signal"] is not None,
                     announce=lambda line: say(args.stdout, line))
    except (ServeError, LawError) as exc:     # LawError: a law that cannot be made for every board
        raise usage_error(str(exc)) from None
    except (OSError, RrdReadError) as exc:
        sys.stderr.write(outputs.write_failed(exc))
        return 1
    outputs.commit()
    for path in outputs.final.values():
        sys.stderr.write(f"humanoid-twin serve: wrote {path}\n")
    return code


def _check_remote(host: str, allow: bool) -> None:
    """``--host`` is a loopback address unless ``--allow-remote`` (the protocol has no
    authentication: anyone who reaches the port can drive, e-stop or reset the robot)."""
    import ipaddress
    import socket

    try:
        infos = socket.getaddrinfo(host, None, 0, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
        addrs = {str(info[4][0]) for info in infos}
    except (socket.gaierror, UnicodeError) as exc:
        raise usage_error(f"--host {host}: not an address or a known host name ({exc})") from None
    remote = [a for a in addrs if not ipaddress.ip_address(a.split("%")[0]).is_loopback]
    if not remote:
        return
    if not allow:
        raise usage_error(f"--host {host} is reachable from other machines and the robot's protocol has "
                          "no authentication: add --allow-remote if that is what you want (docs/serve.md)")
    sys.stderr.write(f"humanoid-twin serve: warning: listening on {host}, reachable from the network; the "
                     "protocol has no authentication: anyone who reaches this port can drive, e-stop or "
                     "reset the robot\n")


def _check_bind(host: str, port: int) -> None:
    """The TCP address is one this machine can listen on, before the twin boots (exit 2 otherwise)."""
    import socket

    try:
        infos = socket.getaddrinfo(host, port, 0, socket.SOCK_STREAM, 0, socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        raise usage_error(f"--host {host}: not an address or a known host name ({exc})") from None
    family, _, _, _, addr = infos[0]
    try:
        with socket.socket(family, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(addr)
            s.listen(1)
    except OSError as exc:
        raise usage_error(f"--host {host} --tcp {port}: cannot listen: {exc.strerror or exc}") from None
