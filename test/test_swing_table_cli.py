"""python -m gait_nodes.swing_table: build, sweep (eq. (2), plot, perturb), ik-check, bad input."""

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


IK_GRID = ['--x-range', '0.3', '0.6', '4', '--y-range', '-0.55', '-0.45', '3', '--z-range', '-0.7',
           '-0.6', '2', '--yaw-range', '-0.3', '0.3', '3']


def test_ik_check_counts_solutions_and_agrees_with_the_multistart_solver(capsys):
    assert main(['ik-check', *IK_GRID, '--check-targets', '6', '--starts', '200']) == 0
    printed = capsys.readouterr().out
    assert '72 targets solved' in printed
    histogram = re.search(r'solutions per target: (.*)', printed).group(1)
    counts = {int(k): int(v) for k, v in re.findall(r'(\d+): (\d+) \(', histogram)}
    assert sum(counts.values()) == 72 and max(counts) >= 8
    assert '6 of 6 agree' in printed and '0 found only by the multistart solver' in printed


@pytest.mark.parametrize('arguments, message', [
    (['--starts', '0'], 'starts'),
    (['--x-range', '0.8', '0.2', '3'], 'x-range'),
    (['--yaw-range', '-0.3', '0.3', '2.5'], 'yaw-range'),
    (['--foot', 'nose'], 'nose'),
    (['--robot', 'biped'], 'limb IK'),
])
def test_ik_check_refuses_bad_input_with_exit_2(capsys, arguments, message):
    assert main(['ik-check', *IK_GRID, '--check-targets', '0', *arguments]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1
