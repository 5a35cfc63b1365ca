"""The whole_body_ik node's per-tick shortcuts, bit for bit against the numpy reference paths.

The node samples its references as Python floats prepared once per message (SwingPath,
ComTrack, FootTargets), reads /gait/com_reference without building ComStates and keeps its last
command's joint vector (limit_joint_step). Each must give exactly the floats of the
straightforward numpy formulas it replaced (written out here as the references), so that the
joint commands stay byte-identical: compared with ``==`` on the IEEE doubles, not a tolerance.
The COM track's Hermite interpolation is checked against its boundary conditions solved
independently (to 1e-9 m), against polynomials it must reproduce, and against the COM
generator's own ticks.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.contract import (
    ComState,
    ContractError,
    FootstepPlan,
    SwingTrajectory,
    com_reference_from_msg,
    com_reference_to_msg,
)
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import (
    ComTrack,
    FootTargets,
    SwingPath,
    com_state_at,
    fallback_swing_pose,
    limit_joint_step,
    limit_joint_velocity,
    swing_pose_at,
    swings_under_way,
)
from gait_nodes.whole_body_ik import com_track_from_msg

NS = 1_000_000_000


def _wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))


# -- the numpy reference formulas (what the node computed per tick before) ---------------------


def reference_swing_pose(trajectory, stamp_ns):
    t = (stamp_ns - trajectory.start_ns) * 1e-9
    times = trajectory.times_s
    positions, yaws = trajectory.positions_in_world, trajectory.yaws_rad
    k = int(np.searchsorted(times, t, side='right')) - 1
    if k < 0:
        return positions[0].copy(), float(yaws[0])
    if k >= len(times) - 1:
        return positions[-1].copy(), float(yaws[-1])
    w = (t - times[k]) / (times[k + 1] - times[k])
    yaw = float(yaws[k])
    return (positions[k] + w * (positions[k + 1] - positions[k]),
            yaw + w * math.remainder(float(yaws[k + 1]) - yaw, 2.0 * math.pi))


def hermite_coefficients(conditions_at_0, conditions_at_1):
    """Coefficients (lowest power first) of a Hermite polynomial in s on [0, 1], solved.

    The conditions are the value, first and (for a quintic) second derivative at s = 0 and 1.
    """
    order = 2 * len(conditions_at_0)
    rows, values = [], []
    for s, conditions in ((0.0, conditions_at_0), (1.0, conditions_at_1)):
        for derivative, value in enumerate(conditions):
            row = [0.0] * order
            for power in range(derivative, order):
                row[power] = math.perm(power, derivative) * s ** (power - derivative)
            rows.append(row)
            values.append(value)
    return np.linalg.solve(np.array(rows), np.array(values))


def reference_com_state(states, stamp_ns, max_extrapolation_s):
    """Quintic Hermite in position, cubic Hermite in yaw, by solving for the coefficients."""
    first, last = states[0], states[-1]
    if stamp_ns <= first.stamp_ns:
        return np.array(first.position_in_world), float(first.yaw_rad)
    if stamp_ns >= last.stamp_ns:
        dt = min((stamp_ns - last.stamp_ns) * 1e-9, max_extrapolation_s)
        return (last.position_in_world + dt * last.velocity_in_world,
                float(last.yaw_rad + dt * last.yaw_rate_rad_s))
    stamps = np.array([s.stamp_ns for s in states], dtype=np.int64)
    k = int(np.searchsorted(stamps, stamp_ns, side='right')) - 1
    a, b = states[k], states[k + 1]
    h = (b.stamp_ns - a.stamp_ns) * 1e-9
    w = (stamp_ns - a.stamp_ns) / (b.stamp_ns - a.stamp_ns)
    powers = w ** np.arange(6)
    position = [powers @ hermite_coefficients(
        (a.position_in_world[i], h * a.velocity_in_world[i], h * h * a.acceleration_in_world[i]),
        (b.position_in_world[i], h * b.velocity_in_world[i], h * h * b.acceleration_in_world[i]))
        for i in range(3)]
    turn = float(_wrap(b.yaw_rad - a.yaw_rad))
    yaw = a.yaw_rad + powers[:4] @ hermite_coefficients((0.0, h * a.yaw_rate_rad_s),
                                                        (turn, h * b.yaw_rate_rad_s))
    return np.array(position), float(yaw)


def reference_fallback_pose(swing, t_s, step_height_m):
    duration = swing.duration_s
    s = (t_s - swing.lift_off_s) / duration if duration > 0 else 1.0
    s = min(max(s, 0.0), 1.0)
    blend = s * s * s * (10.0 + s * (-15.0 + 6.0 * s))
    position = swing.start_in_world + blend * (swing.end_in_world - swing.start_in_world)
    position[2] += step_height_m * math.sin(math.pi * s) ** 2
    yaw = swing.start_yaw_rad + blend * float(_wrap(swing.end_yaw_rad - swing.start_yaw_rad))
    return position, yaw


def reference_feet(plan, foot_names, trajectories, stamp_ns, step_height_m):
    t_plan = (stamp_ns - plan.start_ns) * 1e-9
    index = plan.index_at(t_plan)
    order = [plan.foot_names.index(name) for name in foot_names]
    feet = plan.positions_in_world[index][order]
    yaws = plan.yaws_rad[index][order]
    fallbacks = 0
    swings = swings_under_way(plan, t_plan)
    for k, name in enumerate(foot_names):
        swing = swings.get(name)
        if swing is None:
            continue
        trajectory = trajectories.get(name)
        if trajectory is not None and trajectory.start_ns <= stamp_ns <= (
                trajectory.start_ns + int(round(trajectory.duration_s * 1e9))):
            feet[k], yaws[k] = reference_swing_pose(trajectory, stamp_ns)
        else:
            feet[k], yaws[k] = reference_fallback_pose(swing, t_plan, step_height_m)
            fallbacks += 1
    return feet, yaws, fallbacks


def same_floats(a, b) -> bool:
    """Bit-identical doubles (NaN never appears here; -0.0 and 0.0 would count as different)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


