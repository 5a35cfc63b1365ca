"""recorder node: every contract topic (or the chosen ones) into a rosbag2 MCAP directory.

``python -m gait_nodes.recorder -o DIR [-t TOPIC[:pkg/msg/Type] ...]``. A clean stop (Ctrl-C,
SIGTERM) writes the MCAP summary and ``metadata.yaml``; a SIGKILL loses at most the last
``flush_period_s`` of data (the rest stays readable). A write that fails (a full disk, a
directory made read-only) closes the bag at its last flush, readable with its
``metadata.yaml``; the recorder then reports ERROR on /diagnostics (``recorder: bag``, once a
second), records nothing more, and exits with status 1 when stopped.
"""

from __future__ import annotations

import sys
import time

from gait_nodes import graph
from gait_nodes.bag.writer import BagWriter
from gait_nodes.cli import run_node
from gait_nodes.diagnostics import ERROR, DiagnosticsReporter
from gait_nodes.errors import ArgumentError, os_error_text
from gait_nodes.interfaces import get_message
from gait_nodes.runtime import DurabilityPolicy, Node, QoSProfile
from gait_nodes.runtime.qos import offered_qos_yaml

#: Topics whose publishers are latched (transient local) in the contract.
LATCHED_TOPICS = graph.LATCHED_TOPICS
#: Period of the ERROR report after the bag failed [s].
FAILURE_REPORT_PERIOD_S = 1.0


def parameter_defaults(output: str | None = None) -> dict[str, object]:
    """The recorder's parameters and their defaults (``output``: bags/gait_<date-time>)."""
    return {'output': output or time.strftime('bags/gait_%Y_%m_%d-%H_%M_%S'),
            'flush_period_s': 0.5}


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
            families = [t for prefix, t in graph.FOOT_TOPICS.items()
                        if contract.startswith(prefix) and len(contract) > len(prefix)]
            if contract not in graph.TOPICS and not families:
                raise ArgumentError(f'topic {name} is not in the contract: give its type as '
                                    f'{name}:pkg/msg/Type')
            type_name = graph.TOPICS.get(contract) or families[0]
        topics[name] = type_name
    return topics


