"""footstep_planner node: footsteps, contact schedule and ZMP reference, driven online.

Subscribes ``/cmd_vel`` (geometry_msgs/Twist) and ``/gait/command`` (std_msgs/String, JSON, schema
``msgs_schema/gait_command.schema.json``). Publishes ``/gait/footsteps`` (latched, whenever the
plan changes), ``/gait/zmp_reference`` (the next ``zmp_horizon_s``, 2.5 s, every tick:
``rate_hz``, 10 Hz; the horizon covers the COM controller's ``preview_s + horizon_s`` and one
publication period, so that a late reference is ridden through), ``/gait/command_status`` (one
JSON answer per command) and ``/diagnostics``.

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
the robot's measured state (/tf odom -> base_link and /joint_states, forward kinematics of the
robot model: footholds, foot yaws, COM) and plans from there: the first steps start from the
actual footholds and the ZMP reference from the measured COM. A robot still finishing the steps
of the planner it replaces (a foot in the air, the base moving) is waited for up to
``STAND_WAIT_S``; a foot still in the air then is put down first (a landing swing straight down,
:class:`gait_nodes.planning.footsteps.MeasuredStart`). Without /joint_states (or a robot model
without kinematics) the feet start at their nominal places under the /tf base pose.

Pause: outside inproc the planner follows the stale-input reports of the nodes that move the
robot (``whole_body_ik: inputs`` naming /gait/com_reference, ``kinematic_simulator: inputs``
naming /joint_commands). While one of them reports its input stale during a walk, the robot is
held where it stands, so the plan must not run on in time: the planner pauses (WARN, ``footstep_
planner: walk``), publishes a plan that holds the measured footholds (a foot in the air held where
it is) with the ZMP reference on the measured COM, and once every report is OK again for
``RESUME_AFTER_S`` it plans anew from the robot's measured state and walks on (OK). The planner
also checks that each planned swing gets its /gait/swing_trajectory: one missing when its foot
lifts off (the swing-leg policy is down; the whole-body IK follows its fallback swing) is reported
as a stale input (WARN, ``footstep_planner: inputs``) until the next one arrives.

Failures: a plan that cannot be made (a swing beyond the limbs' reach, any failure of the
planning core) ends the walk in a safe stand, not the process (:mod:`gait_nodes.faults`): no
foot lifts off any more (a swing in the air lands where it was going), the ZMP reference moves
to the stand point of the feet, inside their support polygon, and an ERROR (``footstep_planner:
faults``) names the reason. The planner plans again ``RETRY_AFTER_S`` later, or at once on a new
velocity, from the stance it stands in (as from a measured start: no first step beyond a
stride), and reports OK once it has. A failure to resume a paused walk keeps it paused; the
resume is tried again with the next fresh measured state.

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

import bisect
import itertools
import json
import math
import sys

import numpy as np

from gait_nodes.cli import run_node
from gait_nodes.contract import (
    WORLD_FRAME,
    ContractError,
    FootstepPlan,
    ZmpReference,
    ZmpReferenceMessages,
    footsteps_to_msg,
    swing_trajectory_from_msg,
)
from gait_nodes.diagnostics import OK, WARN, DiagnosticsReporter, level_value
from gait_nodes.errors import GaitNodesError, GaitParameterError, ParameterError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.interfaces import get_message
from gait_nodes.paths import node_defaults
from gait_nodes.planning.footsteps import (
    GaitPlanner,
    MeasuredStart,
    Twist2D,
    centred_pose,
    place,
)
from gait_nodes.planning.gait_params import (
    NUMERIC_RANGES,
    GaitParameters,
    parameters_from_mapping,
    parse_command,
)
from gait_nodes.planning.terrain import STAIRS_DEFAULTS, Staircase, check_walkable
from gait_nodes.robot.description import load_robot_description
from gait_nodes.runtime import Parameter, SetParametersResult, qos_profile_latched
from gait_nodes.watchdog import InputWatchdog

NODE_NAME = 'footstep_planner'
GAIT_FIELDS = tuple(GaitParameters.__dataclass_fields__)
#: Node settings: name -> (lowest, lowest included?, highest included, unit).
NODE_SETTINGS = {'rate_hz': (0.01, True, 1000.0, 'Hz'), 'zmp_horizon_s': (1.6, True, 60.0, 's'),
                 'zmp_sample_period_s': (0.0, False, 0.1, 's'),
                 'cmd_vel_timeout_s': (0.0, True, 60.0, 's')}
#: Most samples in one /gait/zmp_reference.
MAX_ZMP_SAMPLES = 20000
#: A clock jump larger than this [s] restarts the plan from standstill.
CLOCK_JUMP_S = 10.0
NS_PER_S = 1_000_000_000
#: Longest wait of a planner started into a running graph for the robot's pose on /tf [s].
JOIN_WAIT_S = 1.0
#: Longest wait of a planner started into a running walk for the robot to stand still [s].
STAND_WAIT_S = 6.0
#: The robot stands still when its base moved less than this over STILL_S [m] (5 mm/s: the
#: COM controller still settling on a held reference is standing; a weight shift is not).
STILL_M = 1e-3
STILL_S = 0.2
#: A measured foot this close to its nominal foothold is planned from the nominal one [m].
NOMINAL_SNAP_M = 1e-3
#: A foot higher than this above the ground is in the air [m].
AIRBORNE_M = 0.005
#: Status on /diagnostics -> the input whose loss holds the robot still.
DEPENDENCIES = {'whole_body_ik: inputs': '/gait/com_reference',
                'kinematic_simulator: inputs': '/joint_commands'}
#: Every dependency OK again for this long before a paused walk resumes [s].
RESUME_AFTER_S = 0.5
#: A planned swing with no /gait/swing_trajectory this long after its lift-off is missed [s].
SWING_GRACE_S = 0.05
#: A swing trajectory lifting off this close to a planned swing's lift-off is its own [ns].
SAME_LIFT_OFF_NS = 1000
SWING_TOPIC = '/gait/swing_trajectory'
#: After a planning failure the plan stands still this long before it is tried again [s].
RETRY_AFTER_S = 1.0
#: Characters of a /gait/command (and of the reason it was refused) echoed in the answer.
ECHO_CHARACTERS = 500


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


class MeasuredState:
    """The robot's measured state: /tf base pose and /joint_states, by forward kinematics.

    Args:
        model: The robot model (:class:`gait_nodes.robot.model.RobotModel`).
    """

    def __init__(self, model):
        self.model = model
        self._joints = np.array(model.joint_positions(model.configuration((0, 0, 0), 0.0)))
        self._base: np.ndarray | None = None
        self.base_ns: int | None = None
        self.joints_ns: int | None = None
        self.history: list[tuple[int, float, float]] = []  # (received [ns], x, y) of the base

    def on_base(self, pose: np.ndarray, now_ns: int) -> None:
        """Base pose (x, y, z, qx, qy, qz, qw) in odom received at ``now_ns``."""
        self._base, self.base_ns = pose, now_ns
        self.history.append((now_ns, float(pose[0]), float(pose[1])))
        del self.history[:-64]

    def on_joints(self, names, positions, now_ns: int) -> None:
        """Joint positions received at ``now_ns`` (unknown names raise GaitNodesError)."""
        self._joints[self.model.indices(list(names))] = positions
        self.joints_ns = now_ns

    def since(self, now_ns: int) -> bool:
        """Whether both the base pose and the joints were received at or after ``now_ns``."""
        return (self.base_ns is not None and self.joints_ns is not None
                and min(self.base_ns, self.joints_ns) >= now_ns)

    def base_pose(self) -> tuple[float, float, float] | None:
        """(x, y, yaw) of the base in odom, or None."""
        if self._base is None:
            return None
        x, y, _, qx, qy, qz, qw = self._base
        return (float(x), float(y), math.atan2(2.0 * (qw * qz + qx * qy),
                                               1.0 - 2.0 * (qy * qy + qz * qz)))

    def still(self, now_ns: int) -> bool:
        """Whether the base moved less than STILL_M over the last STILL_S."""
        recent = [(t, x, y) for t, x, y in self.history if (now_ns - t) * 1e-9 <= STILL_S]
        if not recent or (now_ns - recent[0][0]) * 1e-9 < 0.5 * STILL_S:
            return False
        xy = np.array([(x, y) for _, x, y in recent])
        return bool(np.ptp(xy, axis=0).max() < STILL_M) if len(xy) > 1 else False

    def measure(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, 3) footholds, (F,) foot yaws [rad], (3,) COM in odom [m], feet in YAML order."""
        q = np.array(self.model.configuration((0.0, 0.0, 0.0), 0.0, self._joints))
        q[:7] = self._base
        feet, yaws = self.model.foot_poses(q)
        return feet, yaws, self.model.com(q)


