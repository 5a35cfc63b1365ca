"""footstep_planner node: footsteps, contact schedule and ZMP reference, driven online.

Subscribes ``/cmd_vel`` (geometry_msgs/Twist) and ``/gait/command`` (std_msgs/String, JSON, schema
``msgs_schema/gait_command.schema.json``). Publishes ``/gait/footsteps`` (latched, whenever the
plan changes), ``/gait/zmp_reference`` (the next ``zmp_horizon_s``, 2.5 s, every tick:
``rate_hz``, 10 Hz; the horizon covers the COM controller's ``preview_s + horizon_s`` and one
publication period, so that a late reference is ridden through), ``/gait/command_status`` (one
JSON answer per command), ``/diagnostics`` and, with each plan, its footholds on
``/gait/markers`` for RViz and Foxglove (namespace ``footsteps``, :mod:`gait_nodes.markers`;
again once a second while no new plan comes, for displays that join late;
``publish_markers: false`` turns them off).

The gait settings are ROS parameters (defaults in ``config/footstep_planner.yaml``); a
``ros2 param set`` and a /gait/command go through the same checks, and an accepted change takes
effect at the next step boundary. The planning itself is :class:`gait_nodes.planning.footsteps.
GaitPlanner`, run by a worker (:class:`gait_nodes.planning.online.OnlinePlanner`); what is
published at each tick is decided by :class:`gait_nodes.planning.supervisor.PlannerSupervisor`.
This module only turns messages into their calls and their answers into messages.

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

Rejoin, pause and failures (:mod:`gait_nodes.planning.supervisor`): started into a running graph
(dds, rclpy), the planner plans from the robot's measured state (/tf and /joint_states, by
forward kinematics), waiting for a robot still finishing its steps; outside inproc it follows the
stale-input reports of the whole-body IK and the simulator on /diagnostics and, while the robot
is held, pauses (WARN, ``footstep_planner: walk``) holding the measured footholds and COM, then
resumes from the measured state (OK); it checks that each planned swing gets its
/gait/swing_trajectory (``footstep_planner: swing inputs``). A plan that cannot be made ends the
walk in a safe stand, not the process (:mod:`gait_nodes.faults`, ERROR ``footstep_planner:
faults``), and is tried again ``RETRY_AFTER_S`` later or at a new velocity.

With ``timing: joint_limit`` (the shipped default) on a robot with closed-form limb IK, the
rhythm follows from the joint velocity limit and the swing method
(:mod:`gait_nodes.swing.timing`): the value table's swings (the cached table of
:mod:`gait_nodes.swing.cache`; until swing_leg_policy has built it, the polynomial swing's longer
times stand in and the table is looked for again every second) or the polynomial swing's
(:mod:`gait_nodes.planning.timing_models`, made in the worker). The 'timing' diagnostic says
which; the 'gait' diagnostic reports the walked step period, swing, transfer, duty factor and
stride; a velocity beyond the fastest feasible one is reduced with a WARN on the 'velocity'
diagnostic.
"""

from __future__ import annotations

import functools
import itertools
import json
import math
import sys

import numpy as np

from gait_nodes import callback_times
from gait_nodes.cli import run_node
from gait_nodes.contract import (
    ContractError,
    FootstepPlan,
    ZmpReferenceMessages,
    base_transforms,
    footsteps_to_msg,
    swing_trajectory_from_msg,
)
from gait_nodes.diagnostics import OK, WARN, DiagnosticsReporter, level_value
from gait_nodes.errors import GaitNodesError, GaitParameterError, ParameterError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.interfaces import get_message
from gait_nodes.markers import footsteps_markers
from gait_nodes.paths import node_defaults
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.gait_params import (
    NUMERIC_RANGES,
    GaitParameters,
    command_id_of,
    parameters_from_mapping,
    parse_gait_command,
)
from gait_nodes.planning.online import (
    ACCEPTED,
    REJECTED,
    Answer,
    Changed,
    ChangeRefused,
    OnlinePlanner,
    Rehearsed,
)
from gait_nodes.planning.supervisor import (
    DEPENDENCIES,
    RETRY_AFTER_S,
    SWING_TOPIC,
    MeasuredState,  # noqa: F401 (its tests import it from here)
    Output,
    PlannerSupervisor,
    SupervisorSettings,
    measured_start,  # noqa: F401 (as MeasuredState)
)
from gait_nodes.planning.supervisor import HorizonCut as _HorizonCut  # noqa: F401 (as above)
from gait_nodes.planning.terrain import STAIRS_DEFAULTS, Staircase, check_walkable
from gait_nodes.planning.timing_models import TimingModels, auto_reason, describe_plan
from gait_nodes.robot.description import load_robot_description
from gait_nodes.runtime import Parameter, SetParametersResult, qos_profile_latched
from gait_nodes.single_source import SingleSource
from gait_nodes.swing.still_body import kept_probes

