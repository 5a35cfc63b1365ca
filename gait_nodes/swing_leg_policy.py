"""swing_leg_policy node: /gait/footsteps in, one /gait/swing_trajectory per swing out.

``python -m gait_nodes.swing_leg_policy --ros-args -p swing:=value_table -p family:=2``

With ``swing: value_table`` (thesis 000, III.C and Appendix A) the node loads a swing value table
at start (``table``, or a cache file under ``$XDG_CACHE_HOME/gait_nodes`` built on first use) and
refuses a corrupt file or one made for another robot (URDF hash), joint velocity limit, IK family
or step height, naming the file and what differs. For each swing of the latched footstep plan it
publishes, ``lead_time_s`` before lift-off, the greedy minimum-time path from the table: the
table's goal mapped onto the planned landing place, the path rotated with the body and mirrored
for the limb, lift-off and landing exactly where planned, filtered into a smooth path
(:func:`gait_nodes.swing.timing.smooth_trajectory`: the polyline's corners would make the foot
change velocity in one tick), moved along in the fastest time law the limb's joint velocity
(``joint_velocity_limit_rad_s``) and acceleration limits allow
(:meth:`gait_nodes.swing.policy.SwingPolicy.fastest_swing`), and the whole stretched to the
swing's planned duration.
When the plan gives less time than the swing needs the timing is compressed to fit and the
shortfall is reported on /diagnostics (the footstep planner with ``timing: joint_limit`` plans
the time the swing needs, :mod:`gait_nodes.swing.timing`). With ``swing: polynomial`` it
publishes a sixth-order swing with a via point at ``step_height_m`` (Lucy, seed 004) instead.
Either way the waypoints are ``sample_period_s`` apart (the whole-body IK interpolates them
linearly, so at its own tick period the foot's velocity changes smoothly). With each swing it
sends, its path goes to /gait/markers for RViz and Foxglove (namespace ``swing_paths``,
:mod:`gait_nodes.markers`; ``publish_markers: false`` turns them off).

The time law of a value-table swing is the one of the gait it is walked in
(:func:`gait_nodes.swing.policy.law_placements`: the static crawl's, or the one of the gaits
whose body moves under a swing), as the footstep planner times it: ``gait`` is the planner's
gait at start (``auto`` resolved as the planner resolves it, at the joint limit), then the
gait of its accepted commands (their ``resolved_gait``).

The swing follows the footstep planner's gait commands: an accepted one on
/gait/command_status that changes ``swing``, ``step_height_m`` or ``gait`` is walked by the
swings that lift off from the step boundary it takes effect at (``takes_effect_ns``; a
``rescheduled`` answer moves it, when a later stop or velocity re-planned the steps before it).
A value table for a new step height is loaded, or built in a background thread (the walk goes
on); until it is there the polynomial swing at that height stands in, as the footstep planner
times it (the polynomial swing's longer times stand in there too until the table's file
appears).

Restarted mid-walk, the node does not send a swing that has been under way for more than
``LATE_SWING_S`` without a trajectory: the whole-body IK follows its fallback swing for it, and a
trajectory arriving mid-air would make the foot jump from one path to the other.
"""

from __future__ import annotations

import json
import math
import sys
import threading

import numpy as np

from gait_nodes import contract
from gait_nodes.cli import run_node
from gait_nodes.diagnostics import ERROR, OK, WARN, DiagnosticsReporter
from gait_nodes.errors import GaitNodesError, ParameterError, SwingPolicyError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.graph import node_topic_name
from gait_nodes.interfaces import get_message
from gait_nodes.markers import swing_path_markers
from gait_nodes.paths import node_defaults
from gait_nodes.planning.gait_params import auto_gait
from gait_nodes.robot.model import load_robot_model
from gait_nodes.runtime import Parameter, SetParametersResult, qos_profile_latched
from gait_nodes.swing.cache import load_or_build
from gait_nodes.swing.policy import SwingPolicy, limb_step, place_swing
from gait_nodes.swing.polynomial import polynomial_swing
from gait_nodes.swing.timing import evenly_resampled

