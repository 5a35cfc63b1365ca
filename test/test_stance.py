"""gait_nodes.robot.stance: robot YAML copies at other stances (bench/stance.py walks them)."""

from __future__ import annotations

import pytest
import yaml

from gait_nodes.errors import ConfigError
from gait_nodes.robot.description import load_robot_description
from gait_nodes.robot.stance import write_stance


def test_a_copy_moves_only_the_feet_asked_and_places_its_standing_com(tmp_path):
    shipped = load_robot_description('robosimian')
    path = write_stance('robosimian', tmp_path, 0.77, None, 0.58, 0.55)
    assert path.name == 'robosimian_h0.77_f0.58_b0.55.yaml'
    copy = load_robot_description(path)
    for foot, before in zip(copy.feet, shipped.feet, strict=True):
        x, y, z = foot.nominal_position_in_base
        assert x == (0.58 if before.nominal_position_in_base[0] > 0 else -0.55)
        assert (y, z) == (before.nominal_position_in_base[1], -0.77)
    # The standing full-model COM's height over the ground, recomputed for the new feet.
    data = yaml.safe_load(path.read_text())
    assert data['com_height_m'] != pytest.approx(shipped.com_height_m, abs=1e-6)
    assert data['com_height_m'] == pytest.approx(shipped.com_height_m, abs=1e-3)


@pytest.mark.parametrize('bad', [0.0, -0.5, 12.0, float('nan')])
def test_a_place_out_of_range_is_refused(tmp_path, bad):
    with pytest.raises(ConfigError, match='rear_x_m must be in'):
        write_stance('robosimian', tmp_path, 0.77, None, None, bad)