NODE_NAME = 'footstep_planner'
GAIT_FIELDS = tuple(GaitParameters.__dataclass_fields__)
#: Node settings: name -> (lowest, lowest included?, highest included, unit).
NODE_SETTINGS = {'rate_hz': (0.01, True, 1000.0, 'Hz'), 'zmp_horizon_s': (1.6, True, 60.0, 's'),
                 'zmp_sample_period_s': (0.0, False, 0.1, 's'),
                 'cmd_vel_timeout_s': (0.0, True, 60.0, 's')}
#: The newest plan's footholds go to /gait/markers again after this long without a plan [s].
FOOTHOLDS_REPEAT_S = 1.0
#: Node settings that are on or off: publish_markers, the footholds on /gait/markers.
NODE_FLAGS = ('publish_markers',)
#: Most samples in one /gait/zmp_reference.
MAX_ZMP_SAMPLES = 20000
#: Characters of a /gait/command (and of the reason it was refused) echoed in the answer.
ECHO_CHARACTERS = 500
#: The planning worker keeps the plan this much further ahead than the ZMP horizon and a step
#: [s]: the time a slow change may take while the walk goes on.
WORKER_COVER_S = 4.0
#: Ids of the changes made with ``ros2 param set`` (and set_parameters) start with this.
PARAMETER_ID = 'parameters-'
#: A change joins a standing robot's plan this far ahead [s]: the COM controller commits its
#: states 0.5 s ahead (horizon_s) and publishes them every 0.1 s; nothing of a standing robot's
#: committed COM moves, and the walk's start holds the ZMP while the COM counter-moves
#: (planning.footsteps.START_HOLD_FRACTION). A walking robot's change joins beyond the whole ZMP
#: horizon (zmp_horizon_s), whose every part the COM controller has previewed.
STANDING_LEAD_S = 0.6
#: Depth of the /gait/command subscription: a burst of commands is answered, not dropped.
COMMAND_DEPTH = 1000


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
    for name in NODE_FLAGS:
        if not isinstance(values[name], bool):
            raise ParameterError(f'{name} must be true or false, got {values[name]!r}')
    samples = values['zmp_horizon_s'] / values['zmp_sample_period_s']
    if samples > MAX_ZMP_SAMPLES:
        raise ParameterError(f'zmp_horizon_s / zmp_sample_period_s = {samples:.0f} samples; at '
                             f'most {MAX_ZMP_SAMPLES}')


def supervisor_settings(settings: dict[str, object]) -> SupervisorSettings:
    """The node settings the supervisor works with."""
    return SupervisorSettings(settings['zmp_horizon_s'], settings['zmp_sample_period_s'],
                              settings['cmd_vel_timeout_s'])


