"""Swing times at the joint velocity limit, smoothed swings, and the gait rhythm they give.

Identities checked: a smoothed swing keeps its ends, stays above the ground, has a bounded
acceleration and (at its own timing) keeps the joints within the limit; a timing model's time
replayed through the whole-body IK puts the fastest joint exactly at the limit; the planner's
joint-limit rhythm is the fixed point of thesis eq. (2) and every planned swing lasts at least
the time its own displacement needs.
"""

import functools
import json

import numpy as np
import pinocchio as pin
import pytest
from swing_helpers import FAMILY, STEP_HEIGHT_M, robot, tiny_table

from gait_nodes.contract import SwingTrajectory
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.rhythm import (
    BODY_MOVE_TOLERANCE_S,
    MIN_TRANSFER_S,
    cycle_displacements,
    swing_time_s,
    transfer_move,
)
from gait_nodes.robot.whole_body_ik import IkTargets, WholeBodyIkSolver
from gait_nodes.swing.policy import SwingPolicy
from gait_nodes.swing.timing import (
    BODY_MOTION_MARGIN,
    SMOOTHING_S,
    STEP_MARGIN,
    PolynomialSwingTiming,
    TableSwingTiming,
    needed_probe_period,
    smooth_trajectory,
)


@functools.lru_cache(maxsize=1)
def policy():
    table, _ = tiny_table()
    return SwingPolicy(table, robot())


@functools.lru_cache(maxsize=1)
def polynomial_timing():
    return PolynomialSwingTiming(robot(), FAMILY, 1.0, STEP_HEIGHT_M)


def test_smoothed_swing_keeps_its_ends_stays_up_and_is_smooth():
    path, _ = policy().path_for_step(np.array([0.2, 0.0]))
    polyline = SwingTrajectory('x', 0, path.times_s, path.states[:, :3], path.states[:, 3])
    smooth, needed = smooth_trajectory(polyline, None, 0.002)
    assert needed == pytest.approx(path.duration_s + SMOOTHING_S, abs=3e-3)
    assert np.allclose(smooth.positions_in_world[[0, -1]], polyline.positions_in_world[[0, -1]])
    # Averages of the polyline: never below the ground, never outside its bounding box.
    low, high = polyline.positions_in_world.min(axis=0), polyline.positions_in_world.max(axis=0)
    assert np.all(smooth.positions_in_world >= low - 1e-12)
    assert np.all(smooth.positions_in_world <= high + 1e-12)
    # Bounded acceleration (the polyline's is infinite at every corner): at most the largest
    # velocity change over half the kernel.
    t, p = smooth.times_s, smooth.positions_in_world
    velocity = np.diff(p, axis=0) / np.diff(t)[:, None]
    acceleration = np.linalg.norm(np.diff(velocity, axis=0), axis=1) / np.diff(t)[1:]
    polyline_speed = np.linalg.norm(np.diff(path.states[:, :3], axis=0), axis=1) \
        / np.diff(path.times_s)
    assert acceleration.max() < 2.0 * 2.0 * polyline_speed.max() / SMOOTHING_S
    # Lift-off and touch-down at rest.
    assert np.linalg.norm(velocity[0]) < 0.02 and np.linalg.norm(velocity[-1]) < 0.02
    # Stretched to a planned duration: same path, uniformly slower.
    longer, _ = smooth_trajectory(polyline, 2.0 * needed, 0.002)
    assert longer.duration_s == pytest.approx(2.0 * needed)
    halfway = np.array([np.interp(0.5 * longer.duration_s, longer.times_s, longer.
                                  positions_in_world[:, i]) for i in range(3)])
    expected = np.array([np.interp(0.5 * needed, t, p[:, i]) for i in range(3)])
    assert np.allclose(halfway, expected, atol=1e-3)


