"""The static crawl's kinematics (gait_nodes.swing.still_body), checked against the whole-body IK.

The body-still times and COM come from the closed-form limb IK; here the same motions are
replayed through the whole-body IK with the base held where the plan puts it (Levenberg-Marquardt
on Pinocchio's kinematics, another code path), and the joints' speeds and the COM are measured
on its solutions.
"""

import dataclasses
import json

import numpy as np
import pytest
from swing_helpers import robot

from gait_nodes.contract import Swing
from gait_nodes.errors import GaitParameterError
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.robot.description import load_robot_description
from gait_nodes.robot.whole_body_ik import (
    IkSettings,
    IkTargets,
    WholeBodyIkSolver,
    seed_configuration,
)
from gait_nodes.swing.still_body import (
    BODY_MOVE_PEAK_ACCELERATION,
    BODY_MOVE_PEAK_FACTOR,
    TRACKING_MARGIN,
    StillBody,
    body_move,
    cart_table_zmp,
)
from gait_nodes.swing.timing import PolynomialSwingTiming

HEIGHT_M = 0.7


@pytest.fixture(scope='module')
def still():
    return StillBody(PolynomialSwingTiming(robot(), 2, 1.0, 0.06))


def held_base_joints(model, base, feet, yaws):
    """Joint vectors reaching ``feet`` (N, F, 3) with the base held at ``base`` (N, 3)."""
    solver = WholeBodyIkSolver(model, IkSettings(max_iterations=200))
    joints = []
    q = None
    for b, f, y in zip(base, feet, yaws, strict=True):
        targets = IkTargets(f, y, 0.0, base_position_in_world=b)
        q = solver.solve(targets, seed_configuration(model, targets, 2) if q is None else q).q
        joints.append(model.joint_positions(q))
    return np.array(joints), q


def test_body_move_starts_and_ends_at_rest_with_its_stated_peaks():
    u = np.linspace(0.0, 1.0, 20001)
    s = body_move(u)
    v = np.gradient(s, u)
    a = np.gradient(v, u)
    assert s[0] == 0.0 and s[-1] == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.diff(s) >= 0.0)
    assert v[0] == pytest.approx(0.0, abs=1e-3) and v[-1] == pytest.approx(0.0, abs=1e-3)
    assert abs(a[2]) < 0.05 and abs(a[-3]) < 0.05  # no acceleration jump at the ends
    assert v.max() == pytest.approx(BODY_MOVE_PEAK_FACTOR, rel=1e-6)
    assert np.abs(a[5:-5]).max() == pytest.approx(BODY_MOVE_PEAK_ACCELERATION, rel=1e-4)


def test_cart_table_zmp_of_a_parabola():
    t = np.linspace(0.0, 1.0, 51)
    com = np.column_stack([0.3 * t * t, -0.1 * t * t, np.full_like(t, 0.5)])
    zmp = cart_table_zmp(t, com, 0.5)
    expected = com[:, :2] - 0.5 / 9.81 * np.array([0.6, -0.2])
    np.testing.assert_allclose(zmp[1:-1], expected[1:-1], atol=1e-12)


def test_com_and_base_for_com_agree_with_the_whole_body_ik(still):
    model = robot()
    feet = model.nominal_feet_in_world(np.array([0.0, 0.0, HEIGHT_M]), 0.0)
    feet[0, 0] += 0.08  # a foot a part of a stride off its nominal place
    yaws = np.zeros(len(feet))
    base = still.base_for_com(np.array([0.05, 0.02]), HEIGHT_M, 0.0, feet, yaws)
    joints, q = held_base_joints(model, base[None], feet[None], yaws[None])
    com = model.com(q)
    assert com[:2] == pytest.approx([0.05, 0.02], abs=1e-6)
    np.testing.assert_allclose(still.com(base[None], 0.0, feet[None], yaws[None])[0], com,
                               atol=1e-9)


