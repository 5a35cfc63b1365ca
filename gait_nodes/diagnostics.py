"""/diagnostics reporting shared by every node: OK / WARN / ERROR with key values.

Each node owns one :class:`DiagnosticsReporter`. Status names are ``"<node>: <aspect>"`` (for
example ``"footstep_planner: command"``, ``"kinematic_simulator: stability"``), the
``hardware_id`` is the robot name, and values are strings as diagnostic_msgs requires. A report
is published at once; :meth:`DiagnosticsReporter.drop` is the one way to report a dropped input
message (with the topic, the reason and a running count), so that "a NaN in a message is dropped
and reported on /diagnostics" reads the same in every node.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from gait_nodes.interfaces import get_message

OK = 0
WARN = 1
ERROR = 2
STALE = 3
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}


def level_value(level) -> int:
    """Integer level of a DiagnosticStatus.level as either runtime stores it."""
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


def format_value(value) -> str:
    """A key value as diagnostic_msgs carries it: floats with 6 significant digits."""
    if isinstance(value, float):
        return f'{value:.6g}' if math.isfinite(value) else str(value)
    if isinstance(value, (list, tuple)):
        return ','.join(format_value(v) for v in value)
    return str(value)


def make_status(name: str, level: int, message: str, values: Mapping[str, object] | None = None,
                hardware_id: str = ''):
    """diagnostic_msgs/DiagnosticStatus with ``values`` as string key values."""
    status = get_message('diagnostic_msgs/msg/DiagnosticStatus')()
    key_value = get_message('diagnostic_msgs/msg/KeyValue')
    # DiagnosticStatus.level is a ``byte``: bytes in rclpy's class, an int in ours. Asked of
    # each message, not once at import: the runtime is chosen after this module is loaded.
    status.level = bytes([level]) if isinstance(status.level, bytes) else level
    status.name = name
    status.message = message
    status.hardware_id = hardware_id
    items = []
    for key, value in (values or {}).items():
        item = key_value()
        item.key, item.value = str(key), format_value(value)
        items.append(item)
    status.values = items
    return status


class DiagnosticsReporter:
    """Publishes DiagnosticArray messages on /diagnostics for one node.

    Args:
        node: The node that publishes (runtime or rclpy ``Node``).
        hardware_id: Robot name, or '' when the node has none.
    """

    def __init__(self, node, hardware_id: str = ''):
        self._node = node
        self._hardware_id = hardware_id
        self._publisher = node.create_publisher(
            get_message('diagnostic_msgs/msg/DiagnosticArray'), '/diagnostics', 10)
        self.dropped: dict[str, int] = {}

    def report(self, aspect: str, level: int, message: str,
               values: Mapping[str, object] | None = None) -> None:
        """Publish one status ``"<node>: <aspect>"`` now, and log WARN and ERROR reports."""
        self.publish([(aspect, level, message, values)])
        if level == WARN:
            self._node.get_logger().warning(f'{aspect}: {message}')
        elif level >= ERROR:
            self._node.get_logger().error(f'{aspect}: {message}')

    def publish(self, statuses) -> None:
        """Publish several ``(aspect, level, message, values)`` statuses in one array."""
        array = get_message('diagnostic_msgs/msg/DiagnosticArray')()
        array.header.stamp = self._node.get_clock().now().to_msg()
        node_name = self._node.get_name()
        array.status = [make_status(f'{node_name}: {aspect}', level, message, values,
                                    self._hardware_id)
                        for aspect, level, message, values in statuses]
        self._publisher.publish(array)

    def drop(self, topic: str, reason: str, level: int = WARN) -> None:
        """Report that a message on ``topic`` was dropped, with the reason and a running count."""
        self.dropped[topic] = self.dropped.get(topic, 0) + 1
        self.report(f'input {topic}', level, f'dropped a message on {topic}: {reason}',
                    {'topic': topic, 'reason': reason, 'dropped_count': self.dropped[topic]})
