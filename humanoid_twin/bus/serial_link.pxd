# C declarations for serial_link.py (the compiled core): the RS-232 cable, one clock event per
# byte. Times are C long long microseconds; a burst's byte count ``n`` stays a Python int (the
# stop-bit time n * bits * 1e6 / baud of an endless burst must not overflow).
cimport cython
from humanoid_twin.clock cimport Clock

cdef class _Direction:
    cdef public long long burst_start
    cdef public object n
    cdef public long long last_end
    cdef public object queue


cdef class SerialLink:
    cdef public Clock clock
    cdef public long long baudrate
    cdef public long long bytesize
    cdef public object parity
    cdef public long long stopbits
    cdef public long long bits_per_byte
    cdef long long _num
    cdef _Direction _to_dev
    cdef _Direction _to_host
    cdef object _device_rx
    cdef list _taps
    cdef double _noise_prob
    cdef object _rng
    cdef public long long bytes_to_device
    cdef public long long bytes_to_host
    cdef public long long bytes_corrupted
    cdef public long long bytes_lost

    @cython.locals(now=cython.longlong, times=list, noisy=bint, t=cython.longlong)
    cpdef list _push(self, _Direction d, bytes data)
    cpdef device_write(self, object data)
    cpdef host_write(self, object data)
    @cython.locals(q=object, cb=object)
    cpdef _deliver_to_device(self)
    @cython.locals(q=object, now=cython.longlong, out=bytearray)
    cpdef bytes host_read_available(self)
    cpdef object next_host_byte_us(self)
    cpdef long long host_out_waiting(self) except -1
    cpdef bint host_pending(self) except -1
    cpdef object host_byte_us(self, long long n)
