# C declarations for candrivers.py (the compiled core, docs/architecture.md): the same source,
# compiled. ``controller`` is the wire's CanController (bus/network.pxd): its send, abort and
# load_tx are C calls.
cimport cython

from humanoid_twin.bus.frames cimport Frame
from humanoid_twin.bus.network cimport CanController
from humanoid_twin.protocol.canframes cimport packet_index


cdef class CanDrivers:
    cdef public object network
    cdef public str name
    cdef public CanController controller
    cdef public list rxb
    cdef public list txb
    cdef public long long rx_overflows

    cpdef CanController myCANInitialize(self, list can_filters, object on_rx)
    cpdef CanController _ctl(self)
    @cython.locals(ctl=CanController)
    cdef inline bint _send(self, Py_ssize_t index, object msg) except -1
    cpdef bint myCANSendMessage0(self, object msg)
    cpdef bint myCANSendMessage1(self, object msg)
    @cython.locals(ctl=CanController, txb=list)
    cpdef bint myCANAbort(self)
    @cython.locals(n=cython.longlong)
    cpdef rx_interrupt(self, Frame msg)
    @cython.locals(rxb=list)
    cpdef object myCANReceiveMessage(self)
