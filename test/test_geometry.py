"""Support-polygon geometry: hulls, disc polygons and signed margins against brute force."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.geometry import (
    convex_hull,
    foot_discs_polygon,
    point_signed_distance,
    polygon_edge_list,
    signed_distance,
)

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def test_square_margins():
    margins = signed_distance([[0.5, 0.5], [0.1, 0.5], [2.0, 0.5], [2.0, 2.0], [1.0, 0.3]],
                              convex_hull(SQUARE))
    np.testing.assert_allclose(margins, [0.5, 0.1, -1.0, -np.sqrt(2.0), 0.0], atol=1e-12)


def test_hull_is_counter_clockwise_and_drops_interior_points():
    points = np.vstack([SQUARE, [[0.5, 0.5], [0.2, 0.7]]])
    hull = convex_hull(points)
    assert len(hull) == 4
    x, y = hull[:, 0], hull[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0  # positive area: CCW


def test_degenerate_hulls_have_no_inside():
    segment = convex_hull([[0, 0], [1, 0], [0.5, 0]])
    assert len(segment) == 2
    np.testing.assert_allclose(signed_distance([[0.5, 0.0], [0.5, 1.0]], segment), [0.0, -1.0])
    point = convex_hull([[1, 1], [1, 1]])
    np.testing.assert_allclose(signed_distance([[1, 2]], point), [-1.0])


def test_disc_polygon_contains_the_discs():
    centres = np.array([[0.0, 0.0], [0.6, 0.0], [0.3, 0.5]])
    polygon = foot_discs_polygon(centres, 0.055)
    angles = np.linspace(0, 2 * np.pi, 400)
    circle = 0.055 * np.stack([np.cos(angles), np.sin(angles)], 1)
    rims = (centres[:, None] + circle[None]).reshape(-1, 2)
    assert np.all(signed_distance(rims, polygon) >= -1e-12)
    # A lone disc: the margin at its centre is (about) its radius.
    assert abs(signed_distance([[0, 0]], foot_discs_polygon([[0, 0]], 0.055))[0] - 0.055) < 2e-3


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1)), min_size=3, max_size=12),
       st.tuples(st.floats(-2, 2), st.floats(-2, 2)))
def test_margin_matches_brute_force(vertices, point):
    points = np.array(vertices)
    hull = convex_hull(points)
    margin = signed_distance([point], hull)[0]
    # Brute force: distance to the boundary sampled densely, sign from a containment test.
    edges = [(hull[i], hull[(i + 1) % len(hull)]) for i in range(len(hull))]
    samples = np.vstack([a + np.linspace(0, 1, 2001)[:, None] * (b - a) for a, b in edges])
    boundary = np.min(np.linalg.norm(samples - np.array(point), axis=1))
    assert abs(abs(margin) - boundary) < 2e-3
    if len(hull) >= 3 and boundary > 2e-3:
        # Inside iff the point does not change the hull.
        grown = convex_hull(np.vstack([hull, [point]]))
        inside = len(grown) == len(hull) and np.allclose(np.sort(grown, 0), np.sort(hull, 0))
        assert (margin > 0) == inside


def test_exact_disc_margin_agrees_with_a_fine_disc_polygon():
    from gait_nodes.geometry import disc_support_margin

    centres = np.array([[0.0, 0.0], [0.6, 0.1], [0.2, 0.5]])
    points = np.random.default_rng(3).uniform(-0.5, 1.0, size=(200, 2))
    fine = signed_distance(points, foot_discs_polygon(centres, 0.055, segments=720))
    np.testing.assert_allclose(disc_support_margin(points, centres, 0.055), fine, atol=1e-5)


@given(st.lists(st.tuples(st.floats(-1, 1), st.floats(-1, 1)), min_size=1, max_size=6),
       st.lists(st.tuples(st.floats(-2, 2), st.floats(-2, 2)), min_size=1, max_size=8),
       st.booleans())
@settings(max_examples=200, deadline=None)
def test_one_point_margin_is_the_array_margin_bit_for_bit(centres, points, discs):
    """The monitor's scalar margin of one point is signed_distance's, exactly.

    Hull vertices, edge midpoints and inner points included, for hulls of 1, 2 or more vertices.
    """
    centres = np.array(centres)
    hull = foot_discs_polygon(centres, 0.055) if discs else convex_hull(centres)
    points = np.concatenate([np.array(points), hull, 0.5 * (hull + np.roll(hull, 1, axis=0))])
    edge_list = polygon_edge_list(hull)
    scalar = [point_signed_distance(x, y, edge_list) for x, y in points.tolist()]
    assert scalar == signed_distance(points, hull).tolist()


def test_micrometre_edges_do_not_turn_the_inside_out():
    """A hull rounded to float32 can be non-convex by a micrometre edge; its inside stays.

    The edge from (0.5, 1) to (0.5 - 1e-7, 1 + 1e-7) points down-left of the top edge: the
    half-plane on its left excludes everything with x + y > 1.5, most of the square's upper
    right. The margin of (0.9, 0.9) is its distance to the right and top edges either way.
    """
    polygon = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 1.0],
                        [0.5 - 1e-7, 1.0 + 1e-7], [0.0, 1.0]])
    points = np.array([[0.9, 0.9], [0.1, 0.1], [0.5, 1.5], [1.2, 0.5], [0.5, 0.5]])
    expected = [0.1, 0.1, -0.5 + 1e-7, -0.2, 0.5]
    np.testing.assert_allclose(signed_distance(points, polygon), expected, atol=1e-9)
    edge_list = polygon_edge_list(polygon)
    assert [point_signed_distance(x, y, edge_list) for x, y in points.tolist()] \
        == signed_distance(points, polygon).tolist()
    # Orientation does not matter to the crossings: the same margins clockwise.
    np.testing.assert_allclose(signed_distance(points, polygon[::-1]), expected, atol=1e-9)
