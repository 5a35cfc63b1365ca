"""whole_body_ik node: COM reference, footsteps and swing trajectories in, a joint trajectory out.

``python -m gait_nodes.whole_body_ik [--ros-args -p robot:=go2 ...]``. The node solves the
whole-body IK (:mod:`gait_nodes.robot.whole_body_ik`) at knots ``sample_period_s`` apart on a fixed
time grid, each for the instant it is for: the COM reference and body yaw at that instant
(/gait/com_reference, a stamped horizon), the stance feet where the footstep plan puts them
(/gait/footsteps), each swing foot on its swing trajectory (/gait/swing_trajectory); the body moves
so that the full-model COM is on the reference. Every ``1 / rate_hz`` it solves the knots from its
last solved one up to ``horizon_s`` ahead of the clock, never past the end of the COM reference it
holds, each knot once (warm-started from the knots before it) and reached from the one before
within the joint velocity limits (the step scaled down, as the thesis times its swings; kept within
``KNOT_SPEED_SHARE`` of them, see there). A knot whose references change before its instant comes
(a COM window that revises the states ahead, after a new ZMP reference; a new footstep plan; a
swing trajectory covering it) is solved again, with every later one; knots whose instant has come
never change. Then it publishes /joint_commands, a trajectory_msgs/JointTrajectory as a
ros2_control joint_trajectory_controller takes it: every joint of the URDF in the robot's order,
the knots from the latest one at or before now to the last one solved (header.stamp is the first
point's time, ``time_from_start`` strictly increasing from 0), positions and velocities (the
trajectory's derivative at the knots: central differences, never above the limits; the last knot at
rest, so that a consumer that hears nothing more stops there, and so that a Jazzy
joint_trajectory_controller takes it with allow_nonzero_velocity_at_trajectory_end false), no
accelerations or efforts. A consumer follows it by its stamps on its own clock, so a late message
is no jump: the previous one still covers ``horizon_s`` ahead.

* Before the first COM reference and footstep plan have arrived, the current posture is held
  (a one-point trajectory at the present instant, at rest): the robot's first /joint_states
  (and /tf base pose) once heard, taken once as a joint_trajectory_controller holds its
  position on activation, the nominal stance until then. A node started into a running graph
  (dds, rclpy) waits up to ``stale_timeout_s`` for /joint_states before it commands anything,
  so that a restarted IK picks up the robot where it stands instead of pulling it back to the
  nominal stance, and seeds its solver there.
* A late /gait/com_reference ends the trajectory where the reference ends (at rest, once the
  present has reached its last knot). Silent for more than ``stale_timeout_s``, the node
  holds: it sends its last knot as a one-point trajectory at rest (the robot stops where its
  trajectory ended, it does not keep stepping under a frozen COM) and reports the stale input
  (WARN, ``whole_body_ik: inputs``); when the reference returns it starts a new trajectory from
  the held posture and reports OK. A trajectory that ended before now (the node starved, or its
  COM reference late) was held at its last knot by its consumer: the next one starts there, at
  rest, at the latest knot time at or before now (no knot in the past is solved), and catches
  up within the velocity limits.
* A reference with more than one publisher (two graphs on one domain) is refused, not mixed
  (:mod:`gait_nodes.single_source`): the node holds as with a stale COM reference, ERROR on
  ``whole_body_ik: inputs``, until one publisher is left.
* A foot in swing per the plan with no swing trajectory covering a knot's instant follows the
  fallback swing (quintic smoothstep from lift-off to landing place, lifted by
  ``fallback_step_height_m``; :func:`gait_nodes.robot.whole_body_ik.fallback_swing_pose`).
  A trajectory that comes after its swing lifted off on the fallback is dropped (counted in
  ``late_swing_trajectories`` and logged): the foot lands on the fallback swing rather than
  jump onto the trajectory mid-air.
* /diagnostics: inputs dropped (NaN, wrong frame or feet) at once; every
  ``diagnostics_period_s`` a summary over the knots solved since the last one (the ``ticks``
  keys count knots): velocity saturation (fraction of saturated knots, the largest
  demanded/limit ratio, which joints), tracking residuals (foot, orientation and COM errors,
  unconverged knots, joints on a limit) and input state (waiting, stale, fallbacks).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from gait_nodes.cli import run_node
from gait_nodes.contract import (
    COM_JOINT_NAME,
    UNIT_QUATERNION_TOLERANCE,
    WORLD_FRAME,
    ContractError,
    base_transforms,
    com_reference_from_msg,
    footsteps_from_msg,
    joint_trajectory_to_msg,
    quaternion_to_yaw,
    swing_trajectory_from_msg,
    time_msg_to_ns,
)
from gait_nodes.diagnostics import OK, WARN, DiagnosticsReporter
from gait_nodes.errors import GaitNodesError, ParameterError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.interfaces import get_message
from gait_nodes.paths import node_defaults as shipped_node_defaults
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import (
    ComTrack,
    FootTargets,
    IkSettings,
    IkTargets,
    JointKnots,
    SwingPath,
    WholeBodyIkSolver,
    limb_ik_family,
    limit_joint_step,
    nominal_configuration,
    robosimian_limb_ik,
    seed_configuration,
    walking_vertical,
)
from gait_nodes.runtime import QoSProfile, SetParametersResult, qos_profile_latched
from gait_nodes.settings import checked_number as _number
from gait_nodes.single_source import SingleSource
from gait_nodes.watchdog import InputWatchdog

NODE_NAME = 'whole_body_ik'
#: Foot error and COM error above which a tick is reported as off target [m] (issue accuracy).
FOOT_ERROR_WARN_M = 1e-4
COM_ERROR_WARN_M = 1e-3
#: A COM window that moves a COM state (position, velocity, yaw summed) by more than this (a
#: micrometre: below any mechanical meaning, above the interpolation of equal windows sampled
#: at other instants) changed it [m, m/s, rad].
COM_CHANGE_M = 1e-6
#: Share of the joint velocity limits a step from knot to knot may use. A knot ahead is solved
#: again when its references change (a new COM window, footstep plan or swing): by up to
#: 0.02 mrad on RoboSimian's crawl, 0.002 rad/s over a 10 ms step. A consumer that switches to
#: the new trajectory a tick late (a message that came after its tick) steps from the old knot
#: to the new one: with knots at the full limit, that step was over it by that much (measured
#: over DDS and rclpy: 1.000-1.001x in 3 of 7 runs). The plan keeps 2 % for tracking, so the
#: share slows only knots the plan's sampling puts within half a percent of the limit.
KNOT_SPEED_SHARE = 0.995
#: The inputs that one node only may publish (gait_nodes.single_source).
REFERENCES = ('/gait/com_reference', '/gait/footsteps', '/gait/swing_trajectory')


def node_defaults() -> dict:
    """Parameter defaults from ``config/whole_body_ik.yaml``."""
    return shipped_node_defaults(NODE_NAME)


@dataclass(frozen=True)
class WholeBodyIkParams:
    """The node's parameters, validated (see config/whole_body_ik.yaml for the meanings)."""

    robot: str
    rate_hz: float
    sample_period_s: float
    horizon_s: float
    ik_family: int
    fallback_step_height_m: float
    max_iterations: int
    position_tolerance_m: float
    com_tolerance_m: float
    com_extrapolation_s: float
    stale_timeout_s: float
    diagnostics_period_s: float

    @classmethod
    def from_values(cls, values: dict) -> WholeBodyIkParams:
        """Validate raw parameter values; ParameterError naming the value and the range."""
        robot = values['robot']
        if not isinstance(robot, str) or not robot:
            raise ParameterError(f'robot must be a robot name or YAML path, got {robot!r}')
        family = values['ik_family']
        if isinstance(family, bool) or not isinstance(family, int) or not -1 <= family <= 7:
            raise ParameterError(f'ik_family must be an integer in [-1, 7], got {family!r}')
        iterations = values['max_iterations']
        if isinstance(iterations, bool) or not isinstance(iterations, int) \
                or not 1 <= iterations <= 1000:
            raise ParameterError(f'max_iterations must be an integer in [1, 1000], got '
                                 f'{iterations!r}')
        return cls(
            robot=robot,
            rate_hz=_number(values, 'rate_hz', 0.01, 2000.0),  # 5e-324 Hz: no timer period
            sample_period_s=_number(values, 'sample_period_s', 1e-4, 1.0),
            horizon_s=_number(values, 'horizon_s', 0.0, 10.0),
            ik_family=family,
            fallback_step_height_m=_number(values, 'fallback_step_height_m', 0.0, 0.5),
            max_iterations=iterations,
            position_tolerance_m=_number(values, 'position_tolerance_m', 1e-12, 1e-2),
            com_tolerance_m=_number(values, 'com_tolerance_m', 1e-12, 1e-2),
            com_extrapolation_s=_number(values, 'com_extrapolation_s', 0.0, 1.0),
            stale_timeout_s=_number(values, 'stale_timeout_s', 0.0, 60.0, low_open=True),
            diagnostics_period_s=_number(values, 'diagnostics_period_s', 0.0, 60.0,
                                         low_open=True),
        )

    def ik_settings(self, vertical: str) -> IkSettings:
        """Solver settings from these parameters.

        ``vertical``: the robot's (:func:`gait_nodes.robot.whole_body_ik.walking_vertical`).
        """
        return IkSettings(max_iterations=self.max_iterations,
                          position_tolerance_m=self.position_tolerance_m,
                          orientation_tolerance_rad=self.position_tolerance_m,
                          com_tolerance_m=self.com_tolerance_m, vertical=vertical)


