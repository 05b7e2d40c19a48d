"""Open a recording in rerun's viewer, native or web, listening on loopback only.

``humanoid-twin view FILE.rrd`` runs the native viewer shipped with rerun-sdk; its own gRPC
server binds 127.0.0.1 (rerun's default, ``::``, would listen on every interface).
``humanoid-twin view --web FILE.rrd`` serves rerun's web viewer over HTTP on 127.0.0.1 and prints
the URL to open in a browser; the file is served by a gRPC server on 127.0.0.1 too. Nothing
listens beyond the machine. docs/recording.md, "Viewing".

Live (``serve --viewer`` / ``--connect``, docs/serve.md): :func:`spawn_live_viewer` starts the
native viewer with its gRPC server on a free loopback port, :func:`live_url` turns ``--connect``'s
address into a viewer's gRPC URL (loopback only) once something listens there; the recorder then
streams to it (``Recorder(stream_to=URL)``).
"""

from __future__ import annotations

import os
import pathlib
import signal
import socket
import subprocess
import sys

__all__ = ["LOOPBACK", "ViewerError", "check_port_free", "native_viewer_command", "web_viewer_command",
           "web_url", "view", "grpc_url", "live_url", "spawn_live_viewer", "DEFAULT_CONNECT"]

LOOPBACK = "127.0.0.1"
DEFAULT_WEB_PORT = 9090
DEFAULT_GRPC_PORT = 9876


class ViewerError(RuntimeError):
    """The viewer cannot start here (no display for the native viewer)."""


def _rerun() -> list[str]:
    # the ``rerun`` executable of the installed rerun-sdk, started directly (not through its
    # Python wrapper, which would not pass SIGTERM on), with or without an activated venv
    from humanoid_twin.recording.readback import rerun_executable

    return [str(rerun_executable())]


def native_viewer_command(path: str | pathlib.Path) -> list[str]:
    """The command line of the native viewer on ``path``, its server bound to loopback."""
    return [*_rerun(), "--bind", LOOPBACK, str(path)]


def web_viewer_command(path: str | pathlib.Path, web_port: int = DEFAULT_WEB_PORT,
                       grpc_port: int = DEFAULT_GRPC_PORT) -> list[str]:
    """The command line serving rerun's web viewer on ``path`` (HTTP ``web_port``, gRPC
    ``grpc_port``, both on 127.0.0.1)."""
    return [*_rerun(), "--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(web_port),
            "--port", str(grpc_port), str(path)]


def web_url(web_port: int = DEFAULT_WEB_PORT, grpc_port: int = DEFAULT_GRPC_PORT) -> str:
    """The URL that opens the served recording in a browser. It asks for rerun's WebGL renderer:
    the viewer's default, WebGPU, is missing in many browsers and on machines without a GPU
    (headless Chromium with SwiftShader stays at "Loading ... 100%"), where WebGL renders."""
    proxy = f"rerun%2Bhttp%3A%2F%2F{LOOPBACK}%3A{grpc_port}%2Fproxy"
    return f"http://{LOOPBACK}:{web_port}/?url={proxy}&renderer=webgl"


DEFAULT_CONNECT = f"{LOOPBACK}:{DEFAULT_GRPC_PORT}"     # rerun's own default viewer address
LIVE_VIEWER_START_S = 20.0      # the spawned viewer's gRPC server listens within this (wall s)


def grpc_url(host: str, port: int) -> str:
    """The rerun gRPC URL of a viewer listening on ``host``:``port``."""
    return f"rerun+http://{f'[{host}]' if ':' in host else host}:{port}/proxy"


def _listening(host: str, port: int, timeout_s: float = 1.0) -> bool:
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            return True
    except OSError:
        return False


# A rerun viewer's server speaks gRPC, over HTTP/2: to a client's connection preface it answers
# with its SETTINGS frame at once (RFC 9113 section 3.4; measured: 6 ms). rerun's own client
# (``set_sinks``) waits for that answer without a bound and without letting Python run (issue 36:
# ``--connect`` to a port held by something else hung at start-up, deaf to SIGTERM).
_H2_SETTINGS = 0x04             # the frame type of SETTINGS
# the preface, then an empty SETTINGS frame: length 0 (3 bytes), type, flags 0, stream 0 (4 bytes)
_H2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes(3) + bytes([_H2_SETTINGS]) + bytes(5)
VIEWER_ANSWER_S = 2.0           # a viewer answers the probe within this (wall s)


def _viewer_answers(host: str, port: int, timeout_s: float = VIEWER_ANSWER_S) -> bool | None:
    """None: nothing listens at ``host``:``port``; True: an HTTP/2 server answers (a rerun
    viewer's gRPC server); False: something else holds the port (it said something else, or
    nothing within ``timeout_s``)."""
    import time

    try:
        sock = socket.create_connection((host, port), timeout=timeout_s)
    except OSError:
        return None
    with sock:
        deadline = time.monotonic() + timeout_s
        got = b""
        try:
            sock.sendall(_H2_PREFACE)
            while len(got) < 9 and time.monotonic() < deadline:
                sock.settimeout(max(0.01, deadline - time.monotonic()))
                chunk = sock.recv(9 - len(got))
                if not chunk:
                    break
                got += chunk
        except OSError:
            return False
    return len(got) == 9 and got[3] == _H2_SETTINGS


