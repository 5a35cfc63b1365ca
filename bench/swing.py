#!/usr/bin/env python3
"""Swing value-table build time and policy lookup time (issue 8 targets).

    python bench/swing.py [--lookups 200] [--family 2] [--small]

Builds a RoboSimian-scale table (x 0.2-0.8 m in 31, y -0.65 to -0.4 m in 14, 7 z levels 0.025
m apart, yaw +-0.45 rad in 11: 33,418 states; the default 218 actions) and prints the wall time
of the IK and one-step costs, of the value iteration, the sweeps run and the state-actions per
second of sweeping. Then times policy lookups (start state + greedy descent + IK timing of the
waypoints, :meth:`SwingPolicy.path_for_step`) for random steps of 0.1-0.45 m: median and p95.
``--small`` uses the default grid (2,145 states) instead. Targets: build <= 60 s on 2 cores,
lookup <= 2 ms. Figures only: nothing is asserted.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gait_nodes.robot.model import load_robot_model  # noqa: E402
from gait_nodes.swing.policy import SwingPolicy  # noqa: E402
from gait_nodes.swing.value_iteration import GridSpec, build_table  # noqa: E402

LARGE = GridSpec(x_range_m=(0.2, 0.8, 31), y_range_m=(-0.65, -0.4, 14), z_levels=7,
                 z_spacing_m=0.025, yaw_range_rad=(-0.45, 0.45, 11))


def main() -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--lookups', type=int, default=200)
    parser.add_argument('--family', type=int, default=2)
    parser.add_argument('--small', action='store_true')
    options = parser.parse_args()
    robot = load_robot_model('robosimian')
    spec = GridSpec() if options.small else LARGE
    started = time.perf_counter()
    table, report = build_table(robot, options.family, 0.1, 1.0, spec)
    total = time.perf_counter() - started
    print(f'build: {report.states} states x {report.actions} actions, {report.iterations} '
          f'sweeps; costs (IK) {report.cost_seconds:.2f} s, value iteration '
          f'{report.iteration_seconds:.2f} s, total {total:.2f} s (target <= 60 s); '
          f'{report.state_actions_per_second:.3g} state-actions/s per sweep')
    policy = SwingPolicy(table, robot)
    rng = np.random.default_rng(0)
    steps = np.column_stack([rng.uniform(0.1, 0.45, options.lookups),
                             rng.uniform(-0.03, 0.03, options.lookups)])
    policy.path_for_step(steps[0])  # warm-up
    times, waypoints = [], []
    for step in steps:
        started = time.perf_counter()
        path, _ = policy.path_for_step(step)
        times.append(time.perf_counter() - started)
        waypoints.append(len(path.swing_states))
    times_ms = 1e3 * np.array(times)
    print(f'lookup: median {np.median(times_ms):.2f} ms, p95 {np.percentile(times_ms, 95):.2f} '
          f'ms over {options.lookups} steps (target <= 2 ms); '
          f'{np.median(waypoints):.0f} greedy waypoints (median)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
