"""replay: republish a rosbag2 MCAP bag with its original timing over the chosen runtime.

``python -m gait_nodes.replay BAG [--rate R] [--topics T ...] [--clock [HZ]] [--loop]
[--delay S] [--runtime dds|inproc|rclpy] [--ros-args ...]``

Each recorded topic is published with the QoS its publishers offered (a topic every publisher
offered transient-local is replayed latched), so nodes and other ROS 2 tools (``ros2 topic
echo``, a recorder, Foxglove through a bridge) consume the recording as if it were live. Message
gaps are those of the recording's log times divided by ``--rate``. With ``--clock`` the bag time
is published on ``/clock`` (at HZ, default 100, and before every message), so that nodes run
with ``use_sim_time:=true`` follow it. Payloads are republished as the recorded CDR bytes; only
topics whose type this installation knows can be published, the others are listed and skipped.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable
from pathlib import Path

from gait_nodes.bag.reader import BagReader, Channel
from gait_nodes.cli import ArgumentParser, add_runtime_argument, fail, split_args
from gait_nodes.errors import ArgumentError, GaitNodesError, InterfaceError
from gait_nodes.interfaces import get_message
from gait_nodes.runtime.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

PROG = 'python -m gait_nodes.replay'


def replay_qos(offered: list[dict]) -> QoSProfile:
    """The QoS to replay a topic with, from rosbag2's ``offered_qos_profiles``.

    As ``ros2 bag play`` does: reliable and transient-local only when every recorded publisher
    offered them; the depth is the largest offered (at least 10). Both Jazzy's names
    (``reliable``) and older rosbag2 integers (1 = reliable / transient local) are understood.
    """
    def policy(profile: dict, key: str, strong_name: str) -> bool:
        value = profile.get(key)
        return value == strong_name or value == 1

    if not offered:
        return QoSProfile(depth=10)
    reliable = all(policy(p, 'reliability', 'reliable') for p in offered)
    latched = all(policy(p, 'durability', 'transient_local') for p in offered)
    depths = [p.get('depth') for p in offered if isinstance(p.get('depth'), int)]
    return QoSProfile(
        depth=max([10, *depths]) if not latched else max([1, *depths]),
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=(DurabilityPolicy.TRANSIENT_LOCAL if latched
                    else DurabilityPolicy.VOLATILE))


def bag_channels(reader: BagReader) -> dict[str, Channel]:
    """Topic -> channel of a bag, from a pass over the files (no message is decoded)."""
    for _ in reader.messages(topics=()):
        pass
    return {channel.topic: channel for channel in reader.channels.values()}


def _bag_topic(topic: str, channels) -> str:
    """``topic`` as the bag names it: ``/gait/zmp`` is ``/robot1/gait/zmp`` in a namespaced bag."""
    if topic in channels:
        return topic
    from gait_nodes.bag.analysis import bag_namespace

    try:
        namespace = bag_namespace(channels)
    except GaitNodesError:
        return topic  # several graphs: only the full name tells
    candidate = namespace.rstrip('/') + '/' + topic.lstrip('/')
    return candidate if candidate in channels else topic


class Replayer:
    """Plays a bag through publishers of one node.

    Args:
        node: The node that owns the publishers (any runtime).
        bag: Bag directory or ``.mcap`` file.
        rate: Playback speed factor (> 0).
        topics: Topics to play (all known types when None).
        clock_hz: Publish ``/clock`` at this rate [Hz]; 0 for no clock.
    """

    def __init__(self, node, bag: str | Path, rate: float = 1.0,
                 topics: Iterable[str] | None = None, clock_hz: float = 0.0):
        if not rate > 0:
            raise ArgumentError(f'--rate must be > 0, got {rate}')
        if clock_hz < 0:
            raise ArgumentError(f'--clock rate must be >= 0 Hz, got {clock_hz}')
        self.node = node
        self.bag = Path(bag)
        self.rate = rate
        self.clock_period_ns = int(1e9 / clock_hz) if clock_hz > 0 else 0
        channels = bag_channels(BagReader(self.bag))
        wanted = {_bag_topic(topic, channels) for topic in topics} if topics else set(channels)
        missing = sorted(wanted - set(channels))
        if missing:
            raise ArgumentError(f'topics not in {self.bag}: {missing}; the bag has '
                                f'{sorted(channels)}')
        self.publishers = {}
        self.skipped: dict[str, str] = {}
        for topic in sorted(wanted):
            channel = channels[topic]
            if channel.message_encoding != 'cdr':
                self.skipped[topic] = f'message encoding {channel.message_encoding!r}'
                continue
            try:
                msg_type = get_message(channel.type_name)
            except InterfaceError:
                self.skipped[topic] = f'type {channel.type_name} is not known here'
                continue
            self.publishers[topic] = node.create_publisher(
                msg_type, topic, replay_qos(channel.offered_qos()))
        self.clock_publisher = (node.create_publisher(get_message('rosgraph_msgs/msg/Clock'),
                                                      '/clock', 10)
                                if self.clock_period_ns else None)
        self.published = 0
        self.damage = []

    def _publish_clock(self, bag_ns: int) -> None:
        clock = get_message('rosgraph_msgs/msg/Clock')()
        clock.clock.sec, clock.clock.nanosec = divmod(bag_ns, 1_000_000_000)
        self.clock_publisher.publish(clock)

    def play_once(self, executor, progress=None) -> int:
        """Play the bag once, waiting between messages with ``executor.spin_for``.

        Args:
            executor: The executor spinning the node (and, under inproc, the consumers).
            progress: Called with the bag time played [s] since the last call.

        Returns:
            Messages published.
        """
        reader = BagReader(self.bag)
        start_bag_ns = None
        start_wall = 0.0
        inproc = executor.inproc
        played_ns = 0
        next_clock_ns = 0
        count = 0
        from gait_nodes import runtime

        for channel, log_ns, _, data in reader.messages(topics=list(self.publishers)):
            if not runtime.ok(context=self.node.context):
                break
            if start_bag_ns is None:
                start_bag_ns = log_ns
                start_wall = time.monotonic()
                next_clock_ns = log_ns
            offset_ns = max(log_ns - start_bag_ns, 0)
            while self.clock_publisher is not None and next_clock_ns <= log_ns:
                self._wait(executor, inproc, start_wall, next_clock_ns - start_bag_ns,
                           played_ns)
                played_ns = max(played_ns, next_clock_ns - start_bag_ns)
                self._publish_clock(next_clock_ns)
                next_clock_ns += self.clock_period_ns
            self._wait(executor, inproc, start_wall, offset_ns, played_ns)
            if progress is not None and offset_ns > played_ns:
                progress((offset_ns - played_ns) * 1e-9)
            played_ns = max(played_ns, offset_ns)
            self.publishers[channel.topic].publish(data)
            count += 1
        executor.spin_for(0.0)
        self.published += count
        self.damage = reader.damage
        return count

    def _wait(self, executor, inproc: bool, start_wall: float, offset_ns: int,
              played_ns: int) -> None:
        if inproc:
            if offset_ns > played_ns:
                executor.spin_for((offset_ns - played_ns) * 1e-9 / self.rate)
            return
        due = start_wall + offset_ns * 1e-9 / self.rate
        left = due - time.monotonic()
        if left > 0:
            executor.spin_for(left)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``python -m gait_nodes.replay``."""
    from gait_nodes import runtime

    user, ros = split_args(args)
    parser = ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', help='rosbag2 directory or .mcap file')
    parser.add_argument('--rate', type=float, default=1.0, help='playback speed factor')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC',
                        help="topics to play, as the bag names them (a namespaced bag's "
                             'contract topics also without its namespace)')
    parser.add_argument('--clock', nargs='?', type=float, const=100.0, default=0.0,
                        metavar='HZ', help='publish the bag time on /clock (default 100 Hz)')
    parser.add_argument('--loop', action='store_true', help='play again and again')
    parser.add_argument('--delay', type=float, default=None, metavar='S',
                        help='wait S seconds for subscribers to match before playing '
                             '(default 1 s over DDS, 0 in-process)')
    parser.add_argument('--progress', dest='progress', action='store_true', default=None,
                        help='always show progress on stderr (default: when it is a terminal)')
    add_runtime_argument(parser)
    options = parser.parse_args(user)
    try:
        runtime.init(args=[PROG, *ros], runtime=options.runtime)
    except GaitNodesError as error:
        return fail(PROG, error)
    try:
        node = runtime.Node('replay')
        replayer = Replayer(node, options.bag, rate=options.rate, topics=options.topics,
                            clock_hz=options.clock)
        for topic, reason in replayer.skipped.items():
            print(f'{PROG}: skipping {topic}: {reason}', file=sys.stderr)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        delay = options.delay if options.delay is not None else (0.0 if executor.inproc
                                                                 else 1.0)
        if delay > 0:
            executor.spin_for(delay)
        from tqdm import tqdm

        show = options.progress or (options.progress is None and sys.stderr.isatty())
        while True:
            with tqdm(unit='s', desc='replaying', disable=not show, file=sys.stderr,
                      bar_format='{desc}: {n:.1f} s of bag time [{elapsed}]',
                      leave=False) as bar:
                count = replayer.play_once(executor, progress=bar.update)
            for damage in replayer.damage:
                print(f'{PROG}: DAMAGE: {damage.describe()}', file=sys.stderr)
            print(f'replayed {count} messages on {len(replayer.publishers)} topics from '
                  f'{options.bag}', file=sys.stderr)
            if not options.loop or count == 0 or not runtime.ok():
                break
    except GaitNodesError as error:
        return fail(PROG, error)
    except KeyboardInterrupt:
        pass
    finally:
        runtime.shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
