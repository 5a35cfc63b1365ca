"""ZMP reference of every gait, checked against the seeds.

ZMP reference: inside the support polygon of the scheduled contacts with the margin at every
sample, on the support line as the seeds say (Lucy: at the stance ankle, rear to front in double
support; Kurazume: on the support diagonal, L = 4 D tan(theta); thesis: from the diagonal pairs,
moving half a stride twice a cycle), continuous, and untouched before a change's boundary.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from planning_helpers import check_slid_windows, robot, stance_at, zmp_depths, zmp_margins

from gait_nodes.planning.footsteps import Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.support import point_segment_distance

QUADRUPED = robot('quadruped')
BIPED = robot('biped')
FAST = dict(step_period_s=1.0, max_vx_m_s=1.0, max_vy_m_s=1.0, max_wz_rad_s=1.0)
GAITS = {
    'crawl': (QUADRUPED, dict(gait='crawl', duty_factor=0.85, **FAST)),
    'trot': (QUADRUPED, dict(gait='trot', duty_factor=0.7, **FAST)),
    'biped': (BIPED, dict(gait='biped', duty_factor=0.9, **FAST)),
}
DT = 0.005


def walk(gait, commands, end_s=20.0, **changes):
    description, values = GAITS[gait]
    params = GaitParameters.for_robot(description, **{**values, **changes})
    planner = plan_walk(description, params, commands, end_s)
    plan = planner.footstep_plan()
    times = np.arange(0.0, plan.end_s + 2.0, DT)
    return description, params, planner, plan, times, planner.zmp(times)


TWISTS = [Twist2D(0.1, 0, 0), Twist2D(0.08, 0, 0.1), Twist2D(0, 0.04, 0), Twist2D(-0.05, 0, 0),
          Twist2D(0.06, -0.03, -0.08)]


@pytest.mark.parametrize('gait', sorted(GAITS))
@pytest.mark.parametrize('twist', TWISTS, ids=str)
def test_zmp_inside_the_support_polygon_with_the_margin(gait, twist):
    description, params, planner, plan, times, zmp = walk(
        gait, [(0.3, twist), (7.1, Twist2D(twist.vx_m_s, 0, 0)), (12.0, Twist2D())])
    margins = zmp_margins(plan, times, zmp, description.foot_radius_m)
    assert margins.min() >= params.zmp_margin_m - 1e-9
    if gait == 'crawl':
        # Even with point feet: inside every three-foot support triangle by the margin.
        assert zmp_depths(plan, times, zmp).min() >= params.zmp_margin_m - 1e-9
    # Continuous: no jump between samples.
    assert np.max(np.linalg.norm(np.diff(zmp, axis=0), axis=1)) < 0.02


@settings(max_examples=25, deadline=None)
@given(vx=st.floats(-0.2, 0.2), vy=st.floats(-0.1, 0.1), wz=st.floats(-0.15, 0.15),
       margin=st.floats(0.001, 0.1))
def test_crawl_margin_holds_for_any_twist(vx, vy, wz, margin):
    description, params, planner, plan, times, zmp = walk(
        'crawl', [(0.3, Twist2D(vx, vy, wz)), (6.0, Twist2D())], end_s=12.0, zmp_margin_m=margin)
    kept = min(step.zmp_margin_kept_m for step in planner.steps)
    assert kept >= margin - 1e-9  # in the support polygon of the feet's discs
    assert zmp_margins(plan, times, zmp, description.foot_radius_m).min() >= kept - 1e-9
    # With point feet too, as long as the triangles leave room for the margin.
    assert zmp_depths(plan, times, zmp).min() >= min(margin, kept - description.foot_radius_m) \
        - 1e-9


def test_biped_zmp_is_at_the_stance_ankle_and_moves_rear_to_front_in_double_support():
    description, params, planner, plan, times, zmp = walk(
        'biped', [(0.3, Twist2D(0.1, 0, 0.05)), (12.0, Twist2D())])
    positions, down = stance_at(plan, times)
    single = down.sum(axis=1) == 1
    assert single.any()
    for z, p, d in zip(zmp[single], positions[single], down[single], strict=True):
        np.testing.assert_allclose(z, p[d][0], atol=1e-12)  # Lucy: at the ankle
    # Double support: on the segment between the ankles, from the one that stood to the other.
    for step in planner.steps:
        if step.kind != 'walk' or not step.slots:
            continue
        stance = next(f for f in range(2) if f not in step.slots[0].feet)
        rear = 1 - stance
        t = np.arange(step.start_s, step.slots[0].lift_off_s, DT)
        z = planner.zmp(t)
        a, b = step.positions_start[rear], step.positions_start[stance]
        assert max(point_segment_distance(p, a, b) for p in z) < 1e-9
        progress = (z - a) @ (b - a) / ((b - a) @ (b - a))
        if step.start_s > 2.0:
            assert np.all(np.diff(progress) >= -1e-12)  # rear to front, never back
            assert progress[-1] == pytest.approx(1.0, abs=0.02)


def test_trot_zmp_is_on_the_support_diagonal_and_sways_as_kurazume():
    description, params, planner, plan, times, zmp = walk(
        'trot', [(0.3, Twist2D(0.1, 0, 0)), (14.0, Twist2D())])
    positions, down = stance_at(plan, times)
    two = down.sum(axis=1) == 2
    for z, p, d in zip(zmp[two], positions[two], down[two], strict=True):
        a, b = p[d]
        assert point_segment_distance(z, a, b) < 1e-9
    # Kurazume (22): L = 4 D tan(theta), theta the diagonal's angle to the lateral axis.
    steady = (times > 5.0) & (times < 11.0)
    sway = np.max(np.abs(zmp[steady, 1]))
    half_length, half_width = 0.5, 0.5 * params.step_width_m
    stride = 0.1 * params.cycle_s
    assert stride == pytest.approx(4 * sway * half_length / half_width, rel=1e-6)


def test_crawl_zmp_moves_twice_a_cycle_by_half_a_stride():
    description, params, planner, plan, times, zmp = walk(
        'crawl', [(0.3, Twist2D(0.1, 0, 0)), (14.0, Twist2D())])
    # Held still whenever a foot swings.
    positions, down = stance_at(plan, times)
    swinging = down.sum(axis=1) == 3
    for swing in plan.swings():
        inside = (times > swing.lift_off_s) & (times < swing.touch_down_s)
        assert np.ptp(zmp[inside], axis=0).max() < 1e-12
    # Moves: one per step, i.e. twice per cycle, of half a stride forward in steady state.
    steady = [s for s in planner.steps if s.kind == 'walk' and 5.0 < s.start_s < 10.0]
    assert len(steady) >= 2 * int(5.0 / params.cycle_s)
    for step in steady:
        move = step.zmp_points[1] - step.zmp_points[0]
        assert move[0] == pytest.approx(0.5 * 0.1 * params.cycle_s, abs=1e-9)
    assert swinging.any()


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_a_mid_walk_change_moves_the_zmp_no_more_than_the_new_steps(gait):
    commands = [(0.3, Twist2D(0.1, 0, 0))]
    base = walk(gait, commands, end_s=16.0)
    changed = walk(gait, commands + [(6.2, Twist2D(0.05, 0.02, 0.1))], end_s=16.0)
    planner_a, planner_b = base[2], changed[2]
    boundary = next(s.end_s for s in planner_a.steps if s.start_s <= 6.2 < s.end_s)
    times = np.arange(6.2, 6.2 + 2.0, DT)
    zmp_a, zmp_b = planner_a.zmp(times), planner_b.zmp(times)
    before = times < boundary
    np.testing.assert_array_equal(zmp_a[before], zmp_b[before])
    # After the boundary the reference differs by at most how far the footholds differ.
    feet_a = np.concatenate([s.positions_end for s in planner_a.steps
                             if boundary <= s.start_s < 6.2 + 2.0 + 2.0])
    feet_b = np.concatenate([s.positions_end for s in planner_b.steps
                             if boundary <= s.start_s < 6.2 + 2.0 + 2.0])
    foothold_change = np.max(np.linalg.norm(feet_a - feet_b, axis=1))
    assert np.max(np.linalg.norm(zmp_a - zmp_b, axis=1)) <= foothold_change + 1e-9


@settings(max_examples=60, deadline=None)
@given(knots=st.lists(st.tuples(st.floats(1e-3, 2.0), st.floats(-5.0, 5.0)), min_size=1,
                      max_size=8),
       start=st.floats(-10.0, 10.0), picks=st.lists(st.integers(0, 20), min_size=1, max_size=6),
       between=st.lists(st.floats(-1.0, 2.0), min_size=1, max_size=12))
def test_interp_floats_is_np_interp_to_the_bit(knots, start, picks, between):
    # The planner's slid ZMP windows sample their new points in plain floats: the same bits as
    # np.interp at the knots, between them, beyond both ends, and for a single knot.
    from gait_nodes.planning.zmp_reference import interp_floats

    xs = (start + np.cumsum([gap for gap, _ in knots])).tolist()
    ys = [value for _, value in knots]
    queries = [xs[k % len(xs)] for k in picks]
    queries += [xs[0] + f * (xs[-1] - xs[0] + 0.5) - 0.25 for f in between]
    queries += [xs[0] - 1.0, xs[-1] + 1.0, -0.0, 0.0]
    expected = np.interp(np.array(queries), np.array(xs), np.array(ys))
    got = np.array([interp_floats(x, xs, ys) for x in queries])
    np.testing.assert_array_equal(got.view(np.int64), expected.view(np.int64))
    assert np.isnan(interp_floats(float('nan'), xs, ys)) == (len(xs) > 1)


@pytest.mark.parametrize('gait', sorted(GAITS))
def test_slid_flat_windows_equal_windows_sampled_whole(gait):
    # zmp_reference samples only the new tail of a window slid on flat ground (in floats); every
    # window must be bit for bit the one sampled whole, across velocity changes, a stop, ticks
    # skipped and a tick off the sample lattice.
    from gait_nodes.planning.footsteps import GaitPlanner

    description, values = GAITS[gait]
    planner = GaitPlanner(description, GaitParameters.for_robot(description, **values))
    commands = {0.1: Twist2D(0.1), 3.0: Twist2D(0.05, 0.02, 0.1), 7.0: Twist2D()}
    checked = check_slid_windows(planner, commands, 3_000_000_000, 10_000_000_000)
    assert checked > 400


def test_corners_keep_the_reference_and_drop_the_straight_samples():
    """A piecewise-linear reference sampled every 10 ms goes on the wire as its corners."""
    from gait_nodes.contract import ZmpReference

    stamps = np.arange(0, 2_000_000_001, 10_000_000, dtype=np.int64)
    t = stamps * 1e-9
    x = np.interp(t, [0.0, 0.4, 0.9, 1.3, 2.0], [0.0, 0.0, 0.1, 0.1, 0.25])
    y = np.interp(t, [0.0, 0.4, 0.9, 1.3, 2.0], [0.0, 0.05, 0.05, -0.05, -0.05])
    heights = np.interp(t, [0.0, 1.0, 1.5, 2.0], [0.0, 0.0, 0.1, 0.1])
    reference = ZmpReference(stamps, np.column_stack([x, y]), heights)
    corners = reference.corners()
    assert corners.stamps_ns.tolist() == [int(round(s * 1e9)) for s in
                                          (0.0, 0.4, 0.9, 1.0, 1.3, 1.5, 2.0)]
    np.testing.assert_allclose(corners.sample(stamps), reference.zmp_in_world, atol=1e-12)
    np.testing.assert_allclose(np.interp(stamps, corners.stamps_ns, corners.plane_heights_m),
                               heights, atol=1e-12)
    # Nothing to drop: the same object.
    bent = ZmpReference(stamps[:3], np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1]]))
    assert bent.corners() is bent
