"""The Master's mode supervisor (docs/supervisor.md): modes, detection of a silent Slave and of the
Master's bus-off within 50 ms, safe state holding the robot, emergency stop (PWM off on every
board within one 8 ms round), reset, the serial bytes, and the host's typed errors."""

from __future__ import annotations

import dataclasses
import time

import pytest
from helpers import wait_for_mode

from humanoid_twin.host import drivers
from humanoid_twin.host.motion import exe_traj, power_on
from humanoid_twin.host.planners import flexao
from humanoid_twin.master import supervisor as sv
from humanoid_twin.protocol import rs232
from humanoid_twin.scenarios import boot
from humanoid_twin.twin import Twin

DETECT_US = 50_000


def booted(seed: int = 0, **kw) -> tuple[Twin, object, list]:
    twin = Twin(seed=seed, **kw)
    events: list = []
    twin.master.supervisor.listeners.append(lambda kind, t, v: events.append((kind, t, v)))
    H = boot(twin)
    twin.run_for(0.05)
    return twin, H, events


def test_boot_goes_standby_self_check_ready_and_reads_on_the_wire() -> None:
    twin, H, events = booted()
    with twin:
        assert [v for k, _, v in events if k == "mode"] == [sv.SELF_CHECK, sv.READY]
        r = drivers.readsupervisor(H)
        assert (r.mode, r.fault, r.node, r.nfaults, r.error) == (2, 0, 0, 0, 0)
        assert r.rx == rs232.data_response(2, 0, 0, 0)
        assert r.mode_name == "ready" and r.fault_name is None
        # the raw bytes: FF C2 00 00 00 BCC -> FD 02 00 00 00 BCC; other D1 -> FC
        H.write(bytes([0xFF, 0xC2, 0, 0, 0, 0xFF ^ 0xC2]))
        assert H.read(6) == bytes([0xFD, 2, 0, 0, 0, 0xFD ^ 2])
        bad = bytes([0xFF, 0xC2, 3, 0, 0, 0xFF ^ 0xC2 ^ 3])
        H.write(bad)
        assert H.read(6) == rs232.status_response(bad, rs232.MESSAGE_INVREQ)


@pytest.mark.parametrize("scenario", ["stand", "flexao"])
@pytest.mark.parametrize("fault", ["silent", "bus_off"])
def test_silent_slave_and_master_bus_off_detected_within_50ms_safe_and_standing(scenario, fault) -> None:
    twin, H, events = booted(seed=1)
    with twin:
        t0 = twin.clock.now_us
        twin.clock.schedule(t0 + 300_000, lambda: inject())

        def inject() -> None:
            inject.t = twin.clock.now_us
            if fault == "silent":
                twin.network.silence("slave3")
            else:
                twin.network.force_bus_off("master")

        if scenario == "flexao":       # the fault strikes in the middle of the bend
            pos_apply, k, t = flexao(1.0, 10.0)
            exe_traj(H, t, pos_apply, 0.0, k=k)
        twin.run_for(1.5 - (twin.clock.now_us - t0) / 1e6)
        faults = [v for k, _, v in events if k == "fault"]
        code, node = (sv.SILENT, 3) if fault == "silent" else (sv.BUS_OFF_FAULT, 0)
        assert faults and (faults[0].code, faults[0].node) == (code, node)
        assert 0 <= faults[0].t_us - inject.t <= DETECT_US
        assert twin.master.supervisor.mode == sv.SAFE
        truth = twin.plant.truth()
        assert not truth.fell and truth.trunk_tilt_deg < 10
        # every board still drives its servos (PWM on): the safe state holds, it does not drop
        assert all(s.pic.pwm for s in twin.slaves.values())
        # a new APPLY is refused with a typed error naming the mode and the fault
        named = f"mode safe, latched fault {sv.FAULT_NAMES[code]}"
        with pytest.raises(drivers.SupervisorRefused, match=named):
            drivers.HumanoidClient(H).set_positions(1, [0, 0, 0])


def test_thresholds_are_read_when_a_config_is_set_and_a_config_cannot_change_in_place() -> None:
    """The supervisor reads its thresholds when it is given a config (the compiled round keeps
    them as C values): a new config set whole takes effect at the next round, and a config's
    fields cannot be changed under it (frozen), nor be anything but integers."""
    twin, H, events = booted()
    with twin:
        sup = twin.master.supervisor
        with pytest.raises(dataclasses.FrozenInstanceError):
            sup.config.host_link_ms = 100
        with pytest.raises(ValueError, match="silent_rounds must be an integer"):
            sv.SupervisorConfig(silent_rounds=2.5)
        with pytest.raises(ValueError, match="silent_rounds must be an integer"):
            sv.SupervisorConfig(silent_rounds=True)
        with pytest.raises(ValueError, match="balance_hold_ms must be an integer within"):
            sv.SupervisorConfig(balance_hold_ms=10**16)     # past a C long long in us
        twin.run_for(0.3)                     # no host frame for 300 ms: host_link is off
        assert sup.mode == sv.READY and not sup.faults
        sup.config = sv.SupervisorConfig(host_link_ms=100)
        twin.run_for(0.01)
        assert sup.mode == sv.SAFE and [f.name for f in sup.faults] == ["host_link"]


