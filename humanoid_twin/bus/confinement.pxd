# C declarations for confinement.py (the compiled core): the root of the wire's inheritance
# chain ErrorConfinement <- ForeignPath <- CanNetwork (an extension type has one base). The
# fields declared here are the wire's, read by the confinement; CanNetwork sets them.
from humanoid_twin.clock cimport Clock

cdef class ErrorConfinement:
    cdef public Clock clock
    cdef public long long bitrate
    cdef list _nodes
    cdef list _recovering
    cdef bint _rec_dirty
    cdef long long _dom_end

    # the nodes are typed object here (CanController is declared in network.pxd, which
    # cimports this file): these run on errors and recoveries only, not per frame
    cpdef _rx_success(self, object sender)
    cpdef _update_state(self, object c)
    cpdef _clear_status(self, object c)
    cpdef _close_recovery_runs(self, long long start)
    cpdef _mute(self, object c, bint muted)
    cpdef _recovered(self, object c)
