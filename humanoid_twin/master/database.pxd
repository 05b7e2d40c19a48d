# C declarations for database.py (the compiled core, docs/architecture.md): the same source,
# compiled. Every field is public: the recorder, the supervisor, the host's tests read them.
cimport cython

# constants of the per-packet path as C values (not read from this module by anyone else)
cdef long long CALIB_IDLE, CALIB_REQUESTED, CALIB_RUNNING, STATUS_CALIB


cdef class ScuActuation:
    cdef public bint pwm
    cdef public bint calib
    cdef public long long calib_state
    cdef public list ref
    cdef public list speed
    cdef public list type
    cdef public list ki
    cdef public list kp
    cdef public list kd
    cdef public object payload1
    cdef public object payload2

    cpdef invalidate(self)


cdef class ScuSensors:
    cdef public long long status
    cdef public list pos
    cdef public list vel
    cdef public list current
    cdef public list special
    cdef public bint rx1
    cdef public bint rx2
    cdef public long long packets1
    cdef public long long packets2
    cdef public long long rounds_answered
    cdef public long long rounds_missed
    cdef public long long last_rx_us
    cdef public long long sflags
    cdef public long long sflags2


cdef class MasterCounters:
    cdef public long long serial_bytes_received
    cdef public long long serial_bytes_discarded
    cdef public long long serial_frames_received
    cdef public long long serial_frames_answered
    cdef public long long serial_frames_rejected
    cdef public long long serial_frames_broken
    cdef public long long serial_frames_invalid
    cdef public long long can_tx_requests
    cdef public long long can_tx_refused
    cdef public long long can_tx_aborts
    cdef public long long can_rx_frames
    cdef public long long can_rx_rejected
    cdef public long long can_clear_status
    cdef public long long rounds


cdef class Database:
    cdef public dict actuators
    cdef public dict sensors
    cdef public long long answered_mask
    cdef public MasterCounters counters

    cpdef ScuActuation actuation(self, object scu)
    cpdef ScuSensors sensor(self, object scu)
    @cython.locals(a=ScuActuation)
    cpdef request_calibration(self, object scu)
    @cython.locals(a=ScuActuation, state=cython.longlong, done=cython.longlong)
    cpdef update_calibration(self, long long scu, long long status)
    @cython.locals(mask=cython.longlong, s=ScuSensors, k=cython.longlong)
    cpdef long long finish_round(self)
