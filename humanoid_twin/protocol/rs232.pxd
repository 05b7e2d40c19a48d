# C declarations for rs232.py (the compiled core, docs/architecture.md): the same source,
# compiled. The codecs keep their Python API (the host toolbox, the bridges and the tests call
# them with any value and get the source's checks and messages): arguments a Python caller may
# give as anything stay ``object``; bytes already checked are C long long. The Master's USART
# cimports bcc, status_response and data_response for C calls.
cimport cython

from humanoid_twin.protocol.wire cimport from_s8, int_in_range, s8, scu_error

cpdef str hexdump(object data)
@cython.locals(x=cython.longlong, b=cython.longlong)
cpdef long long bcc(object data) except? -1
cpdef long long _byte(object name, object value) except? -1
cpdef bytes _frame(long long b0, long long b1, long long b2, long long b3, long long b4)
cpdef long long _join_opcode(long long op, long long scu, long long param) except? -1
cpdef tuple _split_opcode(long long opcode)
cpdef long long make_opcode(object op, object scu, object param) except? -1
cpdef tuple parse_opcode(object opcode)
cpdef bytes encode_request(object op, object scu, object param, object d1=*, object d2=*, object d3=*)
cpdef bytes _check_frame(object frame)
@cython.locals(x=cython.longlong)
cpdef _check_bcc(bytes frame)
cpdef bytes status_response(object request, object status)
cpdef bytes data_response(object v1, object v2, object v3, object v4)
cpdef object decode_response(object frame)
cpdef object invalid_reason(object req)
cpdef bint is_valid_request(object req)
