"""Plane geometry of support polygons: hulls, margins, line crossings, projections.

A foot is a disc of radius ``foot_radius_m`` (robot YAML); the support polygon of a set of stance
feet is the convex hull of their discs, i.e. the hull of the contact points grown by the radius.
The *margin* of a point is its distance inside that polygon's boundary (negative outside).
Everything here works on (N, 2) arrays in one frame (the planner uses odom).
"""

from __future__ import annotations

import numpy as np

from gait_nodes.geometry import convex_hull, disc_support_margin, signed_distance

__all__ = ['EPS_M', 'chebyshev_centre', 'convex_hull', 'depth_in_hull', 'halfplanes',
           'line_crossing', 'point_segment_distance', 'project_onto_halfplanes',
           'support_margin']

#: Lengths below this [m] are treated as zero (degenerate hulls, parallel lines).
EPS_M = 1e-12


def point_segment_distance(point: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Euclidean distance [m] from ``point`` to the segment ``[a, b]``."""
    ab = b - a
    length2 = float(ab @ ab)
    s = 0.0 if length2 <= EPS_M ** 2 else float(np.clip((point - a) @ ab / length2, 0.0, 1.0))
    return float(np.linalg.norm(point - (a + s * ab)))


def halfplanes(polygon: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(A, b)`` with unit outward normals: a point z is inside the CCW polygon iff A z <= b."""
    poly = np.asarray(polygon, dtype=float)
    edges = np.roll(poly, -1, axis=0) - poly
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return normals, np.einsum('ij,ij->i', normals, poly)


def depth_in_hull(point: np.ndarray, contacts: np.ndarray) -> float:
    """Signed distance [m] of ``point`` inside the convex hull of ``contacts`` (< 0 outside).

    For a hull that is a point or a segment the depth is minus the distance to it.
    """
    point = np.asarray(point, dtype=float).reshape(1, 2)
    return float(signed_distance(point, convex_hull(contacts))[0])


def support_margin(point: np.ndarray, contacts: np.ndarray, foot_radius_m: float) -> float:
    """Distance [m] of ``point`` inside the hull of discs of ``foot_radius_m`` at ``contacts``.

    Exact (:func:`gait_nodes.geometry.disc_support_margin`).
    """
    point = np.asarray(point, dtype=float).reshape(1, 2)
    return float(disc_support_margin(point, contacts, foot_radius_m)[0])


def line_crossing(p1: np.ndarray, p2: np.ndarray, q1: np.ndarray,
                  q2: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """Crossing of the lines through (p1, p2) and (q1, q2): ``(point, s, t)`` or None if parallel.

    ``point = p1 + s (p2 - p1) = q1 + t (q2 - q1)``.
    """
    d1, d2 = p2 - p1, q2 - q1
    denominator = d1[0] * d2[1] - d1[1] * d2[0]
    scale = np.linalg.norm(d1) * np.linalg.norm(d2)
    if scale <= EPS_M or abs(denominator) <= 1e-9 * scale:
        return None
    w = q1 - p1
    s = (w[0] * d2[1] - w[1] * d2[0]) / denominator
    t = (w[0] * d1[1] - w[1] * d1[0]) / denominator
    return p1 + s * d1, float(s), float(t)


def project_onto_halfplanes(target: np.ndarray, normals: np.ndarray,
                            offsets: np.ndarray) -> np.ndarray | None:
    """The point of ``{z : normals z <= offsets}`` nearest to ``target``; None if it is empty.

    Exact for the small planar regions the planner builds (a handful of half-planes): the
    projection is the target itself, its projection on one edge line, or a vertex.
    """
    target = np.asarray(target, dtype=float)
    tolerance = 1e-10

    def feasible(z):
        return bool(np.all(normals @ z <= offsets + tolerance))

    if feasible(target):
        return target.copy()
    candidates = []
    for n, c in zip(normals, offsets, strict=True):
        candidates.append(target - (n @ target - c) * n)
    count = len(offsets)
    for i in range(count):
        for j in range(i + 1, count):
            matrix = np.array([normals[i], normals[j]])
            if abs(np.linalg.det(matrix)) > 1e-12:
                candidates.append(np.linalg.solve(matrix, [offsets[i], offsets[j]]))
    best = None
    for z in candidates:
        if feasible(z) and (best is None
                            or np.linalg.norm(z - target) < np.linalg.norm(best - target)):
            best = z
    return best


def chebyshev_centre(normals: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius [m] of the largest disc inside ``{z : normals z <= offsets}``."""
    from scipy.optimize import linprog

    # maximise r subject to n_i z + r <= c_i (unit normals).
    a_ub = np.hstack([normals, np.ones((len(offsets), 1))])
    result = linprog(c=[0.0, 0.0, -1.0], A_ub=a_ub, b_ub=offsets,
                     bounds=[(None, None), (None, None), (None, None)], method='highs')
    if not result.success:
        raise ValueError(f'no Chebyshev centre: {result.message}')
    return result.x[:2], float(result.x[2])
