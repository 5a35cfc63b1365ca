#!/usr/bin/env python3
"""The kinematic_simulator node alone: CPU per 5 ms tick on a recorded walk's inputs.

    python bench/sim_node.py BAG [--scenario robosimian_crawl] [--duration S] [--runs 3]
                             [--check] [--profile]

Replays the /joint_commands and /gait/footsteps of a bag of the graph (``python -m gait_nodes
run --scenario S --record BAG``, S the scenario of ``--scenario``, whose parameters the node
gets) into the node under the ``inproc`` runtime, each message at its logged instant and before
the simulator's tick of that instant (as whole_body_ik's tick comes before it in the graph), for
as long as the bag recorded the simulator (or ``--duration`` s), and times the node's callbacks
(its tick and subscriptions, CPU time of the thread): the ``kinematic_simulator`` row of
``bench/sim.py``'s graph run without the other nodes' noise and cache pollution. With
``--check`` the node's /joint_states, /tf, /gait/zmp, /gait/com, /gait/support_polygon and
/gait/markers are compared with the bag's, message by message and byte for byte: a speed change
of the node must leave them as they were.

Prints the CPU per tick of each run and their median. Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import yaml  # noqa: E402

from gait_nodes import runtime  # noqa: E402
from gait_nodes.bag.reader import BagReader  # noqa: E402
from gait_nodes.interfaces import get_message, serialize_message  # noqa: E402
from gait_nodes.runtime import DurabilityPolicy, QoSProfile  # noqa: E402
from gait_nodes.scenarios import get_scenario  # noqa: E402

RATE_HZ = 200.0
INPUTS = {'/joint_commands': 10,
          '/gait/footsteps': QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)}
OUTPUTS = ('/joint_states', '/tf', '/gait/zmp', '/gait/com', '/gait/support_polygon',
           '/gait/markers')


def recorded(bag: Path) -> tuple[list, dict, dict]:
    """(log time [ns], topic, message) of the inputs; CDR bytes of the outputs; topic types."""
    inputs, outputs, types = [], {topic: [] for topic in OUTPUTS}, {}
    for channel, log_time_ns, _, data in BagReader(bag).messages():
        types[channel.topic] = channel.type_name
        if channel.topic in INPUTS:
            inputs.append((log_time_ns, channel.topic,
                           get_message(channel.type_name).deserialize(data)))
        elif channel.topic in outputs:
            outputs[channel.topic].append(bytes(data))
    inputs.sort(key=lambda item: item[0])  # stable: messages of one instant keep their order
    return inputs, outputs, types


class Replay(runtime.Node):
    """Publishes the recorded inputs at their logged instants."""

    def __init__(self, inputs: list, types: dict):
        super().__init__('bench_replay', use_global_arguments=False)
        self.inputs = inputs
        self.next = 0
        self.publishers_by_topic = {
            topic: self.create_publisher(get_message(types[topic]), topic, qos)
            for topic, qos in INPUTS.items() if topic in types}
        self.create_timer(1.0 / RATE_HZ, self.tick)

    def tick(self) -> None:
        """Publish what was logged up to now."""
        now_ns = self.get_clock().now().nanoseconds
        while self.next < len(self.inputs) and self.inputs[self.next][0] <= now_ns:
            _, topic, msg = self.inputs[self.next]
            self.publishers_by_topic[topic].publish(msg)
            self.next += 1


class Sink(runtime.Node):
    """Keeps the CDR bytes of the simulator's outputs."""

    def __init__(self, types: dict):
        super().__init__('bench_sink', use_global_arguments=False)
        self.received = {topic: [] for topic in OUTPUTS}
        for topic in OUTPUTS:
            if topic in types:
                self.create_subscription(get_message(types[topic]), topic,
                                         self.received[topic].append, 1000)


def run(inputs: list, types: dict, params_file: Path, duration_s: float, check: bool,
        profile: bool) -> tuple[float, dict | None]:
    """One replay: CPU [s] of the simulator's callbacks, and its outputs (with ``check``)."""
    runtime.init(args=['bench', '--ros-args', '--params-file', str(params_file)],
                 runtime='inproc', signal_handlers=False)
    try:
        from gait_nodes.kinematic_simulator import KinematicSimulator

        replay = Replay(inputs, types)
        simulator = KinematicSimulator()
        cpu_s = [0.0]

        def timed(callback):
            def call(*args):
                start = time.thread_time()
                try:
                    return callback(*args)
                finally:
                    cpu_s[0] += time.thread_time() - start
            return call

        for item in (*simulator._timers, *simulator._subscriptions):
            item.callback = timed(item.callback)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(replay)
        executor.add_node(simulator)
        sink = Sink(types) if check else None
        if sink is not None:
            executor.add_node(sink)
        profiler = None
        if profile:
            import cProfile

            profiler = cProfile.Profile()
            profiler.enable()
        executor.spin_for(duration_s)
        if profiler is not None:
            import pstats

            profiler.disable()
            pstats.Stats(profiler).sort_stats('tottime').print_stats(30)
        outputs = None
        if sink is not None:
            outputs = {topic: [serialize_message(m) for m in messages]
                       for topic, messages in sink.received.items()}
        return cpu_s[0], outputs
    finally:
        runtime.shutdown()


def main() -> int:
    """Replay, time and (with --check) compare."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', type=Path)
    parser.add_argument('--scenario', default='robosimian_crawl')
    parser.add_argument('--duration', type=float, default=None, help='[s]; default: the bag')
    parser.add_argument('--runs', type=int, default=3)
    parser.add_argument('--check', action='store_true', help='compare outputs with the bag')
    parser.add_argument('--profile', action='store_true', help='cProfile one run')
    options = parser.parse_args()
    inputs, expected, types = recorded(options.bag)
    scenario = get_scenario(options.scenario)
    params_file = Path(tempfile.mkdtemp(prefix='bench_sim_node_')) / 'params.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'robot': scenario.robot, **scenario.settings}}}))
    if options.duration is None:
        options.duration = len(expected['/joint_states']) / RATE_HZ
    ticks = options.duration * RATE_HZ
    if options.check or options.profile:
        _, outputs = run(inputs, types, params_file, options.duration, options.check,
                         options.profile)
        if outputs is not None:
            for topic in OUTPUTS:
                want, got = expected[topic], outputs[topic]
                pairs = enumerate(zip(want, got, strict=False))
                first = next((k for k, (a, b) in pairs if a != b), None)
                same = first is None and len(want) == len(got)
                print(f'{topic:24s} {len(want):6d} recorded {len(got):6d} now  '
                      + ('identical' if same else f'DIFFER (first at #{first})'))
    costs = [run(inputs, types, params_file, options.duration, False, False)[0] / ticks
             for _ in range(options.runs)]
    print(f'kinematic_simulator alone, {options.scenario}, {options.duration:g} s at '
          f'{RATE_HZ:g} Hz: CPU per tick ' + ', '.join(f'{c * 1e6:.1f}' for c in costs)
          + f' us; median {statistics.median(costs) * 1e6:.1f} us')
    return 0


if __name__ == '__main__':
    sys.exit(main())
