"""ZMP reference of each gait, as knots (time, point) with the reference linear in between.

One step of any gait is ``[t0, t1]`` with all feet down (the ZMP moves from where the previous
step left it) followed by ``[t1, t_end]``, the swings. The knots of a step are
``(t0, z0), (t1, z1), (t_end, z_end)``:

biped (Lucy, sections 2-3)
    ``z1 = z_end`` = the stance ankle: the ZMP stays at the ankle of the supporting foot in single
    support and travels from the rear ankle to the front ankle in double support.
trot (Kurazume, section 2.1)
    The ZMP runs along the diagonal line of the support pair, from the crossing of the diagonals
    before the swing to their crossing after it (Kurazume's ``x cos(theta) + y sin(theta) = d``,
    sway width ``D = L / (4 tan(theta))``, eq. 22); ``z1`` is that line's point at ``t1``. Curved
    paths need no extra work: the footholds carry the coordinate transformation.
crawl (thesis, III.B.1 and Fig. 6)
    A lateral pair steps, hind then fore, while the other side stands. The ZMP is the crossing of
    the stance diagonals (the mid-point of the diagonal pairs) between the two swings, moved into
    both support triangles by the margin, and it moves only in the four-foot phase: twice a cycle,
    half a stride each time. ``z1 = z_end`` = that point.

Between two steps all feet are down and both ends of the ZMP's straight path lie inside the
convex support polygon with the margin, so the whole path does.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

import numpy as np

from gait_nodes.planning import support
from gait_nodes.planning.layout import FootLayout


def stand_point(layout: FootLayout, positions: np.ndarray) -> np.ndarray:
    """ZMP of a standing robot: between the feet (biped), the diagonals' crossing (quadruped)."""
    if layout.count == 2:
        return positions.mean(axis=0)
    (a, b), (c, d) = layout.diagonals()
    crossing = support.line_crossing(positions[a], positions[b], positions[c], positions[d])
    if crossing is None or not (0 <= crossing[1] <= 1 and 0 <= crossing[2] <= 1):
        return positions.mean(axis=0)
    return crossing[0]


def standing_zmp(layout: FootLayout, positions: np.ndarray, yaw_rad: float) -> np.ndarray:
    """ZMP of a robot standing still on ``positions`` in its nominal posture: its COM.

    The robot's COM at the nominal stance (``layout.com_xy``) moved with the stance: the
    :func:`stand_point` of ``positions`` plus the COM's offset from the nominal stance's own,
    turned by ``yaw_rad``. A robot standing up (the nominal stance) is planned where its COM
    already is, so that nothing moves before a walk is asked for; it stops there too. Without
    ``com_xy`` (or with the stance so far off the nominal one that the COM would not lie between
    the feet) it is the stand point.
    """
    point = stand_point(layout, positions)
    if layout.com_xy is None:
        return point
    offset = np.asarray(layout.com_xy, dtype=float) - stand_point(layout, layout.nominal_xy)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    moved = point + np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1]])
    if len(positions) > 2 and support.support_margin(moved, positions, 0.0) <= 0.0:
        return point
    return moved


def biped_knots(positions: np.ndarray, stance: int, times: Sequence[float],
                z0: np.ndarray) -> np.ndarray:
    """(3, 2) knots at ``times = (t0, t1, t_end)``: to the stance ankle, then held there."""
    ankle = positions[stance]
    return np.array([z0, ankle, ankle])


