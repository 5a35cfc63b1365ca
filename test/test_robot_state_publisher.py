"""robot_state_publisher: the URDF on /robot_description, the links' frames on /tf_static and /tf.

What RViz and Foxglove need to draw the robot from a live graph or from a bag alone: every
link's pose composed from the tf tree equals Pinocchio's forward kinematics of the joint states
on the URDF, /tf_static holds every fixed joint of the URDF as its XML gives it, and the latched
topics reach late subscribers (inproc here; DDS and rclpy in their tiers).
"""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from gait_nodes import graph, runtime
from gait_nodes.contract import BASE_FRAME, WORLD_FRAME, time_msg_to_ns
from gait_nodes.diagnostics import WARN, level_value
from gait_nodes.errors import ConfigError
from gait_nodes.interfaces import get_message
from gait_nodes.robot.description import available_robots, load_robot_description
from gait_nodes.robot.link_poses import LinkPoses, quaternions_of
from gait_nodes.robot.model import RobotModel, load_robot_model
from gait_nodes.runtime import DurabilityPolicy, Parameter, QoSProfile

NS = 1_000_000_000
#: Largest error of a composed link pose [m] (translation) and of its rotation matrix entries.
TOLERANCE = 1e-9


# -- independent references --------------------------------------------------------------------

def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's ``rpy``: fixed axes x, y, z, i.e. Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch),
                              math.sin(pitch), math.cos(yaw), math.sin(yaw))
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def homogeneous(translation, rotation_xyzw) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_matrix(*rotation_xyzw)
    matrix[:3, 3] = translation
    return matrix


def urdf_joints(urdf_path) -> list[dict]:
    """The URDF's joints as its XML states them: name, type, parent, child, origin (4 x 4)."""
    joints = []
    for joint in ET.parse(urdf_path).getroot().findall('joint'):
        origin = joint.find('origin')
        xyz = [float(v) for v in (origin.get('xyz', '0 0 0') if origin is not None
                                  else '0 0 0').split()]
        rpy = [float(v) for v in (origin.get('rpy', '0 0 0') if origin is not None
                                  else '0 0 0').split()]
        matrix = np.eye(4)
        matrix[:3, :3] = rpy_matrix(*rpy)
        matrix[:3, 3] = xyz
        joints.append({'name': joint.get('name'), 'type': joint.get('type'),
                       'parent': joint.find('parent').get('link'),
                       'child': joint.find('child').get('link'), 'origin': matrix})
    return joints


def tf_tree(transforms) -> dict[str, tuple[str, np.ndarray]]:
    """The tree ``{child frame: (parent frame, 4 x 4)}`` of ``(parent, child, t, xyzw)`` rows."""
    return {child: (parent, homogeneous(t, q)) for parent, child, t, q in transforms}


def pose_in(tree: dict, frame: str, root: str) -> np.ndarray:
    """``frame``'s pose in ``root``, composed up the tree (KeyError if the chain breaks)."""
    pose = np.eye(4)
    while frame != root:
        parent, transform = tree[frame]
        pose = transform @ pose
        frame = parent
    return pose


def rows_of(transforms) -> list[tuple]:
    """(parent, child, translation, xyzw) rows of a LinkTransforms."""
    return list(zip(transforms.parents, transforms.children, transforms.translations_m,
                    transforms.rotations_xyzw, strict=True))


def message_rows(msg) -> list[tuple]:
    """(parent, child, translation, xyzw) rows of a TFMessage."""
    rows = []
    for t in msg.transforms:
        p, r = t.transform.translation, t.transform.rotation
        rows.append((t.header.frame_id, t.child_frame_id, [p.x, p.y, p.z], [r.x, r.y, r.z, r.w]))
    return rows