def test_a_swing_with_the_body_still_puts_its_fastest_joint_at_the_limit(still):
    model = robot()
    base = np.array([0.02, -0.01, HEIGHT_M])
    feet = model.nominal_feet_in_world(base, 0.0)
    yaws = np.zeros(len(feet))
    foot = model.foot_names.index('rear_left')
    end = feet[foot] + [0.18, 0.01, 0.0]
    swings = {foot: Swing('rear_left', 0.0, 1.0, feet[foot], end, 0.0, 0.0)}
    duration_s = still.step_s(swings, feet, yaws, 0.0, base)
    u = np.linspace(0.0, 1.0, 241)
    _, placed, placed_yaws = still.source.swing_feet(swings, feet, yaws, 0.0, u)
    joints, _ = held_base_joints(model, np.repeat(base[None], len(u), axis=0), placed,
                                 placed_yaws)
    rates = np.abs(np.diff(joints, axis=0)) / (np.diff(u) * duration_s)[:, None]
    ratio = (rates / model.velocity_limits_rad_s).max()
    # At the limit, but for the margin kept for the IK's COM tracking.
    assert ratio == pytest.approx(1.0 / (1.0 + TRACKING_MARGIN), abs=0.005)
    # Only the swinging limb moves: the body is still.
    moving = np.flatnonzero(np.abs(joints - joints[0]).max(axis=0) > 1e-9)
    limb = set(model.indices(model.description.feet[foot].joints).tolist())
    assert set(moving.tolist()) <= limb


def test_a_body_move_with_every_foot_down_keeps_its_fastest_joint_at_the_limit(still):
    # At the limit or just under it: the probe takes the largest joint rate per distance
    # times the time law's peak speed, wherever along the move each comes.
    model = robot()
    feet = model.nominal_feet_in_world(np.array([0.0, 0.0, HEIGHT_M]), 0.0)
    yaws = np.zeros(len(feet))
    start, end = np.array([-0.05, 0.0, HEIGHT_M]), np.array([0.05, 0.03, HEIGHT_M])
    duration_s = still.transfer_s(feet, yaws, 0.0, start, end)
    u = np.linspace(0.0, 1.0, 401)
    base = start + body_move(u)[:, None] * (end - start)
    joints, _ = held_base_joints(model, base, np.repeat(feet[None], len(u), axis=0),
                                 np.repeat(yaws[None], len(u), axis=0))
    rates = np.abs(np.diff(joints, axis=0)) / (np.diff(u) * duration_s)[:, None]
    assert 0.95 < (rates / model.velocity_limits_rad_s).max() <= 1.0 + 1e-3


def test_the_static_crawl_needs_closed_form_limb_ik():
    go2 = load_robot_description('go2')
    with pytest.raises(GaitParameterError, match="'static_crawl' is not possible for go2"):
        GaitParameters.for_robot(go2, gait='static_crawl').check_robot(go2)
    # A Go2 YAML that listed it would still be refused, with the reason.
    listed = dataclasses.replace(go2, gaits=(*go2.gaits, 'static_crawl'))
    with pytest.raises(GaitParameterError, match='static_crawl.*closed-form limb IK'):
        GaitParameters.for_robot(listed, gait='static_crawl').check_robot(listed)


def static_walk(still, until_s: float) -> tuple[GaitPlanner, GaitParameters]:
    """RoboSimian's static crawl (0.06 m lift) asked 0.1 m/s from standstill, planned ahead."""
    params = GaitParameters.for_robot(robot().description, gait='static_crawl',
                                      timing='joint_limit', step_height_m=0.06)
    planner = GaitPlanner(robot().description, params, swing_timing=still.source)
    planner.set_velocity(Twist2D(0.1), 0.0)
    planner.advance(until_s)
    return planner, params


