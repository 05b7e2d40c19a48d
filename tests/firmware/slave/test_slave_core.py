"""The Slave firmware on both cores (docs/architecture.md, "The compiled core"): the compiled
modules (slave/*.pxd) and the interpreted source give the same integers for the same inputs, a
user's Python law plugs into a compiled board as into an interpreted one, and what the recorder,
the monitor, the faults and the tests read from a board stays readable.

The trace below drives every module of the Slave (MyMATHS, DATA, PIC2, TRAJECTORY, SERVO with the
four built-in laws and two user laws, CAN's receive and sensor packets) through seeded random
inputs and collects every output; it runs here and in a subprocess on each core, and the three
traces must be equal.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from helpers import REPO

from humanoid_twin import core
from humanoid_twin.clock import Clock
from humanoid_twin.protocol.canframes import control_byte, pack_actuation1, pack_actuation2
from humanoid_twin.slave import can, data, database, laws, mymaths, pic2, servo, slave, trajectory
from humanoid_twin.slave.can import SlaveCan
from humanoid_twin.slave.database import Global
from humanoid_twin.slave.laws import POSITION, VELOCITY, ControlLaw, LawInputs, shr
from humanoid_twin.slave.pic2 import Pic2
from humanoid_twin.slave.servo import BALANCE_CONTROL, LOCOMOTION_CONTROL, ServoControl
from humanoid_twin.slave.trajectory import Trajectory

SLAVE_MODULES = (can, data, database, laws, mymaths, pic2, servo, slave, trajectory)


class PythonPD(ControlLaw):
    """A user's law as docs/controllers.md writes it: a Python subclass with state on self."""

    output = VELOCITY
    needs_foot = True

    def __init__(self) -> None:
        self.prev = 0
        self.starts: list[int] = []

    def start(self, servo: int, inputs: LawInputs) -> None:
        self.starts.append(servo)
        self.prev = 0

    def step(self, inputs: LawInputs) -> list[int]:
        if inputs.cop_mm is None:
            return [0, 0, 0]
        e = inputs.cop_error_mm[1]
        d = e - self.prev
        self.prev = e
        return [0, shr((e + 2 * d) << 10, 1), 0]


