"""The swing timing models of the footstep planner's gait settings, each made once.

With ``timing: joint_limit`` on a robot with closed-form limb IK, a plan's rhythm follows from the
joint velocity limit and the swing method (:mod:`gait_nodes.swing.timing`): the value table's
swings (the cached table of :mod:`gait_nodes.swing.cache`; until swing_leg_policy has built it,
the polynomial swing's longer times stand in, and :meth:`TimingModels.retime` looks for it
again) or the polynomial swing's. A plan with fixed timing is checked against the joint speeds
by a probe: the timing model of its swing (closed-form limb IK) or the polynomial swing through
the whole-body IK. Models and probes take from milliseconds to seconds to make: they are made
in the planning worker (:class:`gait_nodes.planning.online.OnlinePlanner`), once per swing
method and step height, and kept.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from gait_nodes.errors import GaitNodesError, GaitParameterError
from gait_nodes.planning.footsteps import GaitPlanner
from gait_nodes.planning.gait_params import (
    GaitParameters,
    auto_choice,
    auto_gait,
    parameters_from_mapping,
)
from gait_nodes.planning.online import UNCHANGED
from gait_nodes.planning.terrain import Staircase


class TimingModels:
    """The swing timing model and the joint-speed probe of each gait setting, made once.

    Args:
        robot: The robot (:class:`gait_nodes.robot.description.RobotDescription`).
        warn: ``warn(message)``: a probe could not be made (the plans go unchecked).
    """

    def __init__(self, robot, warn: Callable[[str], None] = lambda message: None):
        self.robot = robot
        self._warn = warn
        self._robot_model = None
        self._known: dict = {}  # (swing, step height) -> (model, reason, final); probes

    def robot_model(self):
        """The robot model (:class:`gait_nodes.robot.model.RobotModel`), loaded once.

        Raises:
            GaitNodesError: The robot has none (no URDF, no kinematics).
        """
        if self._robot_model is None:
            from gait_nodes.robot.model import load_robot_model

            self._robot_model = load_robot_model(str(self.robot.path))
        return self._robot_model

    def timing(self, params: GaitParameters) -> tuple[object, str, bool]:
        """(model, reason, final): the swing timing model for ``params`` (None: fixed timing).

        With ``swing: value_table`` and the table not built yet (swing_leg_policy builds it on
        first use), the polynomial swing's longer times stand in (final False).
        """
        if params.timing != 'joint_limit' or self.robot.extra.get('limb_ik') is None:
            return None, ('fixed timing' if params.timing == 'fixed' else
                          f'{self.robot.name} has no closed-form limb IK: fixed timing'), True
        from gait_nodes.swing.policy import law_placements
        from gait_nodes.swing.timing import TableSwingTiming, swing_timing

        # The value table's swings are timed in the law of the gait they are walked in.
        gait = params.resolved_gait(self.robot)
        key = (params.swing, params.step_height_m, law_placements(gait))
        known = self._known.get(key)
        if known is not None and known[2]:
            return known
        if known is not None and not self._table_file(params).is_file():
            return known  # still the stand-in: looked for again in a second
        model, reason = swing_timing(self.robot_model(), params.swing, params.step_height_m,
                                     gait)
        final = params.swing != 'value_table' or isinstance(model, TableSwingTiming)
        if known is not None and not final:
            return known  # still the stand-in: keep the same one
        self._known[key] = (model, reason, final)
        return model, reason, final

    def _table_file(self, params: GaitParameters):
        """Where the swing value table of ``params`` is cached (built or not)."""
        from gait_nodes.robot.whole_body_ik import limb_ik_family
        from gait_nodes.swing.cache import default_table_path

        model = self.robot_model()
        return default_table_path(model, limb_ik_family(model), params.step_height_m,
                                  model.description.joint_velocity_limit_rad_s)

    def check_joint_speeds(self, fork: GaitPlanner, from_s: float) -> None:
        """Refuse a plan with fixed timing whose swings the joints cannot follow.

        A plan timed at the joint limit (``timing: joint_limit`` with a model) is re-timed by
        its probes already; any other is probed here (raises GaitNodesError).
        """
        params = fork.params
        if params.timing == 'joint_limit' and fork.swing_timing is not None:
            return
        probe = self.probe(params)
        if probe is not None:
            fork.check_joint_speeds(probe, from_s)

    def probe(self, params: GaitParameters):
        """The joint-speed probe of ``params``' swings (None: no robot model)."""
        if self.robot.extra.get('limb_ik') is not None:
            # The gait it walks (auto resolved with its own timing), timed at the limit.
            return self.timing(params.replace(gait=params.resolved_gait(self.robot),
                                              timing='joint_limit'))[0]
        key = ('probe', params.step_height_m)
        if key not in self._known:
            from gait_nodes.swing.timing import PolynomialSwingTiming

            try:
                self._known[key] = PolynomialSwingTiming(
                    self.robot_model(), None, self.robot.joint_velocity_limit_rad_s,
                    params.step_height_m)
            except GaitNodesError as exc:
                self._warn(f'no joint-speed check of gait commands: {exc}')
                self._known[key] = None
        return self._known[key]

    def retime(self, fork: GaitPlanner, at_s: float):
        """Time ``fork`` with the table once it exists (UNCHANGED while it does not).

        A change of :meth:`gait_nodes.planning.online.OnlinePlanner.submit_change`: returns
        ``('timing', reason, final)``.
        """
        model, reason, final = self.timing(fork.params)
        if model is fork.swing_timing:
            return UNCHANGED
        fork.set_swing_timing(model, at_s)
        return ('timing', reason, final)

    def apply_changes(self, changes: dict, terrain: Staircase | None, fork: GaitPlanner,
                      at_s: float):
        """Plan gait ``changes`` (and ``terrain``) on ``fork`` from ``at_s`` [s] on.

        A command of :meth:`gait_nodes.planning.online.OnlinePlanner.submit_command`: returns
        ``('timing', reason, final)`` of the changed plan's swing timing.
        """
        params = parameters_from_mapping(fork.params, changes, self.robot)
        model, reason, final = self.timing(params)
        if terrain is not None and terrain != fork.terrain:
            fork.set_terrain(terrain, at_s, params)
        fork.set_parameters(params, at_s, swing_timing=model)
        return ('timing', reason, final)


