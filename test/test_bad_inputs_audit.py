"""Bad inputs found by an outside audit: each was a crash, a hang or a silent acceptance.

Each case is refused with what was wrong and the allowed range, reported, and the node keeps
its last good state (and goes on ticking).
"""

import json
import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import QUADRUPED
from test_footstep_planner_node import Graph
from test_kinematic_simulator import NS, joint_command, run_simulator, stamp_ns, values_of
from test_sim_trajectory import trajectory_msg

from gait_nodes import graph, runtime
from gait_nodes.contract import (
    UNIT_QUATERNION_TOLERANCE,
    ComState,
    ContractError,
    FootstepPlan,
    SwingTrajectory,
    com_reference_from_msg,
    com_reference_to_msg,
    footsteps_from_msg,
    footsteps_to_msg,
    swing_trajectory_from_msg,
    swing_trajectory_to_msg,
)
from gait_nodes.diagnostics import WARN, level_value
from gait_nodes.errors import GaitCommandError
from gait_nodes.planning.gait_params import parse_command
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import nominal_configuration
from gait_nodes.runtime import Parameter

# -- /gait/command ---------------------------------------------------------------------------

#: Texts that raised out of the JSON reader (ValueError, RecursionError) and killed the planner.
READER_KILLERS = {
    'an integer of 5000 digits': '{"step_length_m": ' + '1' * 5000 + '}',
    'nested 100000 deep': '[' * 100000 + ']' * 100000,
    'an object nested 5000 deep': '{"a": ' * 5000 + '1' + '}' * 5000,
}


@pytest.mark.parametrize('text', READER_KILLERS.values(), ids=READER_KILLERS.keys())
def test_json_the_reader_cannot_take_is_a_command_error(text):
    with pytest.raises(GaitCommandError, match='invalid JSON'):
        parse_command(text)


@pytest.fixture
def planner():
    graph_ = Graph(QUADRUPED, step_period_s=1.0, max_vx_m_s=0.5)
    yield graph_
    runtime.shutdown()


def test_gait_commands_that_crashed_or_hung_the_planner_are_refused(planner):
    """Every one answered 'not accepted' with the reason; the gait and the ticks go on."""
    from test_footstep_planner_node import twist_msg

    planner.cmd_vel.publish(twist_msg(0.1))
    planner.spin(0.5)
    before = planner.planner.planner.params
    texts = {**READER_KILLERS,
             'a step of 1 us (hung the planner)': '{"step_period_s": 1e-6}',
             'a 5e-324 s step': '{"step_period_s": 5e-324}',
             'a 5e-324 m swing apex': '{"step_height_m": 5e-324}',
             'a 1 MB gait name': '{"gait": "' + 'x' * 1_000_000 + '"}'}
    for what, text in texts.items():
        answer = planner.command(text)
        assert answer['accepted'] is False, what
        assert len(json.dumps(answer)) < 3000, what  # the echo is cut, not a megabyte
        assert planner.planner.planner.params == before, what
    reasons = [planner.status[-len(texts) + k]['reason'] for k in range(len(texts))]
    assert 'minimum of 0.05' in reasons[3] and 'minimum of 0.001' in reasons[5]
    assert '1000012 characters' in planner.status[-1]['command']
    drops = planner.statuses('input /gait/command')
    assert len(drops) == len(texts) and all(level_value(s.level) == WARN for s in drops)
    assert all(len(s.message) < 1200 for s in drops)
    count = len(planner.zmp)
    planner.spin(1.0)
    assert len(planner.zmp) - count >= 9  # still ticking at 10 Hz


def test_a_step_period_or_apex_below_the_range_is_refused_as_a_parameter(planner):
    node = planner.planner
    before = node.planner.params
    for name, value, allowed in (('step_period_s', 0.05, '(0.05, 60] s'),
                                 ('step_period_s', 1e-9, '(0.05, 60] s'),
                                 ('step_height_m', 5e-324, '(0.001, 2] m')):
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful
        assert name in result.reason and allowed in result.reason
        assert node.planner.params == before
    assert node.set_parameters([Parameter('step_period_s', value=0.06)])[0].successful


# -- timers and waypoint spacing -----------------------------------------------------------

#: node -> (parameter, value) that passed the range check, then left the node without a timer
#: (the old one destroyed, the new one refused by the runtime) or hung it.
TIMER_KILLERS = [
    ('footstep_planner', 'rate_hz', 5e-324),
    ('swing_leg_policy', 'rate_hz', 5e-324),
    ('swing_leg_policy', 'sample_period_s', 5e-324),
    ('whole_body_ik', 'rate_hz', 5e-324),
    ('kinematic_simulator', 'rate_hz', 5e-324),
    ('kinematic_simulator', 'markers_rate_hz', 5e-324),
    ('com_preview_controller', 'status_period_s', 5e-324),
    ('com_preview_controller', 'com_height_m', None),
]


