"""footstep_planner node in the inproc runtime, judged only from its messages.

The published footsteps and ZMP reference are re-read through the contract converters and checked
as a recorded bag would be: the ZMP lies in the support polygon of the scheduled contacts with the
margin, footholds follow the command, a change waits for the step boundary, and every bad input
is refused with a reason while the published plan stays byte-identical.
"""

import json
import math

import numpy as np
import pytest
from planning_helpers import BIPED, QUADRUPED, zmp_margins

from gait_nodes import runtime
from gait_nodes.contract import footsteps_from_msg, zmp_reference_from_msg
from gait_nodes.diagnostics import level_value
from gait_nodes.interfaces import get_message
from gait_nodes.runtime import Parameter, qos_profile_latched

NS = 1_000_000_000


def twist_msg(vx, vy=0.0, wz=0.0):
    msg = get_message('geometry_msgs/msg/Twist')()
    msg.linear.x, msg.linear.y, msg.angular.z = vx, vy, wz
    return msg


class Graph:
    """The planner and a user node that sends commands and keeps everything it hears."""

    def __init__(self, robot_path, **params):
        args = ['test', '--ros-args', '-p', f'robot:={robot_path}']
        for name, value in params.items():
            args += ['-p', f'{name}:={value}']
        runtime.init(args=args, runtime='inproc', signal_handlers=False)
        from gait_nodes.footstep_planner import FootstepPlanner

        self.planner = FootstepPlanner()
        self.user = runtime.Node('user', use_global_arguments=False)
        self.footsteps, self.zmp, self.status, self.diagnostics = [], [], [], []
        self.user.create_subscription(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/footsteps',
            lambda data: self.footsteps.append(data), qos_profile_latched, raw=True)
        self.user.create_subscription(get_message('nav_msgs/msg/Path'), '/gait/zmp_reference',
                                      lambda data: self.zmp.append(data), 10, raw=True)
        self.user.create_subscription(get_message('std_msgs/msg/String'),
                                      '/gait/command_status',
                                      lambda msg: self.status.append(json.loads(msg.data)), 10)
        self.user.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                      '/diagnostics', self.diagnostics.append, 10)
        self.cmd_vel = self.user.create_publisher(get_message('geometry_msgs/msg/Twist'),
                                                  '/cmd_vel', 10)
        self.command_publisher = self.user.create_publisher(
            get_message('std_msgs/msg/String'), '/gait/command', 10)
        self.executor = runtime.SingleThreadedExecutor()
        self.executor.add_node(self.planner)
        self.executor.add_node(self.user)

    def spin(self, seconds):
        """Run the graph for ``seconds`` of simulated time."""
        self.executor.spin_for(seconds)

    def command(self, text):
        """Publish a /gait/command and return its answer."""
        self.command_publisher.publish(get_message('std_msgs/msg/String')(data=text))
        self.spin(0.001)
        return self.status[-1]

    def plans(self):
        """Every /gait/footsteps message heard, as FootstepPlan."""
        msg_type = get_message('trajectory_msgs/msg/MultiDOFJointTrajectory')
        return [footsteps_from_msg(msg_type.deserialize(data)) for data in self.footsteps]

    def references(self):
        """Every /gait/zmp_reference heard, as ZmpReference."""
        msg_type = get_message('nav_msgs/msg/Path')
        return [zmp_reference_from_msg(msg_type.deserialize(data)) for data in self.zmp]

    def statuses(self, name_part):
        """Diagnostic statuses whose name contains ``name_part``."""
        return [s for array in self.diagnostics for s in array.status if name_part in s.name]


@pytest.fixture
def quadruped():
    graph = Graph(QUADRUPED, step_period_s=1.0, max_vx_m_s=0.5, max_wz_rad_s=0.5)
    yield graph
    runtime.shutdown()


@pytest.fixture
def biped():
    graph = Graph(BIPED, step_period_s=0.8, duty_factor=0.9, max_vx_m_s=0.5)
    yield graph
    runtime.shutdown()


def merged_plan(plans):
    """One plan from successive messages: each message replaces everything from its start on."""
    points = {}
    for plan in plans:
        points = {stamp: value for stamp, value in points.items() if stamp < plan.start_ns}
        for k, t in enumerate(plan.times_s):
            points[plan.start_ns + int(round(t * NS))] = (plan.positions_in_world[k],
                                                          plan.yaws_rad[k])
    from gait_nodes.contract import FootstepPlan

    stamps = sorted(points)
    return FootstepPlan(stamps[0], plans[-1].foot_names,
                        (np.array(stamps) - stamps[0]) / NS,
                        np.array([points[s][0] for s in stamps]),
                        np.array([points[s][1] for s in stamps]))


