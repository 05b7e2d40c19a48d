"""The Slave board firmware (seed 000 section 3): modules Slave, TRAJECTORY, SERVO, DATA, MyMATHS,
PIC2, CAN and GLOBAL, one Python module each. See docs/firmware.md."""

from humanoid_twin.slave.slave import Slave

__all__ = ["Slave"]
