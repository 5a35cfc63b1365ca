"""Inputs that one publisher only may feed: two graphs on one domain are refused, not mixed.

Two gait graphs started on one ROS_DOMAIN_ID in the same namespace (or none) merge in silence:
each simulator would follow both whole-body IKs. A node names the inputs that exactly one node
may feed (the simulator its /joint_commands, the IK its references, the COM controller its ZMP
reference, the planner the robot's /joint_states; not /tf, which tf2 meant for many
publishers) to a :class:`SingleSource`. Once a ``period_s`` (a timer, not per message) it
counts the publishers of each, less the node's own, with the ROS graph API
(``Node.count_publishers``, ``Node.get_publishers_info_by_topic``: rclpy's own under rclpy; the
whole DDS domain under ``dds``; the process under ``inproc``). An input
with more than one is *refused*: the node drops its messages and holds (what holding means is the
node's: the simulator holds the robot where it stands, the IK its last command), and the node's
``<node>: inputs`` status (:class:`gait_nodes.watchdog.InputWatchdog`, which lists a refused
input among the stale ones) says ERROR, naming the topic, the count and the publishing nodes
where the graph knows them. Once one publisher is left the node goes on and reports OK.

A publisher that died without a goodbye (SIGKILL) counts until its participant's lease runs out
(3 s for this project's ``dds`` runtime, 10 s for Cyclone DDS under rclpy, 20 s for Fast DDS): a
node restarted after a crash may be refused that long.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from gait_nodes.graph import node_topic_name
from gait_nodes.runtime.endpoints import node_of

#: Time between two counts of the publishers [s].
CHECK_PERIOD_S = 1.0


class SingleSource:
    """Counts the publishers of a node's single-source inputs; refuses those with several.

    Args:
        node: The node (runtime or rclpy ``Node``); the check runs in a timer of it.
        topics: The inputs by their contract names (``/joint_commands``, ``/tf``); each is
            resolved as the node names it (:func:`gait_nodes.graph.node_topic_name`), in its
            namespace and with its remappings.
        holding: What the node does while an input is refused, for the report.
        watchdog: The node's InputWatchdog, which then reports the refused inputs; or give
            this object to the watchdog as ``sources``.
        on_change: Called with no argument when the set of refused inputs changes (after the
            watchdog knows), for the node to hold or go on at once.
        period_s: Time between checks [s] of the node's clock.
    """

    def __init__(self, node, topics: Sequence[str], holding: str, watchdog=None,
                 on_change: Callable[[], None] | None = None,
                 period_s: float = CHECK_PERIOD_S):
        self._node = node
        self.topics = tuple(topics)
        self.holding = holding
        self._on_change = on_change
        #: Resolved topic name of each input (``/robot1/joint_commands``).
        self.names = {topic: node.resolve_topic_name(node_topic_name(topic))
                      for topic in self.topics}
        #: Refused inputs: topic -> what feeds it (``2 publishers on /joint_commands (...)``).
        self.refused: dict[str, str] = {}
        #: Publishers of each input at the last check, the node's own not counted.
        self.publishers: dict[str, int] = {}
        if watchdog is not None:
            watchdog.sources = self
        self.timer = node.create_timer(period_s, self.check)

    def refuses(self, topic: str) -> bool:
        """Whether messages on ``topic`` are refused now."""
        return topic in self.refused

    def check(self) -> bool:
        """Count the publishers of every input; True when the refused inputs changed."""
        refused = {}
        for topic, name in self.names.items():
            own = sum(1 for publisher in self._node.publishers if publisher.topic_name == name)
            count = self._node.count_publishers(name) - own
            self.publishers[topic] = count
            if count > 1:
                refused[topic] = self._describe(name, count, own)
        changed = refused.keys() != self.refused.keys()
        self.refused = refused
        if changed and self._on_change is not None:
            self._on_change()
        return changed

    def _describe(self, name: str, count: int, own: int) -> str:
        """``2 publishers on /joint_commands (/whole_body_ik, an unknown node)``.

        The nodes are named where the graph knows them (rclpy; this process under ``dds``):
        none known, none listed.
        """
        me = self._node.get_fully_qualified_name()
        nodes = []
        for info in self._node.get_publishers_info_by_topic(name):
            node = node_of(info)
            if node == me and own:
                own -= 1
                continue
            nodes.append(node)
        described = f'{count} publishers on {name}'
        if any(nodes):
            described += f' ({", ".join(node or "an unknown node" for node in nodes)})'
        return described
