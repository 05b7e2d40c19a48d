"""The ground truth's arithmetic on MuJoCo's arrays (humanoid_twin/plant/truth.py calls it): the
pad/ground contact scan, the pads' forces, the whole robot's and each foot's CoP, the support
polygon (convex hull) and the CoP margin, the trunk's tilt and the fall test, the soles on the
platform.

Part of the compiled core (contacts.pxd): one call per sample reads MjData's arrays through C
memoryviews and does every loop in C, where the former truth (plain Python in truth.py) made a
Python object of every number it read. No MuJoCo import here: :class:`ContactScan` takes once
the arrays whose memory is MjData's for the plant's whole life (``xpos``, ``xmat``,
``subtree_com``, ``site_xpos``, ``site_xmat``, ``qpos``), and at each call the contacts' arrays
of that instant (``geom``, ``efc_address``, ``pos``: ``ncon`` long) and the constraint forces
(``efc_force``), which MuJoCo moves as the number of contacts changes. (Interpreted, each
value read is turned into a Python float at once, as in ``sensors.py``; the contacts' arrays
may then be nested lists, as ``TruthProbe`` hands them over: a numpy scalar a value costs more
than one ``tolist`` an array.)

The figures are the same numbers on both cores: the same floating-point operations in the same
order (tests/plant/test_truth_core.py). The hull and the margin work on arrays here
(``plant/geometry.py`` gives them on point lists); Python's
``math.hypot`` is called on both cores (its result can differ from C's ``hypot`` in the last
bit); ``math.degrees`` and ``math.radians`` are their products by ``hardware.DEG_PER_RAD`` and
``hardware.RAD_PER_DEG``.
"""

from __future__ import annotations

import math
from array import array
from math import hypot as _hypot  # Python's own hypot on both cores (see above)
from math import inf as _inf
from typing import Any

from humanoid_twin.hardware import DEG_PER_RAD, RAD_PER_DEG
from humanoid_twin.plant import constants as C  # noqa: N812

__all__ = ["ContactScan", "TruthSample", "convex_hull_xy", "signed_distance_xy"]

_DEG = DEG_PER_RAD                    # C doubles in the compiled core
_RAD = RAD_PER_DEG
_LOADED_MIN_N = C.LOADED_MIN_N
_FELL_HEIGHT_M = C.FELL_HEIGHT_M
_FELL_TILT_DEG = C.FELL_TILT_DEG


def _doubles(n: int) -> Any:
    """A buffer of ``n`` C doubles (zeros)."""
    return array("d", bytes(8 * n))


def convex_hull_xy(n: int, xs: Any, ys: Any, hx: Any, hy: Any) -> int:
    """The convex hull of the ``n`` points ``(xs[i], ys[i])`` into ``hx``, ``hy`` (room for ``2 n``):
    its number of points (``plant/geometry.convex_hull`` on point lists): the distinct points sorted
    (x, then y; ``xs``, ``ys`` are sorted in place), then Andrew's monotone chain,
    counter-clockwise, no repeated end point, collinear points dropped; 0, 1 or 2 distinct
    points give a hull of that many points. Arrays too short for ``n`` are a ``ValueError``."""
    if n < 0 or len(xs) < n or len(ys) < n or len(hx) < 2 * n or len(hy) < 2 * n:
        raise ValueError(f"convex_hull_xy: {n} points need xs, ys of {n} and hx, hy of {2 * n} items")
    # sorted and distinct (as sorted(set(...)): of equal points the first stays), by insertion
    m = 0
    for i in range(n):
        x = xs[i]
        y = ys[i]
        j = m
        while j > 0 and (xs[j - 1] > x or (xs[j - 1] == x and ys[j - 1] > y)):
            j -= 1
        if j > 0 and xs[j - 1] == x and ys[j - 1] == y:
            continue                             # a point already there
        k = m
        while k > j:
            xs[k] = xs[k - 1]
            ys[k] = ys[k - 1]
            k -= 1
        xs[j] = x
        ys[j] = y
        m += 1
    if m <= 2:
        for i in range(m):
            hx[i] = xs[i]
            hy[i] = ys[i]
        return m
    h = 0                                        # the hull so far: hx[:h], hy[:h]
    for rev in range(2):                         # the lower chain, then the upper one
        # the chain is hx[c0:h]; its last two points o, a kept in locals; its first two always taken
        c0 = h
        i0 = m - 1 if rev else 0
        step = -1 if rev else 1
        ox = hx[h] = xs[i0]
        oy = hy[h] = ys[i0]
        ax = hx[h + 1] = xs[i0 + step]
        ay = hy[h + 1] = ys[i0 + step]
        h += 2
        for s in range(2, m):
            i = i0 + step * s
            bx = xs[i]
            by = ys[i]
            # o -> a -> b does not turn left (the cross product of o->a and o->b): drop a
            while (ax - ox) * (by - oy) - (ay - oy) * (bx - ox) <= 0:
                h -= 1
                ax = ox
                ay = oy
                if h - c0 < 2:
                    break
                ox = hx[h - 2]
                oy = hy[h - 2]
            hx[h] = bx
            hy[h] = by
            h += 1
            ox = ax
            oy = ay
            ax = bx
            ay = by
        h -= 1                                   # the chain's last point starts the other chain
    return h


