"""Kinematic simulator: actuators, base on the stance feet, the node alone and in the gait graph.

The graph tests check the published motion from outside, as a user with the bag would: foot
positions by a fresh forward kinematics of /joint_states and /tf, the ZMP and COM recomputed body
by body from finite differences of those configurations.
"""

import math
import re
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_sim_trajectory import bad_trajectories, trajectory_msg
from test_zmp_monitor import body_by_body_zmp

from gait_nodes import graph, runtime
from gait_nodes.contract import (
    FootstepPlan,
    base_transforms,
    footsteps_from_msg,
    footsteps_to_msg,
)
from gait_nodes.diagnostics import ERROR, OK, WARN, level_value
from gait_nodes.geometry import disc_support_margin, signed_distance
from gait_nodes.interfaces import get_message
from gait_nodes.kinematic_simulator import node_defaults
from gait_nodes.markers import from_simulator
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import (
    IkTargets,
    WholeBodyIkSolver,
    nominal_configuration,
)
from gait_nodes.runtime import Parameter, qos_profile_latched
from gait_nodes.sim.kinematics import (
    ORIENTATION_PRIOR_M,
    KinematicSimulation,
    PositionActuators,
    _mean_of_rows,
    fit_base_pose,
    fit_base_pose_gauss_newton,
    kabsch,
    svd3,
)
from gait_nodes.sim.zmp_monitor import POLYGON_SEGMENTS_PER_FOOT, central_differences

NS = 1_000_000_000
#: The simulator's default rate (config/kinematic_simulator.yaml) [Hz], its period [ns] and [s].
RATE_HZ = node_defaults()['rate_hz']
PERIOD_NS = round(NS / RATE_HZ)
PERIOD_S = PERIOD_NS / NS
#: Simulated seconds of the crawl the simulator follows (its first two steps at 0.03 m/s).
CRAWL_S = 20.0
#: How far the drawn polygon's edges lie outside the foot circles, per metre of radius.
CIRCUMSCRIBED = 1 / math.cos(math.pi / POLYGON_SEGMENTS_PER_FOOT) - 1


@pytest.fixture(scope='module')
def robot():
    return load_robot_model('robosimian')


@pytest.fixture(scope='module')
def q_nominal(robot):
    return nominal_configuration(robot)


# -- core: actuators -------------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), spread=st.floats(0.0, 4.0), dt=st.floats(1e-4, 0.05),
       moving=st.booleans())
def test_actuators_respect_velocity_acceleration_and_position_limits(robot, q_nominal, seed,
                                                                     spread, dt, moving):
    rng = np.random.default_rng(seed)
    actuators = PositionActuators(robot)
    current = robot.joint_positions(q_nominal)
    limits = robot.velocity_limits_rad_s
    change = robot.acceleration_limits_rad_s2 * dt
    before = rng.uniform(-limits, limits) if moving else np.zeros(len(current))
    command = current + rng.uniform(-spread, spread, len(current))
    step = actuators.step(current, before, command, dt)
    assert np.all(np.abs(step.velocities_rad_s) <= limits * (1 + 1e-12))
    assert np.all(np.abs(step.velocities_rad_s - before) <= change * (1 + 1e-9) + 1e-12)
    np.testing.assert_allclose(step.positions_rad - current, step.velocities_rad_s * dt,
                               atol=1e-15)
    assert np.all(robot.within_limits(step.positions_rad))
    target = np.clip(command, robot.lower_limits, robot.upper_limits)
    demanded = (target - current) / dt
    # A joint lands on its target when the velocity that does it is within both limits (and
    # the joint could stop there: a still target, reached in one step at most a_max dt away).
    reachable = ((np.abs(demanded) <= limits) & (np.abs(demanded - before) <= change)
                 & (np.abs(target - current) <= change * dt))
    np.testing.assert_allclose(step.positions_rad[reachable], target[reachable], atol=1e-15)
    if not moving:  # from rest, a joint that does not land moves toward its target, not past it
        lagging = ~reachable & (target != current)
        assert np.all(np.sign(step.velocities_rad_s[lagging])
                      == np.sign(target - current)[lagging])
        assert np.all(np.abs(step.positions_rad - current)[lagging]
                      <= np.abs(target - current)[lagging])
        np.testing.assert_array_equal(step.saturated, np.abs(target - current)
                                      > change * dt * (1 + 1e-9))
    np.testing.assert_array_equal(step.clamped_to_limits, target != command)
    assert step.any_saturated == bool(step.saturated.any())
    assert step.any_clamped == bool(step.clamped_to_limits.any())


# -- core: the base on the stance feet -------------------------------------------------------


def feet_in_base(robot, q):
    q = q.copy()
    q[:7] = [0, 0, 0, 0, 0, 0, 1]
    data = robot.new_data()
    pin.framesForwardKinematics(robot.model, data, q)
    return [data.oMf[f].copy() for f in robot.foot_frame_ids]


@pytest.mark.parametrize('seed', range(6))
@pytest.mark.parametrize('stance', [(0, 1, 2, 3), (0, 1, 3), (1, 2), (2,)])
def test_base_fit_recovers_the_pose_that_holds_the_feet(robot, q_nominal, seed, stance):
    rng = np.random.default_rng(seed)
    truth = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-0.3, 0.3, 3)),
                    rng.uniform(-1, 1, 3) + [0, 0, 0.6])
    in_base = [feet_in_base(robot, q_nominal)[k] for k in stance]
    in_world = [truth * f for f in in_base]
    guess = truth * pin.exp6(rng.normal(0, 0.02, 6))
    # Flat feet (robosimian holds its soles): one or two feet fix the pose with orientations.
    fitted = fit_base_pose(guess, in_base, in_world, rotation_weight_m=0.1)
    np.testing.assert_allclose(fitted.homogeneous, truth.homogeneous, atol=1e-9)
    if len(stance) >= 3:
        assert kabsch(np.array([f.translation for f in in_base]),
                      np.array([f.translation for f in in_world])) is not None


def numpy_kabsch(points_in_base, points_in_world):
    """The reference: Kabsch with numpy.linalg.svd, as the simulator had it."""
    if len(points_in_base) < 3:
        return None
    centre_base, centre_world = points_in_base.mean(0), points_in_world.mean(0)
    u, singular, vt = np.linalg.svd((points_in_base - centre_base).T
                                    @ (points_in_world - centre_world))
    if singular[1] <= 1e-6 * max(singular[0], 1e-300):
        return None
    rotation = vt.T @ np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
    return pin.SE3(rotation, centre_world - rotation @ centre_base)