# -- swing trajectories ------------------------------------------------------------------------


@settings(max_examples=150, deadline=None)
@given(gaps=st.lists(st.sampled_from([0.0, 0.013, 0.1, 0.25, 1.0 / 3.0]), min_size=1,
                     max_size=7),
       yaws=st.lists(st.floats(-10.0, 10.0), min_size=8, max_size=8),
       start_ns=st.integers(0, 10 ** 12), offset_ns=st.integers(-NS // 2, 3 * NS),
       at_waypoint=st.booleans(), seed=st.integers(0, 100))
def test_swing_path_is_swing_pose_at_bit_for_bit(gaps, yaws, start_ns, offset_ns, at_waypoint,
                                                 seed):
    times = np.concatenate([[0.0], np.cumsum(gaps)])  # repeated times: zero-length segments
    positions = np.random.default_rng(seed).uniform(-1.0, 1.0, (len(times), 3))
    trajectory = SwingTrajectory('front_left', start_ns, times, positions,
                                 np.array(yaws[:len(times)]))
    if at_waypoint:  # exactly on a waypoint time, where the segment choice matters
        offset_ns = int(round(times[seed % len(times)] * 1e9))
    stamp = start_ns + offset_ns
    path = SwingPath(trajectory)
    position, yaw = path.pose_at(stamp)
    expected, expected_yaw = reference_swing_pose(trajectory, stamp)
    assert same_floats(position, expected) and same_floats(yaw, expected_yaw)
    public = swing_pose_at(trajectory, stamp)
    assert same_floats(public[0], expected) and same_floats(public[1], expected_yaw)
    assert path.covers(stamp) == (trajectory.start_ns <= stamp <= trajectory.start_ns
                                  + int(round(trajectory.duration_s * 1e9)))


# -- COM reference -----------------------------------------------------------------------------


def com_states(rng, count, start_ns, step_ns):
    return [ComState(start_ns + k * step_ns, rng.uniform(-2, 2, 3), rng.uniform(-1, 1, 3),
                     rng.uniform(-1, 1, 3), yaw_rad=float(rng.uniform(-4, 4)),
                     yaw_rate_rad_s=float(rng.uniform(-1, 1))) for k in range(count)]


@settings(max_examples=150, deadline=None)
@given(count=st.integers(1, 5), step_ns=st.sampled_from([1, 5_000_000, 333_333_333]),
       offset_ns=st.integers(-NS // 10, 2 * NS), on_state=st.booleans(),
       extrapolation_s=st.sampled_from([0.0, 0.05, 1.0]), seed=st.integers(0, 1000))
def test_com_track_is_the_hermite_interpolant_of_its_states(count, step_ns, offset_ns, on_state,
                                                             extrapolation_s, seed):
    # Written out in closed form in ComTrack; here solved from its boundary conditions.
    rng = np.random.default_rng(seed)
    start = 7 * NS + seed
    states = com_states(rng, count, start, step_ns)
    stamp = start + (seed % count) * step_ns if on_state else start + offset_ns
    position, yaw = ComTrack.from_states(states).at(stamp, extrapolation_s)
    expected, expected_yaw = reference_com_state(states, stamp, extrapolation_s)
    np.testing.assert_allclose(position, expected, rtol=0, atol=1e-9)
    assert yaw == pytest.approx(expected_yaw, abs=1e-9)
    if on_state:  # at a state: that state, exactly
        assert same_floats(position, expected) and same_floats(yaw, expected_yaw)
    public = com_state_at(states, stamp, extrapolation_s)
    assert same_floats(public[0], position) and same_floats(public[1], yaw)


def _polynomial_states(coefficients, yaw_coefficients, stamps_ns):
    """ComStates of a quintic COM (3 axes) and a cubic yaw, sampled at ``stamps_ns``."""
    states = []
    for stamp in stamps_ns:
        t = stamp * 1e-9
        p, v, a = (np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyder(
            coefficients, m, axis=0)) for m in (0, 1, 2))
        yaw = np.polynomial.polynomial.polyval(t, yaw_coefficients)
        rate = np.polynomial.polynomial.polyval(t, np.polynomial.polynomial.polyder(
            yaw_coefficients))
        states.append(ComState(stamp, p, v, a, yaw_rad=float(math.remainder(yaw, 2 * math.pi)),
                               yaw_rate_rad_s=float(rate)))
    return states


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 1000), spacing_ns=st.sampled_from([5_000_000, 20_000_000,
                                                              100_000_000]))
