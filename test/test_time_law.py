"""The fastest time law along a path (TOPP-RA) and the value-table swings timed by it.

Checked against closed forms (a straight joint move at rest at both ends: trapezoidal or
triangular velocity), against the limits on the law's own motion sampled finely, and on
RoboSimian's swings: the law at every placement it is computed for keeps the joints within
their velocity and acceleration limits, and is faster than the uniform stretch it replaced.
"""

import functools
import math
from types import SimpleNamespace

import numpy as np
import pytest
from swing_helpers import robot, tiny_table

from gait_nodes.contract import SwingTrajectory
from gait_nodes.errors import SwingPolicyError
from gait_nodes.swing.policy import LAW_PLACEMENTS_M, SwingPolicy, law_placements
from gait_nodes.swing.time_law import fastest_times
from gait_nodes.swing.timing import joint_path_time_s, smooth_trajectory


def rest_to_rest_s(length, velocity, acceleration):
    """Least time of a straight move of ``length`` from rest to rest (bang-coast-bang)."""
    if length >= velocity ** 2 / acceleration:
        return length / velocity + velocity / acceleration
    return 2.0 * math.sqrt(length / acceleration)


@pytest.mark.parametrize('length, velocity, acceleration', [
    (1.0, 1.0, 20.0),    # cruises at the velocity limit
    (0.02, 1.0, 20.0),   # never reaches it: a triangle
    (0.3, 0.5, 2.0),
])
def test_a_straight_move_takes_the_bang_coast_bang_time(length, velocity, acceleration):
    u = np.linspace(0.0, 1.0, 41)
    joints = np.column_stack([length * u, -0.5 * length * u])  # the second joint slower
    times = fastest_times(u, joints, velocity, acceleration)
    expected = rest_to_rest_s(length, velocity, acceleration)
    assert times[0] == 0.0
    assert np.all(np.diff(times) > 0)
    assert times[-1] == pytest.approx(expected, rel=0.02)


def test_each_joint_has_its_own_limits():
    u = np.linspace(0.0, 1.0, 41)
    joints = np.column_stack([u, u])
    one = fastest_times(u, joints, np.array([1.0, 0.5]), np.array([20.0, 20.0]))
    assert one[-1] == pytest.approx(rest_to_rest_s(1.0, 0.5, 20.0), rel=0.02)


def test_the_law_keeps_a_curved_path_within_its_limits():
    u = np.linspace(0.0, 2.0, 81)
    joints = np.column_stack([np.sin(2.0 * u), 0.3 * u ** 2, np.cos(u)])
    velocity, acceleration = np.array([1.0, 0.8, 1.2]), np.array([5.0, 10.0, 8.0])
    # Clustered at the ends, where from rest a small step of the path takes long.
    fine = 1.0 - np.cos(np.linspace(0.0, math.pi, 4001))
    times = fastest_times(u, joints, velocity, acceleration, at=fine)
    dt = 0.002
    played = np.arange(0.0, times[-1], dt)
    s = np.interp(played, times, fine)
    q = np.column_stack([np.sin(2.0 * s), 0.3 * s ** 2, np.cos(s)])
    rates = np.abs(np.diff(q, axis=0)) / dt
    accelerations = np.abs(np.diff(q, 2, axis=0)) / dt ** 2
    assert (rates / velocity).max() <= 1.01
    assert (rates / velocity).max() >= 0.97  # some joint at its limit: no slack left
    assert (accelerations / acceleration).max() <= 1.1


def test_a_path_without_length_or_order_is_refused():
    with pytest.raises(SwingPolicyError, match='increasing path parameter'):
        fastest_times(np.zeros(1), np.zeros((1, 2)), 1.0, 1.0)
    with pytest.raises(SwingPolicyError, match='increasing path parameter'):
        fastest_times(np.array([0.0, 1.0, 0.5]), np.zeros((3, 2)), 1.0, 1.0)


@functools.lru_cache(maxsize=1)
def policy():
    table, _ = tiny_table()
    return SwingPolicy(table, robot())


@pytest.mark.parametrize('gait', ['static_crawl', 'crawl'])
@pytest.mark.parametrize('foot, step', [('front_right', 0.2), ('rear_left', -0.2),
                                        ('front_left', 0.1)])
