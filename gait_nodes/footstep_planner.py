"""footstep_planner node: footsteps, contact schedule and ZMP reference, driven online.

Subscribes ``/cmd_vel`` (geometry_msgs/Twist) and ``/gait/command`` (std_msgs/String, JSON, schema
``msgs_schema/gait_command.schema.json``). Publishes ``/gait/footsteps`` (latched, whenever the
plan changes), ``/gait/zmp_reference`` (the next ``zmp_horizon_s`` every tick),
``/gait/command_status`` (one JSON answer per command) and ``/diagnostics``.

The gait settings are ROS parameters (defaults in ``config/footstep_planner.yaml``); a
``ros2 param set`` and a /gait/command go through the same checks, and an accepted change takes
effect at the next step boundary. The planning itself is :class:`gait_nodes.planning.footsteps.
GaitPlanner`.

/cmd_vel watchdog (``cmd_vel_timeout_s`` > 0, as twist_mux's timeout): when no /cmd_vel has come
for that long the planner walks a zero twist from the next step boundary (closing steps, then
standing), reports the stale input (WARN, ``footstep_planner: inputs``) and walks again with the
next /cmd_vel. 0 (the default) keeps the last /cmd_vel until the next one, as
``python -m gait_nodes.command --vel`` expects; a launcher that streams /cmd_vel sets it.

Terrain: a staircase ahead in odom (Lucy's stairway), parameters ``stairs_start_x_m`` (x of the
first riser), ``stairs_rise_m`` (per stair, negative down), ``stairs_tread_m`` and
``stairs_count`` (0, the default: flat ground); see :mod:`gait_nodes.planning.terrain`. The
footholds on /gait/footsteps carry the ground's height and lie on one tread each. A change is
checked like a gait setting (ranges, a tread long enough for the foot and its swing, the
polynomial swing) and may move the stairs ahead of the feet, never under them.

Rejoin: started into a running graph (dds, rclpy), the planner waits up to ``JOIN_WAIT_S`` for
the robot's base pose (/tf odom -> base_link) and plans from there (feet at their nominal places
under that pose) instead of from the origin.

With ``timing: joint_limit`` (the shipped default) on a robot with closed-form limb IK, the
rhythm follows from the joint velocity limit and the swing method
(:mod:`gait_nodes.swing.timing`): the value table's swings (the cached table of
:mod:`gait_nodes.swing.cache`; until swing_leg_policy has built it, the polynomial swing's longer
times stand in and the table is looked for again every second) or the polynomial swing's. The
'timing' diagnostic says which; the 'gait' diagnostic reports the walked step period, swing,
transfer, duty factor and stride; a velocity beyond the fastest feasible one is reduced with a
WARN on the 'velocity' diagnostic.
"""

from __future__ import annotations

import json
import math
import sys

from gait_nodes.cli import run_node
from gait_nodes.contract import ZmpReferenceMessages, footsteps_to_msg
from gait_nodes.diagnostics import OK, WARN, DiagnosticsReporter
from gait_nodes.errors import GaitParameterError, ParameterError
from gait_nodes.interfaces import get_message
from gait_nodes.paths import node_defaults
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.gait_params import (
    NUMERIC_RANGES,
    GaitParameters,
    parameters_from_mapping,
    parse_command,
)
from gait_nodes.planning.terrain import STAIRS_DEFAULTS, Staircase, check_walkable
from gait_nodes.robot.description import load_robot_description
from gait_nodes.runtime import Node, Parameter, SetParametersResult, qos_profile_latched
from gait_nodes.watchdog import InputWatchdog

NODE_NAME = 'footstep_planner'
GAIT_FIELDS = tuple(GaitParameters.__dataclass_fields__)
#: Node settings: name -> (lowest, lowest included?, highest included, unit).
NODE_SETTINGS = {'rate_hz': (0.0, False, 1000.0, 'Hz'), 'zmp_horizon_s': (1.6, True, 60.0, 's'),
                 'zmp_sample_period_s': (0.0, False, 0.1, 's'),
                 'cmd_vel_timeout_s': (0.0, True, 60.0, 's')}
#: Most samples in one /gait/zmp_reference.
MAX_ZMP_SAMPLES = 20000
#: A clock jump larger than this [s] restarts the plan from standstill.
CLOCK_JUMP_S = 10.0
NS_PER_S = 1_000_000_000
#: Longest wait of a planner started into a running graph for the robot's pose on /tf [s].
JOIN_WAIT_S = 1.0


def shipped_defaults() -> dict[str, object]:
    """``ros__parameters`` of ``config/footstep_planner.yaml``."""
    return node_defaults(NODE_NAME)


