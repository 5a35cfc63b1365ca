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
#: The lease our participants announce [s] (Cyclone's default: 10 s). A process that dies
#: without a goodbye (SIGKILL) keeps its endpoints in everyone's graph until its lease runs out,
#: and a node that refuses an input with two publishers (gait_nodes.single_source) would hold
#: that long after a crashed producer was restarted. Cyclone renews the lease from its own
#: threads (and with every message), not from Python's: a busy node does not lose it.
PARTICIPANT_LEASE_S = 3.0
#: Samples read from a built-in topic at once (every endpoint of a domain fits).
_GRAPH_BATCH = 4096


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


def ros_type_name(dds_type: str) -> str:
    """DDS type ``pkg::msg::dds_::Name_`` -> ROS type ``pkg/msg/Name`` (others unchanged)."""
    parts = dds_type.replace('.', '::').split('::')
    if len(parts) == 4 and parts[2] == 'dds_' and parts[3].endswith('_'):
        return f'{parts[0]}/{parts[1]}/{parts[3][:-1]}'
    return dds_type


def _gid(guid) -> list[int]:
    """A DDS GUID as rmw's GID: its 16 bytes (rclpy pads them to 24 with zeros in Jazzy)."""
    return list(guid.bytes) + [0] * 8


def _profile_of(qos):
    """Our QoSProfile of a discovered endpoint's Cyclone Qos (what rclpy reports)."""
    from cyclonedds.core import Policy

    from gait_nodes.runtime.qos import QoSProfile

    profile = QoSProfile(depth=1)
    for policy in qos or ():
        if isinstance(policy, Policy.History.KeepLast):
            profile.history, profile.depth = HistoryPolicy.KEEP_LAST, policy.depth
        elif policy == Policy.History.KeepAll:
            profile.history = HistoryPolicy.KEEP_ALL
        elif isinstance(policy, Policy.Reliability.Reliable):
            profile.reliability = ReliabilityPolicy.RELIABLE
        elif policy == Policy.Reliability.BestEffort:
            profile.reliability = ReliabilityPolicy.BEST_EFFORT
        elif policy == Policy.Durability.TransientLocal:
            profile.durability = DurabilityPolicy.TRANSIENT_LOCAL
        elif policy == Policy.Durability.Volatile:
            profile.durability = DurabilityPolicy.VOLATILE
    return profile


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
        from cyclonedds.core import Policy, Qos
        from cyclonedds.util import duration

        lease = Qos(Policy.Liveliness.Automatic(duration(seconds=PARTICIPANT_LEASE_S)))
        try:
            self.participant = DomainParticipant(domain_id, qos=lease)
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
        #: The node of each endpoint of this process: GUID -> (node name, namespace).
        self.endpoint_nodes: dict = {}
        #: Built-in readers of the domain's publications and subscriptions, made on first use.
        self._graph_readers: dict = {}

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
        self.endpoint_nodes[writer.guid] = (node.get_name(), node.get_namespace())
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
        self.endpoint_nodes[reader.guid] = (node.get_name(), node.get_namespace())
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

    def _discovered(self, kind) -> list:
        """Every live endpoint of ``kind`` on the domain (this process's too), as Cyclone knows.

        Read from the built-in DCPSPublication / DCPSSubscription topics; the samples of
        endpoints gone (deleted, or their participant's lease ran out) are taken away.
        """
        from cyclonedds.builtin import (
            BuiltinDataReader,
            BuiltinTopicDcpsPublication,
            BuiltinTopicDcpsSubscription,
        )
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState

        from gait_nodes.runtime.endpoints import TopicEndpointTypeEnum

        entry = self._graph_readers.get(kind)
        if entry is None:
            topic = BuiltinTopicDcpsPublication if kind == TopicEndpointTypeEnum.PUBLISHER \
                else BuiltinTopicDcpsSubscription
            reader = BuiltinDataReader(self.participant, topic)
            states = SampleState.Any | ViewState.Any
            entry = self._graph_readers[kind] = (
                reader, ReadCondition(reader, states | InstanceState.Alive),
                ReadCondition(reader, states | InstanceState.NotAliveDisposed
                              | InstanceState.NotAliveNoWriters))
        reader, alive, gone = entry
        reader.take(N=_GRAPH_BATCH, condition=gone)
        return reader.read(N=_GRAPH_BATCH, condition=alive)

    def count(self, name: str, kind) -> int:
        """Endpoints (``kind``: TopicEndpointTypeEnum) of ROS topic ``name`` on the domain."""
        dds_name = dds_topic_name(name)
        return sum(1 for e in self._discovered(kind) if e.topic_name == dds_name)

    def endpoints(self, name: str, kind) -> list:
        """TopicEndpointInfo of the endpoints of ROS topic ``name`` on the domain.

        The node of an endpoint of this process is known; of any other, not (rmw learns it
        from ``ros_discovery_info``, which this runtime does not read): rmw's unknown names.
        """
        from gait_nodes.runtime.endpoints import (
            UNKNOWN_NODE_NAME,
            UNKNOWN_NODE_NAMESPACE,
            TopicEndpointInfo,
        )

        dds_name = dds_topic_name(name)
        infos = []
        for endpoint in self._discovered(kind):
            if endpoint.topic_name != dds_name:
                continue
            node, namespace = self.endpoint_nodes.get(
                endpoint.key, (UNKNOWN_NODE_NAME, UNKNOWN_NODE_NAMESPACE))
            infos.append(TopicEndpointInfo(
                node_name=node, node_namespace=namespace,
                topic_type=ros_type_name(endpoint.type_name or ''), endpoint_type=kind,
                endpoint_gid=_gid(endpoint.key), qos_profile=_profile_of(endpoint.qos)))
        return infos

    def notify(self) -> None:
        """Wake a waiting executor."""
        guard = getattr(self, 'guard', None)
        if guard is not None:
            guard.set(True)

    def close(self) -> None:
        """Delete every entity of this process."""
        participant, self.participant = self.participant, None
        self._graph_readers.clear()
        self.endpoint_nodes.clear()
        self.readers.clear()
        self.writers.clear()
        self.topics.clear()
        self.topic_types.clear()
        if participant is not None:
            participant.__del__()

