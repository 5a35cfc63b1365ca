"""view: serve the running graph live to Foxglove over its WebSocket protocol, without ROS.

``python -m gait_nodes.view [--port 8765] [--host 127.0.0.1] [--namespace NS] [--robot NAME]``,
then open ``ws://localhost:8765`` in Foxglove (desktop app or web). Every contract topic, plus
``/robot_description`` and ``/tf_static`` (latched, as ROS's robot_state_publisher has them), is a
Foxglove channel: message encoding ``cdr`` (the bytes as they travel on DDS, taken without a
decode), schema encoding ``ros2msg`` (the schema text rosbag2 writes in MCAP). The view reads a
topic from the graph only while a Foxglove client subscribes to it and it has publishers, with
QoS that matches them (transient local when they all offer it: a client that subscribes late to
a latched topic, such as ``/robot_description``, gets its last sample). Under ROS 2, run
``foxglove_bridge`` instead: ``ros2 launch foxglove_bridge foxglove_bridge_launch.xml``.
"""

from __future__ import annotations

import dataclasses
import queue
import sys
import time

from gait_nodes import graph
from gait_nodes.cli import run_node
from gait_nodes.errors import LiveViewError
from gait_nodes.foxglove_relay import DEFAULT_HOST, DEFAULT_PORT, FoxgloveRelay
from gait_nodes.interfaces import get_message
from gait_nodes.replay import replay_qos
from gait_nodes.runtime import DurabilityPolicy, Node
from gait_nodes.runtime.qos import offered_qos_yaml
from gait_nodes.runtime.selection import active_runtime

PROG = 'python -m gait_nodes.view'
#: How often the clients' subscriptions are followed [s]: the delay before a channel that a
#: client subscribes to starts to flow.
CLIENT_PERIOD_S = 0.1
#: How often the publishers of the topics that clients subscribe to are looked up again [s]
#: (a node restarted with other QoS, a publisher that appears). Looking up costs the view most
#: of its idle CPU: only the topics a client subscribes to are looked up.
GRAPH_PERIOD_S = 1.0
#: Samples a subscription keeps until the view takes them (a /tf_static reader gets the
#: latched sample of each of its publishers at once).
SUBSCRIPTION_DEPTH = 100


def view_topics(foot_names=()) -> dict[str, str]:
    """``{contract topic: pkg/msg/Type}`` the view serves, with the per-foot topics of a robot.

    Args:
        foot_names: Foot names of the robot whose per-foot topics
            (``/gait/contact_wrench/<foot>``) are served too.
    """
    return {**graph.TOPICS, **graph.foot_topics(foot_names)}


def subscription_qos(offered: list[dict]):
    """The QoS that matches every publisher of a topic, from their offered profiles.

    As a player of bags has it (:func:`gait_nodes.replay.replay_qos`): reliable and transient
    local only when every publisher offers them (a reader asking for more than a writer offers
    does not match it), with a depth of SUBSCRIPTION_DEPTH.

    Args:
        offered: The publishers' profiles as rosbag2 writes them
            (:func:`gait_nodes.runtime.qos.offered_qos_yaml`).
    """
    return dataclasses.replace(replay_qos(offered), depth=SUBSCRIPTION_DEPTH)