def check_node_settings(values: dict[str, object]) -> None:
    """Raise ParameterError if a node setting is out of range."""
    for name, (low, low_included, high, unit) in NODE_SETTINGS.items():
        value = values[name]
        number = not isinstance(value, bool) and isinstance(value, (int, float))
        if not (number and math.isfinite(value) and value <= high
                and (value >= low if low_included else value > low)):
            bound = f'[{low:g}' if low_included else f'({low:g}'
            raise ParameterError(f'{name} must be in {bound}, {high:g}] {unit}, got {value!r}')
    samples = values['zmp_horizon_s'] / values['zmp_sample_period_s']
    if samples > MAX_ZMP_SAMPLES:
        raise ParameterError(f'zmp_horizon_s / zmp_sample_period_s = {samples:.0f} samples; at '
                             f'most {MAX_ZMP_SAMPLES}')


class FootstepPlanner(Node):
    """Plans footsteps and the ZMP reference from /cmd_vel and /gait/command."""

    def __init__(self):
        super().__init__(NODE_NAME)
        defaults = shipped_defaults()
        robot_name = self.declare_parameter('robot', str(defaults.pop('robot'))).value
        self.robot = load_robot_description(robot_name)
        # The robot's defaults, unchecked: checking resolves gait 'auto', which for a robot
        # with limb IK runs the thesis' crossover (seconds), and the settings are checked below.
        robot_defaults = GaitParameters(**GaitParameters.robot_defaults(self.robot)).to_dict()
        values = {}
        for name in NODE_SETTINGS:
            values[name] = self.declare_parameter(name, float(defaults[name])).value
        for name in GAIT_FIELDS:
            default = defaults.get(name, robot_defaults[name])
            if name in NUMERIC_RANGES:
                default = float(default)
            values[name] = self.declare_parameter(name, default).value
        for name, default in STAIRS_DEFAULTS.items():
            default = defaults.get(name, default)
            values[name] = self.declare_parameter(
                name, int(default) if name == 'stairs_count' else float(default)).value
        check_node_settings(values)
        self.settings = {name: values[name] for name in NODE_SETTINGS}
        params = GaitParameters(**{name: values[name] for name in GAIT_FIELDS})
        params.check_robot(self.robot)
        terrain = Staircase.from_parameters(values)
        check_walkable(terrain, self.robot, params)

        self.origin_ns = self.get_clock().now().nanoseconds
        self.diagnostics = DiagnosticsReporter(self, self.robot.name)
        self._robot_model = None
        self._timing_key, self._timing_model, self._timing_final = None, None, True
        self._timing_reason = 'fixed timing'
        self.planner = GaitPlanner(self.robot, params, swing_timing=self._swing_timing(params),
                                   terrain=terrain)
        self.inputs = InputWatchdog(['/cmd_vel'], self.settings['cmd_vel_timeout_s'] or 1.0,
                                    self.origin_ns, holding='stopping (zero velocity from the '
                                    'next step boundary)')
        # Under inproc every node starts together; elsewhere the robot may be somewhere already.
        self._joined = self.context.runtime == 'inproc'
        self._base_pose: tuple[float, float, float] | None = None
        self._last_now_s = 0.0
        self._pending: tuple[GaitParameters, dict, Staircase] | None = None
        self._last_plan = None
        self._zmp_messages = ZmpReferenceMessages()
        self._last_velocity_notes: list[str] = []
        self.footsteps_publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/footsteps',
            qos_profile_latched)
        self.zmp_publisher = self.create_publisher(get_message('nav_msgs/msg/Path'),
                                                   '/gait/zmp_reference', 10)
        self.status_publisher = self.create_publisher(get_message('std_msgs/msg/String'),
                                                      '/gait/command_status', 10)
        self.create_subscription(get_message('geometry_msgs/msg/Twist'), '/cmd_vel',
                                 self.on_cmd_vel, 10)
        self.create_subscription(get_message('std_msgs/msg/String'), '/gait/command',
                                 self.on_command, 10)
        if not self._joined:
            self._tf_subscription = self.create_subscription(
                get_message('tf2_msgs/msg/TFMessage'), '/tf', self.on_tf, 100)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(self.on_parameters_set)
        self.timer = self.create_timer(1.0 / self.settings['rate_hz'], self.tick)
        self.create_timer(1.0, self.report_state)
        if self.planner.swing_timing is not None:
            # Time the fastest forward walk now, so that a first /cmd_vel is answered at once.
            fastest, _ = self.planner.set_velocity(Twist2D(params.max_vx_m_s), 0.0)
            self.planner.set_velocity(Twist2D(), 0.0)
            rhythm = self.planner.rhythm(params, fastest)
            timing = (f'timing from the joint limit ({self._timing_reason}): fastest '
                      f'{fastest.vx_m_s:.4g} m/s, swing {rhythm.swing_s:.3f} s, step period '
                      f'{rhythm.step_period_s:.3f} s')
        else:
            timing = (f'{self._timing_reason}: step period {params.step_period_s:g} s, duty '
                      f'factor {params.duty_factor:g}')
        self.get_logger().info(f'{self.robot.name}: gait {params.gait} '
                               f'({params.resolved_gait(self.robot)}), {timing}')

    # --- swing timing --------------------------------------------------------------------------

    def _swing_timing(self, params: GaitParameters):
        """The swing timing model for ``params`` (None: fixed timing); kept while it fits.

        With ``swing: value_table`` and the table not built yet (swing_leg_policy builds it on
        first use), the polynomial swing's longer times stand in and the table is looked for
        again once a second (:meth:`report_state`).
        """
        if params.timing != 'joint_limit' or self.robot.extra.get('limb_ik') is None:
            key, model, final = None, None, True
            reason = ('fixed timing' if params.timing == 'fixed' else
                      f'{self.robot.name} has no closed-form limb IK: fixed timing')
        else:
            key = (params.swing, params.step_height_m)
            if key == self._timing_key and self._timing_final:
                return self._timing_model
            from gait_nodes.robot.model import load_robot_model
            from gait_nodes.swing.timing import TableSwingTiming, swing_timing

            if self._robot_model is None:
                self._robot_model = load_robot_model(str(self.robot.path))
            model, reason = swing_timing(self._robot_model, params.swing, params.step_height_m)
            final = params.swing != 'value_table' or isinstance(model, TableSwingTiming)
            if not final and key == self._timing_key:
                return self._timing_model  # still the stand-in: keep the same one
        if reason != self._timing_reason:
            self.diagnostics.report('timing', OK if final else WARN, reason)
        self._timing_key, self._timing_model = key, model
        self._timing_reason, self._timing_final = reason, final
        return model

    def _refresh_timing(self, now_s: float) -> None:
        """Re-make the timing model when the settings changed or the table appeared."""
        model = self._swing_timing(self.planner.params)
        if model is not self.planner.swing_timing:
            self.planner.set_swing_timing(model, now_s)

    # --- time ----------------------------------------------------------------------------------

    def now_s(self) -> tuple[int, float]:
        """ROS time [ns] and the planner's time [s]."""
        now_ns = self.get_clock().now().nanoseconds
        return now_ns, (now_ns - self.origin_ns) * 1e-9

    def _restart_if_clock_jumped(self, now_ns: int, now_s: float) -> float:
        if 0.0 <= now_s - self._last_now_s <= CLOCK_JUMP_S:
            return now_s
        jump_s = now_s - self._last_now_s
        self.diagnostics.report('clock', WARN, f'the clock jumped by {jump_s:.3f} s; the plan '
                                f'restarts from standstill')
        state = self.planner.steps[-1].state_after if self.planner.steps else None
        pose = state.rest_pose if state is not None else (0.0, 0.0, 0.0)
        twist = self.planner.requested_twist
        self.origin_ns = now_ns
        self.planner = GaitPlanner(self.robot, self.planner.params, base_pose=pose,
                                   swing_timing=self.planner.swing_timing,
                                   terrain=self.planner.terrain)
        self.planner.set_velocity(twist, 0.0)
        self._last_now_s = 0.0
        return 0.0

    # --- inputs --------------------------------------------------------------------------------

    def on_cmd_vel(self, msg) -> None:
        """Walk the commanded twist from the next step boundary (NaN dropped, excess clamped)."""
        values = (msg.linear.x, msg.linear.y, msg.linear.z,
                  msg.angular.x, msg.angular.y, msg.angular.z)
        if not all(math.isfinite(v) for v in values):
            self.diagnostics.drop('/cmd_vel', f'non-finite velocity {values}')
            return
        twist = Twist2D(float(msg.linear.x), float(msg.linear.y), float(msg.angular.z))
        changed = twist != self.planner.requested_twist
        now_ns, now_s = self.now_s()
        self.inputs.heard('/cmd_vel', now_ns)
        applied, notes = self.planner.set_velocity(twist, now_s)
        # /cmd_vel is usually streamed: report a clamp when it starts or changes, not per message.
        if changed or notes != self._last_velocity_notes:
            self._last_velocity_notes = notes
            self.diagnostics.report(
                'velocity', WARN if notes else OK,
                '; '.join(notes) if notes else 'velocity command accepted',
                {'requested_twist': twist.as_tuple(), 'applied_twist': applied.as_tuple(),
                 'takes_effect_s': self.planner.next_boundary_s(now_s)})

    def on_tf(self, msg) -> None:
        """Keep the robot's base pose (x, y, yaw) in odom until the planner has joined."""
        for transform in msg.transforms:
            if transform.header.frame_id.lstrip('/') == 'odom' and \
                    transform.child_frame_id.lstrip('/') == 'base_link':
                t, r = transform.transform.translation, transform.transform.rotation
                yaw = math.atan2(2.0 * (r.w * r.z + r.x * r.y), 1.0 - 2.0 * (r.y ** 2 + r.z ** 2))
                if all(math.isfinite(v) for v in (t.x, t.y, yaw)):
                    self._base_pose = (float(t.x), float(t.y), yaw)

    def _join(self, now_ns: int) -> bool:
        """Whether the planner may plan: it knows where the robot is, or waited long enough."""
        if self._base_pose is None and (now_ns - self.origin_ns) * 1e-9 < JOIN_WAIT_S:
            return False
        if self._base_pose is not None:
            twist = self.planner.requested_twist
            self.planner = GaitPlanner(self.robot, self.planner.params, base_pose=self._base_pose,
                                       swing_timing=self.planner.swing_timing,
                                       terrain=self.planner.terrain)
            self.origin_ns, self._last_now_s = now_ns, 0.0
            self.planner.set_velocity(twist, 0.0)
            self.get_logger().info(f'planning from the robot\'s pose {self._base_pose}')
        self._joined = True
        self.destroy_subscription(self._tf_subscription)
        return True

    def _check_cmd_vel(self, now_ns: int, now_s: float) -> None:
        timeout = self.settings['cmd_vel_timeout_s']
        if not timeout:
            return
        self.inputs.timeout_s = timeout
        if self.inputs.update(now_ns):
            self.diagnostics.publish([self.inputs.status(now_ns)])
        if self.inputs.stale and not self.planner.twist.is_zero():
            self.planner.set_velocity(Twist2D(), now_s)

    def on_command(self, msg) -> None:
        """Apply a JSON gait command as parameters; answer on /gait/command_status."""
        try:
            changes = parse_command(msg.data)
        except GaitParameterError as exc:
            self._answer(msg.data, False, str(exc))
            return
        parameters = [self._parameter(name, value) for name, value in changes.items()]
        result = (self.set_parameters_atomically(parameters) if parameters
                  else SetParametersResult(successful=True))
        self._answer(msg.data, result.successful,
                     result.reason if not result.successful else 'accepted')

    def _parameter(self, name: str, value):
        if self.rclpy_node is not None:
            from rclpy.parameter import Parameter as RclpyParameter

            return RclpyParameter(name, value=value)
        return Parameter(name, value=value)

    def _answer(self, command: str, accepted: bool, reason: str) -> None:
        params = self.planner.params.to_dict()
        status = {'accepted': accepted, 'reason': reason, 'params': params, 'command': command}
        self.status_publisher.publish(get_message('std_msgs/msg/String')(
            data=json.dumps(status)))
        if accepted:
            _, now_s = self.now_s()
            self.diagnostics.report('command', OK, f'command accepted: {command}',
                                    {'takes_effect_s': self.planner.next_boundary_s(now_s)})
        else:
            self.diagnostics.drop('/gait/command', f'{reason} (command: {command})')

    # --- parameters ----------------------------------------------------------------------------

    def on_set_parameters(self, parameters) -> SetParametersResult:
        """Check a parameter change as a /gait/command is checked; keep it for the post step."""
        settings = dict(self.settings)
        gait_changes = {}
        stairs = {name: self.get_parameter(name).value for name in STAIRS_DEFAULTS}
        for parameter in parameters:
            if parameter.name == 'robot':
                if parameter.value != self.get_parameter('robot').value:
                    return SetParametersResult(successful=False,
                                               reason='robot is fixed when the node starts')
            elif parameter.name in NODE_SETTINGS:
                settings[parameter.name] = parameter.value
            elif parameter.name in GAIT_FIELDS:
                gait_changes[parameter.name] = parameter.value
            elif parameter.name in STAIRS_DEFAULTS:
                stairs[parameter.name] = parameter.value
        try:
            check_node_settings(settings)
            params = parameters_from_mapping(self.planner.params, gait_changes, self.robot)
            terrain = Staircase.from_parameters(stairs)
            if terrain != self.planner.terrain:
                self.planner.check_terrain(terrain, self.now_s()[1], params)
            else:
                check_walkable(terrain, self.robot, params)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._pending = (params, settings, terrain)
        return SetParametersResult(successful=True)

    def on_parameters_set(self, parameters) -> None:
        """Apply what :meth:`on_set_parameters` accepted."""
        if self._pending is None:
            return
        params, settings, terrain = self._pending
        self._pending = None
        _, now_s = self.now_s()
        if terrain != self.planner.terrain:
            self.planner.set_terrain(terrain, now_s, params)
            self._refresh_timing(now_s)
        elif params != self.planner.params:
            self.planner.set_parameters(params, now_s)
            self._refresh_timing(now_s)
        if settings['rate_hz'] != self.settings['rate_hz']:
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / settings['rate_hz'], self.tick)
        self.settings = settings

    # --- outputs -------------------------------------------------------------------------------

    def tick(self) -> None:
        """Extend the plan, publish the footsteps if they changed and the ZMP reference."""
        now_ns, now_s = self.now_s()
        if not self._joined and not self._join(now_ns):
            return
        now_ns, now_s = self.now_s()
        now_s = self._restart_if_clock_jumped(now_ns, now_s)
        self._last_now_s = now_s
        self._check_cmd_vel(now_ns, now_s)
        horizon = self.settings['zmp_horizon_s']
        self.planner.advance(now_s + horizon + self.planner.params.step_period_s)
        self.planner.prune(now_s)
        plan = self.planner.footstep_plan(now_s, self.origin_ns)
        if self._last_plan is None or not _same_plan(plan, self._last_plan):
            self.footsteps_publisher.publish(footsteps_to_msg(plan))
            self._last_plan = plan
        reference = self.planner.zmp_reference(now_ns, self.origin_ns, horizon,
                                               self.settings['zmp_sample_period_s'])
        self.zmp_publisher.publish(self._zmp_messages.to_msg(reference))

    def report_state(self) -> None:
        """Once a second: the gait, the twist, the rhythm and the margin of the planned ZMP."""
        _, now_s = self.now_s()
        self._refresh_timing(now_s)
        params = self.planner.params
        steps = self.planner.steps
        kept = min((step.zmp_margin_kept_m for step in steps), default=math.inf)
        level = OK if kept >= params.zmp_margin_m - 1e-12 else WARN
        mode = steps[-1].state_after.mode if steps else 'standing'
        self.diagnostics.report('gait', level, f'{params.resolved_gait(self.robot)}, {mode}', {
            'gait': params.gait, 'resolved_gait': params.resolved_gait(self.robot),
            'mode': mode, 'requested_twist': self.planner.requested_twist.as_tuple(),
            'applied_twist': self.planner.twist.as_tuple(),
            'zmp_margin_kept_m': kept, 'zmp_margin_m': params.zmp_margin_m,
            'planned_steps': len(steps), 'timing': params.timing,
            'stairs_count': self.planner.terrain.count,
            'stairs_total_rise_m': self.planner.terrain.total_rise_m,
            'timing_source': self._timing_reason, **self._rhythm_values()})

    def _rhythm_values(self) -> dict:
        """The walked rhythm (step period, swing, transfer, duty factor, speed) for reports."""
        try:
            rhythm = self.planner.rhythm()
        except GaitParameterError:
            return {}
        params = self.planner.params
        if rhythm is None:
            return {'step_period_s': params.step_period_s, 'swing_s': params.swing_s,
                    'duty_factor': params.duty_factor}
        twist = self.planner.twist
        return {'step_period_s': rhythm.step_period_s, 'swing_s': rhythm.swing_s,
                'transfer_s': rhythm.transfer_s, 'duty_factor': rhythm.duty_factor,
                'stride_m': math.hypot(twist.vx_m_s, twist.vy_m_s) * rhythm.cycle_s}


def _same_plan(a, b) -> bool:
    return (a.start_ns == b.start_ns and a.foot_names == b.foot_names
            and a.times_s.shape == b.times_s.shape
            and bool((a.times_s == b.times_s).all())
            and bool((a.positions_in_world == b.positions_in_world).all())
            and bool((a.yaws_rad == b.yaws_rad).all()))


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.footstep_planner [--ros-args ...]``."""
    return run_node(lambda options: FootstepPlanner(), args,
                    prog=f'python -m gait_nodes.{NODE_NAME}',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