def test_smoothed_table_swing_keeps_the_joints_within_the_limit():
    # The polyline's velocity is a joint-limited one on each segment; the filter averages
    # velocities, so the joints stay at the limit to first order (the IK's curvature over the
    # kernel is the second order: up to 7.4 % with the 0.1 s kernel). The timing models time
    # the smoothed shape by its joints' actual speeds on its samples: played at that time and
    # sampled 10 times finer (as the swing-leg policy publishes it), the joints stay within
    # half a per cent of the limit.
    timing = policy().timing
    for step in (0.1, 0.2):
        path, _ = policy().path_for_step(np.array([step, 0.0]))
        polyline = SwingTrajectory('x', 0, path.times_s, path.states[:, :3],
                                   path.states[:, 3])
        smooth, _ = smooth_trajectory(polyline, None, 0.002)
        q, feasible = timing.joints(np.column_stack([smooth.positions_in_world,
                                                     smooth.yaws_rad]))
        assert feasible.all()
        rates = np.abs(np.diff(q, axis=0)) / np.diff(smooth.times_s)[:, None]
        assert rates.max() <= 1.0 * 1.1
        # The same swing on the samples the timing models probe it at.
        coarse, _ = smooth_trajectory(polyline, None, needed_probe_period(path))
        q_coarse, _ = timing.joints(np.column_stack([coarse.positions_in_world,
                                                     coarse.yaws_rad]))
        probed = np.abs(np.diff(q_coarse, axis=0)) / np.diff(coarse.times_s)[:, None]
        assert probed.max() <= rates.max() <= 1.005 * probed.max()


def _whole_body_peak(timing, step, duration_s) -> float:
    """Peak joint speed / limit of the model's swing played in ``duration_s`` through the IK."""
    model = robot()
    u, states = timing.shape(np.asarray(step, dtype=float), 0.0)
    solver = WholeBodyIkSolver(model)
    q = timing._q_nominal.copy()
    com = pin.centerOfMass(model.model, model.new_data(), q).copy()
    feet = model.nominal_feet_in_world(q[:3], 0.0)
    joints, solutions = [], [q]
    for state in states:
        feet[timing._reference] = timing._q_nominal[:3] + state[:3]
        yaws = np.zeros(len(feet))
        yaws[timing._reference] = state[3]
        q = solver.solve(IkTargets(feet, yaws, 0.0, com_in_world=com),
                         solver.warm_start(solutions[-3:])).q
        solutions.append(q)
        joints.append(model.joint_positions(q))
    rates = np.abs(np.diff(np.array(joints), axis=0)) / (np.diff(u) * duration_s)[:, None]
    return float((rates / model.velocity_limits_rad_s).max())


@pytest.mark.parametrize('make', [polynomial_timing, lambda: TableSwingTiming(
    policy(), robot(), 'static_crawl')])
def test_model_time_puts_the_fastest_joint_at_the_limit(make):
    timing = make()
    for step in (0.04, 0.2):  # lattice nodes: swing_s interpolates between them
        raw = timing.raw_s(np.array([step, 0.0]), 0.0)
        assert _whole_body_peak(timing, [step, 0.0], raw) == pytest.approx(1.0, rel=1e-6)
        # The planner's time has the margin for the body's sway on top.
        assert timing.swing_s(1, np.array([step, 0.0])) == pytest.approx(
            (1.0 + BODY_MOTION_MARGIN) * raw, rel=1e-9)
    # Longer steps take longer; mirrored feet (a rear foot walking forwards) the same time.
    times = [timing.swing_s(1, np.array([s, 0.0])) for s in (0.0, 0.1, 0.2)]
    assert times[0] < times[1] < times[2]
    feet = robot().description.foot_names
    rear = feet.index('rear_left')
    assert timing.swing_s(rear, np.array([0.1, 0.0])) == pytest.approx(
        timing.swing_s(feet.index('front_left'), np.array([-0.1, 0.0])))


