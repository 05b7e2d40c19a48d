# C declarations for frames.py (the compiled core, docs/architecture.md): the same source,
# compiled. The frame length is computed on C integers from two C tables; the wire
# (network.pxd) cimports _frame_bits and calls it for every frame a board loads (a C call, no
# cache: computing the length costs less than the cache's lookup). The interpreted source keeps
# the lru_cache (_frame_bits_cached) in front of it.
cimport cython

cdef long long STD_ID_MAX
cdef unsigned short _CRC15_TABLE[256]
cdef unsigned char _STUFF_TABLE[2048]

@cython.locals(n=cython.longlong, head=cython.longlong, byte=cython.long, crc=cython.long,
               e=cython.long, s=cython.long, stuffed=cython.long, i=cython.longlong)
cpdef long long _frame_bits(long long arbitration_id, bytes data) except -1


cdef class Frame:
    cdef public long arbitration_id
    cdef public long dlc
    cdef public bytes data
    cdef public double timestamp
    cdef public object channel
    cdef public bint is_rx
    cdef public long long bits

    cpdef object to_message(self)

cpdef Frame load_frame(Frame frame, long arbitration_id, bytes data, long long bits)
cpdef object as_message(object msg)
