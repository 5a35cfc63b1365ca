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


# RoboSimian as published in Project Chrono's model (src/chrono_models/robot/robosimian/
# RoboSimian.cpp), copied here as printed there, independently of tools/make_robot_urdfs.py.
# Chrono's chassis frame has z down and y to the right (its demos turn the robot over by pi
# about x); angles are printed to 5 decimals, so positions agree to about 1e-5 m.
CHRONO_MOUNTS = {  # limb: (xyz, rpy) of link 0 on the chassis
    'fr': ((0.29326, 0.20940, 0.03650), (0.0, -1.57080, -0.26180)),
    'rr': ((-0.29326, 0.20940, 0.03650), (0.0, -1.57080, 0.26180)),
    'rl': ((-0.29326, -0.20940, 0.03650), (0.0, -1.57080, 2.87979)),
    'fl': ((0.29326, -0.20940, 0.03650), (0.0, -1.57080, 3.40339)),
}
CHRONO_JOINTS = [  # (xyz, rpy, axis) of joints 1..7 in the parent link
    ((0.17203, 0, 0), (3.14159, 0, 0), (1, 0, 0)),
    ((0, 0, 0), (0, 0, 0), (0, -1, 0)),
    ((0.28650, -0.11700, 0), (0, 0, 0), (1, 0, 0)),
    ((0, 0, 0), (0, 0, 0), (0, -1, 0)),
    ((0.28650, -0.11700, 0), (0, 0, 0), (1, 0, 0)),
    ((0, 0, 0), (0, 0, 0), (0, -1, 0)),
    ((0.19250, -0.11700, 0), (0, 0, 0), (1, 0, 0)),
]
# Masses [kg]: chassis; pitch link (joints 1, 3, 5), roll link (2, 4, 6), force-torque
# adapter and sensor, wheel mount (7), wheel.
CHRONO_MASSES = {'chassis': 46.658335, 'pitch': 0.428770, 'roll': 4.078540,
                 'ft_adapter': 0.253735, 'ft_sensor': 0.195418, 'wheel_mount': 3.1775,
                 'wheel': 1.499326}
CHRONO_FOOT_BEYOND_JOINT_7_M = 0.12024 + 0.055  # foot centre + the thesis' foot radius


def chrono_rotation(rpy):
    r, p, y = rpy
    return (pin.utils.rotate('z', y) @ pin.utils.rotate('y', p) @ pin.utils.rotate('x', r))


def chrono_chain(limb, angles):
    """Joint 1..7 origins and the sole in base_link, from the published figures alone."""
    to_base = pin.utils.rotate('x', math.pi)
    xyz, rpy = CHRONO_MOUNTS[limb]
    position, rotation = to_base @ np.array(xyz), to_base @ chrono_rotation(rpy)
    origins = []
    for (offset, joint_rpy, axis), angle in zip(CHRONO_JOINTS, angles, strict=True):
        position = position + rotation @ np.array(offset, dtype=float)
        rotation = rotation @ chrono_rotation(joint_rpy) @ pin.exp3(np.array(axis) * angle)
        origins.append(position)
    sole = position + rotation @ np.array([CHRONO_FOOT_BEYOND_JOINT_7_M, 0.0, 0.0])
    return np.array(origins), sole, rotation


@pytest.mark.parametrize('limb', ['fl', 'fr', 'rl', 'rr'])
def test_robosimian_urdf_is_the_published_chain(robosimian, limb):
    rng = np.random.default_rng(7)
    configurations = [np.zeros(7), *rng.uniform(-math.pi, math.pi, (4, 7))]
    data = robosimian.new_data()
    joints = [f'{limb}_joint_{k}' for k in range(1, 8)]
    for angles in configurations:
        q = robosimian.configuration(np.zeros(3), 0.0, dict(zip(joints, angles, strict=True)))
        pin.framesForwardKinematics(robosimian.model, data, q)
        origins, sole, link_7 = chrono_chain(limb, angles)
        urdf_origins = [data.oMi[robosimian.model.getJointId(j)].translation for j in joints]
        np.testing.assert_allclose(urdf_origins, origins, atol=2e-5)
        foot = data.oMf[robosimian.model.getFrameId(f'{limb}_foot')]
        np.testing.assert_allclose(foot.translation, sole, atol=2e-5)
        # The foot frame is level (z up) when link 7 points straight down.
        np.testing.assert_allclose(foot.rotation[:, 2], -link_7[:, 0], atol=2e-5)


def test_robosimian_masses_are_the_published_ones(robosimian):
    description = robosimian.description
    published = CHRONO_MASSES
    limb = (3 * published['pitch'] + 3 * published['roll'] + published['ft_adapter']
            + published['ft_sensor'] + published['wheel_mount'] + published['wheel'])
    assert robosimian.mass_kg == pytest.approx(published['chassis'] + 4 * limb, abs=1e-6)
    assert robosimian.mass_kg == pytest.approx(121.25, abs=0.01)
    model = robosimian.model
    # Everything a limb joint carries (fixed parts merged into the moving links).
    limb_mass = sum(model.inertias[model.getJointId(j)].mass for j in description.joint_names)
    assert limb_mass == pytest.approx(4 * limb, abs=1e-6)
    assert limb_mass / robosimian.mass_kg == pytest.approx(0.615, abs=0.001)  # thesis: ~60 %
    per_joint = [published['pitch'], published['roll']] * 3 + [
        published['wheel_mount'] + published['wheel']]
    per_joint[5] += published['ft_adapter'] + published['ft_sensor']
    for foot in description.feet:
        masses = [model.inertias[model.getJointId(j)].mass for j in foot.joints]
        np.testing.assert_allclose(masses, per_joint, atol=1e-9)
    assert model.inertias[1].mass == pytest.approx(published['chassis'])
    assert 'Chrono' in description.description
    assert len(description.feet) == 4
    assert description.foot_radius_m == 0.055
    assert description.body_height_m == 0.77
    assert np.all(robosimian.velocity_limits_rad_s == 1.0)
    # The URDF says 1 rad/s too, and Pinocchio's model carries the YAML's limits.
    assert np.all(robosimian.model.velocityLimit[6:] == 1.0)


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
    # Where it stands: the planner's standing ZMP (to 0.1 mm).
    np.testing.assert_allclose(robot.com(q)[:2], robot.description.com_xy_m, atol=1e-4)
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
     r'extra.posture.fl_joint_3: must be a number in \[-6.283\d*, 6.283\d*\]'),
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
    if robot.description.com_xy_m is not None:
        np.testing.assert_allclose(robot.com(q)[:2], robot.description.com_xy_m, atol=1e-4)
    expected_joints = {'go2': 12, 'solo12': 12, 'talos': 32}[name]
    assert len(robot.joint_names) == expected_joints
