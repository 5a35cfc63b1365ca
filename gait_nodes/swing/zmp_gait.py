"""The joint speed a ZMP gait needs (thesis 000, IV.A.2, Fig. 10; Figs. 8 and 10 of thesis.py).

The ZMP-based gaits are the footstep planner's crawl (the thesis' ZMP gait: the ZMP reference
from the diagonal pairs, moving twice a cycle, III.B.1) and its trot (ZMP on the support
diagonal): the planner's ZMP reference, the COM by Kajita preview control, the body carried
with the COM at the nominal body height, stance feet where planned and swing feet on the
sixth-order polynomial swing. Every foot's limb IK (one family) over the walk, differentiated
in time, gives the joint speed the gait needs at a given step length and period (thesis IV.A.2,
Fig. 10, for the stance limbs or for every limb).

Which gait is fastest at a joint velocity limit is no longer read off this model: ``gait:
auto`` plans each gait with the footstep planner (:mod:`gait_nodes.planning.gait_choice`) and
Fig. 21 walks each with the node graph (:mod:`gait_nodes.walked_crossover`).
"""

from __future__ import annotations

import numpy as np

from gait_nodes.com.preview import PreviewSettings, preview_batch
from gait_nodes.errors import GaitNodesError
from gait_nodes.planning.footsteps import Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.swing.kinematics import LimbTiming
from gait_nodes.swing.polynomial import evaluate, polynomial_swing

#: Duty factor of each ZMP gait (crawl: > 3/4, one foot at a time; trot: > 1/2).
DUTY_FACTORS = {'crawl': 0.8, 'trot': 0.6}
#: Sample time of the joint-speed evaluation [s].
SAMPLE_S = 0.01


def zmp_gait_joint_speed(robot, gait: str, step_length_m: float, step_period_s: float,
                         family: int, step_height_m: float = 0.1, cycles: int = 4,
                         stance_only: bool = False, description=None) -> float:
    """Largest joint speed [rad/s] of a ZMP gait in steady walking (inf if out of reach).

    Args:
        robot: A RobotModel with RoboSimian's limb IK.
        gait: 'crawl' or 'trot'.
        step_length_m: Stride of each foot per swing [m].
        step_period_s: One step, half a cycle [s].
        family: IK family of every limb.
        step_height_m: Swing height of the polynomial swing [m].
        cycles: Gait cycles walked; the joint speed is taken over the last half of them.
        stance_only: Only the stance limbs' joints count (thesis IV.A.2, Fig. 10: the joint
            speed that carrying the body on the ZMP plan needs), not the swinging limb's.
        description: The robot description to plan with (default ``robot.description``), e.g.
            one with a longer ``reach`` to evaluate steps the walker does not take.
    """
    description = description or robot.description
    try:
        params = GaitParameters.for_robot(
            description, gait=gait, step_length_m=step_length_m, step_period_s=step_period_s,
            duty_factor=DUTY_FACTORS[gait], step_height_m=step_height_m, max_vx_m_s=10.0)
    except GaitNodesError:
        return float('inf')
    speed = step_length_m / params.cycle_s
    duration = (cycles + 1) * params.cycle_s
    planner = plan_walk(description, params, [(0.0, Twist2D(speed, 0.0, 0.0))], duration)
    plan = planner.footstep_plan(0.0)
    times = np.arange(0.0, duration, SAMPLE_S)
    com = preview_batch(planner.zmp(times), PreviewSettings(
        com_height_m=description.com_height_m, dt_s=SAMPLE_S))
    window = times >= 0.5 * cycles * params.cycle_s
    window &= times <= cycles * params.cycle_s
    timing = LimbTiming(robot, family, 1.0)
    ik = timing.ik
    feet = np.empty((len(times), len(plan.foot_names), 3))
    swinging = np.zeros((len(times), len(plan.foot_names)), dtype=bool)
    for k, t in enumerate(times):
        feet[k] = plan.stance_positions_at(t)
    for swing in plan.swings():
        # Samples touching the swing (lift-off and touch-down included) for stance_only.
        f = plan.foot_names.index(swing.foot)
        swinging[(times >= swing.lift_off_s) & (times <= swing.touch_down_s), f] = True
        inside = (times > swing.lift_off_s) & (times < swing.touch_down_s)
        if not inside.any():
            continue
        _, coefficients = polynomial_swing(swing, 0, step_height_m)
        feet[inside, f] = evaluate(coefficients, times[inside] - swing.lift_off_s)[:, :3]
    body = np.column_stack([com.positions_in_world,
                            np.full(len(times), description.body_height_m)])
    worst = 0.0
    for f, foot in enumerate(plan.foot_names):
        targets = (feet[window, f] - body[window])
        q, feasible = ik.solve(targets, np.zeros(len(targets)), family, foot)
        if not feasible.all():
            return float('inf')
        speeds = np.abs(np.diff(q[:, :6], axis=0)).max(axis=1) / SAMPLE_S
        if stance_only:
            stance = ~swinging[window, f]
            speeds = speeds[stance[:-1] & stance[1:]]
        worst = max(worst, float(speeds.max(initial=0.0)))
    return worst