def _joint_limit_params(**values):
    return GaitParameters.for_robot(robot().description, gait='crawl', timing='joint_limit',
                                    **values)


def test_rhythm_is_the_fixed_point_of_eq_2():
    timing = polynomial_timing()
    params = _joint_limit_params()
    planner = GaitPlanner(robot().description, params, swing_timing=timing)
    twist = Twist2D(0.006)
    rhythm = planner.rhythm(params, twist)
    displacements, turn = cycle_displacements(planner.layout, params, twist, rhythm.cycle_s)
    assert rhythm.swing_s == pytest.approx(swing_time_s(timing, displacements, turn), rel=1e-5)
    # Thesis eq. (2): four swings and the body's move (the swing's horizontal part) per cycle,
    # the move at least as long as the stance limbs need at the limit.
    in_place = timing.lift_and_lower_s()
    body_move = timing.steady_transfer_s(transfer_move('crawl', planner.layout, params, twist,
                                                       rhythm))
    transfer = max(MIN_TRANSFER_S, 0.5 * (rhythm.swing_s - in_place), body_move)
    assert rhythm.cycle_s == pytest.approx(4 * rhythm.swing_s + 2 * transfer,
                                           abs=2 * BODY_MOVE_TOLERANCE_S)
    assert rhythm.duty_factor > 0.75
    # The stride the velocity asks for over that cycle.
    assert np.abs(displacements[:, 0]).max() == pytest.approx(0.006 * rhythm.cycle_s)


def test_too_fast_a_command_walks_the_fastest_feasible_speed_and_says_so():
    params = _joint_limit_params(max_vx_m_s=1.0)
    planner = GaitPlanner(robot().description, params, swing_timing=polynomial_timing())
    applied, notes = planner.set_velocity(Twist2D(0.5), 0.0)
    assert 0.0 < applied.vx_m_s < 0.5
    assert notes and 'fastest rhythm the joint velocity limit allows' in notes[-1]
    rhythm = planner.rhythm()
    # The fastest speed is the one whose stride is the longest allowed, or (RoboSimian: the
    # swing time grows faster than its stride beyond about 0.15 m) the last with a rhythm.
    assert applied.vx_m_s * rhythm.cycle_s <= params.step_length_m * (1 + 1e-3)
    _, notes = planner.set_velocity(Twist2D(1.01 * applied.vx_m_s), 0.0)
    assert notes and 'fastest rhythm' in notes[-1]
    slower, notes = planner.set_velocity(Twist2D(0.5 * applied.vx_m_s), 0.0)
    assert slower.vx_m_s == pytest.approx(0.5 * applied.vx_m_s) and not notes


def test_every_too_fast_command_in_a_direction_walks_the_same_fastest_twist():
    # The fastest feasible twist is searched along the command's direction, once: a joystick
    # streaming ever new too-fast forward speeds does not make the planner search again (1-3 s
    # each for RoboSimian), and the answer does not depend on which command came first.
    params = _joint_limit_params()
    first = GaitPlanner(robot().description, params, swing_timing=polynomial_timing())
    fast, _ = first.set_velocity(Twist2D(0.08), 0.0)
    faster, notes = first.set_velocity(Twist2D(0.1), 0.0)
    assert faster == fast and 'fastest rhythm' in notes[-1]
    other = GaitPlanner(robot().description, params, swing_timing=polynomial_timing())
    assert other.set_velocity(Twist2D(0.1), 0.0)[0] == fast
    # Another direction has its own fastest twist, in that direction.
    turning, _ = other.set_velocity(Twist2D(0.08, 0.0, 0.05), 0.0)
    assert turning.vx_m_s / turning.wz_rad_s == pytest.approx(0.08 / 0.05)
    assert turning.vx_m_s < fast.vx_m_s