class DuckPosition:
    """A law that does not derive from ControlLaw: only ``output``, ``start`` and ``step``."""

    output = POSITION
    needs_foot = False

    def start(self, servo: int, inputs: Any) -> None:
        pass

    def step(self, inputs: Any) -> tuple[int, int, int]:
        pairs = zip(inputs.reference, inputs.measured, strict=True)
        return tuple(max(-90, min(90, r + m // 4)) for r, m in pairs)


def trace(seed: int = 7) -> list[Any]:
    """Every output of the Slave's modules for seeded random inputs (JSON-able)."""
    rng = random.Random(seed)
    out: list[Any] = []
    out.append([mymaths.seno(a) for a in range(-400, 400, 7)])
    out.append([mymaths.coseno(a) for a in range(-400, 400, 11)])
    for _ in range(200):
        f = [rng.randrange(128) for _ in range(4)]
        out.append(data.calcCoP(f))
    for _ in range(100):
        q = [rng.randrange(-90, 91) for _ in range(3)]
        out.append(data.jacobianMatrix(*q, signs=rng.choice([(1, 1, 1), (-1, 1, 1)])))
    out.append([data.divround(n, d) for n in range(-50, 50, 3) for d in (1, 2, 3, 7, 25)])
    out.append([pic2.position_from_adc(b, a) for b in (0, 512, 900) for a in range(0, 1024, 37)])
    out.append([pic2.median3(*(rng.randrange(-9, 9) for _ in range(3))) for _ in range(50)])
    out.append([laws.shr(v, n) for v in (-70000, -257, -1, 0, 1, 255, 70000) for n in (0, 1, 8, 16)])
    out.append([laws.balance_gain_bytes(kp, kd) for kp in (0, 1, 127, 128, 255) for kd in (0, 3, 15, 200)])
    # TRAJECTORY: cubic moves interrupted at random
    tr = Trajectory()
    for _ in range(300):
        refs = [rng.randrange(-100, 101) if rng.random() < 0.05 else t.theta_final for t in tr.traject]
        per = [rng.randrange(0, 120) for _ in range(3)]
        types = [rng.randrange(4) if rng.random() < 0.02 else t.control_type for t in tr.traject]
        restarted = tr.trajectory(refs, per, types, list(tr.position))
        out.append([restarted, list(tr.position), [tr.done(i) for i in range(3)]])
    # PIC2 with a scripted plant
    class Plant:
        def __init__(self) -> None:
            self.pwm: list[Any] = []

        def set_pwm(self, scu: int, pulses: Any) -> None:
            self.pwm.append(list(pulses))

        def read_servos(self, scu: int) -> tuple[list[int], list[int]]:
            return [rng.randrange(300, 700) for _ in range(3)], [rng.randrange(0, 1200) for _ in range(3)]

        def read_force_adc(self, scu: int) -> list[int]:
            return [rng.randrange(256) for _ in range(4)]

    plant = Plant()
    pic = Pic2(1, plant)
    pic.initPic()
    for k in range(120):
        if k == 20:
            pic.statusFilter(True)
        if k == 40:
            pic.setCalibration([500, 510, 490], [3, -2, 0, 5])
        pic.updateServoMeasures()
        pic.finalizeServoMeasures()
        pic.sampleExtraSensors()
        pic.statusPWM(k % 30 != 29)
        pic.servoActuation([rng.randrange(-100, 101) for _ in range(3)])
        out.append([list(pic.pos), list(pic.vel), list(pic.current), list(pic.special), list(pic.force7)])
    out.append(plant.pwm)
    # SERVO: the four laws, a user's Python law and a duck-typed one, on a leg board
    g = Global()
    sc = ServoControl(g.actuators, True, (-1, 1, 1), scu=1)
    user = PythonPD()
    for k in range(400):
        if k == 150:
            sc.set_law(BALANCE_CONTROL, user)
        if k == 300:
            sc.set_law(LOCOMOTION_CONTROL, DuckPosition())
        for c in g.actuators.control:
            c.kp, c.ki, c.kd = rng.randrange(256), rng.randrange(8), rng.randrange(4)
        types = [rng.randrange(4) for _ in range(3)] if k % 25 == 0 else list(sc.types)
        for i in range(3):
            sc.servoRequest(i, rng.randrange(-60, 61) if k % 10 == 0 else sc.reference[i])
        measured = [rng.randrange(-60, 61) for _ in range(3)]
        forces = [rng.randrange(128) for _ in range(4)]
        cop_x, cop_y = rng.randrange(-60, 61), rng.randrange(-90, 91)
        sc.controller(measured, cop_x, cop_y, rng.random() < 0.9, types, forces)
        out.append([list(sc.output), list(sc.last_v), list(sc.acc), list(sc.cop_f), sc.law_stopped])
    out.append(user.starts)
    # CAN: actuation packets in, sensor packets out
    g = Global()
    sl = SlaveCan(3, Clock(), g, 0)
    for _ in range(200):
        if rng.random() < 0.5:
            payload = pack_actuation1([rng.randrange(-128, 128) for _ in range(3)],
                                      [rng.randrange(256) for _ in range(3)],
                                      control_byte(rng.random() < 0.8, rng.random() < 0.3,
                                                   [rng.randrange(4) for _ in range(3)]), rng.randrange(256))
            ok = sl.receiveCanMessage(0, payload)
        else:
            ok = sl.receiveCanMessage(1, pack_actuation2([rng.randrange(256) for _ in range(3)],
                                                         [rng.randrange(256) for _ in range(3)],
                                                         rng.randrange(256), rng.randrange(256)))
        bad = sl.receiveCanMessage(0, bytes(rng.randrange(9)))
        s = g.sensors
        s.sysStatus.calib = rng.random() < 0.5
        s.sysStatus.motionFin[rng.randrange(3)] = rng.random() < 0.5
        for sv in s.servo:
            sv.pos, sv.vel = rng.randrange(-128, 128), rng.randrange(-128, 128)
            sv.current = rng.randrange(101)
        sl.watchdog = rng.random() < 0.1
        sl.prepareSensorPackets()
        a = g.actuators
        out.append([ok, bad, sl.calib_request, a.sysStatus.pwm, a.sysStatus.calib,
                    [(x.ref, x.speed) for x in a.servo], [(c.kp, c.kd, c.ki, c.type) for c in a.control],
                    sl.payload[0].hex(), sl.payload[1].hex(), sl.rx_packets, sl.rx_errors])
    return json.loads(json.dumps(out))


def _trace_in(core_name: str) -> list[Any]:
    env = dict(os.environ)
    env.pop(core.PURE_PYTHON_ENV, None)
    if core_name == "python":
        env[core.PURE_PYTHON_ENV] = "1"
    code = ("import json, sys; sys.path[:0] = sys.argv[1:3]; import test_slave_core as t; "
            "from humanoid_twin import core; print(core.core_kind()); print(json.dumps(t.trace()))")
    res = subprocess.run([sys.executable, "-c", code, str(Path(__file__).parent), str(REPO / "tests")],
                         env=env, cwd=REPO,
                         capture_output=True, text=True, timeout=300, check=True)
    kind, text = res.stdout.splitlines()[:2]
    if core_name == "python":
        assert kind == "python"
    return json.loads(text)


def test_both_cores_give_the_same_integers_as_this_process():
    here = trace()
    assert _trace_in("python") == here
    assert _trace_in("compiled") == here


def test_the_slave_modules_run_compiled_when_the_core_is():
    kinds = {m.__name__: core.is_compiled(m) for m in SLAVE_MODULES}
    if core.core_kind() == "python":
        assert not any(kinds.values()), kinds
    else:
        assert all(kinds.values()), kinds


def test_a_python_law_plugs_into_the_board_through_the_same_interface():
    g = Global()
    sc = ServoControl(g.actuators, True, (1, 1, 1), scu=2, clock=Clock())
    law = PythonPD()
    sc.set_law(BALANCE_CONTROL, law)
    assert sc.law(BALANCE_CONTROL) is law
    g.actuators.control[1].type = BALANCE_CONTROL
    sc.controller([0, 0, 0], 0, 30, True, [0, BALANCE_CONTROL, 0])
    assert law.starts == [1]                                  # started when servo 1 switched to it
    assert sc.last_v[1] == shr(-30 * 3 << 10, 1) >> 8 and sc.output[1] == -1
    duck = DuckPosition()
    sc.set_law(LOCOMOTION_CONTROL, duck)
    sc.servoRequest(0, 20)
    sc.controller([8, 0, 0], 0, 30, True, [LOCOMOTION_CONTROL, BALANCE_CONTROL, 0])
    assert sc.output[0] == 22 and sc.law_fault is None
    # a broken Python law is stopped, named, as on the interpreted board
    class Broken(ControlLaw):
        def step(self, inputs: LawInputs) -> list[int]:
            return [0, 1.5, 0]
    sc.set_law(BALANCE_CONTROL, Broken())
    sc.controller([8, 0, 0], 0, 30, True, [LOCOMOTION_CONTROL, BALANCE_CONTROL, 0])
    assert sc.law_stopped and sc.law_fault.law.endswith(":test_a_python_law_plugs_into_the_board_through_"
                                                          "the_same_interface.<locals>.Broken")
    assert "ints only" in sc.law_fault.reason


def test_what_others_read_from_a_board_stays_readable_and_the_faults_hooks_work():
    """The attributes docs/firmware.md lists (recorder, monitor, faults, scenarios, tests)."""
    from humanoid_twin.bus.network import CanNetwork

    class StubPlant:
        step_ns_total = 0

        def set_pwm(self, scu: int, pulses: Any) -> None:
            pass

    clock = Clock()
    net = CanNetwork(clock)
    b = slave.Slave(1, clock, StubPlant(), net, phase_us=0)
    for name in ("db", "sensors", "actuators", "traj", "servo", "calib", "pic", "can", "calibrated",
                 "commanded", "cop_x", "cop_y", "cop_loaded", "ticks", "deadline_violations",
                 "task_ns_total", "task_ns_max", "address", "clock", "plant", "network", "phase_us",
                 "has_foot"):
        getattr(b, name)
    for name in ("rx_packets", "rx_ignored", "rx_errors", "tx_packets", "tx_silent", "bus_off_recoveries",
                 "controller", "payload", "watchdog", "law_stopped", "last_rx_us", "calib_request"):
        getattr(b.can, name)
    for name in ("law_fault", "stopped_types", "law_stopped", "laws", "inputs", "last_v", "cop_f",
                 "cop_primed", "output", "reference", "types", "acc"):
        getattr(b.servo, name)
    assert b.sensors.sysStatus.pwm is False and b.traj.position == [0, 0, 0] and b.commanded == [0, 0, 0]
    assert repr(b.servo.inputs).startswith("LawInputs(scu=1")
    b.inject_deadline_violation(3000, 2)
    assert (b._delay_us, b._delay_ticks) == (3000, 2)
    with pytest.raises(ValueError):
        b.inject_deadline_violation(0)