def check_zmp_inside(graph, foot_radius_m, margin_m, plan=None):
    plan = plan or merged_plan(graph.plans())
    for reference in graph.references()[::10]:
        # Every 10 ms between its corners (the consumers interpolate linearly).
        stamps = np.arange(reference.stamps_ns[0], reference.stamps_ns[-1] + 1, 10_000_000)
        times = (stamps - plan.start_ns) / NS
        inside = (times >= 0) & (times <= plan.end_s)
        if not inside.any():
            continue
        margins = zmp_margins(plan, times[inside], reference.sample(stamps)[inside],
                              foot_radius_m)
        assert margins.min() >= margin_m - 1e-9


def test_walk_publishes_the_contract(quadruped):
    quadruped.spin(1.0)
    quadruped.cmd_vel.publish(twist_msg(0.1, 0.0, 0.05))
    quadruped.spin(9.0)
    references = quadruped.references()
    assert 90 <= len(references) <= 102  # every tick at 10 Hz
    for reference in references[::10]:
        assert reference.horizon_s >= 2.5 - 1e-9
        # The corners of the planner's 10 ms samples: far fewer than the 251 samples.
        assert np.all(np.diff(reference.stamps_ns) % 10_000_000 == 0)
        assert len(reference.stamps_ns) < 60
    plans = quadruped.plans()
    assert 5 < len(plans) < len(references)  # latched plan, republished when it changes
    plan = merged_plan(plans)
    assert len(plan.swings()) >= 8
    check_zmp_inside(quadruped, 0.055, 0.01, plan)
    # Footholds follow the turn: the yaw change per swing is wz T in steady state.
    turns = [s.end_yaw_rad - s.start_yaw_rad for s in plan.swings()]
    assert max(turns) == pytest.approx(0.05 * 2.0, abs=1e-6)
    # A late joiner gets the latest plan at once.
    late = runtime.Node('late', use_global_arguments=False)
    heard = []
    late.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                             '/gait/footsteps', heard.append, qos_profile_latched)
    quadruped.executor.add_node(late)
    quadruped.executor.spin_once()
    assert len(heard) == 1
    assert heard[0].serialize() == quadruped.footsteps[-1]


def test_zero_velocity_ends_in_standstill_with_every_foot_down(biped):
    biped.cmd_vel.publish(twist_msg(0.1))
    biped.spin(6.0)
    biped.cmd_vel.publish(twist_msg(0.0))
    biped.spin(6.0)
    plan = merged_plan(biped.plans())
    last = plan.positions_in_world[-1]
    assert last[0, 0] == pytest.approx(last[1, 0], abs=1e-9)  # feet side by side
    assert abs(last[0, 1] - last[1, 1]) == pytest.approx(0.2, abs=1e-9)
    reference = biped.references()[-1]
    assert np.ptp(reference.zmp_in_world, axis=0).max() < 1e-12  # at rest
    np.testing.assert_allclose(reference.zmp_in_world[0], last[:, :2].mean(axis=0), atol=1e-9)
    check_zmp_inside(biped, 0.05, 0.01, plan)


def test_a_command_waits_for_the_step_boundary_and_keeps_the_zmp_continuous(quadruped):
    quadruped.cmd_vel.publish(twist_msg(0.1))
    quadruped.spin(5.33)
    before = quadruped.references()[-1]
    status = quadruped.command('{"step_length_m": 0.15}')
    assert status['accepted'] and status['params']['step_length_m'] == 0.15
    quadruped.spin(0.02)
    after = quadruped.references()[-1]
    values = {v.key: v.value for v in quadruped.statuses('command')[-1].values}
    boundary_s = float(values['takes_effect_s'])
    boundary_ns = quadruped.planner.origin_ns + int(round(boundary_s * NS))
    common = np.intersect1d(before.stamps_ns, after.stamps_ns)
    a, b = before.sample(common), after.sample(common)
    early = common < boundary_ns
    assert early.any() and (~early).any()
    np.testing.assert_allclose(a[early], b[early], atol=1e-12)
    # Shorter steps: the reference moves less far, never by more than the step change.
    assert np.max(np.linalg.norm(a - b, axis=1)) <= 0.3 - 0.15 + 1e-9
    quadruped.spin(4.0)
    plan = merged_plan(quadruped.plans())
    late = [s for s in plan.swings() if s.lift_off_s * NS + plan.start_ns > boundary_ns + 2 * NS]
    assert late and max(s.end_in_world[0] - s.start_in_world[0] for s in late) <= 0.15 + 1e-9