def test_a_table_swing_in_the_fastest_law_keeps_its_joints_within_the_limits(foot, step, gait):
    # At every placement the law is computed for, played at its own times and sampled 5 ms
    # apart (as the swing-leg policy sends it), the limb's joints stay within the velocity
    # limit (to the 1 % the law's grid allows, which the planner's tracking margin covers) and
    # the acceleration limit; and it is faster than the smoothed swing stretched uniformly
    # until its fastest joint reaches the limit (what the policy sent before).
    swing_policy = policy()
    path, _ = swing_policy.fastest_swing(np.array([step, 0.0]), 0.0, foot, gait)
    centre = np.asarray(swing_policy.law_centre(foot))
    model = robot()
    reference = next(f for f in model.description.feet if f.name == 'front_right')
    limb = SimpleNamespace(
        velocity_limits_rad_s=np.ones(6),
        acceleration_limits_rad_s2=np.asarray(model.acceleration_limits_rad_s2)[
            model.indices(reference.joints)[:6]])
    limits = limb.acceleration_limits_rad_s2
    played = np.arange(0.0, path.duration_s, 0.005)
    states = np.column_stack([np.interp(played, path.times_s, path.states[:, i])
                              for i in range(4)])
    placements = law_placements(gait)  # the gait's own law
    between = 0.5 * (np.asarray(placements[1:]) + np.asarray(placements[:-1]))
    for outwards in (*placements, *between):  # between them too
        placed = states.copy()
        placed[:, :2] += centre + (outwards, 0.0) - 0.5 * (states[0, :2] + states[-1, :2])
        q, feasible = swing_policy.timing.joints(placed)
        assert feasible.all()
        rates = np.abs(np.diff(q, axis=0)) / 0.005
        assert rates.max() <= 1.0 * 1.01
        accelerations = np.abs(np.diff(q, 2, axis=0)) / 0.005 ** 2
        assert (accelerations / limits).max() <= 1.0
    # The uniform stretch of the same smoothed path, at the stance place alone.
    table_path, _ = swing_policy.path_for_step(np.array([step, 0.0]))
    polyline = SwingTrajectory('x', 0, table_path.times_s, table_path.states[:, :3],
                               table_path.states[:, 3])
    smooth, _ = smooth_trajectory(polyline, None, 0.005)
    placed = np.column_stack([smooth.positions_in_world, smooth.yaws_rad])
    placed[:, :2] += centre - 0.5 * (placed[0, :2] + placed[-1, :2])
    q, _ = swing_policy.timing.joints(placed)
    stretched = joint_path_time_s(limb, smooth.times_s / smooth.times_s[-1], q[:, :6], 'path')
    assert path.duration_s < 0.97 * stretched, (path.duration_s, stretched)


def test_places_out_of_the_limbs_reach_are_left_out_of_the_law(monkeypatch):
    # A place the limb cannot reach does not make the swing fail: the law keeps the limb
    # within its limits at the places it reaches; at none, the smoothed path keeps the table's
    # own timing (the planner's probe then stretches it as far as it needs).
    from gait_nodes.swing import policy as policy_module

    step = np.array([0.2, 0.0])
    reachable, _ = SwingPolicy(tiny_table()[0], robot()).fastest_swing(
        step, 0.0, 'front_right', 'static_crawl')
    monkeypatch.setattr(policy_module, 'LAW_PLACEMENTS_M', (*LAW_PLACEMENTS_M, 1.5))
    with_far, _ = SwingPolicy(tiny_table()[0], robot()).fastest_swing(
        step, 0.0, 'front_right', 'static_crawl')
    assert with_far.duration_s == reachable.duration_s
    monkeypatch.setattr(policy_module, 'LAW_PLACEMENTS_M', (1.5,))
    swing_policy = SwingPolicy(tiny_table()[0], robot())
    none_reached, _ = swing_policy.fastest_swing(step, 0.0, 'front_right', 'static_crawl')
    table_path, _ = swing_policy.path_for_step(step)
    polyline = SwingTrajectory('x', 0, table_path.times_s, table_path.states[:, :3],
                               table_path.states[:, 3])
    smooth, _ = smooth_trajectory(polyline, None, 0.005)
    assert none_reached.duration_s == pytest.approx(smooth.times_s[-1])
