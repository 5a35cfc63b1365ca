"""Full-model ZMP monitor: static robot, cart-table point mass, rotating body, body-by-body sum."""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.geometry import disc_support_margin, foot_discs_polygon, signed_distance
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import nominal_configuration
from gait_nodes.sim.zmp_monitor import (
    POLYGON_SEGMENTS_PER_FOOT,
    STANDARD_GRAVITY_M_S2,
    SlidingDifferences,
    ZmpMonitor,
    central_differences,
)

G = STANDARD_GRAVITY_M_S2
#: How far the drawn polygon's edges lie outside the foot circles, per metre of radius.
CIRCUMSCRIBED = 1 / math.cos(math.pi / POLYGON_SEGMENTS_PER_FOOT) - 1

ONE_BODY_URDF = """<?xml version="1.0"?>
<robot name="one_body">
  <link name="base_link">
    <inertial>
      <origin xyz="{dx} {dy} {dz}"/>
      <mass value="{mass}"/>
      <inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="0" ixz="0" iyz="0"/>
    </inertial>
  </link>
</robot>
"""


def one_body_model(mass=50.0, offset=(0.0, 0.0, 0.0), inertia=(1e-9, 1e-9, 1e-9)):
    urdf = ONE_BODY_URDF.format(mass=mass, dx=offset[0], dy=offset[1], dz=offset[2],
                                ixx=inertia[0], iyy=inertia[1], izz=inertia[2])
    return pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())


def base_q(position, rotation=None):
    rotation = np.eye(3) if rotation is None else rotation
    return pin.SE3ToXYZQUAT(pin.SE3(rotation, np.asarray(position, dtype=float)))


@pytest.fixture(scope='module')
def robosimian():
    return load_robot_model('robosimian')


def random_configuration(robot, rng):
    q = nominal_configuration(robot)
    joints = robot.joint_positions(q) + rng.uniform(-0.3, 0.3, len(robot.joint_names))
    joints = np.clip(joints, robot.lower_limits, robot.upper_limits)
    robot.set_joint_positions(q, joints)
    rotation = pin.rpy.rpyToMatrix(*rng.uniform(-0.2, 0.2, 3))
    q[:7] = base_q(rng.uniform(-1, 1, 3) + [0, 0, 0.7], rotation)
    return q


@pytest.mark.parametrize('seed', range(5))
def test_static_robot_zmp_is_the_com_ground_projection(robosimian, seed):
    rng = np.random.default_rng(seed)
    q = random_configuration(robosimian, rng)
    monitor = ZmpMonitor(robosimian.model, 0.055, ground_height_m=rng.uniform(-0.1, 0.1))
    zero = np.zeros(robosimian.model.nv)
    com, zmp, fz = monitor.com_and_zmp(q, zero, zero)
    np.testing.assert_allclose(com, robosimian.com(q), atol=1e-12)
    np.testing.assert_allclose(zmp[:2], com[:2], atol=1e-12)
    assert zmp[2] == monitor.ground_height_m
    assert fz == pytest.approx(robosimian.mass_kg * G)


@settings(max_examples=30, deadline=None)
@given(acceleration=st.tuples(*[st.floats(-5, 5)] * 2, st.floats(-5, 5)),
       velocity=st.tuples(*[st.floats(-1, 1)] * 3),
       height=st.floats(0.2, 1.5), ground=st.floats(-0.2, 0.2))
def test_point_mass_zmp_is_the_cart_table_formula(acceleration, velocity, height, ground):
    model = one_body_model(offset=(0.1, -0.05, 0.02))
    monitor = ZmpMonitor(model, 0.05, ground_height_m=ground)
    acceleration = np.array(acceleration)
    dt = 0.005

    def q_at(t):  # the body translates with constant acceleration
        return base_q(np.array([0.3, -0.2, height]) + np.array(velocity) * t
                      + 0.5 * acceleration * t * t)

    v, a = central_differences(model, q_at(-dt), q_at(0.0), q_at(dt), dt)
    com, zmp, fz = monitor.com_and_zmp(q_at(0.0), v, a)
    np.testing.assert_allclose(com, [0.4, -0.25, height + 0.02], atol=1e-12)
    assert fz == pytest.approx(50.0 * (G + acceleration[2]), rel=1e-9)
    # Cart-table model: p = c - (c_z - z0) c_ddot_xy / (g + c_ddot_z).
    expected = com[:2] - (com[2] - ground) * acceleration[:2] / (G + acceleration[2])
    np.testing.assert_allclose(zmp[:2], expected, atol=1e-7)