def live_url(addr: str) -> str:
    """``--connect``'s ``addr`` (``HOST:PORT``, ``PORT``, or ``rerun+http://HOST:PORT/proxy``) as
    a gRPC URL; :class:`ViewerError` (one line) when it is not a loopback address (the recording
    is not sent off the machine) or when nothing listens there."""
    import ipaddress
    from urllib.parse import urlsplit

    text = addr.strip()
    if "://" not in text:
        text = f"rerun+http://{text if ':' in text else f'{LOOPBACK}:{text}'}/proxy"
    try:
        parts = urlsplit(text)
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise ViewerError(f"--connect {addr}: not HOST:PORT or a rerun+http:// URL ({exc})") from None
    if parts.scheme not in ("rerun", "rerun+http") or not host or port is None:
        raise ViewerError(f"--connect {addr}: expected HOST:PORT (default {DEFAULT_CONNECT}) or "
                          "rerun+http://HOST:PORT/proxy")
    try:
        infos = socket.getaddrinfo(host, port, 0, socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise ViewerError(f"--connect {addr}: not an address or a known host name ({exc})") from None
    if not all(ipaddress.ip_address(info[4][0].split("%")[0]).is_loopback for info in infos):  # type: ignore[union-attr]  # an IP family's address is a str
        raise ViewerError(f"--connect {addr}: not a loopback address; the live recording is only sent "
                          f"to a viewer on this machine (e.g. {DEFAULT_CONNECT})")
    answers = _viewer_answers(host, port)
    if answers is None:
        raise ViewerError(f"--connect {addr}: no viewer listens there; start one first "
                          f"(rerun --bind {LOOPBACK} --port {port}), or use --viewer")
    if not answers:
        raise ViewerError(f"--connect {addr}: something listens there but it is not a rerun viewer (no "
                          f"gRPC answer within {VIEWER_ANSWER_S:g} s); start one on a free port "
                          f"(rerun --bind {LOOPBACK} --port N), or use --viewer")
    return grpc_url(host, port)


def spawn_live_viewer() -> tuple[subprocess.Popen, str]:
    """Start rerun's native viewer (its own process, left open when the caller ends) with its
    gRPC server on a free loopback port; returns the process and the URL to stream to, once it
    listens. :class:`ViewerError` without a display or when it does not start."""
    import time

    if not has_display():
        raise ViewerError("--viewer needs a display (DISPLAY/WAYLAND_DISPLAY unset): stream to a viewer "
                          "elsewhere on this machine with --connect, or record with --out and open it "
                          "later with `humanoid-twin view --web FILE.rrd`")
    port = free_loopback_port()
    proc = subprocess.Popen([*_rerun(), "--bind", LOOPBACK, "--port", str(port)], stdin=subprocess.DEVNULL,
                            start_new_session=True)       # Ctrl-C on serve does not close the window
    deadline = time.monotonic() + LIVE_VIEWER_START_S
    while not _listening(LOOPBACK, port, 0.2):
        if proc.poll() is not None or time.monotonic() > deadline:
            if proc.poll() is None:
                proc.kill()
            raise ViewerError(f"rerun's viewer did not start (exit code {proc.poll()}); without a usable "
                              "display use --connect or --out")
        time.sleep(0.1)
    return proc, grpc_url(LOOPBACK, port)


def check_port_free(port: int, what: str) -> None:
    """:class:`ViewerError` (one line) when TCP ``port`` is taken on 127.0.0.1: checked before a
    URL is printed, so that a busy port never prints a URL that would open another viewer."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((LOOPBACK, port))
        except OSError as exc:
            raise ViewerError(f"{what} {port}: in use on {LOOPBACK} ({exc.strerror or exc}; another "
                              "viewer?): pick a free one with --port N") from None


def has_display() -> bool:
    """True where a native window can open (always off Linux; on Linux an X or Wayland display)."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def free_loopback_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def view(path: str | pathlib.Path, *, web: bool = False, web_port: int = DEFAULT_WEB_PORT,
         grpc_port: int | None = None) -> int:
    """Run the viewer on ``path`` until it exits; its exit code. With ``web`` the URL is printed
    on stdout once rerun's server is started (Ctrl-C stops it); ``grpc_port`` None: a free
    loopback port."""
    if web:
        check_port_free(web_port, "--port")
        if grpc_port is None:
            grpc_port = free_loopback_port()
        else:
            check_port_free(grpc_port, "gRPC port")
        url = web_url(web_port, grpc_port)
        cmd = web_viewer_command(path, web_port, grpc_port)
    else:
        if not has_display():
            raise ViewerError("no display (DISPLAY/WAYLAND_DISPLAY unset): use `view --web FILE.rrd` "
                              "and open the printed URL in a browser")
        url = None
        cmd = native_viewer_command(path)
    proc: subprocess.Popen | None = None
    got: list[int] = []

    def _forward(signum: int, frame: object) -> None:   # SIGTERM/SIGHUP: stop rerun too, not orphan it
        got.append(signum)
        if proc is not None:
            proc.terminate()

    # the forwarder is in place before rerun starts and before the URL is printed: a SIGTERM
    # right after the URL (a script, a supervisor) stops rerun too, never orphans it
    old = {sig: signal.signal(sig, _forward) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        proc = subprocess.Popen(cmd)
        if got:
            proc.terminate()
        elif url is not None:
            print(f"rerun web viewer: {url}  (Ctrl-C to stop)", flush=True)
        code = proc.wait()
        # stopped by a signal: 128 + its number, as run does (143 for SIGTERM), not rerun's own code
        return 128 + got[0] if got else code
    except KeyboardInterrupt:      # Ctrl-C reaches rerun too (same process group)
        if proc is not None:
            proc.terminate()
            proc.wait(10)
        return 130
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        if proc is not None and proc.poll() is None:
            proc.kill()