def body_poses(robot, q) -> dict[str, np.ndarray]:
    """Pinocchio's world pose of every link (body frame) at ``q`` (free-flyer base)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return {frame.name: data.oMf[k].homogeneous for k, frame in enumerate(robot.model.frames)
            if frame.type == pin.FrameType.BODY}


def assert_same_pose(composed: np.ndarray, expected: np.ndarray, what: str) -> None:
    assert np.abs(composed[:3, 3] - expected[:3, 3]).max() < TOLERANCE, what
    assert np.abs(composed[:3, :3] - expected[:3, :3]).max() < TOLERANCE, what


# -- the core ----------------------------------------------------------------------------------

@pytest.mark.parametrize('rotation', [
    np.eye(3), rpy_matrix(math.pi, 0, 0), rpy_matrix(0, math.pi, 0), rpy_matrix(0, 0, math.pi),
    rpy_matrix(math.pi - 1e-9, 0.2, -0.1), rpy_matrix(0.3, -1.2, 2.9), rpy_matrix(-2, 0.7, -3),
], ids=['identity', 'x180', 'y180', 'z180', 'near-x180', 'a', 'b'])
def test_quaternions_give_back_the_rotation_on_every_branch(rotation):
    transform = np.eye(4)
    transform[:3, :3] = rotation
    [quaternion] = quaternions_of(transform[None])
    assert quaternion[3] >= 0 and abs(np.linalg.norm(quaternion) - 1) < 1e-15
    assert np.abs(quaternion_matrix(*quaternion) - rotation).max() < 1e-14


@pytest.mark.parametrize('name', available_robots())
def test_every_link_composed_from_the_transforms_is_where_pinocchio_puts_it(name):
    """All links, random joint positions and base pose: the tf chain equals forward kinematics."""
    robot = load_robot_model(name)
    poses = LinkPoses(robot)
    urdf_links = {link.get('name') for link in
                  ET.parse(robot.description.urdf_path).getroot().findall('link')}
    rng = np.random.default_rng(28)
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -math.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, math.pi)
    for _ in range(4):
        joints = rng.uniform(lower, upper)
        q = pin.neutral(robot.model)
        q[:3] = rng.uniform(-5, 5, 3)
        q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(*rng.uniform(-0.5, 0.5, 3))).coeffs()
        robot.set_joint_positions(q, joints)
        base = (WORLD_FRAME, BASE_FRAME, q[:3], q[3:7])
        moving = poses.moving(robot.joint_names, joints)
        tree = tf_tree([base, *rows_of(poses.static), *rows_of(moving)])
        # The frames are the URDF's links (base_link among them, bridged when not the root).
        assert set(tree) == urdf_links | {BASE_FRAME}
        for link, expected in body_poses(robot, q).items():
            assert_same_pose(pose_in(tree, link, WORLD_FRAME), expected, link)


@pytest.mark.parametrize('name', available_robots())
def test_static_transforms_are_the_fixed_joints_of_the_urdf(name):
    robot = load_robot_model(name)
    poses = LinkPoses(robot)
    fixed = [j for j in urdf_joints(robot.description.urdf_path) if j['type'] == 'fixed']
    by_child = {child: k for k, child in enumerate(poses.static.children)}
    bridged = robot.description.base_frame != BASE_FRAME
    assert len(poses.static) == len(fixed) + bridged
    for joint in fixed:
        k = by_child[joint['child']]
        assert (poses.static.joints[k], poses.static.parents[k]) == (joint['name'],
                                                                    joint['parent'])
        published = homogeneous(poses.static.translations_m[k], poses.static.rotations_xyzw[k])
        assert np.abs(published - joint['origin']).max() < 1e-12, joint['name']
    moving = {j['name'] for j in urdf_joints(robot.description.urdf_path)
              if j['type'] != 'fixed'}
    assert set(poses.moving_joints) == moving
    if bridged:  # the Go2's root link is 'base': base_link -> base, identity
        k = by_child[robot.description.base_frame]
        assert poses.static.parents[k] == BASE_FRAME
        assert np.array_equal(poses.static.translations_m[k], np.zeros(3))
        assert np.array_equal(poses.static.rotations_xyzw[k], [0.0, 0.0, 0.0, 1.0])


def test_only_the_named_moving_joints_get_a_transform_and_unknown_names_are_ignored():
    robot = load_robot_model('biped')
    poses = LinkPoses(robot)
    named = [robot.joint_names[5], 'no_such_joint', robot.joint_names[2]]
    moving = poses.moving(named, [0.3, 7.0, -0.2])
    assert set(moving.joints) == {robot.joint_names[2], robot.joint_names[5]}
    every = poses.moving(robot.joint_names, np.zeros(len(robot.joint_names)))
    assert len(every) == len(robot.joint_names)


def biped_variant(tmp_path, change) -> RobotModel:
    """The biped with its URDF text changed by ``change(text) -> text``, and its YAML's."""
    description = load_robot_description('biped')
    urdf = tmp_path / 'variant.urdf'
    urdf.write_text(change(description.urdf_path.read_text()))
    data = yaml.safe_load(description.path.read_text())
    data['urdf'] = str(urdf)
    if 'name="pelvis"' in urdf.read_text():
        data['base_frame'] = 'pelvis'
    path = tmp_path / 'variant.yaml'
    path.write_text(yaml.safe_dump(data))
    return RobotModel(load_robot_description(path))


