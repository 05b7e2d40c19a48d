"""Module Slave: the main program of a Slave board (seed 000 section 3, fig. 6).

``main`` = ``initPic`` (peripherals, CAN, databases, the PWM timer), then the calibration, then the
20 ms loop. On the PIC the loop waits for each PWM period (``waitTick``); in the twin the timer is
an event on the lockstep clock every ``hardware.PWM_PERIOD_US`` from ``phase_us``, and the
calibration is a state machine run by the same tick (it counts ticks, as the manual's lists do).
The CAN receive interrupt (``lowISR``, module CAN) runs whenever a frame ends on the wire.
The board sees the robot only through the plant's servo/sensor calls (``set_pwm``, ``read_servos``,
``read_force_adc``); the plant runs the physics due up to the clock's now itself (``Plant.bind_clock``).

Tick order (docs/firmware.md, "Slave"), at the start of each PWM period:

1. ``checkCan`` (bus-off recovery); deadline check;
2. ``updateServoMeasures`` / ``finalizeServoMeasures`` (period that ended: positions, filtered;
   velocities; currents), ``sampleExtraSensors`` (force), ``calcCoP`` on a leg board;
3. a Calib request (control byte bit 6, 0 -> 1, latched by ``lowISR``) restarts ``calibration``;
   while not calibrated, one step of ``calibration``;
4. once calibrated: ``statusPWM`` from the actuation database, ``trajectory``, ``servoRequest``,
   ``controller``, ``servoActuation`` (the pulses of the new period);
5. the sensor database and status bits (motion finished, deadline), and the two sensor packets
   that ``lowISR`` answers with until the next tick.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from humanoid_twin.clock import Clock
from humanoid_twin.cycles import DEFAULT_PIC_MHZ, SLAVE, check_pic_mhz, cycles_to_us, instructions_per_s
from humanoid_twin.hardware import FOOT_OF_SCU, N_SERVOS, N_SPECIAL_SENSORS, PWM_BUSY_US, PWM_PERIOD_US
from humanoid_twin.protocol.wire import check_scu
from humanoid_twin.slave.can import SlaveCan
from humanoid_twin.slave.data import calcCoP
from humanoid_twin.slave.database import Global
from humanoid_twin.slave.pic2 import Pic2
from humanoid_twin.slave.servo import LOCOMOTION_CONTROL, Calibration, ServoControl
from humanoid_twin.slave.trajectory import Trajectory

if TYPE_CHECKING:
    from humanoid_twin.bus.network import CanNetwork
    from humanoid_twin.plant.plant import Plant

__all__ = ["LEG_SIGNS", "MOTION_FIN_TOL_DEG", "MOTION_FIN_STILL_TICKS", "WATCHDOG_TICKS", "Slave"]

# CAN watchdog (docs/supervisor.md): no actuation packet for this many ticks -> the board holds
# its last reference (it keeps driving the last actuation it received) and says so in SFlags
# bit 2 of its Sensors 1 packets, until a packet arrives again.
WATCHDOG_TICKS = 5

# Servo angle -> kinematic angle of the leg seen from the foot (docs/firmware.md, "DATA"):
# (foot lateral, foot front, knee) of leg boards 1 and 2. A firmware constant per board, as the
# PIC had it compiled in. The robot's joint axes are roll about +x forward, pitch about +y left
# (docs/model.md); the leg seen from the foot turns the other way round the roll axis than the
# foot seen from the leg, and the left roll servo is mounted mirrored (servo = -joint), hence
# right (-1, 1, 1), left (1, 1, 1). tests/firmware/slave/test_slave_board.py checks them against the model.
LEG_SIGNS: dict[int, tuple[int, int, int]] = {1: (-1, 1, 1), 2: (1, 1, 1)}

# Motion finished (status bits 0-2): the trajectory is done and the servo is within this many
# degrees of its target, or has stopped (zero mean velocity) for this many ticks.
MOTION_FIN_TOL_DEG = 1
MOTION_FIN_STILL_TICKS = 2

# The cycle table's entries the loop charges (humanoid_twin/cycles.py, docs/firmware.md)
_C_LOOP = SLAVE["loop"] + N_SERVOS * SLAVE["measure_servo"] + SLAVE["status"] + SLAVE["packets"] \
    + SLAVE["pwm_period"]
_C_SPECIAL = N_SPECIAL_SENSORS * SLAVE["adc_channel"]
_C_COP = SLAVE["calc_cop"]
_C_CALIB = SLAVE["calibration"]
_C_CONTROL = N_SERVOS * SLAVE["trajectory_servo"] + SLAVE["controller"] + SLAVE["actuation"]

_CALIB_DONE = Calibration.DONE      # the loop's test of the calibration (a C constant compiled)


class Slave:
    """One Slave board (PIC18F258): ``Slave(address, clock, plant, network, *, phase_us)``.

    ``address`` 1..8 (SCU, seed 002 slide 19); ``phase_us``: the start of its PWM periods
    (the first tick is the first instant >= ``clock.now_us`` congruent to ``phase_us`` modulo
    20 ms). The firmware has no randomness: a board takes no seed.
    The public attributes are the manual's modules: ``db`` (GLOBAL: ``sensors``,
    ``actuators``), ``traj`` (TRAJECTORY), ``servo`` (SERVO), ``calib`` (its calibration),
    ``pic`` (PIC2), ``can`` (CAN). ``pic_mhz``: the board's clock (humanoid_twin/cycles.py): each
    pass of the loop takes the virtual time its cycles take at that clock.
    """

    def __init__(
        self, address: int, clock: Clock, plant: Plant, network: CanNetwork, *, phase_us: int,
        pic_mhz: float = DEFAULT_PIC_MHZ,
    ) -> None:
        address = check_scu(address, "Slave address (an SCU address)")
        if isinstance(phase_us, bool) or not isinstance(phase_us, int) or phase_us < 0:
            raise ValueError(f"phase_us must be a non-negative int of microseconds, got {phase_us!r}")
        if plant is not None and getattr(plant, "clock", clock) is not clock:
            raise ValueError("the plant must run on the board's clock (Plant(..., clock=clock))")
        self.address = address
        self.clock = clock
        self.plant = plant
        self.network = network
        self.phase_us = phase_us % PWM_PERIOD_US
        self.has_foot = address in FOOT_OF_SCU
        self.ips = instructions_per_s(check_pic_mhz(pic_mhz))
        self.db = Global()
        self.sensors = self.db.sensors
        self.actuators = self.db.actuators
        self.traj = Trajectory()
        self.servo = ServoControl(self.actuators, self.has_foot, LEG_SIGNS.get(address, (1, 1, 1)),
                                  scu=address, clock=clock)
        self.calib = Calibration()
        self.pic = Pic2(address, plant)
        self.can = SlaveCan(address, clock, self.db, self.phase_us)
        # CoP of the foot (mm, foot frame) and whether the foot is loaded (leg boards)
        self.cop_x = 0
        self.cop_y = 0
        self.cop_loaded = False
        # counters and timing
        self.ticks = 0
        self.deadline_violations = 0
        self.task_ns_total = 0
        self.task_ns_max = 0
        # the cycle budget (docs/firmware.md): the last pass's cycles and time, the largest
        # fraction of a period a pass used, the end of the pass in progress, ticks missed
        self.task_cycles = 0
        self.task_us = 0
        self.task_load_max = 0.0
        self.busy_until_us = -1
        self.ticks_skipped = 0
        self._outputs_due = False
        self._overran = False
        self._pass_late = False
        self._finish_cb = self._finish
        self._overrun_cb = self._overrun
        self._due_us = 0
        self._delay_us = 0
        self._delay_ticks = 0
        self._still = [0] * N_SERVOS
        self._refs = [0] * N_SERVOS
        self._periods = [0] * N_SERVOS
        self._types = [0] * N_SERVOS
        self._start = [0] * N_SERVOS
        self.main()

    # -- main -------------------------------------------------------------------------------------
    def main(self) -> None:
        """``main`` (fig. 6): ``initPic``, then the 20 ms loop (calibration first, inside it)."""
        self.initPic()
        self.clock.call_every(PWM_PERIOD_US, self._tick, self.next_tick_us())

    def next_tick_us(self) -> int:
        """The first instant >= now that starts one of this board's PWM periods (a tick)."""
        now = self.clock.now_us
        return now + (self.phase_us - now) % PWM_PERIOD_US

    def initPic(self) -> None:
        """``initPic`` (table 16): databases (``initGlobal``), trajectories, PWM off, filters
        off, nominal position law, CAN (``initCan``)."""
        self.db.initGlobal()
        self.traj.initTrajectory()
        self.servo.reset((0, 0, 0))
        self.calib.reset()
        self.pic.initPic()
        self.can.initCan(self.network)
        self.can.on_stop = self.emergency_stop
        self.can.prepareSensorPackets()

    def emergency_stop(self) -> None:
        """Category-0 stop (docs/supervisor.md): an actuation packet switched the PWM off while it
        was on; the pulses stop at once (not at the next tick) and the status says PWM off."""
        self.pic.statusPWM(False)
        self.sensors.sysStatus.pwm = False
        self.can.prepareSensorPackets()

    # -- fault injection ----------------------------------------------------------------------------
    def inject_deadline_violation(self, delay_us: int, ticks: int = 1) -> None:
        """Fault injection: the work of the next ``ticks`` ticks starts ``delay_us`` late (as if
        the previous pass of the loop overran), which sets the deadline-violation flag."""
        if not 0 < delay_us < PWM_PERIOD_US:
            raise ValueError(f"delay_us must be in 1..{PWM_PERIOD_US - 1}, got {delay_us!r}")
        if ticks < 1:
            raise ValueError(f"ticks must be >= 1, got {ticks!r}")
        self._delay_us = delay_us
        self._delay_ticks = ticks

    # -- the loop -----------------------------------------------------------------------------------
    @property
    def calibrated(self) -> bool:
        """Status bit 6: the calibration has completed."""
        return self.calib.state == Calibration.DONE

    @property
    def commanded(self) -> list[int]:
        """The positions the servos are driven to (PWM), whole degrees."""
        return self.pic.applied

    def _tick(self) -> None:
        """The PWM period timer: ``waitTick`` returns (not while the pass before still runs:
        then the following period's tick is the next ``waitTick``'s)."""
        now = self.clock.now_us
        if now <= self.busy_until_us:
            self.ticks_skipped += 1
            return
        self._due_us = now
        if self._delay_ticks:
            self._delay_ticks -= 1
            self.clock.schedule(now + self._delay_us, self.loop)
        else:
            self.loop()

    def loop(self) -> None:
        """One pass of the main loop (fig. 6), at the start of a PWM period."""
        now = self.clock.now_us
        t0 = time.perf_counter_ns()
        step0 = self.plant.step_ns_total      # the physics due now runs at the first plant read:
        self.ticks += 1
        late = now > self._due_us
        self._pass_late = late
        if late:
            self.deadline_violations += 1
        can_ = self.can
        can_.checkCan()
        last = can_.last_rx_us
        can_.watchdog = now - (last if last > 0 else 0) >= WATCHDOG_TICKS * PWM_PERIOD_US
        pic = self.pic
        pic.updateServoMeasures()
        pic.finalizeServoMeasures()
        pic.sampleExtraSensors()
        cycles = _C_LOOP + can_.take_isr_cycles()
        if self.has_foot:
            self.cop_x, self.cop_y, self.cop_loaded = calcCoP(pic.force7)
            cycles += _C_SPECIAL + _C_COP
        elif pic.has_imu:
            cycles += _C_SPECIAL

        act = self.actuators
        st = self.sensors.sysStatus
        calib = self.calib
        if self.can.calib_request:
            self.can.calib_request = False
            if calib.state == _CALIB_DONE:
                calib.reset()
        if calib.state != _CALIB_DONE:
            self._calibration_step()
            cycles += _C_CALIB

        traj = self.traj
        servo = self.servo
        types = self._types
        if calib.state == _CALIB_DONE:
            pic.statusPWM(act.sysStatus.pwm)
            refs = self._refs
            periods = self._periods
            for i in range(N_SERVOS):
                a = act.servo[i]
                refs[i] = a.ref
                periods[i] = a.speed
                c = act.control[i]
                types[i] = c.type
            # a new trajectory starts from the position commanded now: the balance laws'
            # output (reference + offset), or, under the PID, its reference (the PID's own
            # command carries its integral correction, which it keeps)
            start = self._start
            for i in range(N_SERVOS):
                start[i] = traj.position[i] if servo.types[i] == LOCOMOTION_CONTROL else servo.output[i]
            restarted = traj.trajectory(refs, periods, types, start)
            for i in range(N_SERVOS):
                if restarted >> i & 1:
                    servo.newTrajectory(i)
                servo.servoRequest(i, traj.position[i])
            servo.controller(pic.pos, self.cop_x, self.cop_y, self.cop_loaded, types, pic.force7)
            can_.law_stopped = servo.law_stopped
            cycles += _C_CONTROL + servo.law_cycles_tick
            self._outputs_due = True          # servoActuation: below, when the pass reaches it

        # sensor database (GLOBAL) and status bits
        sv = self.sensors.servo
        still = self._still
        fin = st.motionFin
        done = calib.state == _CALIB_DONE
        n_fin = 0
        for i in range(N_SERVOS):
            s = sv[i]
            p = pic.pos[i]
            v = pic.vel[i]
            s.pos = p
            s.vel = v
            s.current = pic.current[i]
            still[i] = still[i] + 1 if v == 0 else 0
            f = False
            if done and traj.done(i):
                if types[i] == LOCOMOTION_CONTROL:
                    tr = traj.traject[i]
                    target = tr.theta_final
                else:
                    target = servo.output[i]
                d = p - target
                f = -MOTION_FIN_TOL_DEG <= d <= MOTION_FIN_TOL_DEG or still[i] >= MOTION_FIN_STILL_TICKS
            fin[i] = f
            n_fin += f
        sp = self.sensors.special
        for k in range(N_SPECIAL_SENSORS):
            sp[k] = pic.special[k]
        st.motionFinAll = n_fin == N_SERVOS
        st.motionFinOne = n_fin > 0
        st.pwm = pic.pwm
        st.filter = pic.filter_on
        st.calib = done
        st.deadlineError = late or self._overran
        # the pass's time at the board's clock: its outputs (servoActuation, the sensor packets)
        # happen when it reaches them. Within the PWM window no answer leaves (lowISR), so a pass
        # that ends there is seen as ending now; a pass past its period skips the tick it missed
        us = cycles_to_us(cycles, self.ips)
        self.task_cycles = cycles
        self.task_us = us
        load = us / PWM_PERIOD_US
        if load > self.task_load_max:
            self.task_load_max = load
        end = now + us
        if end >= self._due_us + PWM_PERIOD_US:
            self.busy_until_us = end
            self.clock.schedule(self._due_us + PWM_PERIOD_US, self._overrun_cb)
        if us <= PWM_BUSY_US:
            self._finish()
        else:
            self.clock.schedule(end, self._finish_cb)
        dt = time.perf_counter_ns() - t0 - (self.plant.step_ns_total - step0)  # not the board's task time
        self.task_ns_total += dt
        if dt > self.task_ns_max:
            self.task_ns_max = dt

    def _finish(self) -> None:
        """The end of the pass: ``servoActuation`` of the controller's outputs, the deadline flag
        (the period is over: ``deadlineError``, seed 000 section 3), the sensor packets."""
        if self._outputs_due:
            self._outputs_due = False
            self.pic.servoActuation(self.servo.output)
        self._overran = self.clock.now_us >= self._due_us + PWM_PERIOD_US
        if self._overran:                     # counted, and said, when the period ended: _overrun
            self.sensors.sysStatus.deadlineError = True
        can_ = self.can
        can_.prepareSensorPackets()
        can_.bus_off_seen = False

    def _overrun(self) -> None:
        """The PWM period ends with the pass still running (its work overran): PIC2's period
        interrupt sets ``deadlineError`` now, and the status byte ``lowISR`` answers with says it
        from now on, however long the pass still takes (a law declaring 200 000 000 cycles, 20 s
        at 10 MIPS, was seen only at its end: never, in a shorter run). Counted once per pass."""
        if not self._pass_late:               # a late pass is counted once
            self.deadline_violations += 1
        self.sensors.sysStatus.deadlineError = True
        self.can.flag_deadline()

    def _calibration_step(self) -> None:
        """``calibration`` (table 8), one tick of it (see ``servo.Calibration``)."""
        calib = self.calib
        pic = self.pic
        act = self.actuators
        if calib.state == Calibration.WAIT:
            if not act.sysStatus.pwm:
                pic.statusPWM(False)          # servos limp until the first actuation with PWM on
                return
            calib.start([s.ref for s in act.servo])            # steps 1-2
            pic.statusFilter(False)
            pic.setCalibration(pic.b_q, (0,) * N_SPECIAL_SENSORS)   # force samples with zero offset
            pic.servoActuation(calib.pos_master)
            pic.statusPWM(True)
            return
        if not act.sysStatus.pwm:                               # PWM switched off meanwhile
            calib.reset()
            pic.statusPWM(False)
            return
        if calib.step(pic.adc, pic.force7):                     # steps 3-6
            pic.setCalibration(calib.b_q, calib.offsets)
            pic.statusFilter(True)                              # step 7
            types = [c.type for c in act.control]
            self.traj.initTrajectory(calib.pos_master, types)
            self.servo.reset(calib.pos_master)
            for i in range(N_SERVOS):
                self.servo.types[i] = types[i]

    def __repr__(self) -> str:
        return (
            f"Slave({self.address}, phase_us={self.phase_us}, calibrated={self.calibrated}, "
            f"pwm={self.pic.pwm}, ticks={self.ticks})"
        )
