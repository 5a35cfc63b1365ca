"""The footstep planner's supervisor driven directly, without a runtime (no node, no messages).

A planning worker in the caller's thread, a clock that is a number and a stand-in for the node's
fault guard: joining a running graph (waiting for the measured state, for the feet to come
down, falling back to the nominal stance), pausing while a dependency reports its input stale
(holding the measured footholds and COM), resuming, holding at a safe stand after a failure,
and the /cmd_vel, swing-trajectory and clock watchdogs. The measured state is the forward
kinematics of RoboSimian's model; the held and planned footholds are checked against it.
"""

import numpy as np
import pytest
from planning_helpers import zmp_depths

from gait_nodes.diagnostics import OK, WARN
from gait_nodes.errors import GaitParameterError
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.online import OnlinePlanner
from gait_nodes.planning.supervisor import (
    AIRBORNE_M,
    JOIN_WAIT_S,
    NOMINAL_SNAP_M,
    RESUME_AFTER_S,
    RETRY_AFTER_S,
    STAND_WAIT_S,
    PlannerSupervisor,
    SupervisorSettings,
)
from gait_nodes.robot.description import load_robot_description
from gait_nodes.robot.model import load_robot_model

ROBOT = load_robot_description('robosimian')
MODEL = load_robot_model('robosimian')
#: RoboSimian's crawl, polynomial swings at a fixed rhythm: step period 2 s, the rear left
#: foot in the air from 2.7 s to 3.3 s of a walk asked at t = 0.
PARAMS = GaitParameters.for_robot(ROBOT, gait='crawl', timing='fixed', swing='polynomial')
HORIZON_S = 2.5
SAMPLE_PERIOD_S = 0.02
HOLD_S = HORIZON_S + PARAMS.step_period_s + RETRY_AFTER_S  # a failure's stand (the node's)
IK = 'whole_body_ik: inputs'
STALE = ('/gait/com_reference',)
#: Base height of the nominal joint configuration with its feet on the ground [m].
BASE_Z_M = -MODEL.foot_poses(MODEL.configuration((0.0, 0.0, 0.0), 0.0))[0][:, 2].max()
REAR_LEFT = ROBOT.foot_names.index('rear_left')


def ns(seconds: float) -> int:
    return int(round(seconds * 1e9))


def robot_state(x=0.0, y=0.0, yaw=0.0, lifted=False):
    """(base pose, joints) of RoboSimian standing, its rear left foot lifted 3.6 cm or not."""
    joints = MODEL.joint_positions(MODEL.configuration((0.0, 0.0, 0.0), 0.0))
    if lifted:
        joints[MODEL.indices(['rl_joint_2', 'rl_joint_4'])] += (0.4, -0.6)
    q = MODEL.configuration((x, y, BASE_Z_M), yaw, joints)
    return np.array(q[:7]), joints


def forward_kinematics(pose, joints):
    """(F, 3) feet, (F,) yaws, (3,) COM of a robot state: what the supervisor must measure."""
    q = np.array(MODEL.configuration((0.0, 0.0, 0.0), 0.0, joints))
    q[:7] = pose
    feet, yaws = MODEL.foot_poses(q)
    return feet, yaws, MODEL.com(q)


class Faults:
    """What the supervisor uses of the node's FaultGuard: hold on a failure, then recover."""

    def __init__(self, harness):
        self.harness = harness
        self.failing = False
        self.failures = []  # (name, exception, what the supervisor holds)

    def failed(self, name, exc):
        """``name`` raised ``exc``: the supervisor holds."""
        self.failing = True
        self.failures.append((name, exc, self.harness.core.hold(self.harness.now_ns)))

    def succeeded(self, name):
        """``name`` ran cleanly again: recovered once the supervisor says so."""
        if self.harness.core.recovered():
            self.failing = False


