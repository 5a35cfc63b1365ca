"""The ``inproc`` runtime: every node in one process, one deterministic lockstep executor.

Time is simulated: the executor jumps to the next timer deadline, runs the due timers in creation
order and, after each, delivers every message that callback caused (and the messages those
deliveries cause, first in first out) before time moves on. The same inputs therefore give the
same sequence of callbacks and byte-identical outputs, as fast as the CPU allows.

Messages are handed to subscribers by reference, without serialization: a callback must treat a
received message as read-only, as rclpy's intra-process communication also requires, and a
publisher must not edit a message once published. Under that rule node code may share unchanging
sub-messages between the messages it publishes (the kinematic_simulator shares stamps, joint
names and polygon vertices, the footstep_planner the poses its successive ZMP references have in
common), which saves building them again and is invisible to subscribers. The raw subscriptions
of a message share its one serialization, which relies on the rule too: a sequence of flat
structs serialized for an earlier message (the same object, such as the support polygon's
vertices) is copied from then, not packed again (``serialize_published`` of the classes).
"""

from __future__ import annotations

import collections
import functools
import os

from gait_nodes.interfaces import validate_message
from gait_nodes.runtime.qos import DurabilityPolicy, ReliabilityPolicy


class _Topic:
    def __init__(self, name: str):
        self.name = name
        self.publishers: list[_InprocPublisher] = []
        self.subscriptions: list = []
        self.type_name: str | None = None
        #: Bumped whenever ``subscriptions`` changes (publishers keep their matches until then).
        self.version = 0


class _InprocPublisher:
    def __init__(self, transport: InprocTransport, topic: _Topic, msg_type: type, profile,
                 node=None):
        self.transport = transport
        self.node = node
        self.topic = topic
        self.msg_type = msg_type
        self.profile = profile
        latched = profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        self.history = collections.deque(maxlen=profile.depth) if latched else None
        self._queue = transport.queue
        self._matched: tuple = ()
        self._matched_version = -1

    def matched(self) -> tuple:
        """The topic's subscriptions DDS would match with this publisher, in creation order."""
        topic = self.topic
        if self._matched_version != topic.version:
            self._matched = tuple(s for s in topic.subscriptions if _compatible(self, s))
            self._matched_version = topic.version
        return self._matched

    def publish(self, msg) -> None:
        # Called for every message of the graph: one queue entry per message, whatever the
        # number of subscriptions (the executor hands it to each in a row).
        if self.transport.strict:
            validate_message(msg)
        if self.history is not None:
            self.history.append(msg)
        matched = self._matched if self._matched_version == self.topic.version \
            else self.matched()
        if matched:
            self._queue.append((msg, matched))

    def publish_raw(self, data: bytes) -> None:
        self.publish(self.msg_type.deserialize(data))

    def subscription_count(self) -> int:
        return sum(1 for s in self.topic.subscriptions if _compatible(self, s))

    def destroy(self) -> None:
        if self in self.topic.publishers:
            self.topic.publishers.remove(self)


class _InprocSubscription:
    def __init__(self, transport: InprocTransport, topic: _Topic, subscription):
        self.transport = transport
        self.topic = topic
        self.subscription = subscription

    def destroy(self) -> None:
        if self.subscription in self.topic.subscriptions:
            self.topic.subscriptions.remove(self.subscription)
            self.topic.version += 1


def _compatible(publisher: _InprocPublisher, subscription) -> bool:
    """Whether DDS would match this pair: same type and compatible QoS."""
    if publisher.msg_type.__ros_type__ != subscription.msg_type.__ros_type__:
        return False
    if (subscription.qos_profile.reliability == ReliabilityPolicy.RELIABLE
            and publisher.profile.reliability == ReliabilityPolicy.BEST_EFFORT):
        return False
    return not (subscription.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                and publisher.profile.durability != DurabilityPolicy.TRANSIENT_LOCAL)