def describe_plan(robot, planner: GaitPlanner) -> dict:
    """What the planner's 'gait' report says of ``planner`` (made in the worker).

    With ``gait: auto``, ``auto`` says which gait it walks and why
    (:func:`gait_nodes.planning.gait_params.auto_choice`: each gait's planned speed at the
    joint limit, or why it cannot walk).
    """
    params = planner.params
    steps = planner.steps
    kept = min((step.zmp_margin_kept_m for step in steps), default=math.inf)
    auto = {}
    if params.gait == 'auto':
        auto['auto'] = auto_reason(robot, params.timing)
    return {
        **auto,
        'gait': params.gait, 'resolved_gait': params.resolved_gait(robot),
        'mode': steps[-1].state_after.mode if steps else 'standing',
        'applied_twist': planner.twist.as_tuple(),
        'zmp_margin_kept_m': kept, 'zmp_margin_m': params.zmp_margin_m,
        'planned_steps': len(steps), 'timing': params.timing,
        'stairs_count': planner.terrain.count,
        'stairs_total_rise_m': planner.terrain.total_rise_m,
        **rhythm_values(planner)}


def auto_reason(robot, timing: str = 'joint_limit') -> str:
    """Which gait ``gait: auto`` walks on ``robot`` with ``timing``, and why, in one line."""
    choice = auto_choice(robot)
    if choice is None:
        return (f'{robot.gaits[0]}, the first of {list(robot.gaits)}: {robot.name} has no '
                f'closed-form limb IK to plan its gaits at the joint limit with'
                if len(robot.gaits) > 1 else f'{robot.gaits[0]}, its only gait')
    walked = auto_gait(robot, timing)
    if walked == choice.gait:
        return choice.describe()
    return (f'{walked}: {choice.describe()}; {choice.gait} needs timing joint_limit, the '
            f'timing is {timing}')


def rhythm_values(planner: GaitPlanner) -> dict:
    """The walked rhythm (step period, swing, transfer, duty factor, speed) for reports."""
    try:
        rhythm = planner.rhythm()
    except GaitParameterError:
        return {}
    params = planner.params
    if rhythm is None:
        return {'step_period_s': params.step_period_s, 'swing_s': params.swing_s,
                'duty_factor': params.duty_factor}
    twist = planner.twist
    return {'step_period_s': rhythm.step_period_s, 'swing_s': rhythm.swing_s,
            'transfer_s': rhythm.transfer_s, 'duty_factor': rhythm.duty_factor,
            'stride_m': math.hypot(twist.vx_m_s, twist.vy_m_s) * rhythm.cycle_s}
