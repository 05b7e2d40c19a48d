"""The Master's global database (seed 002 slides 31-32).

"In Master, RS-232 and CAN communications are completely independent" (slide 31): the USART
interrupt writes actuation data and reads sensor data, the CAN schedule reads actuation data and
the CAN receive interrupt writes sensor data, all through this one structure.

Per SCU 1..8 (slide 32, ``struct_actuators`` / ``struct_sensors``):
- actuation: ``sysStatus`` (pwm, calib), per servo ``ref`` (int8 degrees), ``speed`` (movement
  period in 20 ms ticks), control ``type`` (0..3), ``ki``/``kp``/``kd`` (bytes);
- sensors: ``sysStatus`` (the slave's CAN status byte), per servo ``pos``/``vel`` (int8) and
  ``current`` (0..100), ``special[4]`` (force sensors, 8 bit);
plus the twin's bookkeeping: which sensor packets arrived in the current schedule round, the
bitmask of the slaves that answered both packets in the last complete round, and counters for
the recording.

Python lists of plain ints, mutated in place: the CAN paths touch them thousands of times per
simulated second.
"""

from __future__ import annotations

from humanoid_twin.hardware import N_SERVOS, N_SPECIAL_SENSORS
from humanoid_twin.protocol.wire import SCUS, STATUS_CALIB, check_scu

# Calibration request state per SCU (APPLY_JOINT SPECIAL D2 = 1; docs/master.md).
CALIB_IDLE = 0        # Calib bit clear
CALIB_REQUESTED = 1   # Calib bit set, waiting for the slave to report "not calibrated" (status bit 6 = 0)
CALIB_RUNNING = 2     # Calib bit set, slave calibrating, waiting for status bit 6 = 1



class ScuActuation:
    """Actuation data of one SCU (slide 32 ``struct_actuators`` entry)."""

    __slots__ = ("pwm", "calib", "calib_state", "ref", "speed", "type", "ki", "kp", "kd",
                 "payload1", "payload2")

    def __init__(self) -> None:
        self.pwm = False
        self.calib = False
        self.calib_state = CALIB_IDLE
        self.ref = [0] * N_SERVOS          # int8 degrees
        self.speed = [0] * N_SERVOS        # movement period, 20 ms ticks (0 = at once)
        self.type = [0] * N_SERVOS         # control type 0..3 (seed 000 table 9)
        self.ki = [0] * N_SERVOS
        self.kp = [0] * N_SERVOS
        self.kd = [0] * N_SERVOS
        # Cached CAN payloads of actuation packets 1 and 2 (None = rebuild on next send).
        self.payload1: bytes | None = None
        self.payload2: bytes | None = None

    def invalidate(self) -> None:
        """Forget the cached CAN payloads after a change."""
        self.payload1 = None
        self.payload2 = None


class ScuSensors:
    """Sensor data of one SCU as last received over CAN (slide 32 ``struct_sensors`` entry)."""

    __slots__ = ("status", "pos", "vel", "current", "special", "rx1", "rx2",
                 "packets1", "packets2", "rounds_answered", "rounds_missed", "last_rx_us", "sflags",
                 "sflags2")

    def __init__(self) -> None:
        self.status = 0                          # sensors 1 byte 8 (docs/protocol.md 2.4)
        self.pos = [0] * N_SERVOS                # int8 degrees
        self.vel = [0] * N_SERVOS                # int8 degrees per 20 ms tick
        self.current = [0] * N_SERVOS            # 0..100
        self.special = [0] * N_SPECIAL_SENSORS   # force sensors, 8 bit
        self.rx1 = False                         # sensors 1 received in the current round
        self.rx2 = False                         # sensors 2 received in the current round
        self.packets1 = 0                        # sensors 1 packets stored, total
        self.packets2 = 0
        self.rounds_answered = 0                 # complete rounds with both packets
        self.rounds_missed = 0                   # complete rounds without both packets
        self.last_rx_us = -1                     # virtual time of the last sensor packet
        self.sflags = 0                          # Sensors 1 SFlags bits 2-0 (docs/supervisor.md)
        self.sflags2 = 0                         # Sensors 2 SFlags bits 2-0 (bit 2: a law stopped)


