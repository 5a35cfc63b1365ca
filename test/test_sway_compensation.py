"""Sway compensation (Kurazume eqs. 1-22): ZMP on the support lines, starts, stops, curves."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.com.sway import (
    ArcPath,
    kurazume_half_cycle,
    solve_sway,
    trapezoid_durations,
    trot_waypoints,
)
from gait_nodes.errors import ComPlanningError

ZC = 0.814


def line_distance(points, a, b):
    """Distance of points to the infinite line through a and b (a point when a == b)."""
    d = b - a
    length = np.linalg.norm(d)
    if length < 1e-12:
        return np.linalg.norm(points - a, axis=1)
    return np.abs((points - a) @ np.array([-d[1], d[0]])) / length


def assert_zmp_on_lines(trajectory, samples_per_segment=40):
    """The cart-table ZMP of the COM stays on each segment's support line."""
    worst = 0.0
    for k in range(len(trajectory.beta)):
        t0, t1 = trajectory.times_s[k], trajectory.times_s[k + 1]
        t = np.linspace(t0, t1, samples_per_segment)[1:-1]
        position, _, acceleration = trajectory.sample(t)
        zmp = position - trajectory.A * acceleration
        a, b = trajectory.waypoints_in_world[k], trajectory.waypoints_in_world[k + 1]
        worst = max(worst, float(np.max(line_distance(zmp, a, b))))
    assert worst < 1e-9, worst


def assert_continuous(trajectory, tolerance=1e-6):
    for t in trajectory.times_s[1:-1]:
        before = trajectory.sample([t - 1e-9])
        after = trajectory.sample([t + 1e-9])
        for b, a, scale in zip(before, after, (1.0, 1.0, 10.0), strict=True):
            assert np.max(np.abs(b - a)) < tolerance * scale, (t, b, a)


def biped_walk(half_cycles=14, D=0.1, L=0.3, speed=0.4, accel=0.5, path=None):
    """Waypoints and times: start between the feet, shift to the right foot, walk, stop."""
    feet = [(0.0, -D)] + [(k * L / 2, D if k % 2 else -D) for k in range(1, half_cycles + 1)]
    final = (feet[-1][0], 0.0)
    points = np.array([(0.0, 0.0), *feet, final, final])
    durations = np.concatenate([[0.6], trapezoid_durations(np.full(half_cycles, L / 2), speed,
                                                           accel), [0.6, 2.5]])
    if path is not None:
        points = path.to_world(points)
    return points, np.concatenate([[0.0], np.cumsum(durations)])


