#!/usr/bin/env python3
"""whole_body_ik node alone: CPU per 5 ms tick, its inputs replayed from a graph run.

    python bench/ik_node.py [--scenario robosimian_crawl] [--duration 20] [--runs 5]
                            [--profile] [--cache FILE]

One inproc graph run of the scenario (every contract node, no recorder) records what the
whole_body_ik node is handed: each callback (its timer, /joint_states, /tf,
/gait/com_reference, /gait/footsteps, /gait/swing_trajectory) with the simulated time and the
message. Then a fresh node, alone, is handed the same callbacks at the same simulated times
``--runs`` times (a subscription the node has dropped meanwhile is skipped, as the executor
would): the CPU time of its callbacks per tick (median of the runs, and per callback kind),
nothing else of the graph in the figure. Every replay's /joint_commands are checked equal
to the graph run's (the same floats), so a figure is never that of a node that does otherwise.
``--profile`` adds a cProfile of one replay.

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
RATE_HZ = 200.0


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


def record(scenario_name: str, duration_s: float) -> tuple[list, list]:
    """The whole_body_ik node's callbacks of one graph run, and its /joint_commands.

    Returns:
        ``(events, commands)``: ``(time_ns, kind, msg)`` per callback, ``(positions,
        velocities)`` per published command.
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
        ik.publisher.publish = lambda msg: (commands.append((list(msg.position),
                                                             list(msg.velocity))),
                                            publish(msg))
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
        node.publisher.publish = lambda msg: commands.append((msg.position, msg.velocity))
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
    finally:
        runtime.shutdown()
    return seconds, commands


def main() -> int:
    """Record once, replay ``--runs`` times, print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='robosimian_crawl')
    parser.add_argument('--duration', type=float, default=20.0)
    parser.add_argument('--runs', type=int, default=5)
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
    ticks = args.duration * RATE_HZ
    runs = []
    for run in range(args.runs):
        seconds, replayed = replay(args.scenario, events, args.profile and run == 0)
        same = len(replayed) == len(commands) and all(
            list(p) == c[0] and list(v) == c[1] for (p, v), c in zip(replayed, commands,
                                                                     strict=True))
        if not same:
            print('replayed /joint_commands differ from the graph run\'s', file=sys.stderr)
            return 1
        runs.append(seconds)
    kinds = sorted({kind for _, kind, _ in events})
    counts = {kind: sum(1 for _, k, _ in events if k == kind) for kind in kinds}
    total = [sum(r.values()) for r in runs]
    print(f'{NODE} alone, {args.scenario}, {args.duration:g} s at {RATE_HZ:g} Hz, '
          f'{len(events)} callbacks replayed, {args.runs} runs (commands equal to the graph '
          f'run\'s)')
    print(f'  CPU per 5 ms tick, median: {np.median(total) / ticks * 1e6:.1f} us '
          f'(runs: {", ".join(f"{t / ticks * 1e6:.1f}" for t in total)})')
    for kind in kinds:
        median = float(np.median([r.get(kind, 0.0) for r in runs]))
        print(f'    {kind:24s} {median / ticks * 1e6:7.1f} us per tick, '
              f'{median / counts[kind] * 1e6:7.1f} us per call ({counts[kind]} calls)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
