"""The boards take time (docs/firmware.md, "Cycle budget"; docs/controllers.md, "A law's cost"):
the PIC18 cycle budget of each pass, an overrun that sets the deadline flag and skips a tick,
the supervisor's deadline fault, a law's declared cost, and the trunk's inertial sensors."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from humanoid_twin import hardware
from humanoid_twin.cycles import DEFAULT_PIC_MHZ, LAW, SLAVE, instructions_per_s
from humanoid_twin.host import drivers
from humanoid_twin.protocol.canframes import unpack_sensors1, unpack_sensors2
from humanoid_twin.protocol.wire import STATUS_DEADLINE
from humanoid_twin.scenarios import RunOptions, boot, run, tilt_profile
from humanoid_twin.slave.laws import ControlLaw, JacobianLaw, LocomotionLaw
from humanoid_twin.twin import Twin


def _status(slave) -> int:
    """The status byte of the Sensors 1 packet the board answers with now."""
    return unpack_sensors1(slave.can.payload[0])[4]


def test_default_clock_budget_holds_with_room(booted_twin):
    """40 MHz (10 MIPS): every pass ends well inside its 20 ms (and inside the 2 ms PWM window,
    so it is seen as today), no deadline flag; the leg boards, which run the balance law, the
    CoP and four ADC channels, cost more than an arm board; the Master's slots fit."""
    twin, _ = booted_twin
    twin.run_for(0.5)
    ips = instructions_per_s(DEFAULT_PIC_MHZ)
    assert ips == 10_000_000
    for scu, s in twin.slaves.items():
        assert s.deadline_violations == 0 and s.ticks_skipped == 0
        assert not _status(s) & STATUS_DEADLINE
        assert 0 < s.task_us <= hardware.PWM_BUSY_US, (scu, s.task_us)
        assert s.task_load_max < 0.1
    assert twin.slaves[1].task_cycles > twin.slaves[6].task_cycles + SLAVE["calc_cop"]
    pic = twin.master.pic
    assert pic.slot_overruns == 0 and pic.slots_lost == 0 and 0 < pic.slot_load_max < 1


def test_an_overrun_sets_the_deadline_flag_and_skips_the_missed_tick():
    """At 0.5 MHz the first pass of a board takes more than its period: the ticks that come
    while it runs are skipped (the next waitTick returns at the following period), the flag
    is set when its period ends, the pass still running (issue 36: not when the pass ends, which
    may lie beyond the run), and the status byte the Master reads shows it from then on."""
    with Twin(seed=0, pic_mhz=0.5) as twin:
        s = twin.slaves[6]
        t0 = s.next_tick_us()
        twin.advance_to(t0)
        assert s.ticks == 1
        end = t0 + s.task_us
        assert s.task_us > hardware.PWM_PERIOD_US
        twin.advance_to(t0 + hardware.PWM_PERIOD_US - 1)
        assert not _status(s) & STATUS_DEADLINE and s.deadline_violations == 0
        twin.advance_to(t0 + hardware.PWM_PERIOD_US)
        assert _status(s) & STATUS_DEADLINE and s.deadline_violations == 1
        twin.advance_to(end)
        assert _status(s) & STATUS_DEADLINE and s.deadline_violations == 1     # counted once
        nxt = t0 + math.ceil((end - t0 + 1) / hardware.PWM_PERIOD_US) * hardware.PWM_PERIOD_US
        twin.advance_to(nxt - 1)
        assert s.ticks == 1 and s.ticks_skipped == (nxt - t0) // hardware.PWM_PERIOD_US - 1
        twin.advance_to(nxt)
        assert s.ticks == 2


def test_master_timer_overrun_delays_the_schedule():
    """A Master clocked so slowly that its slot work passes 250 us serves the next timer
    interrupt late and loses the ones after: fewer actuation frames leave in the same time."""
    counts = {}
    for mhz in (DEFAULT_PIC_MHZ, 0.5):
        with Twin(seed=0) as twin:
            pic = twin.master.pic
            pic.ips = instructions_per_s(mhz)       # the Master's clock (Master(..., pic_mhz=))
            twin.run_for(0.1)
            counts[mhz] = (twin.master.controller.frames_sent, pic.slot_overruns, pic.slots_lost)
    assert counts[DEFAULT_PIC_MHZ][1:] == (0, 0)
    assert counts[0.5][1] > 0 and counts[0.5][2] > 0
    assert counts[0.5][0] < counts[DEFAULT_PIC_MHZ][0] / 2


def test_a_quarter_of_the_clock_takes_four_times_as_long():
    """The same passes at 10 MHz and at 40 MHz: each board's largest task load (the summary's
    ``task_load_max``) is four times as large, within the rounding to whole microseconds."""
    loads = {}
    for mhz in (DEFAULT_PIC_MHZ, DEFAULT_PIC_MHZ / 4):
        with Twin(seed=0, pic_mhz=mhz) as twin:
            twin.run_for(0.3)
            loads[mhz] = {scu: s.task_load_max for scu, s in twin.slaves.items()}
    for scu, load in loads[DEFAULT_PIC_MHZ].items():
        assert 0 < load and loads[DEFAULT_PIC_MHZ / 4][scu] == pytest.approx(4 * load, abs=4e-4), scu


