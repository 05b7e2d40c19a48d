# C declarations for can.py (the compiled core, docs/architecture.md): the same source, compiled.
cimport cython

from humanoid_twin.bus.frames cimport Frame
from humanoid_twin.bus.network cimport CanController
from humanoid_twin.clock cimport Clock
from humanoid_twin.master.candrivers cimport CanDrivers
from humanoid_twin.master.database cimport Database, MasterCounters, ScuActuation, ScuSensors
from humanoid_twin.protocol.canframes cimport (
    control_byte,
    packet_index,
    pack_actuation1,
    pack_actuation2,
    unpack_sensors1_into,
    unpack_sensors2_into,
)

# constants of the per-packet path as C values (imported here; nobody imports them from here)
cdef long long SFLAGS_SUPERVISOR, STD_ID_MAX


cdef class MasterCan:
    cdef public Clock clock
    cdef public Database db
    cdef public CanDrivers drivers
    cdef public list rejected
    cdef list _tx_msgs
    cdef list _tx_ids
    cdef list _actuators
    cdef list _rx_sources
    cdef list _sensors

    cpdef canInit(self, object on_rx)
    @cython.locals(a=ScuActuation, c=MasterCounters, ok=bint, kd=list, drivers=CanDrivers, ctl=CanController,
                   key=cython.longlong, msgs=list, msg=Frame)
    cpdef bint canSendMsg(self, long long scu, long long index)
    cpdef canAbort(self)
    @cython.locals(msg=Frame, data=bytes, db=Database, c=MasterCounters, s=ScuSensors, ident=cython.longlong,
                   src=cython.longlong, index=cython.longlong)
    cpdef bint canReceiveMsg(self)
    @cython.locals(rejected=list)
    cpdef bint _reject(self, long long ident, str reason)
    cpdef canClearStatus(self)
    @cython.locals(ctl=CanController)
    cpdef tuple error_status(self)
