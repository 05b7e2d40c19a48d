# C declarations for wire.py (the compiled core, docs/architecture.md): the same source, compiled.
# Every function keeps its Python API (host, boards, plant and tests call it with any value and
# get the source's checks and messages): arguments stay ``object``; C types only for results that
# are bytes or int8 by the source's own check. Compiled modules cimport them for C calls.
cimport cython

cpdef object _address_error(object value, object what, long long lo)
cpdef object scu_error(object scu, object what=*)
cpdef object check_scu(object scu, object what=*, object error=*)
cpdef object node_error(object node, object what=*)
cpdef str node_name(object node)
cpdef object int_in_range(object name, object value, object lo, object hi, object what)
cpdef str _span(object lo, object hi)
cpdef long long s8(object value) except? -1
cpdef long long from_s8(object byte) except? -1
