"""Footsteps and contact schedule.

Footsteps and contact schedule: footholds follow the commanded (curved) path with the
commanded stride and width, start from and stop at standstill, changes wait for the step
boundary, and the schedule has each gait's structure and duty factor.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import robot

from gait_nodes.planning.footsteps import (
    GaitPlanner,
    Twist2D,
    clamp_velocity,
    contact_schedule,
    integrate_pose,
    place,
    plan_walk,
)
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.layout import FootLayout

QUADRUPED = robot('quadruped')
BIPED = robot('biped')
FAST = dict(step_period_s=1.0, max_vx_m_s=1.0, max_vy_m_s=1.0, max_wz_rad_s=1.0)
GAITS = {
    'crawl': (QUADRUPED, dict(gait='crawl', duty_factor=0.85, **FAST)),
    'trot': (QUADRUPED, dict(gait='trot', duty_factor=0.7, **FAST)),
    'biped': (BIPED, dict(gait='biped', duty_factor=0.9, **FAST)),
}


def walk(gait, twist, stop_s=14.0, end_s=22.0, **changes):
    description, values = GAITS[gait]
    params = GaitParameters.for_robot(description, **{**values, **changes})
    planner = plan_walk(description, params, [(0.3, twist), (stop_s, Twist2D())], end_s)
    return description, params, planner, planner.footstep_plan()


def same_step(a, b) -> bool:
    return (a.start_s, a.end_s, a.gait, a.twist) == (b.start_s, b.end_s, b.gait, b.twist) \
        and np.array_equal(a.zmp_points, b.zmp_points) \
        and np.array_equal(a.positions_end, b.positions_end)


def test_integrate_pose_is_a_flow():
    twist = Twist2D(0.3, -0.1, 0.4)
    pose = np.array([1.0, 2.0, 0.5])
    # Composition: integrating 0.7 s then 0.5 s equals integrating 1.2 s.
    np.testing.assert_allclose(integrate_pose(integrate_pose(pose, twist, 0.7), twist, 0.5),
                               integrate_pose(pose, twist, 1.2), atol=1e-12)
    # Derivative: the body-frame velocity rotated into the world.
    h = 1e-6
    rate = (integrate_pose(pose, twist, h) - integrate_pose(pose, twist, -0.0)) / h
    c, s = math.cos(0.5), math.sin(0.5)
    np.testing.assert_allclose(rate, [c * 0.3 + s * 0.1, s * 0.3 - c * 0.1, 0.4], atol=1e-5)


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_straight_walk_strides_and_width(gait):
    description, params, planner, plan = walk(gait, Twist2D(0.1, 0.0, 0.0))
    layout = FootLayout.of(description)
    stride = 0.1 * params.cycle_s
    swings = plan.swings()
    assert swings and all(s.duration_s == pytest.approx(params.swing_s) for s in swings)
    lengths = np.array([s.end_in_world[0] - s.start_in_world[0] for s in swings])
    assert np.all(lengths > 0) and np.all(lengths <= stride + 1e-9)
    # Steady state: every foot moves exactly v T per swing.
    assert np.sum(np.isclose(lengths, stride, atol=1e-9)) >= len(swings) - 2 * layout.count
    for s in swings:
        assert s.end_in_world[1] == pytest.approx(s.start_in_world[1], abs=1e-12)
    # The stance is step_width_m wide and every foot keeps yaw 0.
    width = plan.positions_in_world[:, layout.left, 1].mean(axis=1) - \
        plan.positions_in_world[:, ~layout.left, 1].mean(axis=1)
    np.testing.assert_allclose(width, params.step_width_m, atol=1e-12)
    np.testing.assert_allclose(plan.yaws_rad, 0.0, atol=1e-12)


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_start_and_stop_at_standstill_with_feet_aligned(gait):
    description, params, planner, plan = walk(gait, Twist2D(0.08, 0.02, 0.05))
    layout = FootLayout.of(description)
    offsets = layout.offsets(params.step_width_m)
    for k in (0, -1):
        positions, yaws = plan.positions_in_world[k, :, :2], plan.yaws_rad[k]
        assert np.ptp(yaws) < 1e-12
        centre = positions.mean(axis=0) - place(np.array([0, 0, yaws[0]]), offsets).mean(axis=0)
        np.testing.assert_allclose(positions, place(np.array([*centre, yaws[0]]), offsets),
                                   atol=1e-9)
    assert plan.positions_in_world[-1, 0, 0] > 0.5  # it did walk
    # After the stop everything is down and nothing moves any more.
    assert planner.steps[-1].kind == 'stand'
    assert np.all(contact_schedule(plan, [plan.end_s + 1.0]))
    # Closing steps only go forward (no step back after the stop).
    assert all(s.end_in_world[0] - s.start_in_world[0] > -1e-9 for s in plan.swings()
               if s.lift_off_s > 14.0)


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_footholds_follow_a_curved_path(gait):
    vx, wz = 0.08, 0.1
    description, params, planner, plan = walk(gait, Twist2D(vx, 0.0, wz))
    layout = FootLayout.of(description)
    offsets = layout.offsets(params.step_width_m)
    # Body on a circle of radius vx / wz about (0, R): each foot keeps its distance to the centre.
    centre = np.array([0.0, vx / wz])
    for f in range(layout.count):
        expected = np.linalg.norm(offsets[f] - centre)
        distances = np.linalg.norm(plan.positions_in_world[:, f, :2] - centre, axis=1)
        np.testing.assert_allclose(distances, expected, atol=1e-9)
    # Each steady swing turns the foot by wz T, and the foot's yaw is the body's heading there.
    turns = np.array([s.end_yaw_rad - s.start_yaw_rad for s in plan.swings()])
    assert np.sum(np.isclose(turns, wz * params.cycle_s, atol=1e-9)) >= len(turns) - 2 * \
        layout.count
    for s in plan.swings():
        heading = s.end_yaw_rad
        pose = np.array([*(centre + vx / wz * np.array([math.sin(heading),
                                                        -math.cos(heading)])), heading])
        f = plan.foot_names.index(s.foot)
        np.testing.assert_allclose(place(pose, offsets[f:f + 1])[0], s.end_in_world[:2],
                                   atol=1e-9)


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_side_steps(gait):
    description, params, planner, plan = walk(gait, Twist2D(0.0, 0.04, 0.0))
    lateral = np.array([s.end_in_world[1] - s.start_in_world[1] for s in plan.swings()])
    assert np.all(np.abs([s.end_in_world[0] - s.start_in_world[0] for s in plan.swings()])
                  < 1e-12)
    assert np.all(lateral > 0) and np.max(lateral) == pytest.approx(0.04 * params.cycle_s)


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_contact_schedule_structure_and_duty_factor(gait):
    description, params, planner, plan = walk(gait, Twist2D(0.1, 0.0, 0.0))
    layout = FootLayout.of(description)
    times = np.arange(0.0, plan.end_s, 0.002)
    down = contact_schedule(plan, times)
    airborne = (~down).sum(axis=1)
    if gait == 'crawl':
        assert airborne.max() == 1
    elif gait == 'biped':
        assert airborne.max() == 1
    else:
        assert airborne.max() == 2
        for s in plan.swings():
            partner = [o.foot for o in plan.swings() if o.lift_off_s == s.lift_off_s]
            assert sorted(partner) in (sorted(['front_left', 'rear_right']),
                                       sorted(['front_right', 'rear_left']))
    # Steady state (the middle cycle): each foot is down a duty factor of the cycle.
    window = (times >= 5.0) & (times < 5.0 + params.cycle_s)
    np.testing.assert_allclose(down[window].mean(axis=0), params.duty_factor, atol=0.01)
    # Left and right alternate.
    sides = [layout.left[plan.foot_names.index(s.foot)] for s in plan.swings()]
    steps = [sides[i] for i in range(len(sides)) if i == 0 or sides[i] != sides[i - 1]]
    assert len(steps) > 4


def test_no_zero_length_step_and_every_step_within_reach():
    for gait in GAITS:
        description, params, planner, plan = walk(gait, Twist2D(0.3, 0.2, 0.3))
        reach = description.reach
        for s in plan.swings():
            step = s.end_in_world[:2] - s.start_in_world[:2]
            c, d = math.cos(s.end_yaw_rad), math.sin(s.end_yaw_rad)
            assert np.linalg.norm(step) > 1e-6 or abs(s.end_yaw_rad - s.start_yaw_rad) > 1e-6
            assert abs(c * step[0] + d * step[1]) <= reach.max_step_length_m + 1e-9
            assert abs(-d * step[0] + c * step[1]) <= reach.max_step_width_m + 1e-9


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_a_change_waits_for_the_next_step_boundary(gait):
    description, values = GAITS[gait]
    params = GaitParameters.for_robot(description, **values)
    commands = [(0.3, Twist2D(0.1, 0.0, 0.0))]
    change_s = 6.37
    base = plan_walk(description, params, commands, 14.0)
    turned = plan_walk(description, params, commands + [(change_s, Twist2D(0.1, 0.0, 0.2))],
                       14.0)
    boundary = next(step.end_s for step in base.steps if step.start_s <= change_s < step.end_s)
    for old, new in zip(base.steps, turned.steps, strict=False):
        if old.start_s < boundary:
            assert same_step(old, new)  # steps under way are untouched
    first_new = next(new for new in turned.steps if new.start_s >= boundary)
    assert first_new.start_s == pytest.approx(boundary)
    assert first_new.twist != base.steps[-1].twist
    # The ZMP before the boundary is the same.
    times = np.arange(0.0, boundary, 0.01)
    np.testing.assert_array_equal(base.zmp(times), turned.zmp(times))


def test_a_parameter_change_applies_at_the_boundary():
    description, values = GAITS['crawl']
    params = GaitParameters.for_robot(description, **values)
    planner = plan_walk(description, params, [(0.3, Twist2D(0.1, 0, 0)),
                                              (5.2, params.replace(gait='trot', duty_factor=0.6))],
                        12.0)
    gaits = [(step.start_s, step.gait) for step in planner.steps]
    switch = next(t for t, g in gaits if g == 'trot')
    step_at_change = next(step for step in planner.steps if step.start_s <= 5.2 < step.end_s)
    assert switch == pytest.approx(step_at_change.end_s)
    assert all(g == 'crawl' for t, g in gaits if t < switch)
    assert all(g == 'trot' for t, g in gaits if t >= switch)


@settings(max_examples=80, deadline=None)
@given(vx=st.floats(-2, 2), vy=st.floats(-2, 2), wz=st.floats(-2, 2))
def test_clamped_velocity_fits_the_limits(vx, vy, wz):
    params = GaitParameters.for_robot(QUADRUPED, **FAST)
    layout = FootLayout.of(QUADRUPED)
    result, notes = clamp_velocity(Twist2D(vx, vy, wz), params, QUADRUPED, layout)
    assert abs(result.vx_m_s) <= params.max_vx_m_s and abs(result.vy_m_s) <= params.max_vy_m_s
    assert abs(result.wz_rad_s) * params.cycle_s <= QUADRUPED.reach.max_turn_rad + 1e-9
    offsets = layout.offsets(params.step_width_m)
    moved = place(integrate_pose(np.zeros(3), result, params.cycle_s), offsets) - offsets
    assert np.all(np.abs(moved[:, 0]) <= params.step_length_m + 1e-9)
    assert np.all(np.abs(moved[:, 1]) <= QUADRUPED.reach.max_step_width_m + 1e-9)
    # Clamping keeps the direction and reports itself.
    for a, b in zip(result.as_tuple(), (vx, vy, wz), strict=True):
        assert a * b >= 0 and abs(a) <= abs(b)
    assert bool(notes) == (result != Twist2D(vx, vy, wz))


def test_planner_refuses_non_finite_velocity_and_keeps_its_plan():
    planner = GaitPlanner(QUADRUPED)
    planner.set_velocity(Twist2D(0.05, 0, 0), 0.0)
    planner.advance(10.0)
    before = planner.footstep_plan()
    with pytest.raises(Exception, match='not finite'):
        planner.set_velocity(Twist2D(math.nan, 0, 0), 3.0)
    planner.advance(10.0)
    after = planner.footstep_plan()
    np.testing.assert_array_equal(before.positions_in_world, after.positions_in_world)


@pytest.mark.parametrize('gait', ['crawl', 'trot'])
def test_a_gait_with_its_own_stance_walks_it_and_stands_at_the_nominal_one(gait, tmp_path):
    # The gait plants its front feet 0.55 m ahead of the base and its rear feet 0.4 m behind;
    # the robot stands with them 0.5 m either way, as it does for a gait without a stance.
    import yaml

    from gait_nodes.robot.description import load_robot_description

    data = yaml.safe_load(QUADRUPED.path.read_text())
    data['urdf'] = str(QUADRUPED.urdf_path)
    data['gait_stances'] = {gait: {'front_x_m': 0.55, 'rear_x_m': 0.4}}
    path = tmp_path / 'quadruped.yaml'
    path.write_text(yaml.safe_dump(data))
    plans = []
    for description in (QUADRUPED, load_robot_description(path)):
        params = GaitParameters.for_robot(description, **GAITS[gait][1])
        commands = [(0.3, Twist2D(0.08)), (14.0, Twist2D())]
        plans.append(plan_walk(description, params, commands, 24.0).footstep_plan())
    nominal, own = plans
    front = QUADRUPED.nominal_stance_in_base()[:, 0] > 0
    # Standing, before and after: the nominal stance.
    np.testing.assert_allclose(own.positions_in_world[0], nominal.positions_in_world[0])
    last = own.positions_in_world[-1, :, :2]
    np.testing.assert_allclose(last - last.mean(axis=0), QUADRUPED.nominal_stance_in_base()[
        :, :2] - QUADRUPED.nominal_stance_in_base()[:, :2].mean(axis=0), atol=1e-9)
    # Walking: every foothold where the nominal stance's is, moved by the stances' difference
    # (the same path, the same times: the first swings' move is the difference too).
    landings = {(s.foot, round(s.lift_off_s, 9)): s for s in nominal.swings()}
    walked = [(s, landings[(s.foot, round(s.lift_off_s, 9))]) for s in own.swings()
              if 2.0 < s.lift_off_s < 12.0]
    assert len(walked) >= 8
    for swing, same in walked:
        shift = 0.05 if front[QUADRUPED.foot_names.index(swing.foot)] else 0.1
        assert swing.end_in_world[0] - same.end_in_world[0] == pytest.approx(shift, abs=1e-9)
        assert swing.end_in_world[1] == pytest.approx(same.end_in_world[1], abs=1e-12)


@pytest.mark.parametrize('gait', ['crawl', 'trot'])
def test_a_robot_stands_where_its_com_is_before_and_after_a_walk(gait, tmp_path):
    """com_xy_m: the standing ZMP is the COM of the nominal posture, not the stance's centre.

    Planned at the diagonals' crossing, a robot whose COM is elsewhere would move its body as
    soon as the graph starts, before any walk (RoboSimian's went 60 mm back and forth).
    """
    import yaml

    from gait_nodes.robot.description import load_robot_description

    data = yaml.safe_load(QUADRUPED.path.read_text())
    data['urdf'] = str(QUADRUPED.urdf_path)
    data['com_xy_m'] = [0.04, -0.01]
    path = tmp_path / 'quadruped.yaml'
    path.write_text(yaml.safe_dump(data))
    description = load_robot_description(path)
    params = GaitParameters.for_robot(description, **GAITS[gait][1])
    standing = GaitPlanner(description, params, base_pose=(1.0, 2.0, 0.5))
    com = place(np.array([1.0, 2.0, 0.5]), np.array([[0.04, -0.01]]))[0]
    np.testing.assert_allclose(standing.zmp(np.array([0.0, 1.0, 5.0])), [com] * 3, atol=1e-12)
    planner = plan_walk(description, params, [(0.3, Twist2D(0.08, 0.0, 0.05)),
                                              (10.0, Twist2D())], 20.0)
    assert planner.steps[-1].kind == 'stand'
    plan = planner.footstep_plan()
    # Stopped: the COM's place in the base frame, under the pose the feet stand at.
    feet = plan.positions_in_world[-1, :, :2]
    yaw = plan.yaws_rad[-1][0]
    offsets = FootLayout.of(description).offsets(params.step_width_m)
    centre = feet.mean(axis=0) - place(np.array([0.0, 0.0, yaw]), offsets).mean(axis=0)
    assert np.linalg.norm(centre) > 0.3  # it did walk
    expected = place(np.array([*centre, yaw]), np.array([[0.04, -0.01]]))[0]
    np.testing.assert_allclose(planner.zmp(np.array([planner.steps[-1].end_s])), [expected],
                               atol=1e-9)
    # Without com_xy_m: the diagonals' crossing, as before.
    np.testing.assert_allclose(GaitPlanner(QUADRUPED, params).zmp(np.array([0.0])), [[0, 0]],
                               atol=1e-12)
