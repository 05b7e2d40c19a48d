# C declarations for slave.py (the Slave's main loop, the compiled core): the same source,
# compiled. Virtual times, counters and the task times (ns) are C long long; the board's modules
# are the compiled classes of its modules; the plant and the network stay Python objects.
# Everything the recorder, the monitor, the faults and the tests read is public.
cimport cython

from humanoid_twin.clock cimport Clock
from humanoid_twin.slave.can cimport SlaveCan
from humanoid_twin.cycles cimport cycles_to_us   # the cycles of a pass, a C call
from humanoid_twin.slave.data cimport calcCoP
from humanoid_twin.slave.database cimport (
    Actuators,
    ActuatorServo,
    Control,
    Global,
    Sensors,
    SensorStatus,
    StructServo,
)
from humanoid_twin.slave.pic2 cimport Pic2
from humanoid_twin.slave.servo cimport Calibration, ServoControl
from humanoid_twin.slave.trajectory cimport StructTrajectory, Trajectory

cdef long N_SERVOS
cdef long N_SPECIAL_SENSORS
cdef long long PWM_PERIOD_US
cdef long LOCOMOTION_CONTROL
cdef long long PWM_BUSY_US
cdef long long _C_LOOP
cdef long long _C_SPECIAL
cdef long long _C_COP
cdef long long _C_CALIB
cdef long long _C_CONTROL
cdef long _CALIB_DONE


cdef class Slave:
    cdef public long address
    cdef public Clock clock
    cdef public object plant
    cdef public object network
    cdef public long long phase_us
    cdef public bint has_foot
    cdef public Global db
    cdef public Sensors sensors
    cdef public Actuators actuators
    cdef public Trajectory traj
    cdef public ServoControl servo
    cdef public Calibration calib
    cdef public Pic2 pic
    cdef public SlaveCan can
    cdef public long cop_x
    cdef public long cop_y
    cdef public bint cop_loaded
    cdef public long long ticks
    cdef public long long deadline_violations
    cdef public long long task_ns_total
    cdef public long long task_ns_max
    cdef public long long ips
    cdef public long long task_cycles
    cdef public long long task_us
    cdef public double task_load_max
    cdef public long long busy_until_us
    cdef public long long ticks_skipped
    cdef bint _outputs_due
    cdef bint _overran
    cdef bint _pass_late
    cdef object _finish_cb
    cdef object _overrun_cb
    cdef long long _due_us
    cdef readonly long long _delay_us
    cdef readonly long long _delay_ticks
    cdef list _still
    cdef list _refs
    cdef list _periods
    cdef list _types
    cdef list _start

    cpdef long long next_tick_us(self) except? -1
    cpdef emergency_stop(self)
    @cython.locals(now=cython.longlong)
    cpdef _tick(self)
    @cython.locals(now=cython.longlong, t0=cython.longlong, step0=cython.longlong,
                   late=bint, last=cython.longlong, can_=SlaveCan, pic=Pic2, act=Actuators,
                   st=SensorStatus, calib=Calibration, traj=Trajectory, servo=ServoControl,
                   types=list, refs=list, periods=list, start=list, i=cython.long,
                   a=ActuatorServo, c=Control, tr=StructTrajectory, restarted=cython.long, sv=list, still=list, fin=list,
                   done=bint, n_fin=cython.long, s=StructServo, p=cython.long, v=cython.long,
                   f=bint, target=cython.long, d=cython.long, sp=list, k=cython.long,
                   dt=cython.longlong, cycles=cython.longlong, us=cython.longlong,
                   load=cython.double, end=cython.longlong)
    cpdef loop(self)
    @cython.locals(can_=SlaveCan)
    cpdef _finish(self)
    cpdef _overrun(self)
    @cython.locals(calib=Calibration, pic=Pic2, act=Actuators, i=cython.long)
    cpdef _calibration_step(self)
