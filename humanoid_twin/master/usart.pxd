# C declarations for usart.py (the compiled core, docs/architecture.md): the same source, compiled.
cimport cython

from humanoid_twin.clock cimport Clock
from humanoid_twin.master.can cimport MasterCan
from humanoid_twin.master.database cimport Database, MasterCounters, ScuActuation, ScuSensors
from humanoid_twin.master.supervisor cimport Supervisor
from humanoid_twin.protocol.rs232 cimport bcc, data_response, invalid_reason, status_response
from humanoid_twin.protocol.wire cimport from_s8, s8

# constants of the per-byte path as C values (FRAME_GAP_US and PROCESS_US stay Python names:
# serve.py and the tests import them)
cdef long long FRAME_LEN, SOF


cdef class Usart:
    cdef public Clock clock
    cdef public Supervisor supervisor
    cdef public object link
    cdef public Database db
    cdef public MasterCan can
    cdef public bytearray rx_buf
    cdef public long long rx_len
    cdef public long long rx_last_us
    cdef public bytearray ext_buf
    cdef public long long ext_len
    cdef public bytearray tx_buf
    cdef public long long tx_len
    cdef public long long tx_pos
    cdef public object last_invalid

    cpdef usartInit(self)
    @cython.locals(now=cython.longlong, c=MasterCounters)
    cpdef bint usartStoreRx(self, long long byte)
    @cython.locals(b=cython.longlong)
    cpdef object usartGetTx(self)
    cpdef usartResetRxBuff(self)
    cpdef usartResetTxBuff(self)
    cpdef usartStore2extBuff(self, long long byte)
    @cython.locals(buf=bytearray, b=cython.longlong)
    cpdef rx_byte(self, long long byte)
    @cython.locals(c=MasterCounters, buf=bytearray, i=cython.longlong, keep=cython.longlong)
    cpdef _resync(self)
    @cython.locals(out=bytearray)
    cpdef bytes tx_drain(self)
    cpdef tx_write(self, object response)
    cpdef _load_tx(self, object frame)
    cpdef usartSendTestMsg(self)
    cpdef usartSendStatus(self, long long status)
    @cython.locals(db=Database, a=ScuActuation, s=ScuSensors,
                   op=cython.longlong, scu=cython.longlong, param=cython.longlong)
    cpdef usartProcessMsg(self)
    cpdef _supervisor_request(self, long long d1)