class _Window:
    """What happened since the last diagnostics summary."""

    def __init__(self):
        self.ticks = 0
        self.saturated_ticks = 0
        self.scaled_ticks = 0  # saturated, or slowed to KNOT_SPEED_SHARE within the limits
        self.max_ratio = 0.0
        self.saturated_joints: dict[str, float] = {}
        self.max_foot_error_m = 0.0
        self.max_orientation_error_rad = 0.0
        self.max_com_error_m = 0.0
        self.unconverged_ticks = 0
        self.joints_at_limit: set[str] = set()
        self.fallback_ticks = 0
        self.late_swings = 0


class WholeBodyIk(GuardedNode):
    """The whole-body IK node (see the module docstring)."""

    def __init__(self):
        super().__init__(NODE_NAME)
        defaults = node_defaults()
        for name, value in defaults.items():
            self.declare_parameter(name, value)
        self.params = WholeBodyIkParams.from_values(
            {name: self.get_parameter(name).value for name in defaults})
        self.robot = load_robot_model(self.params.robot)
        self._family = self._checked_family(self.params.ik_family)
        self.solver = WholeBodyIkSolver(self.robot,
                                        self.params.ik_settings(walking_vertical(self.robot)))
        self.q_nominal = nominal_configuration(self.robot, self._family)
        self._q_solution = self.q_nominal.copy()
        # The last knot's configuration (the posture held before motion): the next step's start.
        self._q_command = self.q_nominal.copy()
        self._joints_command = self.robot.joint_positions(self._q_command)
        self._knots = JointKnots(len(self.robot.joint_names))
        # Solutions of the last consecutive solved knots (oldest first): the warm start.
        self._solutions: list[np.ndarray] = []
        self._solution_times_s: list[int] = []  # their knot times [ns]
        self._reseed = False
        self._plan = None
        self._feet: FootTargets | None = None  # the plan's foot targets
        self._com_track: ComTrack | None = None
        self._com_end_ns = None  # the time of the held COM reference's last point [ns]
        self._com_received_ns = None
        # The latest swing trajectory of each foot (robot order).
        self._swing_paths: list[SwingPath | None] = [None] * len(self.robot.foot_names)
        self._window = _Window()
        self._last_summary_ns = None
        self._moving = False
        self._held = False  # moving, but holding the last knot (stale COM reference)
        # The earliest instant [ns] whose references changed after its knot was solved.
        self._changed_from_ns: int | None = None
        self._zero_velocity = [0.0] * len(self.robot.joint_names)
        self._start_ns = self.get_clock().now().nanoseconds
        self.inputs = InputWatchdog(['/gait/com_reference'], self.params.stale_timeout_s,
                                    self._start_ns, holding='holding the last joint command')
        # Under inproc every node starts together; elsewhere the IK may join a running graph.
        self._joined = self.context.runtime == 'inproc'
        self._posture_measured = False  # the first /joint_states taken (_on_joint_states)
        self._base_pose = None
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self.diagnostics = DiagnosticsReporter(self, self.robot.name)
        self.faults = FaultGuard(self, self.diagnostics)
        # References from two graphs on one domain are refused (held as when stale), never mixed.
        self.sources = SingleSource(self, REFERENCES, 'holding the last joint command',
                                    watchdog=self.inputs)
        # Shared by every /joint_commands message (published messages are read-only).
        self._joint_names = list(self.robot.joint_names)
        self.publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/JointTrajectory'), 'joint_commands', 10)
        trajectory = get_message('trajectory_msgs/msg/MultiDOFJointTrajectory')
        self.create_subscription(trajectory, 'gait/com_reference', self._on_com_reference, 10)
        self.create_subscription(trajectory, 'gait/footsteps', self._on_footsteps,
                                 QoSProfile(depth=1, durability=qos_profile_latched.durability))
        self.create_subscription(trajectory, 'gait/swing_trajectory', self._on_swing, 10)
        # Heard only until motion starts (see _stop_listening_to_the_robot).
        self._robot_subscriptions = [
            self.create_subscription(get_message('sensor_msgs/msg/JointState'), 'joint_states',
                                     self._on_joint_states, 10),
            self.create_subscription(get_message('tf2_msgs/msg/TFMessage'), '/tf', self._on_tf,
                                     100)]
        self.timer = self.create_timer(1.0 / self.params.rate_hz, self.tick)
        self.get_logger().info(f'{self.robot.name}: {len(self.robot.joint_names)} joints, '
                               f'{len(self.robot.ik_joint_names)} moved by the IK, knots '
                               f'{self.params.sample_period_s:g} s apart up to '
                               f'{self.params.horizon_s:g} s ahead, sent at '
                               f'{self.params.rate_hz:g} Hz')

    # -- parameters ----------------------------------------------------------------------------

    def _checked_family(self, requested: int) -> int | None:
        default = limb_ik_family(self.robot)
        if requested == -1:
            return default
        if default is None:
            raise ParameterError(f'ik_family {requested} needs a robot with closed-form limb IK '
                                 f'(extra.limb_ik); {self.robot.name} has none: use -1')
        return requested

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        values = {name: getattr(self.params, name) for name in node_defaults()}
        for parameter in parameters:
            if parameter.name in values:
                values[parameter.name] = parameter.value
        try:
            params = WholeBodyIkParams.from_values(values)
            if params.robot != self.params.robot:
                raise ParameterError(f'robot is fixed at start ({self.params.robot}); restart '
                                     f'the node to change it')
            family = self._checked_family(params.ik_family)
            settings = params.ik_settings(walking_vertical(self.robot))
        except GaitNodesError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if params.rate_hz != self.params.rate_hz:
            self.timer.cancel()
            self.timer = self.create_timer(1.0 / params.rate_hz, self.tick)
        if family != self._family:
            self._family = family
            self._reseed = True
        self.solver.settings = settings
        self.inputs.timeout_s = params.stale_timeout_s
        self.params = params
        return SetParametersResult(successful=True)

    # -- inputs --------------------------------------------------------------------------------

    def _on_com_reference(self, msg) -> None:
        if self.sources.refuses('/gait/com_reference'):
            return
        try:
            track = com_track_from_msg(msg)
        except ContractError as exc:
            self.diagnostics.drop('/gait/com_reference', str(exc))
            return
        held = self._com_track
        if held is not None and self._moving:
            # A window normally repeats the committed states and extends them; one that
            # changes them (a new ZMP reference) has its knots solved again from there.
            changed_ns = held.first_change_ns(track, COM_CHANGE_M)
            if changed_ns is not None:
                self._references_changed(changed_ns)
        self._com_track = track if held is None else held.spliced(track)
        self._com_end_ns = self._com_track.stamps_ns[-1]
        self._com_received_ns = self.get_clock().now().nanoseconds
        self.inputs.heard('/gait/com_reference', self._com_received_ns)

    def _on_footsteps(self, msg) -> None:
        if self.sources.refuses('/gait/footsteps'):
            return
        try:
            plan = footsteps_from_msg(msg)
            if set(plan.foot_names) != set(self.robot.foot_names):
                raise ContractError(f'feet {list(plan.foot_names)} are not the robot\'s '
                                    f'{list(self.robot.foot_names)}')
        except ContractError as exc:
            self.diagnostics.drop('/gait/footsteps', str(exc))
            return
        if self._plan is not None and self._moving:
            self._references_changed(plan.start_ns)  # every knot of the new plan
        self._plan = plan
        self._feet = FootTargets(plan, self.robot.foot_names)

    def _on_swing(self, msg) -> None:
        if self.sources.refuses('/gait/swing_trajectory'):
            return
        try:
            swing = swing_trajectory_from_msg(msg)
            if swing.foot not in self.robot.foot_names:
                raise ContractError(f'foot {swing.foot!r} is not one of the robot\'s '
                                    f'{list(self.robot.foot_names)}')
        except ContractError as exc:
            self.diagnostics.drop('/gait/swing_trajectory', str(exc))
            return
        k = self.robot.foot_names.index(swing.foot)
        if self._moving:
            now_ns = self.get_clock().now().nanoseconds
            held = self._swing_paths[k]
            if swing.start_ns < now_ns and (held is None or not held.covers(now_ns)):
                # The foot lifted off without it and is on the fallback swing: switched now,
                # it would jump to the trajectory (joints at many times their limit). It lands
                # on the fallback; the trajectory is dropped and reported.
                self._window.late_swings += 1
                self.get_logger().warning(
                    f'{swing.foot} swing trajectory came {(now_ns - swing.start_ns) * 1e-9:.3f} '
                    f's after its lift-off: the foot stays on the fallback swing')
                return
            self._references_changed(swing.start_ns)
        self._swing_paths[k] = SwingPath(swing)

    def _on_tf(self, msg) -> None:
        if self._moving:
            return  # the base pose only seeds the posture held before motion
        for transform in base_transforms(msg):
            t, r = transform.transform.translation, transform.transform.rotation
            pose = np.array([t.x, t.y, t.z, r.x, r.y, r.z, r.w], dtype=float)
            if np.all(np.isfinite(pose)) and np.linalg.norm(pose[3:]) > 0.5:
                pose[3:] /= np.linalg.norm(pose[3:])
                self._base_pose = pose

    def _on_joint_states(self, msg) -> None:
        """Until motion is commanded, hold the posture first measured (rejoin a running graph).

        Measured once, as a joint_trajectory_controller holds its position on activation: a
        robot whose drives give under load (the physics simulator's) stands a little below its
        command, and a command that followed every measurement lowered it step by step (until
        session 24: RoboSimian's body 2-3.5 cm in the first 2 s over DDS and rclpy).
        """
        if self._moving or self._posture_measured:
            return
        try:
            names = list(msg.name)
            positions = np.array(msg.position, dtype=float)
            if len(positions) != len(names) or not np.all(np.isfinite(positions)):
                raise ContractError('positions are not one finite value per joint')
            indices = self.robot.indices(names)
        except (ContractError, GaitNodesError) as exc:
            self.diagnostics.drop('/joint_states', str(exc))
            return
        joints = self.robot.joint_positions(self._q_command)
        joints[indices] = positions
        self.robot.set_joint_positions(self._q_command, joints)
        self.robot.set_joint_positions(self._q_solution, joints)
        if self._base_pose is not None:
            self._q_solution[:7] = self._q_command[:7] = self._base_pose
        self._joints_command = self.robot.joint_positions(self._q_command)
        self._joined = True
        self._posture_measured = True

    # -- tick ----------------------------------------------------------------------------------

    def _targets_at(self, stamp_ns: int):
        """IK targets at ``stamp_ns`` (a knot's time): feet, foot yaws, COM, body yaw, fallbacks.

        From references checked where they entered (contract-validated messages, finite):
        the tick hands them to :meth:`WholeBodyIkSolver.solve_trusted` unchecked.
        """
        feet, yaws, fallbacks = self._feet.at(stamp_ns, self._swing_paths,
                                              self.params.fallback_step_height_m)
        com, yaw = self._com_track.at(stamp_ns, self.params.com_extrapolation_s)
        # Interpolations of finite references are finite, short of an overflow (IkTargets
        # refused that too; FootTargets checks the swing feet): one sum tells.
        if not math.isfinite(sum(com) + yaw):
            raise ValueError(f'the COM target is not finite: {com}, {yaw}')
        return feet, yaws, com, yaw, fallbacks

    def _warm_start(self, stamp_ns: int) -> np.ndarray:
        """The solver's start from the last solutions, extrapolated to ``stamp_ns``.

        Knots one sample period apart (the grid) use the equal-spacing formula; after a gap (a
        node that ran late skips the knots in the past) it extrapolates with the real times.
        """
        times = self._solution_times_s  # (at most three)
        step = stamp_ns - times[-1]
        if len(times) < 2 or times[-1] - times[-2] == step and (
                len(times) < 3 or times[-2] - times[-3] == step):
            return self.solver.warm_start(self._solutions)
        return self.solver.warm_start(self._solutions,
                                      [(t - stamp_ns) * 1e-9 for t in self._solution_times_s], 0.0)

    def tick(self) -> None:
        """Solve the knots up to the horizon, publish /joint_commands (module docstring)."""
        now_ns = self.get_clock().now().nanoseconds
        if self.inputs.update(now_ns):
            self.diagnostics.publish([self._input_status(now_ns, self._window)])
        if not self._joined:
            if (now_ns - self._start_ns) * 1e-9 <= self.params.stale_timeout_s:
                return  # wait a moment for the robot's /joint_states before commanding
            self._joined = True
        knots = self._knots
        if self._moving and self.inputs.stale:
            if not self._held:
                self._held = True
                self._solutions.clear()
                self._solution_times_s.clear()
            # The trajectory ends at its last knot: the robot stops there, at rest.
            self._publish([knots.times_ns[-1]], [knots.positions[-1]], [self._zero_velocity])
        elif self._com_track is not None and self._plan is not None and \
                not self.sources.refused:
            if not self._moving:
                self._moving = True
                self._stop_listening_to_the_robot()
                knots.restart(now_ns, self._joints_command, self._knot_state())
            elif self._held:
                self._held = False
                knots.restart(max(now_ns, knots.times_ns[-1]), self._joints_command,
                              self._knot_state())
            elif knots.times_ns[-1] > now_ns + int(round(
                    (self.params.horizon_s + self.params.sample_period_s) * 1e9)):
                knots.restart(now_ns, self._joints_command)  # the clock went back
            self._forget_changed_knots(now_ns)
            self._solve_knots(now_ns)
            start = knots.first_at_or_before(now_ns)
            # Every window ends at rest: a consumer that hears nothing more stops there (and a
            # Jazzy joint_trajectory_controller, allow_nonzero_velocity_at_trajectory_end
            # false by default, takes it); the next window replaces that end long before.
            self._publish(*knots.window(start, ends_at_rest=True))
            knots.drop_before(start)
        else:
            # The current posture (the nominal stance before any), at rest, now.
            self._publish([now_ns], [self._joints_command.tolist()], [self._zero_velocity])
        if self._last_summary_ns is None:
            self._last_summary_ns = now_ns
        elif (now_ns - self._last_summary_ns) * 1e-9 >= self.params.diagnostics_period_s - 1e-9:
            self._publish_summary(now_ns)

    def _knot_state(self) -> tuple:
        """What solving goes on from: commanded configuration and joints, last solution."""
        return self._q_command, self._joints_command, self._q_solution

    def _references_changed(self, from_ns: int) -> None:
        """The references changed from ``from_ns`` on: knots solved for then are solved again."""
        if self._changed_from_ns is None or from_ns < self._changed_from_ns:
            self._changed_from_ns = from_ns

    def _forget_changed_knots(self, now_ns: int) -> None:
        """Drop the knots whose references changed since they were solved (module docstring).

        Knots up to the latest one at or before now were sent for instants that have come:
        they stay; the trajectory goes on from there with the new references.
        """
        changed_ns, self._changed_from_ns = self._changed_from_ns, None
        knots = self._knots
        if changed_ns is None or changed_ns > knots.times_ns[-1]:
            return
        keep_ns = max(changed_ns - 1, knots.times_ns[knots.first_at_or_before(now_ns)])
        state = knots.truncate_after(keep_ns)
        if state is not None:
            self._q_command, self._joints_command, self._q_solution = state
            self._solutions.clear()
            self._solution_times_s.clear()

    def _solve_knots(self, now_ns: int) -> None:
        """Solve the knots after the last one up to the horizon and the COM reference's end.

        On the grid of the knots. A trajectory that ended before now (the node or its COM
        reference late) was held at its last knot by its consumer: it starts again from there,
        at rest, at the latest grid point at or before now; no knot in the past is solved.
        """
        knots = self._knots
        period_ns = max(int(round(self.params.sample_period_s * 1e9)), 1)
        end_ns = min(now_ns + int(round(self.params.horizon_s * 1e9)), self._com_end_ns)
        last_ns = knots.times_ns[-1]
        if last_ns + period_ns < now_ns:
            knots.restart(last_ns + (now_ns - last_ns) // period_ns * period_ns,
                          knots.joints[-1], knots.states[-1])
        stamp_ns = knots.times_ns[-1] + period_ns
        while stamp_ns <= end_ns:
            self._solve_knot(stamp_ns, (stamp_ns - knots.times_ns[-1]) * 1e-9)
            stamp_ns += period_ns

    def _solve_knot(self, stamp_ns: int, dt_s: float) -> None:
        """Solve the IK at ``stamp_ns``, step there from the last knot within the limits."""
        window = self._window
        window.ticks += 1
        feet, yaws, com, yaw, fallbacks = self._targets_at(stamp_ns)
        window.fallback_ticks += fallbacks > 0
        if self._reseed:
            self._q_solution = seed_configuration(
                self.robot, IkTargets(feet, np.array(yaws), yaw, com_in_world=np.array(com)),
                self._family, self._q_solution[:3])
            self._reseed = False
            self._solutions.clear()
            self._solution_times_s.clear()
        result = self.solver.solve_trusted(
            feet, yaws, yaw, self._warm_start(stamp_ns) if self._solutions
            else self._q_solution, com)
        self._q_solution = result.q
        self._solutions.append(result.q)
        self._solution_times_s.append(stamp_ns)
        if len(self._solutions) > 3:
            del self._solutions[0]
            del self._solution_times_s[0]
        window.max_foot_error_m = max(window.max_foot_error_m,
                                      *result.foot_position_errors_m.tolist())
        window.max_orientation_error_rad = max(window.max_orientation_error_rad,
                                               *result.foot_orientation_errors_rad.tolist())
        window.max_com_error_m = max(window.max_com_error_m, result.com_error_m)
        window.unconverged_ticks += not result.converged
        if result.joints_at_limit:
            window.joints_at_limit.update(result.joints_at_limit)
        q, joints, velocities, saturation = limit_joint_step(
            self.robot, self._q_command, self._joints_command, result.q, dt_s,
            KNOT_SPEED_SHARE)
        self._q_command, self._joints_command = q, joints
        self._knots.append(stamp_ns, joints, velocities,
                           (self._q_command, joints, self._q_solution))
        window.scaled_ticks += saturation.scaled
        if saturation.saturated:
            window.saturated_ticks += 1
            window.max_ratio = max(window.max_ratio, saturation.ratio)
            for joint, ratio in zip(saturation.joints, saturation.demanded_over_limit,
                                    strict=True):
                window.saturated_joints[joint] = max(window.saturated_joints.get(joint, 0.0),
                                                     ratio)

    def _stop_listening_to_the_robot(self) -> None:
        """Drop the /joint_states and /tf subscriptions: once moving, the node never reads them.

        They only seed the posture held before motion (and ``_moving`` never goes back), so
        nothing changes but the 400 deliveries a second nobody needs (about 3 us of a 200 Hz
        tick under inproc, the readers' share of the robot's state traffic under DDS).
        """
        for subscription in self._robot_subscriptions:
            self.destroy_subscription(subscription)
        self._robot_subscriptions = []

    def _publish(self, times_ns: list[int], positions: list[list[float]],
                 velocities: list[list[float]]) -> None:
        self.publisher.publish(joint_trajectory_to_msg(self._joint_names, times_ns, positions,
                                                       velocities))

    def _publish_summary(self, now_ns: int) -> None:
        window, self._window = self._window, _Window()
        self._last_summary_ns = now_ns
        statuses = []
        ticks = max(window.ticks, 1)
        joints = sorted(window.saturated_joints, key=lambda j: -window.saturated_joints[j])
        statuses.append((
            'velocity saturation', WARN if window.saturated_ticks else OK,
            (f'{window.saturated_ticks} of {window.ticks} ticks saturated, up to '
             f'{window.max_ratio:.4g}x the limit: {", ".join(joints)}')
            if window.saturated_ticks else 'joint velocities within limits',
            {'saturated_ticks': window.saturated_ticks, 'ticks': window.ticks,
             'slowed_ticks': window.scaled_ticks, 'knot_speed_share': KNOT_SPEED_SHARE,
             'saturated_fraction': window.saturated_ticks / ticks,
             'max_demanded_over_limit': window.max_ratio,
             'joints': ','.join(joints),
             'joint_ratios': ','.join(f'{j}:{window.saturated_joints[j]:.3g}' for j in joints)}))
        off_target = (window.max_foot_error_m > FOOT_ERROR_WARN_M
                      or window.max_com_error_m > COM_ERROR_WARN_M)
        statuses.append((
            'tracking', WARN if off_target else OK,
            'targets out of reach (best effort)' if off_target else 'feet and COM on target',
            {'max_foot_error_m': window.max_foot_error_m,
             'max_foot_orientation_error_rad': window.max_orientation_error_rad,
             'max_com_error_m': window.max_com_error_m,
             'unconverged_ticks': window.unconverged_ticks,
             'joints_at_limit': ','.join(sorted(window.joints_at_limit))}))
        statuses.append(self._input_status(now_ns, window))
        if self._family is not None:
            statuses.append(self._family_status())
        self.diagnostics.publish(statuses)
        if window.saturated_ticks:
            self.get_logger().warning(statuses[0][2])

    def _input_status(self, now_ns: int, window: _Window):
        waiting = [topic for topic, value in (('/gait/com_reference', self._com_track),
                                              ('/gait/footsteps', self._plan)) if value is None]
        aspect, level, message, values = self.inputs.status(now_ns)
        if waiting:
            holding = 'the current posture' if self._joined else 'nothing yet'
            message = f'holding {holding}, waiting for {", ".join(waiting)}' + (
                f'; {message}' if level >= WARN else '')
        values.update({'waiting_for': ','.join(waiting),
                       'fallback_swing_ticks': window.fallback_ticks,
                       'late_swing_trajectories': window.late_swings,
                       'dropped': ','.join(f'{t}:{n}'
                                           for t, n in self.diagnostics.dropped.items())})
        return aspect, level, message, values

    def _family_status(self):
        limb_ik = robosimian_limb_ik(self.robot)
        joints = self.robot.joint_positions(self._q_command)
        families = {}
        for foot in self.robot.description.feet:
            angles = joints[self.robot.indices(foot.joints)]
            families[foot.name] = int(limb_ik.family_of(angles[None], foot.name, 1e-4,
                                                          self._family)[0])
        off = [name for name, family in families.items() if family != self._family]
        return ('ik family', WARN if off else OK,
                f'limbs {off} left family {self._family}' if off
                else f'every limb in family {self._family}',
                {'family': self._family, **{f'{name}_family': family
                                            for name, family in families.items()}})


