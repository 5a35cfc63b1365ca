"""The footstep planner's control path: joining, pausing, holding and its watchdogs, runtime-free.

:class:`PlannerSupervisor` decides, at each tick of the footstep planner node, what the node
publishes: the planning worker's newest plan (:class:`gait_nodes.planning.online.OnlinePlanner`),
a hold of the robot where it stands, or nothing yet. The node feeds it what arrives (the robot's
measured base pose and joints, /cmd_vel, the swing trajectories heard, the stale-input reports
of the nodes that move the robot) and turns each :class:`Output` into messages. Times are
integer nanoseconds of the node's clock at this boundary, seconds inside.

Rejoin: started into a running graph (dds, rclpy), the planner waits up to ``JOIN_WAIT_S`` for
the robot's measured state (/tf odom -> base_link and /joint_states, forward kinematics of the
robot model: footholds, foot yaws, COM) and plans from there: the first steps start from the
actual footholds and the ZMP reference from the measured COM. A robot still finishing the steps
of the planner it replaces (a foot in the air, the base moving) is waited for up to
``STAND_WAIT_S``; a foot still in the air then is put down first (a landing swing straight down,
:class:`gait_nodes.planning.footsteps.MeasuredStart`). Without /joint_states (or a robot model
without kinematics) the feet start at their nominal places under the /tf base pose; without
either, at the nominal stance of the plan's origin.

Pause: the planner follows the stale-input reports of the nodes that move the robot
(``whole_body_ik: inputs`` naming /gait/com_reference, ``kinematic_simulator: inputs`` naming
/joint_commands). While one of them reports its input stale during a walk, the robot is held
where it stands, so the plan must not run on in time: the planner pauses (WARN, ``walk``),
publishes a plan that holds the measured footholds (a foot in the air held where it is) with the
ZMP reference on the measured COM, on the plane of the lowest held foot on the ground, and once
every report is OK again for ``RESUME_AFTER_S`` and the robot was measured since, it plans anew
from the robot's measured state and walks on (OK). The planner also checks that each planned
swing gets its /gait/swing_trajectory: one missing when its foot lifts off (the swing-leg policy
is down; the whole-body IK follows its fallback swing) is reported as a stale input (WARN,
``swing inputs``) until the next one arrives.

Failures: a plan that cannot be made ends the walk in a safe stand (:meth:`PlannerSupervisor.
hold`, called by the node's :class:`gait_nodes.faults.FaultGuard`): no foot lifts off any more,
the ZMP reference moves to the stand point of the feet; the worker plans again
``RETRY_AFTER_S`` later, or at once on a new velocity. A failure to resume a paused walk keeps
it paused; the resume is tried again with the next fresh measured state.

/cmd_vel watchdog (``cmd_vel_timeout_s`` > 0, as twist_mux's timeout): when no /cmd_vel has come
for that long the planner walks a zero twist from the next step boundary, reports the stale
input (WARN, ``inputs``) and walks again with the next /cmd_vel. A clock jump of more than
``CLOCK_JUMP_S`` restarts the plan from standstill (WARN, ``clock``).
"""

from __future__ import annotations

import bisect
import dataclasses
import itertools
import math
from collections.abc import Callable, Iterable, Sequence

import numpy as np

from gait_nodes.contract import FootstepPlan, ZmpReference
from gait_nodes.diagnostics import OK, WARN
from gait_nodes.errors import GaitNodesError
from gait_nodes.planning.footsteps import (
    GaitPlanner,
    MeasuredStart,
    Twist2D,
    centred_pose,
    place,
)
from gait_nodes.planning.online import (
    ChangeRefused,
    Failure,
    OnlinePlanner,
    Replaced,
    VelocityApplied,
)
from gait_nodes.planning.zmp_reference import standing_zmp
from gait_nodes.watchdog import InputWatchdog