class LiveView(Node):
    """Relays the graph's topics to Foxglove clients as their CDR bytes.

    Args:
        host: Interface the WebSocket server listens on.
        port: Its TCP port (0: any free port).
        namespace: The graph's namespace (``run --namespace``): topics are resolved as its
            nodes resolve them (``/robot1/gait/zmp``, ``/robot1/tf``; ``/clock`` stays global).
        robot: A robot name or YAML whose per-foot topics are served too.

    Raises:
        ArgumentError: ``namespace`` is not a valid ROS namespace.
        LiveViewError: The server cannot listen on ``host:port``, or the SDK is missing.
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 namespace: str | None = None, robot: str | None = None):
        arguments = graph.namespace_arguments(namespace)  # an invalid one is refused here
        self.relay = None  # destroy_node after a refusal has no server to stop
        super().__init__('live_view', cli_args=['--ros-args', *arguments] if arguments else None)
        feet = ()
        if robot:
            from gait_nodes.robot.description import load_robot_description

            feet = load_robot_description(robot).foot_names
        #: Topic as the graph names it -> its type.
        self.topic_types = {self.resolve_topic_name(graph.node_topic_name(topic)): type_name
                            for topic, type_name in view_topics(feet).items()}
        #: Topics a client has just subscribed to, put there by the server's threads.
        self._new_subscribers: queue.SimpleQueue = queue.SimpleQueue()
        self.relay = FoxgloveRelay(self.topic_types, host, port,
                                   name=f'gait_nodes {self.get_namespace()}',
                                   on_subscribe=self._new_subscribers.put)
        #: Topic -> the QoS its publishers offered when last looked up, for the topics that
        #: clients subscribe to.
        self._offered: dict[str, list[dict]] = {}
        self._next_lookup_s = 0.0  # time.monotonic() of the next lookup of every such topic
        #: Topic -> (subscription, its QoS), for the topics being read.
        self._reading: dict[str, tuple] = {}
        self.create_timer(CLIENT_PERIOD_S, self._follow_clients)
        self.get_logger().info(
            f'serving {len(self.topic_types)} topics of namespace {self.get_namespace()} to '
            f'Foxglove at {self.relay.url}')

    def _publishers_qos(self, topic: str) -> list[dict]:
        """The QoS profiles the publishers of ``topic`` offer (rosbag2's form)."""
        type_name = self.topic_types[topic]
        return [offered_qos_yaml(info.qos_profile)
                for info in self.get_publishers_info_by_topic(topic)
                if info.topic_type == type_name]

    def _follow_clients(self) -> None:
        """Read each topic while a client subscribes to it, with its publishers' QoS.

        A client that subscribes to a transient-local topic gets its latched samples from a
        new reader (the graph's publishers send them to every new one, as DDS does).
        """
        latched_wanted = set()
        while not self._new_subscribers.empty():
            latched_wanted.add(self._new_subscribers.get_nowait())
        now_s = time.monotonic()
        look_up = now_s >= self._next_lookup_s
        if look_up:
            self._next_lookup_s = now_s + GRAPH_PERIOD_S
        for topic in self.topic_types:
            if not self.relay.is_subscribed(topic):
                self._offered.pop(topic, None)
                self._stop_reading(topic)
                continue
            if look_up or topic not in self._offered:
                self._offered[topic] = self._publishers_qos(topic)
            if not self._offered[topic]:  # no publisher (any more)
                self._stop_reading(topic)
                continue
            profile = subscription_qos(self._offered[topic])
            reading = self._reading.get(topic)
            if reading is not None and reading[1] == profile and not (
                    topic in latched_wanted
                    and profile.durability == DurabilityPolicy.TRANSIENT_LOCAL):
                continue
            self._stop_reading(topic)
            self._reading[topic] = (self.create_subscription(
                get_message(self.topic_types[topic]), topic, self._forwarder(topic), profile,
                raw=True), profile)

    def _stop_reading(self, topic: str) -> None:
        reading = self._reading.pop(topic, None)
        if reading is not None:
            self.destroy_subscription(reading[0])

    def _forwarder(self, topic: str):
        relay, clock = self.relay, self.get_clock()

        def forward(data: bytes) -> None:
            relay.forward(topic, data, clock.now().nanoseconds)  # rclpy's Clock: no now_ns

        return forward

    def destroy_node(self) -> None:
        """Stop the server (clients are disconnected), then release the node."""
        if self.relay is not None:
            self.relay.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.view [--port P] [--host H] [--namespace NS]``."""

    def add_arguments(parser):
        parser.add_argument('--port', type=int, default=DEFAULT_PORT,
                            help=f'TCP port of the WebSocket server (default {DEFAULT_PORT}, '
                                 "Foxglove's; 0: any free port)")
        parser.add_argument('--host', default=DEFAULT_HOST,
                            help=f'interface to listen on (default {DEFAULT_HOST}: this machine '
                                 'only; 0.0.0.0: every interface, for a Foxglove elsewhere)')
        parser.add_argument('--namespace', metavar='NS', default=None,
                            help='the namespace of the graph to serve (as run --namespace NS)')
        parser.add_argument('--robot', default=None, metavar='NAME',
                            help="also serve this robot's per-foot topics "
                                 '(/gait/contact_wrench/<foot>, the physics simulator\'s)')

    def factory(options) -> LiveView:
        if active_runtime() == 'inproc':
            raise LiveViewError('the inproc runtime has no graph outside this process to '
                                'serve: serve a dds graph (--runtime dds)')
        return LiveView(host=options.host, port=options.port, namespace=options.namespace,
                        robot=options.robot)

    return run_node(factory, args, prog=PROG, description=__doc__.split('\n\n')[0],
                    add_arguments=add_arguments)


if __name__ == '__main__':
    sys.exit(main())
