"""Whole-body IK: core solver checked by independent FK, velocity limits, references, the node."""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes import runtime
from gait_nodes.contract import (
    ComState,
    FootstepPlan,
    Swing,
    SwingTrajectory,
    com_reference_to_msg,
    footsteps_to_msg,
    swing_trajectory_to_msg,
)
from gait_nodes.diagnostics import WARN, level_value
from gait_nodes.errors import ConfigError, ParameterError
from gait_nodes.interfaces import get_message
from gait_nodes.robot.description import example_robot_data_dir
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import (
    ComTrack,
    IkSettings,
    IkTargets,
    JointKnots,
    WholeBodyIkSolver,
    com_state_at,
    fallback_swing_pose,
    limit_joint_velocity,
    nominal_configuration,
    swing_pose_at,
)
from gait_nodes.runtime import Parameter, qos_profile_latched
from gait_nodes.whole_body_ik import node_defaults

NS = 1_000_000_000
#: The node's knot spacing (config/whole_body_ik.yaml) [ns].
KNOT_NS = round(node_defaults()['sample_period_s'] * NS)


def _example_robot_data_present() -> bool:
    try:
        example_robot_data_dir()
    except ConfigError:
        return False
    return True


ROBOTS = ['robosimian', 'biped'] + (['go2', 'solo12', 'talos']
                                    if _example_robot_data_present() else [])


