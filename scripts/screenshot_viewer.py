#!/usr/bin/env python3
"""Reproduce ``docs/img/rerun_view.png``, ``docs/img/rerun_tab_*.png`` and ``docs/img/rerun_web.png``:
the rerun viewer, native and web, showing a recorded flexao run with the default blueprint.

Native: records ``humanoid-twin run flexao`` into a temporary ``.rrd``, starts rerun's own headless
viewer (``rerun --headless``, rerun-sdk 0.41; it renders offscreen through wgpu, so no screen is
needed, only a Vulkan driver: on a machine without a GPU, Mesa's lavapipe), opens the recording,
pauses the time cursor in the middle of the squat and asks the viewer for a screenshot
(``rerun.experimental.ViewerClient``), then one per tab of the right column (``--tabs DIR``). For
the pictures only, the viewer's top bar is hidden (on a machine without a GPU it carries warning
badges, "Software rasterizer" and "Docker", that a user with a GPU does not see); the blueprint a
user gets is unchanged. Web: serves the same file with ``humanoid-twin view --web``
and photographs the page in headless Chromium, driven through its DevTools pipe: a picture every
2 s of wall time until the views are drawn (rerun's wasm bundle takes seconds to compile, tens on a
loaded machine; ``--timeout`` and ``--virtual-time-budget`` shot the "Loading ... 100%" or the
welcome page). Everything listens on 127.0.0.1 only and is stopped at the end. (On a machine
without WebGPU, rerun's web viewer stayed at "Loading ... 100%" with its default renderer in
earlier Chromium builds; `view --web` prints a URL with `&renderer=webgl`, which renders there:
that is the URL photographed. Debian's Chromium 156 draws both.) PNGs are cropped of the blank
strip the hidden top bar leaves and reduced to a 256-colour palette with Pillow when it is
installed (Pillow also tells a drawn page from a blank one).

What it needs (Debian/Ubuntu, as root)::

    apt-get update && apt-get install -y mesa-vulkan-drivers chromium   # Vulkan (lavapipe), Chromium

(Pillow comes with the ``analysis`` extra's matplotlib, or ``pip install pillow``.)

Run it with the project's interpreter; no activated venv is needed (every tool is started as
``sys.executable -m ...``)::

    .venv/bin/python scripts/screenshot_viewer.py [--time 3.5] [--only native|web] [--tabs DIR]

The images go to the scratch folder ``out/`` by default; ``--out docs/img/rerun_view.png
--tabs docs/img --web-out docs/img/rerun_web.png`` regenerates the docs' copies.
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
    """Crop the blank top strip and quantize to a 256-colour palette (the viewer's flat UI loses
    nothing visible)."""
    try:
        from PIL import Image
    except ImportError:
        return
    with Image.open(png) as img:
        rgb = img.convert("RGB")
    small = rgb.crop((0, _blank_top(rgb), rgb.width, rgb.height)).quantize(
        colors=256, method=Image.Quantize.MEDIANCUT)
    small.save(png, optimize=True)


def _blank_top(rgb: object) -> int:
    """Rows to crop at the top: the strip the hidden top bar leaves (rows of one colour inside the
    window's border), down to and including the separator line under it; 0 when there is none."""
    def colour(y: int) -> object:
        c = rgb.crop((10, y, rgb.width - 10, y + 1)).getcolors(1)
        return None if c is None else c[0][1]

    blank = colour(1)
    if blank is None:
        return 0
    for y in range(2, rgb.height // 10):
        c = colour(y)
        if c != blank:
            return y + 1 if c is not None else 0
    return 0


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise SystemExit("no Chromium found: apt-get install -y chromium (see this script's docstring)")


def drawn_colours(png: Path) -> int:
    """How many colours the page below the viewer's top bar shows (a blank, loading or welcome
    page: under a thousand, the welcome page 750; the views drawn: over 3000); -1 without Pillow."""
    try:
        from PIL import Image
    except ImportError:
        return -1
    with Image.open(png) as img:
        colours = img.convert("RGB").crop((0, 60, img.width, img.height)).getcolors(1 << 20)
    return len(colours or [])


DRAWN_MIN_COLOURS = 1500


class _DevTools:
    """Chromium's DevTools protocol over ``--remote-debugging-pipe`` (fd 3 in, fd 4 out, JSON
    messages ended by a NUL byte): no websocket library needed."""

    def __init__(self, args: list[str]) -> None:
        cmd_r, self._cmd_w = os.pipe()
        self._res_r, res_w = os.pipe()

        def fds() -> None:      # in the child: the pipe ends Chromium expects on fds 3 and 4
            os.dup2(cmd_r, 3)
            os.dup2(res_w, 4)

        # close_fds=False: the fds 3 and 4 made in fds() must survive (Python's own are not
        # inheritable, PEP 446, so nothing else leaks into Chromium)
        self.proc = subprocess.Popen([*args, "--remote-debugging-pipe"], preexec_fn=fds, close_fds=False,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True)
        os.close(cmd_r)
        os.close(res_w)
        self._buf = b""
        self._id = 0

    def call(self, method: str, params: dict | None = None, session: str | None = None,
             timeout_s: float = 60.0) -> dict:
        import json
        import select

        self._id += 1
        msg: dict = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._cmd_w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout_s
        while True:
            while b"\0" in self._buf:
                raw, self._buf = self._buf.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self._id:
                    if "error" in reply:
                        raise RuntimeError(f"{method}: {reply['error']}")
                    return reply.get("result", {})
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._res_r], [], [], left)[0]:
                raise RuntimeError(f"Chromium did not answer {method} within {timeout_s} s")
            chunk = os.read(self._res_r, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed its DevTools pipe")
            self._buf += chunk

    def close(self) -> None:
        try:
            self.call("Browser.close", timeout_s=10)
        except (RuntimeError, OSError):
            pass
        for fd in (self._cmd_w, self._res_r):
            os.close(fd)
        stop(self.proc)


def _page(png: Path) -> bytes:
    """The pixels below the viewer's top bar (whose latency figure changes while nothing else
    does); empty without Pillow."""
    try:
        from PIL import Image
    except ImportError:
        return b""
    with Image.open(png) as img:
        return img.convert("RGB").crop((0, 60, img.width, img.height)).tobytes()


def shoot_web(url: str, out: Path, size: str, profile: Path, settle_s: float = 90.0,
              stable: bool = False) -> int:
    """Open ``url`` in headless Chromium (WebGL on SwiftShader: no GPU needed) and photograph the
    page every 2 s of wall time until the views are drawn (:data:`DRAWN_MIN_COLOURS`) or
    ``settle_s`` has passed; returns :func:`drawn_colours` of the last picture (-1 without
    Pillow: one picture after ``settle_s / 3``). Wall time, not the page's virtual time: rerun's
    wasm bundle compiles for seconds, tens on a loaded machine. ``stable``: also wait until two
    pictures in a row are the same (the whole recording loaded, the time cursor at its end)."""
    import base64

    w, h = (int(v) for v in size.split(","))
    cdp = _DevTools([chromium(), "--headless=new", "--no-sandbox", "--enable-unsafe-swiftshader",
                     "--use-angle=swiftshader", "--disable-quic", "--no-first-run",
                     "--disable-background-networking", "--disable-component-update", "--disable-sync",
                     f"--user-data-dir={profile}", f"--window-size={w},{h}"])
    try:
        target = cdp.call("Target.createTarget", {"url": url})["targetId"]
        session = cdp.call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        cdp.call("Emulation.setDeviceMetricsOverride",
                 {"width": w, "height": h, "deviceScaleFactor": 1, "mobile": False}, session)
        out.parent.mkdir(parents=True, exist_ok=True)
        try:
            import PIL  # noqa: F401
            poll_s = 2.0
        except ImportError:
            poll_s = settle_s / 3
        deadline = time.monotonic() + settle_s
        before = None
        while True:
            time.sleep(poll_s)
            data = cdp.call("Page.captureScreenshot", {"format": "png"}, session)["data"]
            out.write_bytes(base64.b64decode(data))
            colours = drawn_colours(out)
            page = _page(out) if stable else None
            drawn = colours >= DRAWN_MIN_COLOURS and (not stable or page == before)
            if colours < 0 or drawn or time.monotonic() > deadline:
                return colours
            before = page
    finally:
        cdp.close()


def web_shot(rrd: Path, out: Path, size: str, tmp: Path, settle_s: float = 300.0) -> None:
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
        if 0 <= shoot_web(url, out, f"{w},{h}", tmp / "chromium-profile", settle_s, stable=True) \
                < DRAWN_MIN_COLOURS:
            raise RuntimeError(f"the web viewer drew nothing within {settle_s:g} s: {out}")
    finally:
        stop(proc)


def _slug(name: str) -> str:
    slug = "".join(c if c.isalnum() else "_" for c in name.lower().replace("&", "and")).strip("_")
    while "__" in slug:
        slug = slug.replace("__", "_")
    return slug


def web_tab_shots(rrd: Path, tabs: list[str], out_dir: Path, size: str, tmp: Path, prefix: str,
                  settle_s: float = 300.0) -> list[Path]:
    """The web viewer on ``rrd`` once per tab of ``tabs`` (by name), that tab shown: the recording
    served with a blueprint file (``.rbl``, the recording's own default layout with that tab
    active), which the viewer makes the active layout. ``out_dir/<prefix>_<tab>.png``."""
    from humanoid_twin.protocol.wire import SCUS
    from humanoid_twin.recording.blueprint import default_blueprint
    from humanoid_twin.recording.columns import master_groups
    from humanoid_twin.recording.viewer import free_loopback_port, web_url, web_viewer_command
    from humanoid_twin.twin import Twin

    with Twin(seed=0) as twin:
        masters = [path for path, _ in master_groups(twin)]
    written = []
    for tab in tabs:
        rbl = tmp / f"{_slug(tab)}.rbl"
        default_blueprint(SCUS, masters, active_tab=tab).save("humanoid_twin", rbl)
        port, grpc = free_loopback_port(), free_loopback_port()
        proc = subprocess.Popen([*web_viewer_command(rrd, port, grpc), str(rbl)], stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            time.sleep(3)
            out = out_dir / f"{prefix}_{_slug(tab)}.png"
            w, h = size.split("x")
            out.parent.mkdir(parents=True, exist_ok=True)
            profile = tmp / f"chromium-{_slug(tab)}"
            colours = shoot_web(web_url(port, grpc), out, f"{w},{h}", profile, settle_s, stable=True)
            if 0 <= colours < DRAWN_MIN_COLOURS:
                raise RuntimeError(f"the web viewer drew nothing within {settle_s:g} s: {out}")
            written.append(out)
        finally:
            stop(proc)
    return written


def _tabs_container(bp: dict) -> str:
    return next(k for k, v in bp.items() if v.get("ContainerBlueprint", {}).get("container_kind") == "Tabs")


def hide_top_panel(client: ViewerClient) -> dict:
    """The viewer's current blueprint with the top bar hidden, sent back; returns it."""
    bp = client.get_blueprint().blueprint
    bp["/top_panel"] = {"PanelBlueprint": {"state": "Hidden"}}
    client.set_blueprint(bp, of="recording")
    return bp


def tab_shots(client: ViewerClient, bp: dict, out_dir: Path) -> list[Path]:
    """One screenshot per tab of the right column but the first (the main picture shows it):
    ``rerun_tab_<name>.png`` in ``out_dir``."""
    tabs = _tabs_container(bp)
    written = []
    out_dir.mkdir(parents=True, exist_ok=True)
    for content in bp[tabs]["ContainerBlueprint"]["contents"][1:]:     # the first: the main picture
        name = bp[content]["ContainerBlueprint"].get("display_name", content.rsplit("/", 1)[-1])
        bp[tabs]["ContainerBlueprint"]["active_tab"] = content
        client.set_blueprint(bp, of="recording")
        time.sleep(3)  # let the new tab paint
        path = out_dir / f"rerun_tab_{_slug(name)}.png"
        client.save_screenshot(str(path.resolve()))
        written.append(path)
    return written


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "rerun_view.png")
    ap.add_argument("--time", type=float, default=3.5, help="sim_time of the screenshot, seconds")
    ap.add_argument("--web-out", type=Path, default=ROOT / "out" / "rerun_web.png")
    ap.add_argument("--size", default="1600x1000", help="viewer window size in points")
    ap.add_argument("--only", choices=("native", "web"), help="take one of the two screenshots")
    ap.add_argument("--tabs", type=Path, help="also one native screenshot per tab, into this folder")
    ap.add_argument("--scenario", default="flexao", help="the run photographed (default flexao; e.g. "
                    "examples/push_recovery.py:push_recovery, which falls)")
    ap.add_argument("--web-tabs", default="", metavar="NAME,NAME",
                    help="web viewer pictures with these tabs shown (e.g. Balance,Supervisor), into "
                    "the folder of --web-out, named after it and the tab; then no other picture")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        rrd = Path(tmp) / "run.rrd"
        scenario = args.scenario
        if ".py:" in scenario:          # a user's file: found from the temporary folder too
            where, _, name = scenario.rpartition(":")
            scenario = f"{Path(where).resolve()}:{name}"
        subprocess.run(
            [sys.executable, "-m", "humanoid_twin.cli.main", "run", scenario, "--out", str(rrd)],
            cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        if not rrd.is_file():
            raise SystemExit(f"run {args.scenario} wrote no recording")
        if args.web_tabs:
            tabs = [t.strip() for t in args.web_tabs.split(",") if t.strip()]
            for png in web_tab_shots(rrd, tabs, args.web_out.parent, args.size, Path(tmp), args.web_out.stem):
                shrink(png)
                print(f"wrote {png} ({png.stat().st_size} bytes)")
            return
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
                bp = hide_top_panel(client)
                time.sleep(3)  # let the views settle on the new time
                args.out.parent.mkdir(parents=True, exist_ok=True)
                client.save_screenshot(str(args.out.resolve()))
                tabs = tab_shots(client, bp, args.tabs) if args.tabs is not None else []
            finally:
                stop(proc)
    for png in (args.out, *tabs):
        shrink(png)
        print(f"wrote {png} ({png.stat().st_size} bytes)")


if __name__ == "__main__":
    main()
