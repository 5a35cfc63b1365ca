"""Stairs (Lucy's stairway): terrain, footholds on the treads, COM height, ZMP plane.

The footholds of planned walks are judged from the contract plan alone: each one's height is the
ground's under it, its disc lies on one tread, and the polynomial swing to it passes over the
risers. The COM height over a plan is continuous with its first two derivatives and ends
``total rise`` higher; bad terrain is refused with the range and changes nothing.
"""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import check_slid_windows

from gait_nodes.com.support_height import SupportHeight
from gait_nodes.errors import ParameterError, TerrainError
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.terrain import (
    EDGE_MARGIN_M,
    FLAT,
    Staircase,
    check_walkable,
    keep_out_m,
    swing_clearance_m,
    toe_distance_m,
)
from gait_nodes.robot.description import load_robot_description
from gait_nodes.swing.polynomial import evaluate, polynomial_swing

BIPED = load_robot_description('biped')
STEP_HEIGHT_M = 0.12


def biped_params(**changes):
    values = dict(gait='biped', swing='polynomial', step_height_m=STEP_HEIGHT_M,
                  step_period_s=1.5, duty_factor=0.72)
    return GaitParameters.for_robot(BIPED, **{**values, **changes})


def walk(staircase, vx=0.1, stop_s=14.0, end_s=20.0, **changes):
    params = biped_params(**changes)
    planner = plan_walk(BIPED, params, [(0.0, Twist2D(vx)), (stop_s, Twist2D())], end_s,
                        terrain=staircase)
    return planner, planner.footstep_plan()


# --- the staircase ----------------------------------------------------------------------------


@pytest.mark.parametrize('values, text', [
    (dict(rise_m=0.5, count=2), 'stairs_rise_m = 0.5 is out of range: must be in [-0.3, 0.3] m'),
    (dict(tread_m=0.01, count=2), 'stairs_tread_m = 0.01 is out of range: must be in [0.05, 5]'),
    (dict(count=-1), 'stairs_count = -1 is out of range: must be in [0, 50]'),
    (dict(count=2.0), 'stairs_count must be an integer'),
    (dict(start_x_m=math.nan, count=2), 'stairs_start_x_m = nan is out of range'),
    (dict(rise_m=0.0, count=2), 'a staircase needs a rise'),
])
def test_bad_staircases_are_refused_with_the_range(values, text):
    with pytest.raises(TerrainError) as error:
        Staircase(**values)
    assert text in str(error.value)
    assert isinstance(error.value, ParameterError)


@settings(max_examples=60, deadline=None)
@given(start=st.floats(-2.0, 2.0), rise=st.sampled_from([-0.1, 0.05, 0.2]),
       tread=st.floats(0.1, 1.0), count=st.integers(1, 6), x=st.floats(-5.0, 10.0))
def test_the_ground_is_a_staircase(start, rise, tread, count, x):
    stairs = Staircase(start, rise, tread, count)
    height = float(stairs.height_at(x))
    stair = height / rise
    assert stair == pytest.approx(round(stair), abs=1e-9) and 0 <= round(stair) <= count
    # Monotonic, 0 before the first riser, the total rise on the landing.
    assert (height - float(stairs.height_at(x + 0.01))) * rise <= 1e-12
    assert stairs.height_at(start - 1e-6) == 0.0
    assert stairs.height_at(start + count * tread + 1.0) == pytest.approx(stairs.total_rise_m)
    # The highest ground under a disc is the higher of its two ends' (one riser at most).
    if 0.05 < tread:
        under = np.linspace(x - 0.05, x + 0.05, 101)
        assert float(stairs.highest_under(x, 0.05)) == pytest.approx(
            float(stairs.height_at(under).max()))


def test_the_toe_distance_is_where_the_swing_is_one_stair_high():
    toe = toe_distance_m(0.05, STEP_HEIGHT_M, 0.3)
    assert 0.0 < toe < 0.3
    swing, coefficients = _swing_path((0.0, 0.0, 0.0), (0.3, 0.0, 0.05))
    path = evaluate(coefficients, np.linspace(0.0, swing.duration_s, 4001))
    first = np.flatnonzero(path[:, 2] >= 0.05)[0]
    assert path[first, 0] == pytest.approx(toe, abs=2e-4)
    # A higher via point lifts the foot sooner; down is the same swing reversed.
    assert toe_distance_m(0.05, 0.2, 0.3) < toe
    assert toe_distance_m(-0.05, STEP_HEIGHT_M, 0.3) == toe


