"""/gait/markers shows the plan: the footholds of each /gait/footsteps, the path of each swing.

The footstep planner (namespace ``footsteps``) and the swing policy (``swing_paths``) publish
on the simulator's marker topic when they publish a plan or a swing; here every such marker is
checked against the message it was published with, read back from a recorded walk (inproc), and
``publish_markers`` turns them off and on.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from gait_nodes import graph, runtime
from gait_nodes.__main__ import main as run_main
from gait_nodes.bag.reader import BagReader
from gait_nodes.contract import FootstepPlan, SwingTrajectory, time_msg_to_ns
from gait_nodes.errors import ConfigError
from gait_nodes.interfaces import deserialize_message, get_message
from gait_nodes.markers import (
    DEFAULT_FOOTHOLD_DIAMETER_M,
    footholds,
    footsteps_markers,
    swing_path_markers,
)
from gait_nodes.robot.description import example_robot_data_dir, load_robot_description
from gait_nodes.runtime import Parameter, qos_profile_latched
from gait_nodes.scenarios import get_scenario

NS = 1_000_000_000
TOPICS = ('/gait/markers', '/gait/footsteps', '/gait/swing_trajectory')
#: Scenario -> simulated seconds recorded: a few swings each (the Go2 trots: two at once).
WALKS = {'biped_walk': 4.5, 'go2_trot': 3.0}


def _xyz(vector) -> tuple[float, float, float]:
    return (vector.x, vector.y, vector.z)


def _duration_ns(duration) -> int:
    return duration.sec * NS + duration.nanosec


def footholds_of(footsteps) -> tuple[list, list]:
    """(positions, foot indices) of a /gait/footsteps message, read off its transforms.

    Every foot where the first point has it, then each place a foot moves to, point by point.
    """
    rows = [[_xyz(t.translation) for t in point.transforms] for point in footsteps.points]
    positions, feet = list(rows[0]), list(range(len(rows[0])))
    for before, after in zip(rows, rows[1:], strict=False):
        for foot, (was, now) in enumerate(zip(before, after, strict=True)):
            if math.dist(was, now) > 1e-9:
                positions.append(now)
                feet.append(foot)
    return positions, feet


def split_markers(arrays) -> dict[str, list]:
    """(time [ns], marker) by namespace; each array holds one namespace only."""
    by_namespace: dict[str, list] = {}
    for t_ns, array in arrays:
        (namespace,) = {marker.ns for marker in array.markers}
        by_namespace.setdefault(namespace, []).extend((t_ns, m) for m in array.markers)
    return by_namespace


def check_plan_markers(messages: dict, robot, swinging: bool = True) -> dict[str, list]:
    """Each footsteps and swing_paths marker is its plan's or its swing's; returns them.

    ``swinging``: swings were planned (and their paths shown); else none was.
    """
    markers = split_markers(messages['/gait/markers'])
    assert set(markers) <= {'gait', 'footsteps', 'swing_paths'}
    diameter = 2.0 * robot.foot_radius_m
    plans = messages['/gait/footsteps']
    # Each plan's footholds when it is published, and the newest plan's again once a second
    # while no new one comes.
    plan_times = [t for t, _ in plans]
    marker_times = [t for t, _ in markers['footsteps']]
    assert plans and set(plan_times) <= set(marker_times)
    shown = [max(k for k, t in enumerate(plan_times) if t <= t_ns) for t_ns in marker_times]
    for (earlier, _), (later, _), plan_before, plan_after in zip(
            markers['footsteps'], markers['footsteps'][1:], shown, shown[1:], strict=False):
        if plan_after == plan_before:
            assert later - earlier >= NS
    for (t_ns, marker), k in zip(markers['footsteps'], shown, strict=True):
        footsteps = plans[k][1]
        assert (marker.header.frame_id, marker.id, marker.type, marker.action) == \
            ('odom', 0, marker.SPHERE_LIST, marker.ADD)
        assert time_msg_to_ns(marker.header.stamp) == t_ns
        assert _duration_ns(marker.lifetime) == 0  # until the next plan replaces it
        assert (marker.scale.x, marker.scale.y) == (diameter, diameter)
        positions, feet = footholds_of(footsteps)
        assert [_xyz(p) for p in marker.points] == positions
        # One colour a foot, and a different one for each foot.
        colours = {}
        for foot, colour in zip(feet, marker.colors, strict=True):
            assert colours.setdefault(foot, colour) == colour
        assert len({(c.r, c.g, c.b) for c in colours.values()}) == len(robot.foot_names)
    swings = messages['/gait/swing_trajectory']
    if not swinging:
        assert not swings and 'swing_paths' not in markers
        return markers
    assert swings and [t for t, _ in markers['swing_paths']] == [t for t, _ in swings]
    for (t_ns, marker), (_, swing) in zip(markers['swing_paths'], swings, strict=True):
        assert (marker.header.frame_id, marker.type, marker.action) == \
            ('odom', marker.LINE_STRIP, marker.ADD)
        assert marker.id == robot.foot_names.index(swing.joint_names[0])
        assert time_msg_to_ns(marker.header.stamp) == t_ns
        assert [_xyz(p) for p in marker.points] == \
            [_xyz(point.transforms[0].translation) for point in swing.points]
        # Shown from now until a second after the touch-down.
        touch_down_ns = time_msg_to_ns(swing.header.stamp) + _duration_ns(
            swing.points[-1].time_from_start)
        assert _duration_ns(marker.lifetime) == touch_down_ns - t_ns + NS
    return markers


# -- recorded walks ---------------------------------------------------------------------------


@pytest.fixture(scope='module', params=list(WALKS))
def walk(request, tmp_path_factory):
    """(messages by topic: [(log time [ns], message)], robot) of a recorded inproc walk."""
    scenario = get_scenario(request.param)
    if scenario.robot == 'go2':
        try:
            example_robot_data_dir()
        except ConfigError:
            pytest.skip('example-robot-data is not installed (the Go2 model)')
    bag = tmp_path_factory.mktemp(request.param) / 'bag'
    assert run_main(['run', '--runtime', 'inproc', '--scenario', request.param, '--duration',
                     str(WALKS[request.param]), '--record', str(bag), '--no-plot']) == 0
    messages = {topic: [] for topic in TOPICS}
    for channel, log_ns, _, data in BagReader(bag).messages(TOPICS):
        messages[channel.topic].append(
            (log_ns, deserialize_message(data, get_message(channel.type_name))))
    return messages, load_robot_description(scenario.robot)


def test_recorded_markers_show_each_plans_footholds_and_each_swings_path(walk):
    messages, robot = walk
    markers = check_plan_markers(messages, robot)
    assert markers['gait']  # the simulator's, beside them
    if robot.name == 'go2':
        # A trot swings two feet at once: both paths show, one id a foot.
        at = {}
        for t_ns, marker in markers['swing_paths']:
            at.setdefault(t_ns, []).append(marker.id)
        assert any(len(ids) == 2 for ids in at.values())
        assert all(len(set(ids)) == len(ids) for ids in at.values())


# -- publish_markers ----------------------------------------------------------------------


class Listener(runtime.Node):
    """Sends the walk's velocity and keeps /gait/markers, the plans and the swings."""

    def __init__(self, vx_m_s: float):
        super().__init__('listener', use_global_arguments=False)
        self.messages = {topic: [] for topic in TOPICS}
        for topic in TOPICS:
            qos = qos_profile_latched if topic == '/gait/footsteps' else 1000
            self.create_subscription(get_message(graph.TOPICS[topic]), topic,
                                     self._keeper(topic), qos)
        self.cmd_vel = self.create_publisher(get_message('geometry_msgs/msg/Twist'),
                                             '/cmd_vel', 10)
        self.vx = vx_m_s
        self.create_timer(0.5, self.send_velocity)

    def _keeper(self, topic):
        return lambda msg: self.messages[topic].append(
            (self.get_clock().now().nanoseconds, msg))

    def send_velocity(self):
        """The walk's twist."""
        msg = get_message('geometry_msgs/msg/Twist')()
        msg.linear.x = self.vx
        self.cmd_vel.publish(msg)


