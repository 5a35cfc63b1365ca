"""The simulator's held joint trajectory and its acceleration-limited actuators (pure cores).

Checked against independent references: scipy's cubic Hermite spline for the sampling, the
time-optimal trapezoidal (bang-bang) profile for a step, and plain arithmetic for the stopping
velocity.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import CubicHermiteSpline

from gait_nodes.contract import (
    ContractError,
    JointTrajectoryCommand,
    joint_trajectory_command_to_msg,
    joint_trajectory_from_msg,
)
from gait_nodes.errors import ConfigError
from gait_nodes.interfaces import get_message
from gait_nodes.robot.description import load_robot_description
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import nominal_configuration
from gait_nodes.sim.kinematics import PositionActuators, stopping_velocity
from gait_nodes.sim.trajectory import HeldTrajectory

NS = 1_000_000_000
DT_NS = NS // 200
DT_S = DT_NS * 1e-9


@pytest.fixture(scope='module')
def robot():
    return load_robot_model('robosimian')


@pytest.fixture(scope='module')
def start(robot):
    return robot.joint_positions(nominal_configuration(robot))


def smooth_motion(start, t_s, amplitude_rad=0.1, omega_rad_s=5.0):
    """Positions and velocities of ``start + A (1 - cos(w t))`` per joint (at rest at t = 0)."""
    phase = np.arange(len(start)) * 0.1
    angle = omega_rad_s * t_s + phase * 0.0
    positions = start + amplitude_rad * (1.0 - np.cos(angle)) * np.cos(phase)
    velocities = amplitude_rad * omega_rad_s * np.sin(angle) * np.cos(phase)
    return positions, velocities


def knots(start, times_ns):
    rows = [smooth_motion(start, t * 1e-9) for t in times_ns]
    return np.array([p for p, _ in rows]), np.array([v for _, v in rows])


# -- the held trajectory ---------------------------------------------------------------------


def test_sampling_is_the_knots_exactly_and_scipys_hermite_spline_between(start):
    times = np.arange(0, NS + 1, 20 * NS // 1000)  # knots every 20 ms
    positions, velocities = knots(start, times)
    held = HeldTrajectory(start)
    held.replace(times, positions, velocities, received_ns=0)
    for k, t in enumerate(times):
        p, v = held.sample(int(t))
        assert p.tobytes() == positions[k].tobytes()
        np.testing.assert_array_equal(v, velocities[k])
    spline = CubicHermiteSpline(times * 1e-9, positions, velocities)
    for t in np.arange(0, NS, 1_700_000):  # instants off the knots
        p, v = held.sample(int(t))
        np.testing.assert_allclose(p, spline(t * 1e-9), atol=1e-12)
        np.testing.assert_allclose(v, spline(t * 1e-9, 1), atol=1e-9)
    p, v = held.sample(int(times[-1]) + 1)  # past the end: the last point, held still
    assert p.tobytes() == positions[-1].tobytes() and not v.any()
    p, v = held.sample(-5)  # before the first point: the first point
    assert p.tobytes() == positions[0].tobytes() and not v.any()


def test_without_velocities_the_trajectory_is_linear_between_points(start):
    held = HeldTrajectory(start)
    held.replace([NS, 2 * NS], [start + 0.1, start - 0.1], None, received_ns=NS)
    p, v = held.sample(NS + NS // 4)
    np.testing.assert_allclose(p, start + 0.05, atol=1e-15)
    np.testing.assert_allclose(v, np.full(len(start), -0.2), atol=1e-12)


def test_replacement_keeps_the_old_points_before_the_new_start(start):
    held = HeldTrajectory(start)
    old_times = np.arange(0, NS + 1, NS // 10)
    old_positions, old_velocities = knots(start, old_times)
    held.replace(old_times, old_positions, old_velocities, received_ns=0)
    before = {t: held.sample(t) for t in range(0, NS // 2, 3_000_000)}
    new_times = np.array([NS // 2, NS // 2 + NS // 10, NS])
    new_positions = np.array([start + 0.2, start + 0.3, start + 0.4])
    held.replace(new_times, new_positions, np.zeros_like(new_positions), received_ns=NS // 3)
    assert held.times_ns == (*old_times[old_times < NS // 2].tolist(), *new_times.tolist())
    for t, (p, v) in before.items():
        if t <= 4 * NS // 10:  # segments that end before the new start are the old ones
            got_p, got_v = held.sample(t)
            assert got_p.tobytes() == p.tobytes() and got_v.tobytes() == v.tobytes()
    for t, p in zip(new_times, new_positions, strict=True):
        assert held.sample(int(t))[0].tobytes() == p.tobytes()


def test_a_trajectory_that_starts_later_starts_from_the_command_held_at_receipt(start):
    """No jump: the state at receipt becomes a knot, then the trajectory's own points."""
    held = HeldTrajectory(start)
    held.replace([0, NS // 10], [start, start + 0.01], [np.zeros(len(start))] * 2, 0)
    held.replace([NS // 2], [start + 0.1], None, received_ns=NS // 5)  # held still since 0.1 s
    p, v = held.sample(NS // 5)
    np.testing.assert_allclose(p, start + 0.01, atol=1e-15)
    p, _ = held.sample(NS // 5 + (NS // 2 - NS // 5) // 2)  # linear to the new point
    np.testing.assert_allclose(p, start + 0.055, atol=1e-12)
    # Before any trajectory: from the initial command.
    fresh = HeldTrajectory(start)
    fresh.replace([NS], [start + 0.1], None, received_ns=NS // 2)
    np.testing.assert_allclose(fresh.sample(3 * NS // 4)[0], start + 0.05, atol=1e-12)


def test_discarding_the_past_keeps_every_later_sample(start):
    times = np.arange(0, NS + 1, NS // 20)
    positions, velocities = knots(start, times)
    held = HeldTrajectory(start)
    held.replace(times, positions, velocities, 0)
    later = {t: held.sample(t) for t in range(NS // 3, NS + NS // 10, 7_000_000)}
    held.discard_before(NS // 3)
    assert held.times_ns[0] == 6 * NS // 20 and len(held.times_ns) == 15
    for t, (p, v) in later.items():
        got_p, got_v = held.sample(t)
        assert got_p.tobytes() == p.tobytes() and got_v.tobytes() == v.tobytes()


# -- the actuators ---------------------------------------------------------------------------


def follow(actuators, held, start, seconds, dt_ns=DT_NS):
    """Positions, velocities after each tick (at t = dt, 2 dt, ...) following ``held``."""
    q, v = start.copy(), np.zeros(len(start))
    positions, velocities, steps = [], [], []
    for k in range(1, int(round(seconds * NS / dt_ns)) + 1):
        command, command_velocity = held.sample(k * dt_ns)
        step = actuators.step(q, v, command, dt_ns * 1e-9, command_velocity)
        q, v = step.positions_rad, step.velocities_rad_s
        positions.append(q)
        velocities.append(v)
        steps.append(step)
    return np.array(positions), np.array(velocities), steps


def test_a_trajectory_within_the_limits_is_followed_exactly(robot, start):
    """At the knots to 1e-9, between them on the Hermite polynomial; never saturated."""
    times = np.arange(0, 2 * NS + 1, 20 * NS // 1000)
    positions, velocities = knots(start, times)
    held = HeldTrajectory(start)
    held.replace(times, positions, velocities, 0)
    # Within the limits: 0.5 rad/s against 1, 2.5 rad/s^2 against 20.
    assert np.abs(velocities).max() < 0.6 * robot.velocity_limits_rad_s.min()
    got, _, steps = follow(PositionActuators(robot), held, start, 2.0)
    ticks_per_knot = 20 // 5
    np.testing.assert_allclose(got[ticks_per_knot - 1::ticks_per_knot], positions[1:], atol=1e-9)
    spline = CubicHermiteSpline(times * 1e-9, positions, velocities)
    np.testing.assert_allclose(got, spline(np.arange(1, len(got) + 1) * DT_S), atol=1e-9)
    assert not any(step.any_saturated for step in steps)


@settings(max_examples=30, deadline=None)
@given(distance=st.floats(1e-7, 2.0), sign=st.sampled_from([-1.0, 1.0]),
       dt_ms=st.sampled_from([1.0, 2.0, 5.0, 10.0]))
def test_a_step_is_followed_at_the_limits_without_overshoot(robot, start, distance, sign,
                                                              dt_ms):
    """Velocity and acceleration never above the limits, no overshoot, minimum time to 2 ticks.

    The reference is the time-optimal (trapezoidal) profile of a joint with these limits.
    """
    actuators = PositionActuators(robot)
    k = robot.joint_names.index('fl_joint_2')
    dt = dt_ms * 1e-3
    v_max, a_max = robot.velocity_limits_rad_s[k], robot.acceleration_limits_rad_s2[k]
    target = start.copy()
    target[k] += sign * distance
    q, v = start.copy(), np.zeros(len(start))
    fastest_s = (distance / v_max + v_max / a_max if distance >= v_max ** 2 / a_max
                 else 2.0 * math.sqrt(distance / a_max))
    arrived = None
    for tick in range(int((fastest_s + 0.5) / dt)):
        step = actuators.step(q, v, target, dt)
        assert np.all(np.abs(step.velocities_rad_s) <= robot.velocity_limits_rad_s * (1 + 1e-12))
        assert np.all(np.abs(step.velocities_rad_s - v)
                      <= robot.acceleration_limits_rad_s2 * dt * (1 + 1e-9) + 1e-12)
        q, v = step.positions_rad, step.velocities_rad_s
        assert sign * (q[k] - target[k]) <= 1e-12, 'overshoot'
        if arrived is None and abs(q[k] - target[k]) <= 1e-12:
            arrived = (tick + 1) * dt
    assert arrived is not None and arrived <= fastest_s + 2 * dt + 1e-12
    assert q[k] == pytest.approx(target[k], abs=1e-12) and v[k] == pytest.approx(0, abs=1e-9)
    others = np.arange(len(start)) != k
    assert np.all(q[others] == start[others])


@settings(max_examples=60, deadline=None)
@given(error=st.floats(0.0, 10.0), change=st.floats(1e-3, 10.0), dt=st.floats(1e-4, 0.05))
def test_the_stopping_velocity_stops_exactly_in_the_distance_and_no_faster_one_does(
        error, change, dt):
    """Moving at v, then braking by ``change`` per step, covers at most the error.

    A little faster covers more.
    """
    def covered(v):
        distance = 0.0
        while v > 0.0:
            distance += v * dt
            v -= change
        return distance

    v = float(stopping_velocity(np.array([error]), np.array([change]), dt)[0])
    assert covered(v) <= error * (1 + 1e-9) + 1e-15
    if error > 0.0:
        assert covered(v * (1 + 1e-6) + 1e-12) > error * (1 - 1e-9)


def test_after_the_end_the_joint_decelerates_within_the_limits_and_holds_the_last_point(
        robot, start):
    """A trajectory that ends at full speed: the joint brakes at its limit and comes back."""
    actuators = PositionActuators(robot)
    k = robot.joint_names.index('fr_joint_3')
    rate = 0.8 * robot.velocity_limits_rad_s[k]
    times = np.arange(0, NS // 2 + 1, NS // 100)
    positions = np.repeat(start[None, :], len(times), axis=0)
    velocities = np.zeros_like(positions)
    ramp = np.minimum(times * 1e-9, 0.1) ** 2 / 0.2 + np.maximum(times * 1e-9 - 0.1, 0.0)
    positions[:, k] += rate * ramp
    velocities[:, k] = rate * np.minimum(times * 1e-9 / 0.1, 1.0)
    held = HeldTrajectory(start)
    held.replace(times, positions, velocities, 0)
    got, speeds, _ = follow(actuators, held, start, 1.5)
    change = np.abs(np.diff(np.vstack([np.zeros(len(start)), speeds]), axis=0))
    assert np.all(change <= robot.acceleration_limits_rad_s2 * DT_S * (1 + 1e-9) + 1e-12)
    assert np.all(np.abs(speeds) <= robot.velocity_limits_rad_s * (1 + 1e-12))
    end = len(times) - 1
    ticks_at_end = int(times[-1] // DT_NS)
    overshoot = got[ticks_at_end:, k].max() - positions[end, k]
    # What braking at the limit from the final speed takes, one tick's travel of slack.
    a_max = robot.acceleration_limits_rad_s2[k]
    assert 0.0 < overshoot <= rate ** 2 / (2 * a_max) + rate * DT_S
    np.testing.assert_allclose(got[-1], positions[end], atol=1e-12)
    assert not speeds[-1].any()


def test_position_limits_hold_and_a_clamped_command_is_reported(robot, start):
    actuators = PositionActuators(robot)
    k = robot.joint_names.index('rl_joint_1')
    target = start.copy()
    target[k] = robot.upper_limits[k] + 1.0
    q, v = start.copy(), np.zeros(len(start))
    for _ in range(2000):
        step = actuators.step(q, v, target, DT_S)
        q, v = step.positions_rad, step.velocities_rad_s
        assert q[k] <= robot.upper_limits[k]
    assert q[k] == pytest.approx(robot.upper_limits[k]) and v[k] == 0.0
    assert step.clamped_to_limits[k] and step.any_clamped


# -- the robot YAML ------------------------------------------------------------------------


def test_every_shipped_robot_has_acceleration_limits(robot):
    from gait_nodes.robot.description import available_robots

    for name in available_robots():
        description = load_robot_description(name)
        assert description.joint_acceleration_limit_rad_s2 > 0
        for joint in description.joint_names:
            assert description.acceleration_limit_rad_s2(joint) > 0
    assert np.all(robot.acceleration_limits_rad_s2 == 20.0)


def test_acceleration_limits_in_the_yaml_are_validated(tmp_path):
    from test_robot_description import write_variant

    for change, expected in (
            (lambda d: d.pop('joint_acceleration_limit_rad_s2'),
             'joint_acceleration_limit_rad_s2: missing'),
            (lambda d: d.update(joint_acceleration_limit_rad_s2=0.0),
             r'joint_acceleration_limit_rad_s2: must be a number in \(0.0, 10000.0\]'),
            (lambda d: d.update(joint_acceleration_limit_rad_s2=math.inf), 'must be a number'),
            (lambda d: d.update(joint_acceleration_limits_rad_s2={'elbow': 2.0}),
             'joint_acceleration_limits_rad_s2.elbow: not a limb joint'),
            (lambda d: d.update(joint_acceleration_limits_rad_s2={'fl_1': -2.0}),
             'joint_acceleration_limits_rad_s2.fl_1: must be a number')):
        path = write_variant(tmp_path, change)
        with pytest.raises(ConfigError, match=expected) as info:
            load_robot_description(path)
        assert str(path) in str(info.value)
    path = write_variant(tmp_path, lambda d: d.update(
        joint_acceleration_limits_rad_s2={'fl_1': 7.5}))
    description = load_robot_description(path)
    assert description.acceleration_limit_rad_s2('fl_1') == 7.5
    assert description.acceleration_limit_rad_s2('fl_2') == 20.0


# -- the message ---------------------------------------------------------------------------


def trajectory_msg(names, positions, velocities=(), times_s=None, stamp_ns=0):
    """A JointTrajectory: one point per row of ``positions`` (velocities likewise or empty)."""
    msg = get_message('trajectory_msgs/msg/JointTrajectory')()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
    msg.joint_names = list(names)
    point_type = get_message('trajectory_msgs/msg/JointTrajectoryPoint')
    positions = [list(map(float, row)) for row in np.atleast_2d(positions)]
    times_s = times_s if times_s is not None else [0.1 * k for k in range(len(positions))]
    for k, row in enumerate(positions):
        point = point_type()
        point.positions = row
        if len(velocities):
            point.velocities = [float(x) for x in velocities[k]]
        point.time_from_start.sec, point.time_from_start.nanosec = divmod(
            int(round(times_s[k] * NS)), NS)
        msg.points.append(point)
    return msg


def test_a_valid_trajectory_round_trips_through_the_message(robot, start):
    names = robot.joint_names[:4]
    positions = np.array([start[:4], start[:4] + 0.1])
    velocities = np.array([np.zeros(4), np.full(4, 0.5)])
    command = joint_trajectory_from_msg(trajectory_msg(names, positions, velocities,
                                                       stamp_ns=3 * NS + 7), robot.joint_names)
    assert command.stamp_ns == 3 * NS + 7 and command.joint_names == names
    np.testing.assert_array_equal(command.times_from_start_ns, [0, NS // 10])
    np.testing.assert_array_equal(command.positions_rad, positions)
    np.testing.assert_array_equal(command.velocities_rad_s, velocities)
    assert command.accelerations_rad_s2 is None
    np.testing.assert_array_equal(command.times_ns(99), [3 * NS + 7, 3 * NS + 7 + NS // 10])
    again = joint_trajectory_from_msg(joint_trajectory_command_to_msg(command))
    for field in ('times_from_start_ns', 'positions_rad', 'velocities_rad_s'):
        np.testing.assert_array_equal(getattr(again, field), getattr(command, field))
    zero_stamp = JointTrajectoryCommand(0, names, command.times_from_start_ns, positions)
    np.testing.assert_array_equal(zero_stamp.times_ns(5 * NS), [5 * NS, 5 * NS + NS // 10])


def bad_trajectories(names, start):
    """(what is wrong, message, expected words) of trajectories a JTC refuses."""
    two = np.array([start, start + 0.1])
    cases = [
        ('no names', trajectory_msg([], np.zeros((1, 0))), 'names no joints'),
        ('unknown', trajectory_msg([*names[:-1], 'no_such_joint'], two), 'unknown joints'),
        ('repeated', trajectory_msg([names[0], names[0]], [[0.1, 0.2]]), 'joint names repeat'),
        ('no points', trajectory_msg(names, np.zeros((0, len(names)))), 'has no points'),
        ('same time', trajectory_msg(names, two, times_s=[0.1, 0.1]), 'strictly increasing'),
        ('backwards', trajectory_msg(names, two, times_s=[0.2, 0.1]), 'strictly increasing'),
        ('short positions', trajectory_msg(names[:-1], two), '27 joint names'),
        ('short velocities', trajectory_msg(names, two, velocities=[[0.0] * 3] * 2),
         '3 velocities'),
        ('NaN', trajectory_msg(names, two + np.where(np.arange(len(names)) == 3, math.nan, 0)),
         'NaN or infinite'),
        ('infinite velocity', trajectory_msg(names, two, velocities=[
            np.zeros(len(names)), np.full(len(names), math.inf)]), 'NaN or infinite'),
    ]
    negative = trajectory_msg(names, two)
    negative.points[0].time_from_start.sec = -1
    cases.append(('negative time', negative, 'allowed: >= 0'))
    mixed = trajectory_msg(names, two, velocities=[np.zeros(len(names))] * 2)
    mixed.points[1].velocities = []
    cases.append(('velocities in one point only', mixed, '0 velocities'))
    effort = trajectory_msg(names, two)
    effort.points[1].effort = [1.0] * len(names)
    cases.append(('efforts', effort, 'efforts'))
    accelerations = trajectory_msg(names, two)
    accelerations.points[0].accelerations = [0.0] * 2
    accelerations.points[1].accelerations = [0.0] * 2
    cases.append(('short accelerations', accelerations, '2 accelerations'))
    return cases


def test_trajectories_a_joint_trajectory_controller_refuses_are_refused(robot, start):
    names = robot.joint_names
    for what, msg, words in bad_trajectories(names, start):
        with pytest.raises(ContractError, match=words):
            joint_trajectory_from_msg(msg, names)
            pytest.fail(f'{what} accepted')


def test_huge_finite_values_are_accepted(robot, start):
    names = robot.joint_names
    huge = np.full(len(names), 1e308)
    command = joint_trajectory_from_msg(trajectory_msg(names, [huge, -huge],
                                                       velocities=[-huge, huge]), names)
    assert command.positions_rad[0, 0] == 1e308


def test_bag_analysis_reads_overlapping_trajectories_once_per_instant(robot, start):
    """The windows whole_body_ik publishes overlap; the bag's joint series has each knot once."""
    from gait_nodes.bag.analysis import _Collector
    from gait_nodes.interfaces import serialize_message

    names = robot.joint_names
    collector = _Collector()
    for first in (0, 2):  # knots 0-3, then 2-5 (2 and 3 again, with the same values)
        positions = np.array([start + 0.01 * k for k in range(first, first + 4)])
        msg = trajectory_msg(names, positions, velocities=np.full_like(positions, 2.0),
                             times_s=[0.005 * k for k in range(4)],
                             stamp_ns=NS + first * DT_NS)
        collector.message('/joint_commands', 'trajectory_msgs/msg/JointTrajectory',
                          serialize_message(msg))
    series = collector.series.joints['/joint_commands']
    assert series.stamps_ns == [NS + k * DT_NS for k in range(6)]
    np.testing.assert_allclose(np.array(series.positions)[:, 0], start[0] + 0.01 * np.arange(6))
    assert series.names == list(names) and series.velocities[-1][0] == 2.0