def _point_on_segment(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Crossing of line (a, b) with line (c, d), kept on the segment [a, b]."""
    crossing = support.line_crossing(a, b, c, d)
    s = 0.5 if crossing is None else min(max(crossing[1], 0.0), 1.0)
    return a + s * (b - a)


def trot_knots(layout: FootLayout, start: np.ndarray, end: np.ndarray,
               swinging: Sequence[int], times: Sequence[float], z0: np.ndarray) -> np.ndarray:
    """(3, 2) knots of a trot step: along the support diagonal between diagonal crossings.

    Args:
        layout: Foot roles.
        start: (F, 2) foot positions before the swing [m].
        end: (F, 2) foot positions after the swing [m].
        swinging: Feet of the swinging diagonal pair (one of them may stand still).
        times: ``(t0, t1, t_end)`` [s].
        z0: ZMP at ``t0`` [m].
    """
    first, second = layout.diagonals()
    support_pair, moving = (second, first) if set(swinging) <= set(first) else (first, second)
    a, b = start[support_pair[0]], start[support_pair[1]]
    before = _point_on_segment(a, b, start[moving[0]], start[moving[1]])
    after = _point_on_segment(a, b, end[moving[0]], end[moving[1]])
    t0, t1, t_end = times
    at_lift_off = before + (t1 - t0) / (t_end - t0) * (after - before)
    return np.array([z0, at_lift_off, after])


def crawl_region(layout: FootLayout, slots: Sequence[tuple[Sequence[int], np.ndarray]],
                 margin_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Half-planes ``(A, b)`` of the points ``margin_m`` inside every stance triangle of a step.

    Args:
        layout: Foot roles.
        slots: For each swing slot, the swinging feet and the (F, 2) positions before it.
        margin_m: Margin [m].
    """
    normals, offsets = [], []
    for feet, positions in slots:
        stance = [f for f in range(layout.count) if f not in feet]
        hull = support.convex_hull(positions[stance])
        n, c = support.halfplanes(hull)
        normals.append(n)
        offsets.append(c - margin_m)
    return np.vstack(normals), np.concatenate(offsets)


def crawl_knots(layout: FootLayout, slots: Sequence[tuple[Sequence[int], np.ndarray]],
                mid_positions: np.ndarray, margin_m: float, z0: np.ndarray,
                target_is_point: bool = False) -> tuple[np.ndarray, float]:
    """(3, 2) knots of a crawl step and the margin they keep [m].

    The target is the crossing of the diagonals of ``mid_positions`` (the feet between the hind
    and the fore swing, the thesis' ZMP), or ``mid_positions`` itself if ``target_is_point``;
    the knot is its projection into the region that keeps ``margin_m`` inside every stance
    triangle of the step. If that region is empty, the point of largest margin is used and the
    smaller margin returned.
    """
    normals, offsets = crawl_region(layout, slots, margin_m)
    target = mid_positions if target_is_point else stand_point(layout, mid_positions)
    point = support.project_onto_halfplanes(target, normals, offsets)
    kept = margin_m
    if point is None:
        point, radius = support.chebyshev_centre(normals, offsets + margin_m)
        kept = radius
    return np.array([z0, point, point]), kept


def _steady_crawl_steps(layout: FootLayout, params, step_length_m: float):
    """The two steps of a steady straight crawl: ``(hind, fore, start, mid)`` for each side.

    Foot positions follow the planner's placement (each foot lands where the body will be at
    the middle of its stance), with the body moving ``step_length_m`` per cycle; ``start`` and
    ``mid`` ((F, 2), before the hind and before the fore swing) are relative to the body's pose
    at the start of the step.
    """
    offsets = layout.offsets(params.step_width_m, 'crawl')
    cycle, half = params.cycle_s, params.step_period_s
    swing, transfer = params.swing_s, params.transfer_s('crawl')
    speed = step_length_m / cycle
    groups = layout.swing_groups('crawl')
    for side, (hind, fore) in enumerate(groups):
        other_hind, other_fore = groups[1 - side]
        # Touch-down times relative to the start of this step (steady state, straight).
        last = {hind[0]: transfer + swing - cycle, fore[0]: half - cycle,
                other_hind[0]: transfer + swing - half, other_fore[0]: 0.0}
        start = offsets.copy()
        for foot, t_down in last.items():
            start[foot, 0] += speed * t_down
        mid = start.copy()
        mid[hind[0], 0] = offsets[hind[0], 0] + speed * (transfer + swing)
        yield hind, fore, start, mid


def crawl_margin_feasible(robot, params) -> float:
    """Largest margin [m] a steady straight crawl at full stride leaves (both lateral steps)."""
    layout = FootLayout.of(robot)
    worst = np.inf
    for hind, fore, start, mid in _steady_crawl_steps(layout, params, params.step_length_m):
        normals, offsets_region = crawl_region(layout, [(hind, start), (fore, mid)], 0.0)
        _, radius = support.chebyshev_centre(normals, offsets_region)
        worst = min(worst, radius)
    return float(worst)


def steady_crawl_zmp_move(layout: FootLayout, params, stride_m: float) -> np.ndarray:
    """(2,) the ZMP's move in a transfer of a steady straight crawl, in the body frame [m].

    The knots of the two steps (:func:`crawl_knots` on :func:`_steady_crawl_steps`' stances,
    each relative to the body at its step's start) joined across the body's half-cycle move:
    ``stride_m / 2`` forward and the sway between the diagonals.
    """
    knots = [crawl_knots(layout, [(hind, start), (fore, mid)], mid, params.zmp_margin_m,
                         np.zeros(2))[0][1]
             for hind, fore, start, mid in _steady_crawl_steps(layout, params, stride_m)]
    return knots[1] + [0.5 * stride_m, 0.0] - knots[0]


def interp_floats(x: float, xs: list[float], ys: list[float]) -> float:
    """``np.interp(x, xs, ys)`` for one float, in plain floats, to the last bit.

    numpy's own steps (``arr_interp``): held beyond the ends, the knot's value at a knot,
    else ``slope * (x - xs[j]) + ys[j]`` with ``slope = (ys[j+1] - ys[j]) / (xs[j+1] - xs[j])``
    (from the other end if that is NaN). ``xs`` strictly increasing, as long as ``ys``.
    """
    last = len(xs) - 1
    if last == 0:
        return ys[0]  # (numpy's one-knot case: even for a NaN x)
    if not x <= xs[last]:
        return ys[last] if x > xs[last] else x  # (x NaN: NaN, as numpy)
    if x < xs[0]:
        return ys[0]
    j = bisect.bisect_right(xs, x) - 1
    if j == last or xs[j] == x:
        return ys[j]
    slope = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j])
    value = slope * (x - xs[j]) + ys[j]
    if value != value:
        value = slope * (x - xs[j + 1]) + ys[j + 1]
        if value != value and ys[j] == ys[j + 1]:
            value = ys[j]
    return value


def sample(knot_times_s: np.ndarray, knot_points: np.ndarray,
           times_s: np.ndarray) -> np.ndarray:
    """(N, 2) reference at ``times_s``: linear between knots, held beyond the ends."""
    result = np.empty((len(times_s), 2))  # (np.stack of the two columns costs more)
    result[:, 0] = np.interp(times_s, knot_times_s, knot_points[:, 0])
    result[:, 1] = np.interp(times_s, knot_times_s, knot_points[:, 1])
    return result
