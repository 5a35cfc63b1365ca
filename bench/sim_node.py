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
/gait/markers (the simulator's: namespace ``gait``) are compared with the bag's, message by
message and byte for byte: a speed change of the node must leave them as they were.

A bag whose /joint_commands are sensor_msgs/JointState setpoints (recorded before they became
trajectories) is replayed as whole_body_ik now publishes: every ``--period`` s a
trajectory_msgs/JointTrajectory of the setpoints from that instant to ``--horizon`` s later,
stamped at its first point, with their velocities. The outputs then differ from the bag's (the
joints now have acceleration limits); ``--check`` prints how far /joint_states are from the
setpoints and from the bag's /joint_states, and the monitor's least stability margin.

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

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from gait_nodes import runtime  # noqa: E402
from gait_nodes.bag.reader import BagReader  # noqa: E402
from gait_nodes.interfaces import get_message, serialize_message  # noqa: E402
from gait_nodes.markers import from_simulator  # noqa: E402
from gait_nodes.runtime import DurabilityPolicy, QoSProfile  # noqa: E402
from gait_nodes.scenarios import get_scenario  # noqa: E402

RATE_HZ = 200.0
#: whole_body_ik's publication period and horizon [s] (the agreed defaults).
PUBLISH_PERIOD_S = 0.05
HORIZON_S = 0.3
INPUTS = {'/joint_commands': 10,
          '/gait/footsteps': QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)}
OUTPUTS = ('/joint_states', '/tf', '/gait/zmp', '/gait/com', '/gait/support_polygon',
           '/gait/markers')


def trajectories_from_setpoints(setpoints: list, publish_period_s: float = PUBLISH_PERIOD_S,
                                horizon_s: float = HORIZON_S) -> list:
    """(log time [ns], JointTrajectory) as whole_body_ik publishes them, from JointStates.

    Args:
        setpoints: (log time [ns], sensor_msgs/JointState) of one joint vector each, in stamp
            order, every one naming the same joints.
        publish_period_s: One trajectory per this much of the setpoints' stamps [s].
        horizon_s: Each trajectory holds the setpoints from its first stamp to this later [s].

    Returns:
        The trajectories, each at the log time of its first setpoint.
    """
    from gait_nodes.contract import JointTrajectoryCommand, joint_trajectory_command_to_msg

    stamps = np.array([msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                       for _, msg in setpoints])
    positions = np.array([list(msg.position) for _, msg in setpoints])
    velocities = (np.array([list(msg.velocity) for _, msg in setpoints])
                  if all(len(msg.velocity) for _, msg in setpoints)
                  else np.gradient(positions, stamps * 1e-9, axis=0))
    names = tuple(setpoints[0][1].name)
    trajectories, next_ns = [], stamps[0]
    for k, stamp in enumerate(stamps):
        if stamp < next_ns:
            continue
        next_ns = stamp + int(publish_period_s * 1e9)
        end = int(np.searchsorted(stamps, stamp + int(horizon_s * 1e9), side='right'))
        command = JointTrajectoryCommand(int(stamp), names, stamps[k:end] - stamp,
                                         positions[k:end], velocities[k:end])
        trajectories.append((setpoints[k][0], joint_trajectory_command_to_msg(command)))
    return trajectories


def recorded(bag: Path) -> tuple[list, dict, dict]:
    """(log time [ns], topic, message) of the inputs; CDR bytes of the outputs; topic types.

    JointState /joint_commands come back as the trajectories of
    :func:`trajectories_from_setpoints`.
    """
    inputs, outputs, types, setpoints = [], {topic: [] for topic in OUTPUTS}, {}, []
    for channel, log_time_ns, _, data in BagReader(bag).messages():
        types[channel.topic] = channel.type_name
        if channel.topic in INPUTS:
            msg = get_message(channel.type_name).deserialize(data)
            if channel.type_name == 'sensor_msgs/msg/JointState':
                setpoints.append((log_time_ns, msg))
            else:
                inputs.append((log_time_ns, channel.topic, msg))
        elif channel.topic == '/gait/markers' and not from_simulator(
                get_message(channel.type_name).deserialize(data)):
            continue  # the planner's footholds or a swing's path
        elif channel.topic in outputs:
            outputs[channel.topic].append(bytes(data))
    if setpoints:
        inputs += [(log_ns, '/joint_commands', msg)
                   for log_ns, msg in trajectories_from_setpoints(setpoints)]
        types['/joint_commands'] = 'trajectory_msgs/msg/JointTrajectory'
    inputs.sort(key=lambda item: item[0])  # stable: messages of one instant keep their order
    return inputs, outputs, types


def tracking(expected: dict, outputs: dict) -> str:
    """How far the replayed /joint_states and /gait/zmp are from the bag's, stamp by stamp."""
    from gait_nodes.interfaces import deserialize_message

    def by_stamp(messages, type_name, values):
        table = {}
        for data in messages:
            msg = deserialize_message(bytes(data), get_message(type_name))
            table[msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec] = values(msg)
        return table

    lines = []
    for topic, type_name, values, unit in (
            ('/joint_states', 'sensor_msgs/msg/JointState',
             lambda m: np.array(m.position), 'rad'),
            ('/gait/zmp', 'geometry_msgs/msg/PointStamped',
             lambda m: np.array([m.point.x, m.point.y]), 'm')):
        now = by_stamp(outputs[topic], type_name, values)
        before = by_stamp(expected[topic], type_name, values)
        common = sorted(set(now) & set(before))
        if not common:
            continue
        gaps = np.array([np.abs(now[t] - before[t]).max() for t in common])
        lines.append(f'{topic}: {len(common)} common stamps, largest difference from the '
                     f'bag\'s {gaps.max():.3e} {unit}, 99th percentile '
                     f'{np.percentile(gaps, 99):.3e} {unit}')
    return '\n'.join(lines)


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
            print(tracking(expected, outputs))
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
