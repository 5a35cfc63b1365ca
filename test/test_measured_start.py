"""Plans that start from the robot's measured state (a planner restarted mid-walk).

The first steps start from the measured footholds (no foot is teleported), the ZMP reference from
the measured COM; a foot found in the air is put down first while the ZMP stays inside the feet
on the ground; the walk then goes on with the feet that lag, so no foot steps backwards.
The planner node's pieces: the forward kinematics of /tf + /joint_states, the snap of a robot
standing at its nominal stance, and the swing-trajectory watchdog.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import robot

from gait_nodes.diagnostics import OK, WARN
from gait_nodes.footstep_planner import MeasuredState, measured_start
from gait_nodes.planning import support
from gait_nodes.planning.footsteps import (
    GaitPlanner,
    MeasuredStart,
    Twist2D,
    integrate_pose,
    place,
)
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.zmp_reference import stand_point
from gait_nodes.watchdog import InputWatchdog

QUADRUPED = robot('quadruped')
PARAMS = GaitParameters.for_robot(QUADRUPED, gait='crawl', duty_factor=0.85, step_period_s=1.0,
                                  max_vx_m_s=1.0, max_vy_m_s=1.0, max_wz_rad_s=1.0)


def _mid_walk(stop_s: float):
    """Footholds, yaws, ZMP and body pose of a crawl at 0.1 m/s at ``stop_s``."""
    planner = GaitPlanner(QUADRUPED, PARAMS)
    planner.set_velocity(Twist2D(0.1), 0.0)
    planner.advance(stop_s + 10.0)
    plan = planner.footstep_plan()
    k = plan.index_at(stop_s)
    feet = plan.positions_in_world[k].copy()
    zmp = planner.zmp(np.array([stop_s]))[0]
    path = [step for step in planner.steps if step.start_s <= stop_s][-1].state_after
    body = integrate_pose(path.path_pose, path.path_twist, max(stop_s - path.path_start_s, 0.0))
    return feet, plan.yaws_rad[k].copy(), zmp, body


def _plan_from(start: MeasuredStart, twist: Twist2D, pose):
    planner = GaitPlanner(QUADRUPED, PARAMS, base_pose=pose, start=start)
    planner.set_velocity(twist, 0.0)
    planner.advance(20.0)
    return planner, planner.footstep_plan()


@settings(max_examples=15, deadline=None)
@given(stop_s=st.floats(3.0, 9.0))
def test_the_plan_starts_from_the_measured_footholds_and_no_foot_steps_back(stop_s):
    feet, yaws, zmp, body = _mid_walk(stop_s)
    start = MeasuredStart(feet, yaws, zmp)
    planner, plan = _plan_from(start, Twist2D(0.1), body)
    np.testing.assert_allclose(plan.positions_in_world[0], feet, atol=1e-12)
    np.testing.assert_allclose(planner.zmp(np.array([0.0]))[0], zmp, atol=1e-12)
    # Every swing starts where the foot is: the plan is continuous from the measured state.
    where = {name: feet[k] for k, name in enumerate(plan.foot_names)}
    for swing in plan.swings():
        np.testing.assert_allclose(swing.start_in_world, where[swing.foot], atol=1e-12)
        # Walking on forwards: no foot is put down behind where it stood.
        assert swing.end_in_world[0] >= swing.start_in_world[0] - 1e-9
        where[swing.foot] = swing.end_in_world
    # The walk goes on at the commanded speed.
    assert plan.positions_in_world[-1][:, 0].mean() > feet[:, 0].mean() + 0.1 * 10.0


def _swing_lengths(plan) -> list[float]:
    return [float(np.linalg.norm(s.end_in_world[:2] - s.start_in_world[:2]))
            for s in plan.swings()]


def _centred_pose(planner: GaitPlanner, feet: np.ndarray, yaw: float = 0.0) -> tuple:
    """The path's pose the planner node takes: the footholds' centre, the base's yaw."""
    offsets = planner.layout.offsets(planner.params.step_width_m)
    centre = feet[:, :2].mean(axis=0) - place(np.array([0.0, 0.0, yaw]), offsets).mean(axis=0)
    return (float(centre[0]), float(centre[1]), yaw)


