"""com_preview_controller in the inproc runtime: tracking, continuity, bad input, parameters."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from com_references import NS_PER_S, biped_walk_vertices, sample_vertices, window

from gait_nodes import contract, runtime
from gait_nodes.com_preview_controller import (
    MAX_CATCH_UP_TICKS,
    ComPreviewController,
    node_defaults,
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
#: Spacing of the published states [s].
DEFAULTS = node_defaults()
SAMPLE = DEFAULTS['sample_period_s']


@pytest.fixture
def start():
    """``start(*ros_args)``: the inproc runtime with those arguments; shut down afterwards."""

    def init(*ros_args):
        runtime.init(args=['test', '--ros-args', *ros_args], runtime='inproc',
                     signal_handlers=False)

    yield init
    runtime.shutdown()


class Planner(runtime.Node):
    """Publishes a ``length_s`` window of a piecewise-linear ZMP plan every 50 ms (20 ms samples).

    1.8 s (the default) covers preview_s but not preview_s + horizon_s: the controller then
    computes only as far as the reference allows.
    """

    def __init__(self, plan, length_s=1.8):
        super().__init__('test_planner', use_global_arguments=False)
        self.plan = plan
        self.length_s = length_s
        self.publisher = self.create_publisher(get_message('nav_msgs/msg/Path'),
                                               '/gait/zmp_reference', 10)
        self.extra = []  # messages to publish before the next good one
        self.silent = False  # True: the planner is gone
        self.create_timer(0.05, self.publish)

    def publish(self):
        """Publish the queued extra messages, then the window at now."""
        if self.silent:
            return
        for msg in self.extra:
            self.publisher.publish(msg)
        self.extra = []
        now = self.get_clock().now().nanoseconds
        self.publisher.publish(contract.zmp_reference_to_msg(
            window(*self.plan, now, self.length_s, 0.02)))


class Recorder(runtime.Node):
    """Keeps /gait/com_reference states, as a consumer holds them, and /diagnostics statuses.

    Each message replaces the states held from its first point on (a trajectory
    controller's rule); ``messages`` keeps (clock at delivery [ns], states) of every one.
    """

    def __init__(self):
        super().__init__('test_recorder', use_global_arguments=False)
        self.states, self.statuses, self.messages = [], [], []
        self.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 '/gait/com_reference', self.on_com, QoSProfile(depth=100))
        self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics', self.on_diagnostics, QoSProfile(depth=100))

    def on_com(self, msg):
        """Splice the message's states into the held ones."""
        states = contract.com_reference_from_msg(msg)
        self.messages.append((self.get_clock().now().nanoseconds, states))
        first_ns = states[0].stamp_ns
        while self.states and self.states[-1].stamp_ns >= first_ns:
            self.states.pop()
        self.states.extend(states)

    def on_diagnostics(self, msg):
        """Keep every status."""
        self.statuses.extend(msg.status)

    def arrays(self):
        """Stamps [s], positions, velocities, accelerations (N, 3) of what was received."""
        stamps = np.array([s.stamp_ns for s in self.states]) * 1e-9
        return (stamps, *(np.array([getattr(s, name) for s in self.states]) for name in (
            'position_in_world', 'velocity_in_world', 'acceleration_in_world')))


def run(plan, seconds, actions=(), length_s=1.8):
    """Run controller + planner + recorder for ``seconds``; ``actions``: (time_s, fn(ctx)).

    ``length_s``: the planner's window [s].
    """
    controller = ComPreviewController()
    planner, recorder = Planner(plan, length_s), Recorder()
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


def assert_no_jump(recorder, position_m=2e-4, velocity_m_s=0.01, acceleration_m_s2=0.5,
                   spacing_s=SAMPLE):
    """Consecutive horizontal states agree with one sample of integration: nothing jumps.

    The bounds are for one 20 ms sample (the jerk of a walk over a sample is small); the
    states are ``spacing_s`` apart (None: as they come).
    """
    stamps, position, velocity, acceleration = (a[:, :2] if a.ndim == 2 else a
                                                for a in recorder.arrays())
    step = np.diff(stamps)[:, None]
    if spacing_s is not None:
        np.testing.assert_allclose(step, spacing_s, atol=1e-9)
    predicted = position[:-1] + velocity[:-1] * step + acceleration[:-1] * step * step / 2
    assert np.max(np.abs(position[1:] - predicted)) < position_m
    assert np.max(np.abs(np.diff(velocity, axis=0) - acceleration[:-1] * step)) < velocity_m_s
    assert np.max(np.abs(np.diff(acceleration, axis=0))) < acceleration_m_s2


def test_preview_com_tracks_the_reference_every_tick(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=8, rest_after_s=2.0)
    context = run(plan, 10.0)
    recorder = context['recorder']
    stamps, position, velocity, _ = recorder.arrays()
    # One state per 20 ms sample from the first reference on, at the robot's COM height.
    assert len(stamps) >= int(9.9 / SAMPLE)
    np.testing.assert_allclose(np.diff(stamps), SAMPLE, atol=1e-9)
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


def _parameter_setter(results: list):
    """``setter(**values)``: an action setting the controller's parameters, results kept."""
    def setter(**values):
        def apply(context):
            parameters = [Parameter(name, value=value) for name, value in values.items()]
            results.append(context['controller'].set_parameters(parameters))
        return apply
    return setter


def test_method_and_parameter_switches_mid_walk_do_not_jump(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=6)
    results = []
    setter = _parameter_setter(results)

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
    ('horizon_s', -0.1, 'horizon_s must be in [0, 5] s'), ('horizon_s', 5.5, 'horizon_s'),
    ('publish_period_s', 0.0, 'publish_period_s must be in [0.001, 1] s'),
    ('sample_period_s', 0.0123, 'whole number of generator steps'),
    ('sample_period_s', 2.0, 'sample_period_s must be in'),
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


def test_the_node_declares_the_shipped_defaults(start):
    start()
    controller = ComPreviewController()
    path = HERE.parent / 'config' / 'com_preview_controller.yaml'
    shipped = yaml.safe_load(path.read_text())['com_preview_controller']['ros__parameters']
    declared = {name: controller.get_parameter(name).value for name in shipped}
    assert declared == shipped
    controller.destroy_node()


def starvation(starved_s):
    """Actions that stop the controller's timer at 3 s for ``starved_s`` and start it again."""

    def starve(context):
        controller = context['controller']
        controller.destroy_timer(controller._timer)

    def resume(context):
        controller = context['controller']
        controller._timer = controller.create_timer(DEFAULTS['publish_period_s'],
                                                    controller._tick)

    return [(3.0, starve), (3.0 + starved_s, resume)]


def behind_reports(recorder):
    return [s for s in recorder.statuses if s.name.endswith('controller')
            and 'the clock' in s.message]


@pytest.mark.parametrize('method', ['preview', 'polynomial'])
def test_a_controller_starved_for_less_than_its_horizon_loses_nothing(start, method):
    # The window published before the gap covers it: the consumer's held states go on
    # without a seam, and the controller computes on from where it stopped.
    start('-p', f'robot:={BIPED}', '-p', f'com_method:={method}')
    plan = biped_walk_vertices(steps=6)
    starved_s = 0.8 * DEFAULTS['horizon_s']
    context = run(plan, 6.0, starvation(starved_s), length_s=2.5)
    recorder = context['recorder']
    assert not behind_reports(recorder)
    assert_no_jump(recorder)
    # Every message starts at the latest state the clock has reached.
    for clock_ns, states in recorder.messages:
        assert states[0].stamp_ns <= clock_ns
        assert len(states) == 1 or states[1].stamp_ns > clock_ns
    error = tracking_error(recorder, plan)
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) <= 0.010)


