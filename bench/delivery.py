#!/usr/bin/env python3
"""The inproc runtime's own cost per 5 ms tick of the gait graph: executor, delivery, recorder.

    python bench/delivery.py [--bag DIR] [--duration 20] [--runs 3] [--profile]

Replays a recorded bag of the graph (``python -m gait_nodes run --record DIR``; without
``--bag``, the robosimian_crawl scenario is recorded first with ``--fast``) through the
``inproc`` runtime with the graph's shape but none of its work: one stand-in node per graph node,
with that node's timers (periods and creation order), publishers and subscriptions (callbacks
that do nothing), each timer publishing the bag's messages of its node's topics logged at that
instant, and the real recorder writing a new bag. What is measured is therefore exactly the part
of ``bench/sim.py``'s graph run that is neither a node's computation nor message building: the
executor loop, timers, publish and delivery, CDR serialization of the recorded messages and the
recorder (bag writer). The new bag must be the old one byte for byte (checked: a mismatch is
printed). Two differences with the graph: the replayed messages were all decoded beforehand, so
they share no parts (what ``serialize_published`` saves on the nodes' shared vertex lists and
sliding ZMP reference does not show here), and reading them misses the CPU caches more than
freshly built ones do; the figures are an upper bound of the graph's.

Prints, as medians over ``--runs``: CPU per 5 ms tick of the whole replay, of the recorder's
callbacks, and of serializing the recorded messages (measured apart, on the same messages).
Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import collections
import gc
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mcap.reader import make_reader  # noqa: E402

from gait_nodes import graph  # noqa: E402
from gait_nodes.interfaces import get_message  # noqa: E402

TICK_NS = 5_000_000
NS = 1_000_000_000

#: The graph's nodes in creation order: timer periods [ms] (in creation order), topics
#: published, topics subscribed. /diagnostics, published by all, is replayed by the simulator.
NODES = {
    'footstep_planner': ((100, 1000), ('/gait/footsteps', '/gait/zmp_reference',
                                      '/gait/command_status'),
                         ('/cmd_vel', '/gait/command', '/gait/swing_trajectory')),
    'com_preview_controller': ((50, 1000), ('/gait/com_reference',),
                               ('/gait/zmp_reference', '/gait/footsteps', '/gait/com')),
    'swing_leg_policy': ((20,), ('/gait/swing_trajectory',), ('/gait/footsteps',)),
    'whole_body_ik': ((50,), ('/joint_commands',),
                      ('/gait/com_reference', '/gait/footsteps', '/gait/swing_trajectory',
                       '/joint_states', '/tf')),
    'kinematic_simulator': ((5,), ('/diagnostics', '/joint_states', '/tf', '/gait/zmp',
                                   '/gait/com', '/gait/support_polygon', '/gait/markers'),
                            ('/joint_commands', '/gait/footsteps')),
}
#: The scenario's command driver (bench/sim.py adds it after the recorder).
DRIVER = ('gait_run_monitor', ((20,), ('/cmd_vel', '/gait/command'), ()))
LATCHED = ('/gait/footsteps',)


def read_bag(bag: Path) -> dict[str, list[tuple[int, bytes]]]:
    """``{topic: [(log_time_ns, cdr), ...]}`` of a bag's MCAP file."""
    mcap = next(bag.glob('*.mcap'))
    messages = collections.defaultdict(list)
    with open(mcap, 'rb') as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            messages[channel.topic].append((message.log_time, bytes(message.data)))
    return messages