def measured_start(feet: np.ndarray, yaws: np.ndarray, com: np.ndarray,
                   nominal: np.ndarray, nominal_yaws: np.ndarray, stand_zmp: np.ndarray,
                   ground_height_m: float | np.ndarray = 0.0) -> MeasuredStart | None:
    """The start of a plan from measured feet and COM (None: standing at the nominal stance).

    A foot on the ground within NOMINAL_SNAP_M of its nominal foothold is planned from that
    foothold (the measurement is not the plan's exact number); when every foot is and the COM is
    that close to the stance's ZMP, the plan starts as from standstill (None).

    Args:
        feet: (F, 3) measured footholds [m].
        yaws: (F,) measured foot yaws [rad].
        com: (3,) measured COM [m]: the ZMP reference starts under it.
        nominal: (F, 2) nominal footholds under the base [m].
        nominal_yaws: (F,) their yaws [rad].
        stand_zmp: (2,) ZMP of the nominal stance [m].
        ground_height_m: Ground height in odom under each foot [m]: one number, or (F,).
    """
    feet = np.array(feet, dtype=float)
    yaws = np.array(yaws, dtype=float)
    on_ground = feet[:, 2] - ground_height_m <= AIRBORNE_M
    close = on_ground & (np.linalg.norm(feet[:, :2] - nominal, axis=1) < NOMINAL_SNAP_M)
    zmp = np.asarray(com, dtype=float)[:2]
    if close.all() and np.linalg.norm(zmp - stand_zmp) < NOMINAL_SNAP_M:
        return None
    feet[close, :2] = nominal[close]
    ground = np.broadcast_to(np.asarray(ground_height_m, dtype=float), on_ground.shape)
    feet[close, 2] = ground[close]
    yaws[close] = nominal_yaws[close]
    return MeasuredStart(feet, yaws, zmp, ground_height_m, AIRBORNE_M)


