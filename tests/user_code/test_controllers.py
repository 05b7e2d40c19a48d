"""User controllers (docs/controllers.md): firmware laws plugged in from a package (--law, the
entry point group), a broken law stopped with a named error and a supervisor fault, and the
PC-side --host-controller loop."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
from helpers import REPO

from humanoid_twin.cli.main import main
from humanoid_twin.controllers import LAW_ENTRY_POINT_GROUP

LAWS = '''
from humanoid_twin.slave.laws import POSITION, VELOCITY, ControlLaw


class Push(ControlLaw):
    """Turns both foot front joints at a quarter degree per tick: the robot tips over."""

    output = VELOCITY
    needs_foot = True

    def step(self, inputs):
        return [0, 1 << 14, 0]


class Boom(ControlLaw):
    def step(self, inputs):
        return [0, 1 // 0, 0]


class Floaty(ControlLaw):
    def step(self, inputs):
        return [0.5, 0, 0]


class Pricey(ControlLaw):
    cycles = "a lot"


class Priceless(ControlLaw):
    cycles = 10**13          # more than a board's C arithmetic of microseconds would hold


class Sulky(ControlLaw):
    def cycles(self):
        raise RuntimeError("ask me later")


class TooFar(ControlLaw):
    output = POSITION

    def step(self, inputs):
        return [0, 120, 0]
'''


@pytest.fixture
def user_pkg(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A package of laws in a temporary directory, importable and with an entry point ``push``."""
    pkg = tmp_path / "ctl_user_laws"
    pkg.mkdir()
    (pkg / "__init__.py").write_text(textwrap.dedent(LAWS))
    dist = tmp_path / "ctl_user_laws-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: ctl-user-laws\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(f"[{LAW_ENTRY_POINT_GROUP}]\npush = ctl_user_laws:Push\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    return "ctl_user_laws"


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, dict, str]:
    code = main(["run", *argv, "--no-record", "--no-progress", "--json"])
    out, err = capsys.readouterr()
    summary = json.loads(out.strip().splitlines()[-1]) if code in (0, 3) else {}
    return code, summary, err


def test_a_user_law_from_a_package_selected_by_the_cli_changes_the_robot(user_pkg, capsys):
    code, default, _ = _run(capsys, "stand", "--duration", "5")
    assert code == 0 and not default["fell"] and default["cop_margin_min_mm"] > 50
    code, pushed, _ = _run(capsys, "stand", "--duration", "5", "--law", f"balance={user_pkg}:Push")
    assert pushed["fell"] and pushed["cop_margin_min_mm"] < 5
    # the same law found through the package's entry point
    code, by_name, _ = _run(capsys, "stand", "--duration", "5", "--law", "balance=push")
    assert by_name["fell"] and by_name["fell_at_s"] == pushed["fell_at_s"]


@pytest.mark.parametrize("law, why", [
    ("Boom", "step raised ZeroDivisionError"),
    ("Floaty", "the firmware computes with ints only"),
    ("TooFar", "position (degrees) 120 for servo 1, outside -90..90"),
])
def test_a_broken_law_is_stopped_by_name_the_board_holds_and_the_supervisor_faults(
        user_pkg, capsys, law, why):
    code, s, err = _run(capsys, "stand", "--duration", "4", "--law", f"balance={user_pkg}:{law}")
    assert code == 3 and s["mode"] == "safe"                           # the supervisor ended the run
    assert {f["name"] for f in s["faults"]} == {"law"} and {f["node"] for f in s["faults"]} == {1, 2}
    assert {f["scu"] for f in s["law_faults"]} == {1, 2}
    assert all(f["law"] == f"{user_pkg}:{law}" and why in f["reason"] for f in s["law_faults"])
    assert f"control law {user_pkg}:{law} stopped on SCU 1" in err and why in err
    assert not s["fell"] and s["trunk_tilt_max_deg"] < 1.0             # the boards held the servos


def test_bad_law_options_are_usage_errors_before_anything_is_written(user_pkg, capsys, tmp_path):
    out = tmp_path / "x.asc"
    for value, msg in [("balance", "expected TYPE=module:Class"),
                       ("sideways=ctl_user_laws:Push", "unknown control type"),
                       (f"balance={user_pkg}:Nope", "has no 'Nope'"),
                       ("balance=nopkg_xyz:Law", "cannot import"),
                       ("balance=not_installed", "an entry point of 'humanoid_twin.laws'")]:
        with pytest.raises(SystemExit) as exc:
            main(["run", "stand", "--no-record", "--can-log", str(out), "--law", value])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and msg in err, err
        assert not out.exists()


@pytest.mark.parametrize("law, msg", [("Pricey", "cycles must be a non-negative int"),
                                      ("Priceless", "up to 2147483647"),
                                      ("Sulky", "RuntimeError: ask me later")])
@pytest.mark.parametrize("cmd", [["run", "stand", "--no-record"], ["serve", "--tcp", "0"]])
def test_a_law_with_a_bad_cost_is_a_usage_error_in_run_and_serve(user_pkg, capsys, tmp_path, cmd, law, msg):
    out = tmp_path / "x.asc"
    with pytest.raises(SystemExit) as exc:
        main([*cmd, "--can-log", str(out), "--law", f"balance={user_pkg}:{law}"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and len(err.strip().splitlines()) == 1 and msg in err, err
    assert f"{user_pkg}:{law}" in err and not out.exists()




@pytest.mark.slow
def test_the_host_controller_example_holds_a_tilt_that_open_loop_does_not(capsys, monkeypatch):
    """examples/host_ankle_loop.py through --host-controller: the firmware laws off, the PC's
    loop over the serial toolbox holds 20 deg; the same run without it falls (13 deg is the
    limit without control, docs/balance.md)."""
    monkeypatch.chdir(REPO)
    code, off, _ = _run(capsys, "stand", "--control", "none", "--tilt", "20")
    assert off["fell"], off
    code, on, _ = _run(capsys, "stand", "--control", "none", "--tilt", "20",
                       "--host-controller", "examples.host_ankle_loop:step", "--host-period-ms", "20")
    assert code == 0 and not on["fell"] and on["cop_margin_min_mm"] > 15, on
    assert on["host_controller_calls"] == pytest.approx((on["duration_s"] - on["boot_s"]) / 0.02, abs=3)


@pytest.mark.slow
def test_the_firmware_law_example_holds_a_tilt(capsys, monkeypatch):
    """examples/cop_pd_law.py through --law: the plug-in runs on both leg boards (its own
    margin, not the built-in law's) and the robot stands a 20 deg tilt."""
    monkeypatch.chdir(REPO)
    code, builtin, _ = _run(capsys, "stand", "--tilt", "20")
    code, s, _ = _run(capsys, "stand", "--tilt", "20", "--law", "balance=examples.cop_pd_law:CopPD")
    assert code == 0 and not s["fell"] and s["cop_margin_min_mm"] > 20 and "law_faults" not in s, s
    assert s["cop_margin_min_mm"] != builtin["cop_margin_min_mm"]


def test_a_host_controller_that_raises_is_named(capsys, monkeypatch, tmp_path):
    (tmp_path / "ctl_bad_host.py").write_text("def step(ctx):\n    raise KeyError('oops')\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    code = main(["run", "stand", "--duration", "3", "--no-record", "--no-progress",
                 "--host-controller", "ctl_bad_host:step"])
    err = capsys.readouterr().err
    assert code == 1 and "host controller ctl_bad_host:step raised KeyError" in err, err