@pytest.mark.parametrize(('change', 'reason'), [
    (lambda text: text.replace('"torso"', '"base_link"').replace('"base_link"', '"pelvis"', 1)
     .replace('<parent link="base_link"/>', '<parent link="pelvis"/>'),
     "link 'base_link' is not the root link \\('pelvis'\\)"),
    (lambda text: text.replace('name="torso_joint" type="fixed"',
                               'name="torso_joint" type="planar"'),
     "joint 'torso_joint' has 3 degrees of freedom"),
], ids=['base_link-not-the-root', 'planar-joint'])
def test_a_urdf_whose_frames_cannot_be_published_is_refused_with_the_reason(tmp_path, change,
                                                                           reason):
    robot = biped_variant(tmp_path, change)
    with pytest.raises(ConfigError, match=reason):
        LinkPoses(robot)


# -- the node ----------------------------------------------------------------------------------

class JointStatesSource(runtime.Node):
    """Publishes the given /joint_states messages; keeps what the state publisher says."""

    def __init__(self):
        super().__init__('joint_states_source', use_global_arguments=False)
        self.joint_states = self.create_publisher(get_message('sensor_msgs/msg/JointState'),
                                                  'joint_states', 10)
        self.tf, self.diagnostics = [], []
        self.create_subscription(get_message('tf2_msgs/msg/TFMessage'), '/tf',
                                 self.tf.append, 100)
        self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics', self.diagnostics.append, 100)

    def send(self, names, positions, stamp_ns: int) -> None:
        """Publish one /joint_states message stamped ``stamp_ns``."""
        msg = get_message('sensor_msgs/msg/JointState')()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, NS)
        msg.name, msg.position = list(names), [float(p) for p in positions]
        self.joint_states.publish(msg)


@pytest.fixture
def state_publisher():
    """An inproc robot_state_publisher (biped) and a source of /joint_states."""
    from gait_nodes.robot_state_publisher import RobotStatePublisher

    runtime.init(args=['test', '--ros-args', '-p', 'robot:=biped', '-p',
                       'publish_frequency:=0.0'], runtime='inproc', signal_handlers=False)
    try:
        node, source = RobotStatePublisher(), JointStatesSource()
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        executor.add_node(source)
        yield node, source, executor
    finally:
        runtime.shutdown()


def test_each_joint_state_gives_one_tf_message_with_its_own_stamp(state_publisher):
    node, source, executor = state_publisher
    names = node.poses.robot.joint_names
    stamps = [3 * NS + 7, 3 * NS + 10_000_007, 2 * NS]  # out of order: time is in the data
    for k, stamp in enumerate(stamps):
        source.send(names, np.full(len(names), 0.1 * k), stamp)
    executor.spin_for(0.01)
    assert [{time_msg_to_ns(t.header.stamp) for t in m.transforms} for m in source.tf] == \
        [{s} for s in stamps]
    assert all(len(m.transforms) == len(names) for m in source.tf)
    assert not any(t.child_frame_id == BASE_FRAME for m in source.tf for t in m.transforms)


