"""Ground truth: what really happens in the plant, for the run monitor, the recorder and the
tests (never for the firmware): the trunk's tilt and height, the fall test, the pads' contact
forces, the feet's and the robot's CoP, the support polygon and its margin.

:class:`TruthProbe` reads it from the MuJoCo data of a :class:`~humanoid_twin.plant.Plant`
(which syncs the physics to its clock and caches the result: ``Plant.truth``); its figures come
from the contact forces of the pad/ground contacts (their normal component, as
``mj_contactForce`` gives it), not from the touch sensors.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import mujoco
import numpy as np

from humanoid_twin.clock import US_PER_S
from humanoid_twin.plant import constants as C  # noqa: N812
from humanoid_twin.plant.geometry import convex_hull, signed_distance
from humanoid_twin.plant.sensors import DEG_PER_RAD as _DEG_PER_RAD

FOOT_BODIES: tuple[str, str] = ("r_foot", "l_foot")


class PlainTruth(NamedTuple):
    """The per-foot and polygon fields of a :class:`GroundTruth` as plain Python values (the same
    numbers), for a reader that copies them elsewhere (the recorder): no arrays made and read
    back. Feet in ``FOOT_BODIES`` order."""

    pad_forces_n: list[float]                          # 8: each foot's four pads, table 12 order
    foot_cop_mm: list[tuple[float, float] | None]      # per foot; None when unloaded
    cop_world_xy: tuple[float, float] | None           # None when airborne
    support_polygon_xy: list[tuple[float, float]]      # the hull, counter-clockwise


class GroundTruth:
    """What really happens in the plant at ``t_s`` (for recording and tests, never for firmware).

    World frame: x forward, y left, z up, metres. Foot frame (table 12): x to the robot's right,
    y forward, millimetres, origin on the sole under the ankle. Feet are keyed ``r_foot`` /
    ``l_foot``; pad arrays follow table 12 order (front-left, front-right, rear-left, rear-right).
    Forces are the normal components of the MuJoCo contact forces of the pads (not the touch
    sensors).

    Read-only. The balance figures (tilt, height, CoP margin, total force, ``fell``) are computed
    at the sample; the rest (per-foot forces and CoPs, the joint angles, the polygon, the CoM)
    on first read, from what the plant copied at the sample (the loaded contacts, the CoM, the
    joint positions and the soles' poses): a reader that only wants the balance (the run
    monitor) does not pay for them. :meth:`plain` gives the per-foot and polygon fields as
    plain Python values.
    """

    __slots__ = ("t_s", "trunk_tilt_deg", "trunk_height_m", "cop_margin_mm", "total_normal_force_n", "fell",
                 "_derive", "_derived", "_arrays")

    t_s: float
    trunk_tilt_deg: float                    # angle between the trunk z axis and the vertical
    trunk_height_m: float                    # trunk origin height (0.29 m at the stand pose)
    cop_margin_mm: float                     # signed distance of the CoP inside it; -inf airborne
    total_normal_force_n: float
    fell: bool

    def __init__(self, t_s: float, trunk_tilt_deg: float, trunk_height_m: float, cop_margin_mm: float,
                 total_normal_force_n: float, fell: bool,
                 derive: Callable[[], tuple[np.ndarray, dict[str, float], PlainTruth]]) -> None:
        init = object.__setattr__
        init(self, "t_s", t_s)
        init(self, "trunk_tilt_deg", trunk_tilt_deg)
        init(self, "trunk_height_m", trunk_height_m)
        init(self, "cop_margin_mm", cop_margin_mm)
        init(self, "total_normal_force_n", total_normal_force_n)
        init(self, "fell", fell)
        init(self, "_derive", derive)
        init(self, "_derived", None)
        init(self, "_arrays", None)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"GroundTruth is read-only (cannot set {name!r})")

    def _fields(self) -> tuple[np.ndarray, dict[str, float], PlainTruth]:
        got = self._derived
        if got is None:
            got = self._derive()
            object.__setattr__(self, "_derived", got)
        return got

    def plain(self) -> PlainTruth:
        """The per-foot forces and CoPs, the overall CoP and the polygon as plain Python values."""
        return self._fields()[2]

    def _array_fields(self) -> tuple:
        got = self._arrays
        if got is None:
            pads, cops, cop, hull = self._fields()[2]
            got = ({foot: np.array(pads[4 * f:4 * f + 4]) for f, foot in enumerate(FOOT_BODIES)},
                   {foot: None if c is None else np.array(c)
                    for foot, c in zip(FOOT_BODIES, cops, strict=True)},
                   None if cop is None else np.array(cop),
                   np.array(hull, dtype=float).reshape(-1, 2))
            object.__setattr__(self, "_arrays", got)
        return got

    @property
    def com(self) -> np.ndarray:
        """(3,) whole-robot centre of mass, world."""
        return self._fields()[0]

    @property
    def joint_angles_deg(self) -> dict[str, float]:
        """Every hinge joint's angle, joint frame, degrees."""
        return self._fields()[1]

    @property
    def pad_forces_n(self) -> dict[str, np.ndarray]:
        """(4,) per foot: the pads' normal contact forces (N)."""
        return self._array_fields()[0]

    @property
    def foot_cop_mm(self) -> dict[str, np.ndarray | None]:
        """(2,) per foot in its foot frame (mm); None when the foot is unloaded."""
        return self._array_fields()[1]

    @property
    def cop_world_xy(self) -> np.ndarray | None:
        """(2,) the whole robot's CoP (world, m); None when airborne."""
        return self._array_fields()[2]

    @property
    def support_polygon_xy(self) -> np.ndarray:
        """(k, 2) convex hull of the pads in contact, counter-clockwise (world, m)."""
        return self._array_fields()[3]

    def __repr__(self) -> str:
        return (f"GroundTruth(t_s={self.t_s!r}, trunk_tilt_deg={self.trunk_tilt_deg!r}, "
                f"trunk_height_m={self.trunk_height_m!r}, cop_margin_mm={self.cop_margin_mm!r}, "
                f"total_normal_force_n={self.total_normal_force_n!r}, fell={self.fell!r})")


