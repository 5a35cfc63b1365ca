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
import functools
import itertools
import json
import math
import sys

import numpy as np

from gait_nodes import callback_times
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
    command_id_of,
    parameters_from_mapping,
    parse_gait_command,
)
from gait_nodes.planning.online import (
    ACCEPTED,
    REJECTED,
    UNCHANGED,
    Answer,
    Changed,
    ChangeRefused,
    Failure,
    OnlinePlanner,
    Replaced,
    VelocityApplied,
)
from gait_nodes.planning.terrain import STAIRS_DEFAULTS, Staircase, check_walkable
from gait_nodes.robot.description import load_robot_description
from gait_nodes.runtime import Parameter, SetParametersResult, qos_profile_latched
from gait_nodes.single_source import SingleSource
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
        self._timings: dict = {}  # (swing, step height) -> (model, reason, final): the worker's
        timing, self._timing_reason, self._timing_final = self._swing_timing(params)
        planner = GaitPlanner(self.robot, params, swing_timing=timing, terrain=terrain)
        self.diagnostics.report('timing', OK if self._timing_final else WARN,
                                self._timing_reason)
        self.inputs = InputWatchdog(['/cmd_vel'], self.settings['cmd_vel_timeout_s'] or 1.0,
                                    self.origin_ns, holding='stopping (zero velocity from the '
                                    'next step boundary)')
        self.sources = SingleSource(self, ['/joint_states', '/tf'], 'not reading the robot',
                                    watchdog=self.inputs, on_change=self._on_sources_changed)
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
        self._last_now_ns: int | None = None  # ROS time of the last tick [ns]
        self._pending: tuple[dict, dict, Staircase | None] | None = None
        self._mirroring = False  # setting the declared parameters to what the plan walks
        self._requested_twist = Twist2D()
        self._stale_stop = False  # walking a zero twist because /cmd_vel went stale
        self._replacing: object = None  # token of the plan from scratch the worker makes
        self._commands = itertools.count(1)
        self._late = False
        self._last_plan = None
        self._within = _HorizonCut()
        self._swing_lifts: tuple = (None, [])  # (plan, [(foot, lift-off [ns])])
        self._zmp_messages = ZmpReferenceMessages()
        self._last_velocity_notes: list[str] = []
        self.footsteps_publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), 'gait/footsteps',
            qos_profile_latched)
        self.zmp_publisher = self.create_publisher(get_message('nav_msgs/msg/Path'),
                                                   'gait/zmp_reference', 10)
        # As deep as the command subscription: the answers to a burst of commands all go out.
        self.status_publisher = self.create_publisher(get_message('std_msgs/msg/String'),
                                                      'gait/command_status', COMMAND_DEPTH)
        self.create_subscription(get_message('geometry_msgs/msg/Twist'), 'cmd_vel',
                                 self.on_cmd_vel, 10)
        self.create_subscription(get_message('std_msgs/msg/String'), 'gait/command',
                                 self.on_command, COMMAND_DEPTH)
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 SWING_TOPIC.lstrip('/'), self.on_swing, 10)
        if self.context.runtime != 'inproc':
            self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                     '/diagnostics', self.on_diagnostics, 50)
        if not self._joined:
            self._listen(True)
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.add_post_set_parameters_callback(self.on_parameters_set)
        self.timer = self.create_timer(1.0 / self.settings['rate_hz'], self.tick)
        self.create_timer(1.0, self.report_state)
        if planner.swing_timing is not None:
            # Time the fastest forward walk now, so that a first /cmd_vel walks at once.
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
        # Planning runs in the worker, the tick publishes its finished plans (module docstring).
        self.worker = OnlinePlanner(
            planner, self.origin_ns, lambda: self.get_clock().now().nanoseconds,
            cover_s=self._cover_s(params), lead_s=self.settings['zmp_horizon_s'],
            standing_lead_s=STANDING_LEAD_S,
            threaded=self.context.runtime != 'inproc',
            describe=self._describe_plan,
            failure_hold_s=lambda p: (self.settings['zmp_horizon_s'] + p.params.step_period_s
                                      + RETRY_AFTER_S),
            job_done=lambda kind, seconds: callback_times.record(self.get_name(),
                                                                 f'worker {kind}', seconds),
            check=self._check_joint_speeds)
        self.worker.start()
        parse_gait_command('{}')  # the schema's validator made now, not at the first command

    @property
    def planner(self) -> GaitPlanner:
        """The newest finished plan (read it only: the worker changes the plan)."""
        return self.worker.snapshot.planner

    def _cover_s(self, params: GaitParameters) -> float:
        return self.settings['zmp_horizon_s'] + params.step_period_s + WORKER_COVER_S

    def destroy_node(self):
        """Stop the planning worker, then the node."""
        worker = getattr(self, 'worker', None)
        if worker is not None:
            worker.stop()
        return super().destroy_node()

    # --- swing timing --------------------------------------------------------------------------

    def _swing_timing(self, params: GaitParameters) -> tuple[object, str, bool]:
        """(model, reason, final): the swing timing model for ``params`` (None: fixed timing).

        Runs in the planning worker (and at start). With ``swing: value_table`` and the table
        not built yet (swing_leg_policy builds it on first use), the polynomial swing's longer
        times stand in (final False) and the table is looked for again once a second
        (:meth:`report_state`).
        """
        if params.timing != 'joint_limit' or self.robot.extra.get('limb_ik') is None:
            return None, ('fixed timing' if params.timing == 'fixed' else
                          f'{self.robot.name} has no closed-form limb IK: fixed timing'), True
        key = (params.swing, params.step_height_m)
        known = self._timings.get(key)
        if known is not None and known[2]:
            return known
        from gait_nodes.robot.model import load_robot_model
        from gait_nodes.swing.timing import TableSwingTiming, swing_timing

        if self._robot_model is None:
            self._robot_model = load_robot_model(str(self.robot.path))
        if known is not None and not self._table_file(params).is_file():
            return known  # still the stand-in: looked for again in a second
        model, reason = swing_timing(self._robot_model, params.swing, params.step_height_m)
        final = params.swing != 'value_table' or isinstance(model, TableSwingTiming)
        if known is not None and not final:
            return known  # still the stand-in: keep the same one
        self._timings[key] = (model, reason, final)
        return model, reason, final

    def _check_joint_speeds(self, fork: GaitPlanner, from_s: float) -> None:
        """Worker: refuse a plan with fixed timing whose swings the joints cannot follow.

        A plan timed at the joint limit (``timing: joint_limit`` with a model) is re-timed by
        its probes already; any other is probed here, with the swing timing model of its
        swing (closed-form limb IK) or the polynomial swing through the whole-body IK.
        """
        params = fork.params
        if params.timing == 'joint_limit' and fork.swing_timing is not None:
            return
        probe = self._probe(params)
        if probe is not None:
            fork.check_joint_speeds(probe, from_s)

    def _probe(self, params: GaitParameters):
        """Worker: the joint-speed probe of ``params``' swings (None: no robot model)."""
        if self.robot.extra.get('limb_ik') is not None:
            return self._swing_timing(params.replace(timing='joint_limit'))[0]
        key = ('probe', params.step_height_m)
        if key not in self._timings:
            from gait_nodes.robot.model import load_robot_model
            from gait_nodes.swing.timing import PolynomialSwingTiming

            try:
                if self._robot_model is None:
                    self._robot_model = load_robot_model(str(self.robot.path))
                self._timings[key] = PolynomialSwingTiming(
                    self._robot_model, None, self.robot.joint_velocity_limit_rad_s,
                    params.step_height_m)
            except GaitNodesError as exc:
                self.get_logger().warning(f'no joint-speed check of gait commands: {exc}')
                self._timings[key] = None
        return self._timings[key]

    def _table_file(self, params: GaitParameters):
        """Where the swing value table of ``params`` is cached (built or not)."""
        from gait_nodes.robot.whole_body_ik import limb_ik_family
        from gait_nodes.swing.cache import default_table_path

        return default_table_path(self._robot_model, limb_ik_family(self._robot_model),
                                  params.step_height_m,
                                  self._robot_model.description.joint_velocity_limit_rad_s)

    def _retime(self, fork: GaitPlanner, at_s: float):
        """Worker: time ``fork`` with the table once it exists (UNCHANGED while it does not)."""
        model, reason, final = self._swing_timing(fork.params)
        if model is fork.swing_timing:
            return UNCHANGED
        fork.set_swing_timing(model, at_s)
        return ('timing', reason, final)

    # --- time ----------------------------------------------------------------------------------

    def now_s(self) -> tuple[int, float]:
        """ROS time [ns] and the plan's time [s]."""
        now_ns = self.get_clock().now().nanoseconds
        return now_ns, (now_ns - self.worker.snapshot.origin_ns) * 1e-9

    @property
    def origin_ns(self) -> int:
        """ROS time of the plan's 0 s [ns]."""
        worker = getattr(self, 'worker', None)
        return self._origin_ns if worker is None else worker.snapshot.origin_ns

    @origin_ns.setter
    def origin_ns(self, value: int) -> None:
        self._origin_ns = value

    def _clock_jumped(self, now_ns: int, now_s: float) -> bool:
        """A clock jump restarts the plan from standstill (True: the restart is under way)."""
        last_ns, self._last_now_ns = self._last_now_ns, now_ns
        if last_ns is None or 0 <= now_ns - last_ns <= CLOCK_JUMP_S * NS_PER_S:
            return False
        jump_s = (now_ns - last_ns) * 1e-9
        self.diagnostics.report('clock', WARN, f'the clock jumped by {jump_s:.3f} s; the plan '
                                f'restarts from standstill')
        planner = self.planner
        state = planner.steps[-1].state_after if planner.steps else None
        pose = state.rest_pose if state is not None else (0.0, 0.0, 0.0)
        twist = self._requested_twist

        def restart(live):
            return GaitPlanner(self.robot, live.params, base_pose=pose,
                               swing_timing=live.swing_timing, terrain=live.terrain)

        self._replace(restart, 'clock', twist)
        return True

    def _replace(self, make, token, twist: Twist2D) -> None:
        """Have the worker plan from scratch; the tick waits for it (see :meth:`_on_replaced`).

        The new plan starts standing where the robot is; ``twist`` is then walked as any new
        velocity is, from a step boundary the worker can join (the walk's start, with the COM
        controller holding the robot's measured COM until then).
        """
        self._replacing = (token, next(self._commands))
        self.worker.submit_replace(make, self._replacing)
        if not twist.is_zero():
            self.worker.submit_velocity(twist)
        self.worker.run_pending()
        self._handle_events()

    # --- inputs --------------------------------------------------------------------------------

    def on_cmd_vel(self, msg) -> None:
        """Walk the commanded twist from the next step boundary (NaN dropped, excess clamped)."""
        values = (msg.linear.x, msg.linear.y, msg.linear.z,
                  msg.angular.x, msg.angular.y, msg.angular.z)
        if not all(math.isfinite(v) for v in values):
            self.diagnostics.drop('/cmd_vel', f'non-finite velocity {values}')
            return
        twist = Twist2D(float(msg.linear.x), float(msg.linear.y), float(msg.angular.z))
        self.inputs.heard('/cmd_vel', self.get_clock().now().nanoseconds)
        # /cmd_vel is usually streamed: the worker plans a twist that differs from the one it
        # walks; its report (on_velocity) comes when it is planned.
        if twist != self._requested_twist or self._stale_stop:
            self._requested_twist, self._stale_stop = twist, False
            self.worker.submit_velocity(twist)

    def _on_velocity(self, event: VelocityApplied) -> None:
        notes = list(event.notes)
        self._last_velocity_notes = notes
        self.diagnostics.report(
            'velocity', WARN if notes else OK,
            '; '.join(notes) if notes else 'velocity command accepted',
            {'requested_twist': event.requested.as_tuple(),
             'applied_twist': event.applied.as_tuple(),
             'takes_effect_s': (event.takes_effect_ns - self.origin_ns) * 1e-9})

    def _on_sources_changed(self) -> None:
        """Report at once that the robot's state is refused (two robots) or read again."""
        now_ns = self.get_clock().now().nanoseconds
        self.inputs.update(now_ns)
        self.diagnostics.publish([self.inputs.status(now_ns)])

    def on_tf(self, msg) -> None:
        """Keep the robot's base pose (joining or paused: the measured state)."""
        if self.sources.refused:
            return
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
        if self.sources.refused:
            return
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
                                         'joint_states', self.on_joint_states, 10)]
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

    def _plan_from_robot(self, now_ns: int, token: str) -> None:
        """Have the worker plan anew from the robot's measured state (or its base pose).

        The measurement is taken now; the plan (its fastest rhythm, probes) is made in the
        worker, and ``token`` comes back in its :class:`Replaced` event.
        """
        twist = self._requested_twist
        start = self._start(now_ns)
        pose = self._measured.base_pose() if self._measured is not None \
            and self._measured.base_ns is not None else self._base_pose
        if start is not None:
            # The walk's path starts where the footholds are centred, with the base's yaw: the
            # base itself may lean off them (the IK keeps the COM where the reference was).
            pose = tuple(float(v) for v in centred_pose(
                start.feet_in_world, self.planner.layout.offsets(self.planner.params.step_width_m),
                pose[2]))

        def plan(live):
            return GaitPlanner(self.robot, live.params, base_pose=pose,
                               swing_timing=live.swing_timing, start=start,
                               terrain=live.terrain)

        self._replace(plan, token, twist)
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
            if self._replacing is None:
                self._plan_from_robot(now_ns, 'join')
            return False  # joined once the worker's plan is live (_on_replaced)
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
        if pause['hold'] is not None:
            if self._replacing is None:
                # Held until the worker's plan is live (_on_replaced; at once under inproc). If
                # it fails, the walk stays paused.
                self._plan_from_robot(now_ns, 'resume')
            return self._pause is not None
        self._resumed(now_ns)
        return False

    def _resumed(self, now_ns: int) -> None:
        held_s = (now_ns - self._pause['since_ns']) * 1e-9
        self._pause = None
        self._listen(False)
        self.diagnostics.report('walk', OK, f'walking on after a pause of {held_s:.2f} s, '
                                f'planned from the robot\'s measured state',
                                {'paused_s': held_s})

    # --- failures ------------------------------------------------------------------------------

    def _hold(self, exc: Exception) -> str:
        """After a failure (see the module docstring): what the planner holds."""
        now_ns, now_s = self.now_s()
        if self._pause is not None:
            self._pause['fresh_ns'] = now_ns
            return 'the walk stays paused, the robot held where it stands; resuming again later'
        if not self._joined:
            return 'not planning yet; joining again at the next tick'
        if not self.planner.halted:
            self.worker.submit_stand(self.settings['zmp_horizon_s']
                                     + self.planner.params.step_period_s + RETRY_AFTER_S)
            self.worker.run_pending()
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
        if self.inputs.stale and not self._stale_stop and not self._requested_twist.is_zero():
            self._stale_stop = True
            self.worker.submit_velocity(Twist2D())

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
            command_id, msg.data, functools.partial(self._apply_changes, changes, None))
        if repeated is None:
            self.worker.run_pending()
        self._handle_events()

    def _new_id(self) -> str:
        return f'{self.get_name()}-{next(self._commands)}'

    def _apply_changes(self, changes: dict, terrain: Staircase | None, fork: GaitPlanner,
                       at_s: float):
        """Worker: plan gait ``changes`` (and ``terrain``) on ``fork`` from ``at_s`` on."""
        params = parameters_from_mapping(fork.params, changes, self.robot)
        model, reason, final = self._swing_timing(params)
        if terrain is not None and terrain != fork.terrain:
            fork.set_terrain(terrain, at_s, params)
        fork.set_parameters(params, at_s, swing_timing=model)
        return ('timing', reason, final)

    def _answer(self, answer: Answer) -> None:
        """Publish ``answer`` on /gait/command_status and report it on /diagnostics."""
        command, reason = _shortened(answer.text), _shortened(answer.reason)
        now_ns = self.get_clock().now().nanoseconds
        status = {'id': answer.command_id, 'state': answer.state,
                  'accepted': answer.accepted, 'reason': reason, 'params': answer.params,
                  'command': command}
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

    # --- the worker's events ------------------------------------------------------------------

    def _handle_events(self) -> None:
        """Answers, plans live, failures: what the worker did since the last call."""
        failed = False
        for event in self.worker.events():
            if isinstance(event, Answer):
                self._answer(event)
                if event.state == ACCEPTED and not event.repeated:
                    self._mirror(event.params)
                elif event.command_id.startswith(PARAMETER_ID) and not event.accepted:
                    self._mirror(self.planner.params.to_dict())  # the refused value set back
            elif isinstance(event, VelocityApplied):
                self._on_velocity(event)
            elif isinstance(event, Changed):
                kind, reason, final = event.info
                self._report_timing(reason, final)
            elif isinstance(event, ChangeRefused) and event.key == 'velocity':
                self._requested_twist = self.planner.requested_twist
                self.diagnostics.report(
                    'velocity', WARN, f'velocity {event.payload.as_tuple()} refused: '
                    f'{event.reason}; walking {self.planner.twist.as_tuple()} on',
                    {'requested_twist': event.payload.as_tuple(),
                     'applied_twist': self.planner.twist.as_tuple()})
            elif isinstance(event, ChangeRefused):
                self.diagnostics.report('timing', WARN, f'{self._timing_reason}; a change '
                                        f'({event.key}) could not be planned: {event.reason}')
            elif isinstance(event, Replaced):
                self._on_replaced(event)
            elif isinstance(event, Failure):
                failed = True
                self.faults.failed('plan', event.error)
        if not failed and self.faults.failing:
            self.faults.succeeded('plan')

    def _report_timing(self, reason: str, final: bool) -> None:
        if reason != self._timing_reason or final != self._timing_final:
            self._timing_reason, self._timing_final = reason, final
            self.diagnostics.report('timing', OK if final else WARN, reason)

    def _on_replaced(self, event: Replaced) -> None:
        if event.token != self._replacing:
            return
        token, self._replacing = event.token[0], None
        now_ns = self.get_clock().now().nanoseconds
        self._last_plan = None
        if event.error is not None:
            if token == 'resume' and self._pause is not None:
                self._pause['fresh_ns'] = now_ns  # the walk stays paused; resumed again later
            self.faults.failed(f'{token} plan', event.error)
            return
        if token == 'join':
            self._joined = True
            self._listen(False)
        elif token == 'resume' and self._pause is not None:
            self._resumed(now_ns)

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
                functools.partial(self._apply_changes, gait_changes, terrain))
        if settings['rate_hz'] != self.settings['rate_hz']:
            self.destroy_timer(self.timer)
            self.timer = self.create_timer(1.0 / settings['rate_hz'], self.tick)
        self.settings = settings
        self.worker.cover_s = self._cover_s(self.planner.params)
        self.worker.lead_s = settings['zmp_horizon_s']
        self.worker.run_pending()

    # --- outputs -------------------------------------------------------------------------------

    def tick(self) -> None:
        """Publish the worker's newest plan: the footsteps if they changed, the ZMP reference."""
        self._handle_events()
        now_ns, now_s = self.now_s()
        if not self._joined:
            if not self._join(now_ns):
                return
            now_ns, now_s = self.now_s()
        if self._replacing is not None and self._replacing[0] != 'resume' \
                or self._clock_jumped(now_ns, now_s):
            return  # a plan from scratch is under way
        self._check_cmd_vel(now_ns, now_s)
        origin_ns, pause = self.origin_ns, self._pause
        if self._paused(now_ns, now_s):
            return
        if pause is not None or origin_ns != self.origin_ns:  # resumed: the time read anew
            now_ns, now_s = self.now_s()
        self.worker.run_pending()
        self._handle_events()
        snapshot = self.worker.snapshot
        planner, horizon = snapshot.planner, self.settings['zmp_horizon_s']
        plan = self._within(planner.footstep_plan(now_s, snapshot.origin_ns), now_ns,
                            now_ns + int(horizon * NS_PER_S))
        if self._last_plan is None or not _same_plan(plan, self._last_plan):
            self.footsteps_publisher.publish(footsteps_to_msg(plan))
            self._last_plan = plan
        self._check_swings(plan, now_ns)
        reference = planner.zmp_reference(now_ns, snapshot.origin_ns, horizon,
                                          self.settings['zmp_sample_period_s'])
        # Its corners only: the consumers interpolate linearly between the poses.
        self.zmp_publisher.publish(self._zmp_messages.to_msg(reference.corners()))
        late = snapshot.planned_until_s < now_s + horizon
        if late != self._late:
            self._late = late
            ahead_s = snapshot.planned_until_s - now_s
            self.diagnostics.report(
                'planning', WARN if late else OK,
                f'the plan reaches {ahead_s:.2f} s ahead, less than the {horizon:g} s horizon: '
                f'the planning worker is late' if late else 'the plan covers the horizon',
                {'planned_ahead_s': ahead_s, 'worker_busy_s': self.worker.busy_s})

    def report_state(self) -> None:
        """Once a second: the gait, the twist, the rhythm and the margin of the planned ZMP."""
        if not self._timing_final:
            self.worker.submit_change(self._retime, key='timing')
            self.worker.run_pending()
        snapshot = self.worker.snapshot
        report = snapshot.report
        if not report:
            return
        level = OK if report['zmp_margin_kept_m'] >= report['zmp_margin_m'] - 1e-12 else WARN
        self.diagnostics.report('gait', level, f'{report["resolved_gait"]}, {report["mode"]}',
                                {**report, 'requested_twist': self._requested_twist.as_tuple(),
                                 'timing_source': self._timing_reason})

    def _describe_plan(self, planner: GaitPlanner) -> dict:
        """Worker: what :meth:`report_state` reports of ``planner``."""
        params = planner.params
        steps = planner.steps
        kept = min((step.zmp_margin_kept_m for step in steps), default=math.inf)
        return {
            'gait': params.gait, 'resolved_gait': params.resolved_gait(self.robot),
            'mode': steps[-1].state_after.mode if steps else 'standing',
            'applied_twist': planner.twist.as_tuple(),
            'zmp_margin_kept_m': kept, 'zmp_margin_m': params.zmp_margin_m,
            'planned_steps': len(steps), 'timing': params.timing,
            'stairs_count': planner.terrain.count,
            'stairs_total_rise_m': planner.terrain.total_rise_m,
            **self._rhythm_values(planner)}

    def _rhythm_values(self, planner: GaitPlanner) -> dict:
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