@st.composite
def stance_point_sets(draw):
    """(points in the base, in the world): 1 to 5 feet, noisy, coplanar, collinear, tiny."""
    rng = np.random.default_rng(draw(st.integers(0, 2**31)))
    count = draw(st.integers(1, 5))
    shape = draw(st.sampled_from(['general', 'coplanar', 'collinear', 'nearly collinear']))
    scale = draw(st.sampled_from([1e-3, 0.3, 1.0, 50.0]))
    points = rng.uniform(-1.0, 1.0, (count, 3)) * scale
    if shape == 'coplanar':  # feet on flat ground
        points[:, 2] = -0.5 * scale
    elif shape in ('collinear', 'nearly collinear'):
        points = np.outer(rng.uniform(-1.0, 1.0, count), rng.normal(size=3)) * scale
        if shape == 'nearly collinear':
            points += rng.normal(0.0, 1e-5 * scale, points.shape)
    truth = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3)),
                    rng.uniform(-2.0, 2.0, 3))
    noise = draw(st.sampled_from([0.0, 1e-9, 1e-4])) * scale
    in_world = points @ truth.rotation.T + truth.translation + rng.normal(0.0, noise,
                                                                             points.shape)
    return points, in_world


@settings(max_examples=300, deadline=None)
@given(stance_point_sets())
def test_kabsch_agrees_with_the_numpy_svd_reference(point_sets):
    """The fit (LAPACK's SVD called directly) is numpy's Kabsch.

    None on 1, 2 or collinear feet, else the same pose to 1e-12 relative (here bit for bit:
    one LAPACK routine).
    """
    in_base, in_world = point_sets
    fitted, reference = kabsch(in_base, in_world), numpy_kabsch(in_base, in_world)
    assert (fitted is None) == (reference is None)
    if fitted is None:
        return
    scale = 1.0 + np.abs(in_world).max()
    np.testing.assert_allclose(fitted.rotation, reference.rotation, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fitted.translation, reference.translation, rtol=0,
                               atol=1e-12 * scale)
    assert np.linalg.det(fitted.rotation) > 0.0


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**31), rank=st.integers(0, 3),
       scale=st.sampled_from([1e-12, 1e-3, 1.0, 1e6]))
def test_svd3_is_numpys_svd(seed, rank, scale):
    rng = np.random.default_rng(seed)
    matrix = (rng.normal(size=(3, rank)) @ rng.normal(size=(rank, 3))) * scale
    u, singular, vt = svd3(matrix)
    reference = np.linalg.svd(matrix)
    np.testing.assert_allclose(singular, reference[1], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose((u * singular) @ vt, matrix, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(u @ u.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(vt @ vt.T, np.eye(3), atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**31), count=st.integers(1, 12),
       scale=st.sampled_from([1e-9, 1e-3, 1.0, 1e3]))
def test_mean_of_rows_is_numpys_reduction_bit_for_bit(seed, count, scale):
    """The Kabsch centre in floats: np.add.reduce(points, 0) / len(points), bytes included."""
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(count, 3)) * scale * 10.0 ** rng.uniform(-3, 3, (count, 1))
    assert (_mean_of_rows(points.tolist()).tobytes()
            == (np.add.reduce(points, 0) / count).tobytes())


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31), h=st.sampled_from([1e-3, 0.005, 1.0 / 3.0, 0.02]),
       other=st.sampled_from([None, 0.004, 0.0051]))
def test_central_differences_with_equal_steps_are_the_general_formula(robot, seed, h, other):
    """The equal-step shortcut gives the general formula's values to the bit."""
    rng = np.random.default_rng(seed)
    model = robot.model
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q_before = pin.integrate(model, q, -rng.normal(0.0, 0.5, model.nv) * h)
    q_after = pin.integrate(model, q, rng.normal(0.0, 0.5, model.nv) * h)
    h2 = h if other is None else other
    v, a = central_differences(model, q_before, q, q_after, h, h2)
    d1, d2 = pin.difference(model, q_before, q), pin.difference(model, q, q_after)
    np.testing.assert_array_equal(v, (d1 * (h2 / h) + d2 * (h / h2)) / (h + h2))
    np.testing.assert_array_equal(a, 2.0 * (d2 / h2 - d1 / h) / (h + h2))


def test_plan_contacts_are_the_plans_at_every_instant(robot):
    """Looked up once between contact changes, equal to FootstepPlan.contacts_at everywhere."""
    from gait_nodes.kinematic_simulator import PlanContacts

    feet, yaws = robot.foot_poses(nominal_configuration(robot))
    rng = np.random.default_rng(3)
    times = np.cumsum(rng.choice([0.0, 0.25, 0.4], 12))  # repeated instants included
    positions = np.array([feet + rng.choice([0.0, 0.1], (len(feet), 1)) * [1, 0, 0] * k
                          for k in range(len(times))])
    plan = FootstepPlan(0, robot.foot_names, times, positions,
                        np.tile(yaws, (len(times), 1)))
    order = np.array([3, 1, 0, 2])
    contacts = PlanContacts(plan, order)
    changes = contacts.changes_s
    instants = [*changes, *(np.array(changes) + 1e-9), *(np.array(changes) - 1e-9),
                *np.linspace(-1.0, times[-1] + 1.0, 997)]
    for t in rng.permutation(instants):  # in any order: the cache holds for any query
        np.testing.assert_array_equal(contacts.at(float(t)), plan.contacts_at(float(t))[order])


def test_two_point_feet_keep_the_free_rotation_of_the_previous_pose(robot, q_nominal):
    truth = pin.SE3(pin.rpy.rpyToMatrix(0.05, -0.02, 0.3), np.array([0.2, -0.1, 0.65]))
    in_base = [feet_in_base(robot, q_nominal)[k] for k in (1, 2)]
    in_world = [truth * f for f in in_base]
    fitted = fit_base_pose(truth, in_base, in_world, rotation_weight_m=0.0)
    np.testing.assert_allclose(fitted.homogeneous, truth.homogeneous, atol=1e-9)
    # From a guess off the truth, the feet are met exactly whatever the rotation they leave.
    guess = truth * pin.exp6(np.array([0.01, 0.0, 0.0, 0.02, -0.03, 0.01]))
    fitted = fit_base_pose(guess, in_base, in_world, rotation_weight_m=0.0)
    for base_foot, world_foot in zip(in_base, in_world, strict=True):
        np.testing.assert_allclose((fitted * base_foot).translation, world_foot.translation,
                                   atol=1e-8)


