"""A planning failure ends in a safe stand, not in a dead planner (issue 18, item 4).

The core: :meth:`GaitPlanner.stand` at any instant of any gait lifts no foot after it, keeps the
ZMP reference inside the support polygon of the feet down, and the walk planned after it goes on
from the stance with no step longer than a stride and none backwards. The node: a planning core
that raises (SwingPolicyError, or anything else) leaves the footstep_planner process running; it
reports the ERROR with the reason, stands, and walks on (OK) once planning works again. The
guard itself (:mod:`gait_nodes.faults`) on a node of its own.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import QUADRUPED, robot, zmp_margins

from gait_nodes import runtime
from gait_nodes.contract import footsteps_from_msg, zmp_reference_from_msg
from gait_nodes.diagnostics import ERROR, OK, DiagnosticsReporter, level_value
from gait_nodes.errors import SwingPolicyError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.interfaces import get_message
from gait_nodes.planning.footsteps import Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.runtime import qos_profile_latched

NS = 1_000_000_000
FAST = dict(step_period_s=1.0, max_vx_m_s=1.0, max_vy_m_s=1.0, max_wz_rad_s=1.0)
GAITS = {
    'crawl': ('quadruped', dict(gait='crawl', duty_factor=0.85, **FAST)),
    'trot': ('quadruped', dict(gait='trot', duty_factor=0.7, **FAST)),
    'biped': ('biped', dict(gait='biped', duty_factor=0.9, **FAST)),
}
HOLD_S = 3.0


@settings(max_examples=30, deadline=None)
@given(gait=st.sampled_from(sorted(GAITS)), now_s=st.floats(0.5, 8.0),
       vx=st.floats(0.05, 0.2))
def test_a_stand_lifts_no_foot_keeps_the_zmp_inside_and_the_walk_goes_on(gait, now_s, vx):
    name, values = GAITS[gait]
    description = robot(name)
    params = GaitParameters.for_robot(description, **values)
    planner = plan_walk(description, params, [(0.3, Twist2D(vx))], now_s + 3.0)
    planned = planner.footstep_plan()
    planner.stand(now_s, HOLD_S)
    assert planner.halted
    plan = planner.footstep_plan()
    stood_s = planner.steps[-1].end_s
    # No foot lifts off after the failure; a swing in the air lands where it was going.
    swings = plan.swings()
    assert all(s.lift_off_s <= now_s for s in swings)
    in_air = [s for s in planned.swings() if s.lift_off_s <= now_s < s.touch_down_s]
    for swing in in_air:
        assert any(s.foot == swing.foot and s.touch_down_s == swing.touch_down_s
                   and np.array_equal(s.end_in_world, swing.end_in_world) for s in swings)
    # The ZMP reference never leaves the support of the feet down, up to the end of the stand.
    times = np.linspace(0.0, stood_s, 2000)
    margins = zmp_margins(plan, times - plan.start_ns * 1e-9, planner.zmp(times),
                          description.foot_radius_m)
    assert margins.min() > 0.0
    # It ends at rest between the feet.
    np.testing.assert_allclose(planner.zmp(np.array([stood_s, stood_s + 5.0])),
                               planner.zmp(np.array([stood_s]))[[0, 0]], atol=1e-12)
    # The walk goes on after the stand: no step longer than a stride, none backwards.
    planner.advance(stood_s + 12.0)
    assert not planner.halted
    walked = [s for s in planner.footstep_plan().swings() if s.lift_off_s >= stood_s]
    stride = planner.twist.vx_m_s * params.cycle_s
    assert len(walked) >= 4
    for swing in walked:
        step = swing.end_in_world[:2] - swing.start_in_world[:2]
        assert np.linalg.norm(step) <= stride + 1e-9
        assert step[0] >= -1e-9


def test_a_new_velocity_ends_the_stand_at_once():
    description = robot('quadruped')
    params = GaitParameters.for_robot(description, **GAITS['crawl'][1])
    planner = plan_walk(description, params, [(0.3, Twist2D(0.1))], 6.0)
    planner.stand(5.0, HOLD_S)
    planner.set_velocity(Twist2D(0.12), 5.5)
    planner.advance(12.0)
    assert not planner.halted
    lifts = [s.lift_off_s for s in planner.footstep_plan().swings() if s.lift_off_s > 5.0]
    assert lifts and lifts[0] < 5.5 + params.step_period_s + 1.0


class _Flaky(GuardedNode):
    """A node whose tick raises while ``broken``, with a counter of its clean runs."""

    def __init__(self):
        super().__init__('flaky')
        self.diagnostics = DiagnosticsReporter(self)
        self.holds = []
        self.faults = FaultGuard(self, self.diagnostics, hold=self._hold)
        self.broken = False
        self.clean = 0
        self.create_timer(0.1, self.tick)

    def tick(self):
        if self.broken:
            raise ValueError('the core failed')
        self.clean += 1

    def _hold(self, exc):
        self.holds.append(exc)
        return 'holding'


def _statuses(diagnostics, name):
    return [(level_value(s.level), s.message) for array in diagnostics for s in array.status
            if s.name == name]


def test_a_guarded_callback_reports_holds_and_recovers():
    runtime.init(args=['test'], runtime='inproc', signal_handlers=False)
    try:
        node = _Flaky()
        listener = runtime.Node('listener', use_global_arguments=False)
        diagnostics = []
        listener.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                     '/diagnostics', diagnostics.append, 100)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        executor.add_node(listener)
        executor.spin_for(0.55)
        node.broken = True
        executor.spin_for(2.5)  # 25 failed ticks: held each time, reported once a second
        node.broken = False
        executor.spin_for(0.5)
    finally:
        runtime.shutdown()
    statuses = _statuses(diagnostics, 'flaky: faults')
    assert len(node.holds) == 25 and node.clean == 10
    errors = [m for level, m in statuses if level == ERROR]
    assert errors[0] == 'tick failed: ValueError: the core failed; holding'
    assert len(errors) == 3
    assert statuses[-1] == (OK, 'running again after 2.50 s of failures')


class _PlannerGraph:
    """The footstep planner alone and a listener, inproc; what it hears in arrival order."""

    def __init__(self):
        runtime.init(args=['test', '--ros-args', '-p', f'robot:={QUADRUPED}', '-p',
                           'step_period_s:=1.0', '-p', 'gait:=crawl', '-p', 'timing:=fixed'],
                     runtime='inproc', signal_handlers=False)
        from gait_nodes.footstep_planner import FootstepPlanner

        self.planner = FootstepPlanner()
        self.user = runtime.Node('user', use_global_arguments=False)
        self.heard, self.diagnostics = [], []
        self.user.create_subscription(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/footsteps',
            lambda msg: self.heard.append(footsteps_from_msg(msg)), qos_profile_latched)
        self.user.create_subscription(
            get_message('nav_msgs/msg/Path'), '/gait/zmp_reference',
            lambda msg: self.heard.append(zmp_reference_from_msg(msg)), 10)
        self.user.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                      '/diagnostics', self.diagnostics.append, 100)
        self.cmd_vel = self.user.create_publisher(get_message('geometry_msgs/msg/Twist'),
                                                  '/cmd_vel', 10)
        self.executor = runtime.SingleThreadedExecutor()
        self.executor.add_node(self.planner)
        self.executor.add_node(self.user)

    def walk(self, vx: float) -> None:
        twist = get_message('geometry_msgs/msg/Twist')()
        twist.linear.x = vx
        self.cmd_vel.publish(twist)

    def now_ns(self) -> int:
        return self.planner.get_clock().now().nanoseconds


@pytest.mark.parametrize('error', [SwingPolicyError('a swing to [...] leaves the reach of '
                                                    'the limbs'),
                                   FloatingPointError('anything else')])
def test_a_planner_that_cannot_plan_stands_says_why_and_walks_on(monkeypatch, error):
    graph = _PlannerGraph()
    try:
        graph.walk(0.1)
        graph.executor.spin_for(4.0)
        core = type(graph.planner.planner)
        next_step = core._next_step

        def failing(self, *args, **kwargs):
            raise error

        monkeypatch.setattr(core, '_next_step', failing)
        graph.executor.spin_for(4.0)  # tried again every second: it fails
        monkeypatch.setattr(core, '_next_step', next_step)
        fixed_ns = graph.now_ns()
        graph.executor.spin_for(6.0)
    finally:
        runtime.shutdown()
    errors = [(array.header.stamp, s.message) for array in graph.diagnostics
              for s in array.status
              if s.name == 'footstep_planner: faults' and level_value(s.level) == ERROR]
    assert len(errors) >= 3  # the failure, and each retry
    failed_ns = errors[0][0].sec * NS + errors[0][0].nanosec
    assert f'{type(error).__name__}: {error}' in errors[0][1] and 'safe stand' in errors[0][1]
    assert _statuses(graph.diagnostics, 'footstep_planner: faults')[-1][0] == OK
    # From the failure until planning works again: no foot lifts off (a swing in the air
    # lands), and every ZMP reference keeps the ZMP inside the support polygon of the plan.
    radius = robot('quadruped').foot_radius_m
    plan, checked = None, 0
    for item in graph.heard:
        if hasattr(item, 'foot_names'):
            plan = item
            continue
        # A ZMP reference starts at the tick that published it, after that tick's plan (a
        # plan's own start can be earlier: the stand it began).
        if failed_ns < item.stamps_ns[0] < fixed_ns:
            assert all(plan.start_ns + s.lift_off_s * NS <= failed_ns for s in plan.swings())
        if failed_ns <= item.stamps_ns[0] < fixed_ns:
            times = (item.stamps_ns - plan.start_ns) * 1e-9
            assert zmp_margins(plan, times, item.zmp_in_world, radius).min() > 0.0
            checked += 1
    assert checked > 30  # (3.4 s at 10 Hz)
    # Once it can plan again it walks on.
    assert any(plan.start_ns + s.lift_off_s * NS > fixed_ns for s in plan.swings())
