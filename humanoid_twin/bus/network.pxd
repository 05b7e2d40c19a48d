# C declarations for network.py (the compiled core, docs/architecture.md): the same source,
# compiled. Virtual times, counters and bit lengths are C long long.
#
# The interface other compiled modules cimport (``from humanoid_twin.bus.network cimport
# CanController``; then a ``cdef public CanController controller`` attribute or a typed local
# makes these calls C calls):
#   send(msg) -> bint, send_at(msg, t_us) -> bint, abort() -> long long (frames dropped),
#   load_tx(msg, arbitration_id, payload) -> the can.Message to send, clear_status().
# ``pending`` stays a Python property (for C code: ``_n_pending`` is the wire's own field).
cimport cython

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
    cdef public object _net
    cdef public object _on_rx
    cdef public long long _tx_buffers
    cdef public long long _n_pending
    cdef public bint _off
    cdef public long long _suspend_until
    cdef public long long _rec_count
    cdef public long long _rec_mark
    cdef public object _filt
    cdef public bint _external
    cdef public object _loaded
    cdef public long long _loaded_bits

    cpdef bint send(self, object msg) except -1
    cpdef bint send_at(self, object msg, long long t_us) except -1
    cpdef long long abort(self) except -1
    cpdef clear_status(self)
    cpdef object load_tx(self, object msg, int arbitration_id, object payload)