class FootstepPlanner(GuardedNode):
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
        self.faults = FaultGuard(self, self.diagnostics, hold=self._hold,
                                 recovered=self._recovered)
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
        self._measured: MeasuredState | None = None
        self._measured_subscriptions: list = []
        self._dependencies: dict[str, bool] = {}
        self._dependencies_fresh: set[str] = set()  # reported their inputs fresh at least once
        # Reported stale since the last tick: a stale spell shorter than the planner's period
        # (stale, then fresh again between two 10 Hz ticks) still pauses the walk.
        self._stale_since_tick: set[str] = set()
        self._pause: dict | None = None
        self._join_start_ns: int | None = None
        self._swings_heard: set[tuple[str, int]] = set()
        self._swings_checked: set[tuple[str, int]] = set()
        self._swings_pruned_ns = -NS_PER_S
        self.swing_inputs = InputWatchdog([], 1.0, self.origin_ns, events=[SWING_TOPIC],
                                          holding='the whole-body IK follows its fallback swing')
        self._last_now_s = 0.0
        self._pending: tuple[GaitParameters, dict, Staircase] | None = None
        self._last_plan = None
        self._within = _HorizonCut()
        self._swing_lifts: tuple = (None, [])  # (plan, [(foot, lift-off [ns])])
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
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 SWING_TOPIC, self.on_swing, 10)
        if self.context.runtime != 'inproc':
            self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                     '/diagnostics', self.on_diagnostics, 50)
        if not self._joined:
            self._listen(True)
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
        """Keep the robot's base pose (joining or paused: the measured state)."""
        for transform in msg.transforms:
            if transform.header.frame_id.lstrip('/') == WORLD_FRAME and \
                    transform.child_frame_id.lstrip('/') == 'base_link':
                t, r = transform.transform.translation, transform.transform.rotation
                pose = np.array([t.x, t.y, t.z, r.x, r.y, r.z, r.w], dtype=float)
                if not np.isfinite(pose).all() or np.linalg.norm(pose[3:]) < 0.5:
                    continue
                pose[3:] /= np.linalg.norm(pose[3:])
                yaw = math.atan2(2.0 * (r.w * r.z + r.x * r.y), 1.0 - 2.0 * (r.y ** 2 + r.z ** 2))
                self._base_pose = (float(t.x), float(t.y), yaw)
                if self._measured is not None:
                    self._measured.on_base(pose, self.get_clock().now().nanoseconds)
                    self._hold_once_measured()

    def on_joint_states(self, msg) -> None:
        """Keep the robot's joint positions (joining or paused: the measured state)."""
        if self._measured is None:
            return
        positions = np.array(msg.position, dtype=float)
        if len(positions) != len(msg.name) or not np.isfinite(positions).all():
            return
        try:
            self._measured.on_joints(msg.name, positions, self.get_clock().now().nanoseconds)
        except (GaitNodesError, ValueError):
            return
        self._hold_once_measured()

    def _hold_once_measured(self) -> None:
        """Paused: publish the hold as soon as the robot's state is measured, not at the tick.

        (At 10 Hz the node that was starved may be back before the next tick, and follow the
        walking plan a tick long before the hold comes.)
        """
        pause = self._pause
        if pause is not None and pause['hold'] is None \
                and self._measured.since(pause['since_ns']):
            self.tick()

    def _listen(self, on: bool) -> None:
        """Subscribe to the robot's measured state (/tf, /joint_states) or stop."""
        if on and not self._measured_subscriptions:
            if self._measured is None:
                model = self._model()
                if model is not None:
                    self._measured = MeasuredState(model)
            self._measured_subscriptions = [
                self.create_subscription(get_message('tf2_msgs/msg/TFMessage'), '/tf',
                                         self.on_tf, 100),
                self.create_subscription(get_message('sensor_msgs/msg/JointState'),
                                         '/joint_states', self.on_joint_states, 10)]
        elif not on:
            for subscription in self._measured_subscriptions:
                self.destroy_subscription(subscription)
            self._measured_subscriptions = []

    def _model(self):
        """The robot model for forward kinematics, or None (a robot without one)."""
        if self._robot_model is None:
            from gait_nodes.robot.model import load_robot_model

            try:
                self._robot_model = load_robot_model(str(self.robot.path))
            except GaitNodesError as exc:
                self.get_logger().warning(f'no forward kinematics ({exc}): a rejoining planner '
                                          f'starts the feet at their nominal places')
                return None
        return self._robot_model

    def _start(self, now_ns: int) -> MeasuredStart | None:
        """The measured state to plan from (None: nominal stance under the base pose)."""
        measured = self._measured
        if measured is None or measured.joints_ns is None or measured.base_ns is None:
            return None
        feet, yaws, com = measured.measure()
        pose = np.array(measured.base_pose())
        params = self.planner.params
        nominal = place(pose, self.planner.layout.offsets(params.step_width_m))
        from gait_nodes.planning.zmp_reference import stand_point

        return measured_start(feet, yaws, com, nominal, np.full(len(nominal), pose[2]),
                              stand_point(self.planner.layout, nominal),
                              self.planner.terrain.height_at(feet[:, 0]))

    def _plan_from_robot(self, now_ns: int) -> None:
        """Start a new plan at ``now_ns`` from the robot's measured state (or its base pose)."""
        twist = self.planner.requested_twist
        start = self._start(now_ns)
        pose = self._measured.base_pose() if self._measured is not None \
            and self._measured.base_ns is not None else self._base_pose
        if start is not None:
            # The walk's path starts where the footholds are centred, with the base's yaw: the
            # base itself may lean off them (the IK keeps the COM where the reference was).
            pose = tuple(float(v) for v in centred_pose(
                start.feet_in_world, self.planner.layout.offsets(self.planner.params.step_width_m),
                pose[2]))
        self.planner = GaitPlanner(self.robot, self.planner.params, base_pose=pose,
                                   swing_timing=self.planner.swing_timing, start=start,
                                   terrain=self.planner.terrain)
        self.origin_ns, self._last_now_s = now_ns, 0.0
        self.planner.set_velocity(twist, 0.0)
        where = 'its nominal stance' if start is None else (
            f'the measured footholds, ZMP at {np.round(start.zmp_in_world, 4).tolist()}'
            + (f', landing {[self.robot.foot_names[f] for f in np.flatnonzero(start.airborne())]}'
               if start.airborne().any() else ''))
        self.get_logger().info(f'planning from the robot\'s pose {pose}: {where}')

    def _join(self, now_ns: int) -> bool:
        """Whether the planner may plan: it knows where the robot is, or waited long enough.

        The robot still finishing the steps of the planner this one replaces (a foot in the
        air, the base moving) is waited for up to STAND_WAIT_S.
        """
        if self._join_start_ns is None:
            self._join_start_ns = now_ns  # the wait counts from the first tick, after the setup
        waited_s = (now_ns - self._join_start_ns) * 1e-9
        measured = self._measured
        if measured is not None and measured.since(self.origin_ns):
            if waited_s < STAND_WAIT_S:
                feet, _, _ = measured.measure()
                ground = self.planner.terrain.height_at(feet[:, 0])
                if (feet[:, 2] - ground > AIRBORNE_M).any() or not measured.still(now_ns):
                    return False
        elif self._base_pose is None and waited_s < JOIN_WAIT_S:
            return False
        elif measured is not None and self._base_pose is not None and waited_s < JOIN_WAIT_S:
            return False  # the pose, not the joints yet
        if self._base_pose is not None:
            self._plan_from_robot(now_ns)
        self._joined = True
        self._listen(False)
        return True

    # --- pause while the robot is held ---------------------------------------------------------

    def on_diagnostics(self, msg) -> None:
        """Follow the stale-input reports of the nodes that move the robot.

        A report that holds the robot while it walks pauses the walk at once, not at the next
        tick (up to 0.1 s later at 10 Hz: the held robot's plan would run on that long).
        """
        newly_stale = False
        for status in msg.status:
            topic = DEPENDENCIES.get(status.name)
            if topic is None:
                continue
            stale = next((v.value for v in status.values if v.key == 'stale'), '')
            is_stale = level_value(status.level) >= WARN and topic in stale.split(',')
            if not is_stale:
                self._dependencies_fresh.add(status.name)
            # A node still waiting for its first input (the graph starting: the IK has no COM
            # reference before this planner's first plan) holds nothing that a pause would save.
            self._dependencies[status.name] = is_stale and \
                status.name in self._dependencies_fresh
            if self._dependencies[status.name]:
                newly_stale |= status.name not in self._stale_since_tick
                self._stale_since_tick.add(status.name)
        if newly_stale and self._pause is None and self._joined:
            self.tick()

    def _in_motion(self, now_s: float) -> bool:
        return not self.planner.twist.is_zero() or any(
            step.slots and step.end_s > now_s for step in self.planner.steps)

    def _paused(self, now_ns: int, now_s: float) -> bool:
        """Pause, hold and resume (see the module docstring); True while paused."""
        stale = sorted({name for name, is_stale in self._dependencies.items() if is_stale}
                       | self._stale_since_tick)
        self._stale_since_tick = set()
        pause = self._pause
        if pause is None:
            if not stale or not self._in_motion(now_s):
                return False
            zmp = self.planner.zmp(np.array([now_s]))[0]
            pause = self._pause = {'since_ns': now_ns, 'hold': None, 'zmp': zmp,
                                   'fresh_ns': None}
            self._listen(True)
            self.diagnostics.report('walk', WARN, f'paused: {", ".join(stale)} stale; holding '
                                    f'the robot where it stands', {'stale': ','.join(stale)})
        if pause['hold'] is None and self._measured is not None \
                and self._measured.since(pause['since_ns']):
            feet, yaws, com = self._measured.measure()
            pause['hold'] = (feet, yaws)
            pause['zmp'] = com[:2]
            order = [self.robot.foot_names.index(n) for n in self.planner.layout.names]
            plan = FootstepPlan(now_ns, self.planner.layout.names, np.zeros(1),
                                feet[order][None], yaws[order][None])
            self.footsteps_publisher.publish(footsteps_to_msg(plan))
            self._last_plan = None
        horizon = self.settings['zmp_horizon_s']
        period_ns = int(round(self.settings['zmp_sample_period_s'] * NS_PER_S))
        count = int(math.ceil(horizon * NS_PER_S / period_ns - 1e-9)) + 1
        stamps = now_ns + period_ns * np.arange(count, dtype=np.int64)
        # On the plane of the lowest held foot (a foot held in the air is not a contact).
        plane = None
        if pause['hold'] is not None:
            held = pause['hold'][0][:, 2]
            ground = held[held - self.planner.terrain.height_at(pause['hold'][0][:, 0])
                          <= AIRBORNE_M]
            plane = np.full(count, float(ground.min() if len(ground) else held.min()))
        self.zmp_publisher.publish(self._zmp_messages.to_msg(
            ZmpReference(stamps, np.tile(pause['zmp'], (count, 1)), plane).corners()))
        if stale:
            pause['fresh_ns'] = None
            return True
        if pause['fresh_ns'] is None:
            pause['fresh_ns'] = now_ns
        if (now_ns - pause['fresh_ns']) * 1e-9 < RESUME_AFTER_S:
            return True
        if pause['hold'] is not None and not self._measured.since(pause['fresh_ns']):
            return True
        held_s = (now_ns - pause['since_ns']) * 1e-9
        if pause['hold'] is not None:
            self._plan_from_robot(now_ns)  # (if this fails, the walk stays paused)
        self._pause = None
        self._listen(False)
        self.diagnostics.report('walk', OK, f'walking on after a pause of {held_s:.2f} s, '
                                f'planned from the robot\'s measured state',
                                {'paused_s': held_s})
        return False

    # --- failures ------------------------------------------------------------------------------

    def _hold(self, exc: Exception) -> str:
        """After a failure (see the module docstring): what the planner holds."""
        now_ns, now_s = self.now_s()
        if self._pause is not None:
            self._pause['fresh_ns'] = now_ns
            return 'the walk stays paused, the robot held where it stands; resuming again later'
        if not self._joined:
            return 'not planning yet; joining again at the next tick'
        self.planner.stand(now_s, self.settings['zmp_horizon_s']
                           + self.planner.params.step_period_s + RETRY_AFTER_S)
        self._last_plan = None
        return (f'stopped at a safe stand (no foot lifts off, the ZMP to the stand point of '
                f'the feet); planning again in {RETRY_AFTER_S:g} s or at a new velocity')

    def _recovered(self) -> bool:
        return self._pause is None and not self.planner.halted

    # --- swing trajectories --------------------------------------------------------------------

    def on_swing(self, msg) -> None:
        """Note the swing trajectory of a planned swing (see :meth:`_check_swings`)."""
        try:
            trajectory = swing_trajectory_from_msg(msg)
        except ContractError:
            return  # the whole-body IK reports malformed swings
        self._swings_heard.add((trajectory.foot, int(trajectory.start_ns)))
        self.swing_inputs.heard(SWING_TOPIC, self.get_clock().now().nanoseconds)

    def _check_swings(self, plan, now_ns: int) -> None:
        """A planned swing that lifted off without its trajectory: the swing policy is down."""
        grace_ns = int(SWING_GRACE_S * NS_PER_S)
        if plan is not self._swing_lifts[0]:
            self._swing_lifts = (plan, [
                (swing.foot, plan.start_ns + int(round(swing.lift_off_s * NS_PER_S)))
                for swing in plan.swings()])
        for key in self._swing_lifts[1]:
            foot, lift_ns = key
            if key in self._swings_checked or not lift_ns + grace_ns <= now_ns:
                continue
            self._swings_checked.add(key)
            # (the policy works the lift-off out from the plan message it got, whose start
            # may differ from this plan's: the same instant can come out a nanosecond apart)
            heard = key in self._swings_heard or any(
                f == foot and abs(t - lift_ns) <= SAME_LIFT_OFF_NS for f, t in self._swings_heard)
            if not heard and now_ns - lift_ns < 2 * grace_ns + NS_PER_S:
                self.swing_inputs.missed(SWING_TOPIC, f'the swing of {foot} lifting off '
                                                      f'at {lift_ns * 1e-9:.3f} s')
        if not 0 <= now_ns - self._swings_pruned_ns < NS_PER_S:
            # Swings a minute old forgotten, once a second (what is kept longer is never asked:
            # a swing that old is past its checks).
            old = now_ns - 60 * NS_PER_S
            self._swings_checked = {k for k in self._swings_checked if k[1] > old}
            self._swings_heard = {k for k in self._swings_heard if k[1] > old}
            self._swings_pruned_ns = now_ns
        if self.swing_inputs.update(now_ns):
            aspect, level, message, values = self.swing_inputs.status(now_ns)
            self.diagnostics.report('swing inputs', level, message if level != OK else
                                    f'a swing trajectory for every swing: {SWING_TOPIC}', values)

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
        parameters = [Parameter(name, value=value) for name, value in changes.items()]
        result = (self.set_parameters_atomically(parameters) if parameters
                  else SetParametersResult(successful=True))
        self._answer(msg.data, result.successful,
                     result.reason if not result.successful else 'accepted')

    def _answer(self, command: str, accepted: bool, reason: str) -> None:
        command, reason = _shortened(command), _shortened(reason)
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
        if not self._joined:
            if not self._join(now_ns):
                return
            now_ns, now_s = self.now_s()
        now_s = self._restart_if_clock_jumped(now_ns, now_s)
        self._last_now_s = now_s
        self._check_cmd_vel(now_ns, now_s)
        origin_ns, pause = self.origin_ns, self._pause
        if self._paused(now_ns, now_s):
            return
        if pause is not None or origin_ns != self.origin_ns:  # resumed: the time read anew
            now_ns, now_s = self.now_s()
        horizon = self.settings['zmp_horizon_s']
        self.planner.advance(now_s + horizon + self.planner.params.step_period_s)
        self.planner.prune(now_s)
        plan = self._within(self.planner.footstep_plan(now_s, self.origin_ns), now_ns,
                            now_ns + int(horizon * NS_PER_S))
        if self._last_plan is None or not _same_plan(plan, self._last_plan):
            self.footsteps_publisher.publish(footsteps_to_msg(plan))
            self._last_plan = plan
        self._check_swings(plan, now_ns)
        reference = self.planner.zmp_reference(now_ns, self.origin_ns, horizon,
                                               self.settings['zmp_sample_period_s'])
        # Its corners only: the consumers interpolate linearly between the poses.
        self.zmp_publisher.publish(self._zmp_messages.to_msg(reference.corners()))

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