NS_PER_S = 1_000_000_000
#: A clock jump larger than this [s] restarts the plan from standstill.
CLOCK_JUMP_S = 10.0
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
                'kinematic_simulator: inputs': '/joint_commands',
                'physics_simulator: inputs': '/joint_commands'}
#: Every dependency OK again for this long before a paused walk resumes [s].
RESUME_AFTER_S = 0.5
#: A planned swing with no /gait/swing_trajectory this long after its lift-off is missed [s].
SWING_GRACE_S = 0.05
#: A swing trajectory lifting off this close to a planned swing's lift-off is its own [ns].
SAME_LIFT_OFF_NS = 1000
SWING_TOPIC = '/gait/swing_trajectory'
CMD_VEL_TOPIC = '/cmd_vel'
#: After a planning failure the plan stands still this long before it is tried again [s].
RETRY_AFTER_S = 1.0


def yaw_of(pose: np.ndarray) -> float:
    """Yaw [rad] of a pose (x, y, z, qx, qy, qz, qw)."""
    _, _, _, qx, qy, qz, qw = pose
    return math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


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
        return float(self._base[0]), float(self._base[1]), yaw_of(self._base)

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


class HorizonCut:
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
        """``plan`` cut at ``until_ns`` [ns] (``now_ns``: the clock [ns]; nothing before it)."""
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


def same_plan(a: FootstepPlan, b: FootstepPlan) -> bool:
    """Whether two plans say the same (published once)."""
    return a is b or (a.start_ns == b.start_ns and a.foot_names == b.foot_names
                      and a.times_s.shape == b.times_s.shape
                      and bool((a.times_s == b.times_s).all())
                      and bool((a.positions_in_world == b.positions_in_world).all())
                      and bool((a.yaws_rad == b.yaws_rad).all()))


@dataclasses.dataclass(frozen=True)
class SupervisorSettings:
    """The node settings the supervisor works with.

    Attributes:
        zmp_horizon_s: The ZMP reference reaches this far ahead of the clock [s].
        zmp_sample_period_s: Period of the ZMP reference's samples [s].
        cmd_vel_timeout_s: /cmd_vel older than this stops the walk [s]; 0: never.
    """

    zmp_horizon_s: float
    zmp_sample_period_s: float
    cmd_vel_timeout_s: float = 0.0


@dataclasses.dataclass(frozen=True)
class Report:
    """A status for /diagnostics: ``"<node>: <aspect>"``; ``logged``: WARN and ERROR logged."""

    aspect: str
    level: int
    message: str
    values: dict | None = None
    logged: bool = True


@dataclasses.dataclass
class Output:
    """What the node publishes after a call of the supervisor.

    Attributes:
        footsteps: The footstep plan to publish (latched), None: it did not change.
        zmp_reference: The ZMP reference to publish (its corners: consumers interpolate
            linearly), None: none this tick (joining, a plan from scratch under way).
        reports: Statuses for /diagnostics, in order.
        events: The planning worker's events the node answers (gait command answers,
            :class:`gait_nodes.planning.online.Changed`, refused changes but velocities).
        log: Lines for the node's info log.
    """

    footsteps: FootstepPlan | None = None
    zmp_reference: ZmpReference | None = None
    reports: list[Report] = dataclasses.field(default_factory=list)
    events: list = dataclasses.field(default_factory=list)
    log: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class _Pause:
    since_ns: int  # the pause began [ns]
    zmp: np.ndarray  # (2,) the ZMP held [m]
    hold: tuple[np.ndarray, np.ndarray] | None = None  # measured (F, 3) feet, (F,) yaws
    fresh_ns: int | None = None  # every dependency fresh since [ns]


