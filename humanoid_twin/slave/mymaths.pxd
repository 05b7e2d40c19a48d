# C declarations for mymaths.py (MyMATHS, the compiled core): the same source, compiled. Angles
# and table values are C longs; the table stays the module's tuple (SINE_TABLE is public).

cpdef long seno(long angle_deg) except? -9999
cpdef long coseno(long angle_deg) except? -9999