def independent_errors(robot, q, targets):
    """Foot and COM errors of ``q`` by a fresh Pinocchio FK (no solver code involved)."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    feet = []
    orientations = []
    for k, frame in enumerate(robot.foot_frame_ids):
        placement = data.oMf[frame]
        contact = placement.translation - [0.0, 0.0, robot.foot_frame_height_m]
        feet.append(np.linalg.norm(contact - targets.feet_in_world[k]))
        level = placement.rotation @ robot.foot_rotation_offsets[k].T
        wanted = pin.rpy.rpyToMatrix(0.0, 0.0, targets.foot_yaws_rad[k])
        orientations.append(np.linalg.norm(pin.log3(wanted.T @ level)))
    com = pin.centerOfMass(model, data, q)
    return np.array(feet), np.array(orientations), np.linalg.norm(com - targets.com_in_world)


@pytest.fixture(scope='module', params=ROBOTS)
def setup(request):
    robot = load_robot_model(request.param)
    return robot, WholeBodyIkSolver(robot), nominal_configuration(robot)


def perturbed_targets(robot, q0, rng, com_shift_m=0.03, swing_m=0.06, yaw_rad=0.15):
    feet, yaws = robot.foot_poses(q0)
    com = robot.com(q0)
    swing = rng.integers(len(feet))
    feet[swing] += rng.uniform(-swing_m, swing_m, 3) * [1, 1, 0.5] + [0, 0, swing_m / 2]
    base_yaw = rng.uniform(-yaw_rad, yaw_rad)
    yaws = yaws + rng.uniform(-yaw_rad, yaw_rad, len(yaws))
    com = com + rng.uniform(-com_shift_m, com_shift_m, 3) * [1, 1, 0.3]
    return IkTargets(feet, yaws, base_yaw, com_in_world=com)


def test_feasible_targets_are_reached_by_independent_fk(setup):
    robot, solver, q0 = setup
    rng = np.random.default_rng(3)
    q = q0
    for _ in range(15):
        targets = perturbed_targets(robot, q0, rng)
        result = solver.solve(targets, q)
        assert result.converged, result
        feet, orientations, com = independent_errors(robot, result.q, targets)
        assert feet.max() <= 1e-4  # 0.1 mm, the accuracy
        assert com <= 1e-3
        if robot.foot_orientation == 'yaw':
            assert orientations.max() <= 1e-4
        joints = robot.joint_positions(result.q)
        assert np.all(robot.within_limits(joints))
        # Joints the IK does not move hold the posture.
        still = robot.indices([j for j in robot.joint_names if j not in robot.ik_joint_names])
        np.testing.assert_allclose(joints[still], robot.posture[still])
        # The body stays level with the commanded yaw.
        rotation = pin.Quaternion(result.q[3:7]).toRotationMatrix()
        np.testing.assert_allclose(rotation, pin.rpy.rpyToMatrix(0, 0, targets.base_yaw_rad),
                                   atol=1e-12)
        q = result.q


def test_unreachable_targets_give_best_effort_without_nan(setup):
    robot, solver, q0 = setup
    feet, yaws = robot.foot_poses(q0)
    feet[0] += [0.0, 0.0, 5.0]  # five metres up: out of reach
    targets = IkTargets(feet, yaws, 0.0, com_in_world=robot.com(q0))
    result = solver.solve(targets, q0)
    assert not result.converged
    assert np.all(np.isfinite(result.q))
    assert result.foot_position_errors_m[0] > 1.0
    joints = robot.joint_positions(result.q)
    assert np.all(robot.within_limits(joints))
    # The residual in the result is the real one.
    measured, _, com = independent_errors(robot, result.q, targets)
    np.testing.assert_allclose(measured, result.foot_position_errors_m, atol=1e-9)
    assert com == pytest.approx(result.com_error_m, abs=1e-9)


SOLED_ROBOTS = [name for name in ROBOTS if name not in ('go2', 'solo12')]  # not point feet


@pytest.mark.parametrize('name', SOLED_ROBOTS)
def test_large_sole_rotations_are_measured_like_an_independent_log3(name):
    """Sole errors beyond the small-angle shortcut (up to a half turn) are the true angles."""
    robot = load_robot_model(name)
    solver, q0 = WholeBodyIkSolver(robot), nominal_configuration(robot)
    assert robot.foot_orientation == 'yaw'
    feet, yaws = robot.foot_poses(q0)
    com = robot.com(q0)
    one_step = WholeBodyIkSolver(robot, IkSettings(max_iterations=1))
    for turn in (3e-5, 2e-4, 0.3, 1.5, 3.0, math.pi - 1e-3):
        targets = IkTargets(feet, yaws + turn * np.array([1, -1] * (len(yaws) // 2)
                                                         + [1] * (len(yaws) % 2)),
                            0.0, com_in_world=com)
        for result in (one_step.solve(targets, q0), solver.solve(targets, q0)):
            _, orientations, _ = independent_errors(robot, result.q, targets)
            np.testing.assert_allclose(result.foot_orientation_errors_rad, orientations,
                                       rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize('name', ['robosimian', 'biped'])
def test_error_map_is_the_per_foot_formulas(name):
    """The solver's one affine map of the placements against target - p and E = R_target R^T.

    Positions bit for bit; vee(E - E^T) / 2 and trace(E) to rounding; after one sole's yaw
    changes only its block is redone, and the map equals a fresh workspace's.
    """
    robot = load_robot_model(name)
    solver = WholeBodyIkSolver(robot)
    rng = np.random.default_rng(7)
    feet_count = len(robot.foot_frame_ids)
    work = solver._workspace(True)
    yaws = rng.uniform(-3.0, 3.0, feet_count).tolist()
    for changed in range(feet_count + 1):
        if changed < feet_count:
            yaws[changed] += 0.25
        targets = rng.uniform(-1.0, 1.0, (feet_count, 3))
        np.add(targets, solver._frame_offset, out=work.frame_targets)
        work.aim_soles(yaws, solver._offsets)
        fresh = WholeBodyIkSolver(robot)._workspace(True)
        fresh.aim_soles(yaws, solver._offsets)
        np.add(targets, solver._frame_offset, out=fresh.frame_targets)
        np.testing.assert_array_equal(work.error_map, fresh.error_map)
        for k in range(feet_count):
            rotation = pin.rpy.rpyToMatrix(*rng.uniform(-3.0, 3.0, 3))
            work.placements[k] = pin.SE3(rotation, rng.uniform(-1.0, 1.0, 3)).homogeneous
        np.dot(work.placements_flat, work.error_map, out=work.mapped)
        positions = work.placements[:, :3, 3]
        np.testing.assert_array_equal(work.per_foot[:, :3],
                                      targets + solver._frame_offset - positions)
        relative = np.array([pin.rpy.rpyToMatrix(0.0, 0.0, yaw) @ offset
                             for yaw, offset in zip(yaws, solver._offsets, strict=True)]) \
            @ work.placements[:, :3, :3].transpose(0, 2, 1)
        if work.rows_per_foot == 6:
            vees = 0.5 * np.stack([relative[:, 2, 1] - relative[:, 1, 2],
                                   relative[:, 0, 2] - relative[:, 2, 0],
                                   relative[:, 1, 0] - relative[:, 0, 1]], axis=1)
            np.testing.assert_allclose(work.per_foot[:, 3:], vees, rtol=0, atol=1e-15)
            np.testing.assert_allclose(work.traces, np.trace(relative, axis1=1, axis2=2),
                                       rtol=0, atol=1e-15)


def test_warm_start_reaches_a_smooth_walk_in_one_newton_step(setup):
    """Extrapolating the last solutions lands within one step of 1e-9 on a smooth walk."""
    robot, _, q0 = setup
    tight = IkSettings(position_tolerance_m=1e-9, orientation_tolerance_rad=1e-9,
                       com_tolerance_m=1e-9)
    solver = WholeBodyIkSolver(robot, tight)
    feet, yaws = robot.foot_poses(q0)
    com0 = robot.com(q0)
    size = robot.description.body_height_m
    solutions, iterations = [q0], []
    for k in range(120):  # 0.6 s at 200 Hz
        t = k / 200.0
        targets = IkTargets(feet, yaws, 0.0, com_in_world=com0 + 0.05 * size * np.array(
            [math.sin(2.0 * t), math.sin(3.0 * t), 0.2 * math.sin(2.5 * t)]))
        result = solver.solve(targets, solver.warm_start(solutions[-3:]))
        assert result.converged
        feet_errors, _, com_error = independent_errors(robot, result.q, targets)
        assert feet_errors.max() <= 2e-9 and com_error <= 2e-9
        solutions.append(result.q)
        iterations.append(result.iterations)
    assert max(iterations[3:]) <= 1


def test_warm_start_keeps_the_joints_within_their_limits():
    robot = load_robot_model('robosimian')
    solver = WholeBodyIkSolver(robot)
    q = nominal_configuration(robot)
    index = robot.indices(robot.ik_joint_names[:1])
    joints = robot.joint_positions(q)
    upper = robot.upper_limits[index][0]
    history = []
    for offset in (0.02, 0.01, 0.0):  # running into the limit at 0.01 per tick
        joints[index] = upper - offset
        history.append(robot.configuration(q[:3], 0.0, joints))
    start = solver.warm_start(history)
    assert robot.joint_positions(start)[index][0] == upper
    # The clip of q with infinite bounds off the IK joints is the clip of the IK joints.
    expected = 3.0 * (history[-1] - history[-2]) + history[-3]
    ik = robot.q_indices(robot.ik_joint_names)
    expected[ik] = np.clip(expected[ik], solver._lower, solver._upper)
    np.testing.assert_array_equal(start, expected)
    np.testing.assert_allclose(solver.warm_start(history[:2])[:3], q[:3])
    np.testing.assert_array_equal(solver.warm_start(history[:1]), history[0])


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), zeros=st.booleans())
def test_warm_start_is_the_plain_formula_bit_for_bit(seed, zeros):
    """The in-place extrapolation and the clip ufunc equal the plain numpy formula exactly.

    Joints pushed past their limits, onto them, infinite bounds off the IK joints, and signed
    zeros (a clip of -0.0 against a 0.0 bound must keep what maximum/minimum keep).
    """
    robot = load_robot_model('robosimian')
    solver = WholeBodyIkSolver(robot)
    rng = np.random.default_rng(seed)
    q = nominal_configuration(robot)
    history = [q + rng.normal(0.0, 0.3, q.shape) for _ in range(3)]
    if zeros:
        for k in range(len(q)):
            history[-1][k] = -0.0 if k % 2 else 0.0
        history[-2][:] = history[-1]
        history[-3][:] = -history[-1]
    for count in (3, 2):
        recent = history[-count:]
        line = 3.0 * (recent[-1] - recent[-2]) + recent[-3] if count == 3 \
            else 2.0 * recent[-1] - recent[-2]
        expected = np.minimum(np.maximum(line, solver._q_lower), solver._q_upper)
        assert solver.warm_start(recent).tobytes() == expected.tobytes()


def test_solver_workspace_views_are_the_rows_of_the_stacked_jacobian():
    """The per-foot and COM blocks the solver writes through are views of its ``full``."""
    robot = load_robot_model('robosimian')
    solver = WholeBodyIkSolver(robot)
    q = nominal_configuration(robot)
    solver.solve(IkTargets(robot.foot_poses(q)[0] + [0.0, 0.0, 0.01],
                           np.zeros(len(robot.foot_names)), com_in_world=robot.com(q)), q)
    work = solver._work[True]
    nv, rows = solver.model.nv, work.rows_per_foot
    for k, (view, frame) in enumerate(work.foot_blocks):
        assert frame == solver._frames[k]
        assert view.base is work.full and np.shares_memory(view, work.full[k * rows:, :nv])
        np.testing.assert_array_equal(view, work.full[k * rows:(k + 1) * rows, :nv])
    assert np.shares_memory(work.com_block, work.full[-3:, :nv])
    for k, (view, frame) in enumerate(work.foot_placements):
        assert frame == solver._frames[k] and np.shares_memory(view, work.placements[k])
    # A one-step solve leaves there Pinocchio's Jacobians at its start.
    solver.settings = IkSettings(max_iterations=1)
    feet = robot.foot_poses(q)[0] + [0.0, 0.0, 0.01]
    result = solver.solve(IkTargets(feet, np.zeros(len(feet)), com_in_world=robot.com(q)), q)
    assert result.iterations == 1
    data = robot.new_data()
    pin.forwardKinematics(solver.model, data, q)
    pin.centerOfMass(solver.model, data, pin.KinematicLevel.POSITION, False)
    pin.computeJointJacobians(solver.model, data)
    for view, frame in work.foot_blocks:
        np.testing.assert_array_equal(view, pin.getFrameJacobian(
            solver.model, data, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED))
    np.testing.assert_array_equal(work.com_block,
                                  pin.jacobianCenterOfMass(solver.model, data, False))


def test_warm_start_follows_the_real_tick_times():
    """Ticks late or early: the extrapolation follows their real times.

    Exact for motion quadratic in time, where the equal-spacing guess is off (its error would
    land in the redundant joints).
    """
    robot = load_robot_model('robosimian')
    solver = WholeBodyIkSolver(robot)
    q0 = nominal_configuration(robot)
    velocity, acceleration = np.full(len(q0), 0.05), np.full(len(q0), -0.2)
    velocity[3:7] = acceleration[3:7] = 0.0  # the base orientation stays put

    def q_at(t_s):
        return q0 + velocity * t_s + 0.5 * acceleration * t_s ** 2

    times = [-0.017, -0.005, 0.0]  # the middle tick 7 ms late, the last one 5 ms after it
    history = [q_at(t) for t in times]
    expected = q_at(0.005)
    np.testing.assert_allclose(solver.warm_start(history, times, 0.005), expected, atol=1e-12)
    assert np.abs(solver.warm_start(history) - expected).max() > 1e-4
    # Two solutions: the line through them.
    np.testing.assert_allclose(solver.warm_start(history[1:], times[1:], 0.005),
                               2.0 * history[2] - history[1], atol=1e-12)


def test_robosimian_stays_in_its_family_while_walking_the_body():
    robot = load_robot_model('robosimian')
    from gait_nodes.robot.limb_ik import RoboSimianLimbIk

    limb_ik = RoboSimianLimbIk(robot)
    # The walking family and another that holds every stance within the body's sway. The COM
    # sways as far as in the crawl (+-0.05 m along, +-0.03 m across: the body moves twice as
    # far, the limbs being 61.5 % of the mass).
    for family in (2, 5):
        solver = WholeBodyIkSolver(robot)
        q = nominal_configuration(robot, family)
        feet, yaws = robot.foot_poses(q)
        com0 = robot.com(q)
        for k in range(60):
            com = com0 + [0.05 * math.sin(0.05 * k), 0.03 * math.sin(0.07 * k), 0.0]
            result = solver.solve(IkTargets(feet, yaws, 0.0, com_in_world=com), q)
            assert result.converged
            q = result.q
            joints = robot.joint_positions(q)
            for foot in robot.description.feet:
                angles = joints[robot.indices(foot.joints)]
                assert limb_ik.family_of(angles[None], foot.name, 1e-5)[0] == family


def test_settings_are_validated():
    with pytest.raises(ParameterError, match=r'max_iterations must be an integer in \[1, 1000\]'):
        IkSettings(max_iterations=0)
    with pytest.raises(ParameterError, match='com_tolerance_m'):
        IkSettings(com_tolerance_m=1.0)
    with pytest.raises(ValueError, match='NaN'):
        IkTargets(np.full((4, 3), np.nan), np.zeros(4), 0.0, com_in_world=np.zeros(3))


@settings(max_examples=50, deadline=None)
@given(scale=st.floats(0.0, 20.0), dt=st.floats(1e-4, 0.1), seed=st.integers(0, 1000))
def test_velocity_limit_is_never_exceeded_and_saturation_is_reported(scale, dt, seed):
    robot = load_robot_model('robosimian')
    rng = np.random.default_rng(seed)
    q0 = robot.configuration([0, 0, 0.65], 0.0, rng.uniform(-1, 1, 28))
    step = rng.normal(size=28) * scale * dt
    q1 = robot.configuration([0.1, 0, 0.65], 0.0, robot.joint_positions(q0) + step)
    q, velocities, saturation = limit_joint_velocity(robot, q0, q1, dt)
    limits = robot.velocity_limits_rad_s
    assert np.all(np.abs(velocities) <= limits)
    moved = (robot.joint_positions(q) - robot.joint_positions(q0)) / dt
    assert np.all(np.abs(moved) <= limits * (1 + 1e-9))
    np.testing.assert_allclose(moved, velocities, atol=1e-9)
    demanded = np.abs(step) / dt / limits
    assert saturation.ratio == pytest.approx(demanded.max())
    assert set(saturation.joints) == {robot.joint_names[k] for k in np.flatnonzero(demanded > 1)}
    if saturation.saturated:
        # Same direction, scaled: the fastest joint exactly at its limit.
        assert np.abs(moved / limits).max() == pytest.approx(1.0)
        # (atol: the rounding of two positions, divided by dt and scaled back by the ratio)
        np.testing.assert_allclose(moved * saturation.ratio, step / dt, rtol=1e-9,
                                   atol=1e-14 * saturation.ratio / dt)
    else:
        np.testing.assert_allclose(q, q1)


def test_fallback_swing_lifts_and_lands_smoothly():
    swing = Swing('front_left', 1.0, 3.0, np.array([0.5, 0.5, 0.0]), np.array([0.8, 0.6, 0.02]),
                  0.0, 0.4)
    height = 0.06
    start, yaw0 = fallback_swing_pose(swing, 1.0, height)
    end, yaw1 = fallback_swing_pose(swing, 3.0, height)
    np.testing.assert_allclose(start, swing.start_in_world, atol=1e-12)
    np.testing.assert_allclose(end, swing.end_in_world, atol=1e-12)
    assert (yaw0, yaw1) == pytest.approx((0.0, 0.4))
    middle, _ = fallback_swing_pose(swing, 2.0, height)
    assert middle[2] == pytest.approx(0.01 + height)
    # At rest at lift-off and touch-down (finite differences), upward at first.
    h = 1e-5
    for t in (1.0, 3.0):
        before, _ = fallback_swing_pose(swing, t - h, height)
        after, _ = fallback_swing_pose(swing, t + h, height)
        assert np.linalg.norm(after - before) / (2 * h) < 1e-3
    early, _ = fallback_swing_pose(swing, 1.2, height)
    assert early[2] > 0.0 and abs(early[0] - 0.5) < early[2]


def test_com_reference_and_swing_sampling():
    states = [ComState(NS * k // 10, [0.1 * k, 0.0, 0.5], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0],
                       yaw_rad=0.1 * k, yaw_rate_rad_s=1.0) for k in range(3)]
    position, yaw = com_state_at(states, NS // 20)
    assert position == pytest.approx([0.05, 0.0, 0.5]) and yaw == pytest.approx(0.05)
    position, _ = com_state_at(states, NS * 3 // 10, max_extrapolation_s=0.05)
    assert position[0] == pytest.approx(0.2 + 0.05)  # extrapolated 50 ms at most
    swing = SwingTrajectory('rear_right', NS, np.array([0.0, 1.0]),
                            np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.1]]), np.array([3.0, -3.0]))
    position, yaw = swing_pose_at(swing, NS + NS // 2)
    assert position == pytest.approx([0.1, 0.0, 0.05])
    # Yaw interpolates the short way round (3 -> -3 rad crosses pi).
    assert abs(math.remainder(yaw - math.pi, 2 * math.pi)) < 1e-9


@settings(max_examples=60, deadline=None)
@given(times=st.lists(st.floats(0.0, 2.0), min_size=2, max_size=8),
       yaws=st.lists(st.floats(-10.0, 10.0), min_size=8, max_size=8),
       t_s=st.floats(-0.5, 2.5), seed=st.integers(0, 100))
def test_swing_sampling_is_linear_between_waypoints(times, yaws, t_s, seed):
    """Positions as np.interp; yaw as np.interp of the unwrapped yaws, modulo a turn."""
    times = np.sort(np.array(times) - min(times))
    positions = np.random.default_rng(seed).uniform(-1.0, 1.0, (len(times), 3))
    swing = SwingTrajectory('front_left', NS, times, positions, np.array(yaws[:len(times)]))
    position, yaw = swing_pose_at(swing, NS + int(round(t_s * 1e9)))
    t = int(round(t_s * 1e9)) * 1e-9
    if np.any((np.diff(times) == 0) & (times[1:] == t)):
        return  # np.interp picks either side of a zero-length segment
    expected = [np.interp(t, times, positions[:, i]) for i in range(3)]
    np.testing.assert_allclose(position, expected, atol=1e-12)
    wanted = np.interp(t, times, np.unwrap(swing.yaws_rad))
    assert abs(math.remainder(yaw - wanted, 2 * math.pi)) < 1e-9


def test_joint_knots_velocities_are_central_differences_within_the_steps():
    """Uneven spacing: the time-weighted mean of the two steps; the last backward or at rest."""
    knots = JointKnots(2)
    knots.restart(0, np.array([0.0, 1.0]))
    rng = np.random.default_rng(3)
    times, joints = [0], [np.array([0.0, 1.0])]
    for dt in (5, 5, 20, 5, 15):
        times.append(times[-1] + dt)
        joints.append(joints[-1] + rng.uniform(-1, 1, 2))
        knots.append(times[-1], joints[-1], (joints[-1] - joints[-2]) / dt)
        if len(knots) == 4:
            knots.drop_before(knots.first_at_or_before(times[-1]))  # one knot left
            assert len(knots) == 1
    window_times, positions, velocities = knots.window(0)
    assert window_times == times[3:]
    np.testing.assert_array_equal(positions, joints[3:])
    for k in range(1, len(window_times) - 1):
        j = k + 3
        central = (joints[j + 1] - joints[j - 1]) / (times[j + 1] - times[j - 1])
        np.testing.assert_allclose(velocities[k], central, rtol=1e-12)
    np.testing.assert_allclose(velocities[-1], (joints[-1] - joints[-2]) / 15, rtol=1e-12)
    assert knots.window(len(knots) - 1, ends_at_rest=True)[2] == [[0.0, 0.0]]
    # Dropped knots keep their velocities in the later ones: the first knot's is central.
    np.testing.assert_allclose(velocities[0], (joints[4] - joints[2]) / (times[4] - times[2]),
                               rtol=1e-12)
    restarted = JointKnots(2)
    restarted.restart(7, np.array([1.0, 2.0]))
    restarted.append(12, np.array([1.5, 2.0]), np.array([0.1, 0.0]))
    assert restarted.window(0)[2] == [[0.0, 0.0], [0.1, 0.0]]  # from rest


def test_com_track_first_change_is_where_a_later_window_departs_from_it():
    """A window repeating the held states changes nothing; one that departs does.

    It changes the track from the point before the first that differs.
    """
    def track(stamps, xs):
        return ComTrack(stamps, [[x, 0.0, 0.8] for x in xs], [[0.1, 0.0, 0.0]] * len(xs),
                        [0.0] * len(xs), [0.0] * len(xs), [[0.0] * 3] * len(xs))

    held = track([0, 20, 40, 60], [0.0, 0.002, 0.004, 0.006])
    assert held.first_change_ns(track([20, 40, 60, 80], [0.002, 0.004, 0.006, 0.008]),
                                1e-9) is None
    assert held.first_change_ns(track([20, 40, 60, 80], [0.002, 0.004, 0.0065, 0.008]),
                                1e-9) == 40
    assert held.first_change_ns(track([40, 60], [0.005, 0.006]), 1e-9) == 40
    # Between the held points: compared with the held track's interpolation there.
    assert held.first_change_ns(track([30, 70], [*held.at(30)[0][:1], 0.009]), 1e-9) is None
    assert held.first_change_ns(track([30, 50], [0.0031, 0.005]), 1e-9) == 30


def test_joint_knots_truncate_after_gives_back_the_state_to_solve_on_from():
    """Knots after a stamp are forgotten (never the first); the last kept one steps backward."""
    knots = JointKnots(1)
    knots.restart(0, np.array([0.0]), 'start')
    for k in range(1, 5):
        knots.append(10 * k, np.array([float(k * k)]), np.array([(2 * k - 1) / 10]), k)
    assert knots.truncate_after(25) == 2
    assert knots.times_ns == [0, 10, 20]
    assert knots.window(0)[2][-1] == [0.3]  # the backward step into the knot at 20
    knots.append(30, np.array([5.0]), np.array([0.1]), 'again')
    np.testing.assert_allclose(knots.window(0)[2][2], [0.2])  # central again: (0.3 + 0.1) / 2
    assert knots.truncate_after(-5) == 'start' and knots.times_ns == [0]
    assert knots.truncate_after(100) == 'start'


# -- the node in the inproc runtime ------------------------------------------------------------


@pytest.fixture
def inproc():
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    yield
    runtime.shutdown()


class Collector(runtime.Node):
    """Keeps /joint_commands and /diagnostics."""

    def __init__(self):
        super().__init__('collector')
        self.commands, self.statuses = [], []
        self.published_ns = []  # when each /joint_commands came (delivery is instant inproc)
        self.create_subscription(get_message('trajectory_msgs/msg/JointTrajectory'),
                                 '/joint_commands', self._on_command, 100)
        self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics',
                                 lambda msg: self.statuses.extend(msg.status), 100)

    def _on_command(self, msg):
        self.commands.append(msg)
        self.published_ns.append(self.get_clock().now().nanoseconds)

    def status(self, aspect):
        """Statuses received for ``aspect``."""
        return [s for s in self.statuses if s.name.endswith(f': {aspect}')]


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * NS + msg.header.stamp.nanosec


def knot_times_ns(msg) -> list[int]:
    """Absolute times [ns] of a JointTrajectory's points."""
    start = stamp_ns(msg)
    return [start + p.time_from_start.sec * NS + p.time_from_start.nanosec for p in msg.points]