class PlannerSupervisor:
    """Joins, pauses, holds and watches over the footstep planner's plan (module docstring).

    Args:
        robot: The robot (:class:`gait_nodes.robot.description.RobotDescription`).
        worker: The planning worker, started by the caller; this object submits velocities,
            plans from scratch and stands to it and takes its events.
        faults: The node's :class:`gait_nodes.faults.FaultGuard` (``failed(name, exc)``,
            ``succeeded(name)``, ``failing``), whose ``hold`` and ``recovered`` are
            :meth:`hold` and :meth:`recovered` of this object.
        settings: The node settings (also settable later as ``settings``).
        start_ns: The node's start [ns]: an input never heard is as old as that.
        joining: Started into a running graph: plan from the robot's measured state first.
        load_model: ``load_model() -> RobotModel | None``: the model for forward kinematics,
            asked when the robot's state is first needed (None: no kinematics; asked again
            the next time).
    """

    def __init__(self, robot, worker: OnlinePlanner, faults, settings: SupervisorSettings,
                 start_ns: int, joining: bool = False,
                 load_model: Callable[[], object] = lambda: None):
        self.robot = robot
        self.worker = worker
        self.faults = faults
        self.settings = settings
        self._load_model = load_model
        self.inputs = InputWatchdog([CMD_VEL_TOPIC], settings.cmd_vel_timeout_s or 1.0, start_ns,
                                    holding='stopping (zero velocity from the next step '
                                    'boundary)')
        self.swing_inputs = InputWatchdog([], 1.0, start_ns, events=[SWING_TOPIC],
                                          holding='the whole-body IK follows its fallback swing')
        self._joined = not joining
        self._listening = False
        self._base_pose: tuple[float, float, float] | None = None
        self._measured: MeasuredState | None = None
        self._join_start_ns: int | None = None
        self._delivered = None  # the worker's newest snapshot this node has published
        self._dependencies: dict[str, bool] = {}
        self._dependencies_fresh: set[str] = set()  # reported their inputs fresh at least once
        # Reported stale since the last tick: a stale spell shorter than the planner's period
        # (stale, then fresh again between two 10 Hz ticks) still pauses the walk.
        self._stale_since_tick: set[str] = set()
        self._pause: _Pause | None = None
        self._swings_heard: set[tuple[str, int]] = set()
        self._swings_checked: set[tuple[str, int]] = set()
        self._swings_pruned_ns = -NS_PER_S
        self._swing_lifts: tuple = (None, [])  # (plan, [(foot, lift-off [ns])])
        self._last_now_ns: int | None = None  # the last tick [ns]
        self._requested_twist = Twist2D()
        self._stale_stop = False  # walking a zero twist because /cmd_vel went stale
        self._replacing: tuple[str, int] | None = None  # the plan from scratch under way
        self._tokens = itertools.count(1)
        self._late = False
        self._last_plan: FootstepPlan | None = None
        self._within = HorizonCut()
        self._out = Output()
        if joining:
            self._listen(True)

    # --- what the node reads --------------------------------------------------------------

    @property
    def planner(self) -> GaitPlanner:
        """The newest finished plan (read it only: the worker changes the plan)."""
        return self.worker.snapshot.planner

    @property
    def origin_ns(self) -> int:
        """Time of the plan's 0 s [ns]."""
        return self.worker.snapshot.origin_ns

    @property
    def requested_twist(self) -> Twist2D:
        """The twist last asked on /cmd_vel (the walked one while a velocity is refused)."""
        return self._requested_twist

    @property
    def listening(self) -> bool:
        """Whether the node should listen to the robot's state (/tf, /joint_states)."""
        return self._listening

    @property
    def joined(self) -> bool:
        """Whether the plan is live (joined the running graph, or started with it)."""
        return self._joined

    @property
    def paused(self) -> bool:
        """Whether the walk is paused (held where the robot stands)."""
        return self._pause is not None

    # --- inputs ---------------------------------------------------------------------------

    def on_cmd_vel(self, twist: Twist2D, now_ns: int) -> None:
        """Walk ``twist`` from the next step boundary (a finite one; the worker clamps it)."""
        self.inputs.heard(CMD_VEL_TOPIC, now_ns)
        # /cmd_vel is usually streamed: the worker plans a twist that differs from the one it
        # walks; its report (VelocityApplied) comes when it is planned.
        if twist != self._requested_twist or self._stale_stop:
            self._requested_twist, self._stale_stop = twist, False
            # Before the join the twist waits for it (the join plan walks the newest one):
            # planned on the plan the join replaces, it would hold the join back.
            if self._joined or self._replacing is not None:
                self.worker.submit_velocity(twist)

    def on_base(self, pose_in_world: np.ndarray, now_ns: int) -> bool:
        """The base pose (x, y, z, qx, qy, qz, qw; unit quaternion) in odom at ``now_ns``.

        Returns:
            Whether the node should tick now: the robot is measured for a pause's hold (at
            10 Hz the starved node may be back before the next tick, and follow the walking
            plan a tick long before the hold comes).
        """
        pose_in_world = np.asarray(pose_in_world, dtype=float)
        self._base_pose = (float(pose_in_world[0]), float(pose_in_world[1]),
                           yaw_of(pose_in_world))
        if self._measured is None:
            return False
        self._measured.on_base(pose_in_world, now_ns)
        return self._hold_due()

    def on_joints(self, names: Sequence[str], positions: np.ndarray, now_ns: int) -> bool:
        """Finite joint positions at ``now_ns``; unknown names are dropped. See :meth:`on_base`."""
        if self._measured is None:
            return False
        try:
            self._measured.on_joints(names, positions, now_ns)
        except (GaitNodesError, ValueError):
            return False
        return self._hold_due()

    def on_diagnostics(self, reports: Iterable[tuple[str, Sequence[str]]]) -> bool:
        """Stale-input reports ``(status name, stale topics)`` of the nodes on /diagnostics.

        Returns:
            Whether the node should tick now: a dependency went stale during a walk, which
            pauses it at once, not at the next tick (up to 0.1 s later at 10 Hz: the held
            robot's plan would run on that long).
        """
        newly_stale = False
        for name, stale_topics in reports:
            topic = DEPENDENCIES.get(name)
            if topic is None:
                continue
            is_stale = topic in stale_topics
            if not is_stale:
                self._dependencies_fresh.add(name)
            # A node still waiting for its first input (the graph starting: the IK has no COM
            # reference before this planner's first plan) holds nothing that a pause would save.
            self._dependencies[name] = is_stale and name in self._dependencies_fresh
            if self._dependencies[name]:
                newly_stale |= name not in self._stale_since_tick
                self._stale_since_tick.add(name)
        return newly_stale and self._pause is None and self._joined

    def on_swing(self, foot: str, start_ns: int, now_ns: int) -> None:
        """A swing trajectory of ``foot`` lifting off at ``start_ns`` arrived at ``now_ns``."""
        self._swings_heard.add((foot, int(start_ns)))
        self.swing_inputs.heard(SWING_TOPIC, now_ns)

    # --- outputs --------------------------------------------------------------------------

    def tick(self, now_ns: int) -> Output:
        """What to publish at ``now_ns``: the worker's newest plan, a hold, or nothing yet."""
        self._out = Output()
        self._drain(now_ns)
        if not self._joined and not self._join(now_ns):
            return self._out
        if self._replacing is not None and self._replacing[0] != 'resume' \
                or self._clock_jumped(now_ns):
            return self._out  # a plan from scratch is under way
        self._check_cmd_vel(now_ns)
        if self._paused(now_ns, (now_ns - self.origin_ns) * 1e-9):
            return self._out
        now_s = (now_ns - self.origin_ns) * 1e-9  # (a resumed plan has its own origin)
        self.worker.run_pending()
        self._drain(now_ns)
        snapshot = self.worker.snapshot
        if snapshot is not self._delivered:
            self._delivered = snapshot
            self.worker.delivered(snapshot)  # published now, at the end of this tick
        planner, horizon = snapshot.planner, self.settings.zmp_horizon_s
        plan = self._within(planner.footstep_plan(now_s, snapshot.origin_ns), now_ns,
                            now_ns + int(horizon * NS_PER_S))
        if self._last_plan is None or not same_plan(plan, self._last_plan):
            self._out.footsteps = self._last_plan = plan
        self._check_swings(plan, now_ns)
        reference = planner.zmp_reference(now_ns, snapshot.origin_ns, horizon,
                                          self.settings.zmp_sample_period_s)
        self._out.zmp_reference = reference.corners()
        late = snapshot.planned_until_s < now_s + horizon
        if late != self._late:
            self._late = late
            ahead_s = snapshot.planned_until_s - now_s
            self._report('planning', WARN if late else OK,
                         f'the plan reaches {ahead_s:.2f} s ahead, less than the {horizon:g} s '
                         f'horizon: the planning worker is late' if late
                         else 'the plan covers the horizon',
                         {'planned_ahead_s': ahead_s, 'worker_busy_s': self.worker.busy_s})
        return self._out

    def poll(self, now_ns: int) -> Output:
        """The worker's events since the last call (e.g. after a gait command was submitted)."""
        self._out = Output()
        self._drain(now_ns)
        return self._out

    # --- failures -------------------------------------------------------------------------

    def hold(self, now_ns: int) -> str:
        """After a failure at ``now_ns`` (module docstring): hold; what is held, for the report."""
        if self._pause is not None:
            self._pause.fresh_ns = now_ns
            return 'the walk stays paused, the robot held where it stands; resuming again later'
        if not self._joined:
            return 'not planning yet; joining again at the next tick'
        if not self.planner.halted:
            self.worker.submit_stand(self.settings.zmp_horizon_s
                                     + self.planner.params.step_period_s + RETRY_AFTER_S)
            self.worker.run_pending()
        self._last_plan = None
        return (f'stopped at a safe stand (no foot lifts off, the ZMP to the stand point of '
                f'the feet); planning again in {RETRY_AFTER_S:g} s or at a new velocity')

    def recovered(self) -> bool:
        """Whether the plan walks again after a failure (not paused, past its safe stand)."""
        return self._pause is None and not self.planner.halted

    # --- the worker's events --------------------------------------------------------------

    def _drain(self, now_ns: int) -> None:
        """Plans live, failures, velocities: what the worker did since the last call."""
        failed = False
        for event in self.worker.events():
            if isinstance(event, VelocityApplied):
                self._report('velocity', WARN if event.notes else OK,
                             '; '.join(event.notes) if event.notes
                             else 'velocity command accepted',
                             {'requested_twist': event.requested.as_tuple(),
                              'applied_twist': event.applied.as_tuple(),
                              'takes_effect_s': (event.takes_effect_ns - self.origin_ns) * 1e-9})
            elif isinstance(event, ChangeRefused) and event.key == 'velocity':
                self._requested_twist = self.planner.requested_twist
                self._report('velocity', WARN, f'velocity {event.payload.as_tuple()} refused: '
                             f'{event.reason}; walking {self.planner.twist.as_tuple()} on',
                             {'requested_twist': event.payload.as_tuple(),
                              'applied_twist': self.planner.twist.as_tuple()})
            elif isinstance(event, Replaced):
                self._on_replaced(event, now_ns)
            elif isinstance(event, Failure):
                failed = True
                self.faults.failed('plan', event.error)
            else:
                self._out.events.append(event)
        if not failed and self.faults.failing:
            self.faults.succeeded('plan')

    def _on_replaced(self, event: Replaced, now_ns: int) -> None:
        if event.token != self._replacing:
            return
        token, self._replacing = event.token[0], None
        self._last_plan = None
        if event.error is not None:
            if token == 'resume' and self._pause is not None:
                self._pause.fresh_ns = now_ns  # the walk stays paused; resumed again later
            elif token == 'join':
                self._listen(True)  # joined again from the robot's state then
            self.faults.failed(f'{token} plan', event.error)
            return
        if token == 'join':
            self._joined = True
            self._listen(False)
        elif token == 'resume' and self._pause is not None:
            self._resumed(now_ns)

    def _replace(self, make, token: str, twist: Twist2D, now_ns: int) -> None:
        """Have the worker plan from scratch; the tick waits for it (see :meth:`_on_replaced`).

        The new plan starts standing where the robot is; ``twist`` is then walked as any new
        velocity is, from a step boundary the worker can join (the walk's start, with the COM
        controller holding the robot's measured COM until then).
        """
        self._replacing = (token, next(self._tokens))
        self.worker.submit_replace(make, self._replacing)
        if not twist.is_zero():
            self.worker.submit_velocity(twist)
        self.worker.run_pending()
        self._drain(now_ns)

    def _report(self, aspect: str, level: int, message: str, values: dict | None = None,
                logged: bool = True) -> None:
        self._out.reports.append(Report(aspect, level, message, values, logged))

    # --- the robot's measured state -------------------------------------------------------

    def _listen(self, on: bool) -> None:
        """Follow the robot's measured state (the node subscribes to it) or stop."""
        if on and not self._listening and self._measured is None:
            model = self._load_model()
            if model is not None:
                self._measured = MeasuredState(model)
        self._listening = on

    def _hold_due(self) -> bool:
        pause = self._pause
        return pause is not None and pause.hold is None and self._measured.since(pause.since_ns)

    def _start(self) -> MeasuredStart | None:
        """The measured state to plan from (None: nominal stance under the base pose)."""
        measured = self._measured
        if measured is None or measured.joints_ns is None or measured.base_ns is None:
            return None
        feet, yaws, com = measured.measure()
        pose = np.array(measured.base_pose())
        planner = self.planner
        nominal = place(pose, planner.layout.offsets(planner.params.step_width_m))
        return measured_start(feet, yaws, com, nominal, np.full(len(nominal), pose[2]),
                              standing_zmp(planner.layout, nominal, pose[2]),
                              planner.terrain.height_at(feet[:, 0]))

    def _plan_from_robot(self, now_ns: int, token: str) -> None:
        """Have the worker plan anew from the robot's measured state (or its base pose).

        The measurement is taken now; the plan (its fastest rhythm, probes) is made in the
        worker, and ``token`` comes back in its :class:`Replaced` event.
        """
        twist = self._requested_twist
        start = self._start()
        pose = self._base_pose
        if start is not None:
            # The walk's path starts where the footholds are centred, with the base's yaw: the
            # base itself may lean off them (the IK keeps the COM where the reference was).
            pose = tuple(float(v) for v in centred_pose(
                start.feet_in_world,
                self.planner.layout.offsets(self.planner.params.step_width_m), pose[2]))

        def plan(live):
            return live.anew(pose, start)

        self._replace(plan, token, twist, now_ns)
        where = 'its nominal stance' if start is None else (
            f'the measured footholds, ZMP at {np.round(start.zmp_in_world, 4).tolist()}'
            + (f', landing {[self.robot.foot_names[f] for f in np.flatnonzero(start.airborne())]}'
               if start.airborne().any() else ''))
        self._out.log.append(f'planning from the robot\'s pose {pose}: {where}')

    # --- joining a running graph ----------------------------------------------------------

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
                # Measured: the robot's state is not read while the worker plans from it (at
                # /tf's and /joint_states' rates it would take the CPU the first plan needs).
                self._listen(False)
            return False  # joined once the worker's plan is live (_on_replaced)
        self._joined = True
        self._listen(False)
        if not self._requested_twist.is_zero():
            self.worker.submit_velocity(self._requested_twist)  # heard while joining
        return True

    def _clock_jumped(self, now_ns: int) -> bool:
        """A clock jump restarts the plan from standstill (True: the restart is under way)."""
        last_ns, self._last_now_ns = self._last_now_ns, now_ns
        if last_ns is None or 0 <= now_ns - last_ns <= CLOCK_JUMP_S * NS_PER_S:
            return False
        jump_s = (now_ns - last_ns) * 1e-9
        self._report('clock', WARN, f'the clock jumped by {jump_s:.3f} s; the plan restarts '
                     f'from standstill')
        planner = self.planner
        state = planner.steps[-1].state_after if planner.steps else None
        pose = state.rest_pose if state is not None else (0.0, 0.0, 0.0)
        twist = self._requested_twist

        def restart(live):
            return live.anew(pose)

        self._replace(restart, 'clock', twist, now_ns)
        return True

    # --- pause while the robot is held ----------------------------------------------------

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
            pause = self._pause = _Pause(now_ns, self.planner.zmp(np.array([now_s]))[0])
            self._listen(True)
            self._report('walk', WARN, f'paused: {", ".join(stale)} stale; holding the robot '
                         f'where it stands', {'stale': ','.join(stale)})
        if pause.hold is None and self._measured is not None \
                and self._measured.since(pause.since_ns):
            feet, yaws, com = self._measured.measure()
            pause.hold, pause.zmp = (feet, yaws), com[:2]
            names = self.planner.layout.names
            order = [self.robot.foot_names.index(name) for name in names]
            self._out.footsteps = FootstepPlan(now_ns, names, np.zeros(1), feet[order][None],
                                               yaws[order][None])
            self._last_plan = None
        self._out.zmp_reference = self._held_reference(pause, now_ns)
        if stale:
            pause.fresh_ns = None
            return True
        if pause.fresh_ns is None:
            pause.fresh_ns = now_ns
        if (now_ns - pause.fresh_ns) * 1e-9 < RESUME_AFTER_S:
            return True
        if pause.hold is None:
            self._resumed(now_ns)
            return False
        if not self._measured.since(pause.fresh_ns):
            return True
        if self._replacing is None:
            # Held until the worker's plan is live (_on_replaced; at once in the caller's
            # thread). If it fails, the walk stays paused.
            self._plan_from_robot(now_ns, 'resume')
        return self._pause is not None

    def _held_reference(self, pause: _Pause, now_ns: int) -> ZmpReference:
        """The ZMP reference of a pause: the held ZMP over the horizon, from ``now_ns``."""
        period_ns = int(round(self.settings.zmp_sample_period_s * NS_PER_S))
        count = int(math.ceil(self.settings.zmp_horizon_s * NS_PER_S / period_ns - 1e-9)) + 1
        stamps = now_ns + period_ns * np.arange(count, dtype=np.int64)
        # On the plane of the lowest held foot (a foot held in the air is not a contact).
        plane = None
        if pause.hold is not None:
            held = pause.hold[0][:, 2]
            ground = held[held - self.planner.terrain.height_at(pause.hold[0][:, 0])
                          <= AIRBORNE_M]
            plane = np.full(count, float(ground.min() if len(ground) else held.min()))
        return ZmpReference(stamps, np.tile(pause.zmp, (count, 1)), plane).corners()

    def _resumed(self, now_ns: int) -> None:
        held_s = (now_ns - self._pause.since_ns) * 1e-9
        self._pause = None
        self._listen(False)
        self._report('walk', OK, f'walking on after a pause of {held_s:.2f} s, planned from '
                     f'the robot\'s measured state', {'paused_s': held_s})

    # --- watchdogs ------------------------------------------------------------------------

    def _check_cmd_vel(self, now_ns: int) -> None:
        timeout = self.settings.cmd_vel_timeout_s
        if not timeout:
            return
        self.inputs.timeout_s = timeout
        if self.inputs.update(now_ns):
            self._report(*self.inputs.status(now_ns), logged=False)
        if self.inputs.stale and not self._stale_stop and not self._requested_twist.is_zero():
            self._stale_stop = True
            self.worker.submit_velocity(Twist2D())

    def _check_swings(self, plan: FootstepPlan, now_ns: int) -> None:
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
            _, level, message, values = self.swing_inputs.status(now_ns)
            self._report('swing inputs', level, message if level != OK else
                         f'a swing trajectory for every swing: {SWING_TOPIC}', values)
