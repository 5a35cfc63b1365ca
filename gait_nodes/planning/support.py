"""Plane geometry of support polygons: hulls, margins, line crossings, projections.

A foot is a disc of radius ``foot_radius_m`` (robot YAML); the support polygon of a set of stance
feet is the convex hull of their discs, i.e. the hull of the contact points grown by the radius.
The *margin* of a point is its distance inside that polygon's boundary (negative outside).
Everything here works on (N, 2) arrays in one frame (the planner uses odom).
"""

from __future__ import annotations

import numpy as np

#: Lengths below this [m] are treated as zero (degenerate hulls, parallel lines).
EPS_M = 1e-12


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of ``points`` (N, 2), counter-clockwise, no repeats.

    Andrew's monotone chain: unlike Qhull it accepts 1, 2 or collinear points, whose hull is a
    point or a segment (returned as 1 or 2 vertices).
    """
    pts = np.unique(np.asarray(points, dtype=float).reshape(-1, 2), axis=0)
    if len(pts) <= 2:
        return pts

    def half(sequence):
        chain: list[np.ndarray] = []
        for p in sequence:
            while len(chain) >= 2 and _cross(chain[-2], chain[-1], p) <= EPS_M:
                chain.pop()
            chain.append(p)
        return chain

    lower, upper = half(pts), half(pts[::-1])
    hull = np.array(lower[:-1] + upper[:-1])
    return hull


def _cross(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


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
    point = np.asarray(point, dtype=float)
    hull = convex_hull(contacts)
    if len(hull) == 1:
        return -float(np.linalg.norm(point - hull[0]))
    if len(hull) == 2:
        return -point_segment_distance(point, hull[0], hull[1])
    normals, offsets = halfplanes(hull)
    slack = offsets - normals @ point
    if np.all(slack >= 0):
        return float(slack.min())
    return -min(point_segment_distance(point, hull[i], hull[(i + 1) % len(hull)])
                for i in range(len(hull)))


def support_margin(point: np.ndarray, contacts: np.ndarray, foot_radius_m: float) -> float:
    """Distance [m] of ``point`` inside the hull of discs of ``foot_radius_m`` at ``contacts``.

    Exact: the hull of equal discs is the hull of their centres grown by the radius.
    """
    return depth_in_hull(point, contacts) + foot_radius_m


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
