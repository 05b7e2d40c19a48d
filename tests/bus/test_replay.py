"""``humanoid-twin replay FILE`` (humanoid_twin/replay.py, cli/replay.py; docs/buses.md "Replay"):
a serial log of every fault kind replays; a log is data: records that contradict each other,
times beyond a simulated day, a meta the twin cannot be rebuilt from and laws the command line
does not name are one line and exit 2 before anything runs or is written; the re-recording
follows a run's output rules."""

from __future__ import annotations

import json
import math
import os
import subprocess
import textwrap
import time
from pathlib import Path

import pytest
from helpers import CLI

from humanoid_twin.cli.main import main
from humanoid_twin.faults import KINDS, parse_fault
from humanoid_twin.recording.serial_log import MAX_LOG_S, read_log
from humanoid_twin.replay import replay
from humanoid_twin.scenarios import RunOptions, run

# one fault of each kind, from the boot on or while the host still talks (flexao's motion)
FAULT_OF_KIND = {
    "can-drop": "can-drop:0.05",
    "can-corrupt": "can-corrupt:0.02",
    "silent": "silent:3@2.9",
    "bus-off": "bus-off:2@2.9",
    "serial-noise": "serial-noise:0.002",          # from 0: the host's first request is noisy
    "deadline": "deadline:1@2.9",
    "force-noise": "force-noise:3",
    "force-stuck": "force-stuck:1@2.8",
    "servo-stuck": "servo-stuck:1.2@2.8",
    "push": "push:30@3",
}


def _log(tmp: Path, name: str = "flexao.serial", **opts) -> Path:
    """A serial log of a short flexao run (the host reads and writes through the motion)."""
    path = tmp / name
    run(RunOptions(scenario="flexao", duration=4.0, serial_log=path, progress=False, **opts))
    return path


