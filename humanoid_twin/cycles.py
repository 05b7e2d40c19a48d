"""The boards' time: the PIC18F258 cycle table (docs/firmware.md, "Cycle budget").

Every firmware function, interrupt and built-in control law of the twin charges the PIC18
instruction cycles its C code takes on the real board, from this one table; the board's clock
(``--pic-mhz``) turns cycles into virtual time (4 clock periods per instruction cycle, PIC18F258
datasheet DS41159, "Instruction cycle"). A Slave's 20 ms pass of its main loop then takes the time it took
on the robot: past its period it sets ``deadlineError`` and skips the tick it missed; the
Master's 250 us timer interrupt past its slot delays the CAN schedule (docs/firmware.md,
docs/master.md). How each figure was estimated is in docs/firmware.md next to the table.

Also here: the cost of a control law (:func:`law_cycles`: a law's ``cycles`` attribute or
method, else the built-in law of its control type). The summary's ``task_load_max`` and
``deadline_misses``: humanoid_twin/board_report.py.
"""

from __future__ import annotations

import math
import sys

from humanoid_twin.clock import US_PER_S

__all__ = [
    "DEFAULT_PIC_MHZ",
    "CLOCKS_PER_CYCLE",
    "SLAVE",
    "MASTER",
    "LAW",
    "LAW_CYCLES_MAX",
    "instructions_per_s",
    "cycles_to_us",
    "check_pic_mhz",
    "law_cycles",
    "note_default_cost",
]

# The robot's crystal: no seed names it; the PIC18F258's top speed, 10 MHz crystal x4 PLL
# (HS-PLL) = 40 MHz, 10 MIPS (DS41159, "Oscillator configurations", HS-PLL), which the ISR latency of the
# Slaves' CAN answers (20 us, docs/firmware.md) already assumed.
DEFAULT_PIC_MHZ = 40.0
CLOCKS_PER_CYCLE = 4          # Fosc/4: one instruction cycle (DS41159, "Instruction cycle")
PIC_MHZ_MIN = 0.032           # the 32 kHz Timer1 oscillator, the slowest clock a PIC18 runs on
PIC_MHZ_MAX = 40.0            # DS41159: Fosc max 40 MHz
LAW_CYCLES_MAX = 2**31 - 1    # a law's declared cost per call: at most ~215 s at 10 MIPS (the
                              # boards' cycle counts stay far inside a C long long of microseconds)

# Instruction cycles per call, Slave firmware (seed 000 section 3). The estimates, their sources
# (PIC18 instruction timings, the C compiler's arithmetic routines) and the work each function
# does are in docs/firmware.md, "Cycle budget"; tests/firmware/test_cycles.py pins the totals.
SLAVE: dict[str, int] = {
    "loop": 150,                # waitTick return, checkCan, CAN watchdog, loop bookkeeping
    "measure_servo": 450,       # updateServoMeasures + finalizeServoMeasures + filter, per servo
    "adc_channel": 365,         # one 8-bit ADC conversion (32 us at 10 MIPS) + shift/offset/clamp
    "calc_cop": 1300,           # calcCoP: 8 16x16 multiplies, 2 32/16 divisions
    "calibration": 400,         # one tick of calibration (sums of ADC and force values)
    "trajectory_servo": 520,    # trajectory + executeTrajectory + servoRequest, per servo
    "controller": 300,          # controller's own work: grouping by type, filterCoP (32-bit IIR)
    "actuation": 180,           # servoActuation: limitPosition + pulse width, 3 servos
    "status": 250,              # sensor database and status bits
    "packets": 300,             # prepareSensorPackets: the two 8-byte payloads
    "isr_actuation": 250,       # lowISR for this board: entry/exit, RXB copy, receiveCanMessage
    "isr_answer": 80,           # sendCanMessage: TXB load and TXREQ
    "isr_other": 80,            # lowISR for a frame the mask lets in that is not ours
    "pwm_period": 3300,         # highISR per period: pulse edges, descent zone, servo sampling
}

# Instruction cycles per call, Master firmware (seed 000 section 2: all its work is interrupts).
MASTER: dict[str, int] = {
    "timer_tx": 190,            # timer ISR, slots 0/2: entry/exit, slot logic, canSendMsg
    "timer_rx": 60,             # timer ISR, slots 1/3: canAbort, next destination
    "can_rx": 200,              # CAN RX ISR: a sensor packet into the database
    "usart_byte": 100,          # USART RX/TX ISR per byte, usartProcessMsg amortised per byte
}

# Instruction cycles per call of the built-in laws (one call per control type in use and tick,
# for its servos; docs/firmware.md). A --law that declares no cost is charged like these.
LAW: dict[int, int] = {
    0: 30,                      # openloopControl: a copy
    1: 540,                     # locomotionControl: incremental PID, 3 x (3 16x16 mult + clamp)
    2: 500,                     # reactionControl: 2 x (32-bit mult, shift) + applyVelocity
    3: 1600,                    # jacobianControl: jacobianMatrix (6 seno/coseno look-ups, 12
                                #   16x16 mult) + 3 x 32-bit mult + applyVelocity
}


def instructions_per_s(pic_mhz: float) -> int:
    """Instruction cycles per second of a PIC18 clocked at ``pic_mhz`` (Fosc / 4)."""
    return round(pic_mhz * 1e6 / CLOCKS_PER_CYCLE)


def cycles_to_us(cycles: int, ips: int) -> int:
    """The virtual microseconds ``cycles`` take at ``ips`` instructions per second, rounded up."""
    return -(-cycles * US_PER_S // ips)


def check_pic_mhz(value: float) -> float:
    """``pic_mhz`` if it is a clock a PIC18F258 runs on (0.032..40 MHz), else ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not PIC_MHZ_MIN <= value <= PIC_MHZ_MAX:
        raise ValueError(f"the PIC clock must be {PIC_MHZ_MIN:g}..{PIC_MHZ_MAX:g} MHz, got {value!r}")
    return float(value)


def law_cycles(law: object, ctype: int) -> tuple[int, bool]:
    """``(cycles per call, declared)`` of a control law: its ``cycles`` (an int, or a method
    called with no arguments that returns one), else the built-in law of control type ``ctype``
    (``declared`` False). A declared cost that is not an int in 0..``LAW_CYCLES_MAX`` raises
    ValueError."""
    c = getattr(law, "cycles", None)
    if callable(c):
        c = c()
    if c is None:
        return LAW.get(ctype, LAW[3]), False
    if isinstance(c, bool) or not isinstance(c, int) or not 0 <= c <= LAW_CYCLES_MAX:
        raise ValueError(f"a law's cycles must be a non-negative int up to {LAW_CYCLES_MAX} "
                         f"(instruction cycles per call), got {c!r}")
    return c, True


def note_default_cost(law: object, ctype: int, cost: tuple[int, bool] | None = None) -> None:
    """The one line a run writes when a law declares no cost (docs/controllers.md); ``cost``: its
    :func:`law_cycles`, already asked (None: asked here)."""
    from humanoid_twin.protocol.wire import ControlType

    cycles, declared = law_cycles(law, ctype) if cost is None else cost
    if not declared:
        label = ControlType(ctype).label
        name = getattr(type(law), "__qualname__", "?")
        sys.stderr.write(f"humanoid-twin: law {name} declares no cost (cycles): charged {cycles} "
                         f"cycles per call, as the built-in {label} law\n")
