"""com_preview_controller in the inproc runtime: tracking, continuity, bad input, parameters."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from com_references import NS_PER_S, biped_walk_vertices, sample_vertices, window

from gait_nodes import contract, runtime
from gait_nodes.com_preview_controller import (
    DEFAULTS,
    MAX_CATCH_UP_TICKS,
    ComPreviewController,
    plan_yaw,
)
from gait_nodes.diagnostics import level_value
from gait_nodes.interfaces import get_message
from gait_nodes.runtime import Parameter, QoSProfile, qos_profile_latched

HERE = Path(__file__).resolve().parent
BIPED = str(HERE / 'data' / 'robots' / 'biped.yaml')
QUADRUPED = str(HERE / 'data' / 'robots' / 'quadruped.yaml')
G = 9.81
ZC = 0.814
DT = 0.005


@pytest.fixture
def start():
    """``start(*ros_args)``: the inproc runtime with those arguments; shut down afterwards."""

    def init(*ros_args):
        runtime.init(args=['test', '--ros-args', *ros_args], runtime='inproc',
                     signal_handlers=False)

    yield init
    runtime.shutdown()


class Planner(runtime.Node):
    """Publishes a 1.8 s window of a piecewise-linear ZMP plan every 50 ms (20 ms samples)."""

    def __init__(self, plan):
        super().__init__('test_planner', use_global_arguments=False)
        self.plan = plan
        self.publisher = self.create_publisher(get_message('nav_msgs/msg/Path'),
                                               '/gait/zmp_reference', 10)
        self.extra = []  # messages to publish before the next good one
        self.create_timer(0.05, self.publish)

    def publish(self):
        """Publish the queued extra messages, then the window at now."""
        for msg in self.extra:
            self.publisher.publish(msg)
        self.extra = []
        now = self.get_clock().now().nanoseconds
        self.publisher.publish(contract.zmp_reference_to_msg(window(*self.plan, now, 1.8, 0.02)))


class Recorder(runtime.Node):
    """Keeps /gait/com_reference states and /diagnostics statuses."""

    def __init__(self):
        super().__init__('test_recorder', use_global_arguments=False)
        self.states, self.statuses = [], []
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 '/gait/com_reference', self.on_com, QoSProfile(depth=100))
        self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics', self.on_diagnostics, QoSProfile(depth=100))

    def on_com(self, msg):
        """Keep the state at the header stamp."""
        self.states.append(contract.com_reference_from_msg(msg)[0])

    def on_diagnostics(self, msg):
        """Keep every status."""
        self.statuses.extend(msg.status)

    def arrays(self):
        """Stamps [s], positions, velocities, accelerations (N, 3) of what was received."""
        stamps = np.array([s.stamp_ns for s in self.states]) * 1e-9
        return (stamps, *(np.array([getattr(s, name) for s in self.states]) for name in (
            'position_in_world', 'velocity_in_world', 'acceleration_in_world')))


def run(plan, seconds, actions=(), node_args=()):
    """Run controller + planner + recorder for ``seconds``; ``actions``: (time_s, fn(ctx))."""
    controller = ComPreviewController()
    planner, recorder = Planner(plan), Recorder()
    executor = runtime.SingleThreadedExecutor()
    for node in (controller, planner, recorder):
        executor.add_node(node)
    context = {'controller': controller, 'planner': planner, 'recorder': recorder}
    elapsed = 0.0
    for at_s, action in sorted(actions, key=lambda a: a[0]):
        executor.spin_for(at_s - elapsed)
        elapsed = at_s
        action(context)
    executor.spin_for(seconds - elapsed)
    return context


def tracking_error(recorder, plan):
    stamps, position, _, acceleration = recorder.arrays()
    zmp = position[:, :2] - ZC / G * acceleration[:, :2]
    return zmp - sample_vertices(*plan, stamps)


def assert_no_jump(recorder, position_m=2e-4, velocity_m_s=0.01, acceleration_m_s2=0.5):
    """Consecutive horizontal states agree with one tick of integration: nothing jumps."""
    stamps, position, velocity, acceleration = (a[:, :2] if a.ndim == 2 else a
                                                for a in recorder.arrays())
    np.testing.assert_allclose(np.diff(stamps), DT, atol=1e-9)
    predicted = position[:-1] + velocity[:-1] * DT + acceleration[:-1] * DT * DT / 2
    assert np.max(np.abs(position[1:] - predicted)) < position_m
    assert np.max(np.abs(np.diff(velocity, axis=0) - acceleration[:-1] * DT)) < velocity_m_s
    assert np.max(np.abs(np.diff(acceleration, axis=0))) < acceleration_m_s2


def test_preview_com_tracks_the_reference_every_tick(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=8, rest_after_s=2.0)
    context = run(plan, 10.0)
    recorder = context['recorder']
    stamps, position, velocity, _ = recorder.arrays()
    # One state per 5 ms tick from the first reference on, at the robot's COM height.
    assert len(stamps) >= int(9.9 / DT)
    np.testing.assert_allclose(np.diff(stamps), DT, atol=1e-9)
    np.testing.assert_allclose(position[:, 2], ZC)
    assert all(s.yaw_rad == 0.0 for s in recorder.states)
    error = tracking_error(recorder, plan)
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) <= 0.010)
    assert np.max(np.abs(error)) <= 0.030
    np.testing.assert_allclose(position[-1, :2], plan[1][-1], atol=2e-3)
    np.testing.assert_allclose(velocity[-1], 0.0, atol=2e-3)
    statuses = [s for s in recorder.statuses if s.name.endswith('controller')]
    assert statuses and level_value(statuses[-1].level) == 0


def test_polynomial_method_tracks_the_reference(start):
    start('-p', f'robot:={BIPED}', '-p', 'com_method:=polynomial')
    plan = biped_walk_vertices(steps=4)
    recorder = run(plan, 7.0)['recorder']
    error = tracking_error(recorder, plan)
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) <= 0.010)
    assert_no_jump(recorder)


def test_sway_method_is_continuous_and_comes_to_rest(start):
    start('-p', f'robot:={BIPED}', '-p', 'com_method:=sway')
    plan = biped_walk_vertices(steps=4)
    context = run(plan, 8.4)
    recorder = context['recorder']
    assert_no_jump(recorder, acceleration_m_s2=2.0)
    error = tracking_error(recorder, plan)
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) <= 0.010)
    _, position, velocity, _ = recorder.arrays()
    np.testing.assert_allclose(position[-1, :2], plan[1][-1], atol=5e-3)
    np.testing.assert_allclose(velocity[-1], 0.0, atol=5e-3)
    generator = context['controller']._generator
    assert generator.sway_plans > 0


def test_method_and_parameter_switches_mid_walk_do_not_jump(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=6)
    results = []

    def setter(**values):
        def apply(context):
            parameters = [Parameter(name, value=value) for name, value in values.items()]
            results.append(context['controller'].set_parameters(parameters))
        return apply

    actions = [(3.1, setter(com_method='polynomial')), (4.37, setter(com_method='preview')),
               (5.02, setter(R=1e-5, preview_s=1.2)), (5.61, setter(com_method='sway')),
               (5.93, setter(com_method='polynomial', com_height_m=0.8)),
               (6.51, setter(com_method='preview'))]
    recorder = run(plan, 10.0, actions)['recorder']
    assert all(r.successful for batch in results for r in batch)
    assert_no_jump(recorder, acceleration_m_s2=2.0)
    _, position, velocity, _ = recorder.arrays()
    np.testing.assert_allclose(position[-1, :2], plan[1][-1], atol=2e-3)


def test_plan_change_keeps_the_state(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=6)
    shorter = biped_walk_vertices(steps=5, step_m=[0.3] * 3 + [0.2] * 2)

    def change(context):
        context['planner'].plan = shorter

    recorder = run(plan, 9.0, [(3.5, change)])['recorder']
    assert_no_jump(recorder)
    _, position, velocity, _ = recorder.arrays()
    np.testing.assert_allclose(position[-1, :2], shorter[1][-1], atol=2e-3)


def bad_references(now_ns):
    """One message per bad-input case, each with the reason expected in the report."""
    times, points = biped_walk_vertices(steps=8)
    good = contract.zmp_reference_to_msg(window(times, points, now_ns, 1.8, 0.02))
    cases = []
    nan = contract.zmp_reference_to_msg(window(times, points, now_ns, 1.8, 0.02))
    nan.poses[5].pose.position.y = math.nan
    cases.append((nan, 'NaN'))
    shuffled = contract.zmp_reference_to_msg(window(times, points, now_ns, 1.8, 0.02))
    shuffled.poses[3].header.stamp, shuffled.poses[4].header.stamp = \
        shuffled.poses[4].header.stamp, shuffled.poses[3].header.stamp
    cases.append((shuffled, 'increasing'))
    empty = get_message('nav_msgs/msg/Path')()
    empty.header.frame_id = 'odom'
    cases.append((empty, 'no poses'))
    short = contract.zmp_reference_to_msg(window(times, points, now_ns, 1.0, 0.02))
    cases.append((short, 'shorter than preview_s'))
    wrong_frame = contract.zmp_reference_to_msg(window(times, points, now_ns, 1.8, 0.02))
    wrong_frame.header.frame_id = 'base_link'
    cases.append((wrong_frame, 'frame'))
    old = contract.zmp_reference_to_msg(window(times, points, now_ns - NS_PER_S, 1.8, 0.02))
    cases.append((old, 'out of order'))
    for msg, _ in cases:
        # Far-off content: if any of them were used, the COM would leave the walk.
        for pose in msg.poses:
            if math.isfinite(pose.pose.position.x):
                pose.pose.position.x += 5.0
    return good, cases


def test_every_bad_reference_is_dropped_and_reported(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=2)
    clean = run(plan, 4.0)['recorder']
    runtime.shutdown()
    start('-p', f'robot:={BIPED}')
    reasons = []

    def inject(context):
        now = context['controller'].get_clock().now().nanoseconds
        _, cases = bad_references(now + 20_000_000)
        context['planner'].extra = [msg for msg, _ in cases]
        reasons.extend(reason for _, reason in cases)

    noisy = run(plan, 4.0, [(2.5, inject)])['recorder']
    # The COM is exactly the one of the clean run: bad input changed nothing.
    np.testing.assert_array_equal(clean.arrays()[1], noisy.arrays()[1])
    drops = [s for s in noisy.statuses if 'dropped' in s.message]
    assert len(drops) == len(reasons)
    for status, reason in zip(drops, reasons, strict=True):
        assert reason in status.message, (reason, status.message)
        assert level_value(status.level) == 1
        values = {kv.key: kv.value for kv in status.values}
        assert values['topic'] == '/gait/zmp_reference'


REFUSED = [
    ('R', 0.0, 'R'), ('R', -1e-6, 'R'), ('Q', -1.0, 'Q'), ('dt_s', 0.0, 'dt_s'),
    ('preview_s', 0.001, 'shorter than one step'), ('com_method', 'spline', 'com_method'),
    ('com_height_m', -0.5, 'com_height_m'), ('robot', 'no_such_robot', 'no_such_robot'),
]


def test_unusable_parameters_are_refused_and_nothing_changes(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=2)
    results = []

    def attempt(context):
        node = context['controller']
        for name, value, _ in REFUSED:
            result = node.set_parameters([Parameter(name, value=value)])[0]
            results.append((result, node.get_parameter(name).value))

    context = run(plan, 3.0, [(2.5, attempt)])
    for (result, kept), (name, _, reason) in zip(results, REFUSED, strict=True):
        assert not result.successful, name
        assert reason in result.reason, (name, result.reason)
        assert kept == (DEFAULTS[name] if name != 'robot' else BIPED)
    assert_no_jump(context['recorder'])


def test_com_height_comes_from_the_robot_yaml(start):
    start('-p', f'robot:={QUADRUPED}')
    plan = biped_walk_vertices(steps=1)
    recorder = run(plan, 1.0)['recorder']
    np.testing.assert_allclose(recorder.arrays()[1][:, 2], 0.6)


def test_yaw_follows_the_footstep_plan(start):
    start('-p', f'robot:={BIPED}')
    times = np.array([0.0, 1.0, 2.0, 3.0])
    yaws = np.array([[0.0, 0.0], [0.0, 0.0], [0.4, 0.0], [0.4, 0.4]])
    positions = np.zeros((4, 2, 3))
    positions[:, 0, 1], positions[:, 1, 1] = 0.1, -0.1
    plan = contract.FootstepPlan(0, ('left', 'right'), times, positions, yaws)
    context = {}

    def publish_plan(ctx):
        node = ctx['controller']
        publisher = node.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/footsteps',
            qos_profile_latched)
        publisher.publish(contract.footsteps_to_msg(plan))
        context.update(ctx)

    recorder = run(biped_walk_vertices(steps=1), 4.0, [(0.01, publish_plan)])['recorder']
    for state in recorder.states:
        t = state.stamp_ns * 1e-9
        expected, rate = plan_yaw(plan, t)
        assert state.yaw_rad == pytest.approx(expected, abs=1e-9)
        assert state.yaw_rate_rad_s == pytest.approx(rate, abs=1e-9)
    assert recorder.states[-1].yaw_rad == pytest.approx(0.4)
    assert any(s.yaw_rate_rad_s > 0 for s in recorder.states)


def test_shipped_defaults_match_the_declared_parameters():
    path = HERE.parent / 'config' / 'com_preview_controller.yaml'
    shipped = yaml.safe_load(path.read_text())['com_preview_controller']['ros__parameters']
    assert shipped == DEFAULTS


@pytest.mark.parametrize('method', ['preview', 'polynomial'])
def test_a_controller_starved_of_ticks_publishes_no_state_from_the_future(start, method):
    # On two overloaded cores a node process can miss its timer for more than
    # MAX_CATCH_UP_TICKS periods (0.6 s seen over DDS). The controller then starts again at
    # the clock; it once also stepped the ticks it had missed from there, and published a COM
    # state 0.3 s ahead of the clock (stamped in the future, the next one 0.3 s earlier): the
    # whole-body IK followed a COM that ran ahead, then dropped back.
    start('-p', f'robot:={BIPED}', '-p', f'com_method:={method}')
    plan = biped_walk_vertices(steps=6)
    starved_s = (MAX_CATCH_UP_TICKS + 10) * DT
    received = []  # (clock at delivery [ns], stamp [ns])

    def starve(context):
        controller = context['controller']
        controller.destroy_timer(controller._timer)
        recorder = context['recorder']
        recorder.create_subscription(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), '/gait/com_reference',
            lambda msg: received.append((recorder.get_clock().now().nanoseconds,
                                         contract.time_msg_to_ns(msg.header.stamp))),
            QoSProfile(depth=100))

    def resume(context):
        controller = context['controller']
        controller._timer = controller.create_timer(DT, controller._tick)

    context = run(plan, 6.0, [(3.0, starve), (3.0 + starved_s, resume)])
    clock_ns, stamps_ns = np.array(received).T
    assert len(stamps_ns) > 300
    # Every state describes an instant the clock has reached, and time never runs back.
    assert np.all(stamps_ns <= clock_ns)
    assert np.all(np.diff(stamps_ns) > 0)
    # After the gap the states go on from the clock, one tick apart.
    np.testing.assert_allclose(np.diff(stamps_ns[1:]), DT * NS_PER_S)
    assert stamps_ns[0] - int(3.0 * NS_PER_S) >= starved_s * NS_PER_S - DT * NS_PER_S
    # The gap is reported, with how far behind the controller was.
    late = [s for s in context['recorder'].statuses if s.name.endswith('controller')
            and 'behind the clock' in s.message]
    assert late and level_value(late[0].level) == 1
    values = {kv.key: kv.value for kv in late[0].values}
    assert float(values['behind_s']) >= starved_s - DT
