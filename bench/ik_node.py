#!/usr/bin/env python3
"""whole_body_ik node alone: CPU-seconds per second walked, its inputs replayed from a graph run.

    python bench/ik_node.py [--scenario robosimian_crawl] [--duration 20] [--runs 5]
                            [--com-horizon S] [--profile] [--cache FILE]

One inproc graph run of the scenario (every contract node, no recorder) records what the
whole_body_ik node is handed: each callback (its timer, /joint_states, /tf,
/gait/com_reference, /gait/footsteps, /gait/swing_trajectory) with the simulated time and the
message. Then a fresh node, alone, is handed the same callbacks at the same simulated times
``--runs`` times (a subscription the node has dropped meanwhile is skipped, as the executor
would): the CPU time of its callbacks per second walked (median of the runs, and per callback
kind), nothing else of the graph in the figure. Every replay's /joint_commands (each
JointTrajectory's times, positions and velocities) are checked equal to the graph run's (the
same floats), so a figure is never that of a node that does otherwise. ``--profile`` adds a
cProfile of one replay.

``--com-horizon S`` hands the node, instead of the graph's /gait/com_reference messages, one
message every ``--com-period`` (0.05 s) carrying the graph run's COM states from then to S
seconds later, every ``--com-sample`` (0.02 s): the stamped horizon of the agreed design, from
a graph whose com_preview_controller still publishes one state per tick. The commands are then
checked equal between the replays (the graph run's IK had other inputs).

``--cache FILE`` keeps the graph run's callbacks (messages as CDR) and commands in FILE and
replays from there when FILE holds the same scenario and duration: a replay then runs without
the graph run, e.g. under ``valgrind --tool=callgrind``, where the instructions of
``--runs 2`` minus those of ``--runs 1`` are one replay's (the node alone, no wall-clock noise
from the other processes of the machine). Valgrind has no AVX-512, so OpenBLAS picks another
kernel there and the floats (and the commands) would differ from a native recording: set
``OPENBLAS_CORETYPE=Haswell`` for the recording and the replays alike.

Figures only: nothing is asserted but the equality of the commands.
"""

from __future__ import annotations

import argparse
import pickle
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gait_nodes import graph, runtime  # noqa: E402
from gait_nodes.scenarios import CommandDriver, get_scenario  # noqa: E402

NODE = 'whole_body_ik'


def _init(scenario) -> None:
    import yaml

    params_file = Path(tempfile.mkdtemp(prefix='bench_ik_node_')) / 'graph_params.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'robot': scenario.robot, **scenario.settings}}}))
    runtime.init(args=['bench', '--ros-args', '--params-file', str(params_file)],
                 runtime='inproc', signal_handlers=False)


def _callbacks(node) -> dict[str, object]:
    """The node's callbacks by name: 'timer' and the subscriptions' topics."""
    found = {'timer': node._timers}
    found.update({s.topic_name: [s] for s in node._subscriptions})
    return found


def trajectory_of(msg) -> tuple[list[int], list[list[float]], list[list[float]]]:
    """A /joint_commands JointTrajectory's point times [ns], positions and velocities."""
    from gait_nodes.contract import time_msg_to_ns

    start_ns = time_msg_to_ns(msg.header.stamp)
    return ([start_ns + time_msg_to_ns(p.time_from_start) for p in msg.points],
            [list(p.positions) for p in msg.points], [list(p.velocities) for p in msg.points])


def with_com_horizon(events: list, horizon_s: float, period_s: float,
                     sample_s: float) -> list:
    """``events`` with the /gait/com_reference ones replaced by messages with a horizon.

    One message every ``period_s`` (at the recorded COM events whose time is a multiple of
    it), holding the recorded COM states from that time to ``horizon_s`` later, ``sample_s``
    apart (the states of one-state messages; the latest one at or before each sample time).
    """
    import bisect

    from gait_nodes.contract import com_reference_from_msg, com_reference_to_msg

    kind = '/gait/com_reference'
    states = [com_reference_from_msg(msg)[0] for _, k, msg in events if k == kind]
    stamps = [state.stamp_ns for state in states]
    period_ns = int(round(period_s * 1e9))
    offsets = [int(round(k * sample_s * 1e9)) for k in range(int(horizon_s / sample_s) + 1)]
    replaced = []
    for now_ns, k, msg in events:
        if k != kind:
            replaced.append((now_ns, k, msg))
        elif now_ns % period_ns == 0:
            picked = [states[max(bisect.bisect_right(stamps, now_ns + dt) - 1, 0)]
                      for dt in offsets]
            horizon = [picked[0]] + [b for a, b in zip(picked[:-1], picked[1:], strict=True)
                                     if b.stamp_ns > a.stamp_ns]
            replaced.append((now_ns, k, com_reference_to_msg(horizon)))
    return replaced


def record(scenario_name: str, duration_s: float) -> tuple[list, list]:
    """The whole_body_ik node's callbacks of one graph run, and its /joint_commands.

    Returns:
        ``(events, commands)``: ``(time_ns, kind, msg)`` per callback, :func:`trajectory_of`
        each published command.
    """
    scenario = get_scenario(scenario_name)
    _init(scenario)
    events, commands = [], []
    try:
        nodes = [graph.load_class(graph.NODES[name])() for name in graph.available_nodes()]
        driver_node = runtime.Node('gait_run_monitor', use_global_arguments=False)
        driver = CommandDriver(driver_node, scenario.commands)
        nodes.append(driver_node)
        transport = runtime.default_context().transport
        ik = next(node for node in nodes if node.get_name() == NODE)
        for kind, holders in _callbacks(ik).items():
            for holder in holders:
                def logged(*args, _callback=holder.callback, _kind=kind):
                    events.append((transport.now_ns, _kind, args[0] if args else None))
                    return _callback(*args)

                holder.callback = logged
        publish = ik.publisher.publish
        ik.publisher.publish = lambda msg: (commands.append(trajectory_of(msg)), publish(msg))
        executor = runtime.SingleThreadedExecutor()
        for node in nodes:
            executor.add_node(node)
        driver.start()
        executor.spin_for(duration_s)
    finally:
        runtime.shutdown()
    return events, commands


