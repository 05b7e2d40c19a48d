# C declarations for trajectory.py (TRAJECTORY, the compiled core): the same source, compiled.
# Ticks and int8 positions are C longs; the coefficients are the manual's doubles, kept in the
# public ``coef`` list of Python floats and computed in C doubles with the same operations in the
# same order (IEEE double either way: the same bits).
cimport cython

from humanoid_twin.slave.pic2 cimport limitPosition

cdef long N_SERVOS
cdef long _MAX_PERIOD

cpdef long round_deg(double x)


cdef class StructTrajectory:
    cdef public long type
    cdef public list coef
    cdef public long period
    cdef public long time
    cdef public long theta_final
    cdef public long control_type


cdef class Trajectory:
    cdef public list traject
    cdef public list position

    @cython.locals(i=cython.long, p=cython.long, t=StructTrajectory)
    cpdef initTrajectory(self, object positions=*, object control_types=*)
    @cython.locals(t=StructTrajectory, c=list, d=cython.double)
    cpdef calcTrajectory(self, long i, long start, long theta_final, long period, long control_type)
    @cython.locals(t=StructTrajectory, p=cython.long, tt=cython.long, c0=cython.double,
                   c1=cython.double, c2=cython.double, c3=cython.double)
    cpdef long executeTrajectory(self, long i) except? -9999
    @cython.locals(restarted=cython.long, traject=list, i=cython.long, ref=cython.long,
                   t=StructTrajectory)
    cpdef long trajectory(self, object refs, object periods, object types, object start) except? -1
    @cython.locals(t=StructTrajectory)
    cpdef bint done(self, long i) except -1
