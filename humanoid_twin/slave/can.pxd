# C declarations for can.py (CAN and lowISR, the compiled core): the same source, compiled.
# Virtual times and counters are C long long; the board's CAN controller is the wire's
# CanController (bus/network.pxd: load_tx, send, send_at, abort, clear_status are C calls); the
# payload codecs are cimported from protocol/canframes.pxd. Every field the recorder, the
# supervisor tests and the fault tests read is public.
cimport cython

from humanoid_twin.bus.frames cimport Frame
from humanoid_twin.bus.network cimport CanController
from humanoid_twin.clock cimport Clock
from humanoid_twin.protocol.canframes cimport (
    pack_sensors1_fields,
    ActuationFields,
    pack_sensors2_fields,
    status_byte,
    unpack_actuation1_into,
    unpack_actuation2_into,
)
from humanoid_twin.slave.database cimport (
    ActuatorServo,
    ActuatorStatus,
    Actuators,
    Control,
    Global,
    Sensors,
    SensorStatus,
    StructServo,
)

cdef long PWM_BUSY_US
cdef long PWM_PERIOD_US
cdef long SFLAGS_WATCHDOG
cdef long long _C_ISR_RX
cdef long long _C_ISR_TX
cdef long long _C_ISR_OTHER


cdef class SlaveCan:
    cdef public long address
    cdef public Clock clock
    cdef public Global db
    cdef public long long phase_us
    cdef public CanController controller
    cdef public object node_name
    cdef public list payload
    cdef public bint calib_request
    cdef tuple _sensor_ids
    cdef dict _rx_index
    cdef long _rx_id1
    cdef long _rx_id2
    cdef ActuationFields _rx_fields
    cdef list _tx_msgs
    cdef object _isr_send_cb
    cdef long _tx_index
    cdef long long _tx_due_us
    cdef public long long rx_packets
    cdef long long _rx_ignored
    cdef public long long rx_errors
    cdef public long long tx_packets
    cdef public long long tx_silent
    cdef public long long bus_off_recoveries
    cdef public long long last_rx_us
    cdef public bint watchdog
    cdef public bint law_stopped
    cdef public bint bus_off_seen
    cdef public object on_stop
    cdef public long long isr_cycles
    cdef long long _skipped_seen

    @cython.locals(now=cython.longlong, due=cython.longlong, arb=cython.long, index=cython.long)
    cpdef lowISR(self, Frame msg)
    @cython.locals(c=CanController, skipped=cython.longlong, cycles=cython.longlong)
    cpdef long long take_isr_cycles(self) except? -1
    cpdef _isr_send(self)
    @cython.locals(act=Actuators, sys_=ActuatorStatus, st=SensorStatus, a0=ActuatorServo,
                   a1=ActuatorServo, a2=ActuatorServo, c0=Control, c1=Control, c2=Control, pwm=bint,
                   calib=bint, f=ActuationFields)
    cpdef bint receiveCanMessage(self, long index, object data) except -1
    @cython.locals(controller=CanController)
    cpdef sendCanMessage(self, long index, long long at_us=*)
    @cython.locals(c=CanController)
    cpdef bint checkCan(self) except -1
    @cython.locals(s=Sensors, st=SensorStatus, s0=StructServo, s1=StructServo, s2=StructServo,
                   status=cython.long, flags=cython.long, c=CanController, d1=cython.long,
                   d2=cython.long, d3=cython.long, d4=cython.long)
    cpdef prepareSensorPackets(self)
