"""``humanoid-twin compare``: a CAN log drives the twin's Slaves, their Sensors frames are compared.

The "robot" is the twin itself: a log it wrote (``run flexao --can-log``), compared with the same
seed, gives every RMS exactly 0, on both cores; untidy copies of it (frames dropped, error frames,
other IDs, a clock offset, cut after the boot) are handled and counted; bad input is one line,
exit 2, and leaves an existing output alone.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import can
import pytest
from helpers import REPO

from humanoid_twin.compare import CompareOptions, compare_log, read_robot_log
from humanoid_twin.compare.robot_log import SENSORS_OF, robot_log_from_messages
from humanoid_twin.compare.signals import GROUPS
from humanoid_twin.core import PURE_PYTHON_ENV
from humanoid_twin.protocol import canframes

DURATION_S = "4"        # the boot (2.6 s) and the start of the squat: short, still every signal


def _cli(*args: str, env: dict[str, str] | None = None,
         cwd: Path | None = None) -> subprocess.CompletedProcess:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(REPO) + os.pathsep + e.get("PYTHONPATH", "")
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", *args], capture_output=True,
                          text=True, env=e, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def flexao_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 4 s flexao CAN log written by the twin (seed 0), as .blf."""
    d = tmp_path_factory.mktemp("robot")
    r = _cli("run", "flexao", "--duration", DURATION_S, "--no-record", "--can-log", "robot.blf", "--json",
             cwd=d)
    assert r.returncode == 0, r.stderr
    return d / "robot.blf"


def _all_zero(d: dict) -> None:
    assert d["frames_compared"] > 3000
    assert d["frames_missing"] == {"twin": 0, "log": 0}
    for g in GROUPS:
        assert d["rms"][g] == 0.0 and d["max_abs"][g] == 0.0, g
    assert all(s["rms"] == 0.0 for s in d["signals"].values() if s["n"])


@pytest.mark.parametrize("core", ["python", "compiled"])
def test_own_log_gives_zero_on_both_cores(flexao_log: Path, tmp_path: Path, core: str) -> None:
    env = {PURE_PYTHON_ENV: "1"} if core == "python" else {}
    if core == "compiled":
        v = _cli("--version")
        if "core: compiled" not in v.stdout:
            pytest.skip("no compiled core in this tree (scripts/build_core.py)")
    # the log written by this core, in three formats, and compared by it
    for suffix in (".blf", ".asc", ".log"):
        r = _cli("run", "flexao", "--duration", DURATION_S, "--no-record", "--can-log", f"own{suffix}",
                 "--json", env=env, cwd=tmp_path)
        assert r.returncode == 0, r.stderr
        r = _cli("compare", str(tmp_path / f"own{suffix}"), "--json", env=env)
        assert r.returncode == 0, r.stderr
        assert len(r.stdout.splitlines()) == 1
        _all_zero(json.loads(r.stdout))


def test_another_seed_differs(flexao_log: Path) -> None:
    """The comparison can fail: another seed (other sensor noise, other PWM phases) is seen."""
    result = compare_log(read_robot_log(flexao_log), CompareOptions(seed=5, phases="seed"))
    assert result.rms["position_deg"] > 0.0
    assert result.frames_missing["twin"] + result.frames_missing["log"] > 0


