"""Issue 24, points 7 and 8: serve and view follow run's exit codes (130 on SIGINT, 143 on
SIGTERM); serve binds a non-loopback address only with --allow-remote, and then warns."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

import pytest
from helpers import CLI, default_signals

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)



@pytest.mark.parametrize("sig,code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_serve_exits_130_or_143_on_a_signal(serve, sig: int, code: int) -> None:
    proc, port = serve("--tcp", "0")
    assert port.startswith("socket://127.0.0.1:")
    proc.send_signal(sig)
    proc.wait(15)
    assert proc.returncode == code, proc.stderr.read()


def test_view_web_exits_143_on_sigterm(tmp_path: Path) -> None:
    rrd = tmp_path / "x.rrd"
    res = subprocess.run([*CLI, "run", "stand", "--duration", "3", "--no-progress", "--out", str(rrd)],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    proc = subprocess.Popen([*CLI, "view", "--web", "--port", "19391", str(rrd)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=default_signals)
    try:
        assert "rerun web viewer: http://127.0.0.1:19391" in proc.stdout.readline()
        time.sleep(1.0)
        proc.send_signal(signal.SIGTERM)
        proc.wait(20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143


@pytest.mark.parametrize("host", ["0.0.0.0", "::"])
def test_serve_on_a_network_address_needs_allow_remote(host: str) -> None:
    res = subprocess.run([*CLI, "serve", "--tcp", "0", "--host", host], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and "--allow-remote" in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and res.stdout == ""


def test_serve_with_allow_remote_warns_that_the_protocol_has_no_authentication(serve) -> None:
    proc, port = serve("--tcp", "0", "--host", "0.0.0.0", "--allow-remote")
    assert port.startswith("socket://0.0.0.0:")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=15)
    assert "no authentication" in err and "warning" in err