def test_rotational_inertia_moves_the_zmp():
    """A body spinning up about y at its COM: p_x = c_x - I_yy alpha / (m g)."""
    inertia_yy, mass, alpha = 2.0, 40.0, 3.0
    model = one_body_model(mass=mass, inertia=(1.0, inertia_yy, 1.0))
    monitor = ZmpMonitor(model, 0.05)
    dt = 0.002

    def q_at(t):
        return base_q([0.1, 0.2, 0.8], pin.exp3(np.array([0.0, 0.5 * alpha * t * t + 0.4 * t,
                                                          0.0])))

    v, a = central_differences(model, q_at(-dt), q_at(0.0), q_at(dt), dt)
    np.testing.assert_allclose(a[3:], [0.0, alpha, 0.0], atol=1e-6)
    com, zmp, _ = monitor.com_and_zmp(q_at(0.0), v, a)
    assert zmp[0] == pytest.approx(com[0] - inertia_yy * alpha / (mass * G), abs=1e-6)
    assert zmp[1] == pytest.approx(com[1], abs=1e-9)


def body_by_body_zmp(model, q, v, a, ground=0.0):
    """Kurazume eqs. 26-27 with rotational terms, summed body by body (no centroidal code).

    Returns:
        ZMP (2,) [m], COM (3,) [m] and the vertical ground force [N].
    """
    data = model.createData()
    pin.forwardKinematics(model, data, q, v, a)
    numerator = np.zeros(2)
    denominator = 0.0
    weighted = np.zeros(3)
    for joint in range(1, model.njoints):
        inertia = model.inertias[joint]
        if inertia.mass <= 0:
            continue
        placement, twist, spatial = data.oMi[joint], data.v[joint], data.a[joint]
        lever = inertia.lever
        omega, alpha = twist.angular, spatial.angular
        velocity = twist.linear + np.cross(omega, lever)
        # Classical acceleration of the body's COM, in the body frame.
        accel = spatial.linear + np.cross(alpha, lever) + np.cross(omega, velocity)
        rotation = placement.rotation
        r = placement.act(lever)
        r_ddot = rotation @ accel
        rotational = inertia.inertia  # about the body's COM, in the body frame
        dl = rotation @ (rotational @ alpha + np.cross(omega, rotational @ omega))
        m = inertia.mass
        denominator += m * (r_ddot[2] + G)
        numerator[0] += m * (r_ddot[2] + G) * r[0] - m * r_ddot[0] * (r[2] - ground) - dl[1]
        numerator[1] += m * (r_ddot[2] + G) * r[1] - m * r_ddot[1] * (r[2] - ground) + dl[0]
        weighted += m * r
    return numerator / denominator, weighted / pin.computeTotalMass(model), denominator


@pytest.mark.parametrize('seed', range(4))
def test_multibody_zmp_equals_the_body_by_body_sum(robosimian, seed):
    rng = np.random.default_rng(seed)
    model = robosimian.model
    q = random_configuration(robosimian, rng)
    v = rng.normal(0.0, 0.5, model.nv)
    a = rng.normal(0.0, 2.0, model.nv)
    monitor = ZmpMonitor(model, 0.055, ground_height_m=0.03)
    com, zmp, _ = monitor.com_and_zmp(q, v, a)
    expected_zmp, expected_com, _ = body_by_body_zmp(model, q, v, a, ground=0.03)
    np.testing.assert_allclose(com, expected_com, atol=1e-12)
    np.testing.assert_allclose(zmp[:2], expected_zmp, atol=1e-9)


def test_central_differences_on_the_free_flyer_are_exact_for_constant_twist(robosimian):
    model = robosimian.model
    q0 = nominal_configuration(robosimian)
    twist = np.array([0.3, -0.1, 0.05, 0.2, -0.1, 0.4])
    v_true = np.zeros(model.nv)
    v_true[:6] = twist
    dt = 0.005
    qs = [pin.integrate(model, q0, v_true * k * dt) for k in (-1, 0, 1)]
    v, a = central_differences(model, *qs, dt)
    np.testing.assert_allclose(v, v_true, atol=1e-12)
    np.testing.assert_allclose(a, 0.0, atol=1e-9)