@pytest.mark.parametrize('method', ['preview', 'polynomial'])
def test_a_controller_starved_beyond_its_horizon_starts_again_at_the_clock(start, method):
    # On two overloaded cores a node process can miss its timer for longer than its horizon
    # (0.6 s seen over DDS). Its computed end is then behind the clock; beyond
    # MAX_CATCH_UP_TICKS steps the state is carried over to now, never stepped from the
    # stale time (which would publish a COM that lags the clock by as much).
    start('-p', f'robot:={BIPED}', '-p', f'com_method:={method}')
    plan = biped_walk_vertices(steps=6)
    horizon_s = DEFAULTS['horizon_s']
    starved_s = horizon_s + (MAX_CATCH_UP_TICKS + 20) * DT
    context = run(plan, 6.0, starvation(starved_s), length_s=2.5)
    recorder = context['recorder']
    firsts = np.array([states[0].stamp_ns for _, states in recorder.messages])
    clocks = np.array([clock for clock, _ in recorder.messages])
    # Every message starts at an instant the clock has reached, and time never runs back.
    assert np.all(firsts <= clocks)
    assert np.all(np.diff(firsts) > 0)
    # The first message after the gap starts at the clock.
    resumed_ns = int((3.0 + starved_s) * NS_PER_S)
    after = np.flatnonzero(clocks >= resumed_ns)[0]
    assert firsts[after] >= resumed_ns - DEFAULTS['publish_period_s'] * NS_PER_S
    # The gap is reported, with how far behind the computed end was.
    late = behind_reports(recorder)
    assert late and level_value(late[0].level) == 1
    values = {kv.key: kv.value for kv in late[0].values}
    assert float(values['behind_s']) >= starved_s - horizon_s - DEFAULTS['publish_period_s']


