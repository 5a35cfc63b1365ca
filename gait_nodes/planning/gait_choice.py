"""Which of a robot's gaits walks fastest at its joint velocity limit (``gait: auto``).

Thesis 000, IV.C asks which gait is faster at a joint velocity limit. Here every gait the robot
has (its YAML ``gaits``: RoboSimian's ZMP crawl, static crawl and trot) is planned by the
footstep planner's own :class:`~gait_nodes.planning.footsteps.GaitPlanner`, timed at the
robot's joint velocity limit (``timing: joint_limit`` with the robot's swing timing model,
:func:`gait_nodes.swing.timing.swing_timing`), walking straight ahead asked for
:data:`COMMANDED_SPEED_M_S`: far more than it can walk, so the planner's velocity clamp walks
the fastest rhythm the joints allow within the longest stride. A gait's speed is the net
displacement of its feet over :data:`STEADY_STEPS` steps (whole cycles) after the first
:data:`START_STEPS` (the start from standstill), divided by their time, with every re-timing
the planner makes (a step whose swings or body move need more time than the rhythm gives)
included.

A gait is infeasible when the planner refuses it (a setting the robot cannot keep, a rhythm the
joints cannot walk at any speed, a planning error) or re-times its steps beyond use: steady
steps lasting more than :data:`RETIMED_BEYOND_USE` times the rhythm the velocity clamp chose
(the planner re-times a step whose swings or body move need more time at the joint limit, a
few times at most). The joint limits are the planner's own: the ZMP gaits' rhythm at the
velocity limit, the static crawl's at the velocity and acceleration limits. (The stricter
probe of fixed-timing plans, :meth:`GaitPlanner.check_joint_speeds`, times every swing at the
acceleration limit as well and finds RoboSimian's ZMP gaits 5 % short at 3 rad/s and 40 % at 4;
walked there by the node graph they keep the ZMP inside, the joints below 0.93 of the limit and
the COM within a millimetre of its reference: :mod:`gait_nodes.walked_crossover`.) The fastest
feasible gait is chosen; with none, the robot's first gait.

The gaits are compared with :data:`COMPARED_WITH`, the footstep planner's shipped settings
(``config/footstep_planner.yaml``: the polynomial swing, 0.1 m high), whatever the planner is
then asked to walk with: the choice is made once per robot and limit, needs no value table, and
no command waits for it. Planning the three RoboSimian gaits takes about 3.7 s.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import GaitNodesError
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.gait_params import GaitParameters

#: Forward speed asked of every gait [m/s] (and its max_vx_m_s): beyond what any walks.
COMMANDED_SPEED_M_S = 1.0
#: Steps of the start from standstill, left out of the speed.
START_STEPS = 2
#: Steps (two gait cycles) whose displacement over their time is the gait's speed.
STEADY_STEPS = 4
#: Steady steps lasting more than this times the rhythm's are re-timed beyond use.
RETIMED_BEYOND_USE = 1.5
#: The settings the gaits are compared with: the footstep planner's shipped ones.
COMPARED_WITH = {'timing': 'joint_limit', 'swing': 'polynomial', 'step_height_m': 0.1}


@dataclass(frozen=True)
class PlannedGait:
    """One gait planned straight ahead at the velocity clamp.

    Attributes:
        gait: The gait.
        speed_m_s: Net speed of the steady steps [m/s] (0: not planned).
        step_period_s: Mean duration of the steady steps [s] (0: not planned).
        rhythm_period_s: The step period of the planner's joint-limit rhythm at the clamped
            velocity [s] (the steady steps take longer when the planner re-times them).
        reason: Why the gait is infeasible ('' when feasible): not planned, or its steps
            re-timed beyond use (then with its speed and steps as planned).
    """

    gait: str
    speed_m_s: float = 0.0
    step_period_s: float = 0.0
    rhythm_period_s: float = 0.0
    reason: str = ''

    @property
    def feasible(self) -> bool:
        """Whether the gait walks within the joint limits (a speed > 0, no reason against)."""
        return not self.reason and self.speed_m_s > 0.0

    def describe(self) -> str:
        """``'trot 0.0194 m/s (steps of 5.16 s)'`` or ``'trot infeasible (...): why'``."""
        if self.step_period_s > 0.0:
            retimed = self.step_period_s / self.rhythm_period_s
            more = f', re-timed x{retimed:.2f}' if retimed > 1.0 + 1e-3 else ''
            walk = f'{self.speed_m_s:.4f} m/s (steps of {self.step_period_s:.2f} s{more})'
            if self.feasible:
                return f'{self.gait} {walk}'
            return f'{self.gait} infeasible (planned {walk}): {self.reason}'
        return f'{self.gait} infeasible: {self.reason}'


@dataclass(frozen=True)
class GaitChoice:
    """The gaits of a robot compared at its joint velocity limit, and the one chosen.

    Attributes:
        robot: Robot name.
        joint_velocity_limit_rad_s: The limit [rad/s].
        gait: The gait chosen: the fastest feasible one, else the robot's first.
        candidates: Every gait, fastest first (infeasible ones last).
        compared_with: The settings the gaits were planned with, in words.
        seconds: Wall time of the comparison [s].
    """

    robot: str
    joint_velocity_limit_rad_s: float
    gait: str
    candidates: tuple[PlannedGait, ...]
    compared_with: str
    seconds: float

    def candidate(self, gait: str) -> PlannedGait:
        """The planned walk of ``gait``."""
        return next(c for c in self.candidates if c.gait == gait)

    def describe(self) -> str:
        """Which gait and why, in one line (the planner's log and its 'gait' diagnostic)."""
        feasible = any(c.feasible for c in self.candidates)
        why = ('the fastest planned walk' if feasible else
               'none of the gaits can be planned, so the first one')
        return (f'{self.gait}, {why} at {self.joint_velocity_limit_rad_s:g} rad/s '
                f'({self.compared_with}; straight ahead at the velocity clamp): '
                + '; '.join(c.describe() for c in self.candidates))


def plan_gait(robot, gait: str, swing_timing, **settings) -> PlannedGait:
    """Plan ``gait`` straight ahead at the velocity clamp (see the module docstring).

    Args:
        robot: The robot description.
        gait: One of its gaits.
        swing_timing: The swing timing model at the robot's limit
            (:func:`gait_nodes.swing.timing.swing_timing`).
        **settings: Gait parameters besides the gait (default :data:`COMPARED_WITH`).
    """
    try:
        params = GaitParameters.for_robot(robot, **{**COMPARED_WITH, **settings}, gait=gait,
                                          max_vx_m_s=COMMANDED_SPEED_M_S)
        planner = GaitPlanner(robot, params, swing_timing=swing_timing)
        twist, _ = planner.set_velocity(Twist2D(COMMANDED_SPEED_M_S), 0.0)
        if twist.is_zero():
            return PlannedGait(gait, reason='the joints cannot walk it at any speed within the '
                               'stride')
        rhythm = planner.rhythm()
        rhythm_period_s = params.step_period_s if rhythm is None else rhythm.step_period_s
        needed = START_STEPS + STEADY_STEPS
        until_s = 0.0
        for _ in range(4 * needed):
            if len(planner.steps) >= needed:
                break
            until_s += rhythm_period_s
            planner.advance(until_s)
    except GaitNodesError as exc:
        return PlannedGait(gait, reason=str(exc))
    steady = planner.steps[START_STEPS:needed]
    if len(steady) < STEADY_STEPS or any(step.kind != 'walk' for step in steady):
        return PlannedGait(gait, reason=f'no steady walk planned by {until_s:.1f} s')
    first, last = steady[0], steady[-1]
    moved = last.positions_end.mean(axis=0) - first.positions_start.mean(axis=0)
    elapsed_s = last.end_s - first.start_s
    walk = PlannedGait(gait, float(np.hypot(*moved) / elapsed_s), elapsed_s / len(steady),
                       rhythm_period_s)
    if walk.step_period_s > RETIMED_BEYOND_USE * rhythm_period_s:
        return dataclasses.replace(walk, reason=(
            f'steps re-timed beyond use: the steady steps last {walk.step_period_s:.3f} s, '
            f'more than {RETIMED_BEYOND_USE:g} times the {rhythm_period_s:.3f} s of the rhythm '
            f'the velocity clamp chose'))
    return walk


def compare_gaits(robot_model, gaits=None, **settings) -> GaitChoice:
    """Every gait of ``robot_model`` planned at its joint velocity limit, the fastest chosen.

    Args:
        robot_model: The :class:`gait_nodes.robot.model.RobotModel` (its description's joint
            velocity limit is the one compared at).
        gaits: The gaits to compare (default: the robot's).
        **settings: Gait parameters besides the gait (default :data:`COMPARED_WITH`); the swing
            method and step height choose the swing timing model.
    """
    from gait_nodes.swing.timing import swing_timing

    started = time.perf_counter()
    robot = robot_model.description
    settings = {**COMPARED_WITH, **settings}
    planned = []
    for gait in gaits or robot.gaits:
        # Each gait with its own swings' time law (gait_nodes.swing.policy.law_placements).
        timing, source = swing_timing(robot_model, settings['swing'], settings['step_height_m'],
                                      gait)
        planned.append(plan_gait(robot, gait, timing, **settings))
    planned.sort(key=lambda c: (not c.feasible, -c.speed_m_s))
    chosen = planned[0].gait if planned[0].feasible else (gaits or robot.gaits)[0]
    words = (f'{settings["swing"]} swing, {settings["step_height_m"]:g} m lift, timing '
             f'{settings["timing"]}' + (f': {source}' if settings['swing'] == 'value_table'
                                        else ''))
    return GaitChoice(robot.name, robot.joint_velocity_limit_rad_s, chosen, tuple(planned),
                      words, time.perf_counter() - started)