def test_probe_where_the_swing_happens_agrees_with_the_nominal_model():
    # A swing from half a step behind to half a step ahead of the nominal foot, the other feet
    # and the COM at the nominal stance: the per-step probe and the planner's lattice model
    # time the same motion.
    from gait_nodes.contract import Swing

    timing = polynomial_timing()
    description = robot().description
    feet = timing._feet.copy()
    front_right = description.foot_names.index('front_right')
    for step in (0.0, 0.1, 0.2):
        swing = Swing('front_right', 0.0, 1.0, feet[front_right] - [0.5 * step, 0.0, 0.0],
                      feet[front_right] + [0.5 * step, 0.0, 0.0], 0.0, 0.0)
        start = feet.copy()
        start[front_right] = swing.start_in_world
        probed = timing.step_s({front_right: swing}, start, np.zeros(len(feet)), 0.0,
                               timing._com)
        assert probed / (1.0 + STEP_MARGIN) == pytest.approx(
            timing.raw_s(np.array([step, 0.0]), 0.0), rel=1e-3)


def test_every_planned_swing_has_the_time_its_own_step_needs():
    # Start, a velocity change, a turn, a gait change and the stop: the steps that do not
    # follow the steady pattern are re-timed to what the probe of their swings needs.
    timing = polynomial_timing()
    description = robot().description
    params = _joint_limit_params()
    probed = []
    step_s = timing.step_s

    def spy(swings, *args):
        needed = step_s(swings, *args)
        probed.append((tuple(sorted(swings)), tuple(s.end_in_world[0] for s in
                                                    swings.values()), needed))
        return needed

    timing.step_s = spy
    try:
        commands = [(0.5, Twist2D(0.03)), (6.0, Twist2D(0.02, 0.0, 0.02)),
                    (12.0, params.replace(gait='trot')), (18.0, Twist2D())]
        planner = plan_walk(description, params, commands, 30.0, swing_timing=timing)
    finally:
        del timing.step_s
    needed = {(feet, ends): value for feet, ends, value in probed}
    swings = 0
    for step in planner.steps:
        for slot in step.slots:
            key = (tuple(sorted(slot.feet)), tuple(slot.positions_after[f][0]
                                                   for f in sorted(slot.feet)))
            assert slot.touch_down_s - slot.lift_off_s >= needed[key] * (1 - 1e-9)
            swings += 1
    assert swings >= 5  # RoboSimian at 1 rad/s: a swing takes 2-5 s
    assert {step.gait for step in planner.steps} == {'crawl', 'trot'}


def test_every_transfer_has_the_time_its_body_move_needs():
    # The body's move with every foot down is timed at the joint limit as a swing is: the
    # steady crawl's rhythm gives it that time, and any other step is re-timed to it.
    timing = polynomial_timing()
    params = _joint_limit_params()
    probed = []
    transfer_s = timing.transfer_s

    def spy(feet, yaws, body_yaw, com_from, com_to, *rest):
        needed = transfer_s(feet, yaws, body_yaw, com_from, com_to, *rest)
        probed.append((tuple(com_from[:2]), needed))
        return needed

    timing.step_s, timing.transfer_s = timing.step_s, spy
    try:
        planner = plan_walk(robot().description, params, [(0.5, Twist2D(0.03))], 60.0,
                            swing_timing=timing)
    finally:
        del timing.transfer_s, timing.step_s
    needed = dict(probed)
    walking = [step for step in planner.steps if step.slots]
    assert len(walking) >= 5
    for step in walking:
        transfer = step.slots[0].lift_off_s - step.start_s
        assert transfer >= needed[tuple(step.zmp_points[0])] * (1 - 1e-9)
    # Steady steps keep the rhythm's period: it already holds the transfer they need.
    rhythm = planner.rhythm()
    assert walking[-1].end_s - walking[-1].start_s == pytest.approx(rhythm.step_period_s)