def test_a_static_crawl_plan_keeps_its_zmp_inside_and_its_body_still_between_moves(still):
    model = robot()
    planner, params = static_walk(still, 25.0)
    walking = [step for step in planner.steps if step.slots]
    assert len(walking) >= 3
    for step in walking:
        assert step.zmp_margin_kept_m > 0.03  # measured on the ZMP made, foot discs included
        assert step.bases is not None and np.all(np.diff(step.zmp_times_s) > 0)
        # At rest between steps: the reference ends where the COM of the full model is with
        # the body at its second base and the feet where the step leaves them.
        feet = np.column_stack([step.positions_end, np.zeros(len(step.positions_end))])
        com = still.com(step.bases[1][None], 0.0, feet[None], step.yaws_end[None])[0]
        assert step.zmp_points[-1] == pytest.approx(com[:2], abs=1e-9)
    # Faster than the ZMP crawl at the same settings and joint limit.
    crawl = GaitPlanner(model.description, params.replace(gait='crawl'),
                        swing_timing=still.source)
    fastest_static, _ = planner.set_velocity(Twist2D(0.2), 25.0)
    fastest_crawl, _ = crawl.set_velocity(Twist2D(0.2), 0.0)
    assert fastest_static.vx_m_s > 1.5 * fastest_crawl.vx_m_s


def test_a_static_step_keeps_its_full_model_zmp_inside_and_slows_its_swings_for_it(still):
    """The swinging limb's momentum, which the cart-table ZMP leaves out, is planned for."""
    from gait_nodes.geometry import disc_support_margin
    from gait_nodes.robot.dynamics import multibody_zmp_trajectory

    model = robot()
    params = GaitParameters.for_robot(model.description, gait='static_crawl',
                                      timing='joint_limit', step_height_m=0.06)

    def walk():
        planner = GaitPlanner(model.description, params, swing_timing=still.source)
        planner.set_velocity(Twist2D(0.1), 0.0)
        planner.advance(16.0)
        return planner, [step for step in planner.steps if step.slots]

    planner, steps = walk()
    radius = model.description.foot_radius_m
    for step in steps:
        # The step reports the smaller of its cart-table and full-model margins: recomputed
        # here for its swings, independently, at 5 ms on the placed swing.
        slot = step.slots[0]
        duration = slot.touch_down_s - slot.lift_off_s
        count = int(round(duration / 0.005))
        u = np.linspace(0.0, 1.0, count + 1)
        foot = slot.feet[0]
        swing = Swing(model.foot_names[foot], slot.lift_off_s, slot.touch_down_s,
                      planner._with_heights(step.positions_start)[foot],
                      planner._with_heights(slot.positions_after)[foot], 0.0, 0.0)
        _, placed, yaws = still.source.swing_feet({foot: swing},
                                                 planner._with_heights(step.positions_start),
                                                 step.yaws_start, 0.0, u)
        joints = still.joints(np.repeat(step.bases[1][None], len(u), axis=0), 0.0, placed,
                              yaws)
        q = np.array([model.configuration(step.bases[1], 0.0, j) for j in joints])
        zmp, _ = multibody_zmp_trajectory(model, q, duration / count)
        stance = step.positions_start[[f for f in range(4) if f != foot], :2]
        assert disc_support_margin(zmp, stance, radius).min() > 0.0
        assert 0.0 < step.zmp_margin_kept_m
    # Faster swings keep less: the limbs' momentum grows as 1 / T^2 (what the planner slows a
    # step's swings for when its margin falls under zmp_margin_m).
    from gait_nodes.planning.footsteps import _State

    step = steps[-1]
    state = _State(time_s=step.start_s, positions=step.positions_start, yaws=step.yaws_start,
                   zmp=step.zmp_points[0], mode='walking', next_group=0,
                   rest_pose=np.zeros(3), last_anchor=np.zeros(3))
    move_to = step.slots[0].lift_off_s

    def full_margin(scale):
        slots = [dataclasses.replace(slot, touch_down_s=slot.lift_off_s + scale * (
            slot.touch_down_s - slot.lift_off_s)) for slot in step.slots]
        return planner._still_body_multibody_margin(state, slots, step.bases, step.start_s,
                                                    move_to)

    # (RoboSimian's static crawl at its stance: 64.1 mm at 0.7 times the swing time, 68.6 mm.)
    assert full_margin(0.7) < full_margin(1.0) - 0.003
    assert step.zmp_margin_kept_m <= full_margin(1.0) + 1e-9  # it reports the smaller


