"""The ground truth's compiled arithmetic (humanoid_twin/plant/contacts.py) gives the same numbers,
bit for bit, as the plain-Python reference: the hull and the margin on point lists (below), and the
contact scan, the CoPs, the tilt, the fall test and the soles as truth.py computed them on Python
lists before. The run summary's figures (the goldens) are these numbers."""

from __future__ import annotations

import importlib.util
import math
import random
from array import array
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from humanoid_twin.core import core_kind, is_compiled
from humanoid_twin.hardware import DEG_PER_RAD, RAD_PER_DEG
from humanoid_twin.plant import constants as C  # noqa: N812
from humanoid_twin.plant import contacts, geometry
from humanoid_twin.plant.contacts import convex_hull_xy, signed_distance_xy

SOURCE = Path(contacts.__file__).with_name("contacts.py")


def _source_module():
    """contacts.py loaded from its source (the interpreted core), whichever core runs here."""
    spec = importlib.util.spec_from_file_location("_contacts_source", SOURCE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _ref_convex_hull(points: Sequence[Sequence[float]]) -> list[tuple[float, float]]:
    """The plain-Python reference of the hull (Andrew's monotone chain on point lists, as
    plant/geometry.py computed it before the compiled scan), counter-clockwise, no repeated end
    point.

    Collinear points on the hull's edges are dropped; 0, 1 or 2 distinct points give a
    degenerate hull of that many points.
    """
    pts = sorted({(float(p[0]), float(p[1])) for p in points})
    if len(pts) <= 2:
        return pts
    hull: list[tuple[float, float]] = []
    for seq in (pts, pts[::-1]):              # the lower chain, then the upper one
        # the chain's last two points o, a kept in locals; its first two are always taken
        chain = seq[:2]
        (ox, oy), (ax, ay) = chain
        for p in seq[2:]:
            bx, by = p
            # o -> a -> b does not turn left (the cross product of o->a and o->b): drop a
            while (ax - ox) * (by - oy) - (ay - oy) * (bx - ox) <= 0:
                chain.pop()
                ax, ay = ox, oy
                if len(chain) < 2:
                    break
                ox, oy = chain[-2]
            chain.append(p)
            ox, oy, ax, ay = ax, ay, bx, by
        hull += chain[:-1]
    return hull


def _ref_signed_distance(point: Sequence[float], hull: Sequence[tuple[float, float]]) -> float:
    """The plain-Python reference of the CoP margin: signed distance of ``point`` to the convex
    polygon ``hull`` (counter-clockwise).

    Positive inside (distance to the nearest edge), negative outside (minus the distance to
    the polygon), zero on the boundary. A degenerate hull (a point or a segment) has no
    inside: the result is minus the distance to it. An empty hull gives ``-inf``.
    """
    if not hull:
        return -math.inf
    px, py = float(point[0]), float(point[1])
    n = len(hull)
    if n == 1:
        return -math.hypot(px - hull[0][0], py - hull[0][1])
    # the edges (a, b) of the polygon, the closing one first; a segment's one edge
    if n == 2:
        (ax, ay), verts = hull[0], hull[1:]
    else:
        ax, ay = hull[-1]
        verts = hull
    inside = True
    nearest = math.inf
    for bx, by in verts:
        ex, ey = bx - ax, by - ay
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
        dist = math.hypot(px - (ax + t * ex), py - (ay + t * ey))
        if dist < nearest:
            nearest = dist
        ax, ay = bx, by
    if n == 2:
        return -dist
    return nearest if inside else -nearest


def _bits(x):
    """A value with every float as its exact bits (-0.0 and 0.0 differ, NaN equals itself)."""
    if isinstance(x, float):
        return x.hex()
    if isinstance(x, (list, tuple)):
        return [_bits(v) for v in x]
    return x


def _points(rng: random.Random, n: int) -> list[tuple[float, float]]:
    """``n`` points: on a small grid (ties, duplicates, collinear runs) or anywhere."""
    if rng.random() < 0.5:
        return [(rng.randint(-3, 3) * 0.25, rng.randint(-3, 3) * 0.5) for _ in range(n)]
    return [(rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2)) for _ in range(n)]


def _hull_of(mod, pts):
    n = len(pts)
    xs = array("d", [p[0] for p in pts])
    ys = array("d", [p[1] for p in pts])
    hx = array("d", bytes(16 * n + 16))
    hy = array("d", bytes(16 * n + 16))
    h = mod.convex_hull_xy(n, xs, ys, hx, hy)
    return [(hx[i], hy[i]) for i in range(h)], hx, hy, h