def test_the_window_reaches_horizon_s_ahead_and_its_states_never_change(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=4)
    controller = ComPreviewController()
    planner, recorder = Planner(plan, length_s=2.5), Recorder()
    executor = runtime.SingleThreadedExecutor()
    for node in (controller, planner, recorder):
        executor.add_node(node)
    executor.spin_for(4.0)
    horizon_ns = DEFAULTS['horizon_s'] * NS_PER_S
    seen = {}
    for clock_ns, states in recorder.messages[5:]:
        stamps = np.array([state.stamp_ns for state in states])
        np.testing.assert_allclose(np.diff(stamps), SAMPLE * NS_PER_S)
        assert stamps[0] <= clock_ns < stamps[1]
        assert clock_ns + horizon_ns - SAMPLE * NS_PER_S <= stamps[-1] <= clock_ns + horizon_ns
        for state in states:  # a committed state is the same in every window
            values = np.concatenate([state.position_in_world, state.velocity_in_world,
                                     state.acceleration_in_world])
            if state.stamp_ns in seen:
                np.testing.assert_array_equal(seen[state.stamp_ns], values)
            seen[state.stamp_ns] = values


def test_a_reference_short_of_preview_plus_horizon_is_used_as_far_as_it_reaches(start):
    # The test planner's 1.8 s windows cover preview_s (1.6 s) but not preview_s + horizon_s:
    # the controller computes up to the reference's end minus preview_s (and always through
    # the next publication), and the COM still tracks the reference.
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=4)
    recorder = run(plan, 5.0)['recorder']
    reach_ns = (1.8 - DEFAULTS['preview_s'] + 0.05) * NS_PER_S  # (+ the planner's period)
    least_ns = DEFAULTS['publish_period_s'] * NS_PER_S
    for clock_ns, states in recorder.messages[5:]:
        assert clock_ns + least_ns - SAMPLE * NS_PER_S <= states[-1].stamp_ns \
            <= clock_ns + reach_ns
    assert not [s for s in recorder.statuses if 'dropped' in s.message]
    error = tracking_error(recorder, plan)
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) <= 0.010)


