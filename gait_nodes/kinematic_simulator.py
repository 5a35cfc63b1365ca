"""kinematic_simulator node: /joint_commands in; joint states, base pose and the ZMP monitor out.

``python -m gait_nodes.kinematic_simulator [--ros-args -p robot:=talos -p publish_clock:=true]``.
/joint_commands is a trajectory_msgs/JointTrajectory, as a ros2_control
joint_trajectory_controller takes it: the simulator holds one trajectory
(:class:`gait_nodes.sim.trajectory.HeldTrajectory`); a new message replaces it from the message's
first point's time on (the held points before that time are kept), a zero header stamp meaning
"start when received". Every tick (``rate_hz``) the simulator samples the held trajectory at the
tick's own stamp (cubic Hermite between points with velocities, linear without; past the end the
last point, held) and moves each joint toward that as a position-controlled actuator with the
robot's velocity and acceleration limits would, the trajectory's velocity as feed-forward
(:class:`gait_nodes.sim.kinematics.PositionActuators`): the joints follow the stamps the
commands carry, not the moments their messages arrive. It places the floating base on the stance
feet so that they do not slip (:class:`gait_nodes.sim.kinematics.KinematicSimulation`; which
feet stand comes from the latest /gait/footsteps plan, a foot due down touching down once it
is within ``contact_height_tolerance_m`` of its planned foothold, without a plan from the foot
heights) and
publishes /joint_states (positions, velocities) and /tf (odom -> base_link).

The ZMP monitor (:mod:`gait_nodes.sim.zmp_monitor`) evaluates the full multi-body model one tick
behind, by central differences of the integrated configurations: the /gait/zmp, /gait/com,
/gait/support_polygon and /gait/markers messages are stamped at the instant they describe (the
previous tick). /gait/markers (ZMP and COM spheres, support polygon outline, for RViz or
Foxglove; namespace ``gait``, beside the planner's footholds and the swing paths,
:mod:`gait_nodes.markers`) comes at a display's rate, ``markers_rate_hz``: the first sample of
each of its periods. /diagnostics: a stability report at once whenever the level changes (OK, WARN
below ``warn_margin_m``, ERROR with the ZMP outside the support polygon) and a stale-input report
when /joint_commands stop for ``stale_after_s`` (the simulator goes on following what it holds,
then holds its last point); every ``diagnostics_period_s`` a summary (stability margin, joint
velocity and acceleration saturation, foot slip, inputs). A trajectory that a
joint_trajectory_controller would refuse (unknown or repeated joint names, no points,
``time_from_start`` negative or not strictly increasing, positions not one per joint, velocities
or accelerations neither empty nor one per joint, efforts, NaN) is dropped whole and reported
with what was wrong; the held trajectory is unchanged. Accelerations are checked, not used.
/joint_commands from more than one publisher (two graphs on one domain) are refused, not mixed
(:mod:`gait_nodes.single_source`): the robot is held where its trajectory has it, ERROR on
``kinematic_simulator: inputs``, until one IK is left.

With ``publish_clock`` the simulator owns time: it advances by one period per tick (paced by the
wall clock) and publishes /clock, which every node started with ``use_sim_time:=true`` follows.
Under the inproc runtime time is the executor's and /clock repeats it. On the wall clock the
simulation still steps on a fixed grid of one period (as a fixed-step simulator synchronized to
real time): a timer that fires late delays the publication, not the stamps, so the monitor's
finite differences see the motion and not the scheduler's jitter; if the timer falls more than
``MAX_LAG_PERIODS`` behind, the grid is re-anchored to the clock.
"""

from __future__ import annotations

import bisect
import math
import sys
from collections import deque
from dataclasses import dataclass

import numpy as np

from gait_nodes.cli import run_node
from gait_nodes.contract import (
    BASE_FRAME,
    WORLD_FRAME,
    ContractError,
    FootstepPlan,
    JointTrajectoryCommand,
    footsteps_from_msg,
    joint_trajectory_from_msg,
)
from gait_nodes.diagnostics import ERROR, OK, WARN, DiagnosticsReporter
from gait_nodes.errors import GaitNodesError, ParameterError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.interfaces import get_constructor, get_message
from gait_nodes.markers import SIMULATOR_NAMESPACE
from gait_nodes.paths import node_defaults as shipped_node_defaults
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import nominal_configuration
from gait_nodes.runtime import (
    Clock,
    ClockType,
    DurabilityPolicy,
    QoSProfile,
    SetParametersResult,
)
from gait_nodes.settings import checked_number as _number
from gait_nodes.sim.kinematics import ActuatorStep, KinematicSimulation, SimulationSettings
from gait_nodes.sim.trajectory import HeldTrajectory
from gait_nodes.sim.zmp_monitor import SlidingDifferences, Support, ZmpMonitor, ZmpState
from gait_nodes.single_source import SingleSource
from gait_nodes.watchdog import InputWatchdog