def test_hull_and_margin_match_the_reference_on_random_and_degenerate_points():
    rng = random.Random(22)
    cases = [[], [(0.0, 0.0)], [(0.0, 0.0), (0.0, 0.0)], [(0.0, 1.0), (0.0, -1.0)],
             [(0.0, 0.0), (1.0, 1.0), (2.0, 2.0), (3.0, 3.0)],          # collinear
             [(0.0, 0.0), (-0.0, 0.0), (1.0, 0.0), (0.0, 1.0)],           # -0.0 and 0.0: one point
             [(1.0, 1.0)] * 5 + [(2.0, 1.0)] * 3]
    cases += [_points(rng, rng.randint(0, 12)) for _ in range(3000)]
    mods = [contacts, _source_module()]
    checked = 0
    for pts in cases:
        ref = _ref_convex_hull(pts)
        assert _bits(geometry.convex_hull(pts)) == _bits(ref), pts      # the point-list form
        queries = [(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)) for _ in range(4)]
        queries += [p for p in pts[:2]] + [(0.0, 0.0)]
        for mod in mods:
            hull, hx, hy, h = _hull_of(mod, pts)
            assert _bits(hull) == _bits(ref), pts
            for qx, qy in queries:
                got = mod.signed_distance_xy(qx, qy, h, hx, hy)
                assert _bits(got) == _bits(_ref_signed_distance((qx, qy), ref)), (pts, qx, qy)
                assert _bits(geometry.signed_distance((qx, qy), ref)) == _bits(got)
                checked += 1
    assert checked > 40000


def test_degrees_and_radians_are_the_products_the_compiled_core_uses():
    rng = random.Random(5)
    for _ in range(20000):
        x = rng.uniform(-400.0, 400.0)
        assert math.degrees(x) == x * DEG_PER_RAD and math.radians(x) == x * RAD_PER_DEG
    assert convex_hull_xy(0, array("d"), array("d"), array("d"), array("d")) == 0
    assert signed_distance_xy(0.0, 0.0, 0, array("d"), array("d")) == -math.inf


# --- the contact scan, against the former plain-Python computation ----------------------------------

def _reference(geom, adr, pos, efc, pad, trunk, soles, xpos, xmat, com, spos, smat, qpos, qadr, tilt_p):
    """truth.py's former TruthProbe.compute / foot_cop_mm / soles_on_surface_mm on lists."""
    xp = xpos[trunk].tolist()
    xm = xmat[trunk].tolist()
    tilt = math.degrees(math.acos(max(-1.0, min(1.0, xm[8]))))
    s, c = math.sin(math.radians(tilt_p)), math.cos(math.radians(tilt_p))
    if -s * xp[0] + c * xp[2] < C.FELL_HEIGHT_M:
        fell = True
    elif tilt <= C.FELL_TILT_DEG:
        fell = False
    else:
        fell = math.degrees(math.acos(max(-1.0, min(1.0, -s * xm[2] + c * xm[8])))) > C.FELL_TILT_DEG

    def loaded(foot):
        ef = efc.tolist()
        out = []
        for ci, (g0, g1) in enumerate(geom.tolist()):
            p = max(pad[g0], pad[g1])
            a = int(adr[ci])
            if p < 0 or a < 0 or (foot >= 0 and p >> 2 != foot):
                continue
            f = ef[a] + ef[a + 1] + ef[a + 2] + ef[a + 3]
            if f > 0.0:
                out.append((p, f, pos[ci].tolist()))
        return out

    def foot_cop(f, con, total):
        sx = sy = sz = 0.0
        for p, fn, xyz in con:
            if p >> 2 == f:
                sx += fn * xyz[0]
                sy += fn * xyz[1]
                sz += fn * xyz[2]
        o = spos[soles[f]].tolist()
        r = smat[soles[f]].tolist()
        vx, vy, vz = sx / total - o[0], sy / total - o[1], sz / total - o[2]
        return ((vx * r[0] + vy * r[3] + vz * r[6]) * 1000.0, (vx * r[1] + vy * r[4] + vz * r[7]) * 1000.0)

    con = loaded(-1)
    pad_f = [0.0] * 8
    wx = wy = 0.0
    for p, f, xyz in con:
        pad_f[p] += f
        wx += f * xyz[0]
        wy += f * xyz[1]
    tot = (pad_f[0] + pad_f[1] + pad_f[2] + pad_f[3], pad_f[4] + pad_f[5] + pad_f[6] + pad_f[7])
    total = tot[0] + tot[1]
    hull = _ref_convex_hull([xyz for _, _, xyz in con])
    cop = (wx / total, wy / total) if total > C.LOADED_MIN_N else None
    margin = _ref_signed_distance(cop, hull) * 1000.0 if cop is not None else -math.inf
    cops = [foot_cop(f, con, tot[f]) if tot[f] > C.LOADED_MIN_N else None for f in range(2)]
    alone = []
    for f in range(2):
        own = loaded(f)
        t = sum(fn for _, fn, _ in own)
        alone.append(foot_cop(f, own, t) if t > C.LOADED_MIN_N else None)
    soles_mm = []
    for site in soles:
        x, y, z = spos[site].tolist()
        soles_mm.append(((c * x + s * z) * 1000.0, y * 1000.0, (c * z - s * x) * 1000.0))
    return [tilt, xp[2], fell, total, margin, pad_f, cops, cop, hull, tuple(soles_mm), com[trunk].tolist(),
            [qpos[a] for a in qadr.tolist()], alone]


