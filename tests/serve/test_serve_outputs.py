"""``serve`` assembles its twin as ``run`` does (a :class:`~humanoid_twin.rig.Rig`): it records
(``--out``, ``--can-log``) and keeps complete files when stopped, checks its options as ``run``
does before anything is written, runs ``--law``, and tilts the platform once the robot has booted."""

from __future__ import annotations

import signal
import subprocess

import can
import pytest
from helpers import CLI

from humanoid_twin.recording.readback import read_rrd_rows, verify_rrd
from humanoid_twin.rig import Rig, RigOptions, boot

pytestmark = pytest.mark.slow       # subprocess-heavy: skipped by `pytest -m "not slow"` (README)


BOOT_CLIENT = """
import json, sys
from humanoid_twin.host import initcom, killcom, power_on
H, _ = initcom(sys.argv[1])
power_on(H, timeout=30)
print(json.dumps({"booted": True}))
killcom(H)
"""


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_serve_records_the_run_and_keeps_complete_files_when_stopped(serve, tmp_path, sig, code):
    out, log = tmp_path / "serve.rrd", tmp_path / "serve.asc"
    out.write_text("an earlier recording")          # replaced only by a complete one
    proc, port = serve("--tcp", "0", "--out", str(out), "--can-log", str(log), "--tilt", "2",
                       "--law", "balance=humanoid_twin.slave.laws:JacobianLaw", "--fault", "force-noise:1")
    assert serve.client(BOOT_CLIENT, port)["booted"]
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert "Traceback" not in err and f"wrote {out}" in err and f"wrote {log}" in err, err
    verify_rrd(out)
    assert read_rrd_rows(out)["robot/trunk_tilt_deg"] > 100     # 20 ms rows over the boot (2.65 s)
    with can.LogReader(str(log)) as reader:
        frames = sum(1 for _ in reader)
    assert frames > 2000                                        # ~3 800 frames per second
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize("args, message", [
    (["--out", "x.txt"], "must end in .rrd"),
    (["--can-log", "x.nope"], "--can-log"),
    (["--law", "balance=no_such_mod_xyz:Law"], "cannot import"),
    (["--tilt", "80"], "--tilt 80"),
    (["--seed", "-1"], "--seed -1"),
])
def test_serve_checks_its_options_as_run_does_before_writing(tmp_path, args, message):
    log = tmp_path / "kept.asc"
    r = subprocess.run([*CLI, "serve", "--tcp", "0", "--can-log", str(log), *args] if "--can-log" not in args
                       else [*CLI, "serve", "--tcp", "0", *args], capture_output=True, text=True, timeout=60,
                       cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == "", r
    assert len(r.stderr.strip().splitlines()) == 1 and message in r.stderr, r.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_tilt_starts_when_the_robot_has_booted() -> None:
    """serve's tilt ramp starts when the supervisor enters ``ready`` (a client's boot), as run's
    starts after its boot: flat through the boot, then 1 deg/s."""
    with Rig(RigOptions(tilt=2.0, monitor=False)) as rig:
        rig.tilt_after_ready()
        rig.twin.run_for(2.0)
        assert rig.twin.plant.tilt_deg == 0.0 and rig.boot_s is None      # nobody booted it: flat
        boot(rig.twin)                          # as a client boots it, through the serial port
        ready_s = rig.boot_s
        assert ready_s is not None and rig.twin.plant.tilt_deg < 0.1
        rig.twin.run_for(1.0)
        assert rig.twin.plant.tilt_deg == pytest.approx(rig.now_s - ready_s, abs=0.05)


def test_a_stop_that_arrives_between_the_loops_check_and_the_next_step_ends_the_session_cleanly(
        tmp_path) -> None:
    """SIGTERM handled while serve polled its port (after the loop's ``should_stop()``, before the
    twin's next step) was raised again by ``Twin.advance_to`` out of ``serve``: the CLI then
    exited 143 and discarded the session's files (the docs' replay found no ``session.serial``,
    seen in CI). Here the stop lands exactly there; serve must end as for any stop, its serial
    log complete."""
    from humanoid_twin import signals
    from humanoid_twin.recording.serial_log import read_log
    from humanoid_twin.serve import ServeOptions, serve

    asked = {"n": 0, "stop": False}

    def should_stop() -> bool:
        asked["n"] += 1
        if asked["n"] == 50:            # the signal's handler, run just after this check
            signals.stop_requested(signal.SIGTERM)
            asked["stop"] = True
            return False
        return asked["stop"]

    log = tmp_path / "s.serial"
    signals.user_code_runs()            # as the CLI: the laws may run from here to the rig's close
    try:
        code = serve(ServeOptions(tcp_port=0, serial_log=log), should_stop=should_stop,
                     announce=lambda line: None, log=lambda line: None)
    except KeyboardInterrupt as exc:    # (a KeyboardInterrupt would end pytest itself)
        pytest.fail(f"serve raised {type(exc).__name__} for a stop it was asked to make")
    finally:
        signals.user_code_done()
    assert code == 0 and asked["n"] == 51      # asked once more after the stop: not cut short
    meta, _ = read_log(log)
    assert meta["seed"] == 0                   # a complete log, its header written