def test_a_retimed_step_keeps_its_footholds_and_the_path_waits():
    # Every swing probed twice as long as it is (as a body sway the rhythm's model does not see
    # would; the model has 1.4 times the probe's time at most): each step is re-timed, keeps
    # the footholds the rhythm chose and delays the path by the time it adds. (Re-planned with
    # the longer swing to footholds further ahead, the strides grew with every re-timing until
    # a swing left the reach.)
    timing = polynomial_timing()
    params = _joint_limit_params()
    step_s = timing.step_s
    timing.step_s = lambda *args: 2.0 * step_s(*args)
    try:
        planner = plan_walk(robot().description, params, [(0.5, Twist2D(0.01))], 120.0,
                            swing_timing=timing)
    finally:
        del timing.step_s
    rhythm = planner.rhythm()
    stride = 0.01 * rhythm.cycle_s
    walking = [step for step in planner.steps if step.slots]
    assert len(walking) >= 6
    for k, step in enumerate(walking):
        before = step.positions_start
        for slot in step.slots:
            moved = slot.positions_after[list(slot.feet)] - before[list(slot.feet)]
            assert np.abs(moved[:, 0]).max() <= stride * (1 + 1e-6)
            if k >= 2:  # the first steps (shorter than a stride) may fit their rhythm
                assert slot.touch_down_s - slot.lift_off_s > 1.3 * rhythm.swing_s
            before = slot.positions_after
    # Steady: every foot a stride a (longer) cycle, the footholds a stride apart.
    last = walking[-1].slots[-1]
    assert np.abs(last.positions_after - walking[-3].slots[-1].positions_after)[:, 0] \
        == pytest.approx(stride, rel=1e-6)


def test_a_command_from_standstill_starts_the_walk_at_once():
    params = _joint_limit_params()
    planner = GaitPlanner(robot().description, params, swing_timing=polynomial_timing())
    planner.advance(7.3 + 2 * params.step_period_s)  # standing steps planned ahead
    planner.set_velocity(Twist2D(0.02), 7.3)
    planner.advance(20.0)
    first = min(slot.lift_off_s for step in planner.steps for slot in step.slots)
    # After the weight shift (at most 1 s) and the first transfer (1.8 s at the joint limit).
    assert 7.3 < first <= 7.3 + 3.0
    # The ZMP reference is continuous where the standstill was cut.
    times = np.linspace(7.0, 8.0, 201)
    zmp = planner.zmp(times)
    assert np.abs(np.diff(zmp, axis=0)).max() < 0.01


def test_without_a_built_table_the_slower_polynomial_times_stand_in(tmp_path, monkeypatch):
    from gait_nodes.swing.timing import STAND_IN_FACTOR, swing_timing

    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path))
    model, reason = swing_timing(robot(), 'value_table', STEP_HEIGHT_M, 'static_crawl')
    assert isinstance(model, PolynomialSwingTiming) and 'not built yet' in reason
    assert model.swing_s(1, np.array([0.1, 0.0])) == pytest.approx(
        STAND_IN_FACTOR * polynomial_timing().swing_s(1, np.array([0.1, 0.0])))
    # A robot without closed-form limb IK has no model: its gait keeps fixed timing.
    from gait_nodes.robot.model import load_robot_model

    assert swing_timing(load_robot_model('biped'), 'polynomial', STEP_HEIGHT_M, 'biped')[0] is None


def _lattice_s_numpy(timing, step_in_base, turn_rad):
    """SwingTiming._lattice_s as it was first written (numpy), on the same cache."""
    from gait_nodes.swing.timing import _CORNERS, LATTICE

    point = np.array([step_in_base[0], step_in_base[1], turn_rad], dtype=float)
    if point[0] < 0 or (point[0] == 0 and (point[1] < 0 or (point[1] == 0
                                                              and point[2] < 0))):
        point = -point
    point = point / LATTICE
    low = np.floor(point).astype(int)
    weight = point - low
    weights = np.prod(np.where(_CORNERS, weight, 1.0 - weight), axis=1)
    total = 0.0
    for corner, w in zip(low + _CORNERS, weights, strict=True):
        if w == 0.0:
            continue
        total += float(w) * timing._cache[(int(corner[0]), int(corner[1]), int(corner[2]))]
    return total