def _swing_path(start, end):
    from gait_nodes.contract import Swing

    swing = Swing('left', 0.0, 1.0, np.array(start, float), np.array(end, float), 0.0, 0.0)
    trajectory, coefficients = polynomial_swing(swing, 0, STEP_HEIGHT_M)
    return swing, coefficients


def test_a_value_table_swing_and_a_short_tread_are_refused():
    stairs = Staircase(0.4, 0.05, 0.3, 3)
    with pytest.raises(TerrainError, match='value-table swing is built for flat ground'):
        check_walkable(stairs, BIPED, biped_params(swing='value_table'))
    needed = sum(keep_out_m(stairs, BIPED.sole_extent_x_m, STEP_HEIGHT_M,
                            BIPED.reach.max_step_length_m))
    with pytest.raises(TerrainError, match=f'tread must be >= {needed:.4g} m'):
        check_walkable(Staircase(0.4, 0.05, 0.9 * needed, 3), BIPED, biped_params())
    assert check_walkable(FLAT, BIPED, biped_params(swing='value_table')) == (0.0, 0.0)


# --- footholds --------------------------------------------------------------------------------


@pytest.mark.parametrize('start_x_m, rise_m, tread_m', [
    (0.4, 0.05, 0.3),      # the scenario
    (0.36, 0.05, 0.3),     # risers where the feet would land: steps shortened or lengthened
    (0.5, 0.08, 0.37),     # a tread that is no multiple of the stride
    (0.45, -0.05, 0.3),    # a staircase down
])
def test_footholds_lie_on_one_tread_at_its_height_and_the_swings_clear_the_risers(
        start_x_m, rise_m, tread_m):
    stairs = Staircase(start_x_m, rise_m, tread_m, 3)
    keep_before, keep_after = check_walkable(stairs, BIPED, biped_params())
    behind, ahead = BIPED.sole_extent_x_m
    assert (behind, ahead) == pytest.approx((0.08, 0.12))  # the sole box, not the 0.05 m disc
    planner, plan = walk(stairs)
    feet = plan.positions_in_world.reshape(-1, 3)
    assert np.allclose(feet[:, 2], stairs.height_at(feet[:, 0]), atol=1e-12)
    to_riser = stairs.risers_x_m[None, :] - feet[:, :1]  # > 0: the riser is ahead of the foot
    assert to_riser[to_riser > 0].min() >= keep_before - 1e-9 > ahead
    assert (-to_riser[to_riser <= 0]).min() >= keep_after - 1e-9 > behind
    # The whole sole on one tread, the toe distance (at least the edge margin) from each riser.
    assert not any(stairs.riser_under(x, behind + EDGE_MARGIN_M, ahead + EDGE_MARGIN_M)
                   for x in feet[:, 0])
    swings = plan.swings()
    climbed = [s.end_in_world[2] - s.start_in_world[2] for s in swings]
    assert max(np.abs(climbed)) == pytest.approx(abs(rise_m))
    for swing in swings:
        step = swing.end_in_world[:2] - swing.start_in_world[:2]
        assert abs(step[0]) <= BIPED.reach.max_step_length_m + 1e-9
        assert swing_clearance_m(stairs, swing.start_in_world, swing.end_in_world,
                                 STEP_HEIGHT_M, BIPED.sole_extent_x_m) >= -1e-12
    # The walk ends on the landing, both feet side by side (the closing step) on one tread.
    last = plan.positions_in_world[-1]
    assert last[:, 2] == pytest.approx([stairs.total_rise_m] * 2)
    assert last[0, 0] == pytest.approx(last[1, 0])


def test_a_swing_that_cuts_a_riser_is_seen():
    stairs = Staircase(0.2, 0.05, 0.3, 3)
    # Toe 0.01 m from the riser: the foot is still low when it gets there.
    assert swing_clearance_m(stairs, (0.14, 0.0, 0.0), (0.44, 0.0, 0.05), STEP_HEIGHT_M,
                             (0.05, 0.05)) < -0.01
    # A sole reaching further ahead of its frame hits it sooner, and lower.
    assert swing_clearance_m(stairs, (0.1, 0.0, 0.0), (0.4, 0.0, 0.05), STEP_HEIGHT_M,
                             (0.08, 0.12)) < swing_clearance_m(
        stairs, (0.1, 0.0, 0.0), (0.4, 0.0, 0.05), STEP_HEIGHT_M, (0.05, 0.05)) < 0.0


