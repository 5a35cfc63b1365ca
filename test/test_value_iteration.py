"""Swing value iteration (thesis 000, III.C): Bellman equation, goal, 1/W scaling, lift time."""

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from swing_helpers import TINY_ACTIONS, TINY_GRID, fine_time, robot, tiny_table

from gait_nodes.errors import SwingTableError
from gait_nodes.swing.grid import SwingActions, SwingGrid, make_grid
from gait_nodes.swing.kinematics import FEASIBLE_BELOW_S, INFEASIBLE_S, LimbTiming
from gait_nodes.swing.value_iteration import at_limit, build_table


def independent_backup(table, timing):
    """T(V) at every node with direct IK and 16-corner interpolation (no shared code path)."""
    grid = table.grid
    states = grid.points()
    q, ok = timing.joints(states)
    best = np.full(len(states), np.inf)
    for move in table.actions.displacements():
        following = np.clip(states + move, grid.lower, grid.upper)
        q_next, ok_next = timing.joints(following)
        cost = np.abs(q_next - q).max(axis=1) / timing.joint_velocity_limit_rad_s
        cost = np.where(ok & ok_next, cost, INFEASIBLE_S)
        best = np.minimum(best, cost + grid.interpolate(table.values_s, following))
    return best.reshape(grid.shape)


def test_value_function_satisfies_bellman_equation_at_convergence():
    table, report = tiny_table()
    assert report.max_change_s < 1e-4 and table.converged
    timing = LimbTiming(robot(), table.family, table.joint_velocity_limit_rad_s)
    backup = independent_backup(table, timing)
    goal = table.grid.nearest_node(table.goal)
    finite = table.values_s < FEASIBLE_BELOW_S
    finite[goal] = False
    # RoboSimian's family 2 does not reach every node of this box (the limb IK's holes).
    assert finite.sum() > 0.6 * table.grid.size
    residual = np.abs(backup - table.values_s)[finite]
    assert residual.max() < 2e-4


def test_goal_value_is_zero_and_every_other_value_positive():
    table, _ = tiny_table()
    goal = table.grid.nearest_node(table.goal)
    assert table.values_s[goal] == 0.0
    others = np.ones(table.grid.shape, dtype=bool)
    others[goal] = False
    assert np.all(table.values_s[others] > 0)
    # The goal is a node of the grid: its coordinates are exactly the table's goal.
    assert np.array_equal([a[i] for a, i in zip(table.grid.axes, goal, strict=True)],
                          table.goal)


def test_swing_time_scales_as_one_over_the_limit():
    slow, _ = tiny_table(1.0)
    fast, _ = tiny_table(2.5)
    finite = slow.values_s < FEASIBLE_BELOW_S
    assert np.allclose(fast.values_s[finite] * 2.5, slow.values_s[finite], atol=5e-4)
    assert fast.lower_s * 2.5 == pytest.approx(slow.lower_s)
    liftable = slow.lift_s < FEASIBLE_BELOW_S
    np.testing.assert_array_equal(fast.lift_s < FEASIBLE_BELOW_S, liftable)
    assert np.allclose(fast.lift_s[liftable] * 2.5, slow.lift_s[liftable])


def test_a_table_scaled_to_another_limit_is_the_table_built_there():
    slow, _ = tiny_table(1.0)
    fast, _ = tiny_table(2.5)
    scaled = at_limit(slow, 2.5)
    assert scaled.joint_velocity_limit_rad_s == 2.5
    # Feasible values to the sweeps' tolerance, infeasible ones stay infeasible.
    np.testing.assert_array_equal(scaled.values_s < FEASIBLE_BELOW_S,
                                  fast.values_s < FEASIBLE_BELOW_S)
    finite = fast.values_s < FEASIBLE_BELOW_S
    assert np.abs(scaled.values_s - fast.values_s)[finite].max() < 1e-3
    np.testing.assert_allclose(scaled.lift_s, fast.lift_s, rtol=1e-9)
    assert scaled.lower_s == pytest.approx(fast.lower_s, rel=1e-9)
    np.testing.assert_allclose(at_limit(scaled, 1.0).values_s, slow.values_s, rtol=1e-12)
    with pytest.raises(SwingTableError, match='> 0'):
        at_limit(slow, 0.0)


def test_lift_time_is_the_vertical_move_from_the_ground():
    table, _ = tiny_table()
    timing = LimbTiming(robot(), table.family, 1.0)
    state = table.goal
    path = timing.vertical_path(state)
    assert path[0, 2] == pytest.approx(table.ground_z_m)
    assert path[-1, 2] == pytest.approx(state[2])
    times, feasible = timing.path_times(path)
    assert feasible and table.lower_s == pytest.approx(times.sum())
    # Finer sampling of the vertical line can only find more joint travel, but not much more.
    assert fine_time(timing, path[[0, -1]], 200) == pytest.approx(table.lower_s, rel=0.02)
    assert table.step_height_m == pytest.approx(state[2] - table.ground_z_m)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4))
def test_interpolation_is_exact_on_multilinear_functions(coefficients):
    grid = SwingGrid([0.0, 0.3, 1.0], [-1.0, 0.0], [0.0, 0.5, 0.7, 2.0], [-0.2, 0.2])
    states = grid.points()
    a, b, c, d = coefficients
    values = (1 + a * states[:, 0]) * (1 + b * states[:, 1]) * (1 + c * states[:, 2]) \
        * (1 + d * states[:, 3])
    rng = np.random.default_rng(0)
    probes = rng.uniform(grid.lower, grid.upper, (50, 4))
    expected = (1 + a * probes[:, 0]) * (1 + b * probes[:, 1]) * (1 + c * probes[:, 2]) \
        * (1 + d * probes[:, 3])
    assert np.allclose(grid.interpolate(values.reshape(grid.shape), probes), expected)


