"""Robot models on Pinocchio: shipped robots, name checks, kinematics identities."""

import math

import numpy as np
import pinocchio as pin
import pytest
import yaml

from gait_nodes.errors import ConfigError
from gait_nodes.robot.description import (
    example_robot_data_dir,
    load_robot_description,
    robots_dir,
)
from gait_nodes.robot.model import RobotModel, load_robot_model
from gait_nodes.robot.whole_body_ik import nominal_configuration


def _example_robot_data_present() -> bool:
    try:
        example_robot_data_dir()
    except ConfigError:
        return False
    return True


needs_example_robot_data = pytest.mark.skipif(
    not _example_robot_data_present(), reason='example-robot-data is not installed')


@pytest.fixture(scope='module')
def robosimian():
    return load_robot_model('robosimian')


def test_robosimian_matches_the_thesis_figures(robosimian):
    description = robosimian.description
    assert 'approximation' in description.description
    assert len(description.feet) == 4
    assert all(len(foot.joints) == 7 for foot in description.feet)
    assert robosimian.mass_kg == pytest.approx(100.0, rel=0.1)
    limb_mass = sum(robosimian.model.inertias[robosimian.model.getJointId(j)].mass
                    for j in description.joint_names)
    assert limb_mass / robosimian.mass_kg == pytest.approx(0.6, abs=0.05)
    assert description.foot_radius_m == 0.055
    assert 0.6 <= description.body_height_m <= 0.7
    assert np.all(robosimian.velocity_limits_rad_s == 1.0)
    # The URDF says 1 rad/s too, and Pinocchio's model carries the YAML's limits.
    assert np.all(robosimian.model.velocityLimit[6:] == 1.0)
    # Identical limbs: same link masses.
    masses = [[robosimian.model.inertias[robosimian.model.getJointId(j)].mass
               for j in foot.joints] for foot in description.feet]
    assert all(m == masses[0] for m in masses)


@pytest.mark.parametrize('name', ['robosimian', 'biped'])
def test_nominal_stance_puts_feet_and_com_where_the_yaml_says(name):
    robot = load_robot_model(name)
    q = nominal_configuration(robot)
    feet, yaws = robot.foot_poses(q)
    np.testing.assert_allclose(feet, robot.nominal_feet_in_world(), atol=1e-6)
    np.testing.assert_allclose(yaws, 0.0, atol=1e-6)
    # The feet are on the ground, the COM height in the YAML is the model's (to 1 cm).
    np.testing.assert_allclose(feet[:, 2], 0.0, atol=1e-6)
    assert robot.com(q)[2] == pytest.approx(robot.description.com_height_m, abs=0.01)
    assert np.all(robot.within_limits(robot.joint_positions(q)))


def test_joint_vector_round_trip(robosimian):
    rng = np.random.default_rng(1)
    joints = rng.uniform(-1, 1, len(robosimian.joint_names))
    q = robosimian.configuration([0.1, -0.2, 0.6], 0.3, joints)
    np.testing.assert_allclose(robosimian.joint_positions(q), joints)
    assert q[:3] == pytest.approx([0.1, -0.2, 0.6])
    rotation = pin.Quaternion(q[3:7]).toRotationMatrix()
    assert math.atan2(rotation[1, 0], rotation[0, 0]) == pytest.approx(0.3)
    named = robosimian.configuration([0, 0, 0.6], 0.0, {'fr_joint_3': -1.2})
    assert robosimian.joint_positions(named)[robosimian.indices(['fr_joint_3'])] == -1.2
    assert len(robosimian.q_indices(robosimian.joint_names)) == 28


def test_com_jacobian_matches_finite_differences(robosimian):
    rng = np.random.default_rng(2)
    q = robosimian.configuration(rng.normal(size=3), rng.uniform(-3, 3),
                                 rng.uniform(-1.5, 1.5, len(robosimian.joint_names)))
    jacobian = robosimian.com_jacobian(q)
    eps = 1e-6
    numeric = np.empty_like(jacobian)
    for k in range(robosimian.model.nv):
        dv = np.zeros(robosimian.model.nv)
        dv[k] = eps
        plus = robosimian.com(pin.integrate(robosimian.model, q, dv))
        minus = robosimian.com(pin.integrate(robosimian.model, q, -dv))
        numeric[:, k] = (plus - minus) / (2 * eps)
    np.testing.assert_allclose(jacobian, numeric, atol=1e-8)
    # Base translation moves the COM one for one (expressed in the base frame).
    rotation = pin.Quaternion(q[3:7]).toRotationMatrix()
    np.testing.assert_allclose(jacobian[:, :3], rotation, atol=1e-12)