def test_phases_are_read_from_the_log(flexao_log: Path) -> None:
    """A robot's Slaves run at phases of their own: the twin of another seed reads them from the
    log's silent rounds and starts its Slaves there, so that it is silent in the same rounds; a
    log of its own seed keeps the seed's phases (and compares exactly)."""
    from humanoid_twin.twin import seed_phases

    r = _cli("compare", str(flexao_log), "--seed", "5", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["frames_missing"] == {"twin": 0, "log": 0}          # with --phases seed: hundreds
    assert {p["from"] for p in d["phases"].values()} >= {"log"}
    five = seed_phases(5)
    assert all(p["us"] == five[int(scu)] for scu, p in d["phases"].items() if p["from"] == "seed")
    assert "phases read from the log" in _cli("compare", str(flexao_log), "--seed", "5").stdout
    same = compare_log(read_robot_log(flexao_log), CompareOptions(seed=0))
    assert {src for _, src in same.phases.values()} == {"seed"}


def _messages(path: Path) -> list[can.Message]:
    with can.LogReader(path) as reader:
        return list(reader)


def test_untidy_log_is_counted_and_still_exact(flexao_log: Path) -> None:
    """Sensors frames dropped, error frames, other IDs (an extended one, a frame of the robot's ID
    with a wrong length) and an adapter's clock (seconds since 1970): counted, and what is left
    still compares exactly."""
    msgs = _messages(flexao_log)
    offset = 1_764_633_600.0
    out: list[can.Message] = []
    dropped = foreign = errors = 0
    for i, m in enumerate(msgs):
        m.timestamp += offset
        if m.arbitration_id in SENSORS_OF and i % 97 == 0:
            dropped += 1
            continue
        out.append(m)
        if i % 500 == 0:
            out.append(can.Message(timestamp=m.timestamp, arbitration_id=0x7F0, data=b"\x01\x02",
                                   is_extended_id=False))
            out.append(can.Message(timestamp=m.timestamp, arbitration_id=0x18DAF110, data=b"\x00" * 8))
            out.append(can.Message(timestamp=m.timestamp, arbitration_id=canframes.SENSOR_IDS[1][0],
                                   data=b"\x10\x00", is_extended_id=False))
            foreign += 3
        if i % 700 == 0:
            out.append(can.Message(timestamp=m.timestamp, is_error_frame=True))
            errors += 1
    log = robot_log_from_messages(out, "untidy")
    assert abs(log.clock_offset_s - offset) < 1e-3
    result = compare_log(log, CompareOptions(seed=0))
    assert result.frames_foreign == foreign
    assert result.error_frames == errors
    assert result.frames_missing == {"twin": 0, "log": dropped}
    assert all(v == 0.0 for v in result.rms.values())


def test_log_that_starts_after_the_boot(flexao_log: Path, tmp_path: Path) -> None:
    """A log cut 3 s in (every Slave calibrated, the squat under way): no traceback, the twin's
    own calibration rounds are counted as warm-up, the rest compared."""
    msgs = [m for m in _messages(flexao_log) if m.timestamp >= 3.0]
    cut = tmp_path / "cut.asc"
    with can.Logger(cut) as w:
        for m in msgs:
            w.on_message_received(m)
    r = _cli("compare", str(cut), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["started_after_boot"] is True
    assert d["frames_compared"] > 0
    assert d["rms"]["position_deg"] is not None


def test_out_overlays_twin_and_log(flexao_log: Path, tmp_path: Path) -> None:
    from humanoid_twin.recording.readback import read_rrd_entities, read_rrd_scalars

    out = tmp_path / "cmp.rrd"
    r = _cli("compare", str(flexao_log), "--seed", "5", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "position_deg" in r.stdout
    ents = read_rrd_entities(out)
    assert {"compare/position_deg/r_knee/twin", "compare/position_deg/r_knee/log"} <= ents
    t, v = read_rrd_scalars(out, "compare/position_deg/r_knee/log")
    assert len(t) > 100


def _one_line_exit2(r: subprocess.CompletedProcess, words: str) -> None:
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], r.stderr


def test_bad_input_is_one_line_exit_2(flexao_log: Path, tmp_path: Path) -> None:
    text = tmp_path / "notes.asc"
    text.write_text("this is not a CAN log\n")
    _one_line_exit2(_cli("compare", str(text)), "none of the robot's frames")
    junk = tmp_path / "junk.blf"
    junk.write_bytes(os.urandom(2000))
    _one_line_exit2(_cli("compare", str(junk)), "not a readable .blf CAN log")
    _one_line_exit2(_cli("compare", str(tmp_path / "missing.blf")), "no such file")
    # a log with the Slaves' frames only: nothing to drive the twin with
    sensors_only = tmp_path / "sensors.asc"
    with can.Logger(sensors_only) as w:
        for m in _messages(flexao_log)[:2000]:
            if m.arbitration_id in SENSORS_OF:
                w.on_message_received(m)
    _one_line_exit2(_cli("compare", str(sensors_only)), "no Master frame")
    # another machine's bus
    other = tmp_path / "other.asc"
    with can.Logger(other) as w:
        for i in range(50):
            w.on_message_received(can.Message(timestamp=i * 0.01, arbitration_id=0x123, data=b"\x00" * 8,
                                              is_extended_id=False))
    _one_line_exit2(_cli("compare", str(other)), "none of the robot's frames")
    # a failed run leaves an existing --out alone
    out = tmp_path / "keep.rrd"
    out.write_bytes(b"old")
    _one_line_exit2(_cli("compare", str(text), "--out", str(out)), "none of the robot's frames")
    assert out.read_bytes() == b"old"
    _one_line_exit2(_cli("compare", str(flexao_log), "--out", str(tmp_path / "x.txt")), "must end in .rrd")


def test_support_stand_holds_the_trunk_in_the_air(flexao_log: Path) -> None:
    """On a stand the twin's feet carry nothing while the robot's stood on them: the forces
    differ by the robot's weight; the trunk stays where it was put."""
    from humanoid_twin.plant.plant import HOLD_LIFT_MM
    from humanoid_twin.twin import Twin

    floor = compare_log(read_robot_log(flexao_log), CompareOptions(support="floor"))
    stand = compare_log(read_robot_log(flexao_log), CompareOptions(support="stand"))
    assert floor.rms["force_counts"] == 0.0
    assert stand.rms["force_counts"] > 5.0 and stand.frames_compared == floor.frames_compared
    with Twin(seed=0, master=False) as tw:
        z0 = float(tw.plant.data.qpos[2])
        tw.plant.hold_trunk()
        tw.advance_to(2_000_000)
        assert abs(float(tw.plant.data.qpos[2]) - (z0 + HOLD_LIFT_MM / 1000)) < 1e-5