class Harness:
    """A supervisor over a worker planning in the caller's thread, and a clock [ns]."""

    def __init__(self, joining=False, cmd_vel_timeout_s=0.0, model=MODEL):
        self.now_ns = 0
        self.worker = OnlinePlanner(
            GaitPlanner(ROBOT, PARAMS), 0, lambda: self.now_ns,
            cover_s=HORIZON_S + PARAMS.step_period_s + 4.0, lead_s=HORIZON_S,
            standing_lead_s=0.6, failure_hold_s=lambda planner: HOLD_S)
        self.faults = Faults(self)
        self.core = PlannerSupervisor(
            ROBOT, self.worker, self.faults,
            SupervisorSettings(HORIZON_S, SAMPLE_PERIOD_S, cmd_vel_timeout_s), 0,
            joining=joining, load_model=lambda: model)
        self.outputs = []  # (tick [ns], Output)

    def tick(self, at_s: float):
        """The supervisor's tick at ``at_s`` [s]; its output."""
        self.now_ns = ns(at_s)
        output = self.core.tick(self.now_ns)
        self.outputs.append((self.now_ns, output))
        return output

    def run(self, from_s: float, until_s: float, period_s: float = 0.1):
        """Tick from ``from_s`` to ``until_s`` (included); the outputs."""
        count = int(round((until_s - from_s) / period_s)) + 1
        return [self.tick(from_s + k * period_s) for k in range(count)]

    def measure(self, state, at_s: float) -> bool:
        """The robot's state measured at ``at_s``; whether the supervisor asks for a tick."""
        self.now_ns = ns(at_s)
        pose, joints = state
        base = self.core.on_base(pose, self.now_ns)
        return self.core.on_joints(MODEL.joint_names, joints, self.now_ns) or base

    def plans(self, since_s: float = -1.0):
        """The footsteps published from ``since_s`` [s] on."""
        return [out.footsteps for t, out in self.outputs
                if out.footsteps is not None and t >= ns(since_s)]

    def reports(self, aspect: str, since_s: float = -1.0):
        """The statuses of ``aspect`` reported from ``since_s`` [s] on."""
        return [report for t, out in self.outputs for report in out.reports
                if report.aspect == aspect and t >= ns(since_s)]


def _lifts_ns(plan):
    return [plan.start_ns + ns(swing.lift_off_s) for swing in plan.swings()]


# --- joining a running graph ---------------------------------------------------------------


def test_a_joining_planner_waits_for_the_measured_state_and_plans_from_it():
    harness = Harness(joining=True)
    assert harness.core.listening
    assert not harness.run(0.0, 0.5)[-1].zmp_reference  # nothing heard of the robot yet
    state = robot_state(0.4, -0.2, 0.3)
    for k in range(3):  # 40 ms of a standing robot: not known to stand still yet
        harness.measure(state, 0.6 + 0.02 * k)
    output = harness.tick(0.65)
    assert output.footsteps is None and output.zmp_reference is None
    assert not harness.core.joined
    for k in range(3, 10):
        harness.measure(state, 0.6 + 0.02 * k)
    harness.tick(0.8)  # the plan from the measured state, made at once by this worker
    assert harness.core.joined and not harness.core.listening
    assert harness.worker.snapshot.origin_ns == ns(0.8)
    output = harness.tick(0.9)
    feet, _, com = forward_kinematics(*state)
    np.testing.assert_allclose(output.footsteps.positions_in_world[0], feet,
                               atol=NOMINAL_SNAP_M)
    # The ZMP reference starts under the measured COM, not at the nominal stand point.
    np.testing.assert_allclose(output.zmp_reference.zmp_in_world[0], com[:2], atol=1e-9)


def test_a_joining_planner_waits_for_a_foot_in_the_air_to_come_down():
    harness = Harness(joining=True)
    lifted = robot_state(0.1, 0.0, 0.0, lifted=True)
    assert forward_kinematics(*lifted)[0][REAR_LEFT, 2] > 0.03
    for k in range(40):  # standing still on three feet for 2 s
        harness.measure(lifted, 0.05 * k)
        if k % 2 == 0:
            assert harness.tick(0.05 * k).footsteps is None
    assert not harness.core.joined
    down = robot_state(0.1, 0.0, 0.0)
    for k in range(40, 46):
        harness.measure(down, 0.05 * k)
    harness.tick(2.3)
    assert harness.core.joined
    feet = forward_kinematics(*down)[0]
    plan = harness.tick(2.4).footsteps
    np.testing.assert_allclose(plan.positions_in_world[0], feet, atol=NOMINAL_SNAP_M)
    assert all(swing.start_in_world[2] < AIRBORNE_M for swing in plan.swings())


def test_a_foot_still_in_the_air_after_the_stand_wait_is_put_down_first():
    harness = Harness(joining=True)
    lifted = robot_state(0.1, 0.0, 0.0, lifted=True)
    for k in range(int(STAND_WAIT_S / 0.05) - 1):
        harness.measure(lifted, 0.05 * k)
        harness.tick(0.05 * k)
    assert not harness.core.joined
    harness.measure(lifted, STAND_WAIT_S)
    harness.tick(STAND_WAIT_S)
    assert harness.core.joined
    plan = harness.tick(STAND_WAIT_S + 0.1).footsteps
    first = min(plan.swings(), key=lambda swing: swing.lift_off_s)
    feet = forward_kinematics(*lifted)[0]
    assert first.foot == 'rear_left'
    np.testing.assert_allclose(first.start_in_world, feet[REAR_LEFT], atol=1e-9)
    assert abs(first.end_in_world[2]) < 1e-9  # on the ground


