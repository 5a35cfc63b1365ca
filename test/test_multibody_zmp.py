"""Multi-body ZMP from the momentum rate, and the multi-mass correction on the full robot model."""

import numpy as np
import pytest

from gait_nodes.com.multibody import correct_plan
from gait_nodes.planning.footsteps import Twist2D, plan_walk
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.robot.dynamics import multibody_zmp_trajectory, zmp_from_momentum
from gait_nodes.robot.model import load_robot_model

GRAVITY = 9.81


@pytest.fixture(scope='module')
def robosimian():
    return load_robot_model('robosimian')


def test_static_robot_zmp_is_the_com_projection(robosimian):
    rng = np.random.default_rng(0)
    for _ in range(5):
        joints = np.clip(rng.normal(0.0, 0.5, len(robosimian.joint_names)),
                         robosimian.lower_limits, robosimian.upper_limits)
        q = robosimian.configuration(rng.uniform(-1, 1, 3) + [0, 0, 0.65],
                                     rng.uniform(-3, 3), joints)
        zeros = np.zeros(robosimian.model.nv)
        zmp, com = zmp_from_momentum(robosimian, q, zeros, zeros)
        np.testing.assert_allclose(zmp, com[:2], atol=1e-12)
        np.testing.assert_allclose(com, robosimian.com(q), atol=1e-12)


def test_translating_rigid_robot_follows_the_cart_table_formula(robosimian):
    # Joints frozen, base translating without rotation: no angular momentum, so the whole
    # robot is a point mass at its COM and p = c - z_c / g * c_ddot (Kajita's cart-table).
    q = robosimian.configuration([0.0, 0.0, 0.65], 0.3)
    for acceleration in ([0.5, 0.0, 0.0], [0.0, -0.8, 0.0], [0.3, 0.4, 0.0]):
        v = np.zeros(robosimian.model.nv)
        a = np.zeros(robosimian.model.nv)
        yaw = 0.3
        c, s = np.cos(yaw), np.sin(yaw)
        # Pinocchio's free-flyer velocity is in the base frame: rotate the world acceleration.
        a[:3] = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) @ np.array(acceleration)
        zmp, com = zmp_from_momentum(robosimian, q, v, a)
        expected = com[:2] - com[2] / GRAVITY * np.array(acceleration)[:2]
        np.testing.assert_allclose(zmp, expected, atol=1e-9)


def test_finite_differenced_trajectory_matches_the_formula(robosimian):
    # A base moving as x(t) = A sin(w t): the sampled trajectory's ZMP from finite differences
    # agrees with the cart-table formula with the analytic acceleration.
    dt = 0.005
    t = np.arange(0.0, 2.0, dt)
    amplitude, omega = 0.05, 2.0
    configurations = np.array([robosimian.configuration(
        [amplitude * np.sin(omega * tk), 0.0, 0.65], 0.0) for tk in t])
    zmp, com = multibody_zmp_trajectory(robosimian, configurations, dt)
    acceleration = -amplitude * omega ** 2 * np.sin(omega * t)
    expected = com[:, 0] - com[:, 2] / GRAVITY * acceleration
    inner = slice(2, -2)  # the ends are taken at rest
    np.testing.assert_allclose(zmp[inner, 0], expected[inner], atol=2e-5)
    np.testing.assert_allclose(zmp[inner, 1], com[inner, 1], atol=1e-9)


def test_multimass_correction_on_the_robot_model(robosimian):
    description = robosimian.description
    params = GaitParameters.for_robot(description, gait='crawl', step_period_s=4.0)
    planner = plan_walk(description, params, [(0.0, Twist2D(0.02, 0.0, 0.0))], 10.0)
    dt = 0.02
    reference = planner.zmp(np.arange(0.0, 8.0, dt))
    correction = correct_plan(robosimian, planner.footstep_plan(), reference, dt,
                              params.body_height_m, params.step_height_m, max_iterations=8)
    result = correction.result
    # The legs are 60 % of the mass: the cart-table COM misses the reference by centimetres;
    # the correction brings the full model's ZMP onto it.
    assert result.residual_before_m > 0.01
    assert result.residual_after_m < result.residual_before_m / 10
    assert result.residual_after_m < 2e-3
    assert np.all(np.diff(result.history_m) < 0)