def test_the_flat_default_plans_the_same_walk():
    _, flat = walk(FLAT)
    params = biped_params()
    plain = plan_walk(BIPED, params, [(0.0, Twist2D(0.1)), (14.0, Twist2D())], 20.0)
    other = plain.footstep_plan()
    assert np.array_equal(flat.positions_in_world, other.positions_in_world)
    assert np.array_equal(flat.times_s, other.times_s)
    assert not flat.positions_in_world[:, :, 2].any()


# --- terrain changes --------------------------------------------------------------------------


def _plan_bytes(planner, now_s):
    plan = planner.footstep_plan(now_s)
    return plan.times_s.tobytes() + plan.positions_in_world.tobytes()


def test_terrain_under_the_feet_is_refused_and_the_plan_stays_the_same():
    planner = GaitPlanner(BIPED, biped_params())
    planner.set_velocity(Twist2D(0.1), 0.0)
    planner.advance(8.0)
    before = _plan_bytes(planner, 5.0)
    params = planner.params
    cases = [
        (Staircase(0.0, 0.05, 0.3, 3), 'puts a riser under the'),      # across a foot
        (Staircase(-1.0, 0.05, 0.3, 3), 'would move the ground under'),  # feet on stair 3
        (Staircase(0.4, 0.05, 0.05, 3), 'tread must be >='),
    ]
    for stairs, text in cases:
        with pytest.raises(TerrainError, match=text):
            planner.set_terrain(stairs, 5.0)
        assert planner.terrain is FLAT and planner.params is params
        assert _plan_bytes(planner, 5.0) == before
    # Ahead of the feet it is accepted, and the later footholds climb.
    planner.set_terrain(Staircase(1.0, 0.05, 0.3, 2), 5.0)
    with pytest.raises(TerrainError, match='value-table swing'):
        planner.set_parameters(params.replace(swing='value_table'), 5.0)
    assert planner.params is params
    planner.advance(30.0)
    assert planner.footstep_plan().positions_in_world[-1, :, 2].min() == pytest.approx(0.1)


def test_a_planner_cannot_start_across_a_riser():
    with pytest.raises(TerrainError, match='puts a riser under the left foot'):
        GaitPlanner(BIPED, biped_params(), terrain=Staircase(0.03, 0.05, 0.3, 2))


# --- COM height -------------------------------------------------------------------------------


def test_the_com_height_follows_the_support_smoothly_to_the_total_rise():
    stairs = Staircase(0.4, 0.05, 0.3, 3)
    _, plan = walk(stairs)
    support = SupportHeight(plan)
    dt = 1e-3
    t = np.arange(-1.0, plan.end_s + 1.0, dt)
    h, v, a = np.array([support.at(s) for s in t]).T
    assert h[0] == 0.0 and h[-1] == pytest.approx(stairs.total_rise_m)
    assert np.all(np.diff(h) >= -1e-12)  # going up, never down
    # Continuous position, velocity and acceleration, each the derivative of the one before.
    assert np.abs(np.diff(h)).max() < 0.01 * 0.05
    assert np.abs(np.diff(v)).max() < 0.005
    assert np.abs(np.diff(a)).max() < 0.05
    # (central differences: second-order errors where the jerk steps)
    assert np.allclose(np.gradient(h, dt)[1:-1], v[1:-1], atol=1e-4)
    assert np.allclose(np.gradient(v, dt)[1:-1], a[1:-1], atol=5e-3)
    # At each contact change it is the lowest foot's height: never above a foot it stands on.
    for k, t_k in enumerate(plan.times_s):
        assert support.at(t_k)[0] == pytest.approx(plan.positions_in_world[k, :, 2].min())


def _support_height_numpy(support, t_s):
    """SupportHeight.at in numpy scalars (np.searchsorted), as it was written first."""
    times, heights = support.times_s, support.heights_m
    k = int(np.searchsorted(times, t_s, side='right'))
    if k == 0 or k == len(times):
        return float(heights[min(k, len(times) - 1)]), 0.0, 0.0
    t0, t1 = times[k - 1], times[k]
    h0, h1 = heights[k - 1], heights[k]
    span = t1 - t0
    s = (t_s - t0) / span
    rise = h1 - h0
    return (float(h0 + rise * s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)),
            float(rise * 30.0 * s * s * (1.0 - s) ** 2 / span),
            float(rise * 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / span ** 2))


