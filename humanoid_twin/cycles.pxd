# C declarations for cycles.py (the compiled core, docs/architecture.md): the same source,
# compiled. The boards charge their cycles on every pass and every timer interrupt; the Master's
# pic.pxd and the Slave's slave.pxd cimport cycles_to_us, a C call there.
cdef long long US_PER_S

cpdef long long cycles_to_us(long long cycles, long long ips) except? -1