def replay(recorded: dict, duration_s: float, output: Path, profile: bool) -> dict:
    """One replay: CPU of the spin and of the recorder's callbacks [s], the new bag's path."""
    from gait_nodes import runtime
    from gait_nodes.recorder import Recorder

    end_ns = int(duration_s * NS)
    queues = {topic: collections.deque(
        (stamp, get_message(graph.TOPICS[topic]).deserialize(data))
        for stamp, data in messages if stamp <= end_ns)
        for topic, messages in recorded.items()}
    # The replayed messages, all made beforehand, are not the runtime's garbage: out of the
    # collector's sight (else its full collections would walk them all, unlike in the graph).
    gc.collect()
    gc.freeze()
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    try:
        nodes = []
        for name, (periods_ms, published, subscribed) in [*NODES.items(), DRIVER]:
            node = runtime.Node(name, use_global_arguments=False)
            publishers = []
            for topic in published:
                latched = topic in LATCHED
                qos = runtime.QoSProfile(
                    depth=1 if latched else 10,
                    durability=runtime.DurabilityPolicy.TRANSIENT_LOCAL if latched
                    else runtime.DurabilityPolicy.VOLATILE)
                publishers.append((node.create_publisher(
                    get_message(graph.TOPICS[topic]), topic, qos), queues.get(topic)))
            for topic in subscribed:
                latched = topic in LATCHED
                qos = runtime.QoSProfile(
                    depth=10, durability=runtime.DurabilityPolicy.TRANSIENT_LOCAL if latched
                    else runtime.DurabilityPolicy.VOLATILE)
                node.create_subscription(get_message(graph.TOPICS[topic]), topic,
                                         lambda msg: None, qos)
            for index, period_ms in enumerate(periods_ms):
                node.create_timer(period_ms / 1000, _player(node, publishers if index == 0
                                                            else []))
            nodes.append(node)
            if name == 'kinematic_simulator':
                nodes.append(Recorder(output=str(output)))
        recorder = nodes[len(NODES)]
        recorder_cpu = [0.0]
        for subscription in recorder._subscriptions:
            subscription.callback = _timed(subscription.callback, recorder_cpu)
        executor = runtime.SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        profiler = None
        if profile:
            import cProfile

            profiler = cProfile.Profile()
            profiler.enable()
        start = time.thread_time()
        executor.spin_for(duration_s)
        cpu = time.thread_time() - start
        if profiler is not None:
            profiler.disable()
            import pstats

            pstats.Stats(profiler).sort_stats('tottime').print_stats(30)
    finally:
        runtime.shutdown()
        gc.unfreeze()
    return {'cpu': cpu, 'recorder': recorder_cpu[0]}


def _player(node, publishers):
    clock = node.get_clock()

    def tick():
        now = clock.now_ns()
        for publisher, queue in publishers:
            while queue and queue[0][0] <= now:
                publisher.publish(queue.popleft()[1])

    return tick


def _timed(callback, total: list[float]):
    def timed(data):
        start = time.thread_time()
        callback(data)
        total[0] += time.thread_time() - start

    return timed


def serialization_cpu(recorded: dict, duration_s: float) -> float:
    """CPU [s] of serializing, once each, the messages the replay records."""
    end_ns = int(duration_s * NS)
    messages = [get_message(graph.TOPICS[topic]).deserialize(data)
                for topic, items in recorded.items() for stamp, data in items if stamp <= end_ns]
    start = time.thread_time()
    for message in messages:
        message.serialize()
    return time.thread_time() - start


def main() -> int:
    """Run the replays and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--bag', default=None,
                        help='a bag of the graph (default: robosimian_crawl recorded first)')
    parser.add_argument('--duration', type=float, default=20.0)
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--profile', action='store_true')
    options = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix='bench_delivery_'))
    results = []
    try:
        if options.bag is None:
            options.bag = str(work / 'graph')
            subprocess.run([sys.executable, '-m', 'gait_nodes', 'run', '--fast', '--scenario',
                            'robosimian_crawl', '--duration', str(options.duration),
                            '--record', options.bag, '--no-plot'],
                           check=True, stdout=subprocess.DEVNULL, cwd=REPO)
        recorded = read_bag(Path(options.bag))
        for run in range(options.runs):
            output = work / f'bag{run}'
            results.append(replay(recorded, options.duration, output, options.profile))
            replayed = read_bag(output)
            end_ns = int(options.duration * NS)
            for topic, items in recorded.items():
                if [m for m in items if m[0] <= end_ns] != replayed.get(topic, []):
                    print(f'  run {run}: {topic} differs from the bag replayed')
        serialize = [serialization_cpu(recorded, options.duration) for _ in range(options.runs)]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    ticks = options.duration * NS / TICK_NS
    total = statistics.median(r['cpu'] for r in results)
    recorder = statistics.median(r['recorder'] for r in results)
    print(f'replay of {options.bag}, {options.duration:g} s, {options.runs} runs (medians), '
          f'CPU per 5 ms tick:')
    print(f'  whole replay   {total / ticks * 1e6:6.1f} us  (runs: '
          + ', '.join(f'{r["cpu"] / ticks * 1e6:.1f}' for r in results) + ')')
    print(f'  recorder       {recorder / ticks * 1e6:6.1f} us  (its subscription callbacks)')
    print(f'  serialization  {statistics.median(serialize) / ticks * 1e6:6.1f} us  '
          f'(the recorded messages, measured apart)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
