# C declarations for database.py (GLOBAL, the compiled core, docs/architecture.md): the same
# source, compiled. Every field is public: the recorder, the monitor and the tests read the
# board's database. The fields are the PIC's integers (int8 positions, bytes, counters) and bits.

cdef class SensorStatus:
    cdef public bint pwm
    cdef public bint calib
    cdef public bint filter
    cdef public bint deadlineError
    cdef public bint motionFinAll
    cdef public bint motionFinOne
    cdef public list motionFin


cdef class StructServo:
    cdef public long pos
    cdef public long vel
    cdef public long current


cdef class Sensors:
    cdef public SensorStatus sysStatus
    cdef public list servo
    cdef public list special


cdef class ActuatorStatus:
    cdef public bint pwm
    cdef public bint calib


cdef class Control:
    cdef public long kp
    cdef public long kd
    cdef public long ki
    cdef public long type


cdef class ActuatorServo:
    cdef public long ref
    cdef public long speed


cdef class Actuators:
    cdef public ActuatorStatus sysStatus
    cdef public list control
    cdef public list servo
    cdef public long long received


cdef class Global:
    cdef public Sensors sensors
    cdef public Actuators actuators

    cpdef initGlobal(self)
    cpdef initSensors(self)
    cpdef initActuators(self)
    cpdef reinitServo(self)