def signed_distance_xy(px: float, py: float, k: int, hx: Any, hy: Any) -> float:
    """The signed distance (``plant/geometry.signed_distance``) of the point (px, py) to the hull ``hx[:k]``,
    ``hy[:k]`` (counter-clockwise): positive inside, negative outside, zero on the boundary;
    minus the distance to a point or a segment; ``-inf`` for no point. ``hx``, ``hy`` shorter
    than ``k`` are a ``ValueError``."""
    if k < 0 or len(hx) < k or len(hy) < k:
        raise ValueError(f"signed_distance_xy: a hull of {k} points needs hx, hy of {k} items")
    if k == 0:
        return -_inf
    if k == 1:
        return -_hypot(px - hx[0], py - hy[0])
    # the edges (a, b) of the polygon, the closing one first; a segment's one edge
    if k == 2:
        ax = hx[0]
        ay = hy[0]
        first = 1
    else:
        ax = hx[k - 1]
        ay = hy[k - 1]
        first = 0
    inside = True
    nearest = _inf
    dist = 0.0
    for i in range(first, k):
        bx = hx[i]
        by = hy[i]
        ex = bx - ax
        ey = by - ay
        # left of every edge of a counter-clockwise polygon = inside
        if inside and ex * (py - ay) - ey * (px - ax) < 0.0:
            inside = False
        # the distance to the segment: to its point nearest to p
        den = ex * ex + ey * ey
        t = 0.0
        if den != 0.0:      # clamped to the segment, as max(0.0, min(1.0, t)) (NaN -> 1.0)
            t = ((px - ax) * ex + (py - ay) * ey) / den
            t = t if t < 1.0 else 1.0
            t = t if t > 0.0 else 0.0
        dist = _hypot(px - (ax + t * ex), py - (ay + t * ey))
        if dist < nearest:
            nearest = dist
        ax = bx
        ay = by
    if k == 2:
        return -dist
    return nearest if inside else -nearest


def _acos_deg(x: float) -> float:
    """``math.degrees(math.acos(x))`` of ``x`` clamped to [-1, 1] (as ``max(-1.0, min(1.0, x))``:
    NaN -> 1.0)."""
    x = x if x < 1.0 else 1.0
    x = x if x > -1.0 else -1.0
    return math.acos(x) * _DEG


class TruthSample:
    """The figures of one sample (``ContactScan.truth``), read-only: ``tilt_deg``, ``height_m``,
    ``fell``, ``total_n`` (the pads' normal force), ``margin_mm`` (the CoP margin; ``-inf``
    unloaded), ``pad_forces_n`` (8), ``foot_cop_mm`` (per foot, foot frame, None unloaded),
    ``cop_xy`` (world; None unloaded), ``hull`` (the support polygon's points, counter-clockwise),
    ``soles_mm`` (each sole origin on the platform: x, y along it, height above it; mm), ``com``
    (the trunk subtree's centre of mass, world), ``joints_rad`` (the hinge joints' qpos)."""

    def __init__(self) -> None:
        self.tilt_deg = 0.0
        self.height_m = 0.0
        self.fell = False
        self.total_n = 0.0
        self.margin_mm = -_inf
        self.pad_forces_n: list[float] = []
        self.foot_cop_mm: list[tuple[float, float] | None] = []
        self.cop_xy: tuple[float, float] | None = None
        self.hull: list[tuple[float, float]] = []
        self.soles_mm: tuple[tuple[float, float, float], ...] = ()
        self.com: list[float] = []
        self.joints_rad: list[float] = []


