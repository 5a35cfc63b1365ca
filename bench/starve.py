"""Starve one node of the inproc graph for a while, as an overloaded core would, and measure.

A node process starved of CPU over DDS runs none of its callbacks: its timers fire once when it
is back (on their period grid, no burst), and each subscription hands it what its history kept
(the last ``depth`` messages). This script does exactly that to one node of the inproc graph
(deterministic, :mod:`gait_nodes.starvation`), records the bag and prints how the walk
recovered: ZMP samples outside the support polygon after the node is back, the least margin,
the ERROR/WARN statuses, the planner's pauses.

Usage: PYTHONPATH=. python bench/starve.py NODE AT_S GAP_S [--scenario NAME] [--duration S]
"""

from __future__ import annotations

import argparse
import collections
import json
import tempfile

from gait_nodes.__main__ import PROG
from gait_nodes.bag.analysis import inspect_bag, zmp_margins
from gait_nodes.starvation import InprocGraph

NS = 10**9


def run(scenario: str, node_name: str | None, at_s: float, gap_s: float, duration_s: float,
        bag: str, params: dict | None = None, pause: bool = False) -> None:
    """Record ``scenario`` with ``node_name`` starved from ``at_s`` for ``gap_s``.

    ``pause``: the planner follows the stale-input reports on /diagnostics as it does outside
    inproc (it pauses the walk while the robot is held).
    """
    with InprocGraph(scenario, params, bag, pause, prog=PROG) as graph:
        if node_name:
            graph.spin(at_s)
            graph.starve(node_name, gap_s)
            graph.spin(duration_s - at_s - gap_s)
        else:
            graph.spin(duration_s)


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