@pytest.mark.parametrize('accel, a2y', [(0.0, 0.0), (0.3, 0.0), (0.3, 0.05), (-0.1, -0.02)])
def test_closed_form_half_cycle_meets_its_conditions(accel, a2y):
    theta = math.atan(0.3 / 0.4)
    v = 0.4
    cycle = kurazume_half_cycle(ZC, 0.1, theta, v, accel, a2y, line_offset_m=0.02)
    t = np.linspace(0.0, cycle.half_period_s, 200)
    state = cycle.com(t)
    zmp = cycle.zmp(t)
    # ZMP on x cos(theta) + y sin(theta) = d, from y = D to y = -D.
    np.testing.assert_allclose(zmp @ [math.cos(theta), math.sin(theta)], 0.02, atol=1e-12)
    np.testing.assert_allclose(zmp[[0, -1], 1], [0.1, -0.1], atol=1e-12)
    # y velocity zero at both ends (eqs. 13-16); x speed v -> v + a T / 2 (eqs. 17-19).
    np.testing.assert_allclose(state[[0, -1], 1, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(state[[0, -1], 1, 0], [v, v + accel * cycle.half_period_s],
                               atol=1e-12)
    np.testing.assert_allclose(state[-1, 2, 0], state[0, 2, 0], atol=1e-12)
    # The COM covers half a stride L = 4 D tan(theta) (eq. 22).
    assert state[-1, 0, 0] - state[0, 0, 0] == pytest.approx(cycle.stride_m / 2, abs=1e-12)
    # The dynamics hold: x - A x_dd is the ZMP (eq. 1) by finite differences too.
    dt = t[1] - t[0]
    fd_acc = np.diff(state[:, 0], 2, axis=0) / dt ** 2
    np.testing.assert_allclose(fd_acc, state[1:-1, 2], atol=1e-4)


def test_biped_walk_starts_and_stops_at_rest_with_zmp_on_lines():
    points, times = biped_walk()
    trajectory = solve_sway(points, times, ZC, points[0])
    assert trajectory.end_residual_m < 1e-4
    assert_zmp_on_lines(trajectory)
    assert_continuous(trajectory)
    position, velocity, acceleration = trajectory.sample(times[[0, -1]])
    np.testing.assert_allclose(position[0], points[0], atol=1e-12)
    np.testing.assert_allclose(velocity[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(acceleration[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(position[-1], points[-1], atol=1e-4)
    np.testing.assert_allclose(velocity[-1], 0.0, atol=1e-4)
    # Accelerates from rest to the cruise speed of eq. 20 and back to rest.
    mid = 0.5 * (times[0] + times[-1])
    _, velocity, _ = trajectory.sample(np.linspace(mid - 0.375, mid + 0.375, 50))
    assert np.mean(velocity[:, 0]) == pytest.approx(0.4, rel=0.02)


def test_steady_walk_is_kurazumes_closed_form():
    points, times = biped_walk(half_cycles=20)
    trajectory = solve_sway(points, times, ZC, points[0])
    cycle = kurazume_half_cycle(ZC, 0.1, math.atan(0.3 / 0.4), 0.4)
    k = 11  # a cruising half cycle, far from both ends
    assert times[k + 1] - times[k] == pytest.approx(cycle.half_period_s)
    s = np.linspace(0.0, cycle.half_period_s, 30)
    position, velocity, _ = trajectory.sample(times[k] + s)
    expected = cycle.com(s)
    side = np.sign(points[k, 1])  # the closed form sways from +D; mirror for the other foot
    np.testing.assert_allclose(velocity[:, 0], expected[:, 1, 0], atol=1e-4)
    np.testing.assert_allclose(velocity[:, 1], side * expected[:, 1, 1], atol=1e-4)
    np.testing.assert_allclose(position[:, 1], side * expected[:, 0, 1], atol=2e-5)


def test_trot_zmp_stays_on_each_diagonal():
    # RoboSimian-like trot: diagonal pairs alternate, each pair moves a stride of 0.3 m.
    half_x, half_y, stride = 0.5, 0.5, 0.3
    diagonals = []
    front, rear = 0.0, 0.0
    for k in range(12):
        if k % 2 == 0:  # front-left and rear-right in support
            diagonals.append([(half_x + front, half_y), (-half_x + rear, -half_y)])
            front += stride / 2
        else:
            diagonals.append([(half_x + front, -half_y), (-half_x + rear + stride / 2, half_y)])
            rear += stride
    waypoints = trot_waypoints(diagonals)
    start = np.array([0.0, 0.0])
    points = np.vstack([start, waypoints, waypoints[-1]])
    durations = np.concatenate([[0.8], np.full(len(waypoints) - 1, 0.5), [2.0]])
    times = np.concatenate([[0.0], np.cumsum(durations)])
    trajectory = solve_sway(points, times, 0.6, start)
    assert_zmp_on_lines(trajectory)
    assert_continuous(trajectory)
    for k in range(1, len(waypoints)):
        a, b = np.array(diagonals[k])
        mid = np.linspace(times[k], times[k + 1], 9)[1:-1]
        position, _, acceleration = trajectory.sample(mid)
        assert np.max(line_distance(position - trajectory.A * acceleration, a, b)) < 1e-9


def test_curved_path_by_coordinate_transformation():
    path = ArcPath(curvature_per_m=1 / 3.0, origin=(1.0, -2.0), heading_rad=0.3)
    points, times = biped_walk(path=path)
    curved = solve_sway(points, times, ZC, points[0])
    assert_zmp_on_lines(curved)
    assert_continuous(curved)
    # Kurazume's transformation of the straight trajectory stays close to the exact solution
    # on the transformed support lines (gentle curvature: within a centimetre).
    straight_points, _ = biped_walk()
    straight = solve_sway(straight_points, times, ZC, straight_points[0])
    t = np.linspace(times[0], times[-1], 400)
    transformed = path.to_world(straight.sample(t)[0])
    assert np.max(np.linalg.norm(transformed - curved.sample(t)[0], axis=1)) < 0.01
    # The walk turns: final heading 0.3 + 2.1 / 3 rad.
    assert path.heading(2.1) == pytest.approx(1.0)
    position, velocity, _ = curved.sample(times[-1:])
    np.testing.assert_allclose(velocity[0], 0.0, atol=1e-4)


@settings(max_examples=20, deadline=None)
@given(distances=st.lists(st.floats(0.05, 0.3), min_size=1, max_size=12),
       speed=st.floats(0.05, 1.0), accel=st.floats(0.1, 2.0))
def test_trapezoid_durations_follow_eq_19(distances, speed, accel):
    durations = trapezoid_durations(distances, speed, accel)
    assert np.all(durations > 0)
    total, duration = sum(distances), durations.sum()
    # The trapezoid's area is the distance: ramp up, cruise, ramp down.
    v_top = min(speed, math.sqrt(accel * total))
    expected = total / v_top + v_top / accel
    assert duration == pytest.approx(expected, rel=1e-9)


def test_bad_sway_inputs_are_refused():
    with pytest.raises(ComPlanningError, match='strictly increasing'):
        solve_sway([[0, 0], [1, 0]], [0.0, 0.0], ZC, (0, 0))
    with pytest.raises(ComPlanningError, match='deceleration'):
        kurazume_half_cycle(ZC, 0.1, 0.5, 0.1, -5.0)
    with pytest.raises(ComPlanningError, match='end'):
        solve_sway([[0, 0], [1, 0]], [0.0, 1.0], ZC, (0, 0), end='stop')
