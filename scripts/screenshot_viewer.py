#!/usr/bin/env python3
"""Reproduce ``docs/img/rerun_view.png``: the rerun viewer showing a recorded flexao run.

Records ``humanoid-twin run flexao`` into a temporary ``.rrd``, starts rerun's own headless
viewer (``rerun --headless``, rerun-sdk 0.41; it renders offscreen through wgpu, so no screen is
needed, only a Vulkan driver: on a machine without GPU Mesa's lavapipe, Debian package
``mesa-vulkan-drivers``), opens the recording, pauses the time cursor in the middle of the
squat and asks the viewer for a screenshot (``rerun.experimental.ViewerClient``). The viewer
listens on 127.0.0.1 only and is stopped at the end. The PNG is reduced to a 256-colour
palette with Pillow when it is installed, to keep it small for the README.

    python scripts/screenshot_viewer.py [--out docs/img/rerun_view.png] [--time 3.5]
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "rerun_view.png")
    ap.add_argument("--time", type=float, default=3.5, help="sim_time of the screenshot, seconds")
    ap.add_argument("--size", default="1600x1000", help="viewer window size in points")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "flexao.rrd"
        subprocess.run(
            ["humanoid-twin", "run", "flexao", "--out", str(rrd), "--no-progress"],
            cwd=tmp, check=True, stdout=subprocess.DEVNULL,
        )
        port = free_port()
        with open(Path(tmp) / "viewer.log", "w") as log:
            # own session: the `rerun` entry point is a Python wrapper around the real binary,
            # so stop the whole process group, not just the wrapper
            proc = subprocess.Popen(
                ["rerun", "--headless", "--bind", "127.0.0.1", "--port", str(port),
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