@pytest.mark.parametrize('model', [None, MODEL], ids=['no kinematics', 'no joint states'])
def test_a_joining_planner_with_the_base_pose_only_starts_at_the_nominal_stance_under_it(model):
    harness = Harness(joining=True, model=model)
    pose, _ = robot_state(0.4, -0.2, 0.3)
    harness.core.on_base(pose, 0)
    harness.tick(0.0)
    if model is not None:  # the joints may come yet: waited for JOIN_WAIT_S from the first tick
        assert all(out.footsteps is None for out in harness.run(0.1, JOIN_WAIT_S - 0.1))
        assert not harness.core.joined
        harness.tick(JOIN_WAIT_S)
    assert harness.core.joined  # (no kinematics: the pose is all it waits for)
    plan = harness.tick(JOIN_WAIT_S + 0.1).footsteps
    nominal = GaitPlanner(ROBOT, PARAMS, base_pose=(0.4, -0.2, 0.3)).footstep_plan()
    np.testing.assert_allclose(plan.positions_in_world[0], nominal.positions_in_world[0],
                               atol=1e-12)


def test_a_joining_planner_that_hears_nothing_starts_at_the_nominal_stance():
    harness = Harness(joining=True)
    assert all(out.footsteps is None for out in harness.run(0.0, JOIN_WAIT_S - 0.1))
    output = harness.tick(JOIN_WAIT_S)
    assert harness.core.joined and not harness.core.listening
    nominal = GaitPlanner(ROBOT, PARAMS).footstep_plan()
    np.testing.assert_allclose(output.footsteps.positions_in_world[0],
                               nominal.positions_in_world[0], atol=1e-12)


# --- pausing while the robot is held -------------------------------------------------------


def _walking(**settings) -> Harness:
    harness = Harness(**settings)
    harness.core.on_cmd_vel(Twist2D(0.05), 0)
    return harness


def _paused_walk():
    """A walk paused at 3.05 s (rear left in the air), held where the robot was measured."""
    harness = _walking()
    harness.run(0.0, 3.0)
    assert not harness.core.on_diagnostics([(IK, ())])  # fresh: nothing to do
    planned = harness.outputs[-1][1].zmp_reference.sample(np.array([ns(3.05)]))[0]
    assert harness.core.on_diagnostics([(IK, STALE)])  # stale mid-walk: tick at once
    output = harness.tick(3.05)
    assert harness.core.paused and harness.core.listening
    walk = harness.reports('walk')
    assert [(r.level, r.message) for r in walk] == [
        (WARN, 'paused: whole_body_ik: inputs stale; holding the robot where it stands')]
    # Not measured yet: the ZMP held where the plan had it.
    assert output.footsteps is None
    np.testing.assert_allclose(output.zmp_reference.zmp_in_world, [planned, planned])
    state = robot_state(0.02, 0.01, 0.05, lifted=True)
    pose, joints = state
    assert not harness.core.on_base(pose, ns(3.07))  # the joints not yet
    assert harness.core.on_joints(MODEL.joint_names, joints, ns(3.08))  # hold at once
    return harness, state


def test_a_stale_dependency_pauses_the_walk_holding_the_measured_footholds_and_com():
    harness, state = _paused_walk()
    output = harness.tick(3.08)
    feet, yaws, com = forward_kinematics(*state)
    np.testing.assert_allclose(output.footsteps.positions_in_world, feet[None], atol=1e-12)
    np.testing.assert_allclose(output.footsteps.yaws_rad, yaws[None], atol=1e-12)
    reference = output.zmp_reference
    assert reference.stamps_ns[0] == ns(3.08)
    assert reference.stamps_ns[-1] >= ns(3.08 + HORIZON_S)
    np.testing.assert_allclose(reference.zmp_in_world, np.tile(com[:2], (2, 1)), atol=1e-12)
    # On the plane of the lowest foot on the ground.
    assert feet[REAR_LEFT, 2] > AIRBORNE_M
    on_ground = np.delete(feet[:, 2], REAR_LEFT)
    np.testing.assert_allclose(reference.plane_heights_m, on_ground.min(), atol=1e-12)
    # Held while the report stays stale: the plan does not run on.
    for output in harness.run(3.1, 6.0):
        assert output.footsteps is None
        np.testing.assert_allclose(output.zmp_reference.zmp_in_world, np.tile(com[:2], (2, 1)))
    assert harness.core.paused


