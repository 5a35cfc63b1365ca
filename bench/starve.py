"""Starve one node of the inproc graph for a while, as an overloaded core would, and measure.

A node process starved of CPU over DDS runs none of its callbacks: its timers fire once when it
is back (on their period grid, no burst), and each subscription hands it what its history kept
(the last ``depth`` messages). This script does exactly that to one node of the inproc graph
(deterministic), records the bag and prints how the walk recovered: ZMP samples outside the
support polygon after the node is back, the least margin, the ERROR/WARN statuses, the planner's
pauses.

Usage: PYTHONPATH=. python bench/starve.py NODE AT_S GAP_S [--scenario NAME] [--duration S]
"""

from __future__ import annotations

import argparse
import collections
import json
import tempfile
from pathlib import Path

import yaml

from gait_nodes import graph, runtime
from gait_nodes.__main__ import PROG, TopicCounter, _graph_params
from gait_nodes.bag.analysis import inspect_bag, zmp_margins
from gait_nodes.interfaces import get_message
from gait_nodes.scenarios import CommandDriver, get_scenario

NS = 10**9


class Starvation:
    """Holds back every callback of one node between two instants, then lets it go."""

    def __init__(self, node):
        self.node = node
        self.held: list = []  # (subscription, message) in arrival order
        self.saved: dict = {}

    def start(self) -> None:
        """From now on the node's messages wait in its histories and its timers do not fire."""
        kept = {}
        for subscription in self.node._subscriptions:
            depth = max(getattr(subscription.qos_profile, 'depth', 1) or 1, 1)
            kept[id(subscription)] = collections.deque(maxlen=depth)
            self.saved[id(subscription)] = subscription.callback
            queue = kept[id(subscription)]
            subscription.callback = (lambda q: lambda msg: q.append(msg))(queue)
        self.kept = kept
        self.arrivals = []
        for timer in self.node._timers:
            timer._starved_next = timer.next_call_ns
            timer.next_call_ns = 1 << 62

    def stop(self, now_ns: int) -> None:
        """The node runs again at ``now_ns`` [ns]."""
        # Subscriptions first (what waited in the history), then the timers, once, on their grid.
        pending = []
        for subscription in self.node._subscriptions:
            pending.extend((subscription, m) for m in self.kept[id(subscription)])
            subscription.callback = self.saved[id(subscription)]
        for subscription, msg in pending:
            subscription.callback(msg)
        for timer in self.node._timers:
            nxt = timer._starved_next
            if nxt < now_ns:
                nxt += -(-(now_ns - nxt) // timer.timer_period_ns) * timer.timer_period_ns
            timer.next_call_ns = nxt


def run(scenario: str, node_name: str | None, at_s: float, gap_s: float, duration_s: float,
        bag: str, params: dict | None = None, pause: bool = False) -> None:
    """Record ``scenario`` with ``node_name`` starved from ``at_s`` for ``gap_s``.

    ``pause``: the planner follows the stale-input reports on /diagnostics as it does outside
    inproc (it pauses the walk while the robot is held).
    """

    class Options:
        pass

    options = Options()
    options.scenario, options.robot, options.gait = scenario, None, None
    values = _graph_params(options)
    if params:
        values['/**']['ros__parameters'].update(params)
    with tempfile.TemporaryDirectory() as tmp:
        params_file = Path(tmp) / 'p.yaml'
        params_file.write_text(yaml.safe_dump(values))
        runtime.init(args=[PROG, '--ros-args', '--params-file', str(params_file)],
                     runtime='inproc')
    try:
        executor = runtime.SingleThreadedExecutor()
        nodes = {}
        for name in graph.available_nodes():
            nodes[name] = graph.load_class(graph.NODES[name])()
            executor.add_node(nodes[name])
        executor.add_node(graph.load_class(graph.RECORDER)(output=bag))
        if pause:
            planner = nodes['footstep_planner']
            planner.create_subscription(
                get_message('diagnostic_msgs/msg/DiagnosticArray'), '/diagnostics',
                planner.on_diagnostics, 50)
        monitor = runtime.Node('gait_run_monitor', use_global_arguments=False)
        TopicCounter(monitor)
        driver = CommandDriver(monitor, get_scenario(scenario).commands)
        executor.add_node(monitor)
        driver.start()
        transport = runtime.default_context().transport
        if node_name:
            executor.spin_for(at_s)
            starvation = Starvation(nodes[node_name])
            starvation.start()
            executor.spin_for(gap_s)
            starvation.stop(transport.now_ns)
            executor._drain()
            executor.spin_for(duration_s - at_s - gap_s)
        else:
            executor.spin_for(duration_s)
    finally:
        runtime.shutdown()


def measure(bag: str, back_s: float) -> dict:
    """How the walk went, and how it went after ``back_s`` (the node's return)."""
    inspection = inspect_bag(bag, robot='robosimian')
    series = inspection.series
    stamps, margins = zmp_margins(series)
    outside = margins < 0
    after = stamps >= back_s * NS
    out_after = stamps[outside & after]
    diag = collections.Counter()
    messages = collections.Counter()
    for _, name, level, message, *_ in series.diagnostics:
        if level >= 1:
            diag[(name.split('/')[-1].split(':')[0], level)] += 1
            messages[(level, message[:90])] += 1
    gait = inspection.report.get('gait') or {}
    return {
        'samples': len(margins), 'outside': int(outside.sum()),
        'outside_after_back': int(len(out_after)),
        'last_outside_after_back_s': (round(out_after[-1] / NS - back_s, 3)
                                      if len(out_after) else None),
        'min_margin_mm': round(float(margins.min()) * 1e3, 1),
        'min_margin_after_back_plus_0.1s_mm': round(float(
            margins[stamps >= (back_s + 0.1) * NS].min()) * 1e3, 1),
        'warn_error': {f'{k[0]}:{k[1]}': v for k, v in sorted(diag.items())},
        'messages': {f'{k[0]} {k[1]}': v for k, v in sorted(messages.items())},
        'steps': (gait.get('steps') or {}).get('count'),
        'walked_m': (gait.get('base') or {}).get('distance_m'),
    }


def main() -> None:
    """Command line: starve one node, print the measures as JSON."""
    parser = argparse.ArgumentParser()
    parser.add_argument('node', help="node to starve, or 'none'")
    parser.add_argument('at_s', type=float)
    parser.add_argument('gap_s', type=float)
    parser.add_argument('--scenario', default='robosimian_crawl')
    parser.add_argument('--duration', type=float, default=14.0)
    parser.add_argument('--bag', default=None)
    parser.add_argument('--swing', default=None, help='swing parameter override')
    parser.add_argument('--pause', action='store_true',
                        help='the planner pauses on stale-input reports, as outside inproc')
    args = parser.parse_args()
    bag = args.bag or tempfile.mkdtemp(prefix='starve_') + '/bag'
    params = {'swing': args.swing} if args.swing else None
    run(args.scenario, None if args.node == 'none' else args.node, args.at_s, args.gap_s,
        args.duration, bag, params, args.pause)
    result = measure(bag, args.at_s + args.gap_s)
    result.update(node=args.node, at_s=args.at_s, gap_s=args.gap_s, pause=args.pause, bag=bag)
    print(json.dumps(result, indent=1))


if __name__ == '__main__':
    main()