def test_two_point_feet_under_a_translating_body_do_not_tilt_it(robot, q_nominal):
    # A trot: the body moves level over two diagonal point feet. The fit must not turn part of
    # each translation into a rotation about the feet's line (a Go2 pitched 0.09 rad in 20 s).
    in_base = [feet_in_base(robot, q_nominal)[k] for k in (0, 3)]
    base = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.65]))
    in_world = [base * f for f in in_base]
    for k in range(400):
        moved = pin.SE3(np.eye(3), np.array([0.0005, 0.0002, 0.0]) * (k + 1) + [0, 0, 0.65])
        current_in_base = [moved.inverse() * f for f in in_world]
        base = fit_base_pose(base, current_in_base, in_world, rotation_weight_m=0.0)
    np.testing.assert_allclose(base.rotation, np.eye(3), atol=1e-5)
    np.testing.assert_allclose(base.translation, [0.2, 0.08, 0.65], atol=1e-6)


def test_a_swing_foot_without_plan_is_released_and_latched_where_it_lands(robot, q_nominal):
    """Contacts by foot height: lift the front-left foot 5 cm, move it 6 cm forward, lower it."""
    solver = WholeBodyIkSolver(robot)
    feet0, yaws0 = robot.foot_poses(q_nominal)
    com0 = robot.com(q_nominal)
    simulation = KinematicSimulation(robot, q_nominal)
    q_ik = q_nominal.copy()
    dt = 0.005
    lifted = landed = None
    for k in range(1, 601):
        t = k * dt
        feet = feet0.copy()
        s = min(max((t - 0.5) / 1.5, 0.0), 1.0)
        feet[0] += [0.06 * s, 0.0, 0.05 * math.sin(math.pi * s)]
        targets = IkTargets(feet, yaws0, 0.0, com_in_world=com0 + [0.0, -0.04, 0.0])
        q_ik = solver.solve(targets, q_ik).q
        step = simulation.step(robot.joint_positions(q_ik), dt)
        if lifted is None and not step.contacts[0]:
            lifted = t
        if lifted is not None and landed is None and step.contacts[0]:
            landed = t
        # Stance feet never move.
        for f in np.flatnonzero(step.contacts[1:]) + 1:
            np.testing.assert_allclose(step.contact_points_in_world[f], feet0[f], atol=1e-7)
    assert lifted is not None and landed is not None and lifted < landed
    np.testing.assert_allclose(simulation.contact_points()[0], feet0[0] + [0.06, 0.0, 0.0],
                               atol=1e-6)


# -- the node in the gait graph --------------------------------------------------------------


class VelocityCommand(runtime.Node):
    """Publishes a constant /cmd_vel twice a second."""

    def __init__(self, vx_m_s):
        super().__init__('velocity_command')
        self.vx = vx_m_s
        self.publisher = self.create_publisher(get_message('geometry_msgs/msg/Twist'),
                                               '/cmd_vel', 10)
        self.create_timer(0.5, self.tick)

    def tick(self):
        """Publish the twist."""
        msg = get_message('geometry_msgs/msg/Twist')()
        msg.linear.x = self.vx
        self.publisher.publish(msg)


class Collector(runtime.Node):
    """Keeps the simulator's outputs (and the footstep plans) with their reception times."""

    TOPICS = ('/joint_states', '/tf', '/gait/zmp', '/gait/com', '/gait/support_polygon',
              '/diagnostics', '/clock', '/gait/markers')

    def __init__(self):
        super().__init__('collector', use_global_arguments=False)
        self.messages = {topic: [] for topic in self.TOPICS}
        for topic in self.TOPICS:
            type_name = graph.TOPICS.get(topic, 'visualization_msgs/msg/MarkerArray')
            self.create_subscription(get_message(type_name), topic,
                                     self.messages[topic].append, 1000)
        self.plans = []
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 '/gait/footsteps', self.on_plan, qos_profile_latched)

    def on_plan(self, msg):
        """Keep the plan with the time it arrived."""
        self.plans.append((self.get_clock().now().nanoseconds, footsteps_from_msg(msg)))

    def statuses(self, aspect=None):
        """(stamp [ns], status) of the simulator's diagnostics, for one aspect or all."""
        return [(stamp_ns(array), status) for array in self.messages['/diagnostics']
                for status in array.status
                if status.name.startswith('kinematic_simulator: ')
                and (aspect is None or status.name == f'kinematic_simulator: {aspect}')]


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * NS + msg.header.stamp.nanosec


def values_of(status) -> dict:
    return {item.key: item.value for item in status.values}


def configurations(robot, collector):
    """(stamps [ns], q) rebuilt from /joint_states and /tf (matched by stamp)."""
    bases = {}
    for msg in collector.messages['/tf']:
        for transform in base_transforms(msg):
            t, r = transform.transform.translation, transform.transform.rotation
            bases[stamp_ns(transform)] = [t.x, t.y, t.z, r.x, r.y, r.z, r.w]
    stamps, qs = [], []
    for msg in collector.messages['/joint_states']:
        stamp = stamp_ns(msg)
        q = pin.neutral(robot.model)
        q[:7] = bases[stamp]
        joints = np.zeros(len(robot.joint_names))
        joints[robot.indices(list(msg.name))] = msg.position
        robot.set_joint_positions(q, joints)
        stamps.append(stamp)
        qs.append(q)
    return np.array(stamps), qs


