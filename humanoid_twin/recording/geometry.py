"""Static content of a twin recording, sent once: the robot's shapes (one entity per MuJoCo
body, shapes in the body frame), the floor, and the 2D foot views (outline, sensors, legend).
The poses that move them are sampled by the recorder; docs/recording.md."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import rerun as rr

from humanoid_twin.hardware import FOOT_LENGTH_MM, FOOT_WIDTH_MM, FORCE_SENSOR_LABELS, FORCE_SENSOR_XY_MM
from humanoid_twin.recording.columns import GREEN, ORANGE, SENSOR_COLOURS
from humanoid_twin.recording.paths import BODIES, WORLD, foot_view_path

if TYPE_CHECKING:
    from humanoid_twin.plant.plant import Plant

__all__ = ["log_static", "log_geometry", "log_foot_static", "view_xy", "SENSOR_LABELS"]

SENSOR_LABELS = FORCE_SENSOR_LABELS      # table 12 order
# A sensor's name is drawn this far outside the foot's outline (mm), level with its pad.
SENSOR_LABEL_GAP_MM = 16.0
# An infinite MuJoCo plane (size 0) is drawn as a square of this half size (m).
_FLOOR_HALF_M = 1.5


def log_static(rec: rr.RecordingStream, plant: Plant, body_names: Sequence[str],
               foot_scus: Iterable[int]) -> None:
    """Everything static: world axes (z up), geometry, foot views."""
    rec.log(WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    log_geometry(rec, plant, body_names)
    for scu in foot_scus:
        log_foot_static(rec, scu)


def log_foot_static(rec: rr.RecordingStream, scu: int) -> None:
    """Foot outline and sensors in the 2D foot view (mm; drawn with forward up)."""
    v = foot_view_path(scu)
    hl, hw = FOOT_LENGTH_MM / 2, FOOT_WIDTH_MM / 2
    outline = view_xy([[-hw, -hl], [hw, -hl], [hw, hl], [-hw, hl], [-hw, -hl]])
    rec.log(f"{v}/outline", rr.LineStrips2D([outline], colors=[(200, 200, 200)]), static=True)
    rec.log(f"{v}/forward", rr.Arrows2D(origins=[[0.0, 0.0]], vectors=[[0.0, -0.8 * hl]],
                                        colors=[(90, 90, 90)], labels=["forward"]), static=True)
    xy = view_xy(FORCE_SENSOR_XY_MM)
    rec.log(f"{v}/sensors", rr.Points2D(xy, radii=[3.0] * 4, colors=list(SENSOR_COLOURS)), static=True)
    # each sensor's name outside the outline, beside its pad: on the pad its load circle would hide it
    names_xy = [[math.copysign(hw + SENSOR_LABEL_GAP_MM, x), y] for x, y in xy]
    rec.log(f"{v}/sensor_names", rr.Points2D(names_xy, radii=[0.5] * 4, colors=list(SENSOR_COLOURS),
                                             labels=list(SENSOR_LABELS), show_labels=True), static=True)
    rec.log(f"{v}/loads", rr.Points2D(xy, colors=[(*c, 110) for c in SENSOR_COLOURS]), static=True)
    rec.log(f"{v}/cop/firmware", rr.Points2D([[0.0, 0.0]], radii=[4.0], colors=[ORANGE]), static=True)
    rec.log(f"{v}/cop/truth", rr.Points2D([[0.0, 0.0]], radii=[3.0], colors=[GREEN]), static=True)
    # the CoP legend beside the outline: the two moving points often coincide, so their labels
    # would sit on top of each other
    legend = [[-hw, -hl - 50.0], [-hw, -hl - 26.0]]        # above the toes, one under the other
    rec.log(f"{v}/legend", rr.Points2D(legend, radii=[4.0, 3.0], colors=[ORANGE, GREEN],
                                       labels=["CoP firmware", "CoP truth"], show_labels=True), static=True)


def log_geometry(rec: rr.RecordingStream, plant: Plant, body_names: Sequence[str]) -> None:
    """Static shapes: one entity per body under world/bodies, shapes in the body frame; the
    world body's planes as the floor."""
    per_body: dict[str, dict[str, list]] = {}
    floor: list = []
    for g in plant.geometry():
        kind = str(g.type).lower()
        if kind == "plane":
            floor.append(g)
        else:
            per_body.setdefault(g.body, {}).setdefault(kind, []).append(g)
    known = set(body_names)
    for body, kinds in per_body.items():
        base = f"{BODIES}/{body}" if body in known else f"{WORLD}/static/{body}"
        for kind, gs in kinds.items():
            arch = _shapes(kind, gs)
            if arch is not None:
                rec.log(f"{base}/{_KIND_ENTITY[kind]}", arch, static=True)
    for k, g in enumerate(floor):
        hx = g.size[0] if g.size[0] > 0 else _FLOOR_HALF_M
        hy = g.size[1] if g.size[1] > 0 else _FLOOR_HALF_M
        centre = np.asarray(g.pos, dtype=float) - [0.0, 0.0, 0.0005]
        rec.log(f"{WORLD}/floor/{k}", rr.Boxes3D(half_sizes=[[hx, hy, 0.0005]], centers=[centre],
                                                 colors=[_rgba(g)], fill_mode="solid"), static=True)


