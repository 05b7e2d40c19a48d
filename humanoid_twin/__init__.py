"""humanoid-twin: a physics-based digital twin of the University of Aveiro humanoid's legs and of
its 2006 distributed control system (PC -> RS-232 -> Master -> CAN -> 8 Slaves -> servos)."""

__version__ = "0.1.0"
