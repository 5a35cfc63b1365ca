"""python -m gait_nodes.swing_table: build, sweep (eq. (2), plot, --perturb), bad input."""

import re

import numpy as np
import pytest
from swing_helpers import robot

from gait_nodes.swing.sweep import FT_PER_MIN, gait_speed_m_s
from gait_nodes.swing.table import load_table
from gait_nodes.swing_table import main

TINY = ['--x-range', '0.1', '0.8', '15', '--y-range', '-0.6', '-0.45', '4', '--z-levels', '2',
        '--yaw-range', '-0.15', '0.15', '3', '--radii-m', '0.05', '0.1', '--elevations-rad',
        '-0.6', '0', '0.6', '--quiet']


def test_build_writes_a_table_for_the_requested_settings(tmp_path, capsys):
    out = tmp_path / 'table.npz'
    assert main(['build', '--family', '7', '--step-height-m', '0.08', '--joint-vel-limit',
                 '1.5', '--out', str(out), *TINY]) == 0
    printed = capsys.readouterr().out
    assert 'states x' in printed and 'state-actions/s' in printed
    table = load_table(out, robot(), 1.5, 7)
    assert table.grid.shape == (15, 4, 2, 3)
    assert -0.5 in table.grid.y_m  # a y node on the goal
    assert table.step_height_m == 0.08
    assert table.goal[2] == pytest.approx(table.ground_z_m + 0.08)
    assert table.converged
    goal = table.grid.nearest_node(table.goal)
    assert table.values_s[goal] == 0.0


@pytest.mark.parametrize('arguments, message', [
    (['--family', '9'], 'family'),
    (['--goal', '2.0', '-0.5', '-0.55', '0'], 'outside the grid'),
    (['--joint-vel-limit', '-1'], 'joint velocity limit'),
    (['--robot', 'no_such_robot'], 'no_such_robot'),
])
def test_build_refuses_bad_input_with_exit_2(tmp_path, capsys, arguments, message):
    assert main(['build', '--out', str(tmp_path / 't.npz'), *TINY, *arguments]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1


def test_gait_speed_formula_of_the_thesis():
    # thesis eq. (2): 4 swings plus the body's move (swing time minus lift and lowering).
    assert gait_speed_m_s(0.34, 2.0, 0.3, 0.3) == pytest.approx(0.34 / (8.0 + 1.4))
    assert FT_PER_MIN == pytest.approx(196.850, rel=1e-5)


def test_sweep_prints_the_optimum_plots_and_perturbs(tmp_path, capsys):
    plot = tmp_path / 'sweep.png'
    assert main(['sweep', '--families', '2', '--step-heights-m', '0.1', '--goal-x', '0.7',
                 '--plot', str(plot), '--perturb', '--trials', '8', *TINY]) == 0
    printed = capsys.readouterr().out
    match = re.search(r'optimal step ([\d.]+) m, ([\d.]+) m/s = ([\d.]+) ft/min', printed)
    assert match
    step, speed, feet_per_min = (float(v) for v in match.groups())
    assert 0 < step <= 0.6 and speed * FT_PER_MIN == pytest.approx(feet_per_min, rel=2e-3)
    losses = [float(v) for v in re.findall(r'mean speed lost ([+-][\d.]+) ft/min', printed)]
    assert len(losses) == 4 and np.mean(losses) > 0
    assert plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