@pytest.fixture(scope='module')
def nodes():
    # (gait auto would work out the crawl/trot crossover, a value-table swing load a table)
    runtime.init(args=['test', '--ros-args', '-p', 'footstep_planner:gait:=crawl',
                       '-p', 'swing_leg_policy:swing:=polynomial'],
                 runtime='inproc', signal_handlers=False)
    made = {name: graph.load_class(graph.NODES[name])() for name in graph.NODES}
    executor = runtime.SingleThreadedExecutor()
    for node in made.values():
        executor.add_node(node)
    executor.spin_for(0.05)
    yield made, executor
    runtime.shutdown()


@pytest.mark.parametrize('node_name, name, value', TIMER_KILLERS)
def test_a_rate_or_period_without_a_timer_period_is_refused(nodes, node_name, name, value):
    made, executor = nodes
    node = made[node_name]
    before = node.get_parameter(name).value
    result = node.set_parameters([Parameter(name, value=value)])[0]
    assert not result.successful
    assert name in result.reason
    assert node.get_parameter(name).value == before
    executor.spin_for(0.05)  # the node's timers still run (an exception would surface here)


# -- rotations in the contract ---------------------------------------------------------------


def _plan():
    feet = np.array([[[0.3, 0.2, 0.0], [0.3, -0.2, 0.0]], [[0.4, 0.2, 0.0], [0.3, -0.2, 0.0]]])
    return FootstepPlan(0, ('left', 'right'), np.array([0.0, 1.0]), feet,
                        np.array([[0.0, 0.0], [0.3, 0.0]]))


def _swing():
    return SwingTrajectory('left', 0, np.array([0.0, 0.5, 1.0]),
                           np.array([[0.3, 0.2, 0.0], [0.35, 0.2, 0.1], [0.4, 0.2, 0.0]]),
                           np.array([0.0, 0.1, 0.3]))


def _com():
    return [ComState(0, np.array([0.0, 0.0, 0.8]), np.zeros(3), np.zeros(3), 0.2)]


def _rotations_of(msg):
    return [t.rotation for point in msg.points for t in point.transforms]


def _readers():
    from gait_nodes.whole_body_ik import com_track_from_msg

    return [(footsteps_to_msg(_plan()), footsteps_from_msg),
            (swing_trajectory_to_msg(_swing()), swing_trajectory_from_msg),
            (com_reference_to_msg(_com()), com_reference_from_msg),
            (com_reference_to_msg(_com()), com_track_from_msg)]


@settings(max_examples=60, deadline=None)
@given(axis=st.tuples(*[st.floats(-1, 1)] * 3), angle=st.floats(-math.pi, math.pi),
       scale=st.one_of(st.floats(0.0, 3.0), st.sampled_from([math.inf, math.nan, 1e200])))
def test_a_rotation_is_read_as_a_yaw_only_when_it_is_a_unit_quaternion(axis, angle, scale):
    """Accepted iff | |q|^2 - 1 | <= tolerance; then the yaw is the rotation matrix's yaw."""
    direction = np.array(axis)
    if np.linalg.norm(direction) < 1e-3:
        direction = np.array([0.0, 0.0, 1.0])
    quaternion = pin.Quaternion(pin.AngleAxis(angle, direction / np.linalg.norm(direction)))
    with np.errstate(all='ignore'):
        x, y, z, w = map(float, quaternion.coeffs() * scale)
    unit = math.isfinite(scale) and abs(scale * scale - 1.0) <= UNIT_QUATERNION_TOLERANCE
    for msg, reader in _readers():
        rotation = _rotations_of(msg)[-1]
        rotation.x, rotation.y, rotation.z, rotation.w = map(float, (x, y, z, w))
        if not unit:
            with pytest.raises(ContractError, match='not a unit quaternion'):
                reader(msg)
            continue
        read = reader(msg)
        if isinstance(read, list):  # ComState list
            yaw = read[-1].yaw_rad
        elif hasattr(read, 'yaws_rad'):  # FootstepPlan, SwingTrajectory
            yaw = float(np.ravel(read.yaws_rad)[-1])
        else:  # the IK's ComTrack
            yaw = read._yaws[-1]
        # The yaw of the z-y-x Euler angles of the rotation matrix (|q|^2 within 1 %: within
        # about 1 % of it; near gimbal lock the yaw is ill-defined).
        matrix = pin.Quaternion(float(w), float(x), float(y), float(z)).normalized().matrix()
        if abs(matrix[2, 0]) < 0.9:
            expected = math.atan2(matrix[1, 0], matrix[0, 0])
            assert abs(math.remainder(yaw - expected, 2 * math.pi)) < 0.05


def test_footsteps_with_an_infinite_rotation_are_dropped_by_the_simulator(robot_model):
    """The robot used to turn a foot by atan2(inf, -inf) = 3 pi / 4 and fall."""
    feet, yaws = robot_model.foot_poses(nominal_configuration(robot_model))
    names = robot_model.foot_names
    plan = FootstepPlan(0, names, np.array([0.0, 1.0]), np.array([feet, feet]),
                        np.array([yaws, yaws]))
    msg = footsteps_to_msg(plan)
    msg.points[1].transforms[0].rotation.z = math.inf
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    try:
        from gait_nodes.kinematic_simulator import KinematicSimulator

        simulator = KinematicSimulator()
        simulator._on_footsteps(msg)
        assert simulator._plan is None
        assert simulator.diagnostics.dropped == {'/gait/footsteps': 1}
    finally:
        runtime.shutdown()