@pytest.fixture(scope='module')
def crawl(tmp_path_factory):
    """Five contract nodes (those installed) crawling at 0.03 m/s for 9 s of simulated time.

    The crawl is pinned (``gait: auto`` would follow the crossover) and the swing is the
    whole-body IK's own fallback swing: the swing_leg_policy's swings, squeezed into the
    planner's swing time, still ask more than 1 rad/s of some joints (the IK saturates and
    stance feet slip by millimetres), which is the gait-timing work of issue 9, not the
    simulator's.
    """
    params = tmp_path_factory.mktemp('crawl') / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    gait: crawl\n    swing: polynomial\n')
    runtime.init(args=['--ros-args', '--params-file', str(params)], runtime='inproc',
                 signal_handlers=False)
    try:
        executor = runtime.SingleThreadedExecutor()
        nodes = {name: graph.load_class(graph.NODES[name])()
                 for name in graph.available_nodes() if name != 'swing_leg_policy'}
        collector = Collector()
        for node in [*nodes.values(), VelocityCommand(0.03), collector]:
            executor.add_node(node)
        executor.spin_for(CRAWL_S)
        yield nodes['kinematic_simulator'], collector
    finally:
        runtime.shutdown()


def test_crawl_moves_the_robot_forward(crawl):
    simulator, collector = crawl
    assert simulator.robot.name == 'robosimian'
    stamps, qs = configurations(simulator.robot, collector)
    assert len(stamps) == CRAWL_S * RATE_HZ
    assert np.all(np.diff(stamps) == PERIOD_NS)
    assert qs[-1][0] - qs[0][0] > 0.05
    plans = [plan for _, plan in collector.plans]
    assert any(plan.swings() for plan in plans)


def stance(robot, collector, stamps):
    """(N, F) booleans: feet in contact per the footstep plan the simulator had at each stamp."""
    plan_times = np.array([t for t, _ in collector.plans])
    in_contact = np.zeros((len(stamps), len(robot.foot_names)), dtype=bool)
    for i, stamp in enumerate(stamps):
        plan = collector.plans[int(np.searchsorted(plan_times, stamp, side='right')) - 1][1]
        order = [plan.foot_names.index(n) for n in robot.foot_names]
        in_contact[i] = plan.contacts_at((stamp - plan.start_ns) * 1e-9)[order]
    return in_contact


def test_stance_feet_do_not_slip(crawl):
    simulator, collector = crawl
    robot = simulator.robot
    stamps, qs = configurations(robot, collector)
    data = robot.new_data()
    feet = np.array([robot.foot_poses(q, data)[0] for q in qs])  # (N, F, 3)
    in_contact = stance(robot, collector, stamps)
    swings = 0
    for f in range(len(robot.foot_names)):
        # Each maximal run of stance samples: the foot stays where it was at the run's start.
        edges = np.flatnonzero(np.diff(np.r_[0, in_contact[:, f].astype(int), 0]))
        for start, end in zip(edges[::2], edges[1::2], strict=True):
            drift = np.linalg.norm(feet[start:end, f] - feet[start, f], axis=1).max()
            assert drift < 1e-4, (robot.foot_names[f], start, end, drift)
        swings += int(np.sum(~in_contact[:, f][1:] & in_contact[:, f][:-1]))
    assert swings >= 3


def test_joint_velocities_never_exceed_the_limits(crawl):
    simulator, collector = crawl
    robot = simulator.robot
    limits = robot.velocity_limits_rad_s
    previous = None
    for msg in collector.messages['/joint_states']:
        assert list(msg.name) == list(robot.joint_names)
        velocities = np.array(msg.velocity)
        assert np.all(np.abs(velocities) <= limits * (1 + 1e-9))
        positions = np.array(msg.position)
        if previous is not None:
            dt = (stamp_ns(msg) - stamp_ns(previous)) * 1e-9
            moved = np.abs(positions - np.array(previous.position)) / dt
            assert np.all(moved <= limits * (1 + 1e-9))
            np.testing.assert_allclose(moved, np.abs(velocities), atol=1e-9)
        previous = msg


def test_independent_zmp_and_com_from_joint_states_and_tf_agree_within_1mm(crawl):
    simulator, collector = crawl
    robot = simulator.robot
    stamps, qs = configurations(robot, collector)
    zmp = {stamp_ns(m): (m.point.x, m.point.y) for m in collector.messages['/gait/zmp']}
    com = {stamp_ns(m): (m.point.x, m.point.y, m.point.z) for m in collector.messages['/gait/com']}
    checked = 0
    worst_zmp = worst_com = 0.0
    for i in range(1, len(qs) - 1):
        dt = (stamps[i] - stamps[i - 1]) * 1e-9
        # Central differences on the configuration manifold, written out here.
        d1 = pin.difference(robot.model, qs[i - 1], qs[i])
        d2 = pin.difference(robot.model, qs[i], qs[i + 1])
        v, a = (d1 + d2) / (2 * dt), (d2 - d1) / dt**2
        expected_zmp, expected_com, force = body_by_body_zmp(robot.model, qs[i], v, a)
        if stamps[i] not in zmp:  # no ZMP without ground force (reported as an ERROR)
            assert force <= 1e-6
            continue
        worst_zmp = max(worst_zmp, float(np.linalg.norm(np.array(zmp[stamps[i]])
                                                        - expected_zmp)))
        worst_com = max(worst_com, float(np.linalg.norm(np.array(com[stamps[i]])
                                                        - expected_com)))
        checked += 1
    assert checked > 8.5 * RATE_HZ
    assert worst_zmp < 1e-3
    assert worst_com < 1e-9


def test_published_polygon_and_margins_agree_with_the_contacts(crawl):
    simulator, collector = crawl
    robot = simulator.robot
    radius = robot.description.foot_radius_m
    stamps, qs = configurations(robot, collector)
    in_contact = stance(robot, collector, stamps)
    data = robot.new_data()
    polygons = {stamp_ns(m): np.array([(p.x, p.y) for p in m.polygon.points])
                for m in collector.messages['/gait/support_polygon']}
    zmp = {stamp_ns(m): np.array([[m.point.x, m.point.y]])
           for m in collector.messages['/gait/zmp']}
    exact_margins = []
    for i, stamp in enumerate(stamps[:-1]):
        if stamp not in zmp:
            continue
        feet = robot.foot_poses(qs[i], data)[0][in_contact[i]]
        exact = disc_support_margin(zmp[stamp], feet[:, :2], radius)[0]
        drawn = signed_distance(zmp[stamp], polygons[stamp])[0]
        # The drawn polygon circumscribes the discs: its margins exceed the exact ones by 0.07 mm
        # at most.
        assert exact - 1e-6 <= drawn <= exact + CIRCUMSCRIBED * radius + 1e-6
        exact_margins.append(exact)
    assert len(exact_margins) > 8.5 * RATE_HZ
    summaries = [float(values_of(s)['min_margin_m'])
                 for _, s in collector.statuses('stability summary')]
    # Diagnostic values carry 6 significant digits.
    assert min(summaries) <= min(exact_margins) + 1e-6
    check_markers(collector, 1.0 / 20.0)


