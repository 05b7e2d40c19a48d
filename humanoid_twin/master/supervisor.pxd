# C declarations for supervisor.py (the compiled core, docs/architecture.md): the same source,
# compiled. The per-round detection (on_round) runs in C; the host's rare requests (applied,
# estop, reset) stay Python-level methods.
cimport cython

from humanoid_twin.bus.network cimport CanController
from humanoid_twin.clock cimport Clock
from humanoid_twin.master.can cimport MasterCan
from humanoid_twin.master.database cimport Database, ScuSensors
from humanoid_twin.slave.data cimport calcCoP


cdef class Supervisor:
    cdef public Clock clock
    cdef public Database db
    cdef public MasterCan can
    cdef public object config
    cdef public long long mode
    cdef public list faults
    cdef public list latched
    cdef public list listeners
    cdef public long long refused
    cdef public long long last_host_us
    cdef public set _seen
    cdef public list _packets
    cdef public list _quiet_rounds
    cdef public long long _master_sent
    cdef public list _deadline_since
    cdef public object _balance_since
    # issue 24: why the last reset was refused; the leg boards' loads before calibration and the
    # margin they gave (falls during the boot); the methods using them stay Python-level
    cdef public object reset_refused
    cdef public dict _raw_load
    cdef public object _raw_margin

    cpdef tuple read(self)
    cpdef bint apply_allowed(self)
    cpdef host_frame(self)
    @cython.locals(now=cython.longlong, db=Database, ctl=CanController, master_down=bint, sent=cython.longlong,
                   q=list, k=cython.longlong, s=ScuSensors, n=cython.longlong)
    cpdef on_round(self)
    @cython.locals(want=cython.longlong, s=ScuSensors)
    cpdef bint _all_ready(self, long long now)
    @cython.locals(w=list, offset=cython.longlong)
    cpdef object foot_cop_mm(self, long long scu)
    @cython.locals(sensors=dict, cops=list, k=cython.longlong, ys=list)
    cpdef object balance_margin_mm(self)
    cpdef _check_balance(self, long long now)
    cpdef _fault(self, long long code, long long node, long long now)
    cpdef _set_mode(self, long long mode)