def test_lattice_interpolation_in_floats_is_the_numpy_form_to_the_bit():
    timing = object.__new__(PolynomialSwingTiming)
    rng = np.random.default_rng(5)
    timing._cache, timing._stored_path = {}, None  # a made-up model: nothing on disk

    def raw_s(node, turn):  # a made-up smooth time law: only the interpolation is checked
        return 0.5 + float(np.hypot(*node)) + 0.3 * abs(turn) + 1e-3 * rng.random()

    timing.raw_s = raw_s
    points = np.concatenate([rng.normal(0.0, 0.1, (3000, 3)),
                             np.round(rng.normal(0.0, 0.1, (300, 3)) / 0.02) * 0.02,
                             [[0.0, 0.0, 0.0], [-0.0, 0.0, -0.05], [0.0, -0.04, 0.1]]])
    for x, y, turn in points.tolist():
        got = timing._lattice_s(np.array([x, y]), turn)
        assert got == _lattice_s_numpy(timing, (x, y), turn)


def test_swing_s_in_floats_and_looked_up_is_the_numpy_form_to_the_bit():
    """swing_s (plain-float mirroring, steps asked again looked up) equals the array form."""
    from gait_nodes.swing.timing import BODY_MOTION_MARGIN

    timing = object.__new__(PolynomialSwingTiming)
    rng = np.random.default_rng(7)
    timing._cache, timing._swing_s, timing._stored_path = {}, {}, None  # nothing on disk
    timing.raw_s = lambda node, turn: 0.5 + float(np.hypot(*node)) + 0.3 * abs(turn)
    timing._mirrors = [np.array(m, dtype=float) for m in
                       ([1, 1, 1], [1, -1, 1], [-1, 1, 1], [-1, -1, 1])]
    timing._mirror_floats = [(float(m[0]), float(m[1])) for m in timing._mirrors]
    steps = np.concatenate([rng.normal(0.0, 0.1, (500, 3)),
                            np.round(rng.normal(0.0, 0.1, (100, 3)) / 0.02) * 0.02,
                            [[0.0, -0.0, 0.0], [-0.0, 0.0, -0.0], [0.1, 0.0, 0.0]]])
    for _ in range(2):  # the second pass is looked up
        for x, y, turn in steps.tolist():
            for foot, mirror in enumerate(timing._mirrors):
                step = np.array([x, y]) * mirror[:2]
                expected = (1.0 + BODY_MOTION_MARGIN) * timing._lattice_s(
                    step, float(mirror[0] * mirror[1]) * turn)
                assert timing.swing_s(foot, np.array([x, y]), turn) == expected


def test_ik_probes_solve_checked_targets_as_solve_does(monkeypatch):
    """The probes' solve_trusted on targets checked once: solve's floats, solve's refusals."""
    timing = polynomial_timing()
    fast = timing.raw_s(np.array([0.15, 0.03]), 0.1)
    solver = timing._solver
    reference = WholeBodyIkSolver(timing.robot, solver.settings)

    def through_solve(feet, yaws, body_yaw_rad, q_start, com):
        return reference.solve(IkTargets(feet, np.array(yaws), body_yaw_rad,
                                         com_in_world=com), q_start)

    with monkeypatch.context() as patch:
        patch.setattr(solver, 'solve_trusted', through_solve)
        assert timing.raw_s(np.array([0.15, 0.03]), 0.1) == fast
    with pytest.raises(ValueError, match='NaN'):
        timing.raw_s(np.array([np.nan, 0.0]), 0.0)


