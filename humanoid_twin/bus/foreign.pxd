# C declarations for foreign.py (the compiled core): the middle of the wire's inheritance chain.
from humanoid_twin.bus.confinement cimport ErrorConfinement

cdef class ForeignPath(ErrorConfinement):
    cdef public object interface
    cdef public object channel

    cpdef _send_and_drain(self, object ctrl, object msg, long long t_us)