def test_too_slow_a_clock_ends_in_deadline_faults_and_exit_3(tmp_path):
    """``run stand --pic-mhz 0.5``: deadline misses, the supervisor's deadline fault (code 5),
    exit 3; the same run at the default clock has none."""
    def cli(*args: str) -> tuple[int, dict]:
        p = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "run", "stand", "--no-record",
                            "--json", "--no-progress", *args], capture_output=True, text=True, cwd=tmp_path,
                           timeout=300)
        return p.returncode, json.loads(p.stdout)

    code, s = cli("--pic-mhz", "0.5")            # the boot fails (5 s): the run goes on, safe
    assert code == 3 and s["mode"] == "safe"
    assert any(f["name"] == "deadline" and f["code"] == 5 for f in s["faults"])
    assert all(s["deadline_misses"][str(k)] > 0 for k in range(1, 9))
    assert s["task_load_max"]["slaves"] > 1
    code, s = cli("--duration", "4")
    assert code == 0 and s["mode"] == "ready"
    assert set(s["deadline_misses"].values()) == {0}
    assert 0 < s["task_load_max"]["slaves"] < 0.2 and 0 < s["task_load_max"]["master"] < 1


class _PricyBalance(JacobianLaw):
    """The balance law, declared at 250 000 cycles per call: 25 ms at 10 MIPS."""

    cycles = 250_000


class _CheapPid(LocomotionLaw):
    """The PID, declared with a method."""

    def cycles(self) -> int:
        return 100


class _Undeclared(ControlLaw):
    """A balance law that says nothing of its cost."""

    def step(self, inputs):
        return [0, 0, 0]


def test_a_law_too_expensive_for_the_pic_misses_its_deadlines():
    """stand runs the balance law on the leg boards: declared at 25 ms per call it overruns
    every tick there (not elsewhere), the supervisor latches ``deadline`` and goes safe."""
    s = run(RunOptions(scenario="stand", duration=4.0, progress=False, laws=(("balance", _PricyBalance),)))
    assert s["mode"] == "safe"
    assert {f["node"] for f in s["faults"] if f["name"] == "deadline"} <= {1, 2}
    assert any(f["name"] == "deadline" for f in s["faults"])
    assert s["deadline_misses"]["1"] > 0 and s["deadline_misses"]["2"] > 0
    assert s["deadline_misses"]["3"] == 0
    assert s["task_load_max"]["slaves"] > 1


def test_declared_and_default_law_costs(capsys):
    """A method's cost is used; a law that declares none is charged as the built-in law of its
    type, and the run says so once (not once per board)."""
    with Twin(seed=0) as twin:
        from humanoid_twin.controllers import install_laws

        install_laws(twin, {"locomotion": _CheapPid, "balance": _Undeclared})
        assert twin.slaves[1].servo.law_cost[1] == 100
        assert all(s.servo.law_cost[3] == LAW[3] for s in twin.slaves.values())
    err = capsys.readouterr().err
    assert err.count("declares no cost") == 1 and "_Undeclared" in err and f"{LAW[3]} cycles" in err


def test_a_bad_declared_cost_is_a_bad_law():
    class Bad(JacobianLaw):
        cycles = -5

    from humanoid_twin.controllers import LawError, install_laws

    with Twin(seed=0) as twin, pytest.raises(LawError, match="cycles"):
        install_laws(twin, {"balance": Bad})


def test_readspecial_of_the_body_board_gives_the_trunk_attitude():
    """readspecial(H, 5): inclinometer roll/pitch and gyroscope rates, 8-bit, decoded within
    the documented error of the truth (1 deg at rest: 0.25 deg quantisation, 0.25 deg noise);
    on a platform tilted to 6 degrees (3 deg/s) the trunk's pitch follows it. The bytes are the
    board's database and its Sensors 2 packet."""
    with Twin(seed=0) as twin:
        H = boot(twin)
        twin.plant.set_tilt_profile(tilt_profile(6.0, twin.now_s, 3.0))
        twin.run_for(2.5)
        r = drivers.readspecial(H, 5)
        assert r.error == 0
        roll, pitch, wr, wp = hardware.imu_from_counts(r.special)
        t_roll, t_pitch, _, _ = twin.plant.trunk_attitude_deg()
        assert abs(t_pitch) > 4                            # the robot leans with its platform
        assert abs(roll - t_roll) <= 1.0 and abs(pitch - t_pitch) <= 1.0, (r.special, t_roll, t_pitch)
        assert abs(wr) <= 5 and abs(wp) <= 5               # standing still
        assert list(r.special) == twin.master.db.sensors[5].special    # the Master's copy, from CAN
        board = twin.slaves[5]
        assert list(unpack_sensors2(board.can.payload[1])[3]) == board.sensors.special


@pytest.mark.parametrize("value", ["0", "41", "nan", "fast"])
def test_a_bad_clock_is_a_usage_error(tmp_path, value):
    """--pic-mhz outside what a PIC18F258 runs at (0.032..40 MHz): one line, exit 2, nothing written."""
    p = subprocess.run([sys.executable, "-m", "humanoid_twin.cli.main", "run", "stand", "--pic-mhz", value,
                        "--out", str(tmp_path / "r.rrd")], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "--pic-mhz" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())
