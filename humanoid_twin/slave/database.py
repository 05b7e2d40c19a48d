"""Module GLOBAL of the Slave firmware (seed 000 section 3, table 19; seed 002 slide 33).

The board's own database: ``sensors`` (what it measures and reports in its sensor packets) and
``actuators`` (what the Master asked for in its actuation packets). The CAN interrupt writes
``actuators`` and reads ``sensors`` at any time; the main loop does the opposite (seed 002
slide 31: "the sensorial data for the response must be available at any time").

Field names follow the manual's structures (slide 33 is the later, complete version of the
manual's ``struct_sensors``: ``pwm, calib, deadlineError, motionFinAll, motionFinOne,
motionFin[N_SERVOS]``). Plain slotted objects of ints and bools: the CAN interrupt touches them
thousands of times per simulated second.
"""

from __future__ import annotations

from humanoid_twin.hardware import N_SERVOS, N_SPECIAL_SENSORS

__all__ = [
    "ORIGIN_POSITIONS",
    "SensorStatus",
    "StructServo",
    "Sensors",
    "ActuatorStatus",
    "Control",
    "ActuatorServo",
    "Actuators",
    "Global",
]

# reinitServo: the origin positions "defined a priori by the SCU" (all joints at 0 degrees, the
# stand pose of the twin's model), with free trajectories (period 0).
ORIGIN_POSITIONS: tuple[int, int, int] = (0, 0, 0)


class SensorStatus:
    """``sensors.sysStatus`` (slide 33)."""

    __slots__ = ("pwm", "calib", "filter", "deadlineError", "motionFinAll", "motionFinOne", "motionFin")

    def __init__(self) -> None:
        self.pwm = False            # motors on/off
        self.calib = False          # calibration done
        self.filter = False         # measurement filters on/off (manual's struct)
        self.deadlineError = False  # deadline violated
        self.motionFinAll = False   # every servo finished its motion
        self.motionFinOne = False   # at least one servo finished its motion
        self.motionFin: list[bool] = [False] * N_SERVOS


class StructServo:
    """``struct_servo`` of the sensor database: position (int8 deg), mean velocity (int8 deg per
    tick), current (0..100)."""

    __slots__ = ("pos", "vel", "current")

    def __init__(self) -> None:
        self.pos = 0
        self.vel = 0
        self.current = 0


class Sensors:
    """``struct_sensors sensors`` (GLOBAL)."""

    __slots__ = ("sysStatus", "servo", "special")

    def __init__(self) -> None:
        self.sysStatus = SensorStatus()
        self.servo: list[StructServo] = [StructServo() for _ in range(N_SERVOS)]
        self.special: list[int] = [0] * N_SPECIAL_SENSORS   # force sensors, 8 bit


class ActuatorStatus:
    """``actuators.sysStatus`` (slide 33): PWM on/off and the calibration request bit."""

    __slots__ = ("pwm", "calib")

    def __init__(self) -> None:
        self.pwm = False
        self.calib = False


class Control:
    """``actuators.control[i]``: the raw gain bytes and the control type (table 9)."""

    __slots__ = ("kp", "kd", "ki", "type")

    def __init__(self) -> None:
        self.kp = 0
        self.kd = 0
        self.ki = 0
        self.type = 0


class ActuatorServo:
    """``actuators.servo[i]``: requested final position (int8 deg) and movement period (ticks)."""

    __slots__ = ("ref", "speed")

    def __init__(self) -> None:
        self.ref = 0
        self.speed = 0


class Actuators:
    """``struct_actuators actuators`` (GLOBAL)."""

    __slots__ = ("sysStatus", "control", "servo", "received")

    def __init__(self) -> None:
        self.sysStatus = ActuatorStatus()
        self.control: list[Control] = [Control() for _ in range(N_SERVOS)]
        self.servo: list[ActuatorServo] = [ActuatorServo() for _ in range(N_SERVOS)]
        self.received = 0           # actuation packets taken since initActuators (twin counter)


class Global:
    """The GLOBAL module of one Slave: the two databases and their initialisation functions."""

    __slots__ = ("sensors", "actuators")

    def __init__(self) -> None:
        self.sensors = Sensors()
        self.actuators = Actuators()
        self.initGlobal()

    def initGlobal(self) -> None:
        """``initGlobal`` (table 19): the whole database to its origin values."""
        self.initSensors()
        self.initActuators()

    def initSensors(self) -> None:
        """``initSensors`` (table 19): the sensor database only."""
        st = self.sensors.sysStatus
        st.pwm = st.calib = st.filter = st.deadlineError = False
        st.motionFinAll = st.motionFinOne = False
        for i in range(N_SERVOS):
            st.motionFin[i] = False
            s = self.sensors.servo[i]
            s.pos = s.vel = s.current = 0
        for k in range(N_SPECIAL_SENSORS):
            self.sensors.special[k] = 0

    def initActuators(self) -> None:
        """``initActuators`` (table 19): the actuation database only (PWM off, no calibration
        request, open loop, zero gains, origin positions)."""
        a = self.actuators
        a.sysStatus.pwm = False
        a.sysStatus.calib = False
        for c in a.control:
            c.kp = c.kd = c.ki = 0
            c.type = 0
        a.received = 0
        self.reinitServo()

    def reinitServo(self) -> None:
        """``reinitServo`` (table 19): the requested positions back to the origin values
        (:data:`ORIGIN_POSITIONS`, free trajectories)."""
        for i, s in enumerate(self.actuators.servo):
            s.ref = ORIGIN_POSITIONS[i]
            s.speed = 0
