"""Planar geometry for the ground truth on point lists: support polygon (convex hull) and CoP
margin.

The algorithms are ``plant/contacts.py``'s (``convex_hull_xy``, ``signed_distance_xy``, on C
arrays in the compiled core, where the ground truth's scan calls them); these take and give
point lists, for a reader with points in hand. tests/plant/test_truth_core.py checks them, bit for bit,
against a plain-Python reference on random and degenerate inputs.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence

from humanoid_twin.plant.contacts import convex_hull_xy, signed_distance_xy

Point = tuple[float, float]


def convex_hull(points: Sequence[Sequence[float]]) -> list[Point]:
    """Convex hull (Andrew's monotone chain), counter-clockwise, no repeated end point.

    Collinear points on the hull's edges are dropped; 0, 1 or 2 distinct points give a
    degenerate hull of that many points.
    """
    n = len(points)
    xs = array("d", [float(p[0]) for p in points])
    ys = array("d", [float(p[1]) for p in points])
    hx = array("d", bytes(16 * n))          # room for 2 n points
    hy = array("d", bytes(16 * n))
    h = convex_hull_xy(n, xs, ys, hx, hy)
    return [(hx[i], hy[i]) for i in range(h)]


def signed_distance(point: Sequence[float], hull: Sequence[Point]) -> float:
    """Signed distance of ``point`` to the convex polygon ``hull`` (counter-clockwise).

    Positive inside (distance to the nearest edge), negative outside (minus the distance to
    the polygon), zero on the boundary. A degenerate hull (a point or a segment) has no
    inside: the result is minus the distance to it. An empty hull gives ``-inf``.
    """
    hx = array("d", [float(p[0]) for p in hull])
    hy = array("d", [float(p[1]) for p in hull])
    return signed_distance_xy(float(point[0]), float(point[1]), len(hull), hx, hy)
