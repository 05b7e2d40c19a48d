"""`humanoid-twin view --web`: rerun's web viewer served on loopback only, URL printed."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import pytest
from helpers import REPO

from humanoid_twin.recording.viewer import LOOPBACK, free_loopback_port, native_viewer_command


def _tiny_rrd(path) -> None:
    import rerun as rr

    rec = rr.RecordingStream("humanoid_twin_test")
    rec.save(path)
    rec.log("x", rr.Scalars(1.0))
    rec.flush()
    rec.disconnect()


def _listening_addresses(port: int) -> list[str]:
    out = subprocess.run(["ss", "-ltnH", f"sport = :{port}"], capture_output=True, text=True).stdout
    return [line.split()[3].rsplit(":", 1)[0] for line in out.splitlines() if line.strip()]


def test_view_web_answers_http_200_on_loopback_only(tmp_path):
    rrd = tmp_path / "t.rrd"
    _tiny_rrd(rrd)
    try:
        port = free_loopback_port()
    except OSError:
        pytest.skip("cannot open a loopback port here")
    proc = subprocess.Popen(
        [sys.executable, "-m", "humanoid_twin.cli.main", "view", "--web", "--port", str(port), str(rrd)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True,
    )
    try:
        first = proc.stdout.readline()
        assert f"http://{LOOPBACK}:{port}/" in first, first
        url = first.split()[3]
        status = None
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(url, timeout=2) as r:
                    status = r.status
                    break
            except OSError:
                time.sleep(0.2)
        assert status == 200
        addrs = _listening_addresses(port)
        if addrs:  # `ss` present: the HTTP server listens on loopback, not on every interface
            assert set(addrs) == {LOOPBACK}, addrs
        # nothing answers on a non-loopback address of this host
        other = socket.gethostbyname(socket.gethostname())
        if not other.startswith("127."):
            with pytest.raises(OSError):
                socket.create_connection((other, port), timeout=1).close()
        # SIGTERM to `humanoid-twin view` alone stops rerun's server too (nothing left listening)
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=15)
        deadline = time.monotonic() + 10
        while _port_open(port) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not _port_open(port), "rerun's web server outlived `view --web`"
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait(timeout=10)


def _port_open(port: int) -> bool:
    try:
        socket.create_connection((LOOPBACK, port), timeout=1).close()
        return True
    except OSError:
        return False


def test_native_view_binds_loopback_and_needs_a_display(tmp_path):
    rrd = tmp_path / "t.rrd"
    _tiny_rrd(rrd)
    cmd = native_viewer_command(rrd)
    assert cmd[cmd.index("--bind") + 1] == LOOPBACK
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    r = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "view", str(rrd)], env=env,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "view --web" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_view_web_on_a_busy_port_is_one_line_exit_2_and_no_url(tmp_path):
    """Issue 25: on a busy port `view --web` printed a URL that pointed at the other viewer, then
    exited 1."""
    rrd = tmp_path / "x.rrd"
    _tiny_rrd(rrd)
    with socket.socket() as busy:
        busy.bind((LOOPBACK, 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        r = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "view", "--web", "--port",
                            str(port), str(rrd)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and f"--port {port}: in use" in r.stderr


def test_the_web_url_asks_for_webgl() -> None:
    """Where WebGPU is missing (headless Chromium, no GPU) rerun's viewer stays at 'Loading';
    the printed URL asks for its WebGL renderer, which renders there."""
    from humanoid_twin.recording.viewer import web_url

    assert web_url(9090, 9876).endswith("&renderer=webgl")


def _screenshot_script():  # noqa: ANN202
    import importlib.util

    path = REPO / "scripts" / "screenshot_viewer.py"
    spec = importlib.util.spec_from_file_location("screenshot_viewer", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_view_web_renders_a_recording_in_headless_chromium(tmp_path):
    import shutil

    if not any(shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")):
        pytest.skip("no Chromium here (apt-get install -y chromium): the web viewer's drawing is not checked")
    pytest.importorskip("PIL.Image", reason="Pillow reads the screenshot")
    rrd = tmp_path / "stand.rrd"
    r = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "run", "stand", "--duration", "2.7",
                        "--out", str(rrd), "--no-progress"], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    shots = _screenshot_script()
    port = free_loopback_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "humanoid_twin.cli.main", "view", "--web", "--port", str(port), str(rrd)],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True,
    )
    png = tmp_path / "web.png"
    try:
        url = next(w for w in proc.stdout.readline().split() if w.startswith("http://"))
        assert "renderer=webgl" in url
        time.sleep(2)
        colours = shots.shoot_web(url, png, "1200,800", tmp_path / "profile", 120.0)
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(30) == 143
    # a canvas that stayed blank ("Loading ...") or the welcome page: a few hundred colours at most
    assert colours >= shots.DRAWN_MIN_COLOURS, f"{colours} colours in {png}: the web viewer drew nothing"
