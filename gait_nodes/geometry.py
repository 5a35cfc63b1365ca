"""Plane geometry of support polygons: convex hulls of foot discs and signed stability margins.

One implementation serves the planner (ZMP inside the support polygon with a margin), the ZMP
monitor and ``inspect`` (which recomputes margins from a bag), so the three always agree.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import ConvexHull, QhullError

#: Vertices per foot disc when a contact is drawn as a polygon.
DISC_SEGMENTS = 16


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull vertices (M, 2) of planar points (N, 2).

    Degenerate inputs (one point, collinear points) return the extreme points in order, so the
    result is always usable by :func:`signed_distance`.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) == 0:
        raise ValueError('a convex hull needs at least one point')
    unique = np.unique(points, axis=0)
    if len(unique) >= 3:
        try:
            return unique[ConvexHull(unique).vertices]
        except QhullError:
            pass  # collinear: fall through to the segment case
    if len(unique) == 1:
        return unique
    direction = unique[-1] - unique[0]
    order = np.argsort(unique @ direction)
    return unique[[order[0], order[-1]]]


def foot_discs_polygon(centres: np.ndarray, radius_m: float,
                       segments: int = DISC_SEGMENTS) -> np.ndarray:
    """Convex hull (M, 2) of discs of ``radius_m`` [m] around contact centres (N, 2).

    The discs are approximated by regular polygons whose edges touch the circle from outside
    (vertices at ``radius / cos(pi / segments)``), so the polygon contains every disc.
    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 2)
    if radius_m <= 0:
        return convex_hull(centres)
    angles = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = (radius_m / np.cos(np.pi / segments)) * np.stack([np.cos(angles), np.sin(angles)], 1)
    return convex_hull((centres[:, None, :] + ring[None, :, :]).reshape(-1, 2))


def polygon_edges(hull: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices (M, 2), edge vectors (M, 2) and squared edge lengths (M,) of a polygon (M, 2).

    What :func:`signed_distance` needs of the polygon: keep it while the polygon is the same.
    """
    starts = np.asarray(hull, dtype=float).reshape(-1, 2)
    edges = np.roll(starts, -1, axis=0) - starts
    return starts, edges, np.maximum(np.einsum('ij,ij->i', edges, edges), 1e-300)


def signed_distance(points: np.ndarray, hull: np.ndarray,
                    edges: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
                    ) -> np.ndarray:
    """Stability margin of planar points (N, 2) against a polygon (M, 2).

    Positive inside (distance to the nearest edge), negative outside (minus the distance to the
    polygon), zero on the boundary. A one- or two-vertex hull (a point or a segment) has no
    inside: every point gets minus its distance to it. ``edges``: :func:`polygon_edges` of
    ``hull``, if known.

    Inside is decided by the edges a ray from the point towards +x crosses (an odd count is
    inside), not by the point's side of every edge: a convex hull of contact points published
    as float32 can have micrometre edges whose direction the rounding turns by tens of degrees,
    and the half-plane of such an edge cuts far into the polygon, while the crossings change
    only for points within micrometres of it. For a convex polygon, either test gives the same
    sign.

    Returns:
        (N,) margins [m].
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    starts, edges, lengths_sq = edges if edges is not None else polygon_edges(hull)
    relative = points[:, None, :] - starts[None, :, :]  # (N, M, 2)
    t = np.clip(np.einsum('nmj,mj->nm', relative, edges) / lengths_sq, 0.0, 1.0)
    nearest = starts[None] + t[..., None] * edges[None]
    distance = np.linalg.norm(points[:, None, :] - nearest, axis=2).min(axis=1)
    if len(starts) < 3:
        return -distance
    cross = edges[None, :, 0] * relative[..., 1] - edges[None, :, 1] * relative[..., 0]
    # An edge crosses the ray when its ends are on either side of the point's y (half-open,
    # so a ray through a vertex counts it once) and the point is on its left going up, or on
    # its right going down (the crossing's x minus the point's x is cross / dy).
    above_start = points[:, None, 1] < starts[None, :, 1]
    above_end = np.roll(above_start, -1, axis=1)
    crossed = (above_start != above_end) & (cross * edges[None, :, 1] > 0.0)
    inside = crossed.sum(axis=1) % 2 == 1
    return np.where(inside, distance, -distance)


def polygon_edge_list(hull: np.ndarray) -> list[tuple[float, float, float, float, float]]:
    """:func:`polygon_edges` as one tuple of floats per edge: ``(x, y, dx, dy, squared length)``.

    What :func:`point_signed_distance` needs of the polygon: keep it while the polygon is the
    same.
    """
    starts, edges, lengths_sq = polygon_edges(hull)
    return [(*start, *edge, length_sq) for start, edge, length_sq
            in zip(starts.tolist(), edges.tolist(), lengths_sq.tolist(), strict=True)]


def point_signed_distance(x: float, y: float,
                          edge_list: list[tuple[float, float, float, float, float]]) -> float:
    """:func:`signed_distance` of the one point ``(x, y)`` [m], in scalar arithmetic.

    The same operations in the same order as :func:`signed_distance`, so the same margin to the
    last bit, without the array overhead that dominates for one point (a monitor testing one
    ZMP per tick). ``(x, y)`` must be finite; ``edge_list``: :func:`polygon_edge_list` of the
    polygon.
    """
    nearest_sq = math.inf
    inside = False
    for index, (start_x, start_y, edge_x, edge_y, length_sq) in enumerate(edge_list):
        relative_x, relative_y = x - start_x, y - start_y
        t = (relative_x * edge_x + relative_y * edge_y) / length_sq
        t = 0.0 if t < 0.0 else 1.0 if t > 1.0 else t
        dx, dy = x - (start_x + t * edge_x), y - (start_y + t * edge_y)
        distance_sq = dx * dx + dy * dy
        if distance_sq < nearest_sq:  # min() without the call
            nearest_sq = distance_sq
        end_y = edge_list[(index + 1) % len(edge_list)][1]
        if (y < start_y) != (y < end_y) \
                and (edge_x * relative_y - edge_y * relative_x) * edge_y > 0.0:
            inside = not inside
    distance = math.sqrt(nearest_sq)
    return distance if inside and len(edge_list) >= 3 else -distance


def disc_support_margin(points: np.ndarray, centres: np.ndarray, radius_m: float) -> np.ndarray:
    """Exact margin of points (N, 2) in the support polygon of discs of ``radius_m`` at centres.

    The hull of equal discs is the hull of their centres grown by the radius, so the signed
    distance to it is the signed distance to the centres' hull plus the radius.

    Returns:
        (N,) margins [m], positive inside.
    """
    return signed_distance(points, convex_hull(centres)) + radius_m