def simulator_markers(collector) -> list:
    """The simulator's arrays on /gait/markers (the planner's footholds share the topic)."""
    return [array for array in collector.messages['/gait/markers'] if from_simulator(array)]


def check_markers(collector, period_s):
    """/gait/markers: one array per markers period, each the monitor's sample of its stamp."""
    markers = simulator_markers(collector)
    stamps = [stamp_ns(m.markers[0]) for m in markers]
    period_ns = round(period_s * NS)
    slots = [stamp // period_ns for stamp in stamps]
    assert slots == sorted(set(slots))  # at most one per period...
    samples = [stamp_ns(m) for m in collector.messages['/gait/support_polygon']]
    assert len(markers) == len({stamp // period_ns for stamp in samples})  # ...and every one
    zmp = {stamp_ns(m): m.point for m in collector.messages['/gait/zmp']}
    com = {stamp_ns(m): m.point for m in collector.messages['/gait/com']}
    polygons = {stamp_ns(m): m.polygon.points for m in collector.messages['/gait/support_polygon']}
    for stamp, array in zip(stamps, markers, strict=True):
        assert {m.ns for m in array.markers} == {'gait'}
        zmp_sphere, com_sphere, outline = array.markers
        assert all(stamp_ns(m) == stamp for m in array.markers)
        if stamp in zmp:
            assert zmp_sphere.pose.position == zmp[stamp]
        else:
            assert zmp_sphere.action == zmp_sphere.DELETE
        assert com_sphere.pose.position == com[stamp]
        vertices = [(p.x, p.y, p.z) for p in polygons[stamp]]
        assert [(p.x, p.y, p.z) for p in outline.points] == vertices + vertices[:1]


# -- the node alone --------------------------------------------------------------------------


@pytest.fixture
def inproc():
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    yield runtime.default_context().transport
    runtime.shutdown()


class CommandSource(runtime.Node):
    """Publishes given /joint_commands messages at given times, and a footstep plan."""

    def __init__(self, schedule, plan=None):
        super().__init__('command_source', use_global_arguments=False)
        self.schedule = sorted(schedule, key=lambda item: item[0])
        self.publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/JointTrajectory'), '/joint_commands', 10)
        if plan is not None:
            footsteps = self.create_publisher(
                get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/footsteps',
                qos_profile_latched)
            footsteps.publish(footsteps_to_msg(plan))
        self.create_timer(0.005, self.tick)

    def tick(self):
        """Publish what is due."""
        now = self.get_clock().now().nanoseconds
        while self.schedule and self.schedule[0][0] <= now:
            self.publisher.publish(self.schedule.pop(0)[1])


def joint_command(names, positions, velocities=()):
    """A one-point /joint_commands trajectory: be at ``positions`` now (zero stamp: receipt)."""
    return trajectory_msg(names, [positions], [velocities] if len(velocities) else (),
                          times_s=[0.0])


def run_simulator(seconds, schedule=(), plan=None, parameters=()):
    from gait_nodes.kinematic_simulator import KinematicSimulator

    simulator = KinematicSimulator()
    if parameters:
        result = simulator.set_parameters([Parameter(n, value=v) for n, v in parameters])
        assert all(r.successful for r in result)
    source = CommandSource(list(schedule), plan)
    collector = Collector()
    executor = runtime.SingleThreadedExecutor()
    for node in (simulator, source, collector):
        executor.add_node(node)
    executor.spin_for(seconds)
    return simulator, collector


def test_a_gait_that_loses_balance_is_flagged_at_the_first_sample_outside(inproc, robot,
                                                                          q_nominal):
    """Both left feet lift at 0.5 s with the COM in the middle: support on the right feet only."""
    feet, yaws = robot.foot_poses(q_nominal)
    names = robot.foot_names
    moved = feet.copy()
    for foot in ('front_left', 'rear_left'):
        moved[names.index(foot)] += [0.2, 0.0, 0.0]
    plan = FootstepPlan(0, names, np.array([0.0, 0.5, 1.5]), np.array([feet, feet, moved]),
                        np.array([yaws, yaws, yaws]))
    hold = joint_command(robot.joint_names, robot.joint_positions(q_nominal))
    simulator, collector = run_simulator(1.0, [(k * NS // 200, hold) for k in range(200)], plan)
    polygons = {stamp_ns(m): np.array([(p.x, p.y) for p in m.polygon.points])
                for m in collector.messages['/gait/support_polygon']}
    first_outside = None
    for msg in collector.messages['/gait/zmp']:
        stamp = stamp_ns(msg)
        point = np.array([[msg.point.x, msg.point.y]])
        assert signed_distance(point, polygons[stamp])[0] == pytest.approx(
            disc_support_margin(point, feet[[1, 3], :2] if stamp > NS // 2 else feet[:, :2],
                                robot.description.foot_radius_m)[0], abs=1e-4)
        if first_outside is None and signed_distance(point, polygons[stamp])[0] < 0:
            first_outside = stamp
    assert first_outside == NS // 2 + PERIOD_NS  # the first tick with the left feet up
    errors = [(t, s) for t, s in collector.statuses('stability') if level_value(s.level) == ERROR]
    assert errors, 'no ERROR reported'
    check_markers(collector, 1.0 / 20.0)  # the ZMP sphere deleted while the ZMP is undefined
    assert int(values_of(errors[0][1])['sample_stamp_ns']) == first_outside
    assert errors[0][0] - first_outside <= PERIOD_NS  # reported at the next tick at the latest
    before = [s for t, s in collector.statuses() if t < first_outside]
    assert all(level_value(s.level) == OK for s in before)


def test_every_monitor_sample_is_of_a_published_joint_state_and_base_pose(inproc, robot,
                                                                          q_nominal):
    """The monitor's outputs are stamped at instants that /joint_states and /tf describe.

    /gait/zmp, /gait/com, /gait/support_polygon, /gait/markers and the stability report: a user
    pairs them by stamp (or looks the base up in tf at the ZMP's stamp) from the first sample on.
    """
    hold = joint_command(robot.joint_names, robot.joint_positions(q_nominal))
    simulator, collector = run_simulator(0.1, [(k * NS // 200, hold) for k in range(20)])
    states = [stamp_ns(m) for m in collector.messages['/joint_states']]
    bases = [stamp_ns(t) for m in collector.messages['/tf'] for t in base_transforms(m)]
    assert bases == states
    for topic in ('/gait/zmp', '/gait/com', '/gait/support_polygon'):
        # Every instant but the newest, whose ZMP needs the next configuration.
        assert [stamp_ns(m) for m in collector.messages[topic]] == states[:-1], topic
    assert {stamp_ns(m.markers[0]) for m in simulator_markers(collector)} <= set(states)
    reports = [int(values_of(s)['sample_stamp_ns']) for _, s in collector.statuses('stability')]
    assert reports and set(reports) <= set(states)


def test_bad_joint_commands_are_rejected_and_the_state_is_held(inproc, robot, q_nominal):
    """Every trajectory a joint_trajectory_controller refuses: dropped whole, reported, held."""
    names = list(robot.joint_names)
    start = robot.joint_positions(q_nominal)
    good = start.copy()
    good[names.index('fl_joint_1')] += 0.02
    bad = bad_trajectories(names, start + 0.3)
    schedule = [(NS // 10, joint_command(names, good))] + [
        (NS // 2 + k * NS // 200, msg) for k, (_, msg, _) in enumerate(bad)]
    simulator, collector = run_simulator(1.0, schedule)
    drops = [s for _, s in collector.statuses('input /joint_commands')]
    assert len(drops) == len(bad)
    assert all(level_value(s.level) == WARN for s in drops)
    assert int(values_of(drops[-1])['dropped_count']) == len(bad)
    for (what, _, words), status in zip(bad, drops, strict=True):
        assert re.search(words, values_of(status)['reason']), what
    states = collector.messages['/joint_states']
    after = [np.array(m.position) for m in states if stamp_ns(m) >= NS // 2 - NS // 10]
    for positions in after:  # the good command was reached and is held
        np.testing.assert_allclose(positions, good, atol=1e-12)
    for msg in states:
        assert np.all(np.isfinite(msg.position))


def test_a_subset_command_moves_only_its_joints(inproc, robot, q_nominal):
    start = robot.joint_positions(q_nominal)
    simulator, collector = run_simulator(0.5, [(NS // 10, joint_command(['rr_joint_7'],
                                                                        [0.05]))])
    final = np.array(collector.messages['/joint_states'][-1].position)
    k = robot.joint_names.index('rr_joint_7')
    assert final[k] == pytest.approx(0.05)
    np.testing.assert_allclose(np.delete(final, k), np.delete(start, k), atol=1e-12)


def test_stale_commands_are_reported(inproc, robot, q_nominal):
    hold = joint_command(robot.joint_names, robot.joint_positions(q_nominal))
    schedule = [(k * NS // 200, hold) for k in range(100)]  # commands stop at 0.5 s
    simulator, collector = run_simulator(1.0, schedule, parameters=[('stale_after_s', 0.1)])
    inputs = [(t, s) for t, s in collector.statuses('inputs')]
    warnings = [(t, s) for t, s in inputs if level_value(s.level) == WARN]
    assert warnings
    first = warnings[0][0]
    last_command = 99 * NS // 200
    assert last_command + NS // 10 < first <= last_command + NS // 10 + PERIOD_NS
    assert 'no /joint_commands' in warnings[0][1].message


def test_parameters_are_validated_and_a_rejected_change_changes_nothing(inproc):
    from gait_nodes.kinematic_simulator import KinematicSimulator

    simulator = KinematicSimulator()
    before = simulator.params
    for name, value in (('warn_margin_m', -0.1), ('rate_hz', 0.0), ('stale_after_s', math.nan),
                        ('publish_clock', True), ('robot', 'biped'),
                        ('contact_height_tolerance_m', 2.0), ('markers_rate_hz', 0.0),
                        ('markers_rate_hz', 2001.0)):
        result = simulator.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful
        assert name in result.reason
        assert simulator.params == before
    assert simulator.set_parameters([Parameter('warn_margin_m', value=0.05)])[0].successful
    assert simulator.params.warn_margin_m == 0.05


def test_markers_at_the_simulation_rate_are_every_monitor_sample(inproc, robot, q_nominal):
    hold = joint_command(robot.joint_names, robot.joint_positions(q_nominal))
    for rate_hz, period_s in ((RATE_HZ, PERIOD_S), (1000.0, PERIOD_S), (7.0, 1.0 / 7.0)):
        simulator, collector = run_simulator(0.6, [(k * NS // 200, hold) for k in range(120)],
                                             parameters=[('markers_rate_hz', rate_hz)])
        check_markers(collector, period_s)
        if rate_hz >= RATE_HZ:
            assert len(simulator_markers(collector)) == len(
                collector.messages['/gait/support_polygon'])
        runtime.shutdown()
        runtime.init(args=[], runtime='inproc', signal_handlers=False)


def test_clock_is_published_every_tick_with_the_simulated_time(inproc):
    simulator, collector = run_simulator(0.2, parameters=())
    assert not collector.messages['/clock']
    runtime.shutdown()
    runtime.init(args=['x', '--ros-args', '-p', 'publish_clock:=true'], runtime='inproc',
                 signal_handlers=False)
    simulator, collector = run_simulator(0.2)
    clocks = [m.clock.sec * NS + m.clock.nanosec for m in collector.messages['/clock']]
    assert clocks == [k * PERIOD_NS for k in range(1, round(0.2 * RATE_HZ) + 1)]
    assert clocks == [stamp_ns(m) for m in collector.messages['/joint_states']]


def test_a_command_beyond_the_limits_saturates_and_is_reported(inproc, robot, q_nominal):
    """A 0.5 rad jump: 1 rad/s reached in 0.05 s at 20 rad/s^2, 0.45 s at 1 rad/s, braking."""
    start = robot.joint_positions(q_nominal)
    jump = start.copy()
    k = robot.joint_names.index('fr_joint_1')
    jump[k] += 0.5
    simulator, collector = run_simulator(1.2, [(NS // 10, joint_command(robot.joint_names,
                                                                        jump))])
    states = collector.messages['/joint_states']
    velocities = np.array([m.velocity[k] for m in states])
    positions = np.array([m.position[k] for m in states])
    limit, acceleration = robot.velocity_limits_rad_s[k], robot.acceleration_limits_rad_s2[k]
    assert np.all(np.abs(velocities) <= limit * (1 + 1e-12))
    assert np.all(np.abs(np.diff(velocities)) <= acceleration * PERIOD_S * (1 + 1e-9))
    np.testing.assert_allclose(np.diff(positions), velocities[1:] * PERIOD_S, atol=1e-15)
    at_limit = int(np.sum(np.isclose(velocities, limit)))
    assert 0.5 / limit - limit / acceleration - 2 * PERIOD_S <= at_limit * PERIOD_S \
        <= 0.5 / limit
    assert np.all(positions <= jump[k] + 1e-12)  # no overshoot
    assert positions[-1] == pytest.approx(jump[k], abs=1e-12)
    summaries = [s for _, s in collector.statuses('velocity saturation')]
    assert level_value(summaries[0].level) == WARN
    values = values_of(summaries[0])
    assert values['joints'] == 'fr_joint_1'
    # The first tick asked for 0.5 rad in one step: 100 rad/s from rest, 1000x a_max dt.
    assert float(values['max_demanded_over_limit']) == pytest.approx(
        0.5 / PERIOD_S / (acceleration * PERIOD_S))
    assert int(values['acceleration_saturated_ticks']) >= 10


class FixedClock:
    """A clock that reads whatever the test sets."""

    def __init__(self):
        self.ns = 0

    def now(self):
        """The time the test set."""
        return SimpleNamespace(nanoseconds=self.ns)


def test_on_the_wall_clock_steps_stay_on_the_period_grid_whatever_the_timer_jitter(inproc):
    """A late timer delays publication, not stamps; missed steps are caught up.

    A clock that jumps (back, or too far ahead) re-anchors the grid.
    """
    from gait_nodes.kinematic_simulator import MAX_LAG_PERIODS, KinematicSimulator

    simulator = KinematicSimulator()
    clock = FixedClock()
    simulator.get_clock = lambda: clock
    period = PERIOD_NS
    stamps = []
    simulator._step = lambda now_ns, _period: (stamps.append(now_ns),
                                               simulator._history.append((now_ns, None, None)))
    clock.ns = 10 * NS
    simulator._owns_time = False
    simulator.tick()
    for jitter in (700_000, -300_000, 1_900_000, 0):
        clock.ns = stamps[-1] + period + jitter
        simulator.tick()
    assert np.all(np.diff(stamps) == period)
    clock.ns = stamps[-1] + 3 * period + 1000  # the timer missed two ticks
    simulator.tick()
    assert np.all(np.diff(stamps) == period) and len(stamps) == 8
    clock.ns = stamps[-1] + (MAX_LAG_PERIODS + 3) * period  # starved: re-anchored on the clock
    simulator.tick()
    assert stamps[-1] == clock.ns
    clock.ns = stamps[-1] - 7 * period  # clock went back
    simulator.tick()
    assert stamps[-1] == clock.ns


def ramp_window(names, start, k, stamp_ns, rate_rad_s, horizon_s=0.1, period_ns=NS // 200):
    """A stamped trajectory from ``stamp_ns`` to ``stamp_ns + horizon_s``.

    Knots ``period_ns`` apart (as whole_body_ik sends them); joint ``k`` ramps at
    ``rate_rad_s`` from 0.25 s on.
    """
    times_ns = np.arange(0, int(horizon_s * NS) + 1, period_ns)
    positions = np.repeat(start[None, :], len(times_ns), axis=0)
    velocities = np.zeros_like(positions)
    absolute_s = (stamp_ns + times_ns) * 1e-9
    positions[:, k] += rate_rad_s * np.maximum(absolute_s - 0.25, 0.0)
    velocities[:, k] = np.where(absolute_s >= 0.25, rate_rad_s, 0.0)
    return trajectory_msg(names, positions, velocities, times_s=times_ns * 1e-9,
                          stamp_ns=stamp_ns)


def test_late_and_lost_trajectories_give_the_commanded_motion_not_their_arrival_times(
        inproc, robot, q_nominal):
    """Stamped 0.1 s windows published every 20 ms: two in three lost, the rest late.

    The joint follows the stamps (the held horizon rides through the gaps): its velocity is
    the commanded one at every tick once the motion is under way, and its position the ramp's.
    """
    names = list(robot.joint_names)
    start = robot.joint_positions(q_nominal)
    k = names.index('fl_joint_1')
    rate = 0.4  # [rad/s], within the limit; the ramp's corner at 0.25 s asks 80 rad/s^2
    rng = np.random.default_rng(7)
    schedule = []
    for publication in range(0, 50):
        stamp = publication * NS // 50
        if publication % 3 and publication > 2:
            continue  # lost
        late = int(rng.uniform(0, 0.03) * NS)
        schedule.append((stamp + late, ramp_window(names, start, k, stamp, rate)))
    simulator, collector = run_simulator(1.0, schedule)
    moving = [m for m in collector.messages['/joint_states']
              if NS // 4 + NS // 10 <= stamp_ns(m) <= NS - NS // 50]
    assert len(moving) > 0.5 * RATE_HZ
    for msg in moving:
        assert msg.velocity[k] == pytest.approx(rate, abs=1e-9)
        assert msg.position[k] == pytest.approx(
            start[k] + rate * (stamp_ns(msg) * 1e-9 - 0.25), abs=1e-9)


def test_a_zero_stamp_starts_at_receipt_and_a_stamp_at_its_time(inproc, robot, q_nominal):
    """The same two-point trajectory received at 0.2 s, with a zero stamp and stamped for 0.5 s.

    The joint reaches the last point 0.2 s after the trajectory's start, wherever that is.
    """
    names = list(robot.joint_names)
    start = robot.joint_positions(q_nominal)
    k = names.index('rr_joint_2')
    positions = np.array([start, start])
    positions[1, k] += 0.01
    for stamp, start_ns in ((0, NS // 5), (NS // 2, NS // 2)):
        msg = trajectory_msg(names, positions, times_s=[0.0, 0.2], stamp_ns=stamp)
        simulator, collector = run_simulator(1.0, [(NS // 5, msg)])
        trace = {stamp_ns(m): m.position[k] for m in collector.messages['/joint_states']}
        still = [t for t, p in trace.items() if p == start[k]]
        assert max(still) == start_ns, stamp  # moves from the first tick after the start
        # Linear to the last point (no velocities), followed exactly within the limits.
        assert trace[start_ns + NS // 10] == pytest.approx(start[k] + 0.005, abs=1e-12)
        assert trace[start_ns + NS // 5] == pytest.approx(start[k] + 0.01, abs=1e-12)
        runtime.shutdown()
        runtime.init(args=[], runtime='inproc', signal_handlers=False)


def base_fit_cost(base, in_base, in_world, rotation_weight_m, guess):
    """What fit_base_pose minimises (its module docstring), evaluated independently."""
    cost = sum(float(np.sum(((base * f).translation - w.translation) ** 2))
               for f, w in zip(in_base, in_world, strict=True))
    if rotation_weight_m == 0.0:
        return cost + ORIENTATION_PRIOR_M ** 2 * float(
            np.sum(pin.log3(guess.rotation.T @ base.rotation) ** 2))
    return cost + rotation_weight_m ** 2 * sum(
        float(np.sum(pin.log3(w.rotation.T @ base.rotation @ f.rotation) ** 2))
        for f, w in zip(in_base, in_world, strict=True))


@pytest.mark.parametrize('seed', range(4))
def test_base_fit_forms_for_one_and_two_feet_agree_with_gauss_newton(seed):
    """The base fit's cheaper forms agree with the 6-dof Gauss-Newton reference.

    The closed forms (one flat foot, two point feet) and the rotation-only Gauss-Newton
    (two flat feet) against the 6-dof reference: on consistent feet (what a walk gives, the
    latched feet a rigid motion away up to 1e-6, any spread) the same pose to 1e-9; on any
    feet, near coincident ones and centimetres of inconsistency included, never a higher cost
    (the reference can stop on a flat valley or diverge where two point feet nearly coincide):
    the residual norm at most 1e-15 m (rounding) above the reference's. Not asked: a
    near-zero sole weight on inconsistent, near-coincident feet, where the two iterations may
    stop in different local minima.
    """
    rng = np.random.default_rng(seed)
    for _ in range(250):
        count = int(rng.choice([1, 2]))
        weight = float(rng.choice([0.0, 1e-4, 0.1, 1.0])) if count == 2 else float(
            rng.choice([0.1, 0.5]))
        spread_m = 10 ** rng.uniform(-6, 0)
        in_base = [pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-0.3, 0.3, 3)),
                           rng.normal(0, spread_m, 3) + [0, 0, -0.6]) for _ in range(count)]
        truth = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-0.5, 0.5, 3)), rng.uniform(-1, 1, 3))
        noise = 10 ** rng.uniform(-12, -2)
        in_world = [truth * f * pin.exp6(rng.normal(0, noise, 6)) for f in in_base]
        if rng.uniform() < 0.1:  # the feet's line exactly where the guess has it
            in_world = [truth * f for f in in_base]
        guess = truth * pin.exp6(rng.normal(0, 10 ** rng.uniform(-8, -1), 6))
        fast = fit_base_pose(guess, in_base, in_world, weight)
        reference = fit_base_pose_gauss_newton(guess, in_base, in_world, weight)
        fast_cost = base_fit_cost(fast, in_base, in_world, weight, guess)
        reference_cost = base_fit_cost(reference, in_base, in_world, weight, guess)
        if weight == 0.0 or weight >= 0.1:
            assert math.sqrt(fast_cost) <= math.sqrt(reference_cost) + 1e-15
        if noise <= 1e-6:
            np.testing.assert_allclose(fast.homogeneous, reference.homogeneous, atol=1e-9)


def test_two_point_feet_pointing_against_the_guess_fall_back_to_gauss_newton(robot,
                                                                            q_nominal):
    in_base = [feet_in_base(robot, q_nominal)[k] for k in (0, 3)]
    truth = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 3.0), np.array([0.1, 0.2, 0.6]))
    in_world = [truth * f for f in in_base]
    guess = pin.SE3(np.eye(3), truth.translation)  # the feet's line turned by 3 rad
    np.testing.assert_array_equal(
        fit_base_pose(guess, in_base, in_world, 0.0).homogeneous,
        fit_base_pose_gauss_newton(guess, in_base, in_world, 0.0).homogeneous)


def test_a_foot_still_in_the_air_at_its_planned_touch_down_lands_where_it_comes_down(
        inproc, robot, q_nominal):
    # The plan puts front_left down at 0.6 s; the commands keep it 5 cm up until 1.0 s, then
    # lower it (a swing running late: the IK held, the planner gone). It is no contact while
    # in the air: latched there, the lowered foot held the base up and tilted it (the other
    # feet left the ground by +-1.4 cm in the killed-planner fault test).
    solver = WholeBodyIkSolver(robot)
    feet0, yaws0 = robot.foot_poses(q_nominal)
    com0 = robot.com(q_nominal) + [-0.02, -0.04, 0.0]
    landing = feet0.copy()
    landing[0] += [0.06, 0.0, 0.0]
    up = landing.copy()
    up[0, 2] += 0.05
    q_up = solver.solve(IkTargets(up, yaws0, 0.0, com_in_world=com0), q_nominal).q
    q_down = solver.solve(IkTargets(landing, yaws0, 0.0, com_in_world=com0), q_up).q
    plan = FootstepPlan(0, robot.foot_names, np.array([0.0, 0.2, 0.6]),
                        np.array([feet0, feet0, landing]), np.tile(yaws0, (3, 1)))
    schedule = [(k * NS // 200, joint_command(robot.joint_names, robot.joint_positions(q)))
                for k, q in ((0, q_nominal), (50, q_up), (200, q_down))]
    simulator, collector = run_simulator(2.5, schedule, plan)
    simulation = simulator.simulation
    assert simulation.contacts.all()
    # It touched down on the ground (where the IK put it), not 5 cm up.
    np.testing.assert_allclose(simulation.contact_points()[0], landing[0], atol=2e-3)
    # The base stayed level and the other feet where they stood.
    rotation = pin.XYZQUATToSE3(simulation.q[:7]).rotation
    assert abs(rotation[2, 2] - 1.0) < 1e-6
    np.testing.assert_allclose(simulation.contact_points()[1:], feet0[1:], atol=1e-6)
    feet, _ = robot.foot_poses(simulation.q)
    np.testing.assert_allclose(feet[:, 2], 0.0, atol=2e-3)
