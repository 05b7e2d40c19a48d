# C declarations for supervisor.py (the compiled core, docs/architecture.md): the same source,
# compiled. The per-round detection (on_round, a C call from the Master's timer interrupt,
# master/pic.pxd) runs on C fields: the config's values read when it is set, the per-node
# counters as C arrays; the host's rare requests (applied, estop, reset) stay Python-level methods.
cimport cython

from humanoid_twin.bus.network cimport CanController
from humanoid_twin.clock cimport Clock
from humanoid_twin.master.can cimport MasterCan
from humanoid_twin.master.database cimport Database, ScuSensors
from humanoid_twin.slave.data cimport calcCoP

# constants of the round as C values (private aliases; supervisor.py)
cdef long long _STANDBY, _SELF_CHECK, _READY, _SAFE, _ESTOP
cdef long long _CAN_STATE, _LAW_STOPPED, _DEADLINE_BIT, _PWM_BIT, _CALIB_BIT
cdef double _X_MIN, _X_MAX, _Y_MIN, _Y_MAX
cdef tuple _FEET
cdef long long _NEVER
cdef str _BUS_OFF

@cython.locals(x=cython.long, y=cython.long, m=cython.double, front=cython.double,
               back=cython.double, first=bint)
cdef double _support_margin(list cops) except? -2
cdef double _min2(double a, double b)


cdef class Supervisor:
    cdef public Clock clock
    cdef public Database db
    cdef public MasterCan can
    cdef object _config
    # the config's values (its setter): SupervisorConfig is frozen
    cdef long long _silent_rounds
    cdef long long _deadline_hold_us
    cdef long long _over_travel_deg
    cdef long long _margin_mm
    cdef long long _balance_hold_us
    cdef long long _force_offset
    cdef long long _host_link_us     # -1: the host_link rule is off
    cdef long long _round_us
    cdef public long long mode
    cdef public list faults
    cdef public list latched
    cdef public list listeners
    cdef public long long refused
    cdef public long long last_host_us
    cdef set _seen
    # per node, by address 0..8 (len(NODES): _per_node's list is copied in, its length checked)
    cdef long long _packets[9]
    cdef long long _quiet_rounds[9]
    cdef long long _deadline_since[9]
    cdef long long _master_sent
    cdef long long _balance_since
    # issue 24: why the last reset was refused; the leg boards' loads before calibration and the
    # margin they gave (falls during the boot); the methods using them stay Python-level
    cdef public object reset_refused
    cdef dict _raw_load
    cdef object _raw_margin

    cpdef tuple read(self)
    cpdef bint apply_allowed(self)
    cpdef host_frame(self)
    @cython.locals(mode=cython.longlong, now=cython.longlong, ctl=CanController, master_down=bint,
                   sent=cython.longlong, silent=cython.longlong, quiet=cython.longlong,
                   k=cython.longlong, s=ScuSensors, n=cython.longlong, since=cython.longlong,
                   lim=cython.longlong, p=cython.longlong)
    cpdef on_round(self)
    @cython.locals(want=cython.longlong, s=ScuSensors)
    cdef bint _all_ready(self, long long now) except -1
    cpdef object foot_cop_mm(self, long long scu)
    @cython.locals(offset=cython.long, f0=cython.long, f1=cython.long, f2=cython.long,
               f3=cython.long, x=cython.long, y=cython.long, loaded=bint)
    cdef object _foot_cop(self, ScuSensors s)
    @cython.locals(sensors=dict, cops=list, k=cython.longlong, s=ScuSensors)
    cpdef object balance_margin_mm(self)
    cdef _check_balance(self, long long now)
    cdef _check_margin(self, object m, long long now)
    cpdef _fault(self, long long code, long long node, long long now)
    cpdef _set_mode(self, long long mode)