def check_controller_rules(msg, robot) -> None:
    """What a ros2_control joint_trajectory_controller checks, and our own rules on top.

    Joint names: the robot's, each once; ``time_from_start`` >= 0 and strictly increasing
    (the first 0: the header stamp is the first point's time); positions and velocities one
    finite value per joint, velocities within the robot's limits; no accelerations, no efforts.
    """
    names = list(msg.joint_names)
    assert names and len(set(names)) == len(names) and names == list(robot.joint_names)
    assert msg.header.frame_id == '' and msg.points
    offsets = [p.time_from_start.sec * NS + p.time_from_start.nanosec for p in msg.points]
    assert offsets[0] == 0 and all(b > a for a, b in zip(offsets[:-1], offsets[1:], strict=True))
    assert all(0 <= p.time_from_start.nanosec < NS for p in msg.points)
    limits = robot.velocity_limits_rad_s
    for point in msg.points:
        positions, velocities = np.array(point.positions), np.array(point.velocities)
        assert positions.shape == velocities.shape == (len(names),)
        assert np.all(np.isfinite(positions)) and np.all(np.isfinite(velocities))
        assert np.all(np.abs(velocities) <= limits)
        assert len(point.accelerations) == 0 and len(point.effort) == 0


def knots_of(commands, published_ns=None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Knot time [ns] -> (positions, velocities) over every message, the latest message's.

    A knot sent in several messages has the same positions in each (it is solved once). With
    the messages' publication instants ``published_ns``, only the knots at or before the
    instant must not have changed: later ones are solved again when their references change.
    """
    knots = {}
    for k, msg in enumerate(commands):
        for t, point in zip(knot_times_ns(msg), msg.points, strict=True):
            positions = np.array(point.positions)
            if t in knots and (published_ns is None or t <= published_ns[k]):
                assert np.array_equal(knots[t][0], positions)
            knots[t] = positions, np.array(point.velocities)
    return dict(sorted(knots.items()))


class CrawlSource(runtime.Node):
    """A synthetic gait: footstep plan (latched), COM reference, one swing message.

    The COM reference comes every ``publish_period_s`` with a horizon of ``horizon_s``, points
    ``sample_period_s`` apart from now on (the com_preview_controller's defaults); it stops at
    ``silent_from_ns`` for ``silent_for_s``.
    """

    def __init__(self, robot, q0, com_amplitude_m=0.03, com_period_s=4.0, nan_at_ns=None,
                 publish_period_s=0.05, horizon_s=0.5, sample_period_s=0.02,
                 silent_from_ns=None, silent_for_s=0.0, swing_lead_s=1.0):
        super().__init__('crawl_source')
        self.swing_lead_ns = int(round(swing_lead_s * NS))
        self.horizon_times_ns = [int(round(k * sample_period_s * NS))
                                 for k in range(int(round(horizon_s / sample_period_s)) + 1)]
        self.silent = (silent_from_ns, None if silent_from_ns is None
                       else silent_from_ns + int(silent_for_s * NS))
        self.period = com_period_s
        self.feet0, _ = robot.foot_poses(q0)
        self.com0 = robot.com(q0)
        self.amplitude = com_amplitude_m
        self.nan_at_ns = nan_at_ns
        names = robot.foot_names
        positions = [self.feet0.copy()]
        for foot in ('front_left', 'rear_right'):
            moved = positions[-1].copy()
            moved[names.index(foot)] += [0.1, 0.0, 0.0]
            positions += [positions[-1], moved]
        self.plan = FootstepPlan(NS // 2, names, np.array([0.0, 1.0, 3.0, 4.0, 6.0]),
                                 np.array(positions), np.zeros((5, len(names))))
        trajectory = runtime.Node.create_publisher(
            self, get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/footsteps',
            qos_profile_latched)
        trajectory.publish(footsteps_to_msg(self.plan))
        self.com_publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/com_reference', 10)
        self.swing_publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/swing_trajectory',
            10)
        start = self.feet0[names.index('rear_right')]
        end = start + [0.1, 0.0, 0.0]
        self.swing = SwingTrajectory(
            'rear_right', self.plan.start_ns + 4 * NS, np.array([0.0, 0.5, 1.5, 2.0]),
            np.array([start, start + [0, 0, 0.05], end + [0, 0, 0.05], end]), np.zeros(4))
        self.create_timer(publish_period_s, self.tick)
        self.sent_swing = False

    def com_at(self, t_ns: int) -> np.ndarray:
        """COM reference at ``t_ns``: slow forward drift and a lateral sway."""
        t = t_ns * 1e-9
        sway = self.amplitude * math.sin(2 * math.pi * t / self.period)
        return self.com0 + [0.01 * t, sway, 0.0]

    def com_velocity_at(self, t_ns: int) -> np.ndarray:
        """Derivative of :meth:`com_at` [m/s]."""
        omega = 2 * math.pi / self.period
        return np.array([0.01, self.amplitude * omega * math.cos(omega * t_ns * 1e-9), 0.0])

    def tick(self):
        """Publish the COM reference from now on, and the swing trajectory one second early."""
        now = self.get_clock().now().nanoseconds
        start, end = self.silent
        if start is not None and start <= now < end:
            return
        msg = com_reference_to_msg([ComState(now + dt, self.com_at(now + dt),
                                             self.com_velocity_at(now + dt), np.zeros(3))
                                    for dt in self.horizon_times_ns])
        if self.nan_at_ns is not None and now == self.nan_at_ns:
            msg.points[0].transforms[0].translation.x = float('nan')
        self.com_publisher.publish(msg)
        if not self.sent_swing and now >= self.swing.start_ns - self.swing_lead_ns:
            self.swing_publisher.publish(swing_trajectory_to_msg(self.swing))
            self.sent_swing = True


def walking_target_error(robot, q, com):
    """How far ``q`` is from the node's COM target: the horizontal COM and the base's height.

    The node's IK holds the body at ``com_z + body_height_m - com_height_m`` (IkSettings
    vertical 'base', the walk's): the COM's own height moves with the limbs.
    """
    description = robot.description
    horizontal = robot.com(q)[:2] - np.asarray(com)[:2]
    height = q[2] - (com[2] + description.body_height_m - description.com_height_m)
    return float(np.hypot(np.linalg.norm(horizontal), height))


def base_from_stance(robot, joints, stance_targets, stance):
    """Base position that best puts the stance feet on their targets with these joints."""
    q = robot.configuration(np.zeros(3), 0.0, joints)
    in_base = robot.feet_in_base(q)
    return np.mean(stance_targets[stance] - in_base[stance], axis=0)


def run_node(seconds, **source_kwargs):
    from gait_nodes.whole_body_ik import WholeBodyIk

    node = WholeBodyIk()
    source = CrawlSource(node.robot, node.q_nominal, **source_kwargs)
    collector = Collector()
    executor = runtime.SingleThreadedExecutor()
    for n in (node, source, collector):
        executor.add_node(n)
    executor.spin_for(seconds)
    return node, source, collector


def test_node_tracks_the_contract_references_checked_by_fk(inproc):
    """Every knot of the trajectories puts the feet and the COM on the references at its time.

    The messages keep ros2_control's rules; each knot is solved once (the same positions in
    every message that carries it), on a 5 ms grid, and reached from the one before within the
    joint velocity limits.
    """
    node, source, collector = run_node(7.0)
    robot = node.robot
    assert len(collector.commands) == pytest.approx(7.0 * 20, abs=1)
    plan = source.plan
    limits = robot.velocity_limits_rad_s
    for msg in collector.commands:
        check_controller_rules(msg, robot)
        # From the latest knot at or before the present (the message's publication time)
        # to about horizon_s ahead.
        times = knot_times_ns(msg)
        assert times[-1] - times[0] >= 0.3 * NS - KNOT_NS or times[0] < plan.start_ns
    # (The first message holds the nominal stance: it comes before the references.)
    assert len(collector.commands[0].points) == 1
    knots = knots_of(collector.commands[1:])
    times = np.array(list(knots))
    assert np.all(np.diff(times) == KNOT_NS)
    positions = np.array([p for p, _ in knots.values()])
    steps = np.abs(np.diff(positions, axis=0)) / (KNOT_NS / NS)
    assert np.all(steps <= limits * (1 + 1e-9))
    checked_swings = {'front_left': 0, 'rear_right': 0}
    for now, (joints, _) in knots.items():
        t_plan = (now - plan.start_ns) * 1e-9
        if t_plan < 0.05:
            continue
        stance = plan.contacts_at(t_plan)
        targets = np.array(plan.stance_positions_at(t_plan))
        base = base_from_stance(robot, joints, targets, stance)
        q = robot.configuration(base, 0.0, joints)
        feet, _ = robot.foot_poses(q)
        # Stance feet where the plan holds them, COM on the reference (0.1 mm, 1 mm).
        assert np.abs(feet[stance] - targets[stance]).max() <= 1e-4
        assert walking_target_error(robot, q, source.com_at(now)) <= 1e-3
        for k in np.flatnonzero(~stance):
            name = robot.foot_names[k]
            if name == 'rear_right':
                expected, _ = swing_pose_at(source.swing, now)
            else:
                swing = [s for s in plan.swings() if s.foot == name][0]
                expected, _ = fallback_swing_pose(swing, t_plan, 0.06)
            assert np.linalg.norm(feet[k] - expected) <= 1e-4
            checked_swings[name] += 1
    assert min(checked_swings.values()) > 1.5 * NS // KNOT_NS  # (swings of 2 s)
    tracking = collector.status('tracking')
    assert tracking and all(level_value(s.level) == 0 for s in tracking)
    inputs = collector.status('inputs')
    values = {kv.key: kv.value for kv in inputs[-1].values}
    assert int(values['fallback_swing_ticks']) == 0  # last second: no swing in progress
    assert any(int({kv.key: kv.value for kv in s.values}['fallback_swing_ticks']) > 0
               for s in inputs)


def test_a_swing_trajectory_after_its_lift_off_leaves_the_foot_on_the_fallback_swing(inproc):
    # The rear right swing (4-6 s) lifts off on the fallback swing; its trajectory comes 0.5 s
    # later. Switched to it then, the foot would jump 2-3 cm (joints at many times their
    # limit): it lands on the fallback, and the dropped trajectory is reported.
    node, source, collector = run_node(7.0, swing_lead_s=-0.5)
    robot, plan = node.robot, source.plan
    swing = [s for s in plan.swings() if s.foot == 'rear_right'][0]
    k = robot.foot_names.index('rear_right')
    knots = knots_of(collector.commands[1:])
    checked = 0
    for now, (joints, _) in knots.items():
        t_plan = (now - plan.start_ns) * 1e-9
        if not swing.lift_off_s < t_plan < swing.touch_down_s:
            continue
        stance = plan.contacts_at(t_plan)
        base = base_from_stance(robot, joints, np.array(plan.stance_positions_at(t_plan)),
                                stance)
        feet, _ = robot.foot_poses(robot.configuration(base, 0.0, joints))
        expected, _ = fallback_swing_pose(swing, t_plan, 0.06)
        assert np.linalg.norm(feet[k] - expected) <= 1e-4, t_plan
        checked += 1
    assert checked > 1.5 * NS // KNOT_NS
    late = [int({kv.key: kv.value for kv in s.values}['late_swing_trajectories'])
            for s in collector.status('inputs')]
    assert sum(late) == 1
    # (The first second's window holds the start from the nominal posture.)
    saturation = collector.status('velocity saturation')[1:]
    assert len(saturation) >= 5
    assert all(level_value(s.level) == 0 for s in saturation), [s.message for s in saturation]


class RevisedSource(CrawlSource):
    """A crawl source whose COM windows change the future from ``revised_at_ns`` on.

    From then, the COM reference after ``revised_at_ns + 0.1 s`` moves 5 mm forward (smoothly,
    over 0.2 s): the knots the IK has already solved up to its horizon are out of date.
    """

    revised_at_ns = 3 * NS

    def com_at(self, t_ns: int) -> np.ndarray:
        """The crawl source's COM, moved forward from ``revised_at_ns`` on."""
        com = super().com_at(t_ns)
        if self.get_clock().now().nanoseconds >= self.revised_at_ns:
            s_ = (t_ns - self.revised_at_ns - NS // 10) / (0.2 * NS)
            com = com + [0.005 * _smoothstep_of(s_), 0.0, 0.0]
        return com


def _smoothstep_of(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def test_node_solves_again_the_knots_a_revised_com_window_changes(inproc):
    """Knots ahead of now follow the revised COM reference; knots whose instant came stay."""
    from gait_nodes.whole_body_ik import WholeBodyIk

    node = WholeBodyIk()
    source = RevisedSource(node.robot, node.q_nominal)
    collector = Collector()
    executor = runtime.SingleThreadedExecutor()
    for n in (node, source, collector):
        executor.add_node(n)
    executor.spin_for(4.0)
    robot, plan = node.robot, source.plan
    knots = knots_of(collector.commands, collector.published_ns)
    revised = [t for t in knots if source.revised_at_ns + NS // 10 <= t <= 3.6 * NS]
    assert len(revised) > 50
    for t in revised:
        joints = knots[t][0]
        t_plan = (t - plan.start_ns) * 1e-9
        stance = plan.contacts_at(t_plan)
        targets = np.array(plan.stance_positions_at(t_plan))
        q = robot.configuration(base_from_stance(robot, joints, targets, stance), 0.0, joints)
        assert walking_target_error(robot, q, source.com_at(t)) <= 1e-3
        # The revision (up to 5 mm) is in the knots, not only within the tolerance.
    late = max(revised)
    assert abs(robot.com(robot.configuration(
        base_from_stance(robot, knots[late][0], np.array(plan.stance_positions_at(
            (late - plan.start_ns) * 1e-9)), plan.contacts_at((late - plan.start_ns) * 1e-9)),
        0.0, knots[late][0]))[0] - (source.com_at(late)[0])) <= 2e-4


def test_knot_velocities_are_the_derivative_of_the_knots(inproc):
    """Central differences of the knots (the last one of a message at rest), as sent.

    (The first message holds the posture before the references; the first knot of the motion
    starts from rest.)
    """
    node, _, collector = run_node(3.0)
    knots = knots_of(collector.commands[1:-1])
    times = np.array(list(knots)) * 1e-9
    positions = np.array([p for p, _ in knots.values()])
    velocities = np.array([v for _, v in knots.values()])
    central = (positions[2:] - positions[:-2]) / (times[2:] - times[:-2])[:, None]
    np.testing.assert_allclose(velocities[1:-1], central, rtol=1e-9, atol=1e-12)
    # Every window ends at rest (a consumer hearing nothing more stops there).
    assert all(not any(msg.points[-1].velocities) for msg in collector.commands)


def test_node_holds_the_last_knot_on_a_stale_reference_and_walks_on(inproc):
    """COM reference silent for 1 s: the trajectory ends, the last knot is held, then resumes."""
    silent_from = 2 * NS
    node, source, collector = run_node(4.5, silent_from_ns=silent_from, silent_for_s=1.0)
    robot = node.robot
    for msg in collector.commands:
        check_controller_rules(msg, robot)
    last_heard = silent_from - 50_000_000
    sent = [(stamp_ns(m), m) for m in collector.commands]
    # The reference covers 0.5 s past its last message: knots go no further.
    assert max(t for m in collector.commands for t in knot_times_ns(m)
               if stamp_ns(m) < silent_from + NS) <= last_heard + NS // 2
    held = [m for t, m in sent if len(m.points) == 1 and silent_from <= t < silent_from + NS]
    assert held, 'no one-point trajectory while the reference was stale'
    for msg in held:
        np.testing.assert_array_equal(msg.points[0].velocities, 0.0)
        np.testing.assert_array_equal(msg.points[0].positions, held[0].points[0].positions)
    statuses = [level_value(s.level) for s in collector.status('inputs')]
    assert WARN in statuses and statuses[-1] == 0
    # Walking on: from the held posture, within the limits, on the references again.
    after = [m for m in collector.commands if knot_times_ns(m)[0] >= silent_from + NS + NS // 5]
    assert after and all(len(m.points) > 10 for m in after)
    knots = knots_of(collector.commands)
    times = np.array(list(knots))
    positions = np.array([p for p, _ in knots.values()])
    steps = np.abs(np.diff(positions, axis=0)) / (np.diff(times) * 1e-9)[:, None]
    assert np.all(steps <= robot.velocity_limits_rad_s * (1 + 1e-9))


def test_node_stops_hearing_the_robot_once_it_moves(inproc):
    """/joint_states and /tf, which only seed the posture held before motion, are dropped.

    Kept while the node holds a posture, dropped at its first solved tick.
    """
    from gait_nodes.whole_body_ik import WholeBodyIk

    robot_topics = {'/joint_states', '/tf'}
    waiting = WholeBodyIk()
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(waiting)
    executor.spin_for(0.1)
    assert robot_topics <= {s.topic_name for s in waiting.subscriptions}
    waiting.destroy_node()
    node, _, collector = run_node(0.6)  # the plan starts at 0.5 s; references from the start
    assert node._moving
    topics = {s.topic_name for s in node.subscriptions}
    assert not robot_topics & topics
    assert {'/gait/com_reference', '/gait/footsteps', '/gait/swing_trajectory'} <= topics
    assert len(collector.commands) == 12


def test_node_holds_the_nominal_stance_before_the_references(inproc):
    from gait_nodes.whole_body_ik import WholeBodyIk

    node = WholeBodyIk()
    collector = Collector()
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    executor.add_node(collector)
    executor.spin_for(1.5)
    nominal = node.robot.joint_positions(node.q_nominal)
    assert len(collector.commands) == 30
    for msg in collector.commands:
        check_controller_rules(msg, node.robot)
        # One point, now, at rest.
        [point] = msg.points
        np.testing.assert_allclose(point.positions, nominal)
        np.testing.assert_allclose(point.velocities, 0.0)
    statuses = collector.status('inputs')
    assert all('waiting for /gait/com_reference, /gait/footsteps' in status.message
               for status in statuses)
    # Nothing has come for longer than stale_timeout_s: reported at once and in the summary.
    assert [level_value(s.level) for s in statuses] == [WARN, WARN]
    assert 'nothing received on /gait/com_reference' in statuses[0].message


def test_node_rides_through_a_late_reference(inproc):
    """COM reference late but not stale: the trajectory ends at rest, then goes on from there.

    A 0.2 s horizon, silent 0.3 s: the reference ends 0.15 s before the next message comes.
    """
    silent_from = 2 * NS
    node, _, collector = run_node(3.5, silent_from_ns=silent_from, silent_for_s=0.3,
                                  horizon_s=0.2)
    robot = node.robot
    for msg in collector.commands:
        check_controller_rules(msg, robot)
    assert node.faults.failures == 0 and not collector.status('faults')
    assert all(level_value(s.level) == 0 for s in collector.status('inputs')[1:])
    ended = [m for m in collector.commands if len(m.points) == 1
             and silent_from < stamp_ns(m) < silent_from + 3 * NS // 10]
    assert ended and all(np.all(np.array(m.points[0].velocities) == 0.0) for m in ended)
    knots = knots_of(collector.commands[1:])
    times = np.array(list(knots))
    assert times.max() <= silent_from - 50_000_000 + NS // 5 or times.max() >= 3.5 * NS
    gaps = np.diff(times)
    assert gaps.max() > 5_000_000 and np.all(gaps % 5_000_000 == 0)  # the grid, past skipped
    positions = np.array([p for p, _ in knots.values()])
    # The robot held the last knot: the trajectory starts again there, at rest.
    gap = int(np.argmax(gaps))
    np.testing.assert_array_equal(positions[gap + 1], positions[gap])
    np.testing.assert_array_equal(knots[times[gap + 1]][1], 0.0)
    steps = np.abs(np.diff(positions, axis=0)) / (gaps * 1e-9)[:, None]
    assert np.all(steps <= robot.velocity_limits_rad_s * (1 + 1e-9))
    assert times[-1] >= 3.5 * NS


def test_a_starved_node_starts_again_at_rest_where_its_trajectory_ended(inproc):
    """The IK's timer stopped 0.5 s: its trajectory (0.3 s ahead) ran out and was held.

    The next message starts at the last knot, at rest, at the latest grid point at or before
    the present; no knot in the past is solved; then the knots catch up within the limits.
    """
    from gait_nodes.whole_body_ik import WholeBodyIk

    node = WholeBodyIk()
    source = CrawlSource(node.robot, node.q_nominal)
    collector = Collector()
    executor = runtime.SingleThreadedExecutor()
    for n in (node, source, collector):
        executor.add_node(n)
    executor.spin_for(2.0)
    node.timer.cancel()
    before = len(collector.commands)
    last_knot_ns = knot_times_ns(collector.commands[-1])[-1]
    executor.spin_for(0.5)
    assert len(collector.commands) == before
    node.timer = node.create_timer(0.05, node.tick)
    executor.spin_for(1.0)
    resumed = collector.commands[before]
    back = node.get_clock().now().nanoseconds - NS  # the timer is back (its tick 50 ms on)
    times = knot_times_ns(resumed)
    assert times[0] > last_knot_ns and times[0] <= back + 50_000_000 < times[1]
    assert (times[0] - last_knot_ns) % 5_000_000 == 0
    np.testing.assert_array_equal(resumed.points[0].positions,
                                  collector.commands[before - 1].points[-1].positions)
    np.testing.assert_array_equal(resumed.points[0].velocities, 0.0)
    for msg in collector.commands:
        check_controller_rules(msg, node.robot)
    knots = knots_of(collector.commands[1:])
    knot_times = np.array(list(knots))
    positions = np.array([p for p, _ in knots.values()])
    steps = np.abs(np.diff(positions, axis=0)) / (np.diff(knot_times) * 1e-9)[:, None]
    assert np.all(steps <= node.robot.velocity_limits_rad_s * (1 + 1e-9))


def test_node_saturates_a_fast_reference_and_reports_the_joints(inproc):
    node, source, collector = run_node(2.0, com_amplitude_m=0.1, com_period_s=0.5)
    for msg in collector.commands:
        check_controller_rules(msg, node.robot)
    saturation = collector.status('velocity saturation')
    assert any(level_value(s.level) == WARN for s in saturation)
    warned = [s for s in saturation if level_value(s.level) == WARN][0]
    values = {kv.key: kv.value for kv in warned.values}
    assert float(values['max_demanded_over_limit']) > 1.0
    assert 0.0 < float(values['saturated_fraction']) <= 1.0
    assert values['joints'] and all(j in node.robot.joint_names
                                    for j in values['joints'].split(','))


def test_node_drops_nan_input_and_keeps_going(inproc):
    nan_at = 2 * NS
    node, source, collector = run_node(2.5, nan_at_ns=nan_at)
    drops = collector.status('input /gait/com_reference')
    assert len(drops) == 1 and 'NaN' in drops[0].message
    assert node.diagnostics.dropped == {'/gait/com_reference': 1}
    # The trajectory goes on through the dropped message: knots every KNOT_NS around it.
    for msg in collector.commands:
        check_controller_rules(msg, node.robot)
    times = np.array(list(knots_of(collector.commands)))
    assert np.all(np.diff(times[(times > nan_at - NS // 2) & (times < nan_at + NS // 2)])
                  == KNOT_NS)


def test_node_parameters_are_validated_and_a_rejected_change_changes_nothing(inproc):
    from gait_nodes.whole_body_ik import WholeBodyIk

    node = WholeBodyIk()
    before = node.params
    for name, value in (('rate_hz', -5.0), ('ik_family', 9), ('robot', 'biped'),
                        ('fallback_step_height_m', 2.0), ('sample_period_s', 0.0),
                        ('horizon_s', -0.1), ('horizon_s', float('nan'))):
        [result] = node.set_parameters([Parameter(name, value=value)])
        assert not result.successful
        assert name in result.reason or 'robot' in result.reason
        assert node.params == before
    [result] = node.set_parameters([Parameter('ik_family', value=7)])
    assert result.successful and node.params.ik_family == 7
    [result] = node.set_parameters([Parameter('rate_hz', value=100.0)])
    assert result.successful
    assert node.timer.timer_period_ns == 10_000_000
    results = node.set_parameters([Parameter('sample_period_s', value=0.01),
                                   Parameter('horizon_s', value=0.5)])
    assert all(result.successful for result in results)
    assert (node.params.sample_period_s, node.params.horizon_s) == (0.01, 0.5)


def test_node_refuses_an_ik_family_for_a_robot_without_limb_ik():
    runtime.init(args=['--ros-args', '-p', 'robot:=biped', '-p', 'ik_family:=3'],
                 runtime='inproc', signal_handlers=False)
    try:
        from gait_nodes.whole_body_ik import WholeBodyIk

        with pytest.raises(ParameterError, match='closed-form limb IK'):
            WholeBodyIk()
    finally:
        runtime.shutdown()


@pytest.mark.parametrize('scenario_name', ['robosimian_crawl', 'biped_walk'])
def test_joint_commands_of_an_inproc_walk_keep_the_controller_rules(scenario_name, tmp_path):
    """The whole inproc graph walking a scenario: every /joint_commands a JTC would take.

    No knot changes once its instant has come (later ones are solved again when the plan
    changes them), knots on
    the 5 ms grid, each step within the velocity limits; a message starts at the latest knot
    at or before its publication and reaches ahead no further than horizon_s. (How far ahead
    depends on the COM reference's horizon: with one state per message, the knots end where
    it ends, at or before the present.)
    """
    import yaml

    from gait_nodes import graph
    from gait_nodes.scenarios import CommandDriver, get_scenario

    scenario = get_scenario(scenario_name)
    params_file = tmp_path / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'robot': scenario.robot, **scenario.settings}}}))
    runtime.init(args=['test', '--ros-args', '--params-file', str(params_file)],
                 runtime='inproc', signal_handlers=False)
    try:
        nodes = [graph.load_class(graph.NODES[name])() for name in graph.available_nodes()]
        [ik] = [node for node in nodes if node.get_name() == 'whole_body_ik']
        driver_node = runtime.Node('driver', use_global_arguments=False)
        driver = CommandDriver(driver_node, scenario.commands)
        collector = Collector()
        executor = runtime.SingleThreadedExecutor()
        for node in [*nodes, driver_node, collector]:
            executor.add_node(node)
        driver.start()
        executor.spin_for(8.0)
        robot = ik.robot
    finally:
        runtime.shutdown()
    commands = collector.commands
    assert len(commands) == pytest.approx(8.0 * 20, abs=1)
    published_ns = collector.published_ns
    for msg, now in zip(commands, published_ns, strict=True):
        check_controller_rules(msg, robot)
        times = knot_times_ns(msg)
        assert times[0] <= now and times[-1] <= now + 0.3 * NS
        assert len(times) == 1 or times[1] > now
    assert ik._moving
    # (the posture held before motion: at publications, 50 ms)
    knots = knots_of(commands, published_ns)
    times = np.array(list(knots))
    assert np.all(np.diff(times) % 5_000_000 == 0)
    positions = np.array([p for p, _ in knots.values()])
    steps = np.abs(np.diff(positions, axis=0)) / (np.diff(times) * 1e-9)[:, None]
    assert np.all(steps <= robot.velocity_limits_rad_s * (1 + 1e-9))
    assert not [s for s in collector.statuses if s.name.startswith('whole_body_ik')
                and level_value(s.level) >= 2]


def test_bag_analysis_reads_joint_commands_as_the_trajectory_followed():
    """The bag analysis of /joint_commands: a message replaces the rest from its first point."""
    from gait_nodes.bag.analysis import _Collector, joint_metrics
    from gait_nodes.contract import joint_trajectory_to_msg
    from gait_nodes.interfaces import serialize_message

    names = ['a', 'b']
    first = joint_trajectory_to_msg(names, [NS, NS + 10, NS + 20, NS + 30],
                                    [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]],
                                    [[0.0, 0.0], [0.5, 0.0], [0.5, 0.0], [4.0, 0.0]])
    second = joint_trajectory_to_msg(names, [NS + 20, NS + 25], [[2.0, 1.0], [2.5, 1.0]],
                                     [[0.1, 0.2], [0.1, 0.3]])
    collector = _Collector()
    for msg in (first, second):
        collector.message('/joint_commands', 'trajectory_msgs/msg/JointTrajectory',
                          serialize_message(msg))
    series = collector.series.joints['/joint_commands']
    assert series.names == names
    assert series.stamps_ns == [NS, NS + 10, NS + 20, NS + 25]
    assert series.positions == [[0.0, 0.0], [1.0, 0.0], [2.0, 1.0], [2.5, 1.0]]
    # The replaced point's 4 rad/s was never followed.
    metrics = joint_metrics(collector.series, lambda joint: 1.0)['/joint_commands']
    assert metrics['peak_rad_s'] == 0.5 and metrics['samples'] == 4


def test_a_step_is_kept_within_a_share_of_the_limits_and_saturates_only_above_them():
    robot = load_robot_model('robosimian')
    q0 = robot.configuration([0, 0, 0.65], 0.0, np.zeros(28))
    dt = 0.01
    limit = robot.velocity_limits_rad_s[0]
    for demanded, saturated in ((0.998, False), (1.2, True)):
        joints = np.zeros(28)
        joints[0] = demanded * limit * dt
        q1 = robot.configuration([0.001, 0, 0.65], 0.0, joints)
        q, velocities, saturation = limit_joint_velocity(robot, q0, q1, dt, share=0.995)
        assert saturation.ratio == pytest.approx(demanded)
        assert saturation.scaled and saturation.saturated is saturated
        assert saturation.joints == ((robot.joint_names[0],) if saturated else ())
        assert abs(velocities[0]) / limit == pytest.approx(0.995)
        # The whole step scaled alike, the base too.
        assert q[0] == pytest.approx(0.001 * 0.995 / demanded)
    # Within the share: untouched.
    joints = np.zeros(28)
    joints[0] = 0.99 * limit * dt
    q1 = robot.configuration([0.001, 0, 0.65], 0.0, joints)
    q, velocities, saturation = limit_joint_velocity(robot, q0, q1, dt, share=0.995)
    assert not saturation.scaled and np.array_equal(q, q1)
    with pytest.raises(ValueError, match='share'):
        limit_joint_velocity(robot, q0, q1, dt, share=1.5)


def test_node_holds_the_posture_first_measured_not_each_measurement(inproc):
    """A robot that gives under load stands below its command: the IK holds what it first saw.

    The robot here sinks 0.01 rad below every command it gets (a position drive under load).
    Following each measurement, the held posture went down with it, 0.01 rad a message (until
    session 24: RoboSimian's body 2-3.5 cm in the physics simulator's first 2 s).
    """
    from gait_nodes.whole_body_ik import WholeBodyIk

    node = WholeBodyIk()
    collector = Collector()
    robot = node.robot
    nominal = robot.joint_positions(node.q_nominal)
    state = runtime.Node('sinking_robot')
    publisher = state.create_publisher(get_message('sensor_msgs/msg/JointState'),
                                       '/joint_states', 10)
    commanded = [nominal.copy()]

    def measure():
        msg = get_message('sensor_msgs/msg/JointState')()
        msg.name = list(robot.joint_names)
        msg.position = (commanded[-1] - 0.01).tolist()
        publisher.publish(msg)

    state.create_timer(0.05, measure)
    executor = runtime.SingleThreadedExecutor()
    for each in (node, collector, state):
        executor.add_node(each)
    for _ in range(20):
        executor.spin_for(0.05)
        if collector.commands:
            commanded.append(np.array(collector.commands[-1].points[0].positions))
    held = [np.array(m.points[0].positions) for m in collector.commands[-10:]]
    first = nominal - 0.01
    for positions in held:
        np.testing.assert_allclose(positions, first, atol=1e-9)