def test_a_dependency_not_yet_fed_once_pauses_nothing():
    # (the graph starting: the IK has no COM reference before the planner's first plan)
    harness = _walking()
    harness.run(0.0, 3.0)
    assert not harness.core.on_diagnostics([(IK, STALE)])
    harness.run(3.1, 4.0)
    assert not harness.core.paused and not harness.reports('walk')
    assert harness.plans(3.1)  # walking on


def test_a_paused_walk_resumes_after_resume_after_s_of_fresh_reports_from_the_measured_state():
    harness, state = _paused_walk()
    harness.run(3.1, 4.0)
    harness.core.on_diagnostics([(IK, ())])
    harness.tick(4.0)  # fresh from here
    harness.measure(state, 4.1)
    for output in harness.run(4.1, 4.0 + RESUME_AFTER_S - 0.1):
        assert harness.core.paused and output.footsteps is None
    output = harness.tick(4.0 + RESUME_AFTER_S)
    assert not harness.core.paused and not harness.core.listening
    report = harness.reports('walk')[-1]
    assert report.level == OK and report.message == (
        "walking on after a pause of 1.45 s, planned from the robot's measured state")
    # The plan from the measured state: the footholds where they were measured, the foot held
    # in the air put down first.
    feet, _, com = forward_kinematics(*state)
    np.testing.assert_allclose(output.footsteps.positions_in_world[0], feet,
                               atol=NOMINAL_SNAP_M)
    first = min(output.footsteps.swings(), key=lambda swing: swing.lift_off_s)
    assert first.foot == 'rear_left' and abs(first.end_in_world[2]) < 1e-9
    np.testing.assert_allclose(output.zmp_reference.zmp_in_world[0], com[:2], atol=1e-9)
    harness.run(4.6, 8.0)  # and walks on at the asked velocity
    assert harness.core.planner.twist == Twist2D(0.05)


def test_a_paused_walk_resumes_only_from_a_state_measured_after_the_reports_are_fresh():
    harness, state = _paused_walk()
    harness.core.on_diagnostics([(IK, ())])
    harness.run(3.1, 5.0)  # fresh since 3.1, measured last at 3.08
    assert harness.core.paused
    harness.measure(state, 5.05)
    harness.tick(5.1)
    assert not harness.core.paused


def test_a_stale_spell_shorter_than_a_tick_keeps_the_walk_paused():
    harness, state = _paused_walk()
    harness.core.on_diagnostics([(IK, ())])
    harness.run(3.1, 3.3)  # fresh since 3.1
    harness.core.on_diagnostics([(IK, STALE)])
    harness.core.on_diagnostics([(IK, ())])  # stale and fresh again between two ticks
    harness.tick(3.4)
    harness.tick(3.5)  # fresh since 3.5
    harness.measure(state, 3.55)
    harness.run(3.6, 3.5 + RESUME_AFTER_S - 0.1)
    assert harness.core.paused
    harness.tick(3.5 + RESUME_AFTER_S)
    assert not harness.core.paused


def test_a_resume_that_fails_keeps_the_walk_paused_and_is_tried_again(monkeypatch):
    harness, state = _paused_walk()
    harness.core.on_diagnostics([(IK, ())])
    harness.run(3.1, 4.0)
    tries = []

    def failing(*args, **kwargs):
        tries.append(harness.now_ns)
        raise GaitParameterError('no plan from there')

    anew = GaitPlanner.anew
    monkeypatch.setattr(GaitPlanner, 'anew', failing)
    harness.measure(state, 4.05)
    output = harness.tick(4.1)
    assert tries == [ns(4.1)] and harness.core.paused
    name, error, holding = harness.faults.failures[-1]
    assert name == 'resume plan' and str(error) == 'no plan from there'
    assert holding.startswith('the walk stays paused')
    com = forward_kinematics(*state)[2]
    np.testing.assert_allclose(output.zmp_reference.zmp_in_world, np.tile(com[:2], (2, 1)))
    # Tried again RESUME_AFTER_S after the failure, from a state measured since.
    monkeypatch.setattr(GaitPlanner, 'anew', anew)
    harness.measure(state, 4.15)
    harness.run(4.2, 4.1 + RESUME_AFTER_S - 0.1)
    assert harness.core.paused and harness.faults.failing
    harness.tick(4.1 + RESUME_AFTER_S)
    assert not harness.core.paused
    harness.tick(4.2 + RESUME_AFTER_S)
    assert not harness.faults.failing


# --- failures ------------------------------------------------------------------------------