def test_a_value_table_swing_probed_with_accelerations_keeps_them_as_the_ik_commands_them():
    """Timed on the swing's own samples, the joints keep their limits on the ticks.

    RoboSimian with a 10 rad/s^2 limit (its swings then spend longer speeding up and slowing
    down): played at its probed time on the 5 ms waypoints the swing-leg policy publishes (the
    whole-body IK's ticks), one joint reaches its velocity or acceleration limit and none
    exceeds either (the probe's 2 % tracking margin aside). Probed on the swing shape's ~60
    samples, the time was 5 % short: the joints then asked 1.1 times the acceleration limit.
    The swing's time law takes the acceleration limit in (:mod:`gait_nodes.swing.time_law`):
    where it is timed (the static crawl's stance) the swing is over 0.1 s longer than at
    20 rad/s^2.
    """
    from gait_nodes.robot.model import RobotModel
    from gait_nodes.swing.cache import load_or_build
    from gait_nodes.swing.policy import SwingPolicy, limb_step, place_swing
    from gait_nodes.swing.timing import TableSwingTiming, evenly_resampled

    model = RobotModel(dataclasses.replace(robot().description,
                                           joint_acceleration_limit_rad_s2=10.0))
    table, _ = load_or_build(model, 2, 0.06, 1.0)
    timing = TableSwingTiming(SwingPolicy(table, model), model, 'static_crawl')
    still = StillBody(timing)
    fast = StillBody(TableSwingTiming(SwingPolicy(table, robot()), robot(), 'static_crawl'))
    base = np.array([0.0, 0.0, model.description.body_height_m])
    feet = model.nominal_feet_in_world(base, 0.0, 'static_crawl')  # where its law is timed
    yaws = np.zeros(len(feet))
    for name in ('front_left', 'rear_right'):
        foot = model.foot_names.index(name)
        start, end = feet[foot] - [0.1, 0.0, 0.0], feet[foot] + [0.1, 0.0, 0.0]
        before = feet.copy()
        before[foot] = start
        swing = Swing(name, 0.0, 1.0, start, end, 0.0, 0.0)
        duration_s = still.step_s({foot: swing}, before, yaws, 0.0, base, with_acceleration=True)
        at_20_s = fast.step_s({foot: swing}, before, yaws, 0.0, base, with_acceleration=True)
        assert duration_s > at_20_s + 0.1
        # The swing as swing_leg_policy publishes it for that duration, through the limb IK.
        mirror = timing.timing.ik.mirrors[timing.timing.ik.foot_index[name]]
        path, _ = timing.policy.fastest_swing(*limb_step(swing, mirror, 0.0), name,
                                              'static_crawl')
        polyline, _ = place_swing(path, swing, 0, mirror, 0.0, table.ground_z_m, duration_s)
        published = evenly_resampled(polyline, 0.005)
        count = len(published.times_s)
        placed = np.repeat(before[None], count, axis=0)
        placed[:, foot] = published.positions_in_world
        placed_yaws = np.zeros((count, len(feet)))
        placed_yaws[:, foot] = published.yaws_rad
        joints = still.joints(np.repeat(base[None], count, axis=0), 0.0, placed, placed_yaws,
                              limbs=[foot])
        dt = np.diff(published.times_s)
        velocity = np.diff(joints, axis=0) / dt[:, None]
        acceleration = np.diff(velocity, axis=0) / dt[1:, None]
        velocity_ratio = (np.abs(velocity) / np.asarray(model.velocity_limits_rad_s)).max()
        ratio = (np.abs(acceleration) / np.asarray(model.acceleration_limits_rad_s2)).max()
        assert velocity_ratio <= 1.0 and ratio <= 1.0
        # At a limit, but for the tracking margin and the two grids' sampling (the probe's
        # 5 ms are of the swing's own time, the published ones of the stretched swing's).
        assert max(velocity_ratio, ratio) > 1.0 / (1.0 + TRACKING_MARGIN) ** 2 - 0.03