def test_publish_frequency_bounds_the_rate_by_the_stamps_as_ros_does(state_publisher):
    node, source, executor = state_publisher
    assert node.set_parameters([Parameter('publish_frequency', value=20.0)])[0].successful
    names = node.poses.robot.joint_names
    for k in range(20):  # 100 Hz of stamps for 0.2 s
        source.send(names, np.zeros(len(names)), 5 * NS + k * NS // 100)
    executor.spin_for(0.01)
    published = [time_msg_to_ns(m.transforms[0].header.stamp) - 5 * NS for m in source.tf]
    assert published == [0, 50_000_000, 100_000_000, 150_000_000]
    for value in (-1.0, math.inf, 20000.0):
        result = node.set_parameters([Parameter('publish_frequency', value=value)])[0]
        assert not result.successful and '[0.0, 10000.0]' in result.reason
    result = node.set_parameters([Parameter('robot', value='go2')])[0]
    assert not result.successful and 'fixed at start' in result.reason


def test_a_joint_state_that_breaks_its_contract_is_dropped_and_reported(state_publisher):
    node, source, executor = state_publisher
    names = list(node.poses.robot.joint_names)
    source.send(names[:3], [0.0, math.nan, 0.1], NS)
    source.send([names[0], names[0]], [0.0, 0.1], NS)
    bad = get_message('sensor_msgs/msg/JointState')(name=names[:2], position=[0.0])
    source.joint_states.publish(bad)
    source.send(names[:2], [0.0, 0.1], 2 * NS)
    executor.spin_for(0.01)
    assert len(source.tf) == 1 and len(source.tf[0].transforms) == 2
    reports = [s for array in source.diagnostics for s in array.status
               if s.name == 'robot_state_publisher: input /joint_states']
    assert [level_value(s.level) for s in reports] == [WARN] * 3
    reasons = [s.message for s in reports]
    assert names[1] in reasons[0] and 'not finite' in reasons[0]
    assert 'repeated' in reasons[1] and '1 positions for 2 joint names' in reasons[2]


def test_a_late_subscriber_gets_the_urdf_and_the_static_transforms(state_publisher):
    node, source, executor = state_publisher
    executor.spin_for(0.5)
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    late = runtime.Node('late', use_global_arguments=False)
    descriptions, statics = [], []
    late.create_subscription(get_message('std_msgs/msg/String'), 'robot_description',
                             descriptions.append, latched)
    late.create_subscription(get_message('tf2_msgs/msg/TFMessage'), '/tf_static',
                             statics.append, latched)
    executor.add_node(late)
    executor.spin_for(0.01)
    assert [d.data for d in descriptions] == [node.urdf_path.read_text()]
    assert len(statics) == 1
    assert [child for _, child, *_ in message_rows(statics[0])] == \
        list(node.poses.static.children)
    offered = [info.qos_profile for topic in ('/robot_description', '/tf_static')
               for info in late.get_publishers_info_by_topic(topic)]
    assert len(offered) == 2
    assert all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL and p.depth == 1
               for p in offered)


# -- a recorded walk ---------------------------------------------------------------------------

#: Simulated seconds of the recorded motion: the simulator's first 1 s diagnostics summary in.
RECORDED_S = 1.2


class SwayingJoints(runtime.Node):
    """Commands every joint through a sinusoid within its limits, once, at the start."""

    def __init__(self, robot):
        super().__init__('swaying_joints', use_global_arguments=False)
        publisher = self.create_publisher(get_message('trajectory_msgs/msg/JointTrajectory'),
                                          'joint_commands', 10)
        rng = np.random.default_rng(7)
        phases = rng.uniform(0, 2 * math.pi, len(robot.joint_names))
        times = np.arange(1, 13) * 0.1
        rows = robot.posture + 0.3 * np.sin(2 * math.pi * times[:, None] / RECORDED_S + phases)
        rows = np.clip(rows, robot.lower_limits, robot.upper_limits)
        msg = get_message('trajectory_msgs/msg/JointTrajectory')()
        msg.joint_names = list(robot.joint_names)
        point = get_message('trajectory_msgs/msg/JointTrajectoryPoint')
        for t, row in zip(times, rows, strict=True):
            msg.points.append(point(positions=row.tolist(), time_from_start=get_message(
                'builtin_interfaces/msg/Duration')(sec=0, nanosec=int(round(t * NS)))))
        self._send = [(publisher, msg)]
        self.create_timer(0.05, self._once)

    def _once(self) -> None:
        while self._send:
            publisher, msg = self._send.pop()
            publisher.publish(msg)


def record(bag, simulator: str, seconds: float) -> tuple[dict, dict]:
    """A simulator, robot_state_publisher, SwayingJoints and the recorder, inproc (RoboSimian).

    Returns:
        ({topic: [message]}, {topic: [offered QoS]}), read with rosbags (not our reader).
    """
    from rosbags.highlevel import AnyReader

    from gait_nodes.robot_state_publisher import RobotStatePublisher

    runtime.init(args=['test'], runtime='inproc', signal_handlers=False)
    try:
        executor = runtime.SingleThreadedExecutor()
        for node in (graph.load_class(graph.node_path(simulator))(), RobotStatePublisher(),
                     SwayingJoints(load_robot_model('robosimian')),
                     graph.load_class(graph.RECORDER)(output=str(bag))):
            executor.add_node(node)
        executor.spin_for(seconds)
    finally:
        runtime.shutdown()
    messages: dict[str, list] = {}
    with AnyReader([bag]) as reader:
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
        for connection, _, raw in reader.messages():
            messages.setdefault(connection.topic, []).append(
                reader.deserialize(raw, connection.msgtype))
    return messages, qos


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """(bag, robot, messages, offered QoS): the kinematic simulator's RECORDED_S."""
    bag = tmp_path_factory.mktemp('state_publisher') / 'bag'
    return bag, load_robot_model('robosimian'), *record(bag, 'kinematic_simulator', RECORDED_S)


