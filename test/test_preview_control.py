"""ZMP preview control (Kajita 2003): Riccati gains, batch and online forms, tracking."""

import numpy as np
import pytest
import scipy.linalg
from com_references import NS_PER_S, biped_walk, biped_walk_vertices, window
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.com.preview import (
    OnlinePreviewController,
    PreviewSettings,
    preview_batch,
    preview_gains,
)
from gait_nodes.com.trajectory import cart_table_zmp
from gait_nodes.errors import ComPlanningError

STANDARD = PreviewSettings(com_height_m=0.814, dt_s=0.005, preview_s=1.6, q_weight=1.0,
                           r_weight=1e-6)


@pytest.fixture(scope='module')
def standard_gains():
    return preview_gains(STANDARD)


def per_sample_recursion(gains, reference, initial_state):
    """Kajita eq. (13) written out sample by sample, as an independent check of the batch form."""
    steps = len(gains.preview_gain)
    padded = np.concatenate([reference, np.repeat(reference[-1:], steps, axis=0)])
    x, error_sum, states = np.array(initial_state, dtype=float), np.zeros(2), []
    for k in range(len(reference)):
        states.append(x.copy())
        error_sum += gains.C @ x - padded[k]
        u = -gains.integral_gain * error_sum - gains.state_gain @ x \
            - gains.preview_gain @ padded[k + 1:k + 1 + steps]
        x = gains.A @ x + np.outer(gains.B, u)
    return np.array(states)


def test_standard_setting_tracks_an_eight_step_walk(standard_gains):
    times, reference = biped_walk(STANDARD.dt_s, steps=8, step_m=0.3)
    com = preview_batch(reference, standard_gains)
    zmp = cart_table_zmp(com.positions_in_world, com.accelerations_in_world, 0.814)
    error = zmp - reference
    rms = np.sqrt(np.mean(error ** 2, axis=0))
    assert np.all(rms <= 0.010), rms
    assert np.all(np.max(np.abs(error), axis=0) <= 0.030), np.max(np.abs(error), axis=0)
    # The walk really moves: 8 steps of 0.3 m forward and +-0.1 m of ZMP sway.
    assert com.positions_in_world[-1, 0] == pytest.approx(2.25, abs=1e-3)
    assert np.ptp(com.positions_in_world[:, 1]) > 0.05
    # Starts and ends at rest over the reference.
    np.testing.assert_allclose(com.positions_in_world[0], reference[0], atol=1e-12)
    np.testing.assert_allclose(com.velocities_in_world[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(com.positions_in_world[-1], reference[-1], atol=1e-3)
    np.testing.assert_allclose(com.velocities_in_world[-1], 0.0, atol=1e-3)
    np.testing.assert_allclose(com.accelerations_in_world[-1], 0.0, atol=1e-2)


def test_gains_solve_the_augmented_riccati_equation(standard_gains):
    g = standard_gains
    C, A, B = g.C, g.A, g.B
    At = np.zeros((4, 4))
    At[0, 0], At[0, 1:], At[1:, 1:] = 1.0, C @ A, A
    Bt = np.concatenate([[C @ B], B]).reshape(4, 1)
    Qt = np.diag([1.0, 0.0, 0.0, 0.0])
    P = g.riccati
    gain = np.linalg.solve(1e-6 + Bt.T @ P @ Bt, Bt.T @ P @ At)
    residual = At.T @ P @ At - P - At.T @ P @ Bt @ gain + Qt
    assert np.max(np.abs(residual)) <= 1e-8 * np.max(np.abs(P))
    np.testing.assert_allclose(gain.ravel(), [g.integral_gain, *g.state_gain], rtol=1e-9)
    assert np.max(np.abs(np.linalg.eigvals(At - Bt @ gain))) < 1.0
    # First preview gain is -Gi, and the gains decay over the 1.6 s horizon.
    assert g.preview_gain[0] == pytest.approx(-g.integral_gain)
    assert abs(g.preview_gain[-1]) < 1e-2 * abs(g.preview_gain).max()
    # A resting COM over a constant reference needs no jerk: Gx[0] + sum(Gd) = 0 over an
    # infinite preview; the 1.6 s horizon leaves a geometric tail of ratio Gd[-1] / Gd[-2].
    ratio = g.preview_gain[-1] / g.preview_gain[-2]
    tail = g.preview_gain[-1] * ratio / (1.0 - ratio)
    assert abs(g.state_gain[0] + g.preview_gain.sum() + tail) <= 1e-4 * abs(g.state_gain[0])


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2 ** 31), block=st.integers(1, 200), count=st.integers(1, 400))
def test_batch_equals_the_per_sample_recursion(standard_gains, seed, block, count):
    rng = np.random.default_rng(seed)
    reference = np.cumsum(rng.normal(scale=0.01, size=(count, 2)), axis=0)
    initial = rng.normal(scale=[[0.1], [0.2], [0.5]], size=(3, 2))
    expected = per_sample_recursion(standard_gains, reference, initial)
    com = preview_batch(reference, standard_gains, initial_state=initial, block_size=block)
    np.testing.assert_allclose(com.positions_in_world, expected[:, 0], atol=1e-9)
    np.testing.assert_allclose(com.velocities_in_world, expected[:, 1], atol=1e-8)
    np.testing.assert_allclose(com.accelerations_in_world, expected[:, 2], atol=1e-7)