class InprocTransport:
    """Topics, a FIFO of pending deliveries and the simulated clock of one process."""

    def __init__(self, context):
        self.context = context
        self.now_ns = 0
        self.topics: dict[str, _Topic] = {}
        #: Pending deliveries, first in first out: ``(message, subscriptions)``.
        self.queue: collections.deque = collections.deque()
        self.delivered = 0
        #: Bumped whenever a node of this process creates or destroys a timer.
        self.timers_version = 0
        # The clocks of the nodes read the simulated time through this C-level callable (many
        # times per tick: no Python frame for it).
        self.sim_time_source = functools.partial(getattr, self, 'now_ns')
        #: Check every published message as rclpy's setters would (see validate_message).
        self.strict = os.environ.get('GAIT_NODES_STRICT_MESSAGES', '') not in ('', '0')

    def _topic(self, name: str, msg_type: type) -> _Topic:
        topic = self.topics.get(name)
        if topic is None:
            topic = self.topics[name] = _Topic(name)
        if topic.type_name is None:
            topic.type_name = msg_type.__ros_type__
        return topic

    def create_publisher(self, node, msg_type: type, name: str, profile) -> _InprocPublisher:
        """Publisher on a topic of this process."""
        topic = self._topic(name, msg_type)
        publisher = _InprocPublisher(self, topic, msg_type, profile, node)
        topic.publishers.append(publisher)
        return publisher

    def create_subscription(self, node, subscription) -> _InprocSubscription:
        """Subscription; a transient-local one gets the latched history at once."""
        topic = self._topic(subscription.topic_name, subscription.msg_type)
        topic.subscriptions.append(subscription)
        topic.version += 1
        if subscription.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL:
            for publisher in topic.publishers:
                if publisher.history and _compatible(publisher, subscription):
                    depth = subscription.qos_profile.depth
                    for msg in list(publisher.history)[-depth:]:
                        self.queue.append((msg, (subscription,)))
        return _InprocSubscription(self, topic, subscription)

    def deliver(self, publisher: _InprocPublisher, msg) -> None:
        """Queue ``msg`` for every compatible subscription of the topic."""
        matched = publisher.matched()
        if matched:
            self.queue.append((msg, matched))

    def count(self, name: str, kind) -> int:
        """Endpoints (``kind``: TopicEndpointTypeEnum) of a topic: the process is the graph."""
        from gait_nodes.runtime.endpoints import TopicEndpointTypeEnum

        topic = self.topics.get(name)
        if topic is None:
            return 0
        return len(topic.publishers if kind == TopicEndpointTypeEnum.PUBLISHER
                   else topic.subscriptions)

    def endpoints(self, name: str, kind) -> list:
        """TopicEndpointInfo of a topic's publishers or subscriptions, with their nodes."""
        from gait_nodes.runtime.endpoints import TopicEndpointInfo, TopicEndpointTypeEnum

        topic = self.topics.get(name)
        if topic is None:
            return []
        infos = []
        if kind == TopicEndpointTypeEnum.PUBLISHER:
            entries = [(p, p.node, p.msg_type, p.profile) for p in topic.publishers]
        else:
            entries = [(s, s._node, s.msg_type, s.qos_profile) for s in topic.subscriptions]
        for endpoint, node, msg_type, profile in entries:
            infos.append(TopicEndpointInfo(
                node_name=node.get_name() if node is not None else '',
                node_namespace=node.get_namespace() if node is not None else '',
                topic_type=msg_type.__ros_type__, endpoint_type=kind,
                endpoint_gid=list(id(endpoint).to_bytes(8, 'little')) + [0] * 16,
                qos_profile=profile))
        return infos

    def notify(self) -> None:
        """Nothing waits in inproc; present for the transport interface."""

    def close(self) -> None:
        """Drop pending deliveries and topics."""
        self.queue.clear()
        self.topics.clear()