NODE_NAME = 'kinematic_simulator'
#: On the wall clock, how many periods the step grid may trail the clock before re-anchoring.
MAX_LAG_PERIODS = 10
#: Slowest rate [Hz] of the simulation and the markers (a 5e-324 Hz timer has no period).
MIN_RATE_HZ = 0.01
LEVEL_WORDS = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR'}


def node_defaults() -> dict:
    """Parameter defaults from ``config/kinematic_simulator.yaml``."""
    return shipped_node_defaults(NODE_NAME)


def _flag(values: dict, name: str) -> bool:
    value = values[name]
    if not isinstance(value, bool):
        raise ParameterError(f'{name} must be true or false, got {value!r}')
    return value


@dataclass(frozen=True)
class KinematicSimulatorParams:
    """The node's parameters, validated (meanings in config/kinematic_simulator.yaml)."""

    robot: str
    rate_hz: float
    publish_clock: bool
    warn_margin_m: float
    stale_after_s: float
    diagnostics_period_s: float
    contact_height_tolerance_m: float
    ground_height_m: float
    publish_markers: bool
    markers_rate_hz: float

    @classmethod
    def from_values(cls, values: dict) -> KinematicSimulatorParams:
        """Validate raw parameter values; ParameterError naming the value and the range."""
        robot = values['robot']
        if not isinstance(robot, str) or not robot:
            raise ParameterError(f'robot must be a robot name or YAML path, got {robot!r}')
        return cls(
            robot=robot,
            rate_hz=_number(values, 'rate_hz', MIN_RATE_HZ, 2000.0),
            publish_clock=_flag(values, 'publish_clock'),
            warn_margin_m=_number(values, 'warn_margin_m', 0.0, 1.0),
            stale_after_s=_number(values, 'stale_after_s', 0.0, 60.0, low_open=True),
            diagnostics_period_s=_number(values, 'diagnostics_period_s', 0.0, 60.0,
                                         low_open=True),
            contact_height_tolerance_m=_number(values, 'contact_height_tolerance_m', 0.0, 0.5),
            ground_height_m=_number(values, 'ground_height_m', -10.0, 10.0),
            publish_markers=_flag(values, 'publish_markers'),
            markers_rate_hz=_number(values, 'markers_rate_hz', MIN_RATE_HZ, 2000.0),
        )

    def simulation_settings(self) -> SimulationSettings:
        """Settings of the simulation core."""
        return SimulationSettings(ground_height_m=self.ground_height_m,
                                  contact_height_tolerance_m=self.contact_height_tolerance_m)


class PlanContacts:
    """Which feet a footstep plan has on the ground, in the robot's foot order.

    :meth:`FootstepPlan.contacts_at` walks every swing of the plan; its answer only changes
    at a lift-off or a touch-down, so between two consecutive contact changes it is looked up
    once and kept (at a change itself it is asked each time). Equal to
    ``plan.contacts_at(t_s)[order]`` at every instant.

    Args:
        plan: The footstep plan.
        order: (F,) index in ``plan.foot_names`` of each of the robot's feet.
    """

    def __init__(self, plan: FootstepPlan, order: np.ndarray):
        self.plan = plan
        self.order = order
        self.changes_s = sorted({t for swing in plan.swings()
                                 for t in (swing.lift_off_s, swing.touch_down_s)})
        self._between: dict[int, np.ndarray] = {}

    def at(self, t_s: float) -> np.ndarray:
        """(F,) booleans, read-only: the feet on the ground at ``t_s`` [s] from the start."""
        k = bisect.bisect_left(self.changes_s, t_s)
        if k < len(self.changes_s) and self.changes_s[k] == t_s:
            return self._lookup(t_s)
        contacts = self._between.get(k)
        if contacts is None:
            contacts = self._between[k] = self._lookup(t_s)
        return contacts

    def _lookup(self, t_s: float) -> np.ndarray:
        contacts = self.plan.contacts_at(t_s)[self.order]
        contacts.flags.writeable = False
        return contacts


class _Window:
    """What happened since the last diagnostics summary."""

    def __init__(self):
        self.ticks = 0
        self.saturated_ticks = 0
        self.acceleration_saturated_ticks = 0
        self.max_ratio = 0.0
        self.saturated_joints: dict[str, float] = {}
        self.clamped_joints: set[str] = set()
        self.samples = 0
        self.samples_outside = 0
        self.samples_warn = 0
        self.min_margin_m = math.inf
        self.max_slip_m = 0.0
        self.touch_downs = 0


