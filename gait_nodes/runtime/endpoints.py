"""What the ROS graph knows of a topic's endpoints: rclpy's ``TopicEndpointInfo``, jazzy.

``Node.get_publishers_info_by_topic`` returns these. Over DDS a foreign endpoint's node is known
only from the ROS discovery information its process publishes (``ros_discovery_info``); rmw then
says ``_NODE_NAME_UNKNOWN_`` and ``_NODE_NAMESPACE_UNKNOWN_``, and so does the ``dds`` runtime for
endpoints outside its own process.
"""

from __future__ import annotations

from enum import IntEnum

#: rmw's names of a node it knows nothing about (rmw_dds_common's graph cache).
UNKNOWN_NODE_NAME = '_NODE_NAME_UNKNOWN_'
UNKNOWN_NODE_NAMESPACE = '_NODE_NAMESPACE_UNKNOWN_'


class TopicEndpointTypeEnum(IntEnum):
    """Kind of endpoint (rmw_endpoint_type_t)."""

    INVALID = 0
    PUBLISHER = 1
    SUBSCRIPTION = 2


class TopicEndpointInfo:
    """One publisher or subscription of a topic: its node, type, GID and QoS."""

    def __init__(self, node_name: str = '', node_namespace: str = '', topic_type: str = '',
                 topic_type_hash=None,
                 endpoint_type: TopicEndpointTypeEnum = TopicEndpointTypeEnum.INVALID,
                 endpoint_gid: list[int] | None = None, qos_profile=None):
        self.node_name = node_name
        self.node_namespace = node_namespace
        self.topic_type = topic_type
        self.topic_type_hash = topic_type_hash
        self.endpoint_type = TopicEndpointTypeEnum(endpoint_type)
        self.endpoint_gid = list(endpoint_gid or [])
        self.qos_profile = qos_profile

    def __eq__(self, other) -> bool:
        return isinstance(other, TopicEndpointInfo) and vars(self) == vars(other)

    def __repr__(self) -> str:
        return (f'TopicEndpointInfo(node_name={self.node_name!r}, '
                f'node_namespace={self.node_namespace!r}, topic_type={self.topic_type!r}, '
                f'endpoint_type={self.endpoint_type.name})')


def node_of(info) -> str | None:
    """``/namespace/name`` of an endpoint's node (rclpy's or ours), None when unknown."""
    if info.node_name == UNKNOWN_NODE_NAME or info.node_namespace == UNKNOWN_NODE_NAMESPACE:
        return None
    return info.node_namespace.rstrip('/') + '/' + info.node_name