def test_sliding_differences_are_central_differences_bit_for_bit(robosimian):
    """SlidingDifferences gives central_differences' values, bytes included.

    Along a stream (the kept difference reused), after a break in it (recomputed), with
    equal and unequal steps and a configuration repeated (a start at rest).
    """
    model = robosimian.model
    rng = np.random.default_rng(4)
    q0 = nominal_configuration(robosimian)
    qs = [q0, q0]
    for _ in range(12):
        qs.append(pin.integrate(model, qs[-1], rng.normal(0.0, 0.01, model.nv)))
    steps = [0.005, 0.005, 0.004, 0.005, 0.006, 0.005, 0.005, 0.005, 0.005, 0.003, 0.005, 0.005,
             0.005]
    sliding = SlidingDifferences(model)
    calls = [*range(11), 3, 4, 8, 9, 10]  # in order, then jumps back and forth
    for k in calls:
        expected = central_differences(model, qs[k], qs[k + 1], qs[k + 2], steps[k],
                                       steps[k + 1])
        for got, want in zip(sliding.at(qs[k], qs[k + 1], qs[k + 2], steps[k], steps[k + 1]),
                             expected, strict=True):
            assert got.tobytes() == want.tobytes()
    # Along the stream with the kept difference but another step before (its division by the
    # step is not reused), and with the default step after.
    for k, before, after in ((0, 0.005, 0.005), (1, 0.004, None), (2, 0.004, 0.004),
                             (3, 0.005, None)):
        expected = central_differences(model, qs[k], qs[k + 1], qs[k + 2], before, after)
        for got, want in zip(sliding.at(qs[k], qs[k + 1], qs[k + 2], before, after),
                             expected, strict=True):
            assert got.tobytes() == want.tobytes()


def test_margin_matches_the_shared_geometry(robosimian):
    monitor = ZmpMonitor(robosimian.model, 0.055)
    feet = np.array([[0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, 0.5, 0.0]])
    rng = np.random.default_rng(3)
    for point in rng.uniform(-1.0, 1.0, (50, 2)):
        zmp = np.array([*point, 0.0])
        assert monitor.margin(zmp, feet) == pytest.approx(
            disc_support_margin(point[None], feet[:, :2], 0.055)[0], abs=1e-12)
    polygon = monitor.support_polygon(feet)
    np.testing.assert_allclose(polygon, foot_discs_polygon(feet[:, :2], 0.055,
                                                             POLYGON_SEGMENTS_PER_FOOT))
    # The drawn polygon contains every disc: its margin is never below the exact one.
    points = rng.uniform(-1.0, 1.0, (200, 2))
    exact = disc_support_margin(points, feet[:, :2], 0.055)
    drawn = signed_distance(points, polygon)
    assert np.all(drawn >= exact - 1e-12)
    assert np.all(drawn - exact <= 0.055 * CIRCUMSCRIBED + 1e-12)
    # No contact or no ground force: no support.
    assert monitor.margin(np.zeros(3), np.zeros((0, 3))) == -np.inf
    assert monitor.margin(np.full(3, np.nan), feet) == -np.inf


def test_a_kept_support_gives_what_the_contact_points_give(robosimian):
    """The Support built once per stance gives the same state as the points.

    A new one comes whenever the points or the ground (the plane without contacts) change.
    """
    monitor, fresh = (ZmpMonitor(robosimian.model, 0.055) for _ in range(2))
    rng = np.random.default_rng(5)
    stances = [np.array([[0.5, 0.5, 0.0], [0.5, -0.5, 0.02], [-0.5, 0.5, 0.01]]),
               np.array([[0.5, 0.5, 0.1]]), np.zeros((0, 3))]
    for points in stances:
        support = monitor.support(points)
        assert monitor.support(points.copy()) is support
        assert not support.contact_points_in_world.flags.writeable
        for _ in range(5):
            q = random_configuration(robosimian, rng)
            v, a = rng.normal(0, 0.3, (2, robosimian.model.nv))
            kept, direct = monitor.evaluate(q, v, a, support), fresh.evaluate(q, v, a, points)
            np.testing.assert_array_equal(kept.com_in_world, direct.com_in_world)
            np.testing.assert_array_equal(kept.zmp_in_world, direct.zmp_in_world)
            assert kept.margin_m == direct.margin_m
            np.testing.assert_array_equal(kept.contact_points_in_world, points)
        np.testing.assert_array_equal(support.polygon, fresh.support_polygon(points))
        assert support.plane_height_m == fresh.plane_height_m(points)
    monitor.ground_height_m = 0.3
    assert monitor.support(stances[-1]).plane_height_m == 0.3
