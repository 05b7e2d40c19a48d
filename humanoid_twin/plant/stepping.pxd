# C declarations for stepping.py (the compiled core, docs/architecture.md): the same source,
# compiled. The physics time as C long long microseconds; the root of the plant's chain
# PhysicsTime <- BoardIO (sensors.pxd) <- Plant (plant.py, interpreted: it sets these fields,
# so they are public).
cimport cython

cdef class PhysicsTime:
    cdef public long long t_us
    cdef public long long timestep_us
    cdef public long long step_ns_total
    cdef public object _clock
    cdef public object model
    cdef public object data
    cdef public object _tilt_profile

    @cython.locals(now=cython.longlong)
    cpdef _sync(self)
    @cython.locals(due=cython.longlong, k=cython.longlong, w0=cython.longlong)
    cpdef advance_to(self, t_us)