class TruthProbe:
    """The ground truth of one MuJoCo model and data: ``trunk`` (the trunk's body id),
    ``sole_sites`` (each foot's sole site, ``FOOT_BODIES`` order), ``pad_list`` (per geom: its pad
    index 0..7, foot * 4 + table-12 index, or -1), and the hinge joints' names and qpos
    addresses (``joint_names``, ``joint_qadr``)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, *, trunk: int, sole_sites: Sequence[int],
                 pad_list: list[int], joint_names: list[str], joint_qadr: np.ndarray) -> None:
        self.model = model
        self.data = data
        self.trunk = trunk
        self.sole_sites = list(sole_sites)
        self._pad_list = pad_list
        self.joint_names = joint_names
        self.joint_qadr = joint_qadr
        self._qadr = [int(a) for a in joint_qadr]
        self._force6 = np.zeros(6)
        self._pyramidal = model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
        # every contact has dim 3 when every geom has condim 3 (no explicit pairs, no flexes):
        # then the contacts' dims need not be read
        self._all_dim3 = (model.npair == 0 and model.nflex == 0
                          and bool((model.geom_condim == 3).all()))

    def compute(self, t_us: int, platform_tilt_deg: float) -> GroundTruth:
        """The ground truth of the data now (physics time ``t_us``, the platform at
        ``platform_tilt_deg``)."""
        d = self.data
        xpos = d.xpos[self.trunk].tolist()
        xmat = d.xmat[self.trunk].tolist()
        # the trunk z axis' vertical component: element (2, 2) of the trunk's rotation matrix
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, xmat[8]))))
        height = xpos[2]
        fell = _fallen(xpos, xmat, tilt, platform_tilt_deg)

        pids, fns, pts = self.loaded_contacts()
        pad_f = [0.0] * 8
        wx = wy = 0.0
        for p, f, xyz in zip(pids, fns, pts, strict=True):
            pad_f[p] += f
            wx += f * xyz[0]
            wy += f * xyz[1]
        foot_tot = (pad_f[0] + pad_f[1] + pad_f[2] + pad_f[3], pad_f[4] + pad_f[5] + pad_f[6] + pad_f[7])
        total = foot_tot[0] + foot_tot[1]
        hull = convex_hull(pts)
        if total > C.LOADED_MIN_N:
            cop_xy: tuple[float, float] | None = (wx / total, wy / total)
            margin = signed_distance(cop_xy, hull) * 1000.0  # type: ignore[arg-type]
        else:
            cop_xy = None
            margin = -math.inf
        # what the other fields need, copied now (one copy each); they are derived on first read
        com = d.subtree_com[self.trunk].tolist()
        qpos = d.qpos.tolist()
        site_pos = d.site_xpos
        site_mat = d.site_xmat
        soles = [(site_pos[s].tolist(), site_mat[s].tolist()) for s in self.sole_sites]

        def derive() -> tuple[np.ndarray, dict[str, float], PlainTruth]:
            cops = [_foot_cop(f, pids, fns, pts, foot_tot[f], *soles[f])
                    if foot_tot[f] > C.LOADED_MIN_N else None for f in range(len(FOOT_BODIES))]
            return (np.array(com), dict(zip(self.joint_names, [qpos[a] * _DEG_PER_RAD for a in self._qadr],
                                            strict=True)),
                    PlainTruth(pad_f, cops, cop_xy, hull))

        return GroundTruth(t_us / US_PER_S, tilt, height, margin, total, fell, derive)

    def fallen(self, tilt_deg: float, platform_tilt_deg: float) -> bool:
        """The fall test against the surface the feet stand on (humanoid_twin/models/README.md,
        section 9): the trunk origin less than ``FELL_HEIGHT_M`` above the platform's plane (along
        its normal), or the trunk more than ``FELL_TILT_DEG`` from the vertical *and* from the
        platform's normal (``tilt_deg``: the trunk's from the vertical). A robot upright on a
        tilted platform, or whose feet slide down it, has not fallen."""
        d = self.data
        return _fallen(d.xpos[self.trunk].tolist(), d.xmat[self.trunk].tolist(), tilt_deg, platform_tilt_deg)

    def soles_on_surface_mm(self, platform_tilt_deg: float) -> tuple[tuple[float, float, float],
                                                                  tuple[float, float, float]]:
        """Where each foot's sole origin is on the platform, in the platform's own frame (mm,
        x forward along its surface, y left, and its height above the surface; ``FOOT_BODIES``
        order): a foot sliding on the platform moves in x, y; a platform tilting under a still
        foot does not move it (``slip_mm`` of a run)."""
        s, c = math.sin(math.radians(platform_tilt_deg)), math.cos(math.radians(platform_tilt_deg))
        pos = self.data.site_xpos
        out = []
        for site in self.sole_sites:
            x, y, z = pos[site].tolist()
            out.append(((c * x + s * z) * 1000.0, y * 1000.0, (c * z - s * x) * 1000.0))
        return out[0], out[1]

    def loaded_contacts(self, foot: int = -1) -> tuple[list[int], list[float], list[list[float]]]:
        """Pad/ground contacts pressing on the pads (of foot index ``foot``, or of both): pad
        index 0..7 (foot * 4 + table-12 index), normal force (N, as ``mj_contactForce`` gives
        it) and world position (m). Plain Python over the handful of contacts: cheaper than
        numpy's per-call cost on such small arrays."""
        d = self.data
        n = d.ncon
        pids: list[int] = []
        fns: list[float] = []
        pts: list[list[float]] = []
        if not n:
            return pids, fns, pts
        con = d.contact                      # the ncon contacts, no more
        pad = self._pad_list
        geoms = con.geom.tolist()
        adrs = con.efc_address.tolist()
        dims = None if self._all_dim3 else con.dim.tolist()
        pos = con.pos.tolist()
        ef: list[float] | None = None
        pyramidal = self._pyramidal
        edges = pyramidal and dims is None   # every contact's normal force: its 4 edge forces
        for c, (g0, g1) in enumerate(geoms):
            p = pad[g0]
            q = pad[g1]
            if q > p:
                p = q
            a = adrs[c]
            if p < 0 or a < 0 or (foot >= 0 and p >> 2 != foot):
                continue
            if edges or (pyramidal and dims[c] == 3):  # type: ignore[index]
                # pyramidal cone: the normal force is the sum of the pyramid's edge forces
                if ef is None:
                    ef = d.efc_force.tolist()
                f = ef[a] + ef[a + 1] + ef[a + 2] + ef[a + 3]
            else:
                mujoco.mj_contactForce(self.model, d, c, self._force6)
                f = float(self._force6[0])
            if f > 0.0:
                pids.append(p)
                fns.append(f)
                pts.append(pos[c])
        return pids, fns, pts

    def foot_cop_mm(self, f: int) -> np.ndarray | None:
        """The CoP of foot index ``f`` (``FOOT_BODIES`` order; foot frame, mm), None when unloaded."""
        pids, fns, pts = self.loaded_contacts(f)
        tot = sum(fns)
        if not tot > C.LOADED_MIN_N:
            return None
        s = self.sole_sites[f]
        d = self.data
        return np.array(_foot_cop(f, pids, fns, pts, tot, d.site_xpos[s].tolist(), d.site_xmat[s].tolist()))


