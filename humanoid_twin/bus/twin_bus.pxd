# C declarations for twin_bus.py (the compiled core). TwinBus subclasses python-can's BusABC (a
# Python class): it stays a Python class; its RxPort, the per-frame path, is an extension type
# the wire (network.pxd) calls directly.
cimport cython
from humanoid_twin.bus.frames cimport Frame

cdef long long STD_ID_MAX

cdef class RxPort:
    cdef public object bus
    cdef public list routes
    cdef public long long rx_skipped

    @cython.locals(route=object, cbs=tuple, skips=tuple, p=RxPort, frame=Frame, arb=cython.longlong,
                   extended=bint)
    cpdef deliver(self, object msg)
