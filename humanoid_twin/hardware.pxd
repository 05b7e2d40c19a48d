# C declarations for hardware.py (the compiled core): the same source, compiled. Only the PWM law
# is a C function (the Slave's servoActuation calls it, cimported); the constants stay Python
# module attributes (the plant, the host and the tests read them).

cpdef long pulse_from_deg(long deg)