def com_track_from_msg(msg) -> ComTrack:
    """The :class:`ComTrack` of a /gait/com_reference message; ContractError if malformed.

    Equal to ``ComTrack.from_states(com_reference_from_msg(msg))`` (test_whole_body_ik checks
    it on good and bad messages): the well-formed message of every tick is read straight into
    floats, five times cheaper than building a validated ComState per point; a message this
    fast path does not take as it is (a bad frame, a NaN, an odd shape or type) goes through
    the contract's reader, which accepts it the same or names what is wrong.
    """
    try:
        track = _com_track_as_expected(msg)
    except (AttributeError, TypeError, ValueError, IndexError):
        track = None
    return track if track is not None else ComTrack.from_states(com_reference_from_msg(msg))


def _com_track_as_expected(msg) -> ComTrack | None:
    """The track of a /gait/com_reference message that is exactly as expected, else None."""
    names = msg.joint_names
    if msg.header.frame_id != WORLD_FRAME or len(names) != 1 or names[0] != COM_JOINT_NAME \
            or not msg.points:
        return None
    start_ns = time_msg_to_ns(msg.header.stamp)
    stamps, positions, velocities, accelerations, yaws, yaw_rates = [], [], [], [], [], []
    total = 0.0  # every value: finite if and only if each is (short of an overflow)
    for point in msg.points:
        transforms, twists, accels = point.transforms, point.velocities, point.accelerations
        if len(transforms) != 1 or len(twists) != 1 or len(accels) != 1:
            return None
        t, r = transforms[0].translation, transforms[0].rotation
        v, a = twists[0].linear, accels[0].linear
        position = [float(t.x), float(t.y), float(t.z)]
        velocity = [float(v.x), float(v.y), float(v.z)]
        acceleration = [float(a.x), float(a.y), float(a.z)]
        x, y, z, w = r.x, r.y, r.z, r.w
        if not abs(x * x + y * y + z * z + w * w - 1.0) <= UNIT_QUATERNION_TOLERANCE:
            return None  # no yaw: the contract's reader names the rotation
        yaw = quaternion_to_yaw(x, y, z, w)
        yaw_rate = float(twists[0].angular.z)
        total += sum(position) + sum(velocity) + sum(acceleration) + yaw + yaw_rate
        offset = point.time_from_start
        stamps.append(start_ns + int(offset.sec) * 1_000_000_000 + int(offset.nanosec))
        positions.append(position)
        velocities.append(velocity)
        accelerations.append(acceleration)
        yaws.append(yaw)
        yaw_rates.append(yaw_rate)
    if not math.isfinite(total):
        return None
    if any(later <= earlier for earlier, later in zip(stamps, stamps[1:], strict=False)):
        return None  # the contract's reader names it
    return ComTrack(stamps, positions, velocities, yaws, yaw_rates, accelerations)


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.whole_body_ik [--ros-args ...]``."""
    return run_node(lambda options: WholeBodyIk(), args, prog='python -m gait_nodes.whole_body_ik',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
