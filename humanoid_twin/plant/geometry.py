"""Planar geometry for the ground truth: support polygon (convex hull) and CoP margin.

Pure Python on a handful of points (at most the 8 force-sensor pads): cheaper than numpy for
such small inputs, and called only when the ground truth is recorded.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Point = tuple[float, float]


def convex_hull(points: Sequence[Sequence[float]]) -> list[Point]:
    """Convex hull (Andrew's monotone chain), counter-clockwise, no repeated end point.

    Collinear points on the hull's edges are dropped; 0, 1 or 2 distinct points give a
    degenerate hull of that many points.
    """
    pts = sorted({(float(p[0]), float(p[1])) for p in points})
    if len(pts) <= 2:
        return pts

    def cross(o: Point, a: Point, b: Point) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[Point] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[Point] = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _segment_distance(p: Point, a: Point, b: Point) -> float:
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    den = dx * dx + dy * dy
    t = 0.0 if den == 0.0 else max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / den))
    return math.hypot(p[0] - (ax + t * dx), p[1] - (ay + t * dy))


def signed_distance(point: Sequence[float], hull: Sequence[Point]) -> float:
    """Signed distance of ``point`` to the convex polygon ``hull`` (counter-clockwise).

    Positive inside (distance to the nearest edge), negative outside (minus the distance to
    the polygon), zero on the boundary. A degenerate hull (a point or a segment) has no
    inside: the result is minus the distance to it. An empty hull gives ``-inf``.
    """
    if not hull:
        return -math.inf
    p = (float(point[0]), float(point[1]))
    n = len(hull)
    if n == 1:
        return -math.hypot(p[0] - hull[0][0], p[1] - hull[0][1])
    if n == 2:
        return -_segment_distance(p, hull[0], hull[1])
    inside = True
    nearest = math.inf
    for k in range(n):
        a = hull[k]
        b = hull[(k + 1) % n]
        ex, ey = b[0] - a[0], b[1] - a[1]
        # left of every edge of a counter-clockwise polygon = inside
        if ex * (p[1] - a[1]) - ey * (p[0] - a[0]) < 0.0:
            inside = False
        nearest = min(nearest, _segment_distance(p, a, b))
    return nearest if inside else -nearest