# -- /joint_commands -------------------------------------------------------------------------


@pytest.fixture(scope='module')
def robot_model():
    return load_robot_model('robosimian')


@pytest.fixture
def inproc():
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    yield runtime.default_context().transport
    runtime.shutdown()


def test_odd_joint_commands_are_refused_or_held_within_the_limits(inproc, robot_model):
    """Efforts: refused. Huge, subnormal, oddly stamped (far future, negative): within limits."""
    names = list(robot_model.joint_names)
    start = robot_model.joint_positions(nominal_configuration(robot_model))
    efforts = joint_command(names, start + 0.3)
    efforts.points[0].effort = [1.0]
    far_future = joint_command(names, start)
    far_future.header.stamp.sec, far_future.header.stamp.nanosec = 2**31 - 1, 999_999_999
    negative = joint_command(names, start)
    negative.header.stamp.sec = -5
    long_ago = trajectory_msg(names, [start + 0.2, start + 0.25], times_s=[0.0, 0.01],
                              stamp_ns=1)  # over before it arrives: its last point is held
    far_end = trajectory_msg(names, [start, start + 0.3], times_s=[0.0, 1e6])
    schedule = [(NS // 10, efforts),
                (NS // 5, joint_command(names, np.full(len(names), 1e308),
                                        np.full(len(names), -1e308))),
                (NS // 5 + NS // 200, joint_command(names[:3], [-1e308] * 3, [1e308] * 3)),
                (NS // 5 + 2 * NS // 200, joint_command(names, start + 5e-324)),
                (NS // 5 + 3 * NS // 200, far_future),
                (NS // 5 + 4 * NS // 200, negative),
                (NS // 5 + 5 * NS // 200, long_ago),
                (NS // 5 + 6 * NS // 200, far_end),
                (NS // 2, joint_command(names, start))]
    simulator, collector = run_simulator(1.0, schedule)
    drops = [s for _, s in collector.statuses('input /joint_commands')]
    assert len(drops) == 1 and 'efforts' in values_of(drops[0])['reason']
    lower, upper = robot_model.lower_limits, robot_model.upper_limits
    limits = robot_model.velocity_limits_rad_s
    accelerations = robot_model.acceleration_limits_rad_s2
    states = collector.messages['/joint_states']
    period_s = 1.0 / simulator.params.rate_hz
    previous = np.zeros(len(names))
    for msg in states:
        positions = np.array(msg.position)
        assert np.all(np.isfinite(positions)) and np.all(np.isfinite(msg.velocity))
        assert np.all((positions >= lower - 1e-12) & (positions <= upper + 1e-12))
        assert np.all(np.abs(msg.velocity) <= limits * (1 + 1e-9))
        assert np.all(np.abs(np.array(msg.velocity) - previous)
                      <= accelerations * period_s * (1 + 1e-9))
        previous = np.array(msg.velocity)
    before = [np.array(m.position) for m in states if stamp_ns(m) <= NS // 5]
    for positions in before:  # the refused command moved nothing
        np.testing.assert_allclose(positions, start, atol=1e-12)


# -- swing value tables ----------------------------------------------------------------------


def test_swing_tables_with_impossible_times_or_limits_are_refused_naming_the_file(tmp_path):
    import dataclasses

    from swing_helpers import robot, tiny_table

    from gait_nodes.errors import SwingTableError
    from gait_nodes.swing.table import load_table

    table, _ = tiny_table()
    good = table.save(tmp_path / 'good.npz')
    assert load_table(good, robot()).values_s.shape == table.values_s.shape
    for name, change, fragment in (
            ('negative', {'values_s': -table.values_s}, 'values_s must be times >= 0'),
            ('lift', {'lift_s': table.lift_s - 10.0}, 'lift_s must be times >= 0'),
            ('lower', {'lower_s': -1.0}, 'lower_s must be finite and >= 0'),
            ('limit', {'joint_velocity_limit_rad_s': math.nan}, 'joint_velocity_limit_rad_s'),
            ('height', {'step_height_m': 0.0}, 'step_height_m must be finite and > 0')):
        path = tmp_path / f'{name}.npz'
        with pytest.raises(SwingTableError, match=fragment):
            dataclasses.replace(table, **change)  # the table itself refuses it
        # Written around the check (as a corrupted or hand-made file would be): refused at load.
        original = type(table).__post_init__
        try:
            type(table).__post_init__ = lambda self: None
            dataclasses.replace(table, **change).save(path)
        finally:
            type(table).__post_init__ = original
        with pytest.raises(SwingTableError, match=f'{path}: corrupt swing value table: .*'
                                                  f'{fragment}'):
            load_table(path, robot())
