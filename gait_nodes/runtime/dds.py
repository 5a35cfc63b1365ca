"""The ``dds`` runtime: Cyclone DDS speaking the ROS 2 wire conventions, no ROS installed.

Topic ``/gait/zmp`` is DDS topic ``rt/gait/zmp`` with type
``geometry_msgs::msg::dds_::PointStamped_``, plain CDR of ``@final`` types, QoS as rclpy sets it,
``typehash=RIHS01_...;`` in the endpoint user data, domain from ``ROS_DOMAIN_ID``. A ROS 2 Jazzy
machine on the same network (rmw_cyclonedds or rmw_fastrtps) sees and decodes these topics.
"""

from __future__ import annotations

import os
from pathlib import Path

from gait_nodes.errors import GaitNodesError, RuntimeSelectionError
from gait_nodes.interfaces import message_type_name, raw_twins, type_hash
from gait_nodes.runtime.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

#: Longest single wait, so that a signal handler runs within this time [ns].
WAIT_SLICE_NS = 50_000_000
_MAX_BLOCKING_NS = 100_000_000


def _localhost_config() -> Path:
    from gait_nodes.paths import config_file

    return config_file('cyclonedds_localhost.xml')


def configure_cyclonedds() -> str:
    """Pick the Cyclone configuration; returns a description of the choice.

    ``CYCLONEDDS_URI`` set by the user always wins. Otherwise ``GAIT_NODES_DDS_LOCALHOST=1``
    selects the shipped loopback configuration (unicast discovery on 127.0.0.1, for machines or
    containers without multicast); by default Cyclone's own defaults apply, as with ROS 2.
    """
    if os.environ.get('CYCLONEDDS_URI'):
        return 'CYCLONEDDS_URI'
    if os.environ.get('GAIT_NODES_DDS_LOCALHOST', '') not in ('', '0'):
        os.environ['CYCLONEDDS_URI'] = _localhost_config().as_uri()
        return 'localhost'
    return 'default'


def _qos(profile, user_data: bytes):
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    policies = [Policy.Userdata(user_data)]
    if profile.reliability == ReliabilityPolicy.BEST_EFFORT:
        policies.append(Policy.Reliability.BestEffort)
    else:
        policies.append(Policy.Reliability.Reliable(duration(nanoseconds=_MAX_BLOCKING_NS)))
    if profile.history == HistoryPolicy.KEEP_ALL:
        policies.append(Policy.History.KeepAll)
    else:
        policies.append(Policy.History.KeepLast(profile.depth))
    if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL:
        policies.append(Policy.Durability.TransientLocal)
    else:
        policies.append(Policy.Durability.Volatile)
    return Qos(*policies)


def dds_topic_name(topic: str) -> str:
    """ROS topic ``/a/b`` -> DDS topic ``rt/a/b``."""
    return 'rt' + topic


class _DdsPublisher:
    def __init__(self, transport: DdsTransport, writer):
        self.transport = transport
        self.writer = writer

    def publish(self, msg) -> None:
        self.writer.write(msg)

    def publish_raw(self, data: bytes) -> None:
        # (the writer pads to 4 bytes)
        self.writer.write(raw_twins(self.writer.topic.data_type)[1].of(data))

    def subscription_count(self) -> int:
        return len(self.writer.get_matched_subscriptions())

    def destroy(self) -> None:
        self.transport.delete_entity(self.writer)


class _DdsSubscription:
    def __init__(self, transport: DdsTransport, subscription, reader, condition):
        self.transport = transport
        self.subscription = subscription
        self.reader = reader
        self.condition = condition

    def destroy(self) -> None:
        self.transport.remove_reader(self)