def test_the_node_times_are_kept_on_disk_and_found_by_the_next_planner(tmp_path, monkeypatch):
    """A second model of the same robot and swings takes the node times stored by the first.

    Found, they are the same to the bit and none is computed again; a model with other joint
    limits does not take them (it has its own file); an unreadable file is computed anew and
    written again.
    """
    from gait_nodes.robot.model import RobotModel
    from gait_nodes.swing import timing as timing_module

    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path))
    first = StillBody(PolynomialSwingTiming(robot(), 2, 1.0, 0.06))
    assert not first.stored
    swing_s = first.swing_s(0, np.array([0.21, 0.0]))
    transfer_s = first.steady_transfer_s(np.array([0.1, 0.0]))
    files = list((tmp_path / 'gait_nodes').glob('still_robosimian_*.json'))
    assert len(files) == 1

    def no_shape(*args, **kwargs):
        raise AssertionError('a stored node time was computed again')

    with monkeypatch.context() as patched:
        patched.setattr(timing_module.PolynomialSwingTiming, 'shape', no_shape)
        second = StillBody(PolynomialSwingTiming(robot(), 2, 1.0, 0.06))
        assert second.stored
        assert second.swing_s(0, np.array([0.21, 0.0])) == swing_s
        assert second.steady_transfer_s(np.array([0.1, 0.0])) == transfer_s
        slower = RobotModel(dataclasses.replace(robot().description,
                                                joint_velocity_limit_rad_s=0.5))
        other = StillBody(PolynomialSwingTiming(slower, 2, 0.5, 0.06))
        assert not other.stored
        with pytest.raises(AssertionError, match='computed again'):
            other.swing_s(0, np.array([0.21, 0.0]))
    files[0].write_text('{"swing_s": [[1, 2')
    third = StillBody(PolynomialSwingTiming(robot(), 2, 1.0, 0.06))
    assert not third.stored
    assert third.swing_s(0, np.array([0.21, 0.0])) == swing_s
    assert StillBody(PolynomialSwingTiming(robot(), 2, 1.0, 0.06)).stored


def counted_probes(monkeypatch) -> list[str]:
    """The names of the planner's step probes (the limb IK's) as they are called, from now."""
    probes = []
    for name in ('_still_bases', '_slot_needs', '_needed_transfer_s', '_still_body_zmp'):
        original = getattr(GaitPlanner, name)

        def counted(self, *args, _original=original, _name=name, **kwargs):
            probes.append(_name)
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(GaitPlanner, name, counted)
    return probes


def test_a_walk_planned_again_from_later_or_anew_takes_its_probes_from_the_first(still,
                                                                                  monkeypatch):
    # A change planned again from a later join, or by a planner that joined the graph where
    # the robot stood, walks what the first planning probed: no limb IK again, and the same
    # steps, later by the join's difference.
    model = robot()
    params = GaitParameters.for_robot(model.description, gait='static_crawl',
                                      timing='joint_limit', step_height_m=0.06)
    first = GaitPlanner(model.description, params, swing_timing=still.source)
    first.advance(30.0)  # standing
    walk = first.fork()
    walk.set_velocity(Twist2D(0.1), 1.0)
    walk.advance(25.0)
    probes = counted_probes(monkeypatch)
    anew = first.anew(np.zeros(3))
    anew.advance(30.0)
    for planner, at_s in ((first.fork(), 3.3), (anew, 4.1)):
        planner.set_velocity(Twist2D(0.1), at_s)
        planner.advance(18.0)
        assert probes == []
        again = [step for step in planner.steps if step.slots]
        before = [step for step in walk.steps if step.slots][:len(again)]
        shift_s = again[0].start_s - before[0].start_s
        assert len(again) >= 3 and shift_s > 1.0
        for a, b in zip(again, before, strict=True):
            assert a.start_s == pytest.approx(b.start_s + shift_s, abs=1e-9)
            assert a.zmp_times_s == pytest.approx(b.zmp_times_s + shift_s, abs=1e-9)
            assert np.array_equal(a.zmp_points, b.zmp_points)
            assert a.positions_start == pytest.approx(b.positions_start, abs=1e-9)
    # Elsewhere the feet go elsewhere: probed anew.
    planner = first.anew(np.array([0.3, 0.0, 0.0]))
    planner.set_velocity(Twist2D(0.1), 1.0)
    planner.advance(6.0)
    assert '_still_body_zmp' in probes


