"""Fifth-order polynomial hip/COM trajectories (Lucy): continuity, timing, ZMP at the ankle."""

import numpy as np
import pytest
from com_references import biped_walk
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.com.polynomial import (
    LucyObjective,
    PiecewiseQuintic,
    fit_quintic_com,
    lucy_walk,
    quintic,
)
from gait_nodes.errors import ComPlanningError

G = 9.81
finite = st.floats(-2.0, 2.0)


def hip_zmp(walk, t, ankle_height):
    position, _, acceleration = walk.hip.sample(t)
    height = position[:, 1] - ankle_height
    return position[:, 0] - height * acceleration[:, 0] / (acceleration[:, 1] + G)


def assert_c2(trajectory):
    """Position, velocity, acceleration agree on both sides of every knot (2e-10 s apart)."""
    for t in trajectory.knot_times_s[1:-1]:
        before, after = trajectory.sample([t - 1e-10]), trajectory.sample([t + 1e-10])
        for b, a, tolerance in zip(before, after, (1e-8, 1e-7, 1e-5), strict=True):
            np.testing.assert_allclose(b, a, atol=tolerance)


@settings(max_examples=30, deadline=None)
@given(start=st.lists(finite, min_size=6, max_size=6), end=st.lists(finite, min_size=6,
                                                                    max_size=6),
       duration=st.floats(0.05, 3.0))
def test_quintic_meets_its_boundary_states(start, end, duration):
    start, end = np.reshape(start, (3, 2)), np.reshape(end, (3, 2))
    poly = quintic(1.0, 1.0 + duration, start, end)
    for t, state in ((1.0, start), (1.0 + duration, end)):
        np.testing.assert_allclose(np.stack(poly.sample([t]))[:, 0], state, atol=1e-9)
    # Velocity and acceleration are the derivatives of the position (finite differences).
    t = np.linspace(1.0, 1.0 + duration, 401)
    position, velocity, acceleration = poly.sample(t)
    dt = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(position, dt, axis=0)[2:-2], velocity[2:-2],
                               atol=1e-3 * (1 + np.abs(velocity).max()))
    np.testing.assert_allclose(np.gradient(velocity, dt, axis=0)[2:-2], acceleration[2:-2],
                               atol=1e-3 * (1 + np.abs(acceleration).max()))


def test_lucy_example_timing():
    # v = 0.5 m/s, lambda = 0.3 m, delta = 0.1 m: T_S = 0.46 s with a 0.07 m double-support
    # advance (eq. 13); T_D = advance / X_d(t+) (eq. 8) is 0.12 s at the cart-table boundary
    # velocity of a 0.814 m hip.
    objective = LucyObjective(0.5, 0.3, 0.1, hip_height_m=0.814, double_support_advance_m=0.07)
    assert objective.single_support_s == pytest.approx(0.46)
    assert round(objective.double_support_s(), 2) == 0.12


@pytest.mark.parametrize('step_height_m', [0.0, 0.1])
def test_lucy_walk_is_c2_with_zmp_at_the_ankles(step_height_m):
    objective = LucyObjective(0.5, 0.3, step_height_m, hip_height_m=0.814)
    walk = lucy_walk(objective, steps=6)
    assert_c2(walk.hip)
    singles = [p for p in walk.phases if p[0] == 'single']
    assert len(singles) == 6
    for _, t_d, t_s, i in singles:
        ankle = walk.ankles[i]
        # Lucy eq. 25: the ZMP is exactly at the stance ankle at both ends of single support,
        # and here stays near it throughout (the boundary speed is the cart-table one).
        np.testing.assert_allclose(hip_zmp(walk, [t_d, t_s], ankle[1]), ankle[0], atol=1e-9)
        inside = hip_zmp(walk, np.linspace(t_d, t_s, 50), ankle[1])
        assert np.max(np.abs(inside - ankle[0])) < 0.005
        # Eq. 13: the hip covers v T_S in single support; the hip rises with the stairs.
        (x_d, y_d), (x_s, y_s) = walk.hip.sample([t_d, t_s])[0]
        assert x_s - x_d == pytest.approx(0.5 * (t_s - t_d), abs=1e-12)
        assert y_d == pytest.approx(ankle[1] + 0.814)
    for kind, t_plus, t_d, i in walk.phases[1:-1]:
        if kind != 'double':
            continue
        # Eq. 8 and the ZMP travelling from the rear to the front ankle.
        position, velocity, _ = walk.hip.sample([t_plus, t_d])
        assert position[1, 0] - position[0, 0] == pytest.approx(velocity[0, 0] * (t_d - t_plus))
        if step_height_m == 0.0:  # on flat ground the ZMP plane is the same for both feet
            zmp = hip_zmp(walk, np.linspace(t_plus, t_d, 30), 0.0)
            np.testing.assert_allclose(zmp[[0, -1]], walk.ankles[[i - 1, i], 0], atol=1e-9)
            assert walk.ankles[i - 1][0] - 0.01 < zmp.min() < zmp.max() \
                < walk.ankles[i][0] + 0.01
    # Starts and ends at rest.
    _, velocity, acceleration = walk.hip.sample(walk.hip.knot_times_s[[0, -1]])
    np.testing.assert_allclose(velocity, 0.0, atol=1e-12)
    np.testing.assert_allclose(acceleration, 0.0, atol=1e-12)


def test_fitted_quintic_com_tracks_a_walk_reference():
    times, reference = biped_walk(0.005, steps=8)
    zc = 0.814
    start = np.zeros((3, 2))
    com = fit_quintic_com(times, reference, zc, start)
    assert_c2(com)
    position, velocity, acceleration = com.sample(times)
    error = position - zc / G * acceleration - reference
    assert np.all(np.sqrt(np.mean(error ** 2, axis=0)) < 0.001)
    assert np.max(np.abs(error)) < 0.005
    # At the knots (the phase changes) the ZMP is exactly the reference.
    knots = com.knot_times_s[1:]
    p, _, a = com.sample(knots)
    expected = np.stack([np.interp(knots, times, reference[:, i]) for i in range(2)], 1)
    np.testing.assert_allclose(p - zc / G * a, expected, atol=1e-9)
    np.testing.assert_allclose(velocity[-1], 0.0, atol=1e-4)
    np.testing.assert_allclose(position[-1], reference[-1], atol=1e-4)


def test_fit_starts_from_a_moving_state():
    times, reference = biped_walk(0.01, steps=3)
    state = np.array([[0.02, -0.01], [0.1, -0.05], [0.3, 0.2]])
    com = fit_quintic_com(times[:300], reference[:300], 0.814, state, end='capture')
    np.testing.assert_allclose(np.stack(com.sample([times[0]]))[:, 0], state, atol=1e-9)


def test_bad_knots_are_refused():
    with pytest.raises(ComPlanningError, match='increasing'):
        PiecewiseQuintic(np.array([0.0, 0.0]), np.zeros((2, 3, 1)))
    with pytest.raises(ComPlanningError, match='NaN'):
        quintic(0.0, 1.0, [np.nan, 0, 0], [0, 0, 0])
    with pytest.raises(ComPlanningError, match='double_support_advance_m'):
        LucyObjective(0.5, 0.3, double_support_advance_m=0.4)