class Recorder(Node):
    """Subscribes to topics without deserializing and writes what arrives to a bag.

    Args:
        output: Bag directory (default: the ``output`` parameter, else bags/gait_<date-time>).
        topics: ``{topic: pkg/msg/Type}`` to record (default: every contract topic).
        open_file: How the MCAP file is opened (:class:`BagWriter`'s ``open_file``).
        robot: A robot name or YAML: also record its per-foot topics
            (``/gait/contact_wrench/<foot>``, the physics simulator's), with the default topics.
    """

    def __init__(self, output: str | None = None, topics: dict[str, str] | None = None,
                 open_file=None, robot: str | None = None):
        super().__init__('recorder')
        self.writer = None  # destroy_node after a refusal has no bag to close
        values = {name: self.declare_parameter(name, default).value
                  for name, default in parameter_defaults(output).items()}
        self.check_parameter_overrides()  # before a bag directory is made
        output, flush_period_s = values['output'], values['flush_period_s']
        if not 0 < flush_period_s <= 1.0:
            raise ArgumentError(f'flush_period_s must be in (0, 1] s, got {flush_period_s}')
        # The contract's topics named as the nodes name them: under a namespace the bag holds
        # /robot1/gait/footsteps, and /tf where the nodes' /tf is.
        topics = topics or {graph.node_topic_name(name): type_name
                            for name, type_name in graph.TOPICS.items()}
        if robot:
            from gait_nodes.robot.description import load_robot_description

            feet = load_robot_description(robot).foot_names
            topics = {**topics, **{graph.node_topic_name(name): type_name
                                   for name, type_name in graph.foot_topics(feet).items()}}
        # Made at start, so that subscribers have matched it when a failure is reported.
        self.diagnostics = DiagnosticsReporter(self)
        self._failure_reported_ns: int | None = None
        self._subscriptions_recorded = []
        self.writer = BagWriter(output, flush_period_s=flush_period_s,
                                on_error=self._on_write_error, open_file=open_file)
        for name, type_name in topics.items():
            latched = '/' + name.lstrip('/') in LATCHED_TOPICS
            profile = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL
                                 if latched else DurabilityPolicy.VOLATILE)
            publisher_qos = QoSProfile(depth=1 if latched else 10,
                                       durability=profile.durability)
            resolved = self.resolve_topic_name(name)
            self.writer.add_topic(resolved, type_name, [offered_qos_yaml(publisher_qos)])
            self._subscriptions_recorded.append(self.create_subscription(
                get_message(type_name), name, self._writer_for(resolved), profile, raw=True))
        # Messages alone trigger flushes only while they keep coming: a timer bounds the age of
        # the open chunk when traffic stops, so a SIGKILL never loses more than flush_period_s.
        self.create_timer(flush_period_s / 4, self._tick)
        self.get_logger().info(f'recording {len(topics)} topics to {self.writer.path}')

    @property
    def failure(self) -> str | None:
        """Why the bag stopped early (one line), or None."""
        return self.writer.failure if self.writer is not None else None

    def _tick(self) -> None:
        if self.writer.error is None:
            self.writer.flush_if_due()
            return
        # Stopped here, not in the failing write: that runs in a subscription's callback.
        while self._subscriptions_recorded:
            self.destroy_subscription(self._subscriptions_recorded.pop())
        now_ns = self.get_clock().now().nanoseconds
        if self._failure_reported_ns is None or \
                now_ns - self._failure_reported_ns >= FAILURE_REPORT_PERIOD_S * 1e9:
            self._report_failure(now_ns)

    def _on_write_error(self, writer: BagWriter) -> None:
        self._report_failure(self.get_clock().now().nanoseconds)

    def _report_failure(self, now_ns: int) -> None:
        writer = self.writer
        first = self._failure_reported_ns is None
        self._failure_reported_ns = now_ns
        values = {'path': str(writer.path), 'error': os_error_text(writer.error),
                  'messages_kept': writer.message_count}
        if first:  # logged once, published until the recorder stops
            self.diagnostics.report('bag', ERROR, writer.failure, values)
        else:
            self.diagnostics.publish([('bag', ERROR, writer.failure, values)])

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
            if self.writer.error is None:
                self.get_logger().info(f'bag closed: {self.writer.message_count} messages in '
                                       f'{self.writer.path}')
            elif self._failure_reported_ns is None:  # failed while closing: the log only
                self.get_logger().error(f'bag: {self.writer.failure}')
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.recorder -o DIR [-t TOPIC ...] [--robot NAME]``."""

    def add_arguments(parser):
        parser.add_argument('-o', '--output', default=None,
                            help='bag directory to create (default bags/gait_<date-time>)')
        parser.add_argument('-t', '--topics', nargs='+', default=None, metavar='TOPIC',
                            help='topics to record (default: every contract topic); '
                                 'non-contract topics as name:pkg/msg/Type; relative names '
                                 'resolve under the namespace (--ros-args -r __ns:=/robot1)')
        parser.add_argument('--robot', default=None, metavar='NAME',
                            help="also record this robot's per-foot topics "
                                 '(/gait/contact_wrench/<foot>, the physics simulator\'s)')

    recorders = []

    def factory(options):
        topics = parse_topics(options.topics) if options.topics else None
        recorders.append(Recorder(output=options.output, topics=topics, robot=options.robot))
        return recorders[-1]

    status = run_node(factory, args, prog='python -m gait_nodes.recorder',
                      description=__doc__.split('\n\n')[0], add_arguments=add_arguments)
    # A bag cut short is a failure of the recording, already reported (log, /diagnostics).
    return 1 if status == 0 and recorders and recorders[0].failure else status


if __name__ == '__main__':
    sys.exit(main())