class MasterCounters:
    """Counters for the recording (docs/master.md lists what each one counts)."""

    __slots__ = ("serial_bytes_received", "serial_bytes_discarded", "serial_frames_received",
                 "serial_frames_answered", "serial_frames_rejected", "serial_frames_broken",
                 "serial_frames_invalid", "can_tx_requests", "can_tx_refused", "can_tx_aborts",
                 "can_rx_frames", "can_rx_rejected", "can_clear_status", "rounds")
    # the slots' types, for the type checker (set to 0 by __init__; database.pxd declares them)
    serial_bytes_received: int
    serial_bytes_discarded: int
    serial_frames_received: int
    serial_frames_answered: int
    serial_frames_rejected: int
    serial_frames_broken: int
    serial_frames_invalid: int
    can_tx_requests: int
    can_tx_refused: int
    can_tx_aborts: int
    can_rx_frames: int
    can_rx_rejected: int
    can_clear_status: int
    rounds: int

    def __init__(self) -> None:
        for name in self.__slots__:
            setattr(self, name, 0)

    def as_dict(self) -> dict[str, int]:
        """All counters by name."""
        return {name: getattr(self, name) for name in self.__slots__}


class Database:
    """The Master's global database: ``actuators[scu]`` and ``sensors[scu]`` for scu 1..8."""

    __slots__ = ("actuators", "sensors", "answered_mask", "counters")

    def __init__(self) -> None:
        self.actuators: dict[int, ScuActuation] = {k: ScuActuation() for k in SCUS}
        self.sensors: dict[int, ScuSensors] = {k: ScuSensors() for k in SCUS}
        # Bit k-1 set: slave k answered both sensor packets in the last complete round.
        self.answered_mask = 0
        self.counters = MasterCounters()

    def actuation(self, scu: int) -> ScuActuation:
        """Actuation data of SCU ``scu`` (1..8); ValueError otherwise."""
        return self.actuators[check_scu(scu)]

    def sensor(self, scu: int) -> ScuSensors:
        """Sensor data of SCU ``scu`` (1..8); ValueError otherwise."""
        return self.sensors[check_scu(scu)]

    def request_calibration(self, scu: int) -> None:
        """Set the Calib flag of ``scu`` (APPLY_JOINT SPECIAL D2 = 1) until the slave reports done."""
        a = self.actuation(scu)
        a.calib = True
        a.calib_state = CALIB_REQUESTED
        a.invalidate()

    def update_calibration(self, scu: int, status: int) -> None:
        """Follow a slave's status bit 6 and clear the Calib flag once its new calibration is done.

        The flag is cleared only after the slave has been seen calibrating (bit 6 = 0) and then
        done (bit 6 = 1), so a stale "done" from before the request does not cancel it.
        """
        a = self.actuators[scu]
        state = a.calib_state
        if state == CALIB_IDLE:
            return
        done = status & STATUS_CALIB
        if state == CALIB_REQUESTED:
            if not done:
                a.calib_state = CALIB_RUNNING
        elif done:
            a.calib_state = CALIB_IDLE
            a.calib = False
            a.invalidate()

    def finish_round(self) -> int:
        """Close a schedule round: compute ``answered_mask``, count per slave, clear the flags."""
        mask = 0
        for k, s in self.sensors.items():
            if s.rx1 and s.rx2:
                mask |= 1 << (k - 1)
                s.rounds_answered += 1
            else:
                s.rounds_missed += 1
            s.rx1 = False
            s.rx2 = False
        self.answered_mask = mask
        self.counters.rounds += 1
        return mask