class _HorizonCut:
    """``plan`` up to its last contact change by ``until_ns`` with every foot down.

    The published footsteps reach no further than the ZMP reference: if the planner stops, the
    whole-body IK ends the walk with the feet down where the COM controller, which holds the
    reference's end, keeps the robot balanced (not with steps the ZMP reference never covered).
    A swing that lifts off by ``until_ns`` is always kept to its landing.

    What depends on the plan alone is worked out once per plan object (the planner hands out
    the same one while its plan does not change), and so is each cut of it.
    """

    def __init__(self):
        self._plan = None
        self._lifts_s: list[float] = []  # the swings' lift-offs, sorted [s]
        self._landings_s: list[float] = []  # latest touch-down of the swings up to each lift
        self._times_ns: list[int] = []
        self._last_down: list[int] = []  # last point up to each with every foot down
        self._cuts: dict[int, FootstepPlan] = {}

    def __call__(self, plan: FootstepPlan, now_ns: int, until_ns: int) -> FootstepPlan:
        if plan is not self._plan:
            swings = sorted((s.lift_off_s, s.touch_down_s) for s in plan.swings())
            self._lifts_s = [lift for lift, _ in swings]
            self._landings_s = list(itertools.accumulate((touch for _, touch in swings), max))
            # (the plan's times never decrease: the points up to a time are a leading run)
            self._times_ns = (plan.start_ns + np.round(plan.times_s * NS_PER_S).astype(
                np.int64)).tolist()
            self._last_down, last = [], 0
            for k, t_s in enumerate(plan.times_s.tolist()):
                if not any(lift < t_s < touch for lift, touch in swings):
                    last = k
                self._last_down.append(last)
            self._plan, self._cuts = plan, {}
        now_s = (now_ns - plan.start_ns) * 1e-9
        until_s = max(now_s, (until_ns - plan.start_ns) * 1e-9)
        # Every swing lifting off within the horizon goes out whole: a swing longer than the
        # horizon (the crawl's value-table swings) must reach the IK before its lift-off.
        lifted = bisect.bisect_right(self._lifts_s, until_s)
        landing_s = self._landings_s[lifted - 1] if lifted else 0.0
        until_ns = max(until_ns, plan.start_ns + int(round(landing_s * NS_PER_S)))
        reached = bisect.bisect_right(self._times_ns, until_ns)
        last = self._last_down[reached - 1] if reached else 0
        if last == len(plan.times_s) - 1:
            return plan
        if last not in self._cuts:
            self._cuts[last] = FootstepPlan(
                plan.start_ns, plan.foot_names, plan.times_s[:last + 1],
                plan.positions_in_world[:last + 1], plan.yaws_rad[:last + 1])
        return self._cuts[last]


def _shortened(text: str) -> str:
    """``text``, cut to ``ECHO_CHARACTERS`` with its length said when longer."""
    if len(text) <= ECHO_CHARACTERS:
        return text
    return f'{text[:ECHO_CHARACTERS]}... ({len(text)} characters)'


def _same_plan(a, b) -> bool:
    return a is b or (a.start_ns == b.start_ns and a.foot_names == b.foot_names
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