BAD_COMMANDS = {
    '{"step_length_m": 0.2': 'invalid JSON',
    '["trot"]': 'JSON object',
    '{"speed": 0.3}': 'unknown key',
    '{"step_length_m": "long"}': 'number',
    '{"step_length_m": NaN}': 'finite',
    '{"step_period_s": Infinity}': 'finite',
    '{"step_period_s": 0}': 'minimum',
    '{"step_length_m": -0.2}': 'minimum',
    '{"duty_factor": 0.7}': 'duty_factor',
    '{"gait": "trot", "duty_factor": 0.5}': 'duty_factor',
    '{"step_length_m": 0.9}': 'reach',
    '{"gait": "biped"}': 'not possible',
    '{"zmp_margin_m": 0.3}': 'margin',
}


def run_session(bad: bool) -> tuple[list[bytes], list[bytes], list]:
    graph = Graph(QUADRUPED, step_period_s=1.0)
    try:
        graph.cmd_vel.publish(twist_msg(0.05))
        graph.spin(2.0)
        if bad:
            for text in BAD_COMMANDS:
                graph.command(text)
            nan = twist_msg(math.nan)
            graph.cmd_vel.publish(nan)
            graph.spin(0.001)
            result = graph.planner.set_parameters([Parameter('duty_factor', value=0.6)])[0]
            assert not result.successful and 'duty_factor' in result.reason
        graph.spin(3.0)
        return graph.footsteps, graph.zmp, graph.status, graph.diagnostics
    finally:
        runtime.shutdown()


def test_every_bad_input_is_refused_and_the_plan_stays_byte_identical():
    good_footsteps, good_zmp, _, _ = run_session(bad=False)
    footsteps, zmp, status, diagnostics = run_session(bad=True)
    assert footsteps == good_footsteps
    assert zmp == good_zmp
    assert len(status) == len(BAD_COMMANDS)
    for answer, (text, reason) in zip(status, BAD_COMMANDS.items(), strict=True):
        assert answer['accepted'] is False and answer['command'] == text
        assert reason in answer['reason'], (text, answer['reason'])
        assert answer['params']['duty_factor'] == 0.85
    drops = [s for array in diagnostics for s in array.status
             if s.name == 'footstep_planner: input /gait/command']
    assert len(drops) == len(BAD_COMMANDS)
    assert all(level_value(s.level) >= 1 for s in drops)
    nan_drops = [s for array in diagnostics for s in array.status
                 if s.name == 'footstep_planner: input /cmd_vel']
    assert len(nan_drops) == 1 and 'non-finite' in nan_drops[0].message


def test_trot_on_a_biped_is_refused(biped):
    biped.spin(0.1)
    status = biped.command('{"gait": "trot"}')
    assert not status['accepted'] and "'trot' is not possible" in status['reason']
    assert status['params']['gait'] == 'auto'


def test_excess_velocity_is_clamped_with_a_warning(quadruped):
    quadruped.cmd_vel.publish(twist_msg(3.0, 0.0, 0.0))
    quadruped.spin(6.0)
    warnings = quadruped.statuses('velocity')
    assert warnings and level_value(warnings[0].level) == 1
    assert 'clamped' in warnings[0].message
    plan = merged_plan(quadruped.plans())
    assert max(s.end_in_world[0] - s.start_in_world[0] for s in plan.swings()) \
        <= 0.3 + 1e-9


def test_ros_parameters_go_through_the_same_checks(quadruped):
    node = quadruped.planner
    assert not node.set_parameters([Parameter('step_length_m', value=-1.0)])[0].successful
    assert not node.set_parameters([Parameter('robot', value='other')])[0].successful
    assert not node.set_parameters([Parameter('zmp_horizon_s', value=1.0)])[0].successful
    assert not node.set_parameters([Parameter('duty_factor', value=0.6)])[0].successful  # crawl
    result = node.set_parameters_atomically([Parameter('gait', value='trot'),
                                             Parameter('duty_factor', value=0.6)])
    assert result.successful
    assert node.planner.params.gait == 'trot'
    assert node.get_parameter('duty_factor').value == 0.6
    assert node.set_parameters([Parameter('rate_hz', value=20.0)])[0].successful
    count = len(quadruped.zmp)
    quadruped.spin(1.0)
    assert 19 <= len(quadruped.zmp) - count <= 21


