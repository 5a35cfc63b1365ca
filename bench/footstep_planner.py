"""Speed of footstep_planner: one tick (plan, footsteps, 2 s ZMP reference, messages).

``PYTHONPATH=. python bench/footstep_planner.py`` prints medians in microseconds for each gait:
the planning core alone (advance + footstep plan + 201 ZMP samples) and the whole tick with the
contract messages built, side by side, so the cost of message construction is visible.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from gait_nodes.contract import footsteps_to_msg, zmp_reference_to_msg
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.robot.description import load_robot_description

ROBOTS = Path(__file__).resolve().parent.parent / 'test' / 'data' / 'robots'
CASES = {'crawl': ('quadruped', {}), 'trot': ('quadruped', {'gait': 'trot', 'duty_factor': 0.7}),
         'biped': ('biped', {'duty_factor': 0.9})}
TICK_S, HORIZON_S, PERIOD_S = 0.1, 2.5, 0.01  # the node's defaults: 10 Hz, 2.5 s, 10 ms


def run(gait: str, with_messages: bool, seconds: float = 30.0) -> list[float]:
    """Tick costs [s] of a 30 s turning walk of ``gait``."""
    robot_name, values = CASES[gait]
    robot = load_robot_description(ROBOTS / f'{robot_name}.yaml')
    params = GaitParameters.for_robot(robot, step_period_s=1.0, max_wz_rad_s=0.2, **values)
    planner = GaitPlanner(robot, params)
    planner.set_velocity(Twist2D(0.1, 0.0, 0.1), 0.0)
    costs = []
    for k in range(int(seconds / TICK_S)):
        now_s = k * TICK_S
        start = time.perf_counter()
        planner.advance(now_s + HORIZON_S + params.step_period_s)
        planner.prune(now_s)
        plan = planner.footstep_plan(now_s)
        reference = planner.zmp_reference(int(now_s * 1e9), 0, HORIZON_S, PERIOD_S)
        if with_messages:
            footsteps_to_msg(plan)
            zmp_reference_to_msg(reference)
        costs.append(time.perf_counter() - start)
    return costs


def main() -> None:
    """Print the median and 95th percentile tick cost per gait."""
    print(f'{"gait":6} {"core median us":>15} {"core p95 us":>12} {"tick+msgs median us":>20} '
          f'{"tick+msgs p95 us":>17} {"budget at 10 Hz":>16}')
    for gait in CASES:
        core, whole = run(gait, False), run(gait, True)
        p95 = statistics.quantiles
        print(f'{gait:6} {statistics.median(core) * 1e6:15.0f} {p95(core, n=20)[-1] * 1e6:12.0f} '
              f'{statistics.median(whole) * 1e6:20.0f} {p95(whole, n=20)[-1] * 1e6:17.0f} '
              f'{statistics.median(whole) / TICK_S * 100:15.1f}%')


if __name__ == '__main__':
    main()