class KinematicSimulator(GuardedNode):
    """The kinematic simulator and ZMP monitor node (see the module docstring).

    A simulator with the same topics and another simulation core (the physics simulator)
    subclasses it and replaces the hooks: its name and parameters (``NODE_NAME``, ``Params``,
    ``FIXED_PARAMETERS``), :meth:`_make_simulation`, :meth:`_plan_inputs`,
    :meth:`_publish_measurements`, :meth:`_account` and :meth:`_summary_statuses`.
    """

    NODE_NAME = NODE_NAME
    Params = KinematicSimulatorParams
    #: Parameters that cannot change once the node runs.
    FIXED_PARAMETERS = ('robot', 'publish_clock')

    @classmethod
    def node_defaults(cls) -> dict:
        """Parameter defaults from ``config/<NODE_NAME>.yaml``."""
        return shipped_node_defaults(cls.NODE_NAME)

    def __init__(self):
        super().__init__(self.NODE_NAME)
        defaults = self.node_defaults()
        self._declare_parameters(defaults)
        self.params = self.Params.from_values(
            {name: self.get_parameter(name).value for name in defaults})
        self.robot = load_robot_model(self.params.robot)
        q_initial = nominal_configuration(self.robot)
        self.simulation = self._make_simulation(q_initial)
        self.monitor = ZmpMonitor(self.robot.model, self._monitor_foot_radius_m(),
                                  self.params.ground_height_m)
        # The monitor's finite differences, each configuration difference computed once.
        self._differences = SlidingDifferences(self.robot.model)
        #: The joint trajectory being followed (the initial configuration until a command).
        self.trajectory = HeldTrajectory(self.robot.joint_positions(q_initial))
        self._joint_index = {name: k for k, name in enumerate(self.robot.joint_names)}
        self._plan: FootstepPlan | None = None
        self._plan_contacts: PlanContacts | None = None
        self._last_command_ns: int | None = None
        self._started_ns: int | None = None
        self.inputs: InputWatchdog | None = None  # from the first tick, when time starts
        # [checked, quiet until) [ns]: the instants at which the watchdog's verdict cannot
        # have changed since it was last asked (see _check_inputs).
        self._inputs_quiet_ns = (0, 0)
        self._stability_level: int | None = None
        # (stamp [ns], q, contact points, odom header or None) of the last three ticks, oldest
        # first; None: an instant before the first step (not published, no monitor sample).
        self._history: deque = deque(maxlen=3)
        self._window = self._new_window()
        self._last_summary_ns: int | None = None
        self._sim_ns = 0
        # The monitor's Support of the simulation's contact points (the same array until a
        # foot lands or lifts), and the polygon's message parts of that support.
        self._support_source: np.ndarray | None = None
        self._support: Support | None = None
        self._polygon_support: Support | None = None
        self._polygon_cache: tuple = (None, [])
        #: Index of the last /gait/markers period that got its message.
        self._markers_slot: int | None = None
        self._period_ns = int(round(1e9 / self.params.rate_hz))
        self._markers_period_ns = int(round(1e9 / self.params.markers_rate_hz))
        # Under inproc the executor owns time; elsewhere publish_clock makes the simulator the
        # source of time (even with use_sim_time, which would make it wait for itself).
        self._owns_time = self.params.publish_clock and self.context.runtime != 'inproc'
        if self._owns_time and hasattr(self.get_clock(), 'set_source'):
            # Logs and diagnostics carry the simulated time too (rclpy: use_sim_time does it).
            self.get_clock().set_source(lambda: self._sim_ns)

        self.diagnostics = DiagnosticsReporter(self, self.robot.name)
        self.faults = FaultGuard(self, self.diagnostics)
        # Commands from two IKs (two graphs on one domain) are refused, never mixed.
        self.sources = SingleSource(self, ['/joint_commands'], 'holding the robot where it is',
                                    on_change=self._on_sources)
        self._msg = {name.rsplit('/', 1)[1]: get_message(name) for name in (
            'sensor_msgs/msg/JointState', 'geometry_msgs/msg/PointStamped',
            'geometry_msgs/msg/PolygonStamped', 'geometry_msgs/msg/Point32',
            'geometry_msgs/msg/Point', 'geometry_msgs/msg/TransformStamped',
            'tf2_msgs/msg/TFMessage', 'visualization_msgs/msg/Marker',
            'visualization_msgs/msg/MarkerArray', 'rosgraph_msgs/msg/Clock',
            'builtin_interfaces/msg/Time')}
        # Positional constructors of every message built per tick (get_constructor).
        self._new = {name.rsplit('/', 1)[1]: get_constructor(name) for name in (
            'sensor_msgs/msg/JointState', 'std_msgs/msg/Header', 'geometry_msgs/msg/Point',
            'geometry_msgs/msg/PointStamped', 'geometry_msgs/msg/PolygonStamped',
            'geometry_msgs/msg/Polygon', 'geometry_msgs/msg/TransformStamped',
            'geometry_msgs/msg/Transform', 'geometry_msgs/msg/Vector3',
            'geometry_msgs/msg/Quaternion', 'geometry_msgs/msg/Pose', 'tf2_msgs/msg/TFMessage',
            'visualization_msgs/msg/Marker', 'visualization_msgs/msg/MarkerArray',
            'std_msgs/msg/ColorRGBA', 'builtin_interfaces/msg/Duration',
            'sensor_msgs/msg/CompressedImage', 'visualization_msgs/msg/MeshFile',
            'builtin_interfaces/msg/Time')}
        self._joint_names = list(self.robot.joint_names)
        self._marker_parts_cache = self._marker_parts()
        joint_state = self._msg['JointState']
        point = self._msg['PointStamped']
        self._joint_states = self.create_publisher(joint_state, 'joint_states', 10)
        self._tf = self.create_publisher(get_message('tf2_msgs/msg/TFMessage'), '/tf', 100)
        self._zmp = self.create_publisher(point, 'gait/zmp', 10)
        self._com = self.create_publisher(point, 'gait/com', 10)
        self._polygon = self.create_publisher(get_message('geometry_msgs/msg/PolygonStamped'),
                                              'gait/support_polygon', 10)
        self._markers = self.create_publisher(get_message('visualization_msgs/msg/MarkerArray'),
                                              'gait/markers', 10)
        self._clock_publisher = (
            self.create_publisher(get_message('rosgraph_msgs/msg/Clock'), '/clock', 10)
            if self.params.publish_clock else None)
        self.create_subscription(get_message('trajectory_msgs/msg/JointTrajectory'),
                                 'joint_commands', self._on_joint_commands, 10)
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 'gait/footsteps', self._on_footsteps,
                                 QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        self.timer = self._make_timer(self.params.rate_hz)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(f'{self.robot.name}: {len(self.robot.joint_names)} joints, '
                               f'{self.robot.mass_kg:.1f} kg, {self.params.rate_hz:g} Hz'
                               + (', publishing /clock' if self.params.publish_clock else ''))

    # -- the simulation core (hooks) -----------------------------------------------------------

    def _declare_parameters(self, defaults: dict) -> None:
        for name, value in defaults.items():
            self.declare_parameter(name, value)

    def _make_simulation(self, q_initial: np.ndarray):
        """The simulation core, started at ``q_initial``."""
        simulation = KinematicSimulation(self.robot, q_initial,
                                         self.params.simulation_settings())
        # With continuous joints (cos, sin in q) the joint positions are read from q.
        self._continuous_joints = bool(simulation.actuators.continuous.any())
        return simulation

    def _monitor_foot_radius_m(self) -> float:
        """Radius of the discs the ZMP monitor puts around each contact point [m]."""
        return self.robot.description.foot_radius_m

    def _apply_settings(self, params) -> None:
        """Hand changed parameters to the simulation core."""
        self.simulation.settings = params.simulation_settings()

    def _plan_inputs(self, now_ns: int) -> tuple:
        """``(contacts, heights)`` the plan gives the simulation at ``now_ns`` (or None)."""
        contacts = heights = None
        if self._plan is not None:
            t_s = (now_ns - self._plan.start_ns) * 1e-9
            contacts = self._plan_contacts.at(t_s)
            if any(down and foot is None
                   for down, foot in zip(contacts.tolist(), self.simulation.latched,
                                         strict=True)):
                # A foot due down: it touches down on its foothold, not in the air.
                heights = self._plan.stance_positions_at(t_s)[self._plan_contacts.order, 2]
        return contacts, heights

    def _publish_measurements(self, now_ns: int, step, header) -> None:
        """Publish what the core measured beyond the state (nothing here)."""

    # -- time ----------------------------------------------------------------------------------

    def _make_timer(self, rate_hz: float):
        # Owning time, the simulator is paced by the steady clock: its own ROS time is what it
        # publishes on /clock, and a timer on it would wait for itself.
        # (Under rclpy, Node.create_timer makes rclpy's own steady clock of it.)
        clock = Clock(clock_type=ClockType.STEADY_TIME) if self._owns_time else None
        return self.create_timer(1.0 / rate_hz, self.tick, clock=clock)

    def _stamp(self, stamp_ns: int):
        return self._new['Time'](*divmod(int(stamp_ns), 1_000_000_000))

    def _now_ns(self) -> int:
        if self._owns_time:
            return self._sim_ns
        return self._clock_ns()

    def _clock_ns(self) -> int:
        """The node clock's time [ns] (the runtime's ``Clock.now_ns`` skips building a Time)."""
        clock = self.get_clock()
        now_ns = getattr(clock, 'now_ns', None)
        return now_ns() if now_ns is not None else clock.now().nanoseconds

    # -- parameters ----------------------------------------------------------------------------

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        values = {name: getattr(self.params, name) for name in self.node_defaults()}
        for parameter in parameters:
            if parameter.name in values:
                values[parameter.name] = parameter.value
        try:
            params = self.Params.from_values(values)
            for fixed in self.FIXED_PARAMETERS:
                if getattr(params, fixed) != getattr(self.params, fixed):
                    raise ParameterError(f'{fixed} is fixed at start '
                                         f'({getattr(self.params, fixed)}); restart the node')
            params.simulation_settings()
        except GaitNodesError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if params.rate_hz != self.params.rate_hz:
            self.timer.cancel()
            self.timer = self._make_timer(params.rate_hz)
        self._apply_settings(params)
        self.monitor.ground_height_m = params.ground_height_m
        self._period_ns = int(round(1e9 / params.rate_hz))
        self._markers_period_ns = int(round(1e9 / params.markers_rate_hz))
        self._support_source = None  # the support's plane height may follow the ground
        if self.inputs is not None:
            self.inputs.timeout_s = params.stale_after_s
            self._inputs_quiet_ns = (0, 0)
        self.params = params
        return SetParametersResult(successful=True)

    # -- inputs --------------------------------------------------------------------------------

    def _on_joint_commands(self, msg) -> None:
        if self.sources.refuses('/joint_commands'):
            return
        received_ns = self._now_ns()
        try:
            command = joint_trajectory_from_msg(msg, self.robot.joint_names)
        except ContractError as exc:
            self.diagnostics.drop('/joint_commands', str(exc))
            return
        self._follow(command, received_ns)
        self._last_command_ns = received_ns
        if self.inputs is not None:
            self.inputs.heard('/joint_commands', received_ns)
            if self.inputs.stale:
                self._inputs_quiet_ns = (0, 0)  # fresh again: the verdict changes

    def _on_sources(self) -> None:
        """Refusing /joint_commands: hold the robot where its trajectory has it now."""
        self._inputs_quiet_ns = (0, 0)  # the verdict changes
        if self.sources.refused:
            now_ns = self._now_ns()
            held, _ = self.trajectory.sample(now_ns)
            self.trajectory.replace([now_ns], held[None, :], np.zeros((1, held.size)), now_ns)

    def _follow(self, command: JointTrajectoryCommand, received_ns: int) -> None:
        """Replace the held trajectory with ``command`` from its first point on.

        A trajectory of some joints only is completed as a joint_trajectory_controller does:
        the other joints hold their command at receipt, at zero velocity.
        """
        positions, velocities = command.positions_rad, command.velocities_rad_s
        if command.joint_names != self.robot.joint_names:
            held, _ = self.trajectory.sample(received_ns)
            count = len(command.times_from_start_ns)
            indices = [self._joint_index[name] for name in command.joint_names]
            full = np.repeat(held[None, :], count, axis=0)
            full[:, indices] = positions
            positions = full
            if velocities is not None:
                full = np.zeros_like(positions)
                full[:, indices] = velocities
                velocities = full
        self.trajectory.replace(command.times_ns(received_ns), positions, velocities,
                                received_ns)

    def _on_footsteps(self, msg) -> None:
        try:
            plan = footsteps_from_msg(msg)
            if set(plan.foot_names) != set(self.robot.foot_names):
                raise ContractError(f'feet {list(plan.foot_names)} are not the robot\'s '
                                    f'{list(self.robot.foot_names)}')
        except ContractError as exc:
            self.diagnostics.drop('/gait/footsteps', str(exc))
            return
        self._plan = plan
        self._plan_contacts = PlanContacts(
            plan, np.array([plan.foot_names.index(n) for n in self.robot.foot_names]))

    # -- tick ----------------------------------------------------------------------------------

    def tick(self) -> None:
        """Integrate one step, publish the state and the monitor's view of the previous tick."""
        period_ns = self._period_ns
        if self._owns_time:
            self._sim_ns += period_ns
            self._step(self._sim_ns, period_ns)
        else:
            for now_ns in self._grid_times_ns(period_ns):
                self._step(now_ns, period_ns)

    def _step(self, now_ns: int, period_ns: int) -> None:
        """One integration step at ``now_ns`` and everything published for it."""
        if self._clock_publisher is not None:
            clock = self._msg['Clock']()
            clock.clock = self._stamp(now_ns)
            self._clock_publisher.publish(clock)
        if self._started_ns is None:
            self._started_ns = now_ns
            self.inputs = InputWatchdog(
                ['/joint_commands'], self.params.stale_after_s, now_ns,
                holding='following the held trajectory, then holding its last point',
                sources=self.sources)
            if self._last_command_ns is not None:
                self.inputs.heard('/joint_commands', self._last_command_ns)
            q0 = self.simulation.q.copy()
            points = self.simulation.contact_points()
            self._history.extend([(now_ns - 2 * period_ns, q0, points, None),
                                  (now_ns - period_ns, q0, points, None)])
        previous_ns = self._history[-1][0]
        dt_s = (now_ns - previous_ns) * 1e-9 if now_ns > previous_ns else period_ns * 1e-9

        contacts, heights = self._plan_inputs(now_ns)
        trajectory = self.trajectory
        command, command_velocity = trajectory.sample(now_ns)
        trajectory.discard_before(now_ns)
        step = self.simulation.step(command, dt_s, contacts, command_velocity, heights)
        header = self._publish_state(now_ns, step.q, step.actuators)
        self._publish_measurements(now_ns, step, header)
        self._history.append((now_ns, step.q, step.contact_points_in_world, header))
        self._account(step)

        (t0, q0, _, _), (t1, q1, points1, header1), (t2, q2, _, _) = self._history
        # header1 None: the instant before the first step, whose configuration (the initial
        # one) was never published on /joint_states and /tf; its monitor sample would carry a
        # stamp that no joint state and no base pose has.
        if header1 is not None and t0 < t1 < t2:
            v, a = self._differences.at(q0, q1, q2, (t1 - t0) * 1e-9, (t2 - t1) * 1e-9)
            support = self._support_of(points1)
            state = self.monitor.evaluate(q1, v, a, support)
            self._publish_monitor(t1, header1, state, support)
            self._check_stability(t1, state)
        self._check_inputs(now_ns)
        if self._last_summary_ns is None:
            self._last_summary_ns = now_ns
        elif (now_ns - self._last_summary_ns) * 1e-9 >= self.params.diagnostics_period_s - 1e-9:
            self._publish_summary(now_ns)

    def _support_of(self, contact_points: np.ndarray) -> Support:
        """The monitor's :class:`Support` of the simulation's (F, 3) contact points."""
        if contact_points is not self._support_source:
            self._support = self.monitor.support(
                contact_points[np.isfinite(contact_points[:, 0])])
            self._support_source = contact_points
        return self._support

    def _grid_times_ns(self, period_ns: int) -> list[int]:
        """The grid instants this tick steps through: the next one, and any the timer missed.

        The grid is re-anchored to the clock when the clock went back or the timer starved for
        more than ``MAX_LAG_PERIODS``.
        """
        clock_ns = self._clock_ns()
        if not self._history:
            return [clock_ns]
        last_ns = self._history[-1][0]
        next_ns = last_ns + period_ns
        if clock_ns < last_ns or clock_ns - next_ns > MAX_LAG_PERIODS * period_ns:
            return [clock_ns]
        if clock_ns < next_ns + period_ns:
            return [next_ns]  # on time (every tick under inproc): no missed instant
        missed = (clock_ns - next_ns) // period_ns
        return [next_ns + k * period_ns for k in range(missed + 1)]

    def _account(self, step) -> None:
        window = self._window
        window.ticks += 1
        actuators = step.actuators
        if actuators.any_saturated:
            window.saturated_ticks += 1
            window.acceleration_saturated_ticks += bool(
                np.count_nonzero(actuators.acceleration_saturated))
            ratios = actuators.demanded_over_limit
            window.max_ratio = max(window.max_ratio, float(ratios.max()))
            for k in np.flatnonzero(actuators.saturated):
                name = self.robot.joint_names[k]
                window.saturated_joints[name] = max(window.saturated_joints.get(name, 0.0),
                                                    float(ratios[k]))
        if actuators.any_clamped:
            for k in np.flatnonzero(actuators.clamped_to_limits):
                window.clamped_joints.add(self.robot.joint_names[k])
        if step.slip_m > window.max_slip_m:
            window.max_slip_m = step.slip_m
        window.touch_downs += len(step.touched_down)

    # -- outputs -------------------------------------------------------------------------------

    # Messages are built in one constructor call each (the per-tick cost of this node is mostly
    # Python objects). Published messages are read-only (ROS 2's intra-process rule, which the
    # inproc runtime relies on): the stamp, the headers of one instant, the joint name list, the
    # support polygon (its Polygon message, while the contacts stay) and the markers' unchanging
    # parts are shared between messages rather than copied.

    def _publish_state(self, now_ns: int, q: np.ndarray, actuators: ActuatorStep):
        """Publish /joint_states and /tf; return the odom-frame header of ``now_ns``."""
        new = self._new
        stamp = self._stamp(now_ns)
        # Without continuous joints (cos, sin in q) the joint positions are q's as they were
        # integrated.
        positions = self.robot.joint_positions(q) if self._continuous_joints \
            else actuators.positions_rad
        self._joint_states.publish(new['JointState'](
            new['Header'](stamp, ''), self._joint_names,
            positions.tolist(), actuators.velocities_rad_s.tolist(),
            self._joint_efforts(actuators)))
        x, y, z, qx, qy, qz, qw = q[:7].tolist()
        header = new['Header'](stamp, WORLD_FRAME)
        transform = new['TransformStamped'](
            header, BASE_FRAME,
            new['Transform'](new['Vector3'](x, y, z), new['Quaternion'](qx, qy, qz, qw)))
        self._tf.publish(new['TFMessage']([transform]))
        return header

    def _joint_efforts(self, actuators) -> list:
        """The ``effort`` of /joint_states: none from a kinematic simulation."""
        return []

    def _publish_monitor(self, stamp_ns: int, header, state: ZmpState,
                         support: Support) -> None:
        """Publish the monitor's view of ``stamp_ns`` (``header``: its odom header)."""
        new = self._new
        zmp = state.zmp_in_world.tolist()
        zmp_finite = all(map(math.isfinite, zmp))
        com = state.com_in_world.tolist()
        if zmp_finite:
            self._zmp.publish(new['PointStamped'](header, new['Point'](*zmp)))
        self._com.publish(new['PointStamped'](header, new['Point'](*com)))
        polygon, outline = self._polygon_points(support)
        self._polygon.publish(new['PolygonStamped'](header, polygon))
        if self.params.publish_markers:
            # A visualization topic at a display's rate (markers_rate_hz), not the monitor's:
            # the samples whose stamps open a new markers period.
            slot = stamp_ns // self._markers_period_ns
            if slot != self._markers_slot:
                self._markers_slot = slot
                self._markers.publish(self._marker_array(
                    header, zmp if zmp_finite else None,
                    com if all(map(math.isfinite, com)) else None, outline))

    def _polygon_points(self, support: Support) -> tuple:
        """Polygon message and closed marker outline of the support polygon, once per support.

        At the height of the ZMP's plane [m].
        """
        if support is not self._polygon_support:
            point32, point = self._msg['Point32'], self._msg['Point']
            z = support.plane_height_m
            vertices = [point32(x=x, y=y, z=z) for x, y in support.polygon.tolist()]
            outline = [point(x=x, y=y, z=z) for x, y in support.polygon.tolist()]
            self._polygon_cache = (self._new['Polygon'](vertices), outline + outline[:1])
            self._polygon_support = support
        return self._polygon_cache

    def _marker_parts(self) -> dict:
        """The parts of the markers that never change, built once."""
        new = self._new
        return {
            'orientation': new['Quaternion'](0.0, 0.0, 0.0, 1.0),
            'origin': new['Pose'](new['Point'](0.0, 0.0, 0.0),
                                  new['Quaternion'](0.0, 0.0, 0.0, 1.0)),
            'lifetime': new['Duration'](0, 0),
            'texture': new['CompressedImage'](new['Header'](new['Time'](0, 0), ''), '', b''),
            'mesh_file': new['MeshFile']('', b''),
            'empty': [],
            # (scale, colour) of the ZMP and COM spheres and of the support polygon outline.
            0: (new['Vector3'](0.04, 0.04, 0.04), new['ColorRGBA'](1.0, 0.1, 0.1, 1.0)),
            1: (new['Vector3'](0.05, 0.05, 0.05), new['ColorRGBA'](0.1, 0.8, 0.1, 1.0)),
            2: (new['Vector3'](0.01, 0.0, 0.0), new['ColorRGBA'](0.2, 0.4, 1.0, 1.0)),
        }

    def _marker(self, header, marker_id: int, kind: int, action: int, pose, points: list):
        parts = self._marker_parts_cache
        scale, color = parts[marker_id]
        empty = parts['empty']
        return self._new['Marker'](
            header, SIMULATOR_NAMESPACE, marker_id, kind, action, pose, scale, color,
            parts['lifetime'], False, points, empty, '', parts['texture'], empty, '', '',
            parts['mesh_file'], False)

    def _marker_array(self, header, zmp: list | None, com: list | None, outline_points: list):
        """ZMP and COM spheres (deleted when not finite), support polygon outline."""
        marker_type, new = self._msg['Marker'], self._new
        parts = self._marker_parts_cache
        empty = parts['empty']
        markers = []
        for marker_id, xyz in enumerate((zmp, com)):
            if xyz is None:
                markers.append(self._marker(header, marker_id, marker_type.SPHERE,
                                            marker_type.DELETE, parts['origin'], empty))
            else:
                markers.append(self._marker(
                    header, marker_id, marker_type.SPHERE, marker_type.ADD,
                    new['Pose'](new['Point'](*xyz), parts['orientation']), empty))
        markers.append(self._marker(header, 2, marker_type.LINE_STRIP, marker_type.ADD,
                                    parts['origin'], outline_points))
        return new['MarkerArray'](markers)

    # -- diagnostics ---------------------------------------------------------------------------

    def _stability_values(self, stamp_ns: int, state: ZmpState) -> dict:
        return {'margin_m': state.margin_m, 'sample_stamp_ns': stamp_ns,
                'zmp_x_m': float(state.zmp_in_world[0]), 'zmp_y_m': float(state.zmp_in_world[1]),
                'com_x_m': float(state.com_in_world[0]), 'com_y_m': float(state.com_in_world[1]),
                'com_z_m': float(state.com_in_world[2]),
                'contacts': len(state.contact_points_in_world),
                'warn_margin_m': self.params.warn_margin_m}

    def _check_stability(self, stamp_ns: int, state: ZmpState) -> None:
        margin = state.margin_m
        level = ERROR if not margin >= 0.0 else WARN if margin < self.params.warn_margin_m \
            else OK
        window = self._window
        window.samples += 1
        window.samples_outside += level == ERROR
        window.samples_warn += level == WARN
        if margin < window.min_margin_m:  # min() without the call
            window.min_margin_m = margin
        if level != self._stability_level:
            self._stability_level = level
            self.diagnostics.report('stability', level, self._stability_message(level, state),
                                    self._stability_values(stamp_ns, state))

    def _stability_message(self, level: int, state: ZmpState) -> str:
        margin = state.margin_m
        if level == ERROR:
            if math.isfinite(margin):
                return f'ZMP outside the support polygon by {-margin:.4f} m'
            if not len(state.contact_points_in_world):
                return 'no foot in contact'
            return (f'vertical ground force {state.normal_force_n:.1f} N <= 0: the motion '
                    f'would lift the feet off the ground (ZMP undefined)')
        if level == WARN:
            return (f'ZMP {margin:.4f} m inside the support polygon '
                    f'(< {self.params.warn_margin_m} m)')
        return f'ZMP {margin:.4f} m inside the support polygon'

    def _check_inputs(self, now_ns: int) -> None:
        # The watchdog's verdict changes only when a command arrives while it is stale (which
        # ends the quiet interval), time goes back, or the last command ages past
        # stale_after_s: until a microsecond before that, update() would answer "unchanged"
        # and is not asked.
        checked_ns, quiet_until_ns = self._inputs_quiet_ns
        if checked_ns <= now_ns < quiet_until_ns:
            return
        if self.inputs.update(now_ns):
            self.diagnostics.publish([self._input_status(now_ns)])
        if self.inputs.stale:
            self._inputs_quiet_ns = (now_ns, math.inf)
        else:
            last_ns = self._last_command_ns if self._last_command_ns is not None \
                else self._started_ns
            self._inputs_quiet_ns = (
                now_ns, last_ns + int(self.params.stale_after_s * 1e9) - 1_000)

    def _input_status(self, now_ns: int):
        aspect, level, message, values = self.inputs.status(now_ns)
        values.update({'joint_commands_age_s': self.inputs.age_s('/joint_commands', now_ns),
                       'footstep_plan': 'yes' if self._plan is not None else 'no (contacts by '
                       'foot height)',
                       'dropped': ','.join(f'{t}:{n}'
                                           for t, n in self.diagnostics.dropped.items())})
        if level == OK and not self.inputs.ever_heard('/joint_commands'):
            message = 'waiting for /joint_commands'
        return aspect, level, message, values

    def _publish_summary(self, now_ns: int) -> None:
        window, self._window = self._window, self._new_window()
        self._last_summary_ns = now_ns
        statuses = self._summary_statuses(window)
        statuses.append(self._input_status(now_ns))
        self.diagnostics.publish(statuses)

    def _new_window(self):
        """A fresh record of what happens until the next summary."""
        return _Window()

    def _stability_summary(self, window) -> list:
        """The 'stability summary' status of the window's monitor samples (none without)."""
        statuses = []
        if window.samples:
            level = ERROR if window.samples_outside else WARN if window.samples_warn else OK
            statuses.append((
                'stability summary', level,
                f'least margin {window.min_margin_m:.4f} m over {window.samples} samples, '
                f'{window.samples_outside} outside the support polygon',
                {'min_margin_m': window.min_margin_m, 'samples': window.samples,
                 'samples_outside': window.samples_outside,
                 'samples_below_warn': window.samples_warn,
                 'warn_margin_m': self.params.warn_margin_m}))
        return statuses

    def _summary_statuses(self, window) -> list:
        """Every status of the periodic summary but the inputs'."""
        statuses = self._stability_summary(window)
        joints = sorted(window.saturated_joints, key=lambda j: -window.saturated_joints[j])
        # The aspect keeps its name ('velocity saturation'); it counts the ticks where a joint
        # lagged its command at its velocity or its acceleration limit.
        statuses.append((
            'velocity saturation', WARN if window.saturated_ticks else OK,
            (f'{window.saturated_ticks} of {window.ticks} ticks saturated '
             f'({window.acceleration_saturated_ticks} at an acceleration limit), commands up to '
             f'{window.max_ratio:.4g}x the limit: {", ".join(joints)}')
            if window.saturated_ticks else 'joint velocities and accelerations within limits',
            {'saturated_ticks': window.saturated_ticks, 'ticks': window.ticks,
             'acceleration_saturated_ticks': window.acceleration_saturated_ticks,
             'max_demanded_over_limit': window.max_ratio, 'joints': ','.join(joints),
             'clamped_to_position_limits': ','.join(sorted(window.clamped_joints))}))
        statuses.append((
            'contacts', OK, f'{window.touch_downs} touch-downs, stance feet slip up to '
            f'{window.max_slip_m:.2e} m',
            {'touch_downs': window.touch_downs, 'max_slip_m': window.max_slip_m,
             'contacts': ','.join(n for n, down in zip(self.robot.foot_names,
                                                       self.simulation.contacts, strict=True)
                                  if down)}))
        return statuses


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.kinematic_simulator [--ros-args ...]``."""
    return run_node(lambda options: KinematicSimulator(), args,
                    prog='python -m gait_nodes.kinematic_simulator',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
