# C declarations for servo.py (SERVO, the compiled core): the same source, compiled. Positions
# are int8 degrees, the PID's and the balance laws' fixed-point values (1/16 degree, 1/256 mm,
# 1/65536 degree) fit a C long long many times over. The laws stay Python-callable objects
# (``self.laws``: a user's law is any object with ``start``/``step``); the board's state lists and
# the law fault are public (the recorder, the scenarios' summary and the tests read them).
cimport cython

from humanoid_twin.clock cimport Clock
from humanoid_twin.slave.data cimport divround
from humanoid_twin.slave.database cimport Actuators, Control
from humanoid_twin.slave.laws cimport LawInputs, balance_gain_bytes
from humanoid_twin.slave.pic2 cimport limitPosition

cdef long N_SERVOS
cdef long N_SPECIAL_SENSORS
cdef long POT_COUNTS_PER_DEG
cdef long FORCE_CALIBRATION_VALUE
cdef long long POS_LIMIT_DEG
cdef long long VELOCITY_MAX
cdef long long VELOCITY_MIN
cdef long long _V_MAX16

cdef tuple _SERVO_SETS

cpdef tuple balance_gain(object control)
@cython.locals(out=list, j=cython.long)
cdef object _plain_output(object values, object servos, object lo, object hi)
cpdef long long calibration_b(long pos_master, long long adc_sum, long n=*) except? -1
cpdef long long force_offset(long long sum7, long n=*) except? -1


cdef class Calibration:
    cdef public long state
    cdef public long ticks
    cdef public list pos_master
    cdef public list adc_sum
    cdef public list force_sum
    cdef public list b_q
    cdef public list offsets
    cdef public long long runs

    cpdef reset(self)
    @cython.locals(i=cython.long, k=cython.long, p=cython.long)
    cpdef start(self, object pos_master)
    @cython.locals(i=cython.long, k=cython.long)
    cpdef bint step(self, object adc, object force7) except -1


cdef class ServoControl:
    cdef public Actuators actuators
    cdef public bint has_foot
    cdef public tuple signs
    cdef public long scu
    cdef public Clock clock
    cdef public list reference
    cdef public list output
    cdef public list types
    cdef public list acc
    cdef public list cop_ref
    cdef public list cop_f
    cdef public bint cop_primed
    cdef public list last_v
    cdef public dict laws
    cdef public LawInputs inputs
    cdef public object law_fault
    cdef set _stopped
    cdef public list law_cost
    cdef public long long law_cycles_tick

    cpdef object law(self, long ctype)
    @cython.locals(i=cython.long, p=cython.long)
    cpdef reset(self, object positions)
    cpdef servoRequest(self, long i, long position)
    cpdef newTrajectory(self, long i)
    @cython.locals(inp=LawInputs, mine=list, i=cython.long, j=cython.long, t=cython.long,
                   done=cython.long, servos=tuple, mask=cython.long)
    cpdef controller(self, object measured, long cop_x, long cop_y, bint loaded, object types,
                     object forces=*)
    cpdef _start(self, object law, long i)
    # issue 24: what a law returns is judged by containment.law_output (guarded len/items/repr)
    @cython.locals(position=bint, lo=cython.longlong, hi=cython.longlong)
    cpdef object _run(self, object law, long t, LawInputs inp)
    cpdef _stop(self, object law, long t, object reason)
    @cython.locals(inp=LawInputs, c0=Control, c1=Control, c2=Control, f0=cython.longlong,
                   f1=cython.longlong)
    cpdef LawInputs _fill_inputs(self, object measured, bint loaded=*, object forces=*)
    @cython.locals(x8=cython.longlong, y8=cython.longlong, f0=cython.longlong, f1=cython.longlong)
    cpdef filterCoP(self, long cop_x, long cop_y, bint loaded)
    @cython.locals(ex=cython.longlong, ey=cython.longlong, f0=cython.longlong, f1=cython.longlong)
    cpdef tuple copError(self)
    cpdef applyVelocity(self, long i, long long v_q8)
    @cython.locals(ref=cython.longlong, acc=cython.longlong, hi=cython.longlong, lo=cython.longlong)
    cpdef _apply16(self, long i, long long v)