def test_a_first_walks_probes_kept_on_disk_plan_it_alike_in_another_planner(tmp_path,
                                                                            monkeypatch):
    """The main job's first walk, kept on disk, is planned from it by the graph's planner.

    Another planner with an alike swing timing model (as in another process) takes the kept
    probes and search: it probes and searches nothing and plans the same steps to the bit; a
    walk elsewhere, or with
    another model, is probed; an unreadable file or probe is probed again.
    """
    from gait_nodes.planning.terrain import STAIRS_DEFAULTS, Staircase
    from gait_nodes.swing.still_body import MAX_KEPT_PROBES, keep_probes, kept_probes

    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path))
    model = robot()
    params = GaitParameters.for_robot(model.description, gait='static_crawl',
                                      timing='joint_limit', step_height_m=0.06)

    def first_walk(timing, pose=(0.0, 0.0, 0.0), terrain=None):
        planner = GaitPlanner(model.description, params, swing_timing=timing,
                              base_pose=np.array(pose), terrain=terrain)
        planner.take_probes(kept_probes(timing))
        planner.set_velocity(Twist2D(0.1), 0.0)
        planner.advance(12.0)
        return planner

    timing = PolynomialSwingTiming(model, 2, 1.0, 0.06)
    assert kept_probes(timing) == {}
    first = first_walk(timing)
    keep_probes(timing, first.probes_to_keep())
    (path,) = (tmp_path / 'gait_nodes').glob('probes_still_robosimian_*.json')
    assert 4 <= len(kept_probes(timing)) <= MAX_KEPT_PROBES
    probes = counted_probes(monkeypatch)
    rhythms = []
    rhythm = GaitPlanner.rhythm
    monkeypatch.setattr(GaitPlanner, 'rhythm',
                        lambda self, *args: rhythms.append(args) or rhythm(self, *args))
    alike = PolynomialSwingTiming(model, 2, 1.0, 0.06)  # (another process's)
    again = first_walk(alike, terrain=Staircase.from_parameters(STAIRS_DEFAULTS))  # (flat)
    assert probes == []
    # Nor searched its fastest walk (a bisection: 30 rhythms, and 6 for its steps): kept.
    assert again.twist == first.twist and 0 < len(rhythms) <= 10
    walked = [step for step in first.steps if step.slots]
    assert len(walked) >= 3
    for a, b in zip([step for step in again.steps if step.slots], walked, strict=True):
        assert (a.start_s, a.end_s) == (b.start_s, b.end_s)
        assert np.array_equal(a.zmp_times_s, b.zmp_times_s)
        assert np.array_equal(a.zmp_points, b.zmp_points)
        assert np.array_equal(a.bases, b.bases)
    first_walk(alike, pose=(0.5, 0.0, 0.0))  # elsewhere
    assert '_still_body_zmp' in probes
    probes.clear()
    first_walk(PolynomialSwingTiming(model, 2, 1.0, 0.08))  # another model: its own file
    assert '_still_body_zmp' in probes
    probes.clear()
    path.write_text(json.dumps({'probes': {name: {'tuple': 'x'} for name in
                                           kept_probes(timing)}}))
    assert first_walk(alike).steps[-1].end_s == first.steps[-1].end_s
    assert '_still_body_zmp' in probes
    path.write_text('{"probes": {"')
    assert kept_probes(timing) == {}


def test_the_first_static_step_from_standstill_takes_what_it_needs(still):
    # Its swings go half a stride to the crawl's stance (less than the rhythm's): stretched to
    # the rhythm's period, it would stand a second and a half longer; the path starts earlier.
    from gait_nodes.planning.footsteps import START_SHIFT_S

    planner, _ = static_walk(still, 20.0)
    first, second = [step for step in planner.steps if step.slots][:2]
    rhythm = planner.rhythm()
    assert first.end_s - first.start_s < 0.9 * (rhythm.step_period_s + START_SHIFT_S)
    # Each of its swings as long as a probe of it needs (and the retiming allowance).
    for slot in first.slots:
        duration = slot.touch_down_s - slot.lift_off_s
        assert duration < 0.9 * rhythm.swing_s
    assert second.end_s - second.start_s > rhythm.step_period_s  # catching up: longer steps