def test_com_track_reproduces_a_quintic_com_and_a_cubic_yaw_exactly(seed, spacing_ns):
    # Quintic Hermite is exact on a quintic; cubic Hermite on a cubic yaw, across +-pi too.
    rng = np.random.default_rng(seed)
    coefficients = rng.uniform(-1, 1, (6, 3))
    yaw_coefficients = rng.uniform(-3, 3, 4)
    states = _polynomial_states(coefficients, yaw_coefficients, spacing_ns * np.arange(11))
    track = ComTrack.from_states(states)
    for stamp in rng.integers(0, 10 * spacing_ns, 50):
        expected = _polynomial_states(coefficients, yaw_coefficients, [int(stamp)])[0]
        position, yaw = track.at(int(stamp))
        np.testing.assert_allclose(position, expected.position_in_world, rtol=0, atol=1e-12)
        assert math.remainder(yaw - expected.yaw_rad, 2 * math.pi) == pytest.approx(0, abs=1e-12)


def test_com_track_of_the_published_samples_is_the_generators_every_tick():
    # The controller publishes every 4th 5 ms state of the preview generator (20 ms apart);
    # between them the IK's track gives the generator's own states to 1.1e-8 m (measured
    # on this 8-step walk: the generator's COM is piecewise cubic, one piece per 5 ms step;
    # cubic Hermite, without the accelerations, misses by 1.9e-7 m).
    from com_references import biped_walk_vertices, window

    from gait_nodes.com.preview import OnlinePreviewController, PreviewSettings

    times, points = biped_walk_vertices(steps=8, rest_after_s=2.0)
    settings = PreviewSettings(com_height_m=0.814, dt_s=0.005, preview_s=1.6, q_weight=1.0,
                               r_weight=1e-6)
    reference = window(times, points, 0, times[-1] + 3.0, 0.02)
    generator = OnlinePreviewController(settings, reference.zmp_in_world[0], 0)
    generator.set_reference(reference)
    ticks = [generator.step_values() for _ in range(int(12.0 / settings.dt_s))]
    published = [ComState(stamp, (x, y, 0.8), (vx, vy, 0.0), (ax, ay, 0.0))
                 for stamp, x, y, vx, vy, ax, ay in ticks[::4]]
    track = ComTrack.from_states(published)
    error = max(np.max(np.abs(np.array(track.at(stamp)[0][:2]) - (x, y)))
                for stamp, x, y, *_ in ticks[:len(ticks) - 4])
    assert error < 5e-8


