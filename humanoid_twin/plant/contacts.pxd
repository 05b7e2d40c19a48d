# C declarations for contacts.py (the compiled core, docs/architecture.md): the same source,
# compiled. MjData's arrays as C memoryviews; the scan, the hull and the margin on C doubles.
# math is C's libm here (sin, cos, acos: the functions Python's math calls); hypot stays Python's.
cimport cython
from libc cimport math

cdef double _DEG
cdef double _RAD
cdef double _LOADED_MIN_N
cdef double _FELL_HEIGHT_M
cdef double _FELL_TILT_DEG

@cython.locals(m=cython.long, i=cython.long, j=cython.long, k=cython.long, x=cython.double, y=cython.double,
               h=cython.long, rev=cython.long, c0=cython.long, i0=cython.long, step=cython.long, s=cython.long,
               ox=cython.double, oy=cython.double, ax=cython.double, ay=cython.double, bx=cython.double,
               by=cython.double)
cpdef long convex_hull_xy(long n, double[::1] xs, double[::1] ys, double[::1] hx, double[::1] hy) except -1

@cython.locals(ax=cython.double, ay=cython.double, first=cython.long, inside=cython.bint, nearest=cython.double,
               dist=cython.double, i=cython.long, bx=cython.double, by=cython.double, ex=cython.double,
               ey=cython.double, den=cython.double, t=cython.double)
cpdef double signed_distance_xy(double px, double py, long k, double[::1] hx, double[::1] hy) except? -1.0

cdef double _acos_deg(double x)

cdef class TruthSample:
    cdef readonly double tilt_deg
    cdef readonly double height_m
    cdef readonly bint fell
    cdef readonly double total_n
    cdef readonly double margin_mm
    cdef readonly list pad_forces_n
    cdef readonly list foot_cop_mm
    cdef readonly object cop_xy
    cdef readonly list hull
    cdef readonly tuple soles_mm
    cdef readonly list com
    cdef readonly list joints_rad

cdef class ContactScan:
    cdef int[::1] _pad
    cdef long long[::1] _sole
    cdef long _trunk
    cdef long long[::1] _qadr
    cdef double[:, ::1] _xpos
    cdef double[:, ::1] _xmat
    cdef double[:, ::1] _com
    cdef double[:, ::1] _site_pos
    cdef double[:, ::1] _site_mat
    cdef double[::1] _qpos
    cdef long _cap
    cdef int[::1] _pid
    cdef double[::1] _fn
    cdef double[::1] _px
    cdef double[::1] _py
    cdef double[::1] _pz
    cdef double[::1] _sx
    cdef double[::1] _sy
    cdef double[::1] _hx
    cdef double[::1] _hy
    cdef double[::1] _padf

    cdef _grow(self, long n)
    @cython.locals(n=cython.long, pad=cython.int[::1], pid=cython.int[::1], fn=cython.double[::1],
                   px=cython.double[::1], py=cython.double[::1], pz=cython.double[::1], k=cython.long,
                   c=cython.long, p=cython.long, q=cython.long, a=cython.long, f=cython.double)
    cdef long _scan(self, int[:, :] geom, int[:] adr, double[:, :] pos, double[:] force, bint edges,
                    long foot) except -1
    @cython.locals(pid=cython.int[::1], fn=cython.double[::1], px=cython.double[::1], py=cython.double[::1],
                   pz=cython.double[::1], sx=cython.double, sy=cython.double, sz=cython.double, i=cython.long,
                   s=cython.long, o=cython.double[:, ::1], r=cython.double[:, ::1], vx=cython.double,
                   vy=cython.double, vz=cython.double)
    cdef tuple _foot_cop(self, long k, long f, double total)
    @cython.locals(k=cython.long, fn=cython.double[::1], tot=cython.double, i=cython.long)
    cpdef object foot_cop(self, int[:, :] geom, int[:] adr, double[:, :] pos, double[:] force, bint edges, long f)
    cpdef object foot_cop_of(self, object data, long f)
    cpdef double tilt_deg(self)
    @cython.locals(t=cython.long, xpos=cython.double[:, ::1], xmat=cython.double[:, ::1], a=cython.double,
                   s=cython.double, c=cython.double, height=cython.double)
    cpdef bint fallen(self, double tilt_deg, double platform_tilt_deg) except -1
    @cython.locals(a=cython.double, s=cython.double, c=cython.double, pos=cython.double[:, ::1], out=list,
                   f=cython.long, site=cython.long, x=cython.double, y=cython.double, z=cython.double)
    cpdef tuple soles_mm(self, double platform_tilt_deg)
    @cython.locals(out=TruthSample, t=cython.long, tilt=cython.double, k=cython.long, pid=cython.int[::1],
                   fn=cython.double[::1], px=cython.double[::1], py=cython.double[::1], pad_f=cython.double[::1],
                   j=cython.long, i=cython.long, wx=cython.double, wy=cython.double, f=cython.double,
                   foot0=cython.double, foot1=cython.double, total=cython.double, xs=cython.double[::1],
                   ys=cython.double[::1], hx=cython.double[::1], hy=cython.double[::1], h=cython.long,
                   cx=cython.double, cy=cython.double, com=cython.double[:, ::1], qpos=cython.double[::1],
                   qadr=cython.longlong[::1])
    cpdef TruthSample truth(self, int[:, :] geom, int[:] adr, double[:, :] pos, double[:] force, bint edges,
                            double platform_tilt_deg)
    cpdef TruthSample truth_of(self, object data, double platform_tilt_deg)