def _scene(rng: np.random.Generator, n: int):
    """A random MjData-like scene with ``n`` contacts (the contacts' arrays strided like MuJoCo's)."""
    ngeom, nbody, nsite = 14, 4, 5
    pad = [-1] * ngeom
    for k, g in enumerate(rng.permutation(ngeom)[:8]):
        pad[g] = int(k)
    block = np.zeros((n, 7), dtype=np.int32)          # geom at 0:2, efc_address at 5: strided views
    block[:, 0:2] = rng.integers(0, ngeom, size=(n, 2))
    block[:, 5] = 4 * np.arange(n) - np.where(rng.random(n) < 0.1, 10**6, 0)
    block[:, 5] = np.maximum(block[:, 5], -1)
    geom, adr = block[:, 0:2], block[:, 5]
    posblock = np.zeros((n, 5))
    grid = rng.random() < 0.4                          # ties, duplicates and collinear points
    posblock[:, 1:4] = (rng.integers(-2, 3, size=(n, 3)) * 0.03 if grid
                        else rng.uniform(-0.1, 0.1, size=(n, 3)))
    pos = posblock[:, 1:4]
    efc = rng.uniform(-1.0, 3.0, size=4 * n) * (rng.random() < 0.9)
    trunk = int(rng.integers(0, nbody))
    xpos = rng.uniform(-0.3, 0.4, size=(nbody, 3))
    xmat = rng.uniform(-1.2, 1.2, size=(nbody, 9))
    com = rng.uniform(-0.3, 0.3, size=(nbody, 3))
    spos = rng.uniform(-0.2, 0.2, size=(nsite, 3))
    smat = rng.uniform(-1.0, 1.0, size=(nsite, 9))
    qpos = rng.uniform(-3.0, 3.0, size=9)
    qadr = np.array(rng.permutation(9)[:6], dtype=np.int64)
    soles = [int(s) for s in rng.permutation(nsite)[:2]]
    tilt_p = float(rng.choice([0.0, rng.uniform(-30.0, 30.0)]))
    return geom, adr, pos, efc, pad, trunk, soles, xpos, xmat, com, spos, smat, qpos, qadr, tilt_p


def _scanned(mod, geom, adr, pos, efc, pad, trunk, soles, xpos, xmat, com, spos, smat, qpos, qadr, tilt_p):
    scan = mod.ContactScan(array("i", pad), soles, trunk, qadr, xpos, xmat, com, spos, smat, qpos)
    t = scan.truth(geom, adr, pos, efc, True, tilt_p)
    alone = [scan.foot_cop(geom, adr, pos, efc, True, f) for f in range(2)]
    assert scan.soles_mm(tilt_p) == t.soles_mm and scan.fallen(t.tilt_deg, tilt_p) == t.fell
    # the same scan reading the arrays off an MjData-like object itself (the probe's compiled path)
    data = SimpleNamespace(contact=SimpleNamespace(geom=geom, efc_address=adr, pos=pos), efc_force=efc)
    assert _bits([scan.foot_cop_of(data, f) for f in range(2)]) == _bits(alone)
    t2 = scan.truth_of(data, tilt_p)
    assert _bits([t2.margin_mm, t2.pad_forces_n, t2.foot_cop_mm, t2.hull]) == _bits(
        [t.margin_mm, t.pad_forces_n, t.foot_cop_mm, t.hull])
    return [t.tilt_deg, t.height_m, t.fell, t.total_n, t.margin_mm, t.pad_forces_n, t.foot_cop_mm, t.cop_xy,
            t.hull, t.soles_mm, t.com, t.joints_rad, alone]


def test_contact_scan_matches_the_former_plain_python_truth():
    rng = np.random.default_rng(27)
    mods = [contacts, _source_module()]
    loaded = fallen = 0
    for trial in range(1500):
        n = int(rng.integers(0, 4)) if trial % 5 == 0 else int(rng.integers(0, 12))
        scene = _scene(rng, n)
        ref = _reference(*scene)
        for mod in mods:
            assert _bits(_scanned(mod, *scene)) == _bits(ref), trial
        loaded += ref[7] is not None
        fallen += ref[2]
    assert 300 < loaded < 1450 and 100 < fallen < 1400     # both branches of each figure were taken


