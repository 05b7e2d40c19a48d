# C declarations for sensors.py (the compiled core, docs/architecture.md): the same source,
# compiled. MjData's arrays as C memoryviews, taken once; the arithmetic on C doubles.
cimport cython

from humanoid_twin.plant.stepping cimport PhysicsTime

cdef bint _COMPILED
cdef double _DEG
cdef double _COUNTS
cdef double _POT_COUNTS_PER_DEG
cdef long _POT_ADC_MAX
cdef long _CURRENT_FULL_US
cdef long _CURRENT_IDLE_US
cdef long _FORCE_ADC_MAX

@cython.locals(a=cython.double, r=cython.long, d=cython.double)
cpdef long round_half_even(double x) except? -1

cdef class SensorFrontEnd:
    cdef const double[::1] _qpos
    cdef const double[::1] _qvel
    cdef const double[::1] _force
    cdef const double[::1] _sensordata
    cdef double[::1] _fscale
    cdef double[::1] _foffset
    cdef long long[::1] _fzero
    cdef bint _has_offset

    @cython.locals(v=cython.long)
    cpdef set_force_calibration(self, long adr, double gain, double offset_counts)

    @cython.locals(i=cython.long, qadr=cython.long, dadr=cython.long, a=cython.long, sign=cython.long,
                   stall=cython.double, damping=cython.double, deg=cython.double, x=cython.double, v=cython.long,
                   torque=cython.double, load=cython.double, w=cython.long, adc=list, cur=list)
    cpdef tuple servos(self, tuple rows, tuple b_true, list powered, list noise)
    @cython.locals(k=cython.long, adr=cython.long, f=cython.double, x=cython.double, v=cython.long, out=list)
    cpdef list forces(self, tuple adrs, list noise)
    @cython.locals(w=cython.double, x=cython.double, y=cython.double, z=cython.double,
                   roll=cython.double, s=cython.double, pitch=cython.double)
    cpdef tuple attitude(self, long quat_adr, long gyro_adr)

cdef long _IMU_SCU
cdef long _NOISE_BLOCK

cdef class BoardIO(PhysicsTime):
    # set by Plant (plant/plant.py, interpreted: so they are public), which documents them; C
    # fields so a board's read stays in C
    cdef public object _imu
    cdef public SensorFrontEnd _sense
    cdef public dict _servo
    cdef public dict _foot_touch_of_scu
    cdef public dict pot_b_true_deg
    cdef public list _powered
    cdef public list _pot_noise
    cdef public list _force_noise
    cdef public bint _force_fault

    @cython.locals(noise=list)
    cpdef tuple read_servos(self, scu)
    @cython.locals(noise=list, out=list)
    cpdef list read_force_adc(self, scu)
    cpdef list read_imu_adc(self, scu)