def test_online_on_sliding_windows_equals_batch(standard_gains):
    # A planner publishing a 1.6 s window sampled every 10 ms, every tick; linear between
    # samples, so resampled at 5 ms it is the same reference the batch form sees.
    times, points = biped_walk_vertices(steps=3)
    start_ns = 7 * NS_PER_S
    controller = OnlinePreviewController(STANDARD, points[0], stamp_ns=start_ns)
    count = int(round(times[-1] / STANDARD.dt_s))
    states = []
    for k in range(count):
        stamp = start_ns + k * STANDARD.dt_ns
        reference = window(times, points, stamp - start_ns, 1.6, 0.01)
        controller.set_reference(type(reference)(reference.stamps_ns + start_ns,
                                                 reference.zmp_in_world))
        sample = controller.step()
        assert sample.stamp_ns == stamp
        states.append([sample.position_in_world, sample.velocity_in_world,
                       sample.acceleration_in_world])
    states = np.array(states)
    sample_times = STANDARD.dt_s * np.arange(count)
    reference = np.stack([np.interp(sample_times, times, points[:, i]) for i in range(2)], 1)
    com = preview_batch(reference, standard_gains)
    np.testing.assert_allclose(states[:, 0], com.positions_in_world, atol=1e-9)
    np.testing.assert_allclose(states[:, 2], com.accelerations_in_world, atol=1e-7)


def test_online_keeps_its_state_across_a_plan_change():
    times, points = biped_walk_vertices(steps=8)
    controller = OnlinePreviewController(STANDARD, points[0])
    dt = STANDARD.dt_s
    switch_k = int(3.5 / dt)
    # Same first three steps, then four shorter ones: the change is beyond the current step.
    short_times, short_points = biped_walk_vertices(steps=7, step_m=[0.3] * 3 + [0.2] * 4)
    samples = []
    for k in range(int(12.0 / dt)):
        plan = (times, points) if k < switch_k else (short_times, short_points)
        controller.set_reference(window(*plan, k * STANDARD.dt_ns, 1.6, 0.005))
        samples.append(controller.step())
    position = np.array([s.position_in_world for s in samples])
    velocity = np.array([s.velocity_in_world for s in samples])
    acceleration = np.array([s.acceleration_in_world for s in samples])
    # The state integrates one step at a time: no jump at the switch (jerk-driven, so the
    # acceleration changes by at most jerk * dt and the position as the velocity says).
    steps = np.diff(position, axis=0)
    predicted = velocity[:-1] * dt + acceleration[:-1] * dt * dt / 2
    assert np.max(np.abs(steps - predicted)) < 1e-3
    assert np.max(np.abs(np.diff(acceleration, axis=0))) < 0.5
    # It then follows the new (shorter) plan to rest over its end point.
    np.testing.assert_allclose(position[-1], short_points[-1], atol=2e-3)
    np.testing.assert_allclose(velocity[-1], 0.0, atol=2e-3)


def test_retune_keeps_the_com_state_and_changes_the_gains():
    times, points = biped_walk_vertices(steps=4)
    controller = OnlinePreviewController(STANDARD, points[0])
    for k in range(int(3.0 / STANDARD.dt_s)):
        controller.set_reference(window(times, points, k * STANDARD.dt_ns, 1.6, 0.005))
        controller.step()
    before = controller.state()
    controller.retune(PreviewSettings(com_height_m=0.7, dt_s=0.005, preview_s=1.0,
                                      q_weight=1.0, r_weight=1e-5))
    after = controller.state()
    np.testing.assert_array_equal(before.position_in_world, after.position_in_world)
    np.testing.assert_array_equal(before.velocity_in_world, after.velocity_in_world)
    assert len(controller.gains.preview_gain) == 200


@pytest.mark.parametrize('changes, match', [
    ({'r_weight': 0.0}, 'R'), ({'r_weight': -1.0}, 'R'), ({'q_weight': -1.0}, 'Q'),
    ({'q_weight': 0.0}, 'Q'), ({'dt_s': 0.0}, 'dt_s'), ({'dt_s': -0.005}, 'dt_s'),
    ({'preview_s': 0.001}, 'shorter than one step'), ({'com_height_m': 0.0}, 'com_height_m'),
    ({'com_height_m': float('nan')}, 'com_height_m'),
])
def test_unsolvable_settings_are_refused_with_the_reason(changes, match):
    values = {'com_height_m': 0.814, 'dt_s': 0.005, 'preview_s': 1.6, 'q_weight': 1.0,
              'r_weight': 1e-6, **changes}
    with pytest.raises(ComPlanningError, match=match):
        preview_gains(PreviewSettings(**values))