_KIND_ENTITY = {"box": "boxes", "capsule": "capsules", "sphere": "spheres", "ellipsoid": "ellipsoids",
                "cylinder": "cylinders"}


def view_xy(xy: Iterable[Sequence[float]]) -> list[list[float]]:
    """Foot frame (x right, y forward, mm) -> 2D view (x right, y down): forward is drawn up."""
    return [[float(p[0]), -float(p[1])] for p in xy]


def _rgba(g: Any) -> list[int]:
    """MuJoCo rgba (0..1 floats) -> 8-bit RGBA."""
    return [max(0, min(255, round(float(v) * 255))) for v in g.rgba]


def _rotate_xyzw(q: Sequence[float], v: Sequence[float]) -> np.ndarray:
    """Rotate ``v`` by the unit quaternion ``q`` (x, y, z, w)."""
    x, y, z, w = (float(c) for c in q)
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    return r @ np.asarray(v, dtype=float)


def _shapes(kind: str, gs: list) -> Any:
    """One rerun archetype for the geoms of one kind of one body (poses in the body frame); None
    for a kind not drawn."""
    build = _ARCHETYPES.get(kind)
    if build is None:
        return None
    pos = np.array([g.pos for g in gs], dtype=float)
    quats = [list(g.quat_xyzw) for g in gs]
    sizes = [np.asarray(g.size, dtype=float) for g in gs]
    colors = [_rgba(g) for g in gs]
    return build(pos, quats, sizes, {"quaternions": quats, "colors": colors})


def _boxes(pos: np.ndarray, quats: list, sizes: list, common: dict[str, Any]) -> Any:
    return rr.Boxes3D(half_sizes=[s[:3] for s in sizes], centers=pos, fill_mode="solid", **common)


def _spheres(pos: np.ndarray, quats: list, sizes: list, common: dict[str, Any]) -> Any:
    radii = [[s[0]] * 3 for s in sizes]
    return rr.Ellipsoids3D(half_sizes=radii, centers=pos, fill_mode="solid", **common)


def _ellipsoids(pos: np.ndarray, quats: list, sizes: list, common: dict[str, Any]) -> Any:
    return rr.Ellipsoids3D(half_sizes=[s[:3] for s in sizes], centers=pos, fill_mode="solid", **common)


def _capsules(pos: np.ndarray, quats: list, sizes: list, common: dict[str, Any]) -> Any:
    # MuJoCo: centred on pos along local z, radius size[0], half-length size[1];
    # rerun: starts at the translation and runs ``length`` along local +z.
    starts = [p - _rotate_xyzw(q, (0.0, 0.0, s[1])) for p, q, s in zip(pos, quats, sizes, strict=True)]
    return rr.Capsules3D(lengths=[2 * s[1] for s in sizes], radii=[s[0] for s in sizes],
                         translations=starts, **common)


def _cylinders(pos: np.ndarray, quats: list, sizes: list, common: dict[str, Any]) -> Any:
    return rr.Cylinders3D(lengths=[2 * s[1] for s in sizes], radii=[s[0] for s in sizes], centers=pos,
                          fill_mode="solid", **common)


# each MuJoCo geom kind drawn, and the rerun archetype that draws the geoms of one body
_ARCHETYPES = {"box": _boxes, "sphere": _spheres, "ellipsoid": _ellipsoids, "capsule": _capsules,
               "cylinder": _cylinders}
