"""When to walk the ZMP gait and when the value-iteration crawl (thesis 000, IV.C, Fig. 21).

The value-iteration crawl is limited by its swing times, which scale as ``1 / W`` with the joint
velocity limit ``W``: its speed is ``W`` times its speed at 1 rad/s (thesis: "the gait speed
increases linearly according to the joint velocity limit"). It is read off a swing value table
(eq. (2), the fastest step within the robot's reach).

The ZMP-based gaits are the footstep planner's crawl (the thesis' ZMP gait: the ZMP reference
from the diagonal pairs, moving twice a cycle, III.B.1) and its trot (ZMP on the support
diagonal): the planner's ZMP reference, the COM by Kajita preview control, the body carried
with the COM at the nominal body height, stance feet where planned and swing feet on the
sixth-order polynomial swing. Every foot's limb IK (one family) over the walk, differentiated
in time, gives the joint speed the gait needs (thesis IV.A.2, Fig. 10, here for all limbs, not
only the stance ones). For a limit ``W`` the
gait's speed is the fastest step length and period whose joint speed stays within ``W``.

:func:`choose_gait` answers the question ``gait: auto`` asks: 'crawl' when the value-iteration
crawl (swing: value_table) or the ZMP crawl is fastest, 'trot' when the ZMP trot is;
:func:`recommend_gait` says which of the three and with what step and period.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from gait_nodes.com.preview import PreviewSettings, preview_batch
from gait_nodes.errors import GaitNodesError
from gait_nodes.planning.footsteps import Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.swing.kinematics import LimbTiming
from gait_nodes.swing.polynomial import evaluate, polynomial_swing

#: Step lengths [m] (as fractions of the robot's reach) and step periods [s] searched.
STEP_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
STEP_PERIODS_S = (0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0)
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


@dataclass(frozen=True)
class ZmpGaitTable:
    """Joint speed a ZMP gait needs over step lengths and periods.

    Attributes:
        gait: 'crawl' or 'trot'.
        step_lengths_m: (L,) strides [m].
        step_periods_s: (P,) step periods [s].
        joint_speeds_rad_s: (L, P) largest joint speed [rad/s] (inf: out of reach).
    """

    gait: str
    step_lengths_m: np.ndarray
    step_periods_s: np.ndarray
    joint_speeds_rad_s: np.ndarray

    def fastest(self, joint_velocity_limit_rad_s: float) -> tuple[float, float, float] | None:
        """``(speed [m/s], step [m], period [s])`` of the fastest walk within the limit."""
        speeds = self.step_lengths_m[:, None] / (2.0 * self.step_periods_s[None, :])
        allowed = self.joint_speeds_rad_s <= joint_velocity_limit_rad_s
        if not allowed.any():
            return None
        i, j = np.unravel_index(np.argmax(np.where(allowed, speeds, -1.0)), speeds.shape)
        return float(speeds[i, j]), float(self.step_lengths_m[i]), float(self.step_periods_s[j])


def zmp_gait_table_for(robot, gait: str, family: int, step_height_m: float, step_lengths_m,
                       step_periods_s=STEP_PERIODS_S, stance_only: bool = False,
                       description=None) -> ZmpGaitTable:
    """:class:`ZmpGaitTable` over given strides and periods (see :func:`zmp_gait_joint_speed`).

    ``stance_only``: only the stance limbs' joint speed limits the gait (the thesis' Figs. 10
    and 21), as if the swing leg were free; otherwise every limb's.
    """
    lengths = np.array(step_lengths_m, dtype=float)
    periods = np.array(step_periods_s, dtype=float)
    speeds = np.array([[zmp_gait_joint_speed(robot, gait, s, t, family, step_height_m,
                                              stance_only=stance_only, description=description)
                        for t in periods] for s in lengths])
    return ZmpGaitTable(gait, lengths, periods, speeds)


@functools.lru_cache(maxsize=8)
def zmp_gait_table(robot_name: str, gait: str, family: int, step_height_m: float
                   ) -> ZmpGaitTable:
    """:class:`ZmpGaitTable` of a robot within its reach (cached per process)."""
    from gait_nodes.robot.model import load_robot_model

    robot = load_robot_model(robot_name)
    reach = robot.description.reach.max_step_length_m
    return zmp_gait_table_for(robot, gait, family, step_height_m,
                              np.array(STEP_FRACTIONS) * reach)


@dataclass(frozen=True)
class GaitChoice:
    """One way to walk at a joint velocity limit.

    Attributes:
        name: 'value-iteration crawl', 'ZMP crawl' or 'ZMP trot'.
        gait: The planner's gait: 'crawl' or 'trot'.
        swing: The swing method: 'value_table' or 'polynomial'.
        speed_m_s: Walking speed [m/s] (0: no such walk within the limit).
        step_length_m: Stride [m] (ZMP gaits; the eq. (2) optimum for the crawl).
        step_period_s: Step period [s] (ZMP gaits; 0 for the value-iteration crawl).
    """

    name: str
    gait: str
    swing: str
    speed_m_s: float
    step_length_m: float
    step_period_s: float


@functools.lru_cache(maxsize=8)
def _crawl_curve(robot_name: str, family: int, step_height_m: float) -> tuple[float, float]:
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.swing.cache import load_or_build
    from gait_nodes.swing.sweep import speed_curve

    robot = load_robot_model(robot_name)
    limit = robot.description.joint_velocity_limit_rad_s
    table, _ = load_or_build(robot, family, step_height_m, limit)
    curve = speed_curve(table)
    within = np.flatnonzero(curve.steps_m <= robot.description.reach.max_step_length_m + 1e-9)
    best = within[int(np.argmax(curve.speeds_m_s[within]))]
    return float(curve.speeds_m_s[best]) / limit, float(curve.steps_m[best])


def compare_gaits(robot_name: str, joint_velocity_limit_rad_s: float, family: int = 2,
                  step_height_m: float = 0.1) -> list[GaitChoice]:
    """The value-iteration crawl, the ZMP crawl and the ZMP trot at a limit (thesis IV.C)."""
    if not joint_velocity_limit_rad_s > 0:
        raise GaitNodesError(f'joint velocity limit must be > 0 rad/s, got '
                             f'{joint_velocity_limit_rad_s}')
    per_limit, step = _crawl_curve(robot_name, family, step_height_m)
    choices = [GaitChoice('value-iteration crawl', 'crawl', 'value_table',
                          per_limit * joint_velocity_limit_rad_s, step, 0.0)]
    for gait in ('crawl', 'trot'):
        fastest = zmp_gait_table(robot_name, gait, family, step_height_m).fastest(
            joint_velocity_limit_rad_s)
        choices.append(GaitChoice(f'ZMP {gait}', gait, 'polynomial',
                                  *(fastest or (0.0, 0.0, 0.0))))
    return choices


def recommend_gait(robot_name: str, joint_velocity_limit_rad_s: float, family: int = 2,
                   step_height_m: float = 0.1) -> GaitChoice:
    """The fastest of :func:`compare_gaits`."""
    return max(compare_gaits(robot_name, joint_velocity_limit_rad_s, family, step_height_m),
               key=lambda c: c.speed_m_s)


def choose_gait(robot_name: str, joint_velocity_limit_rad_s: float, family: int = 2,
                step_height_m: float = 0.1) -> str:
    """'crawl' or 'trot': the gait of the fastest walk at this limit (for ``gait: auto``).

    A robot without closed-form limb IK, or without both gaits, gets its first gait.
    """
    from gait_nodes.robot.model import load_robot_model

    robot = load_robot_model(robot_name)
    gaits = robot.description.gaits
    if not {'crawl', 'trot'} <= set(gaits) or robot.description.extra.get('limb_ik') is None:
        return gaits[0]
    return recommend_gait(robot_name, joint_velocity_limit_rad_s, family, step_height_m).gait
