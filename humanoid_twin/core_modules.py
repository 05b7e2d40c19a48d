"""The compiled core, named once: the modules built to C extension modules, and why each is
(docs/architecture.md, "The compiled core").

A module is in the core because code in it runs per event: per CAN frame, per RS-232 byte, per
board tick, per monitor sample. Each is its own ``.py`` (the firmware as the manual names it) with
an augmenting ``.pxd`` beside it that declares its C types. This list is the boundary:
``setup.py`` and ``scripts/build_core.py`` compile exactly these modules, the stale check of an
editable install (``humanoid_twin/core.py``) compares exactly these, and a test fails when a
``.pxd`` has no entry here or an entry has no ``.pxd`` (tests/project/test_core_list.py).

This file imports nothing: ``setup.py`` loads it by its path at build time, where the package's
dependencies may not be installed yet.
"""

from __future__ import annotations

# module -> why it is compiled (what per-event work it does). Order: by package, as docs show it.
CORE_MODULES: dict[str, str] = {
    "humanoid_twin.clock":
        "the event queue: every event of the twin is pushed and popped here",
    "humanoid_twin.cycles":
        "the boards' cycle accounting: every firmware function charges its cycles",
    "humanoid_twin.hardware":
        "the PWM and ADC laws and the IMU's tilt, used by every board tick",
    "humanoid_twin.protocol.wire":
        "the shared bus facts (int8 bytes, control and status bits) every codec uses",
    "humanoid_twin.protocol.canframes":
        "the CAN identifiers and payload codecs: every packet is packed and unpacked here",
    "humanoid_twin.protocol.rs232":
        "the RS-232 frame codec and BCC: every host request and answer",
    "humanoid_twin.bus.frames":
        "a CAN frame's record and its bit length: every frame loaded on the wire",
    "humanoid_twin.bus.confinement":
        "the error counters at each frame's end (the wire's base class)",
    "humanoid_twin.bus.foreign":
        "the path to a foreign python-can bus (in the wire's class chain)",
    "humanoid_twin.bus.network":
        "the CAN wire: arbitration, frame timing and delivery of every frame",
    "humanoid_twin.bus.twin_bus":
        "RxPort: every delivered frame to a node's receive interrupt",
    "humanoid_twin.bus.serial_link":
        "the RS-232 cable: every byte's timing and delivery",
    "humanoid_twin.master.pic":
        "the Master's 250 us timer interrupt and its CAN schedule, 4 000 a simulated second",
    "humanoid_twin.master.can":
        "an actuation packet built and a sensor packet stored, every CAN slot",
    "humanoid_twin.master.candrivers":
        "the Master's CAN buffers, every frame sent or received",
    "humanoid_twin.master.database":
        "the global database every packet and every request reads or writes",
    "humanoid_twin.master.supervisor":
        "the supervisor's round from the timer interrupt and its per-packet counters",
    "humanoid_twin.master.usart":
        "the Master's USART: every RS-232 byte received and every request answered",
    "humanoid_twin.slave.slave":
        "a Slave's 20 ms main loop, eight boards",
    "humanoid_twin.slave.can":
        "a Slave's CAN receive interrupt and its sensor packets",
    "humanoid_twin.slave.database":
        "a Slave's database, read and written every tick and every packet",
    "humanoid_twin.slave.trajectory":
        "the servos' trajectories, every tick",
    "humanoid_twin.slave.servo":
        "the calibration and the controller, every tick",
    "humanoid_twin.slave.laws":
        "the built-in control laws, every tick of every servo",
    "humanoid_twin.slave.data":
        "the foot's CoP every tick, the leg's Jacobian for the balance law",
    "humanoid_twin.slave.mymaths":
        "the integer sine and cosine of the leg's Jacobian (the balance law, every tick)",
    "humanoid_twin.slave.pic2":
        "PWM, servo measures and filters, every tick",
    "humanoid_twin.plant.stepping":
        "the physics kept up with the clock: the steps due before each board's read, every tick",
    "humanoid_twin.plant.sensors":
        "the boards' ADC reads on MuJoCo's arrays (after the physics sync), every tick",
    "humanoid_twin.plant.contacts":
        "the ground truth's arithmetic, every monitor sample (20 ms) and foot-CoP comparison",
}


def source_path(module: str) -> str:
    """A core module's ``.py``, relative to the folder that holds the package
    (``humanoid_twin.bus.network`` -> ``humanoid_twin/bus/network.py``)."""
    return module.replace(".", "/") + ".py"


def core_modules_markdown() -> str:
    """The list as the table docs/architecture.md shows (scripts/gen_docs.py writes it there)."""
    rows = [f"| `{source_path(m).removeprefix('humanoid_twin/')}` | {why} |"
            for m, why in CORE_MODULES.items()]
    return "\n".join(["| compiled module | why: its per-event work |", "|---|---|", *rows]) + "\n"