def test_publish_markers_turns_the_plan_markers_off_and_on(tmp_path):
    scenario = get_scenario('biped_walk')
    off = {'ros__parameters': {'publish_markers': False}}
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({
        '/**': {'ros__parameters': {'robot': scenario.robot, **scenario.settings}},
        'footstep_planner': off, 'swing_leg_policy': off}))
    runtime.init(args=['test', '--ros-args', '--params-file', str(params)], runtime='inproc',
                 signal_handlers=False)
    try:
        nodes = {name: graph.load_class(graph.NODES[name])()
                 for name in graph.available_nodes()}
        listener = Listener(0.1)
        executor = runtime.SingleThreadedExecutor()
        for node in [*nodes.values(), listener]:
            executor.add_node(node)
        executor.spin_for(4.5)
        messages = listener.messages
        assert messages['/gait/footsteps'] and messages['/gait/swing_trajectory']
        assert set(split_markers(messages['/gait/markers'])) == {'gait'}
        for name in ('footstep_planner', 'swing_leg_policy'):
            refused = nodes[name].set_parameters([Parameter('publish_markers', value='yes')])
            assert not refused[0].successful
            assert nodes[name].set_parameters(
                [Parameter('publish_markers', value=True)])[0].successful
        for topic in TOPICS:
            messages[topic].clear()
        executor.spin_for(4.0)
        markers = check_plan_markers(messages, load_robot_description(scenario.robot))
        assert markers['gait'] and markers['footsteps'] and markers['swing_paths']
    finally:
        runtime.shutdown()


