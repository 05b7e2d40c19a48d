# C declarations for network.py (the compiled core, docs/architecture.md): the same source,
# compiled. Virtual times, counters and bit lengths are C long long.
#
# The interface other compiled modules cimport (``from humanoid_twin.bus.network cimport
# CanController``; then a ``cdef public CanController controller`` attribute or a typed local
# makes these calls C calls):
#   send(msg) -> bint, send_at(msg, t_us) -> bint, abort() -> long long (frames dropped),
#   load_tx(frame, arbitration_id, payload) -> the Frame to send (bus/frames.pxd), clear_status().
# ``pending`` stays a Python property (for C code: ``_n_pending`` is the wire's own field).
# The clock's C calls for the boards are in clock.pxd (``Clock.due_by(t_us)``: is an event due
# at or before t_us).
cimport cython
from humanoid_twin.clock cimport Clock
from humanoid_twin.bus.foreign cimport ForeignPath
from humanoid_twin.bus.twin_bus cimport RxPort
# the frame length, computed in C on every call (cheaper than the lru_cache the interpreted
# source puts in front of it under this name: frames.py)
from humanoid_twin.bus.frames cimport _frame_bits as _frame_bits_cached
# the wire's own frame record (a C struct; python-can messages only for listeners and foreign buses)
from humanoid_twin.bus.frames cimport Frame, load_frame

# the constants the per-frame path computes with, as C values
cdef long long US_PER_S
cdef long long STD_ID_MAX
cdef long long TRAILING_RECESSIVE_BITS
cdef int _OK, _DROP, _CORRUPT
cdef int _MAX_INLINE

cdef class CanNetwork

cdef class CanController:
    cdef public object name
    cdef public object bus
    cdef public long long tec
    cdef public long long rec
    cdef public object state
    cdef public bint silenced
    cdef public bint recovering
    cdef public long long frames_sent
    cdef public long long tx_refused
    cdef public long long tx_aborted
    cdef public long long tx_errors
    cdef public long long rx_errors
    cdef public long long bus_off_count
    cdef public long long recoveries
    # the wire's own fields (bus/network.py, confinement.py, foreign.py; nobody else)
    cdef CanNetwork _net
    cdef public object _on_rx
    cdef long long _tx_buffers
    cdef public long long _n_pending
    cdef public bint _off
    cdef long long _suspend_until
    cdef public long long _rec_count
    cdef public long long _rec_mark
    cdef public object _filt
    cdef public bint _external
    cdef Frame _loaded
    cdef long long _loaded_bits
    cdef public RxPort _port

    cpdef bint send(self, object msg) except -1
    @cython.locals(net=CanNetwork, clock=Clock)
    cpdef bint send_at(self, object msg, long long t_us) except -1
    cpdef long long abort(self) except -1
    cpdef clear_status(self)
    @cython.locals(data=bytes, n=cython.longlong, frame=Frame, last=Frame, bits=cython.longlong)
    cpdef Frame load_tx(self, object msg, int arbitration_id, object payload)


# a TX request: typed C fields (no tuple, no Python ints per frame); only this module uses them
@cython.final
cdef class _Request:
    cdef long long key
    cdef long long req
    cdef CanController ctrl
    cdef Frame frame
    cdef long long bits


cdef class CanNetwork(ForeignPath):
    cdef long long _bit_us
    cdef bint _twin
    cdef object _medium
    cdef dict _controllers
    cdef dict _external
    cdef list _listeners
    cdef list _pending
    cdef Py_ssize_t _n_req
    cdef list _spare
    cdef Py_ssize_t _n_spare
    cdef bint _busy
    cdef long long _start
    cdef _Request _current
    cdef bint _current_aborted
    cdef int _outcome
    cdef long long _idle_from
    cdef long long _seq
    cdef int _inline
    cdef bint _faults_on
    cdef double _drop_prob
    cdef double _corrupt_prob
    cdef object _rng
    cdef public long long frames_sent
    cdef public long long frames_dropped
    cdef public long long error_frames
    cdef public long long busy_us
    cdef bint _closed
    cdef object _decide_cb
    cdef object _complete_cb
    cdef object _error_cb

    cpdef long long _dur(self, long long bits) except? -1
    @cython.locals(arb=cython.longlong, bits=cython.longlong, seq=cython.longlong,
                   now=cython.longlong, clock=Clock,
                   frame=Frame, n=Py_ssize_t, r=_Request)
    cpdef bint _request(self, CanController ctrl, object msg, long long at=*) except -1
    # the wire's small steps, one copy each, inlined where they are called
    @cython.locals(n=Py_ssize_t)
    cdef inline int _add(self, _Request r) except -1
    @cython.locals(n=Py_ssize_t)
    cdef inline int _release(self, _Request r) except -1
    @cython.locals(idle=cython.longlong, start=cython.longlong)
    cdef inline int _kick(self, long long now) except -1
    @cython.locals(e=_Request, c=CanController, key=cython.longlong, best_key=cython.longlong,
                   best=_Request, pending=list, k=Py_ssize_t)
    cpdef _Request _pick(self, long long start)
    @cython.locals(start=cython.longlong, e=_Request, c=CanController, best=_Request,
                   pending=list, k=Py_ssize_t)
    cpdef _decide(self)
    @cython.locals(bits=cython.longlong, outcome=cython.int, end=cython.longlong,
                   bu=cython.longlong, t_eof=cython.longlong, clock=Clock, pending=list,
                   i=Py_ssize_t, n=Py_ssize_t)
    cpdef _begin(self, _Request best, long long start)
    @cython.locals(cur=_Request, ctrl=CanController, frame=Frame, t=cython.longlong, pending=list,
                   idle=cython.longlong, start=cython.longlong, first=cython.longlong,
                   e=_Request, c=CanController, r=cython.longlong, sof=cython.longlong,
                   best=_Request, k=Py_ssize_t)
    cpdef _complete(self)
    @cython.locals(e=_Request, ctrl=CanController, c=CanController)
    cpdef _error(self)
    @cython.locals(n=cython.longlong, pending=list, kept=Py_ssize_t, k=Py_ssize_t, cur=_Request,
                   e=_Request)
    cpdef long long _abort(self, CanController ctrl) except -1