class FootstepPlanner(GuardedNode):
    """Plans footsteps and the ZMP reference from /cmd_vel and /gait/command."""

    def __init__(self):
        super().__init__(NODE_NAME)
        defaults = shipped_defaults()
        robot_name = self.declare_parameter('robot', str(defaults.pop('robot'))).value
        self.robot = load_robot_description(robot_name)
        # The robot's defaults, unchecked: checking resolves gait 'auto', which for a robot
        # with limb IK plans each of its gaits at the joint limit (seconds, once per robot:
        # planning.gait_choice), and the settings are checked below.
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
        for name in NODE_FLAGS:
            values[name] = self.declare_parameter(name, bool(defaults[name])).value
        check_node_settings(values)
        self.settings = {name: values[name] for name in (*NODE_SETTINGS, *NODE_FLAGS)}
        params = GaitParameters(**{name: values[name] for name in GAIT_FIELDS})
        params.check_robot(self.robot)
        terrain = Staircase.from_parameters(values)
        check_walkable(terrain, self.robot, params)

        start_ns = self._now_ns()
        self.diagnostics = DiagnosticsReporter(self, self.robot.name)
        self.faults = FaultGuard(self, self.diagnostics,
                                 hold=lambda exc: self.core.hold(self._now_ns()),
                                 recovered=lambda: self.core.recovered())
        self.timings = TimingModels(self.robot, warn=self.get_logger().warning)
        timing, self._timing_reason, self._timing_final = self.timings.timing(params)
        planner = GaitPlanner(self.robot, params, swing_timing=timing, terrain=terrain)
        if timing is not None:
            planner.take_probes(kept_probes(timing))  # the main job's first walk, if kept
        self.diagnostics.report('timing', OK if self._timing_final else WARN,
                                self._timing_reason)
        self._log_rhythm(planner, params)
        # Planning runs in the worker; the supervisor decides what each tick publishes.
        self.worker = OnlinePlanner(
            planner, start_ns, self._now_ns,
            cover_s=self._cover_s(params), lead_s=self.settings['zmp_horizon_s'],
            standing_lead_s=STANDING_LEAD_S,
            threaded=self.context.runtime != 'inproc',
            describe=functools.partial(describe_plan, self.robot),
            failure_hold_s=lambda p: (self.settings['zmp_horizon_s'] + p.params.step_period_s
                                      + RETRY_AFTER_S),
            job_done=lambda kind, seconds: callback_times.record(self.get_name(),
                                                                 f'worker {kind}', seconds),
            check=self.timings.check_joint_speeds)
        if self.context.runtime != 'inproc':
            # Beside the clock, the first walk's planning time is measured before it is asked
            # (the deterministic caller plans in no time).
            self.worker.submit_rehearsal(Twist2D(params.max_vx_m_s))
        # Under inproc every node starts together; elsewhere the robot may be somewhere already.
        self.core = PlannerSupervisor(self.robot, self.worker, self.faults,
                                      supervisor_settings(self.settings), start_ns,
                                      joining=self.context.runtime != 'inproc',
                                      load_model=self._model)
        # /joint_states only: /tf has many publishers by tf2's design (the simulator's odom ->
        # base_link, robot_state_publisher's links); a second robot shows on /joint_states.
        self.sources = SingleSource(self, ['/joint_states'], 'not reading the robot',
                                    watchdog=self.core.inputs, on_change=self._on_sources_changed)
        self._measured_subscriptions: list = []
        self._pending: tuple[dict, dict, Staircase | None] | None = None
        self._mirroring = False  # setting the declared parameters to what the plan walks
        self._commands = itertools.count(1)
        self._zmp_messages = ZmpReferenceMessages()
        self._shown: FootstepPlan | None = None  # the newest plan published
        self.footsteps_publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), 'gait/footsteps',
            qos_profile_latched)
        self.zmp_publisher = self.create_publisher(get_message('nav_msgs/msg/Path'),
                                                   'gait/zmp_reference', 10)
        # As deep as the command subscription: the answers to a burst of commands all go out.
        self.status_publisher = self.create_publisher(get_message('std_msgs/msg/String'),
                                                      'gait/command_status', COMMAND_DEPTH)
        self.markers_publisher = self.create_publisher(
            get_message('visualization_msgs/msg/MarkerArray'), 'gait/markers', 10)
        self.create_subscription(get_message('geometry_msgs/msg/Twist'), 'cmd_vel',
                                 self.on_cmd_vel, 10)
        self.create_subscription(get_message('std_msgs/msg/String'), 'gait/command',
                                 self.on_command, COMMAND_DEPTH)
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 SWING_TOPIC.lstrip('/'), self.on_swing, 10)
        if self.context.runtime != 'inproc':
            self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                     '/diagnostics', self.on_diagnostics, 50)
        self._listen(self.core.listening)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(self.on_parameters_set)
        self.timer = self.create_timer(1.0 / self.settings['rate_hz'], self.tick)
        self.create_timer(1.0, self.report_state)
        self._footholds_timer = self.create_timer(FOOTHOLDS_REPEAT_S, self._show_footholds)
        self.worker.start()
        # The command checks' first calls made now (the schema's validator, the robot's checks:
        # a third of a second), not in the first command's callback.
        parse_gait_command('{}')
        parameters_from_mapping(params, {}, self.robot)

    def _log_rhythm(self, planner: GaitPlanner, params: GaitParameters) -> None:
        """Log the gait and its rhythm (with joint-limit timing: the fastest forward walk).

        Beside the clock the worker times the fastest forward walk, in its rehearsal (logged
        when done: :meth:`_on_event`), while the node runs; the deterministic caller times it
        here, so that a first /cmd_vel walks at once.
        """
        if planner.swing_timing is not None and self.context.runtime != 'inproc':
            timing = (f'timing from the joint limit ({self._timing_reason}): the fastest forward '
                      f'walk is being planned')
        elif planner.swing_timing is not None:
            fastest, _ = planner.set_velocity(Twist2D(params.max_vx_m_s), 0.0)
            planner.set_velocity(Twist2D(), 0.0)
            rhythm = planner.rhythm(params, fastest)
            timing = (f'timing from the joint limit ({self._timing_reason}): fastest '
                      f'{fastest.vx_m_s:.4g} m/s, swing {rhythm.swing_s:.3f} s, step period '
                      f'{rhythm.step_period_s:.3f} s')
        else:
            timing = (f'{self._timing_reason}: step period {params.step_period_s:g} s, duty '
                      f'factor {params.duty_factor:g}')
        self.get_logger().info(f'{self.robot.name}: gait {params.gait} '
                               f'({params.resolved_gait(self.robot)}), {timing}')
        if params.gait == 'auto':
            self.get_logger().info(f'gait auto: {auto_reason(self.robot, params.timing)}')

    @property
    def planner(self) -> GaitPlanner:
        """The newest finished plan (:attr:`PlannerSupervisor.planner`)."""
        return self.core.planner

    @property
    def origin_ns(self) -> int:
        """ROS time of the plan's 0 s [ns] (:attr:`PlannerSupervisor.origin_ns`)."""
        return self.core.origin_ns

    def _now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def _cover_s(self, params: GaitParameters) -> float:
        return self.settings['zmp_horizon_s'] + params.step_period_s + WORKER_COVER_S

    def destroy_node(self):
        """Stop the planning worker, then the node."""
        worker = getattr(self, 'worker', None)
        if worker is not None:
            worker.stop()
        return super().destroy_node()

    # --- inputs --------------------------------------------------------------------------------

    def on_cmd_vel(self, msg) -> None:
        """Walk the commanded twist from the next step boundary (NaN dropped, excess clamped)."""
        values = (msg.linear.x, msg.linear.y, msg.linear.z,
                  msg.angular.x, msg.angular.y, msg.angular.z)
        if not all(math.isfinite(v) for v in values):
            self.diagnostics.drop('/cmd_vel', f'non-finite velocity {values}')
            return
        self.core.on_cmd_vel(Twist2D(float(msg.linear.x), float(msg.linear.y),
                                     float(msg.angular.z)), self._now_ns())

    def on_tf(self, msg) -> None:
        """The robot's base pose (joining or paused: the measured state)."""
        if self.sources.refused:
            return
        for transform in base_transforms(msg):
            t, r = transform.transform.translation, transform.transform.rotation
            pose = np.array([t.x, t.y, t.z, r.x, r.y, r.z, r.w], dtype=float)
            if not np.isfinite(pose).all() or np.linalg.norm(pose[3:]) < 0.5:
                continue
            pose[3:] /= np.linalg.norm(pose[3:])
            if self.core.on_base(pose, self._now_ns()):
                self.tick()

    def on_joint_states(self, msg) -> None:
        """The robot's joint positions (joining or paused: the measured state)."""
        if self.sources.refused:
            return
        positions = np.array(msg.position, dtype=float)
        if len(positions) != len(msg.name) or not np.isfinite(positions).all():
            return
        if self.core.on_joints(msg.name, positions, self._now_ns()):
            self.tick()

    def on_diagnostics(self, msg) -> None:
        """Hand the stale-input reports of the nodes that move the robot to the supervisor."""
        reports = [(status.name, _stale_topics(status)) for status in msg.status
                   if status.name in DEPENDENCIES]
        if reports and self.core.on_diagnostics(reports):
            self.tick()

    def on_swing(self, msg) -> None:
        """Note the swing trajectory of a planned swing (the supervisor checks each is sent)."""
        try:
            trajectory = swing_trajectory_from_msg(msg)
        except ContractError:
            return  # the whole-body IK reports malformed swings
        self.core.on_swing(trajectory.foot, int(trajectory.start_ns), self._now_ns())

    def _on_sources_changed(self) -> None:
        """Report at once that the robot's state is refused (two robots) or read again."""
        now_ns = self._now_ns()
        self.core.inputs.update(now_ns)
        self.diagnostics.publish([self.core.inputs.status(now_ns)])

    def _listen(self, on: bool) -> None:
        """Subscribe to the robot's measured state (/tf, /joint_states) or stop."""
        if on and not self._measured_subscriptions:
            self._measured_subscriptions = [
                self.create_subscription(get_message('tf2_msgs/msg/TFMessage'), '/tf',
                                         self.on_tf, 100),
                self.create_subscription(get_message('sensor_msgs/msg/JointState'),
                                         'joint_states', self.on_joint_states, 10)]
        elif not on:
            for subscription in self._measured_subscriptions:
                self.destroy_subscription(subscription)
            self._measured_subscriptions = []

    def _model(self):
        """The robot model for forward kinematics, or None (a robot without one)."""
        try:
            return self.timings.robot_model()
        except GaitNodesError as exc:
            self.get_logger().warning(f'no forward kinematics ({exc}): a rejoining planner '
                                      f'starts the feet at their nominal places')
            return None

    # --- outputs -------------------------------------------------------------------------------

    def tick(self) -> None:
        """Publish what the supervisor says: the worker's newest plan, a hold, or nothing."""
        self._publish(self.core.tick(self._now_ns()))

    def _publish(self, output: Output) -> None:
        """``output`` as messages; the worker's answers to commands on /gait/command_status."""
        for event in output.events:
            self._on_event(event)
        for report in output.reports:
            if report.logged:
                self.diagnostics.report(report.aspect, report.level, report.message,
                                        report.values)
            else:
                self.diagnostics.publish([(report.aspect, report.level, report.message,
                                           report.values)])
        if output.footsteps is not None:
            self.footsteps_publisher.publish(footsteps_to_msg(output.footsteps))
            self._shown = output.footsteps
            self._show_footholds()
        if output.zmp_reference is not None:
            self.zmp_publisher.publish(self._zmp_messages.to_msg(output.zmp_reference))
        for line in output.log:
            self.get_logger().info(line)
        self._listen(self.core.listening)

    def _show_footholds(self) -> None:
        """The newest plan's footholds on /gait/markers (if ``publish_markers``).

        With each plan, and again a second after the last showing while no new plan comes (a
        standing robot's plan changes seldom: a display that joins late shows them within a
        second).
        """
        self._footholds_timer.reset()
        if self.settings['publish_markers'] and self._shown is not None:
            self.markers_publisher.publish(footsteps_markers(
                self._shown, self._now_ns(), self.robot.foot_radius_m))

    def _on_event(self, event) -> None:
        """A worker's answer to a command or a change (its plans live: the supervisor's)."""
        if isinstance(event, Answer):
            self._answer(event)
            if event.state == ACCEPTED and not event.repeated:
                self._mirror(event.params)
            elif event.command_id.startswith(PARAMETER_ID) and not event.accepted:
                self._mirror(self.planner.params.to_dict())  # the refused value set back
        elif isinstance(event, Changed):
            kind, reason, final = event.info
            self._report_timing(reason, final)
        elif isinstance(event, ChangeRefused):
            self.diagnostics.report('timing', WARN, f'{self._timing_reason}; a change '
                                    f'({event.key}) could not be planned: {event.reason}')
        elif isinstance(event, Rehearsed):
            if event.applied is None:
                self.get_logger().warning(f'the fastest forward walk cannot be planned: '
                                          f'{event.reason}')
            elif event.rhythm is not None:
                self.get_logger().info(
                    f'fastest forward walk {event.applied.vx_m_s:.4g} m/s, swing '
                    f'{event.rhythm.swing_s:.3f} s, step period {event.rhythm.step_period_s:.3f} '
                    f's (planned in {event.seconds:.2f} s, while the robot stands)')

    def _report_timing(self, reason: str, final: bool) -> None:
        if reason != self._timing_reason or final != self._timing_final:
            self._timing_reason, self._timing_final = reason, final
            self.diagnostics.report('timing', OK if final else WARN, reason)

    # --- commands ------------------------------------------------------------------------------

    def on_command(self, msg) -> None:
        """Hand a JSON gait command to the worker; its answers come on /gait/command_status."""
        try:
            command_id, changes = parse_gait_command(msg.data)
        except GaitParameterError as exc:
            command_id = command_id_of(msg.data) or self._new_id()
            self._answer(Answer(command_id, REJECTED, str(exc), msg.data,
                                self.planner.params.to_dict()))
            return
        command_id = command_id or self._new_id()
        try:
            # The quick checks here (ranges, the robot, the terrain), the plan in the worker.
            parameters_from_mapping(self.planner.params, changes, self.robot)
        except GaitParameterError as exc:
            self._answer(Answer(command_id, REJECTED, str(exc), msg.data,
                                self.planner.params.to_dict()))
            return
        repeated = self.worker.submit_command(
            command_id, msg.data, functools.partial(self.timings.apply_changes, changes, None))
        if repeated is None:
            self.worker.run_pending()
        self._publish(self.core.poll(self._now_ns()))

    def _new_id(self) -> str:
        return f'{self.get_name()}-{next(self._commands)}'

    def _answer(self, answer: Answer) -> None:
        """Publish ``answer`` on /gait/command_status and report it on /diagnostics."""
        command, reason = _shortened(answer.text), _shortened(answer.reason)
        now_ns = self.get_clock().now().nanoseconds
        status = {'id': answer.command_id, 'state': answer.state,
                  'accepted': answer.accepted, 'reason': reason, 'params': answer.params,
                  'command': command}
        # The gait they walk ('auto' chosen once per robot and process: planning.gait_choice),
        # for swing_leg_policy's time law.
        status['resolved_gait'] = GaitParameters(**answer.params).resolved_gait(self.robot)
        if answer.takes_effect_ns is not None:
            status['takes_effect_ns'] = answer.takes_effect_ns
            status['takes_effect_in_s'] = round((answer.takes_effect_ns - now_ns) * 1e-9, 6)
        if answer.repeated:
            status['repeated'] = True
        self.status_publisher.publish(get_message('std_msgs/msg/String')(
            data=json.dumps(status)))
        values = {'id': answer.command_id, 'state': answer.state}
        if answer.takes_effect_ns is not None:
            values['takes_effect_s'] = (answer.takes_effect_ns - self.origin_ns) * 1e-9
        if answer.accepted:
            self.diagnostics.report('command', OK, f'command {answer.state}: {command}', values)
        else:
            self.diagnostics.drop('/gait/command', f'{reason} (command: {command})')

    def _mirror(self, params: dict) -> None:
        """Set the declared gait parameters to ``params`` (what the plan walks)."""
        changed = [Parameter(name, value=float(value) if name in NUMERIC_RANGES else value)
                   for name, value in params.items()
                   if name in GAIT_FIELDS and self.get_parameter(name).value != value]
        if changed:
            self._mirroring = True
            try:
                self.set_parameters(changed)
            finally:
                self._mirroring = False

    # --- parameters ----------------------------------------------------------------------------

    def on_set_parameters(self, parameters) -> SetParametersResult:
        """Check a parameter change quickly; the worker plans it (answer as for a command).

        A node setting takes effect at once; a gait setting or the staircase is planned by the
        worker like a /gait/command (id ``parameters-N``): refused there, the parameter is set
        back and the answer on /gait/command_status says why.
        """
        if self._mirroring:
            return SetParametersResult(successful=True)
        settings = dict(self.settings)
        gait_changes = {}
        stairs = {name: self.get_parameter(name).value for name in STAIRS_DEFAULTS}
        for parameter in parameters:
            if parameter.name == 'robot':
                if parameter.value != self.get_parameter('robot').value:
                    return SetParametersResult(successful=False,
                                               reason='robot is fixed when the node starts')
            elif parameter.name in NODE_SETTINGS or parameter.name in NODE_FLAGS:
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
                self.planner.check_terrain(
                    terrain, (self._now_ns() - self.origin_ns) * 1e-9, params)
            else:
                check_walkable(terrain, self.robot, params)
        except ParameterError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self._pending = (gait_changes, settings,
                         terrain if terrain != self.planner.terrain else None)
        return SetParametersResult(successful=True)

    def on_parameters_set(self, parameters) -> None:
        """Apply the node settings; hand the gait change to the worker."""
        if self._pending is None:
            return
        gait_changes, settings, terrain = self._pending
        self._pending = None
        if gait_changes or terrain is not None:
            text = json.dumps({**gait_changes, **({'stairs': terrain.count}
                                                  if terrain is not None else {})})
            self.worker.submit_command(
                f'{PARAMETER_ID}{next(self._commands)}', text,
                functools.partial(self.timings.apply_changes, gait_changes, terrain))
        if settings['rate_hz'] != self.settings['rate_hz']:
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / settings['rate_hz'], self.tick)
        self.settings = settings
        self.core.settings = supervisor_settings(settings)
        self.worker.cover_s = self._cover_s(self.planner.params)
        self.worker.lead_s = settings['zmp_horizon_s']
        self.worker.run_pending()

    # --- reports -------------------------------------------------------------------------------

    def report_state(self) -> None:
        """Once a second: the gait, the twist, the rhythm and the margin of the planned ZMP."""
        if not self._timing_final:
            self.worker.submit_change(self.timings.retime, key='timing')
            self.worker.run_pending()
        snapshot = self.worker.snapshot
        report = snapshot.report
        if not report:
            return
        level = OK if report['zmp_margin_kept_m'] >= report['zmp_margin_m'] - 1e-12 else WARN
        self.diagnostics.report('gait', level, f'{report["resolved_gait"]}, {report["mode"]}',
                                {**report, 'requested_twist': self.core.requested_twist.as_tuple(),
                                 'timing_source': self._timing_reason})


def _shortened(text: str) -> str:
    """``text``, cut to ``ECHO_CHARACTERS`` with its length said when longer."""
    if len(text) <= ECHO_CHARACTERS:
        return text
    return f'{text[:ECHO_CHARACTERS]}... ({len(text)} characters)'


def _stale_topics(status) -> list[str]:
    """The topics a DiagnosticStatus reports stale (none unless WARN or worse)."""
    if level_value(status.level) < WARN:
        return []
    return next((v.value for v in status.values if v.key == 'stale'), '').split(',')


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.footstep_planner [--ros-args ...]``."""
    return run_node(lambda options: FootstepPlanner(), args,
                    prog=f'python -m gait_nodes.{NODE_NAME}',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