def _resumed_crawl(start, base_pose) -> tuple:
    """RoboSimian's crawl with the joint-limit rhythm, resumed from ``start`` (None: nominal)."""
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.swing.timing import PolynomialSwingTiming

    model = load_robot_model('robosimian')
    params = GaitParameters.for_robot(model.description, gait='crawl', timing='joint_limit',
                                      swing='polynomial')
    timing = PolynomialSwingTiming(model, 2, 1.0, params.step_height_m)
    kwargs = {} if start is None else {'base_pose': base_pose, 'start': start}
    return params, GaitPlanner(model.description, params, swing_timing=timing, **kwargs)


def test_a_walk_paused_across_a_contact_change_resumes_within_a_stride():
    # bench/starve.py whole_body_ik 4.10 0.15 --pause: the crawl paused just after the rear left
    # foot landed 8.3 cm ahead of its nominal place. The path restarted from the footholds'
    # centre, 2.1 cm ahead of where the front left foot's nominal place puts it: that foot's
    # first step was a stride plus 2.1 cm (0.321 m for a 0.3 m stride), re-timed for the longer
    # swing, its foothold moved on with the longer cycle, re-timed again, until the swing left
    # the reach of the limbs (SwingPolicyError with the value-table timing: the planner died).
    # The measured state (recorded with 0.3 m strides) is scaled to RoboSimian's 0.2 m ones
    # around its nominal stance (x +-0.6 m, y +-0.5 m).
    feet = np.array([[0.6, 0.5, 0.0], [0.6, -0.5, 0.0], [-0.5443, 0.5, 0.0],
                     [-0.6, -0.5, 0.0]])
    start = MeasuredStart(feet, np.zeros(4), np.array([0.0143, 0.008]))
    params, nominal = _resumed_crawl(None, None)
    _, planner = _resumed_crawl(start, _centred_pose(nominal, feet))
    twist, _ = planner.set_velocity(Twist2D(0.04), 0.0)
    planner.advance(80.0)
    plan = planner.footstep_plan()
    stride = twist.vx_m_s * planner.rhythm().cycle_s
    assert stride <= params.step_length_m
    assert max(_swing_lengths(plan)) <= stride + 1e-9
    # No foot steps back, and the walk goes on: four cycles, every foot a stride a cycle.
    assert all(s.end_in_world[0] >= s.start_in_world[0] - 1e-9 for s in plan.swings())
    assert plan.positions_in_world[-1][:, 0].min() > feet[:, 0].min() + 3 * stride


def test_a_resumed_walk_starts_with_the_group_that_need_not_wait():
    # A crawl paused mid-swing of the rear right foot (its COM controller starved 1.5 s at
    # 7 s): the front right foot trails its nominal place by 0.105 m. Started with the rear
    # left group (whose first foot lags most), the path had to begin 3 s further back for the
    # front right's first step to stay within a stride, which put the rear left and front left
    # feet ahead of their footholds: a whole step without a swing, the first lift-off 5.6 s
    # after the landing. Started with the front right's group, none waits.
    # (Scaled to 0.2 m strides around the nominal stance as above, the rear right foot ahead
    # of its first foothold; the COM half as far to the side: RoboSimian's body moves twice as
    # far as its COM, and no further than 0.1 m.)
    feet = np.array([[0.7, 0.5, 0.0], [0.6, -0.5, 0.0], [-0.546038, 0.5, 0.0],
                     [-0.45, -0.5, 0.0621674]])
    start = MeasuredStart(feet, np.zeros(4), np.array([0.0767, -0.035]))
    params, planner = _resumed_crawl(start, (0.070259, 0.0, 0.0))
    twist, _ = planner.set_velocity(Twist2D(0.04), 0.0)
    planner.advance(30.0)
    landing, walk = planner.footstep_plan().swings()[:2]
    assert landing.foot == 'rear_right' and walk.foot != 'rear_right'
    assert walk.lift_off_s - landing.touch_down_s < planner.rhythm().step_period_s
    stride = twist.vx_m_s * planner.rhythm().cycle_s
    assert max(_swing_lengths(planner.footstep_plan())) <= stride + 1e-9