def test_the_scan_is_compiled_with_the_rest_of_the_core():
    """Where the core runs compiled (the clock), the scan is compiled too: the comparisons above
    then compare the C code with its source."""
    assert is_compiled(contacts) == (core_kind() == "compiled")


def test_the_per_contact_force_path_gives_the_same_truth():
    """A model where not every geom has condim 3 takes each contact's normal force in Python
    (``TruthProbe._forces``) instead of summing ``efc_force`` in the scan: a standing robot's
    truth is the same either way."""
    import mujoco

    from humanoid_twin.plant.plant import PAD_SUFFIXES, Plant
    from humanoid_twin.plant.truth import FOOT_BODIES, TruthProbe

    p = Plant(seed=0)
    p.advance_to(300_000)
    m, d = p.model, p.data

    def probe() -> TruthProbe:
        def oid(kind, name):
            return mujoco.mj_name2id(m, kind, name)
        pads = [-1] * m.ngeom
        for f, foot in enumerate(FOOT_BODIES):
            for k, suffix in enumerate(PAD_SUFFIXES):
                pads[oid(mujoco.mjtObj.mjOBJ_GEOM, f"{foot}_pad_{suffix}")] = 4 * f + k
        hinges = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        return TruthProbe(m, d, trunk=oid(mujoco.mjtObj.mjOBJ_BODY, "trunk"),
                          sole_sites=[oid(mujoco.mjtObj.mjOBJ_SITE, f"{foot}_sole") for foot in FOOT_BODIES],
                          pad_list=pads, joint_names=[m.joint(j).name for j in hinges],
                          joint_qadr=np.array([m.jnt_qposadr[j] for j in hinges], dtype=np.int64))

    def figures(pr: TruthProbe):
        t = pr.compute(p.t_us, 0.0)
        cops = [list(pr.foot_cop_xy(f)) for f in range(2)]
        # the per-foot path (the monitor's, at each leg board's tick) gives the whole sample's numbers
        assert cops == [list(c) for c in t.plain().foot_cop_mm]
        return _bits([t.trunk_tilt_deg, t.cop_margin_mm, t.total_normal_force_n, t.fell, list(t.plain()),
                      cops])

    fast = figures(probe())
    visual = int(np.flatnonzero((m.geom_contype == 0) & (m.geom_conaffinity == 0))[0])
    m.geom_condim[visual] = 1                       # a geom that never touches anything: same physics
    slow = figures(probe())
    assert d.ncon >= 4 and fast == slow
    assert 20.0 < p.truth().cop_margin_mm == float.fromhex(fast[1])


def test_the_imu_tilt_is_the_math_module_formula() -> None:
    """``hardware.tilt_from_roll_pitch`` (compiled: C's libm, the degrees and radians as products)
    gives the number the math module's formula gives: the summary's imu_tilt_error_rms_deg."""
    from humanoid_twin.hardware import tilt_from_roll_pitch

    rng = random.Random(11)
    for k in range(20000):
        span = 2.0 if k % 3 else 90.0
        r, p = rng.uniform(-span, span), rng.uniform(-span, span)
        c = math.cos(math.radians(r)) * math.cos(math.radians(p))
        ref = math.degrees(math.acos(max(-1.0, min(1.0, c))))
        assert tilt_from_roll_pitch(r, p) == ref, (r, p)
    assert tilt_from_roll_pitch(0.0, 0.0) == 0.0
    assert tilt_from_roll_pitch(1, 2) == tilt_from_roll_pitch(1.0, 2.0)
    assert tilt_from_roll_pitch(math.nan, 0.0) == 0.0   # as the formula gives it (the clamp takes NaN to 1)
    for bad in ((math.inf, 0.0), (0.0, -math.inf)):                 # C's cos would give NaN, then 0 deg
        with pytest.raises(ValueError, match="infinite"):
            tilt_from_roll_pitch(*bad)


def test_the_hull_and_margin_refuse_arrays_too_short() -> None:
    """The array forms check their lengths (compiled, a short array would be written or read
    past its end)."""
    z = np.zeros
    with pytest.raises(ValueError, match="5 points"):
        contacts.convex_hull_xy(5, z(5), z(5), z(9), z(10))
    with pytest.raises(ValueError, match="5 points"):
        contacts.convex_hull_xy(5, z(4), z(5), z(10), z(10))
    with pytest.raises(ValueError, match="hull of 3 points"):
        contacts.signed_distance_xy(0.0, 0.0, 3, z(2), z(3))
    assert contacts.convex_hull_xy(0, z(0), z(0), z(0), z(0)) == 0
    assert contacts.signed_distance_xy(0.0, 0.0, 0, z(0), z(0)) == -math.inf