def _fallen(xpos: list[float], xmat: list[float], tilt_deg: float, platform_tilt_deg: float) -> bool:
    """:meth:`TruthProbe.fallen` from the trunk's world position and rotation matrix (row-major)."""
    s, c = math.sin(math.radians(platform_tilt_deg)), math.cos(math.radians(platform_tilt_deg))
    # the platform's normal is (-sin, 0, cos) (toes up positive); its top face passes through 0
    height = -s * xpos[0] + c * xpos[2]
    if height < C.FELL_HEIGHT_M:
        return True
    if tilt_deg <= C.FELL_TILT_DEG:
        return False
    cos_n = -s * xmat[2] + c * xmat[8]
    return math.degrees(math.acos(max(-1.0, min(1.0, cos_n)))) > C.FELL_TILT_DEG


def _foot_cop(f: int, pids: list[int], fns: list[float], pts: list[list[float]], total: float,
              sole_pos: list[float], sole_mat: list[float]) -> tuple[float, float]:
    """CoP (foot frame, mm) of foot index ``f`` from the loaded contacts (``total``: its load):
    the force-weighted mean contact point, in the frame of the sole site (``sole_pos``: its world
    position, ``sole_mat``: its rotation matrix, row-major)."""
    sx = sy = sz = 0.0
    for p, fn, xyz in zip(pids, fns, pts, strict=True):
        if p >> 2 == f:
            sx += fn * xyz[0]
            sy += fn * xyz[1]
            sz += fn * xyz[2]
    o = sole_pos
    r = sole_mat
    vx, vy, vz = sx / total - o[0], sy / total - o[1], sz / total - o[2]
    return ((vx * r[0] + vy * r[3] + vz * r[6]) * 1000.0, (vx * r[1] + vy * r[4] + vz * r[7]) * 1000.0)