@settings(max_examples=12, deadline=None)
@given(com_height_m=st.floats(0.3, 1.2), dt_s=st.sampled_from([0.002, 0.005, 0.01]),
       r_exponent=st.floats(-8.0, -5.0))
def test_tracking_holds_over_settings(com_height_m, dt_s, r_exponent):
    setting = PreviewSettings(com_height_m=com_height_m, dt_s=dt_s, preview_s=1.6,
                              q_weight=1.0, r_weight=10.0 ** r_exponent)
    _, reference = biped_walk(dt_s, steps=4)
    com = preview_batch(reference, setting)
    error = com.zmp(com_height_m) - reference
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) <= 0.010)
    np.testing.assert_allclose(com.positions_in_world[-1], reference[-1], atol=2e-3)


def test_dare_matches_scipy_on_the_same_system(standard_gains):
    # The gains rebuild from scipy's DARE with an independently assembled augmented system.
    g = standard_gains
    zc_g = 0.814 / 9.81
    dt = 0.005
    A = np.array([[1, dt, dt ** 2 / 2], [0, 1, dt], [0, 0, 1]])
    B = np.array([[dt ** 3 / 6], [dt ** 2 / 2], [dt]])
    C = np.array([[1, 0, -zc_g]])
    At = np.block([[np.eye(1), C @ A], [np.zeros((3, 1)), A]])
    Bt = np.vstack([C @ B, B])
    P = scipy.linalg.solve_discrete_are(At, Bt, np.diag([1.0, 0, 0, 0]), np.array([[1e-6]]))
    np.testing.assert_allclose(P, g.riccati, rtol=1e-8)


@given(seed=st.integers(0, 2**32 - 1))
@settings(max_examples=20, deadline=None)
def test_float_step_equals_the_matrix_step_to_rounding(seed):
    # step() writes the 3 x 2 products out in floats; step_reference() is Kajita eq. (13) in
    # matrices. Over a walk with a plan change, a random start and a state far from rest, both
    # runs stay within rounding of each other (the BLAS form may fuse multiply-adds).
    rng = np.random.default_rng(seed)
    times, points = biped_walk_vertices(steps=4)
    start = rng.normal(scale=[[0.1, 0.1], [0.3, 0.3], [1.0, 1.0]])
    runs = []
    for name in ('step', 'step_reference'):
        controller = OnlinePreviewController(STANDARD, points[0])
        controller.reset(points[0] + start[0], start[1], start[2], stamp_ns=0)
        samples = []
        for k in range(int(3.0 / STANDARD.dt_s)):
            if k % 4 == 0:
                controller.set_reference(window(times, points, k * STANDARD.dt_ns, 1.6, 0.01))
            sample = getattr(controller, name)()
            samples.append([sample.stamp_ns, *sample.position_in_world,
                            *sample.velocity_in_world, *sample.acceleration_in_world])
        runs.append(np.array(samples))
    fast, reference = runs
    np.testing.assert_array_equal(fast[:, 0], reference[:, 0])
    scale = np.max(np.abs(reference[:, 1:]), axis=0)
    np.testing.assert_allclose(fast[:, 1:], reference[:, 1:], rtol=0, atol=1e-12 * scale.max())


def test_step_values_are_the_step_and_a_short_window_changes_nothing(monkeypatch):
    # step_values() is step() in floats; the window resampled WINDOW_LEAD_TICKS ahead (not to
    # the reference's end) gives the same states to the bit, also when the reference stops
    # coming (the window then runs out and is resampled over and over).
    from gait_nodes.com import preview

    times, points = biped_walk_vertices(steps=4)
    runs = []
    for lead, method in ((10, 'step_values'), (10, 'step'), (100000, 'step')):
        monkeypatch.setattr(preview, 'WINDOW_LEAD_TICKS', lead)
        controller = OnlinePreviewController(STANDARD, points[0])
        values = []
        for k in range(int(4.0 / STANDARD.dt_s)):
            if k % 4 == 0 and k < 300:
                controller.set_reference(window(times, points, k * STANDARD.dt_ns, 3.0, 0.01))
            if method == 'step':
                sample = controller.step()
                values.append((sample.stamp_ns, *sample.position_in_world.tolist(),
                               *sample.velocity_in_world.tolist(),
                               *sample.acceleration_in_world.tolist()))
            else:
                values.append(controller.step_values())
        state = controller.state()
        values.append((state.stamp_ns, *state.position_in_world.tolist(),
                       *state.velocity_in_world.tolist(),
                       *state.acceleration_in_world.tolist()))
        runs.append(np.array(values, dtype=object))
    for run in runs[1:]:
        assert [repr(tuple(row)) for row in run] == [repr(tuple(row)) for row in runs[0]]