def test_published_footsteps_carry_every_swing_that_lifts_off_within_the_horizon():
    # A swing longer than the ZMP horizon (the crawl's value-table swings, 2.1 s > 2 s) must
    # reach the IK before its foot lifts off, not when its landing enters the horizon.
    from gait_nodes.contract import FootstepPlan
    from gait_nodes.footstep_planner import _HorizonCut

    _within = _HorizonCut()  # one cutter for every call, as the node has
    names = ('a', 'b')
    times = np.array([0.0, 0.5, 2.6, 3.0, 5.1])
    feet = np.zeros((5, 2, 3))
    feet[2:, 0, 0] = 0.3   # a swings 0.5 -> 2.6 s
    feet[4:, 1, 0] = 0.3   # b swings 3.0 -> 5.1 s
    plan = FootstepPlan(0, names, times, feet, np.zeros((5, 2)))
    ns = 1_000_000_000
    before_a = _within(plan, int(0.1 * ns), int(2.1 * ns))
    assert [s.foot for s in before_a.swings()] == ['a']
    assert before_a.times_s[-1] == pytest.approx(2.6)
    # Nothing lifts off within the horizon after a's landing: the plan ends with all feet down.
    assert _within(plan, int(0.1 * ns), int(0.4 * ns)).times_s[-1] == pytest.approx(0.0)
    # A swing lifting off inside the horizon is kept whole even when it lands far beyond it.
    late = _within(plan, int(1.0 * ns), int(3.0 * ns))
    assert [s.foot for s in late.swings()] == ['a', 'b']
    assert late.times_s[-1] == pytest.approx(5.1)
    # The cutter's memory of the plan changes nothing: a fresh one cuts the same.
    for now_s, until_s in [(0.1, 2.1), (0.1, 0.4), (1.0, 3.0), (0.1, 2.1), (4.0, 6.0)]:
        args = (int(now_s * ns), int(until_s * ns))
        kept, fresh = _within(plan, *args), _HorizonCut()(plan, *args)
        np.testing.assert_array_equal(kept.times_s, fresh.times_s)
        np.testing.assert_array_equal(kept.positions_in_world, fresh.positions_in_world)


def _cut_by_scanning(plan, now_ns: int, until_ns: int) -> int:
    """Points _HorizonCut keeps, by scanning every swing and point (its first form)."""
    ns = 1_000_000_000
    swings = [(s.lift_off_s, s.touch_down_s) for s in plan.swings()]
    until_s = max((now_ns - plan.start_ns) * 1e-9, (until_ns - plan.start_ns) * 1e-9)
    landing_s = max((touch for lift, touch in swings if lift <= until_s), default=0.0)
    until_ns = max(until_ns, plan.start_ns + int(round(landing_s * ns)))
    last = 0
    for k, t_s in enumerate(plan.times_s):
        if plan.start_ns + int(round(t_s * ns)) > until_ns:
            break
        if not any(lift < t_s < touch for lift, touch in swings):
            last = k
    return last + 1


def test_horizon_cut_by_bisection_keeps_what_a_scan_keeps():
    """The cut found by bisection on the plan's sorted times equals the scan's, over a walk."""
    from gait_nodes.footstep_planner import _HorizonCut
    from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
    from gait_nodes.robot.description import load_robot_description

    rng = np.random.default_rng(11)
    cut = _HorizonCut()
    for robot in (QUADRUPED, BIPED):
        planner = GaitPlanner(load_robot_description(robot))
        planner.set_velocity(Twist2D(0.05, 0.01, 0.05), 0.0)
        planner.advance(30.0)
        for start_s in (0.0, 3.0, 7.5):
            plan = planner.footstep_plan(start_s, 1_000)
            for now_s in np.sort(rng.uniform(start_s, start_s + 20.0, 60)):
                now_ns = 1_000 + int(now_s * 1e9)
                for horizon_ns in (0, int(0.5e9), int(2e9), int(rng.uniform(0, 6e9))):
                    kept = cut(plan, now_ns, now_ns + horizon_ns)
                    assert len(kept.times_s) == _cut_by_scanning(plan, now_ns,
                                                                 now_ns + horizon_ns)
                    assert np.array_equal(kept.positions_in_world,
                                          plan.positions_in_world[:len(kept.times_s)])