@pytest.mark.parametrize('where', ['callback', 'planning'])
def test_a_failure_holds_a_safe_stand_and_the_walk_recovers(monkeypatch, where):
    harness = _walking()
    harness.run(0.0, 3.0)  # rear left in the air, front left lifting off at 3.3 s
    failed_ns = ns(3.0)
    if where == 'callback':  # the node's guard caught an exception of one of its callbacks
        harness.faults.failed('tick', RuntimeError('boom'))
        assert harness.faults.failures[-1][2].startswith('stopped at a safe stand')
    else:  # the worker's planning ahead fails
        next_step = GaitPlanner._next_step

        def failing(self, *args, **kwargs):
            raise FloatingPointError('anything')

        monkeypatch.setattr(GaitPlanner, '_next_step', failing)
        harness.worker.cover_s += 1.0  # (the worker plans further ahead at once)
    output = harness.tick(3.0)
    if where == 'planning':
        assert [name for name, *_ in harness.faults.failures] == ['plan']
        monkeypatch.setattr(GaitPlanner, '_next_step', next_step)
    plan = output.footsteps
    # No foot lifts off any more during the stand (the one in the air lands) ...
    assert plan.swings() and all(lift <= failed_ns or lift >= failed_ns + ns(HOLD_S) - ns(0.1)
                                 for lift in _lifts_ns(plan))
    # ... and the ZMP stays inside the support polygon of the feet down.
    reference = output.zmp_reference
    times_s = (reference.stamps_ns - plan.start_ns) * 1e-9
    assert zmp_depths(plan, times_s, reference.zmp_in_world).min() > 0.0
    harness.run(3.1, 3.0 + HOLD_S + 3.0)
    assert not harness.faults.failing  # planned past the stand: recovered
    assert any(lift > failed_ns + ns(HOLD_S) for plan in harness.plans(3.1)
               for lift in _lifts_ns(plan))


# --- watchdogs -----------------------------------------------------------------------------


def test_the_cmd_vel_watchdog_stops_the_walk_and_the_next_cmd_vel_walks_it_again():
    harness = _walking(cmd_vel_timeout_s=1.0)
    harness.run(0.0, 1.0)
    assert not harness.reports('inputs')
    harness.tick(1.1)
    [report] = harness.reports('inputs')
    assert report.level == WARN and not report.logged
    assert report.message.startswith('no /cmd_vel for 1.1 s (> 1 s): stopping')
    harness.run(1.2, 12.0)
    assert harness.core.planner.twist.is_zero()
    last = harness.plans()[-1]
    assert all(lift < ns(12.0) for lift in _lifts_ns(last))  # standing
    for k in range(80):  # streamed again
        harness.core.on_cmd_vel(Twist2D(0.05), ns(12.05 + 0.1 * k))
        harness.tick(12.1 + 0.1 * k)
        assert harness.reports('inputs')[-1].level == OK
    assert harness.core.planner.twist == Twist2D(0.05)
    assert any(lift > ns(12.0) for plan in harness.plans(12.1) for lift in _lifts_ns(plan))


def test_without_a_cmd_vel_timeout_the_last_cmd_vel_walks_on():
    harness = _walking()
    harness.run(0.0, 12.0)
    assert not harness.reports('inputs')
    assert any(lift > ns(12.0) for lift in _lifts_ns(harness.plans()[-1]))


def test_a_swing_without_its_trajectory_is_reported_until_the_next_one_comes():
    harness = _walking()
    harness.run(0.0, 2.7)
    assert not harness.reports('swing inputs')
    harness.tick(2.8)  # the rear left lifted off at 2.7 s: nothing was heard of it
    [report] = harness.reports('swing inputs')
    assert report.level == WARN and report.message.startswith(
        'no /gait/swing_trajectory for the swing of rear_left lifting off at 2.700 s')
    harness.core.on_swing('front_left', ns(3.3), ns(3.2))
    harness.run(2.9, 3.5)
    assert [r.level for r in harness.reports('swing inputs')] == [WARN, OK]


def test_a_clock_jump_restarts_the_plan_from_standstill():
    harness = _walking()
    harness.run(0.0, 4.0)
    output = harness.tick(16.0)
    [report] = harness.reports('clock')
    assert report.level == WARN
    assert report.message == 'the clock jumped by 12.000 s; the plan restarts from standstill'
    assert output.footsteps is None and harness.worker.snapshot.origin_ns == ns(16.0)
    plan = harness.tick(16.1).footsteps
    assert plan.start_ns >= ns(16.0) and all(lift > ns(16.1) for lift in _lifts_ns(plan))
