# C declarations for laws.py (the control laws of table 9, the compiled core): the same source,
# compiled. ControlLaw is an extension type: the four built-in laws are compiled subclasses of it,
# and a user's law (a Python class, with or without ControlLaw as its base) plugs in as before:
# the board calls ``law.start``/``law.step`` through Python attributes, so a Python override or a
# duck-typed law runs unchanged. Per-servo state and LawInputs stay public Python objects (the
# laws' users and the tests read them). Gains are bytes, errors mm or degrees, velocities fit the
# PIC's 32-bit long: C long long arithmetic with no possible overflow.
cimport cython

from humanoid_twin.protocol.wire cimport from_s8
from humanoid_twin.slave.data cimport jacobianMatrix

cdef long N_SERVOS
cdef long POS_LIMIT_DEG
cdef long _U_MAX
cdef long _U_MIN

cpdef long long shr(long long v, long n)
cpdef tuple balance_gain_bytes(long kp, long kd)


cdef class LawInputs:
    cdef public object scu
    cdef public object has_foot
    cdef public object signs
    cdef public object servos
    cdef public object measured
    cdef public object reference
    cdef public object output
    cdef public object cop_mm
    cdef public object cop_error_mm
    cdef public object cop_ref_mm
    cdef public object forces
    cdef public object gains


cdef class ControlLaw:
    pass


cdef class OpenLoopLaw(ControlLaw):
    pass


cdef class LocomotionLaw(ControlLaw):
    cdef public list u16
    cdef public list e1
    cdef public list e2
    cdef public list fresh

    @cython.locals(out=list, i=cython.long, ki=cython.long,
                   kp=cython.long, kd=cython.long, e=cython.long, e1=cython.long, e2=cython.long,
                   u=cython.longlong)
    cpdef object step(self, LawInputs inputs)


cdef class ReactionLaw(ControlLaw):
    @cython.locals(out=list, ex=cython.longlong, ey=cython.longlong, i=cython.long,
                   kp=cython.long, shift=cython.long)
    cpdef object step(self, LawInputs inputs)


cdef class JacobianLaw(ControlLaw):
    cdef public object last_jacobian

    @cython.locals(out=list, J=tuple, ex=cython.longlong, ey=cython.longlong, j0=tuple,
                   j1=tuple, i=cython.long, kp=cython.long, shift=cython.long)
    cpdef object step(self, LawInputs inputs)
