"""Ground truth: what really happens in the plant, for the run monitor, the recorder and the
tests (never for the firmware): the trunk's tilt and height, the fall test, the pads' contact
forces, the feet's and the robot's CoP, the support polygon and its margin.

:class:`TruthProbe` reads it from the MuJoCo data of a :class:`~humanoid_twin.plant.Plant`
(which syncs the physics to its clock and caches the result: ``Plant.truth``); its figures come
from the contact forces of the pad/ground contacts (their normal component, as
``mj_contactForce`` gives it), not from the touch sensors. The arithmetic on MuJoCo's arrays
(the contact scan, the CoPs, the polygon and its margin, the tilt, the fall test, the soles)
is ``plant/contacts.py``, compiled: one call per sample.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence
from typing import Any, NamedTuple

import mujoco
import numpy as np

from humanoid_twin.clock import US_PER_S
from humanoid_twin.core import is_compiled
from humanoid_twin.hardware import DEG_PER_RAD as _DEG_PER_RAD
from humanoid_twin.plant import contacts
from humanoid_twin.plant.contacts import ContactScan, TruthSample

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

    Read-only, every figure computed at the sample (one compiled call, ``plant/contacts.py``); the
    arrays and the dicts are made on first read: a reader that only wants the balance (the run
    monitor) does not pay for them. :meth:`plain` gives the per-foot and polygon fields as plain
    Python values.
    """

    __slots__ = ("t_s", "_s", "_names", "_plain", "_arrays", "_com_joints")

    t_s: float
    _s: TruthSample
    _names: list[str]
    _plain: PlainTruth | None                                   # made on first read
    _arrays: tuple | None
    _com_joints: tuple[np.ndarray, dict[str, float]] | None

    def __init__(self, t_s: float, sample: TruthSample, joint_names: list[str]) -> None:
        init = object.__setattr__
        init(self, "t_s", t_s)
        init(self, "_s", sample)
        init(self, "_names", joint_names)
        init(self, "_plain", None)
        init(self, "_arrays", None)
        init(self, "_com_joints", None)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"GroundTruth is read-only (cannot set {name!r})")

    @property
    def trunk_tilt_deg(self) -> float:
        """Angle (deg) between the trunk z axis and the vertical."""
        return self._s.tilt_deg

    @property
    def trunk_height_m(self) -> float:
        """Trunk origin height (m; 0.29 m at the stand pose)."""
        return self._s.height_m

    @property
    def cop_margin_mm(self) -> float:
        """Signed distance (mm) of the CoP inside the support polygon; ``-inf`` airborne."""
        return self._s.margin_mm

    @property
    def total_normal_force_n(self) -> float:
        """The pads' normal contact forces, summed (N)."""
        return self._s.total_n

    @property
    def fell(self) -> bool:
        """The fall test (``TruthProbe.fallen``)."""
        return self._s.fell

    @property
    def soles_on_surface_mm(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """Each foot's sole origin on the platform (``Plant.soles_on_surface_mm`` at this instant)."""
        return self._s.soles_mm  # type: ignore[return-value]  # two feet

    def plain(self) -> PlainTruth:
        """The per-foot forces and CoPs, the overall CoP and the polygon as plain Python values."""
        got = self._plain
        if got is None:
            s = self._s
            got = PlainTruth(s.pad_forces_n, s.foot_cop_mm, s.cop_xy, s.hull)
            object.__setattr__(self, "_plain", got)
        return got

    def _array_fields(self) -> tuple:
        got = self._arrays
        if got is None:
            pads, cops, cop, hull = self.plain()
            got = ({foot: np.array(pads[4 * f:4 * f + 4]) for f, foot in enumerate(FOOT_BODIES)},
                   {foot: None if c is None else np.array(c)
                    for foot, c in zip(FOOT_BODIES, cops, strict=True)},
                   None if cop is None else np.array(cop),
                   np.array(hull, dtype=float).reshape(-1, 2))
            object.__setattr__(self, "_arrays", got)
        return got

    def _com_joints_fields(self) -> tuple[np.ndarray, dict[str, float]]:
        got = self._com_joints
        if got is None:
            s = self._s
            deg = [a * _DEG_PER_RAD for a in s.joints_rad]
            got = (np.array(s.com), dict(zip(self._names, deg, strict=True)))
            object.__setattr__(self, "_com_joints", got)
        return got

    @property
    def com(self) -> np.ndarray:
        """(3,) whole-robot centre of mass, world."""
        return self._com_joints_fields()[0]

    @property
    def joint_angles_deg(self) -> dict[str, float]:
        """Every hinge joint's angle, joint frame, degrees."""
        return self._com_joints_fields()[1]

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
        self.joint_names = joint_names
        self.joint_qadr = joint_qadr
        self._force6 = np.zeros(6)
        self._pyramidal = model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
        # every contact has dim 3 when every geom has condim 3 (no explicit pairs, no flexes):
        # then each contact's normal force is the sum of its 4 pyramid edge forces in efc_force
        self._edges = self._pyramidal and (model.npair == 0 and model.nflex == 0
                                           and bool((model.geom_condim == 3).all()))
        # interpreted, the scan reads the contacts' arrays as lists: one tolist an array costs less
        # than a numpy scalar a value (compiled, it reads them in place)
        self._as_lists = not is_compiled(contacts)
        # compiled, with the edge sums: the scan reads the contacts off the data itself (one call)
        self._of_data = self._edges and not self._as_lists
        d = data
        self._scan = ContactScan(array("i", pad_list), self.sole_sites, trunk,
                                 np.ascontiguousarray(joint_qadr, dtype=np.int64), d.xpos, d.xmat,
                                 d.subtree_com, d.site_xpos, d.site_xmat, d.qpos)

    def _forces(self, adr: np.ndarray) -> array:
        """Each contact's normal force (N; ``adr``: the contacts' efc_address) where ``efc_force``
        alone does not give it (``ContactScan`` then reads ``force[c]``): as ``mj_contactForce``
        gives it, or as its pyramid's edge forces sum to."""
        d = self.data
        forces = array("d", bytes(8 * d.ncon))
        dims = d.contact.dim.tolist()
        ef = d.efc_force.tolist()
        for c, a in enumerate(adr.tolist()):
            if a < 0:
                continue
            if self._pyramidal and dims[c] == 3:
                forces[c] = ef[a] + ef[a + 1] + ef[a + 2] + ef[a + 3]
            else:
                mujoco.mj_contactForce(self.model, d, c, self._force6)
                forces[c] = float(self._force6[0])
        return forces

    def compute(self, t_us: int, platform_tilt_deg: float) -> GroundTruth:
        """The ground truth of the data now (physics time ``t_us``, the platform at
        ``platform_tilt_deg``)."""
        # the contacts' arrays (ncon long, made anew at each read: MuJoCo moves them), once
        d = self.data
        if self._of_data:
            return GroundTruth(t_us / US_PER_S, self._scan.truth_of(d, platform_tilt_deg), self.joint_names)
        con = d.contact
        adr = con.efc_address
        edges = self._edges
        force = d.efc_force if edges else self._forces(adr)
        if self._as_lists:
            sample = self._scan.truth(con.geom.tolist(), adr.tolist(), con.pos.tolist(), force.tolist(),
                                      edges, platform_tilt_deg)
        else:
            sample = self._scan.truth(con.geom, adr, con.pos, force, edges, platform_tilt_deg)
        return GroundTruth(t_us / US_PER_S, sample, self.joint_names)

    def fallen(self, tilt_deg: float, platform_tilt_deg: float) -> bool:
        """The fall test against the surface the feet stand on (humanoid_twin/models/README.md,
        section 9): the trunk origin less than ``FELL_HEIGHT_M`` above the platform's plane (along
        its normal), or the trunk more than ``FELL_TILT_DEG`` from the vertical *and* from the
        platform's normal (``tilt_deg``: the trunk's from the vertical). A robot upright on a
        tilted platform, or whose feet slide down it, has not fallen."""
        return self._scan.fallen(tilt_deg, platform_tilt_deg)

    def soles_on_surface_mm(self, platform_tilt_deg: float) -> tuple[tuple[float, float, float],
                                                                  tuple[float, float, float]]:
        """Where each foot's sole origin is on the platform, in the platform's own frame (mm,
        x forward along its surface, y left, and its height above the surface; ``FOOT_BODIES``
        order): a foot sliding on the platform moves in x, y; a platform tilting under a still
        foot does not move it (``slip_mm`` of a run)."""
        return self._scan.soles_mm(platform_tilt_deg)

    def foot_cop_xy(self, f: int) -> tuple[float, float] | None:
        """The CoP of foot index ``f`` (``FOOT_BODIES`` order; foot frame, mm) as two floats, None
        when unloaded."""
        d = self.data
        if self._of_data:
            return self._scan.foot_cop_of(d, f)
        con = d.contact
        adr = con.efc_address
        edges = self._edges
        force = d.efc_force if edges else self._forces(adr)
        if self._as_lists:
            return self._scan.foot_cop(con.geom.tolist(), adr.tolist(), con.pos.tolist(), force.tolist(),
                                       edges, f)
        return self._scan.foot_cop(con.geom, adr, con.pos, force, edges, f)