@settings(max_examples=40, deadline=None)
@given(ahead=st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4), vx=st.floats(0.02, 0.1))
def test_no_first_step_from_a_measured_stance_is_longer_than_a_stride(ahead, vx):
    # Feet anywhere within a stride of their nominal places along the walk (where a walk
    # stopped at any instant leaves them), the path from their centre (as the planner node
    # resumes a paused walk): no step is longer than the steady walk's, none steps back, and
    # the walk goes on.
    planner = GaitPlanner(QUADRUPED, PARAMS)
    twist, _ = planner.set_velocity(Twist2D(vx), 0.0)
    stride = twist.vx_m_s * PARAMS.cycle_s
    feet = np.column_stack([planner.layout.offsets(PARAMS.step_width_m), np.zeros(4)])
    feet[:, 0] += stride * np.array(ahead)
    start = MeasuredStart(feet, np.zeros(4), feet[:, :2].mean(axis=0))
    planner = GaitPlanner(QUADRUPED, PARAMS, base_pose=_centred_pose(planner, feet), start=start)
    planner.set_velocity(twist, 0.0)
    planner.advance(20.0)
    plan = planner.footstep_plan()
    assert max(_swing_lengths(plan)) <= stride + 1e-9
    assert all(s.end_in_world[0] >= s.start_in_world[0] - 1e-9 for s in plan.swings())
    assert plan.positions_in_world[-1][:, 0].min() > feet[:, 0].min() + 3 * stride


@pytest.mark.parametrize('height', [0.03, 0.1])
def test_a_foot_in_the_air_is_put_down_first_inside_the_support(height):
    feet, yaws, zmp, body = _mid_walk(4.0)
    feet[1, 2] = height
    start = MeasuredStart(feet, yaws, zmp)
    planner, plan = _plan_from(start, Twist2D(0.1), body)
    swings = plan.swings()
    first = swings[0]
    assert first.foot == plan.foot_names[1]
    np.testing.assert_allclose(first.start_in_world, feet[1], atol=1e-12)
    np.testing.assert_allclose(first.end_in_world, [*feet[1, :2], 0.0], atol=1e-12)
    assert first.lift_off_s > 0.0  # a lead time for the swing-leg policy
    # Held where it is until it lifts off, nothing else moves before it lands.
    assert all(s.lift_off_s >= first.touch_down_s - 1e-9 for s in swings[1:])
    grounded = np.delete(feet[:, :2], 1, axis=0)
    for t in np.linspace(0.0, first.touch_down_s, 20):
        point = planner.zmp(np.array([t]))[0]
        assert support.support_margin(point, grounded, QUADRUPED.foot_radius_m) > 0.0
    # After the landing every foothold is on the ground.
    assert np.all(plan.positions_in_world[plan.index_at(first.touch_down_s):, :, 2] == 0.0)


def test_a_foot_slightly_off_the_ground_stays_where_it_is_until_it_steps():
    # A foot lifting or landing when the walk paused, below the height from which it is in the
    # air: planned at its measured height until its first swing lands it (put on the ground in
    # one tick, it jolted the stance: the simulated ZMP went 51 m out).
    feet, yaws, zmp, body = _mid_walk(4.0)
    feet[1, 2] = 0.003
    planner, plan = _plan_from(MeasuredStart(feet, yaws, zmp), Twist2D(0.1), body)
    first = next(s for s in plan.swings() if s.foot == plan.foot_names[1])
    before = plan.times_s <= first.lift_off_s
    np.testing.assert_array_equal(plan.positions_in_world[before, 1, 2], 0.003)
    np.testing.assert_array_equal(plan.positions_in_world[before][:, [0, 2, 3], 2], 0.0)
    assert first.start_in_world[2] == 0.003 and first.end_in_world[2] == 0.0
    assert np.all(plan.positions_in_world[plan.times_s >= first.touch_down_s, :, 2] == 0.0)


