"""Quality of service, with rclpy's names and defaults (reliable, keep-last, volatile)."""

from __future__ import annotations

import dataclasses
import enum

from gait_nodes.errors import GaitNodesError


class ReliabilityPolicy(enum.IntEnum):
    """Delivery guarantee."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(enum.IntEnum):
    """Whether late joiners get earlier samples (transient local: the ROS 2 'latched' topic)."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(enum.IntEnum):
    """How many samples are kept."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclasses.dataclass
class QoSProfile:
    """A QoS profile; ``QoSProfile(depth=10)`` is rclpy's default for an int argument."""

    depth: int = 10
    history: HistoryPolicy = HistoryPolicy.KEEP_LAST
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE

    def __post_init__(self):
        if self.history == HistoryPolicy.KEEP_LAST and self.depth < 1:
            raise GaitNodesError(
                f'QoS depth must be >= 1 with keep-last history, got {self.depth}')


qos_profile_system_default = QoSProfile()
qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
#: What ROS 2 calls a latched topic: late subscribers get the last sample.
qos_profile_latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def as_profile(qos_or_depth) -> QoSProfile:
    """Rclpy's rule: an int is a keep-last depth with the default profile."""
    if isinstance(qos_or_depth, QoSProfile):
        return qos_or_depth
    if isinstance(qos_or_depth, int) and not isinstance(qos_or_depth, bool):
        return QoSProfile(depth=qos_or_depth)
    raise GaitNodesError(f'qos_profile must be a QoSProfile or an int depth, got {qos_or_depth!r}')


def offered_qos_yaml(profile: QoSProfile) -> dict:
    """The profile as rosbag2 writes it in ``offered_qos_profiles`` (Jazzy field names)."""
    infinite = {'sec': 2147483647, 'nsec': 4294967295}
    return {
        'history': 'keep_last' if profile.history == HistoryPolicy.KEEP_LAST else 'keep_all',
        'depth': profile.depth,
        'reliability': 'reliable' if profile.reliability == ReliabilityPolicy.RELIABLE
        else 'best_effort',
        'durability': 'transient_local' if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        else 'volatile',
        'deadline': dict(infinite),
        'lifespan': dict(infinite),
        'liveliness': 'automatic',
        'liveliness_lease_duration': dict(infinite),
        'avoid_ros_namespace_conventions': False,
    }


def to_rclpy(qos_or_depth):
    """The same QoS as rclpy wants it: an int stays a depth, a profile becomes rclpy's own.

    rclpy's ``create_publisher`` and ``create_subscription`` take only their own ``QoSProfile``
    or an int (``TypeError: Expected QoSProfile or int`` otherwise). Policies map by name.
    """
    from rclpy import qos as rclpy_qos

    if isinstance(qos_or_depth, rclpy_qos.QoSProfile):
        return qos_or_depth
    profile = as_profile(qos_or_depth)
    return rclpy_qos.QoSProfile(
        depth=profile.depth,
        history=rclpy_qos.HistoryPolicy[profile.history.name],
        reliability=rclpy_qos.ReliabilityPolicy[profile.reliability.name],
        durability=rclpy_qos.DurabilityPolicy[profile.durability.name],
    )