@pytest.mark.parametrize('rise_m', [0.05, -0.04])
def test_the_support_height_in_floats_is_the_numpy_form_to_the_bit(rise_m):
    _, plan = walk(Staircase(0.4, rise_m, 0.3, 3))
    support = SupportHeight(plan)
    rng = np.random.default_rng(3)
    times = np.concatenate([rng.uniform(-1.0, plan.end_s + 1.0, 2000), plan.times_s,
                            np.nextafter(plan.times_s, -np.inf), [-0.0]])
    for t_s in times.tolist():
        got, expected = support.at(t_s), _support_height_numpy(support, t_s)
        # Same floats, signed zeros included (a -0.0 acceleration is other CDR bytes).
        assert [math.copysign(1.0, v) for v in got] == [math.copysign(1.0, v) for v in expected]
        assert got == expected


def test_the_com_height_is_the_same_from_any_later_plan_window():
    stairs = Staircase(0.4, 0.05, 0.3, 3)
    planner, whole = walk(stairs)
    t = np.linspace(9.0, 16.0, 300)
    whole_support = SupportHeight(whole)
    for now_s in (7.3, 8.9, 10.2):
        window = planner.footstep_plan(now_s, origin_ns=0)
        part = SupportHeight(window)
        inside = t >= now_s
        assert np.allclose([part.at_ns(int(s * 1e9))[0] for s in t[inside]],
                           [whole_support.at(s)[0] for s in t[inside]], atol=1e-12)


def test_on_flat_ground_the_com_height_does_not_move():
    _, plan = walk(FLAT)
    support = SupportHeight(plan)
    assert support.flat
    assert {support.at(s) for s in np.linspace(-1, plan.end_s + 1, 50)} == {(0.0, 0.0, 0.0)}


# --- ZMP plane --------------------------------------------------------------------------------


def test_the_zmp_plane_is_the_lowest_contact():
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.sim.zmp_monitor import ZmpMonitor

    robot = load_robot_model('biped')
    monitor = ZmpMonitor(robot.model, robot.description.foot_radius_m, ground_height_m=-0.3)
    q = pin.neutral(robot.model)
    q[2] = 0.7
    rng = np.random.default_rng(3)
    v, a = rng.normal(0.0, 0.1, robot.model.nv), rng.normal(0.0, 0.1, robot.model.nv)
    contacts = np.array([[0.0, 0.1, 0.05], [0.1, -0.1, 0.13]])
    state = monitor.evaluate(q, v, a, contacts)
    assert state.zmp_in_world[2] == 0.05
    # The ZMP on a plane at height z0 moves by (z0 - z) f_xy / f_z from the one at z.
    com, on_ground, fz = monitor.com_and_zmp(q, v, a, 0.0)
    data = robot.model.createData()
    pin.computeCentroidalMomentumTimeVariation(robot.model, data, q, v, a)
    force = data.dhg.linear - monitor.mass_kg * monitor.gravity
    assert np.allclose(state.zmp_in_world[:2], on_ground[:2] + 0.05 * force[:2] / fz)
    assert monitor.evaluate(q, v, a, np.zeros((0, 3))).zmp_in_world[2] == -0.3


# --- footstep_planner node --------------------------------------------------------------------