def test_estop_pwm_off_within_one_round_then_reset_and_power_on_back_to_ready() -> None:
    twin, H, events = booted(seed=2)
    with twin:
        r = drivers.estop(H)
        assert r.error == 0 and r.rx[0] == rs232.MESSAGE_SUCCESS
        t_stop = [t for k, t, v in events if k == "mode" and v == sv.ESTOP][0]
        twin.run_for(0.008 - (twin.clock.now_us - t_stop) / 1e6)
        assert not any(s.pic.pwm for s in twin.slaves.values())
        assert not any(twin.plant.servo_powered(k, i) for k in twin.slaves for i in range(3))
        # and every board's status (its next Sensors 1 answer) says PWM off
        assert not any(s.can.payload[0][7] & drivers.STATUS_PWM for s in twin.slaves.values())
        twin.run_for(0.02)
        for k in twin.slaves:
            assert not drivers.readjoint(H, k, 0).state & drivers.STATUS_PWM
        assert drivers.readsupervisor(H).mode == sv.ESTOP
        a = drivers.applyjoint(H, 1, 0, [0, 0, 0])
        assert a.error == drivers.ErrorCode.INVALID_REQUEST
        with pytest.raises(drivers.SupervisorRefused, match="mode estop"):
            drivers.raise_for_error(a, "apply", H)
        assert drivers.reset(H).error == 0
        assert drivers.readsupervisor(H).mode == sv.SELF_CHECK
        power_on(H)
        twin.run_for(0.05)
        assert drivers.readsupervisor(H).mode == sv.READY


# --- over a real pty / TCP port: humanoid-twin serve in another process ----------------------
@pytest.mark.parametrize("where", ["--pty", "--tcp"])
def test_estop_reset_power_on_over_serve(where, serve) -> None:
    proc, port = serve(*(["--tcp", "0"] if where == "--tcp" else ["--pty"]))
    try:
        with drivers.HumanoidClient(port, timeout=0.5) as robot:
            power_on(robot.serial_port, timeout=10.0)
            assert wait_for_mode(robot, "ready", 5) == "ready"
            robot.estop()
            sup = robot.supervisor()
            assert (sup.mode, sup.mode_name) == (4, "estop")
            time.sleep(0.02)                 # the boards' answers carry it from the next round on
            for k in range(1, 9):            # every board's status: PWM off
                assert not robot.read_status(k) & drivers.STATUS_PWM, k
            with pytest.raises(drivers.SupervisorRefused, match="mode estop") as exc:
                robot.set_positions(1, [0, 5, 0])
            assert exc.value.mode == 4
            robot.reset()
            assert robot.supervisor().mode_name == "self_check"
            power_on(robot.serial_port, timeout=10.0)
            assert wait_for_mode(robot, "ready", 5) == "ready"
            robot.set_positions(1, [0, 5, 0])   # accepted again
    finally:
        serve.stop(proc)


def test_serve_fault_a_client_sees_the_supervisor_refuse_the_boot(serve) -> None:
    proc, port = serve("--pty", "--fault", "silent:5")
    try:
        with drivers.HumanoidClient(port, timeout=0.5) as robot:
            with pytest.raises(drivers.SupervisorRefused, match="mode safe, latched fault silent on node 5"):
                power_on(robot.serial_port, timeout=10.0)
                time.sleep(0.3)
                robot.set_pwm(1, True)
            sup = robot.supervisor()
            assert (sup.mode_name, sup.fault_name, sup.node, sup.nfaults) == ("safe", "silent", 5, 1)
    finally:
        serve.stop(proc)


# A clean seeded run puts on the bus exactly what it did before the supervisor existed: the
# reference log of `humanoid-twin run flexao --seed 0 --can-log flexao_s0.asc`, made before this
# work. Compared: the .asc body after its 2-line header (the first line is the date), each line's
# tokens without the channel number (a process-wide counter, not the run's). The supervisor adds
# nothing on the bus (docs/supervisor.md). Renewed by issue 26: the body board's Sensors 2 bytes
# now carry its inclinometer and gyroscope (the only change of the log: tests/golden/test_golden.py).
FLEXAO_S0_ASC_SHA256 = "6ea13b12184e011d7eb0ba1da4079301b3ffdcaa27bf0b5441395dff1e432c99"


def _asc_digest(data: bytes) -> str:
    import hashlib

    out = []
    for line in data.decode().splitlines()[2:]:
        t = line.split()
        if len(t) > 2 and t[0].replace(".", "").isdigit():
            del t[1]
        out.append(" ".join(t))
    return hashlib.sha256("\n".join(out).encode()).hexdigest()


def test_clean_run_can_log_is_unchanged_by_the_supervisor(tmp_path) -> None:
    from humanoid_twin.scenarios import RunOptions, run

    log = tmp_path / "flexao_s0.asc"
    s = run(RunOptions(scenario="flexao", seed=0, progress=False, can_log=log))
    assert s["mode"] == "ready" and s["faults"] == []
    assert _asc_digest(log.read_bytes()) == FLEXAO_S0_ASC_SHA256
