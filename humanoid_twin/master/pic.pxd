# C declarations for pic.py (the compiled core, docs/architecture.md): the same source, compiled.
cimport cython

from humanoid_twin.clock cimport Clock
from humanoid_twin.master.can cimport MasterCan
from humanoid_twin.master.database cimport Database

cdef long long N_SCU   # a C value here (ROUND_US and the other periods stay Python names)
from humanoid_twin.master.usart cimport Usart


cdef class Pic:
    cdef public Clock clock
    # the Supervisor as a Python object: supervisor.py imports this package's pic.py (ROUND_US)
    cdef public object supervisor
    cdef public Usart usart
    cdef public MasterCan can
    cdef public Database db
    cdef public long long slot
    cdef public long long slave
    cdef public long long started_us
    cdef public bint _round_open

    cpdef initPic(self)
    cpdef isr_usart_rx(self, long long byte)
    cpdef isr_can_rx(self, object msg)
    @cython.locals(slot=cython.longlong)
    cpdef isr_timer(self)
