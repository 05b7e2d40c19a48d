# C declarations for clock.py (the compiled core, docs/architecture.md): the same source,
# compiled. Times are C long long microseconds; the event queue's due times, sequence numbers
# and periods are C long long memoryviews over the source's array('q'), so the heap's sifting
# compares C integers (no tuple, no Python comparison per step).
cimport cython

cdef long long _QUEUE_START
cdef bint _COMPILED

cdef class Clock:
    cdef public long long now_us
    cdef public long long events_run
    cdef long long _until
    cdef long long _seq
    cdef long long _n
    cdef long long[::1] _t
    cdef long long[::1] _s
    cdef long long[::1] _p
    cdef list _cb
    cdef list _queue

    # the heap's primitives (inline: the public methods compile to the code they had inlined)
    cdef inline long long _first_due(self)
    @cython.locals(t=cython.longlong, period=cython.longlong)
    cdef inline int _run_first(self) except -1
    @cython.locals(i=cython.longlong)
    cdef void _grow(self)
    @cython.locals(seq=cython.longlong, i=cython.longlong, up=cython.longlong, tu=cython.longlong,
                   T="long long[::1]", S="long long[::1]", P="long long[::1]", CB=list)
    cdef int _push(self, long long t_us, long long period_us, object callback) except -1
    @cython.locals(n=cython.longlong, t=cython.longlong, s=cython.longlong, p=cython.longlong,
                   i=cython.longlong, c=cython.longlong, tc=cython.longlong, sc=cython.longlong,
                   tr=cython.longlong, T="long long[::1]", S="long long[::1]", P="long long[::1]",
                   CB=list)
    cdef void _pop(self)
    cpdef schedule(self, long long t_us, object callback)
    cpdef schedule_fast(self, long long t_us, object callback)
    @cython.locals(due=cython.longlong)
    cpdef object next_due_us(self)
    @cython.locals(due=cython.longlong)
    cpdef bint due_by(self, long long t_us) except -1
    @cython.locals(due=cython.longlong)
    cpdef bint skip_to(self, long long t_us)
    @cython.locals(n=cython.longlong, outer=cython.longlong, due=cython.longlong)
    cpdef run_until(self, long long t_us)
