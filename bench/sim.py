#!/usr/bin/env python3
"""Kinematic simulator and ZMP monitor: per-tick cost, and the inproc graph's real-time factor.

    python bench/sim.py [--ticks 2000] [--robots robosimian,talos] [--duration 20]
                        [--scenario robosimian_crawl] [--runs 3] [--no-graph] [--no-ticks]
                        [--profile]

1. Per tick, for each robot, on a 200 Hz walking-like joint trajectory (whole-body IK of a
   swaying, drifting COM with one foot at a time swinging, as bench/ik.py builds it):
   ``step``: :meth:`KinematicSimulation.step` (actuators, forward kinematics, base fit);
   ``monitor``: central differences + :meth:`ZmpMonitor.evaluate` (centroidal momentum rate,
   ZMP, margin); ``node``: the kinematic_simulator node's whole tick under inproc, messages
   included (the trajectory replayed as /joint_commands, as whole_body_ik publishes it: a
   JointTrajectory of the next 0.3 s every 50 ms). Median and p99 [ms].
2. The inproc graph of ``python -m gait_nodes run --runtime inproc --record DIR`` (every
   installed contract node, the recorder writing a bag, the scenario's parameters and commands;
   default ``robosimian_crawl``) at 200 Hz for ``--duration`` s of simulated time, ``--runs``
   times: the real-time factor (target >= 20x) of each run and their median, on the wall clock
   and on the executor thread's CPU time (the machine may be shared: the CPU figure is what the
   graph itself costs on its thread, the wall figure adds what other processes took; the CPU of
   the whole process, with the bag writer's chunk-compression thread, is printed beside it); then
   ``--runs`` runs more with every callback timed, for where the CPU time goes (each node's
   timer and subscription callbacks per 5 ms tick, and the rest: executor, delivery,
   serialization for the recorder and the timing wrappers themselves; medians over the runs).
   The real-time factor comes from the untimed runs only.

Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import collections
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
for path in (REPO, REPO / 'bench'):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

from ik import walking_targets  # noqa: E402

from gait_nodes.errors import ConfigError  # noqa: E402
from gait_nodes.robot.model import load_robot_model  # noqa: E402
from gait_nodes.robot.whole_body_ik import (  # noqa: E402
    IkSettings,
    WholeBodyIkSolver,
    nominal_configuration,
)
from gait_nodes.sim.kinematics import KinematicSimulation  # noqa: E402
from gait_nodes.sim.zmp_monitor import ZmpMonitor, central_differences  # noqa: E402

RATE_HZ = 200.0
DT_S = 1.0 / RATE_HZ
NS = 1_000_000_000


def joint_trajectory(robot, ticks: int) -> tuple[np.ndarray, list[np.ndarray]]:
    """Nominal configuration and a walking-like joint trajectory (one joint vector per tick)."""
    q0 = nominal_configuration(robot)
    solver = WholeBodyIkSolver(robot, IkSettings())
    q = q0.copy()
    joints = []
    for targets in walking_targets(robot, q0, ticks):
        q = solver.solve(targets, q).q
        joints.append(robot.joint_positions(q))
    return q0, joints


def percentiles(samples_s: list[float]) -> str:
    """Median and p99 of samples [s], in [ms]."""
    ms = np.array(samples_s) * 1e3
    return f'median {np.median(ms):.3f} ms, p99 {np.percentile(ms, 99):.3f} ms'


def core_costs(robot, q0, joints) -> dict[str, list[float]]:
    """Seconds per tick of the simulation step and of the monitor update."""
    simulation = KinematicSimulation(robot, q0)
    monitor = ZmpMonitor(robot.model, robot.description.foot_radius_m)
    history = collections.deque([(q0, simulation.contact_points())] * 2, maxlen=3)
    costs = {'step': [], 'monitor': []}
    for command in joints:
        start = time.perf_counter()
        step = simulation.step(command, DT_S)
        middle = time.perf_counter()
        history.append((step.q, step.contact_points_in_world))
        (q_a, _), (q_b, points), (q_c, _) = history
        v, a = central_differences(robot.model, q_a, q_b, q_c, DT_S)
        monitor.evaluate(q_b, v, a, points[np.isfinite(points[:, 0])])
        end = time.perf_counter()
        costs['step'].append(middle - start)
        costs['monitor'].append(end - middle)
    return costs


def node_costs(robot_name: str, joints: list[np.ndarray]) -> list[float]:
    """Seconds per tick of the node (inproc), replaying ``joints`` as /joint_commands."""
    from sim_node import HORIZON_S, PUBLISH_PERIOD_S

    from gait_nodes import runtime
    from gait_nodes.contract import JointTrajectoryCommand, joint_trajectory_command_to_msg

    runtime.init(args=['bench', '--ros-args', '-p', f'robot:={robot_name}'], runtime='inproc',
                 signal_handlers=False)
    try:
        from gait_nodes.kinematic_simulator import KinematicSimulator

        simulator = KinematicSimulator()
        names = tuple(simulator.robot.joint_names)
        positions = np.array(joints)
        velocities = np.gradient(positions, DT_S, axis=0)
        every, ahead = round(PUBLISH_PERIOD_S / DT_S), round(HORIZON_S / DT_S) + 1
        # Tick k (at (k + 1) dt) publishes the trajectory from its own instant on.
        messages = {k: joint_trajectory_command_to_msg(JointTrajectoryCommand(
            (k + 1) * NS // int(RATE_HZ), names,
            np.arange(min(ahead, len(joints) - k)) * NS // int(RATE_HZ),
            positions[k:k + ahead], velocities[k:k + ahead]))
            for k in range(0, len(joints), every)}
        message_type = type(next(iter(messages.values())))

        class Replay(runtime.Node):
            def __init__(self):
                super().__init__('replay', use_global_arguments=False)
                self.publisher = self.create_publisher(message_type, '/joint_commands', 10)
                self.index = 0
                self.create_timer(DT_S, self.tick)

            def tick(self):
                if self.index in messages:
                    self.publisher.publish(messages[self.index])
                self.index += 1

        costs = []
        tick = simulator.tick

        def timed_tick():
            start = time.perf_counter()
            tick()
            costs.append(time.perf_counter() - start)

        simulator.timer.callback = timed_tick
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(Replay())
        executor.add_node(simulator)
        executor.spin_for(len(joints) * DT_S)
        return costs
    finally:
        runtime.shutdown()


class CallbackClock:
    """Accumulates the CPU time of every timer and subscription callback, per node."""

    def __init__(self):
        self.seconds = collections.Counter()
        self.calls = collections.Counter()

    def wrap(self, node) -> None:
        """Time every callback of ``node`` from now on."""
        name = node.get_name()
        for timer in node._timers:
            timer.callback = self._timed(name, timer.callback)
        for subscription in node._subscriptions:
            subscription.callback = self._timed(name, subscription.callback)

    def _timed(self, name: str, callback):
        def timed(*args):
            start = time.thread_time()
            try:
                return callback(*args)
            finally:
                self.seconds[name] += time.thread_time() - start
                self.calls[name] += 1

        return timed

    @staticmethod
    def cost_s(calls: int = 20000) -> float:
        """CPU time [s] this timing adds to one callback (two clock reads are ~1.3 us each)."""
        clock = CallbackClock()
        timed = clock._timed('calibration', lambda: None)
        plain = lambda: None  # noqa: E731
        start = time.thread_time()
        for _ in range(calls):
            plain()
        middle = time.thread_time()
        for _ in range(calls):
            timed()
        end = time.thread_time()
        return max((end - middle) - (middle - start), 0.0) / calls


def graph_run(duration_s: float, scenario_name: str, profile: bool, timed: bool) -> dict:
    """One inproc graph run of a scenario with the recorder: wall and CPU time.

    With ``timed``, every callback is wrapped to add up its CPU time per node; the wrappers
    themselves cost about 2 us per callback (two CPU-clock reads), so the real-time factor is
    taken from runs without them.
    """
    import yaml

    from gait_nodes import graph, runtime
    from gait_nodes.bag.analysis import inspect_bag
    from gait_nodes.scenarios import CommandDriver, get_scenario

    scenario = get_scenario(scenario_name)
    work = Path(tempfile.mkdtemp(prefix='bench_sim_'))
    bag_dir = work / 'bag'
    params_file = work / 'graph_params.yaml'
    params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'robot': scenario.robot, **scenario.settings}}}))
    runtime.init(args=['bench', '--ros-args', '--params-file', str(params_file)],
                 runtime='inproc', signal_handlers=False)
    clock = CallbackClock()
    try:
        setup_start = time.perf_counter()
        names = graph.available_nodes()
        nodes = [graph.load_class(graph.NODES[name])() for name in names]
        nodes.append(graph.load_class(graph.RECORDER)(output=str(bag_dir)))
        driver_node = runtime.Node('gait_run_monitor', use_global_arguments=False)
        driver = CommandDriver(driver_node, scenario.commands)
        nodes.append(driver_node)
        executor = runtime.SingleThreadedExecutor()
        for node in nodes:
            if timed:
                clock.wrap(node)
            executor.add_node(node)
        driver.start()
        setup = time.perf_counter() - setup_start
        profiler = None
        if profile:
            import cProfile

            profiler = cProfile.Profile()
            profiler.enable()
        start, start_cpu = time.perf_counter(), time.thread_time()
        start_process = time.process_time()
        executor.spin_for(duration_s)
        wall, cpu = time.perf_counter() - start, time.thread_time() - start_cpu
        process = time.process_time() - start_process
        if profiler is not None:
            profiler.disable()
    finally:
        close_start = time.perf_counter()
        runtime.shutdown()
        close = time.perf_counter() - close_start
    report = inspect_bag(bag_dir).report
    shutil.rmtree(work, ignore_errors=True)
    if profiler is not None:
        import pstats

        pstats.Stats(profiler).sort_stats('tottime').print_stats(25)
    return {'names': names, 'wall': wall, 'cpu': cpu, 'process': process, 'setup': setup,
            'close': close,
            'node_cpu': dict(clock.seconds), 'calls': dict(clock.calls), 'report': report,
            'timing_cost': CallbackClock.cost_s()}


def graph_runs(duration_s: float, scenario: str, runs: int, profile: bool) -> None:
    """``runs`` graph runs: real-time factors (each and median) and the per-node CPU cost."""
    results = [graph_run(duration_s, scenario, profile, timed=False) for _ in range(runs)]
    timed = [graph_run(duration_s, scenario, False, timed=True) for _ in range(runs)]
    first = timed[0]
    print(f'\ninproc graph: {", ".join(first["names"])} + recorder, scenario {scenario}, '
          f'{duration_s:g} s simulated at {RATE_HZ:g} Hz, {runs} runs')
    walls = [r['wall'] for r in results]
    cpus = [r['cpu'] for r in results]
    print(f'  real-time factor, median: wall {duration_s / np.median(walls):.1f}x, '
          f'CPU {duration_s / np.median(cpus):.1f}x (target >= 20x)')
    print('  runs: ' + ', '.join(f'wall {w:.2f} s ({duration_s / w:.1f}x) CPU {c:.2f} s '
                                 f'({duration_s / c:.1f}x)' for w, c in zip(walls, cpus,
                                                                           strict=True)))
    print(f'  node start-up {first["setup"]:.2f} s, bag close {first["close"]:.2f} s '
          f'(not counted)')
    ticks = duration_s * RATE_HZ
    processes = [r['process'] for r in results]
    print(f'  CPU per 5 ms tick, median of the runs: '
          f'{float(np.median(cpus)) / ticks * 1e6:.1f} us on the executor\'s thread, '
          f'{float(np.median(processes)) / ticks * 1e6:.1f} us for the whole process (the bag '
          f'writer compresses its chunks on a thread of its own)')
    cpu = float(np.median([r['cpu'] for r in timed]))
    names = sorted(first['node_cpu'], key=lambda n: -first['node_cpu'][n])
    print(f'  where it goes (as many runs again, every callback timed: total '
          f'{cpu / ticks * 1e6:.1f} us per tick with the timing wrappers)')
    callbacks = 0.0
    for name in names:
        seconds = float(np.median([r['node_cpu'].get(name, 0.0) for r in timed]))
        callbacks += seconds
        print(f'    {name:24s} {seconds / ticks * 1e6:7.1f} us  {100 * seconds / cpu:5.1f} %  '
              f'({first["calls"][name]} callbacks)')
    print(f'    {"executor, delivery, timing":24s} {(cpu - callbacks) / ticks * 1e6:7.1f} us  '
          f'{100 * (cpu - callbacks) / cpu:5.1f} %')
    timed_calls = sum(first['calls'].values())
    timing = float(np.median([r['timing_cost'] for r in results])) * timed_calls / ticks
    print(f'    (the bench\'s own timing of these {timed_calls / ticks:.1f} callbacks per tick '
          f'costs {timing * 1e6:.1f} us per tick, in the figures above: about half in the '
          f'nodes\', half in "executor and delivery")')
    report = first['report']
    gait = report.get('gait', {})
    margin = gait.get('zmp_margin') or {}
    base = gait.get('base') or {}
    print(f'  bag: {report["message_count"]} messages; walked {base.get("distance_m")} m; '
          f'ZMP margin min {margin.get("min_m")} m, {margin.get("samples_outside")} of '
          f'{margin.get("samples")} samples outside')


def main() -> int:
    """Run the benchmarks and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--ticks', type=int, default=2000)
    parser.add_argument('--robots', default='robosimian,talos')
    parser.add_argument('--duration', type=float, default=20.0)
    parser.add_argument('--scenario', default='robosimian_crawl',
                        help='scenario of the graph run (python -m gait_nodes run --scenario)')
    parser.add_argument('--runs', type=int, default=3, help='graph runs (median reported)')
    parser.add_argument('--no-graph', action='store_true')
    parser.add_argument('--no-ticks', action='store_true', help='only the graph run')
    parser.add_argument('--profile', action='store_true', help='cProfile the graph run')
    options = parser.parse_args()
    for name in [] if options.no_ticks else options.robots.split(','):
        try:
            robot = load_robot_model(name)
        except ConfigError as exc:
            print(f'{name}: skipped ({exc})')
            continue
        q0, joints = joint_trajectory(robot, options.ticks)
        costs = core_costs(robot, q0, joints)
        node = node_costs(name, joints)
        print(f'{name} ({len(robot.joint_names)} joints, {robot.model.nbodies - 1} bodies), '
              f'{options.ticks} ticks:')
        print(f'  step    {percentiles(costs["step"])}')
        print(f'  monitor {percentiles(costs["monitor"])}')
        print(f'  node    {percentiles(node)}  (whole tick, messages included)')
    if not options.no_graph:
        graph_runs(options.duration, options.scenario, options.runs, options.profile)
    return 0


if __name__ == '__main__':
    sys.exit(main())
