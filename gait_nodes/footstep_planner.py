"""footstep_planner node: footsteps, contact schedule and ZMP reference, driven online.

Subscribes ``/cmd_vel`` (geometry_msgs/Twist) and ``/gait/command`` (std_msgs/String, JSON, schema
``msgs_schema/gait_command.schema.json``). Publishes ``/gait/footsteps`` (latched, whenever the
plan changes), ``/gait/zmp_reference`` (the next ``zmp_horizon_s`` every tick),
``/gait/command_status`` (one JSON answer per command) and ``/diagnostics``.

The gait settings are ROS parameters (defaults in ``config/footstep_planner.yaml``); a
``ros2 param set`` and a /gait/command go through the same checks, and an accepted change takes
effect at the next step boundary. The planning itself is :class:`gait_nodes.planning.footsteps.
GaitPlanner`.
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
from gait_nodes.robot.description import load_robot_description
from gait_nodes.runtime import Node, Parameter, SetParametersResult, qos_profile_latched

NODE_NAME = 'footstep_planner'
GAIT_FIELDS = tuple(GaitParameters.__dataclass_fields__)
#: Node settings: name -> (lowest, lowest included?, highest included, unit).
NODE_SETTINGS = {'rate_hz': (0.0, False, 1000.0, 'Hz'), 'zmp_horizon_s': (1.6, True, 60.0, 's'),
                 'zmp_sample_period_s': (0.0, False, 0.1, 's')}
#: Most samples in one /gait/zmp_reference.
MAX_ZMP_SAMPLES = 20000
#: A clock jump larger than this [s] restarts the plan from standstill.
CLOCK_JUMP_S = 10.0
NS_PER_S = 1_000_000_000


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
        robot_defaults = GaitParameters.for_robot(self.robot).to_dict()
        values = {}
        for name in NODE_SETTINGS:
            values[name] = self.declare_parameter(name, float(defaults[name])).value
        for name in GAIT_FIELDS:
            default = defaults.get(name, robot_defaults[name])
            if name in NUMERIC_RANGES:
                default = float(default)
            values[name] = self.declare_parameter(name, default).value
        check_node_settings(values)
        self.settings = {name: values[name] for name in NODE_SETTINGS}
        params = GaitParameters(**{name: values[name] for name in GAIT_FIELDS})
        params.check_robot(self.robot)

        self.origin_ns = self.get_clock().now().nanoseconds
        self.planner = GaitPlanner(self.robot, params)
        self._last_now_s = 0.0
        self._pending: tuple[GaitParameters, dict] | None = None
        self._last_plan = None
        self._zmp_messages = ZmpReferenceMessages()
        self.diagnostics = DiagnosticsReporter(self, self.robot.name)
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
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(self.on_parameters_set)
        self.timer = self.create_timer(1.0 / self.settings['rate_hz'], self.tick)
        self.create_timer(1.0, self.report_state)
        self.get_logger().info(
            f'{self.robot.name}: gait {params.gait} ({params.resolved_gait(self.robot)}), '
            f'step period {params.step_period_s:g} s, duty factor {params.duty_factor:g}')

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
        self.planner = GaitPlanner(self.robot, self.planner.params, base_pose=pose)
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
        _, now_s = self.now_s()
        applied, notes = self.planner.set_velocity(twist, now_s)
        # /cmd_vel is usually streamed: report a clamp when it starts or changes, not per message.
        if changed or notes != self._last_velocity_notes:
            self._last_velocity_notes = notes
            self.diagnostics.report(
                'velocity', WARN if notes else OK,
                '; '.join(notes) if notes else 'velocity command accepted',
                {'requested_twist': twist.as_tuple(), 'applied_twist': applied.as_tuple(),
                 'takes_effect_s': self.planner.next_boundary_s(now_s)})

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
        for parameter in parameters:
            if parameter.name == 'robot':
                if parameter.value != self.get_parameter('robot').value:
                    return SetParametersResult(successful=False,
                                               reason='robot is fixed when the node starts')
            elif parameter.name in NODE_SETTINGS:
                settings[parameter.name] = parameter.value
            elif parameter.name in GAIT_FIELDS:
                gait_changes[parameter.name] = parameter.value
        try:
            check_node_settings(settings)
            params = parameters_from_mapping(self.planner.params, gait_changes, self.robot)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._pending = (params, settings)
        return SetParametersResult(successful=True)

    def on_parameters_set(self, parameters) -> None:
        """Apply what :meth:`on_set_parameters` accepted."""
        if self._pending is None:
            return
        params, settings = self._pending
        self._pending = None
        _, now_s = self.now_s()
        if params != self.planner.params:
            self.planner.set_parameters(params, now_s)
        if settings['rate_hz'] != self.settings['rate_hz']:
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / settings['rate_hz'], self.tick)
        self.settings = settings

    # --- outputs -------------------------------------------------------------------------------

    def tick(self) -> None:
        """Extend the plan, publish the footsteps if they changed and the ZMP reference."""
        now_ns, now_s = self.now_s()
        now_s = self._restart_if_clock_jumped(now_ns, now_s)
        self._last_now_s = now_s
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
        """Once a second: the gait, the twist and the margin of the planned ZMP."""
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
            'planned_steps': len(steps)})


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
