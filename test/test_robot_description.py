"""Robot YAML loading: the fixtures load, and every kind of bad file is refused with its path."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from gait_nodes.errors import ConfigError
from gait_nodes.robot.description import load_robot_description

ROBOTS = Path(__file__).parent / 'data' / 'robots'


def test_fixtures_load():
    quad = load_robot_description(ROBOTS / 'quadruped.yaml')
    assert quad.foot_names == ('front_left', 'front_right', 'rear_left', 'rear_right')
    assert quad.nominal_stance_in_base().shape == (4, 3)
    assert quad.velocity_limit_rad_s('fl_1') == 1.0
    assert quad.urdf_path.is_file()
    biped = load_robot_description(ROBOTS / 'biped.yaml')
    assert biped.kind == 'biped' and biped.gaits == ('biped',)


def write_variant(tmp_path, change):
    data = yaml.safe_load((ROBOTS / 'quadruped.yaml').read_text())
    change(data)
    (tmp_path / 'point.urdf').write_text((ROBOTS / 'point.urdf').read_text())
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(('change', 'expected'), [
    (lambda d: d.pop('foot_radius_m'), 'foot_radius_m: missing'),
    (lambda d: d.update(foot_radius_m=-1), r'foot_radius_m: must be a number in \(0.0, 0.5\]'),
    (lambda d: d.update(kind='hexapod'), "kind: must be one of"),
    (lambda d: d.update(gaits=['biped']), "not possible for a quadruped"),
    (lambda d: d.update(urdf='missing.urdf'), "urdf 'missing.urdf' not found"),
    (lambda d: d.update(colour='red'), r"unknown keys \['colour'\]"),
    (lambda d: d['feet'].pop('rear_right'), 'a quadruped has 4 feet, got 3'),
    (lambda d: d['feet']['front_left'].update(nominal_position_m=[0, 0]), 'list of 3 finite'),
    (lambda d: d['feet']['front_left'].update(nominal_position_m=[0, 0, 0.1]), 'z < 0'),
    (lambda d: d.update(joint_velocity_limits_rad_s={'elbow': 2.0}), 'not a limb joint'),
    (lambda d: d['reach'].update(max_turn_rad='wide'), 'max_turn_rad: must be a number'),
    (lambda d: d.update(gait_stances={'gallop': {'front_x_m': 0.3, 'rear_x_m': 0.3}}),
     "gallop: is not one of the robot's gaits"),
    (lambda d: d.update(gait_stances={'trot': {'front_x_m': 0.3, 'rear_x_m': -0.3}}),
     r'rear_x_m: must be a number in \(0.0, 5.0\], got -0.3'),
    (lambda d: d.update(gait_stances={'trot': {'front_x_m': 0.3, 'rear_y_m': 0.3}}),
     r"unknown keys \['rear_y_m'\]"),
    (lambda d: d.update(gait_stances={'trot': {'front_x_m': 0.3}}), 'rear_x_m: missing'),
    (lambda d: d.update(com_xy_m=[0.0]), r'com_xy_m: must be a list of 2 finite numbers'),
    (lambda d: d.update(com_xy_m=[0.0, float('nan')]), r'com_xy_m: must be a list of 2 finite'),
    (lambda d: d.update(com_xy_m=[2.0, 0.0]), r'com_xy_m: the COM at standstill must lie '
                                              r'between the nominal feet'),
])
def test_bad_yaml_is_refused_with_path_and_reason(tmp_path, change, expected):
    path = write_variant(tmp_path, change)
    with pytest.raises(ConfigError, match=expected) as info:
        load_robot_description(path)
    assert str(path) in str(info.value)


def test_unknown_robot_lists_shipped(tmp_path):
    with pytest.raises(ConfigError, match='unknown robot'):
        load_robot_description('no_such_robot')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: [unclosed\n')
    with pytest.raises(ConfigError, match='cannot read robot YAML'):
        load_robot_description(broken)


def test_a_copy_at_another_joint_velocity_limit_differs_in_the_limit_only(tmp_path):
    from gait_nodes.robot.description import write_at_joint_velocity_limit

    original = load_robot_description('robosimian')
    copy = load_robot_description(write_at_joint_velocity_limit('robosimian', 2.5, tmp_path))
    assert copy.path == tmp_path / 'robosimian_w2.5.yaml'
    assert copy.joint_velocity_limit_rad_s == 2.5
    assert copy.urdf_path.read_bytes() == original.urdf_path.read_bytes()
    for field in ('name', 'gaits', 'reach', 'extra', 'body_height_m', 'com_height_m',
                  'joint_acceleration_limit_rad_s2', 'foot_radius_m', 'joint_names'):
        assert getattr(copy, field) == getattr(original, field), field
    assert (copy.nominal_stance_in_base() == original.nominal_stance_in_base()).all()
    with pytest.raises(ConfigError, match='joint velocity limit'):
        write_at_joint_velocity_limit('robosimian', 0.0, tmp_path)


def test_a_gait_with_its_own_stance_places_the_front_and_rear_feet_there(tmp_path):
    from gait_nodes.planning.layout import FootLayout

    path = write_variant(tmp_path, lambda d: d.update(
        gait_stances={'trot': {'front_x_m': 0.31, 'rear_x_m': 0.27, 'max_step_length_m': 0.65}}))
    robot = load_robot_description(path)
    # Its own longest step too; the other gaits keep the reach's.
    assert robot.max_step_length_m('trot') == 0.65 and robot.longest_step_m == 0.65
    assert robot.max_step_length_m('crawl') == robot.reach.max_step_length_m == 0.5
    assert robot.max_step_length_m() == 0.5
    nominal = robot.nominal_stance_in_base()
    trot = robot.nominal_stance_in_base('trot')
    front = nominal[:, 0] > 0
    assert trot[front, 0].tolist() == [0.31, 0.31] and trot[~front, 0].tolist() == [-0.27, -0.27]
    assert (trot[:, 1:] == nominal[:, 1:]).all()  # y and z as they are
    # Gaits without one (and no gait) keep the nominal stance.
    assert (robot.nominal_stance_in_base('crawl') == nominal).all()
    layout = FootLayout.of(robot)
    width = float(nominal[:, 1].max() - nominal[:, 1].min())
    assert layout.offsets(width, 'trot')[:, 0].tolist() == trot[:, 0].tolist()
    wider = layout.offsets(width + 0.1, 'trot')
    assert wider[:, 0].tolist() == trot[:, 0].tolist()
    assert wider[:, 1] == pytest.approx(trot[:, 1] + np.sign(trot[:, 1]) * 0.05)
    assert (layout.offsets(width, 'crawl') == nominal[:, :2]).all()
    assert (layout.offsets(width) == nominal[:, :2]).all()


def test_a_biped_has_no_gait_stance(tmp_path):
    data = yaml.safe_load((ROBOTS / 'biped.yaml').read_text())
    data['gait_stances'] = {'biped': {'front_x_m': 0.1, 'rear_x_m': 0.1}}
    (tmp_path / 'point.urdf').write_text((ROBOTS / 'point.urdf').read_text())
    for urdf in ROBOTS.glob('*.urdf'):
        (tmp_path / urdf.name).write_text(urdf.read_text())
    path = tmp_path / 'biped.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match='a biped has no front and rear feet'):
        load_robot_description(path)
