"""Planar geometry for the ground truth: support polygon (convex hull) and CoP margin.

Pure Python on point lists, the readable reference: the ground truth computes the same two
algorithms on C arrays in its compiled scan (``plant/contacts.py``: ``convex_hull_xy``,
``signed_distance_xy``), and tests/test_truth_core.py checks that both give the same numbers,
bit for bit, on random and degenerate inputs.
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
    hull: list[Point] = []
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


def signed_distance(point: Sequence[float], hull: Sequence[Point]) -> float:
    """Signed distance of ``point`` to the convex polygon ``hull`` (counter-clockwise).

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
