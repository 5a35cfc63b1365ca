"""The contract topics of a recorded gait bag, decoded independently of inspect.

Shared by the end-to-end scenario tests.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gait_nodes import contract
from gait_nodes.bag.reader import BagReader
from gait_nodes.interfaces import deserialize_message, get_message

TYPES = {'/tf': 'tf2_msgs/msg/TFMessage', '/joint_states': 'sensor_msgs/msg/JointState',
         '/gait/footsteps': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
         '/gait/com': 'geometry_msgs/msg/PointStamped',
         '/gait/zmp': 'geometry_msgs/msg/PointStamped',
         '/gait/com_reference': 'trajectory_msgs/msg/MultiDOFJointTrajectory'}


def decode_gait_topics(bag: Path) -> dict:
    """Base poses, joint states, footstep plans, monitor COM and ZMP, COM reference.

    Returns:
        ``tf``: {stamp [ns]: (7,) base pose (x, y, z, qx, qy, qz, qw)}; ``joints``: {stamp:
        {name: position}}; ``plans``: [FootstepPlan]; ``com``, ``zmp``: [(stamp, x, y, z)];
        ``com_reference``: [(stamp, position (3), velocity (3), acceleration (3))].
    """
    data = {'tf': {}, 'joints': {}, 'plans': [], 'com': [], 'zmp': [], 'com_reference': []}
    for channel, _, _, payload in BagReader(bag).messages():
        if channel.topic not in TYPES:
            continue
        msg = deserialize_message(payload, get_message(TYPES[channel.topic]))
        if channel.topic == '/tf':
            for transform in contract.base_transforms(msg):
                t, r = transform.transform.translation, transform.transform.rotation
                data['tf'][contract.time_msg_to_ns(transform.header.stamp)] = np.array(
                    [t.x, t.y, t.z, r.x, r.y, r.z, r.w])
        elif channel.topic == '/joint_states':
            data['joints'][contract.time_msg_to_ns(msg.header.stamp)] = dict(
                zip(msg.name, msg.position, strict=True))
        elif channel.topic == '/gait/footsteps':
            data['plans'].append(contract.footsteps_from_msg(msg))
        elif channel.topic in ('/gait/com', '/gait/zmp'):
            p = msg.point
            data[channel.topic.split('/')[-1]].append(
                (contract.time_msg_to_ns(msg.header.stamp), p.x, p.y, p.z))
        else:  # a window: it replaces the held states from its first one on, as the IK's
            states = contract.com_reference_from_msg(msg)
            held = data['com_reference']
            while held and held[-1][0] >= states[0].stamp_ns:
                held.pop()
            held.extend((s.stamp_ns, *s.position_in_world, *s.velocity_in_world,
                         *s.acceleration_in_world) for s in states)
    return data