def test_standing_still_mid_walk_with_a_zero_twist_closes_the_stance():
    feet, yaws, zmp, pose = _mid_walk(5.0)
    planner, plan = _plan_from(MeasuredStart(feet, yaws, zmp), Twist2D(), pose)
    nominal = place(pose, planner.layout.offsets(PARAMS.step_width_m))
    np.testing.assert_allclose(plan.positions_in_world[-1][:, :2], nominal, atol=1e-9)


@pytest.mark.parametrize('late_s', [0.0, 0.05, 0.2])
def test_a_velocity_that_comes_before_the_first_lift_off_walks_as_one_that_came_first(late_s):
    # A planner that rejoined a robot mid-walk before its first /cmd_vel came plans the stance
    # closed (zero twist). The velocity arriving before the first foot lifts starts the walk
    # there: no group of feet is first squared up (a whole step, the walk then from standstill).
    feet, yaws, zmp, pose = _mid_walk(5.0)
    start = MeasuredStart(feet, yaws, zmp)
    first, plan_first = _plan_from(start, Twist2D(0.1), pose)
    late = GaitPlanner(QUADRUPED, PARAMS, base_pose=pose, start=start)
    late.set_velocity(Twist2D(), 0.0)
    late.advance(late_s + 5.0)
    assert late.steps[0].slots[0].lift_off_s > late_s  # a stopping step, no foot up yet
    late.set_velocity(Twist2D(0.1), late_s)
    late.advance(20.0)
    plan_late = late.footstep_plan()
    # Every swing starts where the foot is and moves it forwards.
    where = {name: feet[k] for k, name in enumerate(plan_late.foot_names)}
    for swing in plan_late.swings():
        np.testing.assert_allclose(swing.start_in_world, where[swing.foot], atol=1e-12)
        assert swing.end_in_world[0] >= swing.start_in_world[0] - 1e-9
        where[swing.foot] = swing.end_in_world
    # The same swings as the velocity that came first, ``late_s`` later.
    early_swings, late_swings = list(plan_first.swings()), list(plan_late.swings())
    for a, b in zip(early_swings[:4], late_swings[:4], strict=True):
        assert a.foot == b.foot
        assert b.lift_off_s == pytest.approx(a.lift_off_s + late_s, abs=1e-9)
        np.testing.assert_allclose(b.end_in_world, a.end_in_world, atol=0.1 * late_s + 1e-9)
    # The ZMP reference is continuous through the cut.
    times = np.linspace(0.0, 3.0, 3001)
    assert np.abs(np.diff(late.zmp(times), axis=0)).max() < 0.01


def test_a_velocity_after_the_first_lift_off_lets_the_stopping_step_end():
    feet, yaws, zmp, pose = _mid_walk(5.0)
    planner = GaitPlanner(QUADRUPED, PARAMS, base_pose=pose, start=MeasuredStart(feet, yaws, zmp))
    planner.set_velocity(Twist2D(), 0.0)
    planner.advance(5.0)
    stop = planner.steps[0]
    lifted = stop.slots[0].lift_off_s + 0.01
    planner.set_velocity(Twist2D(0.1), lifted)
    planner.advance(20.0)
    # The foot in the air lands where the stopping step put it; the walk starts after.
    assert planner.steps[0] == stop
    assert planner.steps[1].start_s == stop.end_s