def test_the_models_node_times_are_kept_on_disk_and_found_by_the_next_model(tmp_path,
                                                                            monkeypatch):
    # The ZMP crawl's fastest walk, searched at every start of it and switch to it, timed its
    # lattice nodes through the whole-body IK each time (1.2 s of 2.5 s on RoboSimian). A
    # second model of the same robot and swings takes the stored times, the same to the bit,
    # and computes none; a model with other limits has its own; an unreadable file is computed
    # anew and written again.
    import dataclasses

    from gait_nodes.robot.model import RobotModel
    from gait_nodes.swing import timing as timing_module

    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path))
    first = PolynomialSwingTiming(robot(), FAMILY, 1.0, 0.06)
    swing_s = first.swing_s(0, np.array([0.13, 0.02]))
    transfer_s = first.steady_transfer_s(np.array([0.05, 0.0]))
    (stored,) = (tmp_path / 'gait_nodes').glob('timing_robosimian_*.json')

    def no_ik(*args, **kwargs):
        raise AssertionError('a stored node time was computed again')

    with monkeypatch.context() as patched:
        patched.setattr(timing_module.SwingTiming, '_time_through_ik', no_ik)
        second = PolynomialSwingTiming(robot(), FAMILY, 1.0, 0.06)
        assert second.swing_s(0, np.array([0.13, 0.02])) == swing_s
        assert second.steady_transfer_s(np.array([0.05, 0.0])) == transfer_s
        slower = RobotModel(dataclasses.replace(robot().description,
                                                joint_velocity_limit_rad_s=0.5))
        with pytest.raises(AssertionError, match='computed again'):
            PolynomialSwingTiming(slower, FAMILY, 0.5, 0.06).swing_s(0, np.array([0.13, 0.02]))
    stored.write_text('{"swing_s": [[1, 2')
    third = PolynomialSwingTiming(robot(), FAMILY, 1.0, 0.06)
    assert third.swing_s(0, np.array([0.13, 0.02])) == swing_s
    assert len(json.loads(stored.read_text())['swing_s']) > 0


def test_a_value_table_swing_is_timed_in_the_law_of_the_gait_it_is_walked_in(tmp_path,
                                                                              monkeypatch):
    # The static crawl's swings happen outwards of its stance (the body still), the ZMP gaits'
    # inwards too (the body moving under them): each gait's swings are timed at its own places,
    # by the swing-leg policy and by the planner's model alike, and each model keeps its own
    # node times.
    from gait_nodes.swing.cache import node_times_path
    from gait_nodes.swing.policy import (
        LAW_PLACEMENTS_M,
        MOVING_BODY_LAW_PLACEMENTS_M,
        law_placements,
    )

    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path))
    assert law_placements('static_crawl') == LAW_PLACEMENTS_M
    assert law_placements('crawl') == law_placements('trot') == MOVING_BODY_LAW_PLACEMENTS_M
    assert min(MOVING_BODY_LAW_PLACEMENTS_M) < 0.0 <= min(LAW_PLACEMENTS_M)
    step = np.array([0.2, 0.0])
    still, _ = policy().fastest_swing(step, 0.0, 'front_left', 'static_crawl')
    moving, _ = policy().fastest_swing(step, 0.0, 'front_left', 'crawl')
    assert still.duration_s != moving.duration_s
    models = {gait: TableSwingTiming(policy(), robot(), gait)
              for gait in ('static_crawl', 'crawl', 'trot')}
    # The planner's probes take the same swing in the same time law as the policy sends.
    shapes = {gait: model.shape(step, 0.0, foot='front_left')[1]
              for gait, model in models.items()}
    assert np.array_equal(shapes['crawl'], shapes['trot'])
    assert shapes['crawl'].shape != shapes['static_crawl'].shape or \
        not np.allclose(shapes['crawl'], shapes['static_crawl'])
    paths = {gait: node_times_path(model, 'timing') for gait, model in models.items()}
    assert paths['crawl'] == paths['trot'] != paths['static_crawl']