def test_velocity_maps_base_twist_into_the_free_flyer(robosimian):
    q = robosimian.configuration([0, 0, 0.6], 0.7)
    v = robosimian.velocity([0.3, 0.1, 0.0], 0.2, np.zeros(28), q)
    dt = 1e-6
    q_next = pin.integrate(robosimian.model, q, v * dt)
    np.testing.assert_allclose((q_next[:3] - q[:3]) / dt, [0.3, 0.1, 0.0], atol=1e-6)


def write_variant(tmp_path, change, robot='robosimian'):
    data = yaml.safe_load((robots_dir() / f'{robot}.yaml').read_text())
    data['urdf'] = str(robots_dir() / data['urdf'])
    change(data)
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(('change', 'expected'), [
    (lambda d: d['feet']['front_left'].update(frame='fl_hand'),
     r"feet.front_left.frame: frame 'fl_hand' is not in robosimian.urdf; valid frames: \[.*"
     r"'fl_foot'"),
    (lambda d: d.update(base_frame='chassis'),
     r"base_frame: frame 'chassis' is not in robosimian.urdf; valid frames: \[.*'base_link'"),
    (lambda d: d['feet']['rear_left']['joints'].__setitem__(2, 'rl_knee'),
     r"feet.rear_left.joints: joint 'rl_knee' is not a 1-DOF joint of robosimian.urdf; "
     r"valid joints: \[.*'rl_joint_3'"),
    (lambda d: (d['feet']['rear_left']['joints'].__setitem__(2, 'fr_joint_3'),
                d['feet']['front_right']['joints'].__setitem__(2, 'rl_joint_3')),
     r"feet.front_right.joints: joint 'rl_joint_3' does not move frame 'fr_foot'"),
    (lambda d: d.update(base_frame='fl_link_2'), 'is not the root link'),
    (lambda d: d['extra'].update(locked_joints=['wrist']), 'extra.locked_joints: must list limb'),
    (lambda d: d['extra'].update(posture={'fl_joint_3': 9.0}),
     r'extra.posture.fl_joint_3: must be a number in \[-2.8, 2.8\]'),
    (lambda d: d['extra'].update(posture={'elbow': 0.1}), "'elbow' is not a 1-DOF joint"),
    (lambda d: d['extra'].update(foot_orientation='full'), 'foot_orientation: must be one of'),
    (lambda d: d['extra'].update(foot_frame_height_m=-1), 'foot_frame_height_m: must be'),
])
def test_yaml_naming_what_the_urdf_lacks_is_refused_with_valid_names(tmp_path, change,
                                                                     expected):
    path = write_variant(tmp_path, change)
    with pytest.raises(ConfigError, match=expected) as info:
        RobotModel(load_robot_description(path))
    assert str(path) in str(info.value)


def test_unparsable_urdf_is_refused_with_its_path(tmp_path):
    (tmp_path / 'broken.urdf').write_text('<robot name="x"><link name=')
    path = write_variant(tmp_path, lambda d: d.update(urdf=str(tmp_path / 'broken.urdf')))
    with pytest.raises(ConfigError, match='broken.urdf'):
        RobotModel(load_robot_description(path))


@needs_example_robot_data
@pytest.mark.parametrize('name', ['go2', 'solo12', 'talos'])
def test_real_robots_load_and_stand(name):
    robot = load_robot_model(name)
    q = nominal_configuration(robot)
    feet, _ = robot.foot_poses(q)
    np.testing.assert_allclose(feet, robot.nominal_feet_in_world(), atol=1e-6)
    assert np.all(robot.within_limits(robot.joint_positions(q)))
    assert robot.com(q)[2] == pytest.approx(robot.description.com_height_m, abs=0.01)
    expected_joints = {'go2': 12, 'solo12': 12, 'talos': 32}[name]
    assert len(robot.joint_names) == expected_joints