NODE_NAME = 'swing_leg_policy'
FOOTSTEPS_TOPIC = '/gait/footsteps'
SWING_TOPIC = '/gait/swing_trajectory'
SWING_METHODS = ('value_table', 'polynomial')
NS_PER_S = 1_000_000_000
#: A lift-off place further than this off the table's grid is reported [m].
CLAMP_REPORT_M = 0.01
#: A value-table swing (built for flat ground) takes footholds this far apart in height [m]:
#: a robot's measured feet are a fraction of a millimetre off the ground they stand on (the
#: physics simulator's discs sink and tilt), and a plan made from where they stand keeps that.
#: The path is placed on the line between the two (``place_swing``); stairs are refused.
FLAT_TOLERANCE_M = 0.005
#: A swing under way for longer than this with no trajectory sent is left to the IK [s].
LATE_SWING_S = 0.05


def shipped_defaults() -> dict[str, object]:
    """``ros__parameters`` of ``config/swing_leg_policy.yaml``."""
    return node_defaults(NODE_NAME)


def check_values(values: dict) -> None:
    """Raise ParameterError naming the first invalid setting and its allowed range."""
    def number(name, low, high, low_open=False):
        value = values[name]
        ok = (not isinstance(value, bool) and isinstance(value, (int, float))
              and math.isfinite(value) and value <= high
              and (value > low if low_open else value >= low))
        if not ok:
            raise ParameterError(f'{name} must be in {"(" if low_open else "["}{low:g}, '
                                 f'{high:g}], got {value!r}')

    if values['swing'] not in SWING_METHODS:
        raise ParameterError(f'swing must be one of {list(SWING_METHODS)}, got '
                             f'{values["swing"]!r}')
    if isinstance(values['family'], bool) or not isinstance(values['family'], int) \
            or not -1 <= values['family'] <= 7:
        raise ParameterError(f'family must be an integer in [-1, 7] (-1: the robot YAML\'s), '
                             f'got {values["family"]!r}')
    if not isinstance(values['publish_markers'], bool):
        raise ParameterError(f'publish_markers must be true or false, got '
                             f'{values["publish_markers"]!r}')
    if not isinstance(values['table'], str):
        raise ParameterError(f'table must be a path string, got {values["table"]!r}')
    if not isinstance(values['gait'], str) or not values['gait']:
        raise ParameterError(f'gait must be a gait name or auto, got {values["gait"]!r}')
    number('step_height_m', 0.0, 1.0, low_open=True)
    number('joint_velocity_limit_rad_s', 0.0, 100.0)
    number('lead_time_s', 0.0, 10.0)
    number('rate_hz', 0.01, 1000.0)  # 5e-324 Hz: no timer period
    # A swing of 1 s at 5e-324 s is more waypoints than there is memory: 1 kHz at most.
    number('sample_period_s', 0.001, 0.1)
    if isinstance(values['polynomial_samples'], bool) \
            or not isinstance(values['polynomial_samples'], int) \
            or not 3 <= values['polynomial_samples'] <= 1000:
        raise ParameterError(f'polynomial_samples must be an integer in [3, 1000], got '
                             f'{values["polynomial_samples"]!r}')


def body_yaw(plan: contract.FootstepPlan, t_s: float) -> float:
    """Circular mean of the planned foot yaws at the contact change before ``t_s`` [rad]."""
    yaws = plan.yaws_rad[plan.index_at(t_s)]
    return float(np.angle(np.exp(1j * yaws).sum()))


