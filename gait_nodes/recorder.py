"""recorder node: every contract topic (or the chosen ones) into a rosbag2 MCAP directory.

``python -m gait_nodes.recorder -o DIR [-t TOPIC[:pkg/msg/Type] ...]``. A clean stop (Ctrl-C,
SIGTERM) writes the MCAP summary and ``metadata.yaml``; a SIGKILL loses at most the last
``flush_period_s`` of data (the rest stays readable).
"""

from __future__ import annotations

import sys
import time

from gait_nodes import graph
from gait_nodes.bag.writer import BagWriter
from gait_nodes.cli import run_node
from gait_nodes.errors import ArgumentError
from gait_nodes.interfaces import get_message
from gait_nodes.runtime import DurabilityPolicy, Node, QoSProfile
from gait_nodes.runtime.qos import offered_qos_yaml

#: Topics whose publishers are latched (transient local) in the contract.
LATCHED_TOPICS = ('/gait/footsteps',)


def parse_topics(specs: list[str]) -> dict[str, str]:
    """``['gait/zmp', '/tf', 'b:pkg/msg/T']`` -> ``{topic: type}``; contract topics need no type.

    Names resolve as the node's own do (``ros2 bag record`` too): a relative name under the
    recorder's namespace, an absolute one as it is.
    """
    topics = {}
    for spec in specs:
        name, _, type_name = spec.partition(':')
        if not type_name:
            contract = '/' + name.lstrip('/')
            if contract not in graph.TOPICS:
                raise ArgumentError(f'topic {name} is not in the contract: give its type as '
                                    f'{name}:pkg/msg/Type')
            type_name = graph.TOPICS[contract]
        topics[name] = type_name
    return topics


class Recorder(Node):
    """Subscribes to topics without deserializing and writes what arrives to a bag."""

    def __init__(self, output: str | None = None, topics: dict[str, str] | None = None):
        super().__init__('recorder')
        default_output = time.strftime('bags/gait_%Y_%m_%d-%H_%M_%S')
        output = self.declare_parameter('output', output or default_output).value
        flush_period_s = self.declare_parameter('flush_period_s', 0.5).value
        if not 0 < flush_period_s <= 1.0:
            raise ArgumentError(f'flush_period_s must be in (0, 1] s, got {flush_period_s}')
        # The contract's topics named as the nodes name them: under a namespace the bag holds
        # /robot1/gait/footsteps, and /tf where the nodes' /tf is.
        topics = topics or {graph.node_topic_name(name): type_name
                            for name, type_name in graph.TOPICS.items()}
        self.writer = None  # destroy_node after a refused output has no bag to close
        self.writer = BagWriter(output, flush_period_s=flush_period_s)
        for name, type_name in topics.items():
            latched = '/' + name.lstrip('/') in LATCHED_TOPICS
            profile = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL
                                 if latched else DurabilityPolicy.VOLATILE)
            publisher_qos = QoSProfile(depth=1 if latched else 10,
                                       durability=profile.durability)
            resolved = self.resolve_topic_name(name)
            self.writer.add_topic(resolved, type_name, [offered_qos_yaml(publisher_qos)])
            self.create_subscription(get_message(type_name), name, self._writer_for(resolved),
                                     profile, raw=True)
        # Messages alone trigger flushes only while they keep coming: a timer bounds the age of
        # the open chunk when traffic stops, so a SIGKILL never loses more than flush_period_s.
        self.create_timer(flush_period_s / 4, self.writer.flush_if_due)
        self.get_logger().info(f'recording {len(topics)} topics to {self.writer.path}')

    def _writer_for(self, topic: str):
        clock = self.get_clock()
        # The runtime's Clock reads integer nanoseconds without a Time object; rclpy's has no
        # now_ns.
        now_ns = getattr(clock, 'now_ns', None) or (lambda: clock.now().nanoseconds)
        return self.writer.topic_writer(topic, now_ns)

    def destroy_node(self) -> None:
        """Finish the bag, then release the node."""
        if self.writer is not None:
            self.writer.close()
            self.get_logger().info(f'bag closed: {self.writer.message_count} messages in '
                                   f'{self.writer.path}')
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.recorder -o DIR [-t TOPIC ...]``."""

    def add_arguments(parser):
        parser.add_argument('-o', '--output', default=None,
                            help='bag directory to create (default bags/gait_<date-time>)')
        parser.add_argument('-t', '--topics', nargs='+', default=None, metavar='TOPIC',
                            help='topics to record (default: every contract topic); '
                                 'non-contract topics as name:pkg/msg/Type; relative names '
                                 'resolve under the namespace (--ros-args -r __ns:=/robot1)')

    def factory(options):
        topics = parse_topics(options.topics) if options.topics else None
        return Recorder(output=options.output, topics=topics)

    return run_node(factory, args, prog='python -m gait_nodes.recorder',
                    description=__doc__.split('\n\n')[0], add_arguments=add_arguments)


if __name__ == '__main__':
    sys.exit(main())