def assert_links_follow_forward_kinematics(robot, messages, samples: int) -> None:
    """At ``samples`` /joint_states across the bag: every link, /tf + /tf_static vs Pinocchio."""
    [static] = messages['/tf_static']
    by_stamp: dict[int, list] = {}
    for msg in messages['/tf']:
        for row, transform in zip(message_rows(msg), msg.transforms, strict=True):
            by_stamp.setdefault(time_msg_to_ns(transform.header.stamp), []).append(row)
    published = {time_msg_to_ns(m.transforms[0].header.stamp) for m in messages['/tf']
                 if m.transforms[0].child_frame_id != BASE_FRAME}
    states = [s for s in messages['/joint_states']
              if time_msg_to_ns(s.header.stamp) in published]
    assert len(states) >= samples
    for state in states[::max(len(states) // samples, 1)]:
        stamp = time_msg_to_ns(state.header.stamp)
        tree = tf_tree([*message_rows(static), *by_stamp[stamp]])
        _, base = tree[BASE_FRAME]
        q = pin.neutral(robot.model)
        q[:3] = base[:3, 3]
        q[3:7] = pin.Quaternion(base[:3, :3]).coeffs()
        joints = np.zeros(len(robot.joint_names))
        joints[robot.indices(list(state.name))] = state.position
        robot.set_joint_positions(q, joints)
        expected = body_poses(robot, q)
        assert len(expected) == len(tree)  # every link (base_link included) has a frame
        for link, pose in expected.items():
            assert_same_pose(pose_in(tree, link, WORLD_FRAME), pose, f'{link} at {stamp}')


def test_the_bag_holds_the_urdf_file_and_every_fixed_joint_once(recorded):
    bag, robot, messages, _ = recorded
    [description] = messages['/robot_description']
    assert description.data.encode() == robot.description.urdf_path.read_bytes()
    [static] = messages['/tf_static']
    fixed = {(j['parent'], j['child']): j['origin']
             for j in urdf_joints(robot.description.urdf_path) if j['type'] == 'fixed'}
    rows = message_rows(static)
    assert {(parent, child) for parent, child, *_ in rows} == set(fixed)
    for parent, child, t, q in rows:
        assert np.abs(homogeneous(t, q) - fixed[parent, child]).max() < 1e-12


def test_the_latched_topics_are_recorded_with_their_transient_local_qos(recorded):
    """In metadata.yaml (ros2 bag play, rosbags) and in the .mcap's channels (Foxglove)."""
    from mcap.reader import make_reader

    bag, _, _, qos = recorded
    for topic in ('/robot_description', '/tf_static'):
        [profile] = qos[topic]
        assert (profile.durability.name, profile.reliability.name, profile.depth) == \
            ('TRANSIENT_LOCAL', 'RELIABLE', 1), topic
    (mcap_path,) = bag.glob('*.mcap')
    with open(mcap_path, 'rb') as stream:
        channels = make_reader(stream).get_summary().channels.values()
    in_mcap = {c.topic: yaml.safe_load(c.metadata['offered_qos_profiles']) for c in channels}
    assert in_mcap['/tf_static'][0]['durability'] == 'transient_local'
    assert in_mcap['/robot_description'][0]['durability'] == 'transient_local'
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    # Version 9 (Jazzy): a list of profiles; channel metadata in the .mcap: the same as text.
    offered = {entry['topic_metadata']['name']: entry['topic_metadata']['offered_qos_profiles']
               for entry in info['topics_with_message_count']}
    for topic in ('/robot_description', '/tf_static'):
        [profile] = offered[topic]
        assert (profile['durability'], profile['reliability'], profile['depth']) == \
            ('transient_local', 'reliable', 1), topic
    assert offered['/tf'][0]['durability'] == 'volatile'


def test_every_link_in_the_bag_is_where_forward_kinematics_of_its_joint_states_puts_it(
        recorded):
    """At samples across the bag: /tf (both publishers) + /tf_static, all links, to 1e-9 m."""
    _, robot, messages, _ = recorded
    states = messages['/joint_states']
    assert len(states) >= 100 * RECORDED_S - 2
    # robot_state_publisher's /tf: at the stamps of /joint_states messages at least 1 /
    # publish_frequency (20 Hz: 50 ms) apart, as ROS's node has it.
    link_messages = [m for m in messages['/tf'] if m.transforms[0].child_frame_id != BASE_FRAME]
    expected = []
    for stamp in (time_msg_to_ns(s.header.stamp) for s in states):
        if not expected or stamp - expected[-1] >= NS // 20:
            expected.append(stamp)
    assert [time_msg_to_ns(m.transforms[0].header.stamp) for m in link_messages] == expected
    assert len(expected) >= 20 * RECORDED_S - 1
    first = np.array(states[0].position)
    assert max(np.abs(np.array(s.position) - first).max() for s in states) > 0.1  # it moved
    assert_links_follow_forward_kinematics(robot, messages, samples=6)


@pytest.fixture(scope='module')
def physics_recorded(tmp_path_factory):
    """{topic: [message]} of the physics simulator's first second (one diagnostics summary)."""
    pytest.importorskip('mujoco')
    bag = tmp_path_factory.mktemp('state_publisher_physics') / 'bag'
    return record(bag, 'physics_simulator', 1.05)[0]


def test_the_links_follow_the_physics_simulator_too(physics_recorded):
    assert len(physics_recorded['/joint_states']) >= 100
    assert_links_follow_forward_kinematics(load_robot_model('robosimian'), physics_recorded,
                                           samples=3)


# -- over DDS ----------------------------------------------------------------------------------

def test_over_dds_a_late_subscriber_gets_the_urdf_and_the_static_transforms(tmp_path,
                                                                            monkeypatch):
    """The node process publishes both at start; a subscriber made afterwards still gets them."""
    import random
    import signal
    import subprocess
    import sys
    import time

    from test_runtime_dds import dds_env

    from gait_nodes.cli import READY_FILE_ENV

    domain = random.SystemRandom().randrange(200, 230)
    ready = tmp_path / 'ready'
    process = subprocess.Popen(
        [sys.executable, '-m', 'gait_nodes.robot_state_publisher', '--ros-args', '-p',
         'robot:=go2'], env={**dds_env(domain), READY_FILE_ENV: str(ready)},
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    try:
        deadline = time.monotonic() + 60.0
        while not ready.exists():
            assert process.poll() is None, process.stderr.read()
            assert time.monotonic() < deadline, 'robot_state_publisher not up after 60 s'
            time.sleep(0.05)
        runtime.init(args=[], runtime='dds', domain_id=domain, signal_handlers=False)
        try:
            late = runtime.Node('late_subscriber')
            latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
            descriptions, statics = [], []
            late.create_subscription(get_message('std_msgs/msg/String'), '/robot_description',
                                     descriptions.append, latched)
            late.create_subscription(get_message('tf2_msgs/msg/TFMessage'), '/tf_static',
                                     statics.append, latched)
            executor = runtime.SingleThreadedExecutor()
            executor.add_node(late)
            deadline = time.monotonic() + 20.0
            while not (descriptions and statics) and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
        finally:
            runtime.shutdown()
    finally:
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=20) == 0
    robot = load_robot_model('go2')
    assert [d.data for d in descriptions] == [robot.description.urdf_path.read_text()]
    [static] = statics
    fixed = {j['child'] for j in urdf_joints(robot.description.urdf_path) if j['type'] == 'fixed'}
    assert {child for _, child, *_ in message_rows(static)} == fixed | {'base'}


# -- the launcher ------------------------------------------------------------------------------

def test_run_starts_the_state_publisher_unless_told_not_to(capsys):
    import json

    from gait_nodes.__main__ import _selected_nodes, build_parser, main

    assert main(['run', '--fast', '--duration', '0.5', '--json', '--nodes',
                 'kinematic_simulator,robot_state_publisher']) == 0
    topics = json.loads(capsys.readouterr().out)['topics']
    assert topics['/robot_description']['messages'] == topics['/tf_static']['messages'] == 1
    # The simulator's odom -> base_link per /joint_states, the links' for one in five (20 Hz).
    states = topics['/joint_states']['messages']
    assert topics['/tf']['messages'] == states + math.ceil(states / 5)

    assert main(['run', '--fast', '--duration', '0.5', '--json', '--nodes',
                 'kinematic_simulator']) == 0
    without = json.loads(capsys.readouterr().out)['topics']
    assert '/robot_description' not in without
    assert without['/tf']['messages'] == without['/joint_states']['messages']
    for simulator in graph.SIMULATORS:
        chosen = _selected_nodes(build_parser().parse_args(['run', '--simulator', simulator]))
        assert chosen[-1] == graph.STATE_PUBLISHER
        assert _selected_nodes(build_parser().parse_args(
            ['run', '--simulator', simulator, '--no-state-publisher'])) == chosen[:-1]


# -- the layouts -------------------------------------------------------------------------------

CONFIG = Path(__file__).resolve().parent.parent / 'config'
#: A diagnostics filter of a Foxglove message path: ``{name=="..."}`` or ``{key=="..."}``.
FILTER = re.compile(r'\{(name|key)=="([^"]*)"\}')
#: RViz display class -> the message type it draws.
RVIZ_TYPES = {'rviz_default_plugins/RobotModel': 'std_msgs/msg/String',
              'rviz_default_plugins/MarkerArray': 'visualization_msgs/msg/MarkerArray',
              'rviz_default_plugins/Path': 'nav_msgs/msg/Path'}


def foxglove_topics(layout: dict) -> set[str]:
    """Every topic a Foxglove layout names: 3D topics and layers, message paths, panels'."""
    topics = set()
    for config in layout['configById'].values():
        topics |= set(config.get('topics', {}))
        topics |= {layer['topic'] for layer in config.get('layers', {}).values()
                   if layer.get('topic')}
        topics |= {re.match(r'/[\w/]+', path['value'])[0] for path in config.get('paths', [])}
        if 'topicToRender' in config:
            topics.add(config['topicToRender'])
    return topics


def status_keys(*bags: dict) -> set[tuple[str, str]]:
    """(status name, key) of every /diagnostics key value in the bags."""
    return {(status.name, value.key) for messages in bags for array in messages['/diagnostics']
            for status in array.status for value in status.values}


def test_the_foxglove_layout_names_only_what_the_graph_publishes(recorded, physics_recorded):
    layout = json.loads((CONFIG / 'foxglove_layout.json').read_text())
    topics = foxglove_topics(layout)
    assert {'/robot_description', '/gait/markers', '/diagnostics', '/joint_states'} <= topics
    assert topics <= set(graph.TOPICS), topics - set(graph.TOPICS)
    scene = layout['configById']['3D!gait']
    assert scene['followTf'] == BASE_FRAME
    assert {layer.get('frameId') for layer in scene['layers'].values()} - {None} == {WORLD_FRAME}
    # Each plotted diagnostics value is a key value that a simulator publishes, under its name.
    published = status_keys(recorded[2], physics_recorded)
    paths = [path['value'] for config in layout['configById'].values()
             for path in config.get('paths', []) if path['value'].startswith('/diagnostics')]
    assert paths
    for path in paths:
        filters = dict(FILTER.findall(path))
        assert (filters['name'], filters['key']) in published, path


def test_the_rviz_config_draws_the_graph_topics_in_odom():
    config = yaml.safe_load((CONFIG / 'gait.rviz').read_text())['Visualization Manager']
    assert config['Global Options']['Fixed Frame'] == WORLD_FRAME
    assert config['Views']['Current']['Target Frame'] == BASE_FRAME
    displays = {display['Class']: display for display in config['Displays']}
    assert {'rviz_default_plugins/RobotModel', 'rviz_default_plugins/TF',
            'rviz_default_plugins/MarkerArray'} <= set(displays)
    for kind, type_name in RVIZ_TYPES.items():
        display = displays[kind]
        subscription = display.get('Description Topic') or display['Topic']
        topic = subscription['Value']
        assert graph.TOPICS.get(topic) == type_name, (kind, topic)
        # A volatile subscription would never get a latched topic's one message.
        latched = topic in graph.LATCHED_TOPICS
        assert (subscription['Durability Policy'] == 'Transient Local') == latched, topic