def test_the_static_crawl_starts_with_its_body_move_and_no_hold(still):
    # The first body move is its weight shift: the ZMP reference starts moving at the step's
    # start (no hold for a counter-move), and the move takes half a second more than it needs
    # (the part of the shift after the hold), so the first foot lifts off half a second
    # sooner than with the hold.
    from gait_nodes.planning.footsteps import START_HOLD_FRACTION, START_SHIFT_S

    planner, _ = static_walk(still, 10.0)
    first = next(step for step in planner.steps if step.slots)
    assert first.zmp_times_s[0] == pytest.approx(first.start_s)
    moving = np.linalg.norm(first.zmp_points - first.zmp_points[0], axis=1) > 1e-6
    assert first.zmp_times_s[np.argmax(moving)] - first.start_s < 0.02  # the next sample
    move_s = first.slots[0].lift_off_s - first.start_s
    stretch_s = (1.0 - START_HOLD_FRACTION) * START_SHIFT_S
    assert stretch_s < move_s < stretch_s + 0.4  # 2.6 cm at the joint limit, and the stretch
    # The ZMP crawl from standstill keeps its hold (its COM's counter-move).

    crawl = GaitPlanner(robot().description, planner.params.replace(gait='crawl'),
                        swing_timing=still.source)
    crawl.set_velocity(Twist2D(0.1), 0.0)
    crawl.advance(10.0)
    step = next(step for step in crawl.steps if step.slots)
    assert step.zmp_times_s[1] - step.start_s == pytest.approx(
        START_HOLD_FRACTION * START_SHIFT_S)


def test_the_rhythm_times_the_steady_walk_where_it_puts_the_feet(still):
    # The steady steps walk the rhythm's period and the path's speed: the rhythm times each
    # swing off its stance place by the path's advance between the slots (the fore foot lands
    # further along than the hind one) and the body's move with one side half a stride ahead.
    # Timed at the stance with the feet abreast, the steps needed 6 % more than the rhythm
    # gave them and the path waited every step.
    planner, _ = static_walk(still, 45.0)
    rhythm, twist = planner.rhythm(), planner.twist
    steady = [step for step in planner.steps if step.slots][-4:]
    for step in steady:
        assert step.end_s - step.start_s == pytest.approx(rhythm.step_period_s, rel=1e-9)
        moved = step.bases[1][0] - step.bases[0][0]
        assert moved / (step.end_s - step.start_s) == pytest.approx(twist.vx_m_s, rel=1e-3)
    lag = np.array([0.05, 0.0])
    shifts = still.steady_shifts(lag)
    names = [foot.name for foot in robot().description.feet]
    for side in ('left', 'right'):
        fore, hind = names.index(f'front_{side}'), names.index(f'rear_{side}')
        np.testing.assert_allclose(shifts[fore] - shifts[hind], lag)
        np.testing.assert_allclose(shifts[fore] + shifts[hind], 0.0, atol=1e-15)


def test_a_fork_taking_another_model_finds_what_a_fork_searched_with_it(still, monkeypatch):
    # A gait command planned on a fork that missed its join leaves the new model's fastest-walk
    # search to the fork its next try plans on (it searched again: seconds, a busy machine's
    # switch to the ZMP crawl 4 s); switching back finds the first model's.
    from gait_nodes.planning import rhythm as rhythm_module

    planner, params = static_walk(still, 10.0)
    crawl = params.replace(gait='crawl')
    other = PolynomialSwingTiming(robot(), 2, 1.0, 0.06)
    searched = []
    real = rhythm_module.walking_rhythm

    def counted(gait, *args, **kwargs):
        searched.append(gait)
        return real(gait, *args, **kwargs)

    monkeypatch.setattr(rhythm_module, 'walking_rhythm', counted)
    planner.fork().set_parameters(crawl, 8.0, swing_timing=other)
    assert searched and set(searched) == {'crawl'}
    searched.clear()
    again = planner.fork()
    again.set_parameters(crawl, 8.0, swing_timing=other)
    assert searched == []  # the first fork's search
    again.set_parameters(params, 9.0, swing_timing=still.source)
    assert searched == []  # the static crawl's, from before the switch
    assert again.twist == planner.twist
