"""The whole graph after one node was starved of CPU, as on two overloaded cores (inproc).

Over DDS a node process can get no CPU for 50-300 ms. It then runs none of its callbacks: its
timers fire once when it is back (on their period grid, no burst) and each subscription hands
it what its history kept. :mod:`gait_nodes.starvation` does exactly that to one node of the
inproc graph, deterministically; the footstep planner follows the nodes' stale-input reports on
/diagnostics as it does outside inproc, so a starved whole-body IK pauses the walk (the
simulator's /joint_commands go stale) and the planner resumes it from the robot's measured
state, putting down first a foot it finds in the air.
"""

from __future__ import annotations

import numpy as np
import pytest

from gait_nodes.bag.analysis import inspect_bag, zmp_margins
from gait_nodes.bag.consistency import configurations
from gait_nodes.diagnostics import OK
from gait_nodes.robot.model import load_robot_model
from gait_nodes.starvation import InprocGraph

NS_PER_S = 10**9
#: The crawl's first swing (rear left) is in the air from about 2.0 s to 4.3 s.
STARVED_AT_S = 3.0
STARVED_FOR_S = 0.15
#: Simulated time: the resumed walk's landing and the first steps after it.
DURATION_S = 6.5
#: Height above the ground under which a foot is down [m].
ON_GROUND_M = 1e-3


@pytest.fixture
def starved_run(tmp_path):
    """``run(node_name)``: the polynomial crawl with that node starved; the bag's path."""

    def run(node_name: str):
        bag = tmp_path / 'bag'
        with InprocGraph('robosimian_crawl_polynomial', bag=str(bag), pause=True,
                         prog='test') as graph:
            graph.spin(STARVED_AT_S)
            graph.starve(node_name, STARVED_FOR_S)
            graph.spin(DURATION_S - STARVED_AT_S - STARVED_FOR_S)
        return bag

    return run


def test_a_walk_resumed_after_a_starved_ik_puts_the_foot_down_and_stays_balanced(starved_run):
    # The IK starved for 0.15 s mid-swing: the simulator reports /joint_commands stale, the
    # planner pauses, holds the rear left foot in the air, resumes and lowers it straight down.
    # That landing once got the polynomial swing's rise of step_height_m above its start: 0.1 m
    # up and 0.2 m down in one swing time, beyond the joint velocity limit; the IK saturated
    # (13x the limit demanded), the foot lagged and was still in the air at its touch-down, and
    # the ZMP left the support polygon there (the value-table crawl: the foot pinned 14 mm up,
    # the base tilted and the ZMP out by up to 26 m at the later contact changes).
    inspection = inspect_bag(starved_run('whole_body_ik'), robot='robosimian')
    series = inspection.series
    back_ns = int((STARVED_AT_S + STARVED_FOR_S) * NS_PER_S)
    resumed = [(stamp, message) for stamp, name, level, message, *_ in series.diagnostics
               if name == 'footstep_planner: walk' and level == OK
               and message.startswith('walking on after a pause')]
    assert resumed, 'the starved IK paused the walk and the planner resumed it'
    landing = next(s for p in series.plans for s in p.swings()
                   if p.start_ns > back_ns and s.start_in_world[2] > 0.05)
    landing_plan = next(p for p in series.plans if landing in p.swings())
    touch_down_ns = landing_plan.start_ns + int(round(landing.touch_down_s * NS_PER_S))
    assert touch_down_ns < DURATION_S * NS_PER_S - 0.5 * NS_PER_S
    # The lowered foot never rises above where it was held, and is down at its touch-down.
    robot = load_robot_model('robosimian')
    stamps, qs = configurations(robot, series)
    foot = robot.foot_names.index(landing.foot)
    data = robot.new_data()
    heights = np.array([robot.foot_poses(q, data)[0][foot][2] for q in qs])
    lift_ns = landing_plan.start_ns + int(round(landing.lift_off_s * NS_PER_S))
    during = (stamps >= lift_ns) & (stamps <= touch_down_ns)
    assert heights[during].max() <= landing.start_in_world[2] + ON_GROUND_M
    k = int(np.searchsorted(stamps, touch_down_ns))
    assert abs(heights[k] - landing.end_in_world[2]) < ON_GROUND_M
    # Once the IK is back (one tick for its jump to the present), the ZMP stays inside.
    zmp_stamps, margins = zmp_margins(series)
    after = zmp_stamps > back_ns + int(0.1 * NS_PER_S)
    assert margins[after].min() > 0.0
    # No joint was asked beyond its velocity limit (the IK's saturation report).
    assert not [message for _, name, level, message, *_ in series.diagnostics
                if name == 'whole_body_ik: velocity saturation' and level > OK]