def test_a_malformed_start_is_refused():
    from gait_nodes.errors import GaitParameterError

    with pytest.raises(GaitParameterError, match='measured start'):
        GaitPlanner(QUADRUPED, PARAMS, start=MeasuredStart(np.zeros((3, 3)), np.zeros(3),
                                                           np.zeros(2)))
    with pytest.raises(GaitParameterError, match='finite'):
        GaitPlanner(QUADRUPED, PARAMS, start=MeasuredStart(np.full((4, 3), np.nan), np.zeros(4),
                                                           np.zeros(2)))


def test_measured_start_snaps_a_nominal_stance_and_keeps_the_rest():
    layout_offsets = GaitPlanner(QUADRUPED, PARAMS).layout
    nominal = place(np.array([0.2, 0.1, 0.3]), layout_offsets.offsets(PARAMS.step_width_m))
    yaws = np.full(4, 0.3)
    zmp = stand_point(layout_offsets, nominal)
    feet = np.column_stack([nominal + 2e-4, np.full(4, 1e-4)])
    assert measured_start(feet, yaws + 1e-5, [*zmp, 0.5], nominal, yaws, zmp) is None
    feet[2, :2] += 0.05
    start = measured_start(feet, yaws + 1e-5, [*zmp, 0.5], nominal, yaws, zmp)
    np.testing.assert_array_equal(start.feet_in_world[[0, 1, 3], :2], nominal[[0, 1, 3]])
    np.testing.assert_array_equal(start.feet_in_world[2], feet[2])
    assert not start.airborne().any()
    feet[3, 2] = 0.04
    assert measured_start(feet, yaws, [*zmp, 0.5], nominal, yaws, zmp).airborne()[3]


def test_measured_state_is_the_forward_kinematics_of_the_robot():
    from gait_nodes.robot.model import load_robot_model

    model = load_robot_model('robosimian')
    state = MeasuredState(model)
    joints = model.joint_positions(model.configuration((0, 0, 0), 0.0)) + 0.05
    q = model.configuration((0.3, -0.1, 0.5), 0.4, joints)
    state.on_joints(model.joint_names, joints, 10)
    assert not state.since(0)
    for k in range(30):
        state.on_base(np.array(q[:7]), 10 + k * 10_000_000)
    assert state.since(10) and state.still(10 + 29 * 10_000_000)
    feet, yaws, com = state.measure()
    expected_feet, expected_yaws = model.foot_poses(q)
    np.testing.assert_allclose(feet, expected_feet, atol=1e-12)
    np.testing.assert_allclose(yaws, expected_yaws, atol=1e-12)
    np.testing.assert_allclose(com, model.com(q), atol=1e-12)
    x, y, yaw = state.base_pose()
    assert (x, y) == pytest.approx((0.3, -0.1)) and math.isclose(yaw, 0.4)
    moved = np.array(q[:7])
    moved[0] += 0.01
    state.on_base(moved, 10 + 30 * 10_000_000)
    assert not state.still(10 + 30 * 10_000_000)


def test_event_inputs_are_stale_from_a_miss_to_the_next_message():
    dog = InputWatchdog(['/a'], 0.5, 0, events=['/e'])
    dog.watch('/a', False)
    assert not dog.update(10 ** 10)  # /a is off: never stale, /e not missed
    dog.missed('/e', 'the swing of FL at 1.0 s')
    assert dog.update(10 ** 10) and dog.stale == ('/e',)
    aspect, level, message, values = dog.status(10 ** 10)
    assert level == WARN and 'no /e for the swing of FL at 1.0 s' in message
    assert values['/a watched'] == 'no'
    dog.heard('/e', 2 * 10 ** 10)
    assert dog.update(2 * 10 ** 10) and dog.status(2 * 10 ** 10)[1] == OK
    dog.watch('/a', True)
    assert dog.update(2 * 10 ** 10) and dog.stale == ('/a',)
    with pytest.raises(KeyError):
        dog.missed('/a', 'x')
    with pytest.raises(KeyError):
        dog.watch('/e', True)
