# C declarations for hardware.py (the compiled core): the same source, compiled. Only the PWM law
# is a C function (the Slave's servoActuation calls it, cimported) and the IMU's tilt a C double
# function (the run's IMU comparison calls it twice a body-board tick); the constants stay Python
# module attributes (the plant, the host and the tests read them). math is C's libm here.
cimport cython
from libc cimport math

cdef double _RAD_PER_DEG
cdef double _DEG_PER_RAD

cpdef long pulse_from_deg(long deg)

@cython.locals(c=cython.double)
cpdef double tilt_from_roll_pitch(double roll_deg, double pitch_deg) except? -1.0
