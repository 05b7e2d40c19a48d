# C declarations for canframes.py (the CAN payload codecs, the compiled core): the same source,
# compiled. The codecs keep their Python API (the host, the recorder, the DBC script and the tests
# call them); compiled boards cimport them for C calls:
#
#   from humanoid_twin.protocol.canframes cimport (unpack_actuation1, unpack_sensors1, ...)
#
# Arguments that Python callers may give as any sequence, or as values to be range-checked with
# PayloadError (a byte 300, a negative address), stay ``object``: the checks and their messages
# are the source's. Identifiers and bytes that are checked by C comparisons are C longs.
cimport cython

# C constants of the codecs (private names and aliases; canframes.py)
cdef long _CAN_STATE, _CAN_STATE_MAX, _SUPERVISOR, _LAW, _CURRENT_MAX, _SF_SHIFT, _SF_INDEX
cdef long _ADDR_MASK, _SFLAGS_LOW, _SRC_SHIFT, _DST_SHIFT, _INDEX_SHIFT, _OP_MASK, _PAYLOAD_LEN
cdef long _PWM, _CALIB, _TYPE_BITS, _TYPE_MASK
cdef tuple _INT8

cdef bint _COMPILED

@cython.locals(b=bytes)
cpdef bytes _payload(object data, str packet)
cdef bytes _bytes8(unsigned char b0, unsigned char b1, unsigned char b2, unsigned char b3,
                   unsigned char b4, unsigned char b5, unsigned char b6, unsigned char b7)

cpdef long can_id(object src, object dst, object index, object op) except? -1
cpdef tuple split_id(object arbitration_id)
cpdef long packet_index(long arbitration_id) except? -1
cpdef long control_byte(object pwm, object calib, object types) except? -1
cpdef tuple parse_control_byte(object b)

# the Slave's receive path: an actuation packet's fields written into its record (C fields)
cdef class ActuationFields:
    cdef public long ref1, ref2, ref3, speed1, speed2, speed3, control
    cdef public bint pwm, calib
    cdef public long type1, type2, type3, kd3, ki1, ki2, ki3, kp1, kp2, kp3, kd1, kd2

cdef void _control_into(long b, ActuationFields out) noexcept
cpdef long status_byte(object pwm, object calib, object deadline, object fin_all, object fin_one,
                       object fin) except? -1
cpdef object parse_status_byte(object b)
cpdef long sflags(object src, object index) except? -1
cpdef long _split_sflags(long sf, long index, str packet) except? -1
cpdef bytes pack_actuation1(object refs, object speeds, object control, object kd3)
@cython.locals(f=ActuationFields)
cpdef tuple unpack_actuation1(object data)
@cython.locals(b=bytes, i8=tuple)
cpdef unpack_actuation1_into(object data, ActuationFields out)
cpdef bytes pack_actuation2(object ki, object kp, object kd1, object kd2)
@cython.locals(f=ActuationFields)
cpdef tuple unpack_actuation2(object data)
@cython.locals(b=bytes)
cpdef unpack_actuation2_into(object data, ActuationFields out)
cpdef bytes pack_sensors1(object src, object pos, object speed, object status, object flags=*)
@cython.locals(b=bytes, src=cython.long, pos=list, vel=list, status=cython.long)
cpdef tuple unpack_sensors1(object data)
# the Master's receive path: the payload's fields straight into its database's lists
@cython.locals(b=bytes, sf_src=cython.long, i8=tuple)
cpdef long unpack_sensors1_into(object data, long src, list pos, list vel) except -1
@cython.locals(sf=cython.long)
cdef long _sensors1_source(bytes b) except -1
cdef object _source_error(long sf_src, long src)
cpdef bytes pack_sensors1_fields(long src, long pos1, long pos2, long pos3, long speed1, long speed2,
                                 long speed3, long status, long flags)
cpdef tuple supervisor_flags(object data)
cpdef bytes pack_sensors2(object src, object curr, object data4, object law_stopped=*)
@cython.locals(b=bytes, src=cython.long, curr=list, data4=list)
cpdef tuple unpack_sensors2(object data)
@cython.locals(b=bytes, sf_src=cython.long)
cpdef unpack_sensors2_into(object data, long src, list curr, list data4)
@cython.locals(c1=cython.long, c2=cython.long, c3=cython.long)
cdef long _sensors2_source(bytes b) except -1
cpdef bytes pack_sensors2_fields(long src, long curr1, long curr2, long curr3, long data1, long data2,
                                 long data3, long data4, bint law_stopped)