def test_a_stale_reference_held_at_its_end_still_gives_the_full_horizon(start):
    # The planner gone mid-walk (killed): the controller runs on the last reference, held at
    # its end, and its windows still reach horizon_s ahead, so that the whole-body IK finishes
    # the swings in the air. (Limited to the reference's end minus preview_s, the windows
    # reached one publication past now: each ended before the IK's next knot, the IK held, and
    # the robot stood frozen with a foot in the air until the planner came back.)
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=4)
    gone_s = 2.0

    def leave(context):
        context['planner'].silent = True

    recorder = run(plan, 5.0, [(gone_s, leave)], length_s=2.5)['recorder']
    stale_ns = (gone_s + DEFAULTS['stale_after_s'] + 0.1) * NS_PER_S
    horizon_ns = DEFAULTS['horizon_s'] * NS_PER_S
    late = [(clock_ns, states) for clock_ns, states in recorder.messages if clock_ns > stale_ns]
    assert late
    for clock_ns, states in late:
        assert states[-1].stamp_ns >= clock_ns + horizon_ns - SAMPLE * NS_PER_S
    assert any('/gait/zmp_reference' in s.message and level_value(s.level) == 1
               for s in recorder.statuses)
    # Held at its end: the COM comes to rest over the reference's last ZMP, without a jump.
    assert_no_jump(recorder)
    _, position, velocity, _ = recorder.arrays()
    assert np.linalg.norm(velocity[-1, :2]) < 0.02


def test_horizon_and_periods_change_at_run_time_without_a_jump(start):
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=6)
    results = []
    setter = _parameter_setter(results)

    actions = [(2.03, setter(horizon_s=0.1)), (3.11, setter(publish_period_s=0.02)),
               (4.07, setter(horizon_s=0.15, sample_period_s=0.01)),
               (5.2, setter(publish_period_s=0.05, sample_period_s=0.02))]
    context = run(plan, 8.0, actions, length_s=2.5)
    recorder = context['recorder']
    assert all(r.successful for batch in results for r in batch)
    assert not behind_reports(recorder)
    assert_no_jump(recorder, spacing_s=None)
    np.testing.assert_allclose(recorder.arrays()[1][-1, :2], plan[1][-1], atol=2e-3)


def test_a_changed_plan_is_followed_at_once_from_the_latest_state_at_or_before_now(start):
    # The states ahead of the clock were computed on the old plan; a reference that changes
    # that plan makes them be computed again from the latest state at or before now (which
    # is kept: nothing at or before now changes), and the new window is published at once.
    start('-p', f'robot:={BIPED}')
    plan = biped_walk_vertices(steps=6)
    shorter = biped_walk_vertices(steps=5, step_m=[0.3] * 3 + [0.2] * 2)
    changed = {}

    def change(context):
        context['planner'].plan = shorter
        changed['ns'] = context['controller'].get_clock().now().nanoseconds
        changed['messages'] = len(context['recorder'].messages)

    recorder = run(plan, 6.0, [(3.52, change)], length_s=2.5)['recorder']
    held, revisions = {}, []
    for k, (clock_ns, states) in enumerate(recorder.messages):
        first = states[0]
        if first.stamp_ns in held:  # nothing at or before now changes
            np.testing.assert_array_equal(first.position_in_world, held[first.stamp_ns])
        change_m = max([np.abs(s.position_in_world - held[s.stamp_ns]).max()
                        for s in states[1:] if s.stamp_ns in held] or [0.0])
        if change_m > 1e-4:
            revisions.append((clock_ns, k))
        held.update((s.stamp_ns, s.position_in_world) for s in states)
    # Revised only after the plan changed, and at once (the planner's next message).
    assert revisions and revisions[0][1] >= changed['messages']
    assert revisions[0][0] - changed['ns'] <= 0.05 * NS_PER_S
    assert_no_jump(recorder)
