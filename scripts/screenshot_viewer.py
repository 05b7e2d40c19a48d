#!/usr/bin/env python3
"""Reproduce ``docs/img/rerun_view.png`` and ``docs/img/rerun_web.png``: the rerun viewer,
native and web, showing a recorded flexao run with the default blueprint.

Native: records ``humanoid-twin run flexao`` into a temporary ``.rrd``, starts rerun's own headless
viewer (``rerun --headless``, rerun-sdk 0.41; it renders offscreen through wgpu, so no screen is
needed, only a Vulkan driver: on a machine without a GPU, Mesa's lavapipe), opens the recording,
pauses the time cursor in the middle of the squat and asks the viewer for a screenshot
(``rerun.experimental.ViewerClient``). Web: serves the same file with ``humanoid-twin view --web``
and photographs the page in headless Chromium. Everything listens on 127.0.0.1 only and is stopped
at the end. (On a machine without WebGPU, headless Chromium with SwiftShader among them, rerun's web
viewer stays at "Loading ... 100%" with its default renderer; `view --web` prints a URL with
`&renderer=webgl`, which renders there: that is the URL photographed.) PNGs are reduced to a
256-colour palette with Pillow when it is installed.

What it needs (Debian/Ubuntu, as root)::

    apt-get update && apt-get install -y mesa-vulkan-drivers chromium

Run it with the project's interpreter; no activated venv is needed (every tool is started as
``sys.executable -m ...``)::

    .venv/bin/python scripts/screenshot_viewer.py [--time 3.5] [--only native|web]

The images go to the scratch folder ``out/`` by default; ``--out docs/img/rerun_view.png`` (and
``--web-out docs/img/rerun_web.png``) regenerate the docs' copies.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rerun.experimental import ViewerClient

ROOT = Path(__file__).resolve().parent.parent


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def connect(url: str, proc: subprocess.Popen, timeout_s: float = 60.0) -> ViewerClient:
    """Poll the freshly started viewer until it answers."""
    deadline = time.monotonic() + timeout_s
    while True:
        if proc.poll() is not None:
            raise RuntimeError(f"rerun viewer exited early with code {proc.returncode}")
        try:
            client = ViewerClient.connect(url)
            client.get_state()
            return client
        except Exception as exc:  # the server is not up yet
            if time.monotonic() > deadline:
                raise RuntimeError(f"rerun viewer did not answer at {url} within {timeout_s} s") from exc
            time.sleep(0.5)


def stop(proc: subprocess.Popen) -> None:
    """Stop the viewer's process group (wrapper and binary), politely first."""
    for sig, wait_s in ((signal.SIGTERM, 15.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(wait_s)
        except subprocess.TimeoutExpired:
            continue
        # the wrapper is gone; make sure the binary it started is gone too
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        return


def shrink(png: Path) -> None:
    """Quantize to a 256-colour palette (the viewer's flat UI loses nothing visible)."""
    try:
        from PIL import Image
    except ImportError:
        return
    with Image.open(png) as img:
        small = img.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    small.save(png, optimize=True)


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise SystemExit("no Chromium found: apt-get install -y chromium (see this script's docstring)")


def web_shot(rrd: Path, out: Path, size: str, tmp: Path, settle_s: float = 45.0) -> None:
    """``humanoid-twin view --web`` on ``rrd``, photographed by headless Chromium."""
    from humanoid_twin.recording.viewer import free_loopback_port

    port = free_loopback_port()
    proc = subprocess.Popen([sys.executable, "-m", "humanoid_twin.cli.main", "view", "--web", "--port",
                             str(port), str(rrd)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            text=True, start_new_session=True)
    try:
        line = proc.stdout.readline()
        url = next(w for w in line.split() if w.startswith("http://127.0.0.1"))
        time.sleep(2)
        w, h = size.split("x")
        out.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--enable-unsafe-swiftshader", f"--user-data-dir={tmp / 'chromium-profile'}",
             f"--window-size={w},{h}", f"--timeout={int(settle_s * 1000)}",
             f"--screenshot={out.resolve()}", url],
            check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=180,
        )
    finally:
        stop(proc)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "rerun_view.png")
    ap.add_argument("--time", type=float, default=3.5, help="sim_time of the screenshot, seconds")
    ap.add_argument("--web-out", type=Path, default=ROOT / "out" / "rerun_web.png")
    ap.add_argument("--size", default="1600x1000", help="viewer window size in points")
    ap.add_argument("--only", choices=("native", "web"), help="take one of the two screenshots")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "flexao.rrd"
        subprocess.run(
            [sys.executable, "-m", "humanoid_twin.cli.main", "run", "flexao", "--out", str(rrd)],
            cwd=tmp, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        if args.only in (None, "web"):
            web_shot(rrd, args.web_out, args.size, Path(tmp))
            shrink(args.web_out)
            print(f"wrote {args.web_out} ({args.web_out.stat().st_size} bytes)")
        if args.only == "web":
            return
        port = free_port()
        with open(Path(tmp) / "viewer.log", "w") as log:
            # own session: the `rerun` entry point is a Python wrapper around the real binary,
            # so stop the whole process group, not just the wrapper
            proc = subprocess.Popen(
                [sys.executable, "-m", "rerun", "--headless", "--bind", "127.0.0.1", "--port", str(port),
                 "--window-size", args.size, "--hide-welcome-screen"],
                stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
            )
            try:
                client = connect(f"rerun+http://127.0.0.1:{port}/proxy", proc)
                client.open(str(rrd))
                deadline = time.monotonic() + 60
                while client.get_state().loading:
                    if time.monotonic() > deadline:
                        raise RuntimeError("rerun viewer is still loading the recording after 60 s")
                    time.sleep(0.5)
                time.sleep(2)
                client.set_time("sim_time", duration=args.time, play_state="paused")
                time.sleep(3)  # let the views settle on the new time
                args.out.parent.mkdir(parents=True, exist_ok=True)
                client.save_screenshot(str(args.out.resolve()))
            finally:
                stop(proc)
    shrink(args.out)
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
