# C declarations for pic2.py (PIC2, the compiled core): the same source, compiled. Positions are
# int8 degrees, ADC counts 10 bits, pulse widths microseconds, force values 8 and 7 bits: C longs.
# The measurement lists stay Python lists (public: the recorder, the tests and the board's loop
# read them); the plant stays a Python object (set_pwm, read_servos, read_force_adc).
cimport cython

from humanoid_twin.hardware cimport pulse_from_deg

# the hardware's and the wire's constants, as C constants in this module (module-private)
cdef long CURRENT_PULSE_FULL_US
cdef long N_SERVOS
cdef long N_SPECIAL_SENSORS
cdef long POT_B_NOMINAL_DEG
cdef long POT_COUNTS_PER_DEG
cdef long POS_LIMIT_DEG
cdef long _HALF_Q
cdef long _SHIFT_Q

cpdef long limitPosition(long position)
cpdef long position_from_adc(long b_q, long adc)
cpdef long current_from_pulse(long pulse_us)
cpdef long force_result(long adc8, long offset)
cpdef long median3(long a, long b, long c)


cdef class Pic2:
    cdef public long address
    cdef public object plant
    cdef public bint has_foot
    cdef public bint has_imu
    cdef public bint pwm
    cdef public bint filter_on
    cdef public list b_q
    cdef public list offsets
    cdef public list pulses
    cdef public list applied
    cdef public object adc
    cdef public object current_us
    cdef public list raw_pos
    cdef public list pos
    cdef public list vel
    cdef public list current
    cdef public object force8
    cdef public list force7
    cdef public list special
    cdef list _hist
    cdef list _med_prev

    cpdef initPic(self)
    @cython.locals(pulses=list, applied=list, changed=bint, i=cython.long, p=cython.long)
    cpdef servoActuation(self, object positions)
    cpdef statusPWM(self, bint on)
    @cython.locals(i=cython.long, r=cython.long, h=list)
    cpdef statusFilter(self, bint on)
    @cython.locals(i=cython.long, k=cython.long, p=cython.long)
    cpdef setCalibration(self, object b_q, object offsets)
    cpdef updateServoMeasures(self)
    @cython.locals(b_q=list, pos=list, i=cython.long, p=cython.long, v=cython.long)
    cpdef finalizeServoMeasures(self)
    @cython.locals(h=list, m=cython.long, out=cython.long)
    cpdef long filter(self, long i, long raw) except? -9999
    @cython.locals(f7=list, off=list, sp=list, k=cython.long)
    cpdef sampleExtraSensors(self)