# -- the markers of a plan and a swing, alone -------------------------------------------------


def test_footholds_are_the_starting_places_then_each_landing():
    start = np.array([[0.0, 0.1, 0.0], [0.0, -0.1, 0.0]])
    first = start + [[0.2, 0.0, 0.0], [0.0, 0.0, 0.0]]
    second = first + [[0.0, 0.0, 0.0], [0.2, 0.0, 0.05]]
    plan = FootstepPlan(0, ('left', 'right'), np.array([0.0, 1.0, 2.0, 3.0]),
                        np.array([start, start, first, second]), np.zeros((4, 2)))
    positions, feet = footholds(plan)
    np.testing.assert_array_equal(positions, [start[0], start[1], first[0], second[1]])
    assert feet.tolist() == [0, 1, 0, 1]
    # A foot that turns where it stands takes a new foothold: the same place, another yaw.
    turned = FootstepPlan(0, ('left', 'right'), np.array([0.0, 1.0]), np.array([start, start]),
                          np.array([[0.0, 0.0], [0.3, 0.0]]))
    assert footholds(turned)[1].tolist() == [0, 1, 0]


def test_a_point_foot_gets_the_default_foothold_size_and_a_swing_lasts_past_landing():
    plan = FootstepPlan(0, ('a',), np.array([0.0]), np.zeros((1, 1, 3)), np.zeros((1, 1)))
    (marker,) = footsteps_markers(plan, 5 * NS, 0.0).markers
    assert marker.scale.x == marker.scale.y == DEFAULT_FOOTHOLD_DIAMETER_M
    swing = SwingTrajectory('a', 7 * NS, np.array([0.0, 0.25, 0.5]), np.zeros((3, 3)),
                            np.zeros(3))
    (path,) = swing_path_markers(swing, 3, 5 * NS).markers
    assert path.id == 3 and (path.lifetime.sec, path.lifetime.nanosec) == (3, 500_000_000)
    (late,) = swing_path_markers(swing, 3, 9 * NS).markers  # sent after its touch-down
    assert (late.lifetime.sec, late.lifetime.nanosec) == (1, 0)


def test_a_standing_robots_footholds_are_shown_again_each_second():
    # A display that joins while the robot stands gets the footholds within a second: the
    # standing plan is published once, its markers again every second.
    scenario = get_scenario('biped_walk')
    runtime.init(args=['test', '--ros-args', '-p', f'robot:={scenario.robot}'],
                 runtime='inproc', signal_handlers=False)
    try:
        nodes = [graph.load_class(graph.NODES[name])() for name in graph.available_nodes()]
        listener = Listener(0.0)
        executor = runtime.SingleThreadedExecutor()
        for node in [*nodes, listener]:
            executor.add_node(node)
        executor.spin_for(5.0)
        messages = listener.messages
        markers = check_plan_markers(messages, load_robot_description(scenario.robot),
                                     swinging=False)
        plans = messages['/gait/footsteps']
        assert len(markers['footsteps']) >= len(plans) + 3
        times = [t for t, _ in markers['footsteps']]
        assert max(b - a for a, b in zip(times, times[1:], strict=False)) <= NS + 10**8
    finally:
        runtime.shutdown()