def test_the_planner_node_refuses_bad_stairs_with_the_range_and_walks_on_unchanged():
    import json

    from gait_nodes import runtime
    from gait_nodes.contract import footsteps_from_msg
    from gait_nodes.interfaces import get_message
    from gait_nodes.runtime import Parameter, qos_profile_latched

    args = ['test', '--ros-args', '-p', 'robot:=biped', '-p', 'gait:=biped',
            '-p', f'step_height_m:={STEP_HEIGHT_M}', '-p', 'step_period_s:=1.5',
            '-p', 'duty_factor:=0.72', '-p', 'stairs_start_x_m:=0.4',
            '-p', 'stairs_rise_m:=0.05', '-p', 'stairs_count:=3']
    runtime.init(args=args, runtime='inproc', signal_handlers=False)
    try:
        from gait_nodes.footstep_planner import FootstepPlanner

        node = FootstepPlanner()
        user = runtime.Node('user', use_global_arguments=False)
        plans, statuses = [], []
        user.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 '/gait/footsteps', plans.append, qos_profile_latched)
        user.create_subscription(get_message('std_msgs/msg/String'), '/gait/command_status',
                                 lambda msg: statuses.append(json.loads(msg.data)), 10)
        command = user.create_publisher(get_message('std_msgs/msg/String'), '/gait/command', 10)
        twist = get_message('geometry_msgs/msg/Twist')()
        twist.linear.x = 0.05
        user.create_publisher(get_message('geometry_msgs/msg/Twist'), '/cmd_vel',
                              10).publish(twist)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        executor.add_node(user)
        executor.spin_for(9.0)
        terrain, params = node.planner.terrain, node.planner.params
        assert terrain == Staircase(0.4, 0.05, 0.3, 3)
        refused = [
            ([Parameter('stairs_rise_m', value=0.5)], 'must be in [-0.3, 0.3] m'),
            ([Parameter('stairs_count', value=99)], 'must be in [0, 50]'),
            ([Parameter('stairs_tread_m', value=0.1)], 'tread must be >='),
            ([Parameter('stairs_start_x_m', value=-2.0)], 'would move the ground under'),
        ]
        for parameters, text in refused:
            result = node.set_parameters(parameters)[0]
            assert not result.successful and text in result.reason, result.reason
        command.publish(get_message('std_msgs/msg/String')(data='{"swing": "value_table"}'))
        executor.spin_for(0.5)
        assert not statuses[-1]['accepted'] and 'flat ground' in statuses[-1]['reason']
        assert node.planner.terrain is terrain and node.planner.params is params
        assert node.get_parameter('stairs_rise_m').value == 0.05
        executor.spin_for(8.0)
        # The walk went on up the stairs, every foothold at its tread's height.
        plan = footsteps_from_msg(plans[-1])
        feet = plan.positions_in_world.reshape(-1, 3)
        assert np.allclose(feet[:, 2], terrain.height_at(feet[:, 0]))
        assert feet[:, 2].max() >= 0.1
    finally:
        runtime.shutdown()


def test_zmp_reference_lies_on_the_plane_of_the_lowest_contact():
    """/gait/zmp_reference's z is the lowest contact's tread at each sample, as the monitor's."""
    from gait_nodes.contract import zmp_reference_from_msg, zmp_reference_to_msg
    from gait_nodes.planning.footsteps import contact_schedule

    planner, _ = walk(Staircase(0.25, 0.07, 0.3, 3))
    reference = planner.zmp_reference(0, 0, 16.0, 0.01)
    heights = zmp_reference_from_msg(zmp_reference_to_msg(reference)).plane_heights_m
    np.testing.assert_array_equal(heights, reference.plane_heights_m)
    plan = planner.footstep_plan()
    times = reference.stamps_ns * 1e-9 - plan.start_ns * 1e-9
    down = contact_schedule(plan, times)
    for n in range(0, len(times), 7):
        k = max(0, int(np.searchsorted(plan.times_s, times[n], side='right')) - 1)
        expected = plan.positions_in_world[k, down[n], 2].min()
        assert heights[n] == pytest.approx(expected, abs=1e-12)
    # It climbs: the first samples on the floor, the last on a stair.
    assert heights[0] == 0.0 and heights[-1] > 0.0
    assert np.all(np.isin(np.round(heights, 9), np.round(np.unique(
        plan.positions_in_world[:, :, 2]), 9)))


@pytest.mark.parametrize('staircase', [Staircase(0.25, 0.07, 0.3, 3), Staircase()],
                         ids=['stairs', 'flat'])
def test_the_sliding_zmp_reference_is_the_whole_computation_to_the_bit(staircase):
    """Each window of the node's ticks is the planner's computation without the last window.

    The ticks advance and prune the plan, change the velocity and jump now and then.
    """
    from gait_nodes.planning.footsteps import GaitPlanner

    planner = GaitPlanner(BIPED, biped_params(), terrain=staircase)
    commands = {0.1: Twist2D(0.1), 4.0: Twist2D(0.05, 0.0, 0.1), 9.0: Twist2D()}
    checked = check_slid_windows(planner, commands, 7_000_000_000, 14_000_000_000)
    assert checked > 500