class SwingLegPolicy(GuardedNode):
    """Publishes a swing trajectory for every planned swing (see the module docstring)."""

    def __init__(self):
        super().__init__(NODE_NAME)
        defaults = shipped_defaults()
        values = {name: self.declare_parameter(name, default).value
                  for name, default in defaults.items()}
        check_values(values)
        self.robot = load_robot_model(values['robot'])
        self.diagnostics = DiagnosticsReporter(self, self.robot.name)
        if values['swing'] == 'value_table' and self.robot.description.extra.get(
                'limb_ik') is None:
            # A default that cannot apply to this robot (e.g. the launch file's, for a biped):
            # start with the swing it can have and say so. Asked for later, it is refused.
            reason = (f'{self.robot.name} has no closed-form limb IK for the swing value '
                      f'table: polynomial swings instead')
            self.set_parameters([Parameter('swing', value='polynomial')])
            values['swing'] = 'polynomial'
            self.diagnostics.report('swing', WARN, reason)
        self.faults = FaultGuard(self, self.diagnostics)
        self._values = values
        self._gait = self._law_gait(values)  # the gait of the swings' time law at start
        self._policy, self._table_path = self._load_policy(values)
        # The planner's swing settings by the time they take effect: [(ns, swing, height, gait)].
        self._followed: list[tuple[int, str, float, str]] = []
        self._tables: dict[float, object] = {}  # step height -> SwingPolicy, or an exception
        self._building: set[float] = set()
        if self._policy is not None:
            self._tables[float(values['step_height_m'])] = self._policy
        self._plan = None
        self._published: dict[tuple[str, int], tuple] = {}
        self._swing_times_of: tuple = (None, [])  # see _swing_times
        self.published_count = 0
        self._publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
            node_topic_name(SWING_TOPIC), 10)
        self._markers = self.create_publisher(
            get_message('visualization_msgs/msg/MarkerArray'), 'gait/markers', 10)
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 node_topic_name(FOOTSTEPS_TOPIC), self._on_footsteps,
                                 qos_profile_latched)
        self.create_subscription(get_message('std_msgs/msg/String'), 'gait/command_status',
                                 self._on_command_status, 100)
        self._timer = self.create_timer(1.0 / values['rate_hz'], self._tick)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(self._describe())

    # --- settings -----------------------------------------------------------------------------

    def _limit(self, values: dict) -> float:
        return float(values['joint_velocity_limit_rad_s']
                     or self.robot.description.joint_velocity_limit_rad_s)

    def _family(self, values: dict) -> int:
        if values['family'] >= 0:
            return int(values['family'])
        setting = self.robot.description.extra.get('limb_ik') or {}
        return int(setting.get('family', 2)) if isinstance(setting, dict) else 2

    def _law_gait(self, values: dict) -> str:
        """The gait ``values['gait']`` walks, whose time law the value-table swings take.

        Raises:
            ParameterError: Not ``auto`` nor a gait of the robot.
        """
        description = self.robot.description
        gait = values['gait']
        if gait == 'auto':
            if values['swing'] != 'value_table':
                return description.gaits[0]  # no time law to choose
            # As the footstep planner resolves it at the joint limit (seconds, once per robot
            # and process: gait_nodes.planning.gait_choice).
            return auto_gait(description)
        if gait not in description.gaits:
            raise ParameterError(f'gait must be auto or one of {list(description.gaits)} '
                                 f'({description.name}), got {gait!r}')
        return gait

    def _load_policy(self, values: dict):
        """(SwingPolicy, path) for value_table, (None, None) for polynomial; raises if refused."""
        if values['swing'] != 'value_table':
            return None, None
        family, limit = self._family(values), self._limit(values)
        table, path = load_or_build(self.robot, family, float(values['step_height_m']), limit,
                                    values['table'] or None, self.get_logger().info)
        if not math.isclose(table.step_height_m, values['step_height_m'], abs_tol=1e-9):
            raise SwingPolicyError(f'{path}: refused: its step height is '
                                   f'{table.step_height_m} m, not {values["step_height_m"]} m')
        return SwingPolicy(table, self.robot), path

    def _describe(self) -> str:
        values = self._values
        if self._policy is None:
            return (f'{self.robot.name}: polynomial swings (sixth order, via at '
                    f'{values["step_height_m"]:g} m)')
        table = self._policy.table
        return (f'{self.robot.name}: value-table swings from {self._table_path} (family '
                f'{table.family}, {table.joint_velocity_limit_rad_s:g} rad/s, step height '
                f'{table.step_height_m:g} m, {table.grid.size} states), timed in the '
                f'{self._gait} time law')

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        values = dict(self._values)
        values.update({p.name: p.value for p in parameters if p.name in values})
        if values['robot'] != self._values['robot']:
            return SetParametersResult(successful=False,
                                       reason='robot is fixed at start; restart the node')
        try:
            check_values(values)
            gait = self._law_gait(values) if values['gait'] != self._values['gait'] \
                else self._gait
            reload = any(values[k] != self._values[k] for k in
                         ('swing', 'table', 'family', 'step_height_m',
                          'joint_velocity_limit_rad_s'))
            policy, path = self._load_policy(values) if reload \
                else (self._policy, self._table_path)
        except GaitNodesError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if values['rate_hz'] != self._values['rate_hz']:
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / values['rate_hz'], self._tick)
        self._values, self._policy, self._table_path = values, policy, path
        if reload or gait != self._gait:
            # The node's own settings, set explicitly, replace what it followed.
            self._followed = []
            self._gait = gait
            if policy is not None:
                self._tables[float(values['step_height_m'])] = policy
        self.diagnostics.report('settings', OK, self._describe())
        return SetParametersResult(successful=True)

    # --- input --------------------------------------------------------------------------------

    def _on_footsteps(self, msg) -> None:
        try:
            plan = contract.footsteps_from_msg(msg)
            unknown = set(plan.foot_names) - set(self.robot.foot_names)
            if unknown:
                raise contract.ContractError(f'feet {sorted(unknown)} are not feet of '
                                             f'{self.robot.name}')
        except contract.ContractError as exc:
            self.diagnostics.drop(FOOTSTEPS_TOPIC, str(exc))
            return
        self._plan = plan
        self._tick()

    def _on_command_status(self, msg) -> None:
        """Follow an accepted gait command's swing, step height and gait from its boundary."""
        try:
            status = json.loads(msg.data)
            if status.get('state') not in ('accepted', 'rescheduled'):
                return
            params, takes_effect_ns = status['params'], int(status['takes_effect_ns'])
            swing, height = str(params['swing']), float(params['step_height_m'])
            gait = str(status.get('resolved_gait', params.get('gait')))
        except (ValueError, TypeError, KeyError, AttributeError):
            return  # not an answer this node can follow (the footstep planner checks commands)
        if swing not in SWING_METHODS or not 0.0 < height <= 1.0:
            return
        if gait not in self.robot.description.gaits:
            gait = self._gait  # 'auto' unresolved (an older planner): the gait it walked
        if self.robot.description.extra.get('limb_ik') is None:
            swing = 'polynomial'
        self._followed = [f for f in self._followed if f[0] < takes_effect_ns]
        self._followed.append((takes_effect_ns, swing, height, gait))
        if swing == 'value_table':
            self._table_for(height)  # start loading (or building) it now

    def _table_for(self, height: float):
        """The value-table policy for ``height``, or None while it is loaded or built."""
        known = self._tables.get(height)
        if known is not None:
            return None if isinstance(known, Exception) else known
        if height not in self._building:
            self._building.add(height)
            values = {**self._values, 'swing': 'value_table', 'step_height_m': height,
                      'table': ''}
            threading.Thread(target=self._load_table, args=(values,), daemon=True,
                             name=f'swing-table-{height:g}').start()
        return None

    def _load_table(self, values: dict) -> None:
        """Worker: load or build the table of ``values`` (the walk goes on meanwhile)."""
        height = float(values['step_height_m'])
        try:
            policy, _ = self._load_policy(values)
        except Exception as exc:  # noqa: BLE001 (reported from the tick; polynomial meanwhile)
            policy = exc
        self._tables[height] = policy
        self._building.discard(height)

    def _swing_settings(self, lift_ns: int) -> tuple[str, float, str]:
        """(swing method, step height [m], gait) of a swing lifting off at ``lift_ns``."""
        settings = (self._values['swing'], float(self._values['step_height_m']), self._gait)
        for takes_effect_ns, *followed in self._followed:
            if takes_effect_ns <= lift_ns:
                settings = tuple(followed)
        return settings

    # --- output -------------------------------------------------------------------------------

    def _tick(self) -> None:
        plan = self._plan
        if plan is None:
            return
        now_ns = self.get_clock().now().nanoseconds
        lead_ns = int(round(self._values['lead_time_s'] * NS_PER_S))
        busy_until: dict[str, int] = {}
        for swing, lift_ns, touch_ns, signature in self._swing_times(plan):
            previous = busy_until.get(swing.foot)
            busy_until[swing.foot] = touch_ns
            if touch_ns <= now_ns or lift_ns - lead_ns > now_ns:
                continue
            if previous is not None and previous > now_ns:
                continue  # this foot's earlier swing is still under way
            key = (swing.foot, lift_ns)
            sent = self._published.get(key)
            if sent is not None and (sent == signature or lift_ns <= now_ns):
                continue
            if sent is None and now_ns - lift_ns > LATE_SWING_S * NS_PER_S:
                continue  # under way already (a restart): the IK's fallback swing goes on
            self._publish(plan, swing, lift_ns)
            self._published[key] = signature
        old_ns = now_ns - 60 * NS_PER_S
        if any(k[1] <= old_ns for k in self._published):
            self._published = {k: v for k, v in self._published.items() if k[1] > old_ns}

    def _swing_times(self, plan: contract.FootstepPlan) -> list:
        """(swing, lift-off [ns], touch-down [ns], signature) of each swing of ``plan``.

        Worked out once per plan (a new one comes with each /gait/footsteps, the tick asks at
        50 Hz); the signature tells a re-planned landing of the same swing.
        """
        if self._swing_times_of[0] is not plan:
            times = []
            for swing in plan.swings():
                touch_ns = plan.start_ns + int(round(swing.touch_down_s * NS_PER_S))
                times.append((swing, plan.start_ns + int(round(swing.lift_off_s * NS_PER_S)),
                              touch_ns, (tuple(np.round(swing.end_in_world, 9)),
                                         round(swing.end_yaw_rad, 9), touch_ns)))
            self._swing_times_of = (plan, times)
        return self._swing_times_of[1]

    def _publish(self, plan: contract.FootstepPlan, swing: contract.Swing, lift_ns: int) -> None:
        values = self._values
        trajectory = None
        climb = float(swing.end_in_world[2] - swing.start_in_world[2])
        method, height, gait = self._swing_settings(lift_ns)
        policy = None
        if method == 'value_table':
            policy = self._table_for(height)
            failed = self._tables.get(height)
            if isinstance(failed, Exception):
                self.diagnostics.report('swing', WARN, f'no value table for step height '
                                        f'{height:g} m ({failed}): polynomial swings')
        if policy is not None and climb < -1e-9:
            # A foot put down from where a pause or a restarted planner found it in the air (the
            # planner refuses stairs with the value table): the table swings between footholds
            # on the ground, the polynomial swing lowers it. Expected, not a failure.
            self.diagnostics.report('swing', WARN, f'{swing.foot} at {swing.lift_off_s:.3f} s '
                                    f'lands from {-climb:.4g} m above its foothold (left in '
                                    f'the air): sending the polynomial swing')
        elif policy is not None:
            try:
                trajectory = self._value_table_swing(policy, plan, swing, lift_ns, gait)
            except GaitNodesError as exc:
                self.diagnostics.report('swing', ERROR, f'{swing.foot} at {swing.lift_off_s:.3f}'
                                        f' s: {exc}; sending the polynomial swing instead')
        if trajectory is None:
            samples = max(values['polynomial_samples'],
                          int(math.ceil(swing.duration_s / values['sample_period_s'])) + 1)
            trajectory, _ = polynomial_swing(swing, lift_ns, height, samples)
        self._publisher.publish(contract.swing_trajectory_to_msg(trajectory))
        self.published_count += 1
        if values['publish_markers']:
            self._markers.publish(swing_path_markers(
                trajectory, self.robot.foot_names.index(swing.foot),
                self.get_clock().now().nanoseconds))

    def _value_table_swing(self, policy, plan, swing, lift_ns: int,
                           gait: str) -> contract.SwingTrajectory:
        climb = float(swing.end_in_world[2] - swing.start_in_world[2])
        if abs(climb) > FLAT_TOLERANCE_M:  # the footstep planner refuses stairs with it
            raise SwingPolicyError(f'the value-table swing is built for flat ground; this '
                                   f'swing climbs {climb:+.4g} m (stairs need swing: '
                                   f'polynomial)')
        table = policy.table
        ik = policy.timing.ik
        mirror = ik.mirrors[ik.foot_index[swing.foot]]
        yaw = body_yaw(plan, swing.lift_off_s)
        step_fr, turn = limb_step(swing, mirror, yaw)
        path, clamped = policy.fastest_swing(step_fr, turn, swing.foot, gait)
        polyline, needed = place_swing(path, swing, lift_ns, mirror, yaw, table.ground_z_m,
                                       swing.duration_s)
        trajectory = evenly_resampled(polyline, self._values['sample_period_s'])
        report = {'foot': swing.foot, 'lift_off_s': swing.lift_off_s,
                  'planned_s': swing.duration_s, 'needed_s': needed,
                  'joint_velocity_limit_rad_s': table.joint_velocity_limit_rad_s,
                  'start_off_grid_m': clamped}
        if needed > swing.duration_s + 1e-9:
            self.diagnostics.report(
                'timing', WARN, f'{swing.foot}: the plan gives {swing.duration_s:.3f} s, the '
                f'table needs {needed:.3f} s at {table.joint_velocity_limit_rad_s:g} rad/s; '
                f'joints will exceed the limit', report)
        elif clamped > CLAMP_REPORT_M:
            self.diagnostics.report(
                'timing', WARN, f'{swing.foot}: the lift-off place is {clamped:.3f} m off the '
                f'table grid; the path was stretched to it', report)
        return trajectory


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.swing_leg_policy [--ros-args ...]``."""
    return run_node(lambda options: SwingLegPolicy(), args,
                    prog='python -m gait_nodes.swing_leg_policy',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