class ContactScan:
    """``ContactScan(pad_of_geom, sole_sites, trunk, joint_qadr, xpos, xmat, subtree_com,
    site_xpos, site_xmat, qpos)``: per geom its pad index 0..7 (foot * 4 + table-12 index) or -1
    (an ``array('i')``), the two feet's sole sites, the trunk's body id, the hinge joints' qpos
    addresses (int64), and MjData's arrays of those names."""

    def __init__(self, pad_of_geom: Any, sole_sites: Any, trunk: int, joint_qadr: Any, xpos: Any, xmat: Any,
                 subtree_com: Any, site_xpos: Any, site_xmat: Any, qpos: Any) -> None:
        self._pad = pad_of_geom
        self._sole = array("q", [int(s) for s in sole_sites])
        self._trunk = trunk
        self._qadr = joint_qadr
        self._xpos = xpos
        self._xmat = xmat
        self._com = subtree_com
        self._site_pos = site_xpos
        self._site_mat = site_xmat
        self._qpos = qpos
        self._cap = 0
        self._grow(8)

    def _grow(self, n: int) -> None:
        """Room for ``n`` loaded contacts."""
        self._cap = n
        self._pid = array("i", bytes(4 * n))
        self._fn = _doubles(n)
        self._px = _doubles(n)
        self._py = _doubles(n)
        self._pz = _doubles(n)
        self._sx = _doubles(n)
        self._sy = _doubles(n)
        self._hx = _doubles(2 * n)      # the hull's chains while they are built
        self._hy = _doubles(2 * n)
        self._padf = _doubles(8)

    def _scan(self, geom: Any, adr: Any, pos: Any, force: Any, edges: bool, foot: int) -> int:
        """The pad/ground contacts pressing on the pads (of foot index ``foot``, or of both for -1)
        into the buffers, in contact order: pad index, normal force (N) and world position (m);
        their number. The normal force of contact c: with ``edges`` (a pyramidal cone, every
        contact of dim 3) the sum of its 4 pyramid edge forces at ``force[efc_address]``
        (``efc_force``), else ``force[c]`` (given per contact)."""
        n = len(geom)
        if n > self._cap:
            self._grow(n)
        pad = self._pad
        pid = self._pid
        fn = self._fn
        px = self._px
        py = self._py
        pz = self._pz
        k = 0
        for c in range(n):
            p = pad[geom[c][0]]
            q = pad[geom[c][1]]
            if q > p:
                p = q
            a = adr[c]
            if p < 0 or a < 0 or (foot >= 0 and p >> 2 != foot):
                continue
            if edges:       # pyramidal cone: the normal force is the sum of the pyramid's edge forces
                f = float(force[a]) + float(force[a + 1]) + float(force[a + 2]) + float(force[a + 3])
            else:
                f = float(force[c])
            if f > 0.0:
                pid[k] = p
                fn[k] = f
                px[k] = float(pos[c][0])
                py[k] = float(pos[c][1])
                pz[k] = float(pos[c][2])
                k += 1
        return k

    def _foot_cop(self, k: int, f: int, total: float) -> tuple[float, float]:
        """CoP (foot frame, mm) of foot index ``f`` from the ``k`` scanned contacts (``total``: its
        load): the force-weighted mean contact point, in the frame of the foot's sole site."""
        pid = self._pid
        fn = self._fn
        px = self._px
        py = self._py
        pz = self._pz
        sx = 0.0
        sy = 0.0
        sz = 0.0
        for i in range(k):
            if pid[i] >> 2 == f:
                sx += fn[i] * px[i]
                sy += fn[i] * py[i]
                sz += fn[i] * pz[i]
        s = self._sole[f]
        o = self._site_pos
        r = self._site_mat
        vx = sx / total - float(o[s, 0])
        vy = sy / total - float(o[s, 1])
        vz = sz / total - float(o[s, 2])
        return ((vx * float(r[s, 0]) + vy * float(r[s, 3]) + vz * float(r[s, 6])) * 1000.0,
                (vx * float(r[s, 1]) + vy * float(r[s, 4]) + vz * float(r[s, 7])) * 1000.0)

    def foot_cop(self, geom: Any, adr: Any, pos: Any, force: Any, edges: bool,
                 f: int) -> tuple[float, float] | None:
        """The CoP of foot index ``f`` (foot frame, mm), None when unloaded; the contacts' arrays
        as for :meth:`truth`."""
        k = self._scan(geom, adr, pos, force, edges, f)
        fn = self._fn
        tot = 0.0
        for i in range(k):
            tot += fn[i]
        if not tot > _LOADED_MIN_N:
            return None
        return self._foot_cop(k, f, tot)

    def foot_cop_of(self, data: Any, f: int) -> tuple[float, float] | None:
        """:meth:`foot_cop` on the contacts of ``data`` (an ``MjData``: its ``contact`` and
        ``efc_force`` read here, once) when every contact's normal force is its pyramid's edge
        forces (``edges``): one call from the probe."""
        con = data.contact
        return self.foot_cop(con.geom, con.efc_address, con.pos, data.efc_force, True, f)

    def tilt_deg(self) -> float:
        """The trunk z axis' angle from the vertical (deg): element (2, 2) of its rotation matrix."""
        return _acos_deg(float(self._xmat[self._trunk, 8]))

    def fallen(self, tilt_deg: float, platform_tilt_deg: float) -> bool:
        """The fall test (``TruthProbe.fallen``) on the trunk's pose now."""
        t = self._trunk
        xpos = self._xpos
        xmat = self._xmat
        a = platform_tilt_deg * _RAD
        s = math.sin(a)
        c = math.cos(a)
        # the platform's normal is (-sin, 0, cos) (toes up positive); its top face passes through 0
        height = -s * float(xpos[t, 0]) + c * float(xpos[t, 2])
        if height < _FELL_HEIGHT_M:
            return True
        if tilt_deg <= _FELL_TILT_DEG:
            return False
        return _acos_deg(-s * float(xmat[t, 2]) + c * float(xmat[t, 8])) > _FELL_TILT_DEG

    def soles_mm(self, platform_tilt_deg: float) -> tuple[tuple[float, float, float],
                                                          tuple[float, float, float]]:
        """Each foot's sole origin in the platform's frame (mm: x forward along its surface, y
        left, the height above it; ``TruthProbe.soles_on_surface_mm``)."""
        a = platform_tilt_deg * _RAD
        s = math.sin(a)
        c = math.cos(a)
        pos = self._site_pos
        out = []
        for f in range(2):
            site = self._sole[f]
            x = float(pos[site, 0])
            y = float(pos[site, 1])
            z = float(pos[site, 2])
            out.append(((c * x + s * z) * 1000.0, y * 1000.0, (c * z - s * x) * 1000.0))
        return out[0], out[1]

    def truth_of(self, data: Any, platform_tilt_deg: float) -> TruthSample:
        """:meth:`truth` on the contacts of ``data``, as :meth:`foot_cop_of`."""
        con = data.contact
        return self.truth(con.geom, con.efc_address, con.pos, data.efc_force, True, platform_tilt_deg)

    def truth(self, geom: Any, adr: Any, pos: Any, force: Any, edges: bool,
              platform_tilt_deg: float) -> TruthSample:
        """Every figure of the ground truth now (:class:`TruthSample`), the platform at
        ``platform_tilt_deg``; the contacts' arrays ``geom`` (ncon, 2), ``adr`` (their
        efc_address), ``pos`` (ncon, 3) and ``force`` as for :meth:`_scan`."""
        out = TruthSample()
        t = self._trunk
        out.tilt_deg = tilt = self.tilt_deg()
        out.height_m = float(self._xpos[t, 2])
        out.fell = self.fallen(tilt, platform_tilt_deg)

        k = self._scan(geom, adr, pos, force, edges, -1)
        pid = self._pid
        fn = self._fn
        px = self._px
        py = self._py
        pad_f = self._padf
        for j in range(8):
            pad_f[j] = 0.0
        wx = 0.0
        wy = 0.0
        for i in range(k):
            f = fn[i]
            pad_f[pid[i]] += f
            wx += f * px[i]
            wy += f * py[i]
        out.pad_forces_n = [pad_f[j] for j in range(8)]
        foot0 = pad_f[0] + pad_f[1] + pad_f[2] + pad_f[3]
        foot1 = pad_f[4] + pad_f[5] + pad_f[6] + pad_f[7]
        out.total_n = total = foot0 + foot1
        xs = self._sx                   # the points, sorted in place
        ys = self._sy
        for i in range(k):
            xs[i] = px[i]
            ys[i] = py[i]
        hx = self._hx
        hy = self._hy
        h = convex_hull_xy(k, xs, ys, hx, hy)
        out.hull = [(hx[i], hy[i]) for i in range(h)]
        if total > _LOADED_MIN_N:
            cx = wx / total
            cy = wy / total
            out.cop_xy = (cx, cy)
            out.margin_mm = signed_distance_xy(cx, cy, h, hx, hy) * 1000.0
        out.foot_cop_mm = [self._foot_cop(k, 0, foot0) if foot0 > _LOADED_MIN_N else None,
                           self._foot_cop(k, 1, foot1) if foot1 > _LOADED_MIN_N else None]
        out.soles_mm = self.soles_mm(platform_tilt_deg)
        com = self._com
        out.com = [float(com[t, 0]), float(com[t, 1]), float(com[t, 2])]
        qpos = self._qpos
        qadr = self._qadr
        out.joints_rad = [float(qpos[qadr[j]]) for j in range(qadr.shape[0])]
        return out