@pytest.fixture(scope="module")
def plain(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _log(tmp_path_factory.mktemp("replay"), seed=5)


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    """``humanoid-twin ARGV`` in this process: (exit code, stdout, stderr)."""
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _with_line(path: Path, tmp: Path, pick, change) -> tuple[Path, int]:
    """A copy of ``path`` whose first record line ``pick`` accepts is ``change(line)``; its number."""
    lines = path.read_text().splitlines(keepends=True)
    i = next(k for k, ln in enumerate(lines) if not ln.startswith("#") and pick(ln))
    bad = tmp / "bad.serial"
    bad.write_text("".join(lines[:i] + [change(lines[i])] + lines[i + 1:]))
    return bad, i + 1


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_a_serial_log_of_every_fault_kind_replays(kind: str, tmp_path: Path) -> None:
    assert set(FAULT_OF_KIND) == set(KINDS)           # a new kind gets its case here
    path = _log(tmp_path, faults=(parse_fault(FAULT_OF_KIND[kind]),), seed=13)
    meta, records = read_log(path)
    assert meta["faults"] == [FAULT_OF_KIND[kind]] and len(records) > 100
    res = replay(path)
    assert res.difference is None, res.difference
    assert res.twin_writes == res.logged_writes > 50


def test_the_command_checks_and_says_so(plain: Path, capsys) -> None:
    code, out, err = _cli(["replay", str(plain)], capsys)
    assert code == 0 and err == "", err
    assert out.startswith(f"{plain}: replayed ") and out.endswith("answer bytes match the log\n")
    code, out, err = _cli(["replay", str(plain), "--json"], capsys)
    assert code == 0 and out.count("\n") == 1
    result = json.loads(out)
    assert result["match"] is True and result["difference"] is None
    assert result["twin_writes"] == result["logged_writes"] > 50
    assert result["end_s"] == 4.0               # the run's end (the log's close), not its last byte
    code, out, err = _cli(["replay", str(plain), "--seed", "6"], capsys)     # another twin
    assert code == 1 and out == "" and err.count("\n") == 1 and "answers differ" in err, err


def test_a_changed_answer_is_exit_1_with_its_line(plain: Path, tmp_path: Path, capsys) -> None:
    bad, no = _with_line(plain, tmp_path, lambda ln: " twin>host " in ln and not ln.endswith(" 00\n"),
                         lambda ln: ln[:-3] + "00\n")        # its last byte, the BCC, changed
    code, _, err = _cli(["replay", str(bad)], capsys)
    assert code == 1 and f"line {no}, twin->host write 1:" in err, err


@pytest.mark.parametrize("change", ["end_us", "cut"])
def test_a_record_that_contradicts_the_log_is_exit_2_with_its_line(change: str, plain: Path, tmp_path: Path,
                                                                   capsys) -> None:
    """A host line whose end_us moved, or cut to 3 of its 6 bytes: its bytes end elsewhere (the
    replay fed the bytes and never read end_us: exit 0 before)."""
    def edit(ln: str) -> str:
        t, ev, end, *hexes = ln.split()
        if change == "end_us":
            return f"{t} {ev} {int(end) + 7} {' '.join(hexes)}\n"
        return f"{t} {ev} {end} {' '.join(hexes[:3])}\n"

    after_boot = lambda ln: " host>twin " in ln and int(ln.split()[0]) > 2_700_000       # noqa: E731
    bad, no = _with_line(plain, tmp_path, after_boot, edit)
    code, out, err = _cli(["replay", str(bad), "--out", str(tmp_path / "r.rrd")], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1, err
    assert f"bad.serial:{no}: the line contradicts the log: end_us" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.serial"]       # nothing written


def test_a_far_future_event_is_refused_at_once(plain: Path, tmp_path: Path, capsys) -> None:
    lines = plain.read_text().splitlines()
    for t_us in (MAX_LOG_S * 1_000_000 + 1, 10**15, int("9" * 4000)):
        bad = tmp_path / "far.serial"
        bad.write_text("\n".join([*lines, f"{t_us} host>twin {t_us + 573} ff c0 00 00 00 3f"]) + "\n")
        code, _, err = _cli(["replay", str(bad)], capsys)
        assert code == 2 and err.count("\n") == 1 and f"far.serial:{len(lines) + 1}:" in err, err


def _meta(plain: Path, tmp: Path, **change) -> Path:
    """``plain`` with its header's meta changed (a value None: the key removed)."""
    lines = plain.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.startswith("# meta "))
    meta = json.loads(lines[i][len("# meta "):])
    meta.update(change)
    bad = tmp / "meta.serial"
    bad.write_text("\n".join([*lines[:i], "# meta " + json.dumps(meta), *lines[i + 1:]]) + "\n")
    return bad


@pytest.mark.parametrize("change, said", [
    ({"can_interface": "socketcan", "can_channel": "vcan0"}, "--can-interface humanoid_twin"),
    ({"can_interface": "pcan"}, "opens no system CAN interface"),
    ({"can_channel": ["x"]}, "can_channel"),
    ({"tilt_from_s": "abc"}, "tilt_from_s"),
    ({"tilt_from_s": 1e300}, "tilt_from_s"),
    ({"tilt": math.nan}, "tilt"),
    ({"tilt": 80}, "tilt"),
    ({"seed": "3"}, "seed"),
    ({"seed": -1}, "seed"),
    ({"seed": True}, "seed"),
    ({"pic_mhz": 0}, "pic_mhz"),
    ({"faults": ["nope:1"]}, "unknown kind"),
    ({"faults": "can-drop:0.1"}, "faults"),
    ({"faults": ["can-drop:0.6", "can-corrupt:0.6"]}, "faults"),
    ({"supervisor": {"silent_rounds": "x"}}, "silent_rounds"),
    ({"supervisor": {"nope": 1}}, "nope"),
    ({"laws": [[9, "a:B"]]}, "laws"),
    ({"laws": [[[3], "a:B"]]}, "laws"),
])
def test_a_meta_the_twin_cannot_be_rebuilt_from_is_one_line_exit_2(change, said, plain: Path, tmp_path: Path,
                                                                    capsys) -> None:
    code, out, err = _cli(["replay", str(_meta(plain, tmp_path, **change))], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and said in err, err


def test_a_socketcan_log_replays_on_the_twins_own_wire(plain: Path, tmp_path: Path, capsys) -> None:
    bad = _meta(plain, tmp_path, can_interface="socketcan", can_channel="vcan0")
    code, out, err = _cli(["replay", str(bad), "--can-interface", "humanoid_twin"], capsys)
    assert code == 0 and "match the log" in out, err


@pytest.mark.parametrize("what", ["empty", "directory", "binary", "nul", "not ascii", "long line", "fifo",
                                  "missing", "meta not an object", "meta twice", "line settings",
                                  "end before a line", "a line after the end"])
def test_a_hostile_file_is_one_line_exit_2(what: str, plain: Path, tmp_path: Path, capsys) -> None:
    f = tmp_path / "x.serial"
    head = plain.read_text().splitlines()[:4]
    if what == "empty":
        f.write_bytes(b"")
    elif what == "directory":
        f.mkdir()
    elif what == "binary":
        f.write_bytes(os.urandom(1 << 20))
    elif what == "nul":
        f.write_text("\n".join(head) + "\n12 host>twin 585 ff\x00 05\n")
    elif what == "not ascii":
        f.write_text("\n".join(head) + "\n12 host>twin 585 ff é5\n", encoding="utf-8")
    elif what == "long line":
        f.write_text("\n".join(head) + "\n0 host>twin 1 " + "ff " * 30_000 + "\n")
    elif what == "fifo":
        os.mkfifo(f)                            # nobody writes: opening it would block for ever
    elif what == "meta not an object":
        f.write_text("\n".join([*head, "# meta [1, 2]"]) + "\n")
    elif what == "meta twice":
        f.write_text("\n".join([*head, '# meta {"seed": 6}']) + "\n")
    elif what == "end before a line":
        f.write_text("\n".join([*head, "0 host>twin 573 ff c0 00 00 00 3f",
                                "600 twin>host 1173 fa f9 f8 f7 f6 f5", '# meta {"end_us": 300}']) + "\n")
    elif what == "a line after the end":
        f.write_text("\n".join([*head, "0 host>twin 573 ff c0 00 00 00 3f", '# meta {"end_us": 1000}',
                                "1100 host>twin 1673 ff c0 00 00 00 3f"]) + "\n")
    elif what == "line settings":
        f.write_text("\n".join([head[0], "# line 9600 8N1; times in virtual microseconds", *head[2:]]) + "\n")
    code, out, err = _cli(["replay", str(f), "--out", str(tmp_path / "r.rrd")], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and "Traceback" not in err, err
    assert not (tmp_path / "r.rrd").exists()


def test_a_log_never_runs_a_law_the_command_line_does_not_name(tmp_path: Path) -> None:
    """The meta names ``mylaw:MyLaw``: the replay imports it only with ``--law balance=mylaw:MyLaw``
    (its import leaves a file behind); a law the log names that no one gives (``os:abort``) is
    never imported either."""
    (tmp_path / "mylaw.py").write_text(textwrap.dedent("""
        import pathlib

        from humanoid_twin.slave.laws import JacobianLaw

        pathlib.Path("imported").touch()


        class MyLaw(JacobianLaw):
            pass
    """))
    log = tmp_path / "law.serial"
    r = subprocess.run([*CLI, "run", "flexao", "--duration", "3.5", "--law", "balance=mylaw:MyLaw",
                        "--serial-log", str(log), "--no-record", "--no-progress"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0 and read_log(log)[0]["laws"] == [[3, "mylaw:MyLaw"]], r.stderr
    (tmp_path / "imported").unlink()
    r = subprocess.run([*CLI, "replay", str(log)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "--law balance=mylaw:MyLaw" in r.stderr
    assert not (tmp_path / "imported").exists()
    r = subprocess.run([*CLI, "replay", str(log), "--law", "balance=humanoid_twin.slave.laws:JacobianLaw"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 2 and "another" in r.stderr and not (tmp_path / "imported").exists(), r.stderr
    r = subprocess.run([*CLI, "replay", str(log), "--law", "balance=mylaw:MyLaw"],
                       capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0 and "match the log" in r.stdout, r.stderr
    assert (tmp_path / "imported").exists()
    text = log.read_text().replace('"mylaw:MyLaw"', '"os:abort"')
    (tmp_path / "abort.serial").write_text(text)
    r = subprocess.run([*CLI, "replay", "abort.serial"], capture_output=True, text=True, timeout=120,
                       cwd=tmp_path)
    assert r.returncode == 2 and "--law balance=os:abort" in r.stderr, r.stderr


def test_a_law_named_and_not_logged_is_refused(plain: Path, capsys) -> None:
    code, _, err = _cli(["replay", str(plain), "--law", "balance=humanoid_twin.slave.laws:JacobianLaw"],
                        capsys)
    assert code == 2 and "records no law for balance" in err, err


def test_the_replay_records_as_a_run_does(plain: Path, tmp_path: Path, capsys) -> None:
    from humanoid_twin.recording.readback import read_rrd_rows, verify_rrd

    out, canlog = tmp_path / "r.rrd", tmp_path / "r.asc"
    out.write_text("an earlier recording")
    code, _, err = _cli(["replay", str(plain), "--out", str(out), "--can-log", str(canlog)], capsys)
    assert code == 0 and f"wrote {out}" in err and f"wrote {canlog}" in err, err
    verify_rrd(out)
    assert read_rrd_rows(out)["robot/trunk_tilt_deg"] > 50
    assert canlog.read_text().count(" Rx ") > 1000
    # answers that differ: exit 1, and the recording of what the twin did is written all the same
    code, _, err = _cli(["replay", str(plain), "--seed", "6", "--out", str(out)], capsys)
    assert code == 1 and "answers differ" in err and f"wrote {out}" in err, err
    # a bad input: nothing replaced
    before = out.read_bytes()
    code, _, err = _cli(["replay", str(plain), "--out", str(out), "--seed", "-1"], capsys)
    assert code == 2 and out.read_bytes() == before
    code, _, err = _cli(["replay", str(plain), "--out", str(tmp_path / "r.txt")], capsys)
    assert code == 2 and ".rrd" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.asc", "r.rrd"]


def test_a_long_silence_is_bounded_by_wall_timeout(plain: Path, tmp_path: Path, capsys) -> None:
    """A log whose last line is an hour on (a valid time): ``--wall-timeout`` ends the replay
    (between two 0.1 s steps of a silence), one line, exit 1, nothing written."""
    long = tmp_path / "long.serial"
    lines = [ln for ln in plain.read_text().splitlines() if '"end_us"' not in ln]
    long.write_text("\n".join([*lines, "3600000000 host>twin 3600000573 ff c0 00 00 00 3f"]) + "\n")
    out = tmp_path / "r.rrd"
    t0 = time.monotonic()
    code, stdout, err = _cli(["replay", str(long), "--wall-timeout", "2", "--out", str(out)], capsys)
    assert code == 1 and stdout == "" and err.count("\n") == 1 and "--wall-timeout" in err, err
    assert time.monotonic() - t0 < 30
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.serial"]


def test_an_output_that_is_the_log_itself_is_refused(plain: Path, tmp_path: Path, capsys) -> None:
    """``replay run.log --can-log run.log`` (.log is a python-can format): the CAN log was renamed
    over the serial log it replayed (exit 0, the log lost)."""
    log = tmp_path / "run.log"
    log.write_bytes(plain.read_bytes())
    (tmp_path / "link.log").symlink_to(log)
    for argv in (["--can-log", str(log)], ["--can-log", str(tmp_path / "link.log")]):
        code, out, err = _cli(["replay", str(log), *argv], capsys)
        assert code == 2 and out == "" and "is the log being replayed" in err, err
        assert log.read_bytes() == plain.read_bytes()


def test_the_help_lists_the_command(capsys) -> None:
    code, out, _ = _cli(["--help"], capsys)
    assert code == 0 and "replay    replay a serial log" in out
    code, out, _ = _cli(["replay", "--help"], capsys)
    assert code == 0 and "--out FILE.rrd" in out and "--wall-timeout S" in out


def test_sigterm_keeps_what_was_recorded(plain: Path, tmp_path: Path) -> None:
    """SIGTERM in the middle of a replay (a log with an hour of silence): exit 143, one line, the
    recording closed whole under its final name, no temporary file left."""
    import signal

    from humanoid_twin.recording.readback import verify_rrd

    long = tmp_path / "long.serial"
    lines = [ln for ln in plain.read_text().splitlines() if '"end_us"' not in ln]
    long.write_text("\n".join([*lines, "3600000000 host>twin 3600000573 ff c0 00 00 00 3f"]) + "\n")
    out = tmp_path / "r.rrd"
    proc = subprocess.Popen([*CLI, "replay", str(long), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not any(p.name.startswith(".partial-") for p in tmp_path.iterdir()) and time.monotonic() < deadline:
        time.sleep(0.05)                  # the outputs exist: the replay is under way
    time.sleep(1.0)
    proc.send_signal(signal.SIGTERM)
    stdout, err = proc.communicate(timeout=60)
    assert proc.returncode == 143 and stdout == "" and err.count("\n") == 1, err
    assert f"terminated (SIGTERM); recorded so far: {out}" in err
    verify_rrd(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.serial", "r.rrd"]


@pytest.mark.parametrize("argv, said", [
    (["replay"], "the following arguments are required: FILE"),
    (["replay", "x.serial", "--bogus"], "unrecognized arguments: --bogus"),
    (["replay", "x.serial", "--can-interface", "socketcan"], "invalid choice: 'socketcan'"),
    (["replay", "x.serial", "--wall-timeout", "0"], "--wall-timeout"),
    (["replay", "x.serial", "--law", "balance"], "--law"),
])
def test_bad_options_are_one_line_exit_2(argv: list[str], said: str, plain: Path, capsys) -> None:
    code, out, err = _cli([argv[0], *[str(plain) if a == "x.serial" else a for a in argv[1:]]], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and said in err, err


def test_one_simulated_day_bounds_a_log_a_run_and_a_fault_alike() -> None:
    from humanoid_twin.faults import MAX_FAULT_S
    from humanoid_twin.limits import MAX_RUN_S
    from humanoid_twin.scenarios import MAX_DURATION_S

    assert MAX_LOG_S == MAX_DURATION_S == MAX_FAULT_S == MAX_RUN_S == 86_400
