# C declarations for data.py (DATA, the compiled core): the same source, compiled. Forces are
# 7-bit counts, coordinates tenths of a millimetre, sines x100: C long arithmetic far from any
# overflow (a CoP sum is < 4 * 127 * 350; a Jacobian product < 10^7). calcCoP stays callable
# from Python (the Master's supervisor runs it too) and from C (cimport it).
cimport cython

cpdef long long divround(long long n, long long d) except? -1
@cython.locals(f0=cython.long, f1=cython.long, f2=cython.long, f3=cython.long, total=cython.long,
               x0=cython.long, x1=cython.long, x2=cython.long, x3=cython.long, y0=cython.long,
               y1=cython.long, y2=cython.long, y3=cython.long, den=cython.long, x=cython.long,
               y=cython.long)
cpdef tuple calcCoP(object forces)
cpdef long long _cdiv100(long long n) except? -1
@cython.locals(s0=cython.long, s1=cython.long, s2=cython.long, a=cython.long, b=cython.long,
               bc=cython.long, sa=cython.long, ca=cython.long, sb=cython.long, cb=cython.long,
               sbc=cython.long, cbc=cython.long, A=cython.long, B=cython.long, z=cython.long,
               y=cython.long, bs=cython.long, bcz=cython.long, j11=cython.long, j12=cython.long,
               j13=cython.long, j31=cython.long, j32=cython.long, j33=cython.long)
cpdef tuple jacobianMatrix(long q0, long q1, long q2, object signs=*)