class DdsTransport:
    """One DomainParticipant per process, a WaitSet over its readers."""

    sim_time_source = None
    #: Bumped whenever a node of this process creates or destroys a timer.
    timers_version = 0

    def __init__(self, context, domain_id: int | None = None):
        from cyclonedds.core import GuardCondition, WaitSet
        from cyclonedds.domain import DomainParticipant

        self.context = context
        self.config = configure_cyclonedds()
        if domain_id is None:
            text = os.environ.get('ROS_DOMAIN_ID', '').strip() or '0'
            try:
                domain_id = int(text)
            except ValueError as exc:
                raise RuntimeSelectionError(
                    f'ROS_DOMAIN_ID must be an integer 0..232, got {text!r}') from exc
        if not 0 <= domain_id <= 232:
            raise RuntimeSelectionError(f'ROS_DOMAIN_ID must be in 0..232, got {domain_id}')
        self.domain_id = domain_id
        try:
            self.participant = DomainParticipant(domain_id)
        except Exception as exc:  # cyclonedds raises DDSException with the C error text
            raise RuntimeSelectionError(
                f'cannot start Cyclone DDS on domain {domain_id} ({self.config} config): {exc}'
            ) from exc
        self.waitset = WaitSet(self.participant)
        self.guard = GuardCondition(self.participant)
        self.waitset.attach(self.guard)
        self.topics: dict[tuple[str, bool], object] = {}
        self.topic_types: dict[tuple[str, bool], type] = {}  # the message class of each
        self.readers: list[_DdsSubscription] = []
        self.writers: list = []

    def _topic(self, name: str, msg_type: type, raw: bool = False):
        """The process's Topic of ``name`` (its raw twin's for raw subscriptions)."""
        from cyclonedds.topic import Topic

        key = (name, raw)
        topic = self.topics.get(key)
        if topic is None:
            data_type = raw_twins(msg_type)[0] if raw else msg_type
            topic = self.topics[key] = Topic(self.participant, dds_topic_name(name), data_type)
            self.topic_types[key] = msg_type
        elif self.topic_types[key] is not msg_type:
            raise GaitNodesError(
                f'topic {name} already carries {message_type_name(self.topic_types[key])} in '
                f'this process, cannot also use {message_type_name(msg_type)}')
        return topic

    @staticmethod
    def _user_data(msg_type: type) -> bytes:
        return f'typehash={type_hash(message_type_name(msg_type))};'.encode()

    def create_publisher(self, node, msg_type: type, name: str, profile) -> _DdsPublisher:
        """DataWriter for a publisher, with ROS 2 QoS and type hash."""
        from cyclonedds.pub import DataWriter

        writer = DataWriter(self.participant, self._topic(name, msg_type),
                            _qos(profile, self._user_data(msg_type)))
        self.writers.append(writer)
        return _DdsPublisher(self, writer)

    def create_subscription(self, node, subscription) -> _DdsSubscription:
        """DataReader for a subscription, watched by the WaitSet."""
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState
        from cyclonedds.sub import DataReader

        msg_type = subscription.msg_type
        # A raw subscription (a recorder) reads the CDR bytes as Cyclone holds them (4-byte
        # padded, as rmw_cyclonedds hands them to rosbag2), without a decode and an encode.
        topic = self._topic(subscription.topic_name, msg_type, subscription.raw)
        reader = DataReader(self.participant, topic,
                            _qos(subscription.qos_profile, self._user_data(msg_type)))
        condition = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
        self.waitset.attach(condition)
        entry = _DdsSubscription(self, subscription, reader, condition)
        self.readers.append(entry)
        return entry

    def remove_reader(self, entry: _DdsSubscription) -> None:
        """Detach and delete a subscription's reader."""
        if entry in self.readers:
            self.readers.remove(entry)
            self.waitset.detach(entry.condition)
            self.delete_entity(entry.condition)
            self.delete_entity(entry.reader)

    @staticmethod
    def delete_entity(entity) -> None:
        """Delete a Cyclone entity now rather than at garbage collection."""
        entity.__del__()

    def wait(self, timeout_ns: int) -> list[tuple[object, object]]:
        """Wait up to ``timeout_ns`` for data; return ``(subscription, message)`` pairs.

        Raw subscriptions get the CDR bytes (encapsulation header included) as the message.
        """
        if timeout_ns > 0:
            self.waitset.wait(min(timeout_ns, WAIT_SLICE_NS))
        self.guard.set(False)
        ready = []
        for entry in list(self.readers):
            if not entry.condition.triggered:
                continue
            depth = max(entry.subscription.qos_profile.depth, 1)
            raw = entry.subscription.raw
            for sample in entry.reader.take(N=depth):
                if getattr(sample, 'sample_info', None) is None or not \
                        sample.sample_info.valid_data:
                    continue
                ready.append((entry.subscription, sample.data if raw else sample))
        return ready

    def count(self, name: str, kind: str) -> int:
        """Endpoints of this process on a topic (``kind``: publishers or subscriptions)."""
        if kind == 'subscriptions':
            return sum(1 for e in self.readers if e.subscription.topic_name == name)
        return sum(1 for w in self.writers if w.topic.name == dds_topic_name(name))

    def notify(self) -> None:
        """Wake a waiting executor."""
        guard = getattr(self, 'guard', None)
        if guard is not None:
            guard.set(True)

    def close(self) -> None:
        """Delete every entity of this process."""
        participant, self.participant = self.participant, None
        self.readers.clear()
        self.writers.clear()
        self.topics.clear()
        self.topic_types.clear()
        if participant is not None:
            participant.__del__()