def save(path: Path, scenario_name: str, duration_s: float, events: list,
         commands: list) -> None:
    """Keep :func:`record`'s results in ``path``, each message as its type and CDR bytes."""
    from gait_nodes.interfaces import message_type_name, serialize_message

    stored = [(now_ns, kind, None, None) if msg is None
              else (now_ns, kind, message_type_name(msg), serialize_message(msg))
              for now_ns, kind, msg in events]
    with open(path, 'wb') as file:
        pickle.dump({'scenario': scenario_name, 'duration_s': duration_s, 'events': stored,
                     'commands': commands}, file)


def load(path: Path, scenario_name: str, duration_s: float) -> tuple[list, list] | None:
    """:func:`record`'s results kept by :func:`save`, or None if ``path`` holds another run."""
    from gait_nodes.interfaces import get_message

    if not path.exists():
        return None
    with open(path, 'rb') as file:
        stored = pickle.load(file)  # noqa: S301 - a file this bench wrote
    if stored['scenario'] != scenario_name or stored['duration_s'] != duration_s:
        return None
    events = [(now_ns, kind, None if type_name is None
               else get_message(type_name).deserialize(data))
              for now_ns, kind, type_name, data in stored['events']]
    return events, stored['commands']


def replay(scenario_name: str, events: list, profile: bool = False) -> tuple[dict, list]:
    """CPU time [s] per callback kind of a fresh node handed ``events``, and its commands."""
    from gait_nodes.whole_body_ik import WholeBodyIk

    _init(get_scenario(scenario_name))
    seconds: dict[str, float] = {}
    commands = []
    try:
        node = WholeBodyIk()
        transport = runtime.default_context().transport
        node.publisher.publish = commands.append  # (read after the timing)
        holders = {kind: found[0] for kind, found in _callbacks(node).items()}
        callbacks = {kind: holder.callback for kind, holder in holders.items()}
        subscriptions = node._subscriptions
        profiler = None
        if profile:
            import cProfile

            profiler = cProfile.Profile()
            profiler.enable()
        clock = time.thread_time
        for now_ns, kind, msg in events:
            if msg is not None and holders[kind] not in subscriptions:
                continue  # the node dropped the subscription: the executor would not call it
            transport.now_ns = now_ns
            callback = callbacks[kind]
            start = clock()
            if msg is None:
                callback()
            else:
                callback(msg)
            seconds[kind] = seconds.get(kind, 0.0) + clock() - start
        if profiler is not None:
            profiler.disable()
            import pstats

            pstats.Stats(profiler).sort_stats('tottime').print_stats(30)
        commands = [trajectory_of(msg) for msg in commands]
    finally:
        runtime.shutdown()
    return seconds, commands


def main() -> int:
    """Record once, replay ``--runs`` times, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='robosimian_crawl')
    parser.add_argument('--duration', type=float, default=20.0)
    parser.add_argument('--runs', type=int, default=5)
    parser.add_argument('--com-horizon', type=float, help='COM horizon [s] (see above)')
    parser.add_argument('--com-period', type=float, default=0.05)
    parser.add_argument('--com-sample', type=float, default=0.02)
    parser.add_argument('--profile', action='store_true')
    parser.add_argument('--cache', type=Path, help='file keeping the graph run (see above)')
    args = parser.parse_args()
    kept = load(args.cache, args.scenario, args.duration) if args.cache else None
    if kept is None:
        events, commands = record(args.scenario, args.duration)
        if args.cache:
            save(args.cache, args.scenario, args.duration, events, commands)
    else:
        events, commands = kept
    source = 'the graph run\'s'
    if args.com_horizon is not None:
        events = with_com_horizon(events, args.com_horizon, args.com_period, args.com_sample)
        commands, source = None, 'each other'
    runs = []
    for run in range(args.runs):
        seconds, replayed = replay(args.scenario, events, args.profile and run == 0)
        if commands is None:
            commands = replayed
        if replayed != commands:
            print(f'replayed /joint_commands differ from {source}', file=sys.stderr)
            return 1
        runs.append(seconds)
    kinds = sorted({kind for _, kind, _ in events})
    counts = {kind: sum(1 for _, k, _ in events if k == kind) for kind in kinds}
    total = [sum(r.values()) for r in runs]
    points = sum(len(times) for times, _, _ in commands)
    horizon = 'the graph\'s COM reference' if args.com_horizon is None else (
        f'a {args.com_horizon:g} s COM horizon every {args.com_period:g} s')
    print(f'{NODE} alone, {args.scenario}, {args.duration:g} s walked, {horizon}, '
          f'{len(events)} callbacks replayed, {args.runs} runs (commands equal to {source}); '
          f'{len(commands)} /joint_commands, {points / max(len(commands), 1):.1f} points each')
    print(f'  CPU-seconds per second walked, median: {np.median(total) / args.duration:.4f} '
          f'(runs: {", ".join(f"{t / args.duration:.4f}" for t in total)})')
    for kind in kinds:
        median = float(np.median([r.get(kind, 0.0) for r in runs]))
        print(f'    {kind:24s} {median / args.duration:7.4f} s/s, '
              f'{median / counts[kind] * 1e6:8.1f} us per call ({counts[kind]} calls)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
