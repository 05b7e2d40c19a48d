"""Drawing geometry: what a viewer or a recording needs to draw the robot (the geoms and their
colours, the bodies' poses) and MuJoCo's own passive viewer window on a plant.

:class:`Drawing` reads them from a :class:`~humanoid_twin.plant.Plant`'s MuJoCo model and data
(``Plant.geometry``, ``Plant.body_poses``, ``Plant.body_pose_views``); :class:`ViewerWindow` is the
window ``humanoid-twin run --viewer`` opens (``Plant.open_viewer``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Collection
from dataclasses import dataclass

import mujoco
import numpy as np

WXYZ_TO_XYZW = [1, 2, 3, 0]        # MuJoCo's quaternion order (w, x, y, z) to (x, y, z, w)
_GEOM_TYPES = {int(v): k for k, v in {
    "plane": mujoco.mjtGeom.mjGEOM_PLANE, "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "capsule": mujoco.mjtGeom.mjGEOM_CAPSULE, "ellipsoid": mujoco.mjtGeom.mjGEOM_ELLIPSOID,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER, "box": mujoco.mjtGeom.mjGEOM_BOX,
}.items()}


@dataclass(frozen=True)
class GeomInfo:
    """A geom to draw: its body, MuJoCo type name, size (MuJoCo convention), pose in the body
    frame (quaternion xyzw) and colour."""

    name: str
    body: str
    type: str
    size: tuple[float, float, float]
    pos: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]
    rgba: tuple[float, float, float, float]
    group: int


class Drawing:
    """The drawing geometry of one MuJoCo model and data; ``pad_geoms``: the force-sensor pads'
    geom ids (drawn whatever their group)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, pad_geoms: Collection[int]) -> None:
        self.model = model
        self.data = data
        self._pad_geoms = frozenset(pad_geoms)
        self.body_names = tuple(model.body(b).name for b in range(1, model.nbody))

    def body_pose_views(self) -> tuple[np.ndarray, np.ndarray]:
        """Live views (no copy) of the world positions (n, 3) and quaternions (n, 4, MuJoCo's order
        w x y z) of every body but the world, in :attr:`body_names` order."""
        d = self.data
        return d.xpos[1:], d.xquat[1:]

    def body_poses(self) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
        """Names, world positions (n, 3) and quaternions (n, 4, xyzw) of every body but the world."""
        pos, quat = self.body_pose_views()
        return self.body_names, pos.copy(), quat[:, WXYZ_TO_XYZW]     # (an index array copies)

    def geometry(self) -> list[GeomInfo]:
        """The geoms to draw: visual geoms (group 2), force-sensor pads, platform and floor.

        Poses are local to the body (``body_poses`` gives the body's world pose); the floor and
        the other world geoms are in the world body ``world``.
        """
        m = self.model
        out = []
        for g in range(m.ngeom):
            name = m.geom(g).name
            if m.geom_group[g] != 2 and g not in self._pad_geoms and name not in ("platform", "floor"):
                continue
            mat = m.geom_matid[g]
            rgba = m.mat_rgba[mat] if mat >= 0 else m.geom_rgba[g]
            q = m.geom_quat[g]
            out.append(GeomInfo(
                name=name,
                body=m.body(m.geom_bodyid[g]).name,
                type=_GEOM_TYPES.get(int(m.geom_type[g]), str(int(m.geom_type[g]))),
                size=tuple(float(x) for x in m.geom_size[g]),  # type: ignore[arg-type]  # MuJoCo's 3-vectors
                pos=tuple(float(x) for x in m.geom_pos[g]),  # type: ignore[arg-type]  # as above
                quat_xyzw=(float(q[1]), float(q[2]), float(q[3]), float(q[0])),
                rgba=tuple(float(x) for x in rgba),  # type: ignore[arg-type]  # 4 values
                group=int(m.geom_group[g]),
            ))
        return out


class ViewerWindowError(RuntimeError):
    """MuJoCo's viewer could not open a window (no usable display)."""


class ViewerWindow:
    """MuJoCo's passive viewer (``mujoco.viewer.launch_passive``) on a model and its data.

    :meth:`draw` shows the data as it is after ``before_draw()`` (the plant's physics run up to
    its clock's now); :meth:`close` closes the window and waits for the viewer's thread.
    """

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, before_draw: Callable[[], None]) -> None:
        import mujoco.viewer

        self._before_draw = before_draw
        before = set(threading.enumerate())
        try:
            self._handle = mujoco.viewer.launch_passive(model, data)
        except Exception as exc:  # GLFW without a usable display raises here
            raise ViewerWindowError(f"MuJoCo's viewer could not open a window: {exc}") from exc
        # the viewer's (daemon) thread: joined at close, so that the interpreter does not exit
        # while it still tears the window down (a segfault in GLFW otherwise)
        self._threads = [t for t in threading.enumerate() if t not in before]

    def is_open(self) -> bool:
        """Whether the window is still open (the user may close it)."""
        return self._handle is not None and self._handle.is_running()

    def draw(self) -> None:
        """Bring the data up to date and show it (nothing once the window is closed)."""
        if not self.is_open():
            return
        self._before_draw()
        self._handle.sync()

    def close(self) -> None:
        """Close the window and wait for the viewer's thread to finish."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None
        for thread in self._threads:
            thread.join(timeout=5.0)
        self._threads = []
