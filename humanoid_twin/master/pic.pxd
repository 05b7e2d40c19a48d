# C declarations for pic.py (the compiled core, docs/architecture.md): the same source, compiled.
cimport cython

from humanoid_twin.clock cimport Clock
from humanoid_twin.master.can cimport MasterCan
from humanoid_twin.cycles cimport cycles_to_us   # the cycles of a timer slot, a C call
from humanoid_twin.master.database cimport Database
from humanoid_twin.master.supervisor cimport Supervisor

cdef long long N_SCU   # a C value here (ROUND_US and the other periods stay Python names)
cdef long long _SLOT_US
cdef long long _C_TIMER_TX
cdef long long _C_TIMER_RX
cdef long long _C_CAN_RX
cdef long long _C_USART
from humanoid_twin.master.usart cimport Usart


cdef class Pic:
    cdef public Clock clock
    cdef public Supervisor supervisor   # on_round: a C call
    cdef public Usart usart
    cdef public MasterCan can
    cdef public Database db
    cdef public long long slot
    cdef public long long slave
    cdef public long long started_us
    cdef bint _round_open
    cdef public long long ips
    cdef public long long isr_cycles
    cdef public long long busy_until_us
    cdef public double slot_load_max
    cdef public long long slot_overruns
    cdef public long long slots_lost
    cdef bint _timer_pending
    cdef object _late_cb

    cpdef initPic(self)
    cpdef isr_usart_rx(self, long long byte)
    cpdef isr_can_rx(self, object msg)
    @cython.locals(now=cython.longlong, slot=cython.longlong, cycles=cython.longlong, us=cython.longlong,
                   load=cython.double)
    cpdef isr_timer(self)
    cpdef _isr_timer_late(self)
