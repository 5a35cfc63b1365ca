"""Multi-mass correction (Kurazume eqs. 26-35) against a synthetic body + swinging-legs model."""

import numpy as np
import pytest
from com_references import biped_walk_vertices, sample_vertices

from gait_nodes.com.multimass import correct_body_trajectory, zmp_correction
from gait_nodes.com.preview import PreviewSettings, preview_batch
from gait_nodes.errors import ComPlanningError

G = 9.81
DT = 0.005
ZC = 0.814


def second_derivative(x, dt):
    padded = np.concatenate([x[:1], x, x[-1:]])
    return (padded[2:] - 2 * padded[1:-1] + padded[:-2]) / dt ** 2


class BodyWithLegs:
    """Body mass plus, per leg, a foot mass and a knee mass between hip and foot.

    The feet follow a fixed plan (lifting and swinging forward); the knees sit between hip and
    foot, so only part of the leg mass follows a body correction. Its ZMP is Kurazume
    eqs. 26-27 for point masses (no rotational inertia).
    """

    def __init__(self, times, feet_xyz, body_height=ZC, body_mass=30.0, foot_mass=4.0,
                 knee_mass=3.0):
        self.times, self.feet = times, feet_xyz  # feet (N, F, 3)
        self.body_height = body_height
        self.masses = (body_mass, foot_mass, knee_mass)

    def points(self, body):
        """Body (N, 3) and knee (N, F, 3) positions for a body trajectory (N, 2)."""
        n, feet = len(body), self.feet.shape[1]
        body_xyz = np.column_stack([body, np.full(n, self.body_height)])
        hips = body_xyz[:, None, :] + np.array([[0.0, 0.1 * (-1) ** f, -0.1]
                                                for f in range(feet)])[None]
        knees = 0.5 * (hips + self.feet) + np.array([0.06, 0.0, 0.0])
        return body_xyz, knees

    def __call__(self, body):
        """Multi-body ZMP (N, 2) of a body trajectory (N, 2)."""
        body_xyz, knees = self.points(body)
        m_body, m_foot, m_knee = self.masses
        points = [(m_body, body_xyz)] + [(m_foot, self.feet[:, f]) for f in
                                         range(self.feet.shape[1])] \
            + [(m_knee, knees[:, f]) for f in range(knees.shape[1])]
        numerator_x = numerator_y = denominator = 0.0
        for mass, r in points:
            acc = second_derivative(r, DT)
            numerator_x = numerator_x + mass * (r[:, 0] * (acc[:, 2] + G) - r[:, 2] * acc[:, 0])
            numerator_y = numerator_y + mass * (r[:, 1] * (acc[:, 2] + G) - r[:, 2] * acc[:, 1])
            denominator = denominator + mass * (acc[:, 2] + G)
        return np.column_stack([numerator_x / denominator, numerator_y / denominator])


def swinging_feet(times, steps=6, step=0.3, width=0.1, single=0.6, double=0.2, rest=2.0):
    """Foot positions (N, 2, 3) of the reference walk: quintic swing with a 5 cm lift."""
    feet = np.zeros((len(times), 2, 3))
    feet[:, 0, 1], feet[:, 1, 1] = width, -width
    t = rest + double
    for i in range(1, steps + 1):
        f = 0 if i % 2 else 1
        start_x = feet[np.searchsorted(times, t), f, 0]
        end_x = step * i
        u = np.clip((times - t) / single, 0.0, 1.0)
        s = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5
        moving = times >= t
        feet[moving, f, 0] = start_x + (end_x - start_x) * s[moving]
        feet[moving, f, 2] = 0.05 * np.sin(np.pi * u[moving]) ** 2
        t += single + double
    return feet


@pytest.fixture(scope='module')
def walk():
    vertices = biped_walk_vertices(steps=6)
    times = np.arange(int(round(vertices[0][-1] / DT)) + 1) * DT
    reference = sample_vertices(*vertices, times)
    model = BodyWithLegs(times, swinging_feet(times))
    com = preview_batch(reference, PreviewSettings(ZC, DT))
    return reference, model, com.positions_in_world


@pytest.mark.parametrize('k', [0.0, 1e-3])
def test_correction_makes_the_multibody_zmp_match(walk, k):
    reference, model, body = walk
    result = correct_body_trajectory(body, reference, model, ZC, DT, smoothness_k=k,
                                     max_iterations=30, tolerance_m=1e-5)
    # The legs' mass and motion put the multi-body ZMP centimetres off the plan ...
    assert result.residual_before_m > 0.01
    # ... and the correction brings it back by a large factor.
    assert result.residual_after_m < result.residual_before_m / 50
    assert result.rms_after_m < result.rms_before_m / 50
    np.testing.assert_allclose(model(result.body_in_world), result.zmp_in_world)
    assert result.history_m[0] == result.residual_before_m
    # The corrected body is a smooth trajectory: bounded accelerations.
    assert np.max(np.abs(second_derivative(result.body_in_world, DT))) < 20.0


def test_smoothness_weight_smooths_the_correction():
    rng = np.random.default_rng(1)
    error = np.cumsum(rng.normal(scale=1e-3, size=(400, 2)), axis=0)
    error[200:] += 0.02  # a step: eq. 33 alone rings there
    rough = zmp_correction(error, ZC, DT, 0.0)
    smooth = zmp_correction(error, ZC, DT, 10.0)
    assert np.abs(np.diff(smooth, 2, axis=0)).sum() < np.abs(np.diff(rough, 2, axis=0)).sum()


def test_k_zero_solves_the_discrete_cart_table_exactly():
    rng = np.random.default_rng(2)
    error = rng.normal(scale=0.01, size=(300, 2))
    correction = zmp_correction(error, ZC, DT, 0.0)
    padded = np.pad(correction, ((1, 1), (0, 0)), mode='edge')
    a = ZC / G / DT ** 2
    np.testing.assert_allclose(correction - a * (padded[2:] - 2 * correction + padded[:-2]),
                               error, atol=1e-9)


def test_bad_inputs_are_refused(walk):
    reference, model, body = walk
    with pytest.raises(ComPlanningError, match='multibody_zmp'):
        correct_body_trajectory(body, reference, lambda b: b[:-1], ZC, DT)
    with pytest.raises(ComPlanningError, match='smoothness_k'):
        zmp_correction(reference, ZC, DT, -1.0)
