"""A synthetic gait bag whose every metric is known by construction (shared by the bag tests).

Ten seconds at 100 Hz of the contract topics:

- the base walks along x at 0.1 m/s (``/tf``);
- the support polygon is the rectangle x in [-0.2, 1.2], y in [-0.3, 0.3];
- the ZMP is at (0.1 t, 0) except during [5, 6) s, when it is at y = 0.4 (0.1 m outside);
- two joints of the fixture quadruped (limit 1 rad/s) move with velocity amplitudes 0.8 and
  1.2 rad/s;
- three gait commands were answered, one rejected; diagnostics carry OK, WARN and one ERROR;
- one footstep plan with two swings of 0.3 m and 0.2 m.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from gait_nodes import contract
from gait_nodes.bag.writer import BagWriter
from gait_nodes.diagnostics import ERROR, OK, WARN, make_status
from gait_nodes.graph import TOPICS
from gait_nodes.interfaces import get_message, serialize_message
from gait_nodes.runtime.qos import QoSProfile, offered_qos_yaml, qos_profile_latched

ROBOT = Path(__file__).parent / 'data' / 'robots' / 'quadruped.yaml'
START_NS = 1_700_000_000_000_000_000
RATE_HZ = 100
SECONDS = 10
POLYGON = [(-0.2, -0.3), (1.2, -0.3), (1.2, 0.3), (-0.2, 0.3)]
JOINTS = ['fl_1', 'fl_2']
AMPLITUDES = [0.8, 1.2]
STATUSES = [{'accepted': True, 'reason': '', 'params': {}},
            {'accepted': False, 'reason': 'step_length_m: must be in (0, 0.5], got 0.9',
             'params': {}},
            {'accepted': True, 'reason': '', 'params': {}}]


def zmp_y(t: float) -> float:
    return 0.4 if 5.0 <= t < 6.0 else 0.0


def expected_margin(x: float, y: float) -> float:
    """Signed distance to the axis-aligned rectangle POLYGON (as an independent formula)."""
    inside = min(x + 0.2, 1.2 - x, y + 0.3, 0.3 - y)
    if inside >= 0:
        return inside
    dx = max(-0.2 - x, 0.0, x - 1.2)
    dy = max(-0.3 - y, 0.0, y - 0.3)
    return -math.hypot(dx, dy)


def footstep_plan() -> contract.FootstepPlan:
    stance = np.array([[0.5, 0.5, 0], [0.5, -0.5, 0], [-0.5, 0.5, 0], [-0.5, -0.5, 0]])
    positions = np.repeat(stance[None], 5, axis=0)
    positions[2:, 0, 0] += 0.3  # front_left lands 0.3 m ahead at 2 s
    positions[4:, 3, 0] += 0.2  # rear_right lands 0.2 m ahead at 4 s
    return contract.FootstepPlan(START_NS, ('front_left', 'front_right', 'rear_left',
                                            'rear_right'),
                                 [0.0, 1.0, 2.0, 3.0, 4.0], positions, np.zeros((5, 4)))


def messages():
    """``(topic, stamp_ns, message)`` in time order."""
    msg = get_message
    yield '/gait/footsteps', START_NS, contract.footsteps_to_msg(footstep_plan())
    for k in range(SECONDS * RATE_HZ):
        t = k / RATE_HZ
        stamp_ns = START_NS + k * 1_000_000_000 // RATE_HZ
        stamp = contract.ns_to_time_msg(stamp_ns)
        tf = msg('tf2_msgs/msg/TFMessage')()
        transform = msg('geometry_msgs/msg/TransformStamped')()
        transform.header.stamp, transform.header.frame_id = stamp, 'odom'
        transform.child_frame_id = 'base_link'
        transform.transform.translation.x = 0.1 * t
        transform.transform.translation.z = 0.65
        transform.transform.rotation.w = 1.0
        tf.transforms = [transform]
        yield '/tf', stamp_ns, tf
        polygon = msg('geometry_msgs/msg/PolygonStamped')()
        polygon.header.stamp, polygon.header.frame_id = stamp, 'odom'
        points = []
        for x, y in POLYGON:
            point = msg('geometry_msgs/msg/Point32')()
            point.x, point.y = x, y
            points.append(point)
        polygon.polygon.points = points
        yield '/gait/support_polygon', stamp_ns, polygon
        zmp = msg('geometry_msgs/msg/PointStamped')()
        zmp.header.stamp, zmp.header.frame_id = stamp, 'odom'
        zmp.point.x, zmp.point.y = 0.1 * t, zmp_y(t)
        yield '/gait/zmp', stamp_ns, zmp
        com = msg('geometry_msgs/msg/PointStamped')()
        com.header.stamp, com.header.frame_id = stamp, 'odom'
        com.point.x, com.point.z = 0.1 * t, 0.6
        yield '/gait/com', stamp_ns, com
        joints = msg('sensor_msgs/msg/JointState')()
        joints.header.stamp = stamp
        joints.name = list(JOINTS)
        joints.position = [a * math.sin(2 * t) / 2 for a in AMPLITUDES]
        joints.velocity = [a * math.cos(2 * t) for a in AMPLITUDES]
        yield '/joint_states', stamp_ns, joints
        if k % 100 == 0:
            array = msg('diagnostic_msgs/msg/DiagnosticArray')()
            array.header.stamp = stamp
            level = ERROR if k == 500 else (WARN if k == 300 else OK)
            array.status = [make_status('kinematic_simulator: stability', level,
                                        f'level {level}', {'margin_m': 0.1}, 'test_quadruped')]
            yield '/diagnostics', stamp_ns, array
        if k in (100, 200, 300):
            status = msg('std_msgs/msg/String')(data=json.dumps(STATUSES[k // 100 - 1]))
            yield '/gait/command_status', stamp_ns, status


def write_gait_bag(path: Path, **writer_options) -> Path:
    """Write the synthetic gait bag to the directory ``path``; returns it."""
    with BagWriter(path, **writer_options) as writer:
        for topic, type_name in TOPICS.items():
            profile = qos_profile_latched if topic == '/gait/footsteps' else QoSProfile()
            writer.add_topic(topic, type_name, [offered_qos_yaml(profile)])
        for topic, stamp_ns, message in messages():
            writer.write(topic, serialize_message(message), stamp_ns)
    return path