def test_actions_lie_on_spheres_of_the_given_radii():
    actions = SwingActions((0.02, 0.07), 6, (-0.4, 0.0, 0.4), (-0.1, 0.0, 0.1))
    moves = actions.displacements()
    radii = np.linalg.norm(moves[:, :3], axis=1)
    on_sphere = np.isclose(radii[:, None], [0.0, 0.02, 0.07]).any(axis=1)
    assert on_sphere.all()
    assert len(moves) == 2 * 3 * 6 * 3 + 2
    assert not np.any(np.all(moves == 0, axis=1))


def test_grid_puts_the_goal_on_a_node_and_refuses_a_goal_outside():
    grid = make_grid((0.2, 0.8, 7), (-0.65, -0.4, 6), 2, 0.05, (-0.3, 0.3, 3), -0.55,
                     goal=np.array([0.57, -0.52, -0.55, 0.05]))
    assert grid.nearest_node([0.57, -0.52, -0.55, 0.05]) is not None
    assert 0.57 in grid.x_m and -0.52 in grid.y_m and 0.05 in grid.yaw_rad
    with pytest.raises(SwingTableError, match='outside the grid'):
        make_grid((0.2, 0.8, 7), (-0.65, -0.4, 6), 2, 0.05, (-0.3, 0.3, 3), -0.55,
                  goal=np.array([0.9, -0.5, -0.55, 0.0]))


def test_build_refuses_bad_settings():
    with pytest.raises(SwingTableError, match='step height'):
        build_table(robot(), 2, -0.1, 1.0, TINY_GRID, TINY_ACTIONS)
    with pytest.raises(SwingTableError, match='joint velocity limit'):
        build_table(robot(), 2, 0.1, 0.0, TINY_GRID, TINY_ACTIONS)
    with pytest.raises(SwingTableError, match='family'):
        build_table(robot(), 8, 0.1, 1.0, TINY_GRID, TINY_ACTIONS)
    with pytest.raises(SwingTableError, match='radii'):
        SwingActions(radii_m=(0.0, 0.1))


def small_thesis_table(step_height_m=0.1):
    """The thesis' setting (planes, goal, lift) on a coarse mesh: 7 x 6 x 2 x 3 nodes.

    Built once per process and step height (two tests read the 0.1 m one; a ValueTable's
    arrays are read-only).
    """
    return _small_thesis_table(float(step_height_m))


@functools.lru_cache(maxsize=2)
def _small_thesis_table(step_height_m):
    from gait_nodes.swing.value_iteration import GridSpec, thesis_goal

    spec = GridSpec.thesis(x_count=7, y_count=6, yaw_count=3)
    goal = thesis_goal(0.6)
    return build_table(robot(), 2, step_height_m, 1.0, spec, TINY_ACTIONS, goal,
                       ground_z_m=goal[2] - step_height_m)


def test_thesis_setting_satisfies_bellman_equation_at_convergence():
    from gait_nodes.swing.value_iteration import THESIS_Z_PLANES_M

    table, report = small_thesis_table()
    assert table.converged
    np.testing.assert_array_equal(table.grid.z_m, THESIS_Z_PLANES_M)
    assert table.grid.x_m[[0, -1]].tolist() == [0.2, 0.8]
    assert table.grid.y_m[[0, -1]].tolist() == [-0.65, -0.4]
    # The goal's y and z are the start's (thesis IV.B.3): y -0.5 m on the upper plane.
    assert table.goal.tolist() == [0.6, -0.5, -0.6, 0.0]
    goal = table.grid.nearest_node(table.goal)
    assert table.values_s[goal] == 0.0
    timing = LimbTiming(robot(), table.family, table.joint_velocity_limit_rad_s,
                        table.ground_z_m)
    backup = independent_backup(table, timing)
    finite = table.values_s < FEASIBLE_BELOW_S
    finite[goal] = False
    assert finite.sum() > 0.3 * table.grid.size
    assert np.abs(backup - table.values_s)[finite].max() < 2e-4


def test_thesis_step_heights_share_the_value_and_lift_from_below_the_plane():
    from gait_nodes.swing.value_iteration import with_step_height

    tall, _ = small_thesis_table(0.1)
    low = with_step_height(tall, robot(), 0.06, tall.goal[2] - 0.06)
    np.testing.assert_array_equal(low.values_s, tall.values_s)
    assert low.ground_z_m == pytest.approx(-0.66) and tall.ground_z_m == pytest.approx(-0.7)
    timing = LimbTiming(robot(), 2, 1.0, -0.66)
    times, feasible = timing.path_times(timing.vertical_path(low.goal))
    assert feasible and low.lower_s == pytest.approx(times.sum())
    # Lifting 0.06 m is quicker than 0.1 m wherever both are possible; the lower plane
    # (0.7 m below the body) lies below the 0.06 m step's ground: no lift-off there.
    both = (low.lift_s < FEASIBLE_BELOW_S) & (tall.lift_s < FEASIBLE_BELOW_S)
    assert both[:, :, 1].any()
    assert np.all(low.lift_s[both & (tall.lift_s > 0)] < tall.lift_s[both & (tall.lift_s > 0)])
    assert np.all(low.lift_s[:, :, 0] == INFEASIBLE_S)
