# C declarations for clock.py (the compiled core, docs/architecture.md): the same source,
# compiled. Times are C long long microseconds.
cimport cython

cdef class Clock:
    cdef public long long now_us
    cdef public list _queue
    cdef public long long _seq
    cdef public long long events_run
    cdef public long long _until

    cpdef schedule(self, long long t_us, object callback)
    cpdef schedule_fast(self, long long t_us, object callback)
    cpdef object next_due_us(self)
    cpdef bint due_by(self, long long t_us) except -1
    @cython.locals(queue=list)
    cpdef bint skip_to(self, long long t_us)
    @cython.locals(queue=list, n=cython.longlong, outer=cython.longlong, t=cython.longlong)
    cpdef run_until(self, long long t_us)