def test_a_spliced_track_keeps_the_held_states_before_the_new_first_one():
    rng = np.random.default_rng(3)
    held = com_states(rng, 30, NS, 20_000_000)  # 1.0 s .. 1.58 s
    newer = com_states(rng, 10, NS + 305_000_000, 20_000_000)  # from 1.305 s (off the grid)
    spliced = ComTrack.from_states(held).spliced(ComTrack.from_states(newer))
    kept = [s for s in held if s.stamp_ns < newer[0].stamp_ns]
    assert list(spliced.stamps_ns) == [s.stamp_ns for s in kept + newer]
    # The held track where the new one does not reach, the new one from its first stamp on.
    before = ComTrack.from_states(kept + newer[:1])
    for stamp in range(NS - NS // 10, newer[0].stamp_ns, 7_000_000):
        assert same_floats(spliced.at(stamp)[0], ComTrack.from_states(held).at(stamp)[0]) \
            if stamp <= kept[-1].stamp_ns else same_floats(spliced.at(stamp)[0],
                                                          before.at(stamp)[0])
    for stamp in range(newer[0].stamp_ns, newer[-1].stamp_ns + NS // 10, 7_000_000):
        (position, yaw), (expected, expected_yaw) = spliced.at(stamp), \
            ComTrack.from_states(newer).at(stamp)
        assert same_floats(position, expected) and same_floats(yaw, expected_yaw)
    # Held states older than keep_s before the new first one are let go.
    short = ComTrack.from_states(held).spliced(ComTrack.from_states(newer), keep_s=0.1)
    assert short.stamps_ns[0] >= newer[0].stamp_ns - 100_000_000
    # A new track that starts before every held state replaces them all.
    earlier = com_states(rng, 3, NS // 2, 20_000_000)
    assert list(ComTrack.from_states(held).spliced(ComTrack.from_states(earlier)).stamps_ns) \
        == [s.stamp_ns for s in earlier]


@settings(max_examples=60, deadline=None)
@given(count=st.integers(1, 4), seed=st.integers(0, 1000))
def test_com_reference_read_straight_into_floats_is_the_contract_reader(count, seed):
    rng = np.random.default_rng(seed)
    msg = com_reference_to_msg(com_states(rng, count, 3 * NS + seed, 5_000_000))
    fast = com_track_from_msg(msg)
    slow = ComTrack.from_states(com_reference_from_msg(msg))
    for stamp in (0, 3 * NS + seed + 2_000_000, 3 * NS + seed + count * 5_000_000, 10 * NS):
        a, b = fast.at(stamp, 0.05), slow.at(stamp, 0.05)
        assert same_floats(a[0], b[0]) and same_floats(a[1], b[1])


def _bad_com_messages():
    def msg():
        return com_reference_to_msg(com_states(np.random.default_rng(0), 2, NS, 5_000_000))

    def set_(path, value):
        def spoil(m):
            obj = m
            for name in path[:-1]:
                obj = obj[name] if isinstance(name, int) else getattr(obj, name)
            setattr(obj, path[-1], value)
        return spoil

    spoilers = {
        'frame': set_(('header', 'frame_id'), 'map'),
        'joint names': set_(('joint_names',), ['base']),
        'no points': set_(('points',), []),
        'two transforms': lambda m: m.points[1].transforms.append(m.points[1].transforms[0]),
        'no acceleration': set_(('points', 0, 'accelerations'), []),
        'NaN position': set_(('points', 1, 'transforms', 0, 'translation', 'y'), float('nan')),
        'inf velocity': set_(('points', 0, 'velocities', 0, 'linear', 'z'), float('inf')),
        'NaN acceleration': set_(('points', 1, 'accelerations', 0, 'linear', 'x'),
                                 float('nan')),
        'NaN yaw rate': set_(('points', 0, 'velocities', 0, 'angular', 'z'), float('nan')),
        'NaN quaternion': set_(('points', 0, 'transforms', 0, 'rotation', 'w'), float('nan')),
    }
    for name, spoil in spoilers.items():
        m = msg()
        spoil(m)
        yield pytest.param(m, id=name)


@pytest.mark.parametrize('msg', list(_bad_com_messages()))
def test_a_bad_com_reference_is_refused_with_the_contract_readers_reason(msg):
    with pytest.raises(ContractError) as slow:
        com_reference_from_msg(msg)
    with pytest.raises(ContractError) as fast:
        com_track_from_msg(msg)
    assert str(fast.value) == str(slow.value)


# -- footstep plan: stance feet, swings, fallback ----------------------------------------------


@settings(max_examples=100, deadline=None)
@given(t_s=st.floats(-0.5, 3.5), height=st.sampled_from([0.0, 0.06, 0.3]),
       yaw_end=st.floats(-7.0, 7.0), seed=st.integers(0, 100))
def test_fallback_swing_is_the_numpy_formula_bit_for_bit(t_s, height, yaw_end, seed):
    from gait_nodes.contract import Swing

    rng = np.random.default_rng(seed)
    for lift_off, touch_down in ((1.0, 3.0), (1.5, 1.5)):  # and a zero-length swing
        swing = Swing('front_left', lift_off, touch_down, rng.uniform(-1, 1, 3),
                      rng.uniform(-1, 1, 3), float(rng.uniform(-3, 3)), yaw_end)
        position, yaw = fallback_swing_pose(swing, t_s, height)
        expected, expected_yaw = reference_fallback_pose(swing, t_s, height)
        assert same_floats(position, expected) and same_floats(yaw, expected_yaw)


def crawl_plan(robot_feet, rng):
    """A plan whose feet are in another order than the robot's, two swings per foot."""
    names = tuple(reversed(robot_feet))
    feet = rng.uniform(-1, 1, (len(names), 3))
    yaws = rng.uniform(-3, 3, len(names))
    times, positions, yaw_rows = [0.0], [feet.copy()], [yaws.copy()]
    t = 0.0
    for _ in range(2):
        for f in range(len(names)):
            t += 0.4
            times.append(t)  # contact change: foot f lifts off here ...
            positions.append(positions[-1].copy())
            yaw_rows.append(yaw_rows[-1].copy())
            t += 0.6 + 0.1 * f
            moved, turned = positions[-1].copy(), yaw_rows[-1].copy()
            moved[f] += rng.uniform(-0.2, 0.2, 3)
            turned[f] += rng.uniform(-4, 4)
            times.append(t)  # ... and lands here
            positions.append(moved)
            yaw_rows.append(turned)
    return FootstepPlan(2 * NS, names, np.array(times), np.array(positions), np.array(yaw_rows))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 1000), height=st.sampled_from([0.0, 0.06]))
def test_foot_targets_are_the_per_tick_numpy_path_bit_for_bit(seed, height):
    robot_feet = ('front_left', 'front_right', 'rear_left', 'rear_right')
    rng = np.random.default_rng(seed)
    plan = crawl_plan(robot_feet, rng)
    # Trajectories for some swings only, one of them shorter than its swing (the fallback
    # takes over when it ends) and one for a swing not under way (never used).
    trajectories = {}
    for swing in plan.swings()[::3]:
        duration = swing.duration_s * (0.6 if swing.foot == 'rear_left' else 1.0)
        waypoints = np.linspace(swing.start_in_world, swing.end_in_world, 4) + [0, 0, 0.05]
        trajectories[swing.foot] = SwingTrajectory(
            swing.foot, plan.start_ns + int(round(swing.lift_off_s * 1e9)),
            np.linspace(0.0, duration, 4), waypoints,
            np.linspace(swing.start_yaw_rad, swing.end_yaw_rad, 4))
    paths = [SwingPath(trajectories[name]) if name in trajectories else None
             for name in robot_feet]
    targets = FootTargets(plan, robot_feet)
    stamps = [plan.start_ns + int(round(t * 1e9)) for t in plan.times_s]  # contact changes
    stamps += [int(x) for x in rng.integers(0, 12 * NS, 60)]
    for stamp in stamps:
        feet, yaws, fallbacks = targets.at(stamp, paths, height)
        expected, expected_yaws, expected_fallbacks = reference_feet(
            plan, robot_feet, trajectories, stamp, height)
        assert same_floats(feet, expected) and same_floats(yaws, expected_yaws)
        assert fallbacks == expected_fallbacks


# -- joint velocity limit ----------------------------------------------------------------------


@settings(max_examples=50, deadline=None)
@given(scale=st.floats(0.0, 20.0), dt=st.floats(1e-4, 0.1), seed=st.integers(0, 1000))
def test_limit_joint_step_is_limit_joint_velocity_with_the_joint_vector(scale, dt, seed):
    robot = load_robot_model('robosimian')
    rng = np.random.default_rng(seed)
    q0 = robot.configuration([0, 0, 0.65], 0.0, rng.uniform(-1, 1, 28))
    q1 = robot.configuration([0.1, 0, 0.65], 0.3,
                             robot.joint_positions(q0) + rng.normal(size=28) * scale * dt)
    q, joints, velocities, saturation = limit_joint_step(robot, q0, robot.joint_positions(q0),
                                                         q1, dt)
    expected_q, expected_velocities, expected_saturation = limit_joint_velocity(robot, q0, q1,
                                                                                dt)
    assert same_floats(q, expected_q) and same_floats(velocities, expected_velocities)
    assert saturation == expected_saturation
    assert same_floats(joints, robot.joint_positions(q))
