"""python -m gait_nodes.swing_table: build, sweep (eq. (2), plot, perturb), ik-check, bad input."""

import re

import numpy as np
import pytest
from swing_helpers import robot

from gait_nodes.swing.sweep import FT_PER_MIN, gait_speed_m_s
from gait_nodes.swing.table import load_table
from gait_nodes.swing_table import main


@pytest.fixture(autouse=True)
def _own_cache(tmp_path, monkeypatch):
    """The sweep caches its one-step costs: in the test's directory, not the user's."""
    monkeypatch.setenv('XDG_CACHE_HOME', str(tmp_path / 'cache'))


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
    match = re.search(r'centred at x 0.45 m: optimal step ([\d.]+) m \(([a-z ,]+)\), '
                      r'([\d.]+) ft/min, swing ([\d.]+) s', printed)
    assert match
    step, feet_per_min, swing_s = (float(match[i]) for i in (1, 3, 4))
    # Goal 0.7 m, its mirror about the middle of 0.1-0.8 m is 0.2 m: one centred step, 0.5 m.
    assert step == pytest.approx(0.5)
    # eq. (2) with the lift and lowering at most the whole swing: between 5 and 4 swings.
    assert step / (5 * swing_s) <= feet_per_min / FT_PER_MIN <= step / (4 * swing_s) * 1.001
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


def test_sweep_defaults_are_the_thesis_setting():
    import argparse

    from gait_nodes.swing.value_iteration import GridSpec, thesis_actions
    from gait_nodes.swing_table import _grid_and_actions

    unset = dict.fromkeys(('x_range', 'y_range', 'yaw_range', 'z_levels', 'z_spacing_m',
                           'radii_m', 'azimuths', 'elevations_rad', 'yaw_steps_rad'))
    spec, actions = _grid_and_actions(argparse.Namespace(**unset), GridSpec.thesis(),
                                      thesis_actions())
    # The thesis command's grid: x 0.2-0.8 m (steps up to 0.6 m, not the 1.0 m of before).
    assert spec == GridSpec.thesis() and spec.x_range_m[:2] == (0.2, 0.8)
    assert actions == thesis_actions()
    levels = _grid_and_actions(argparse.Namespace(**{**unset, 'z_levels': 2}),
                               GridSpec.thesis(), thesis_actions())[0]
    assert levels.z_planes_m is None and levels.z_levels == 2


def test_sweep_says_when_the_optimum_is_at_the_end_of_the_range(capsys):
    # Starts from x 0.45 m on: the slow band near the body (thesis Fig. 12) is off the grid,
    # the speed rises with the step up to the longest one the range holds.
    arguments = [a for a in TINY]
    arguments[arguments.index('--x-range') + 1:arguments.index('--x-range') + 4] = [
        '0.45', '0.8', '8']
    assert main(['sweep', '--families', '2', '--step-heights-m', '0.1', '--goal-x', '0.6',
                 '0.7', '0.8', *arguments]) == 0
    printed = capsys.readouterr().out
    line = next(row for row in printed.splitlines() if 'best over every goal' in row)
    assert 'optimal step 0.35 m (at the end of the range, not an interior optimum)' in line


def test_crossover_walks_each_gait_and_prints_the_walked_table(tmp_path, capsys):
    # A tiny setting: the trot alone at 4 rad/s for 10 s, the polynomial swing (no table).
    bags = tmp_path / 'bags'
    assert main(['crossover', '--joint-vel-limits', '4', '--gaits', 'trot',
                 '--duration-at-1-rad-s', '40', '--swing', 'polynomial', '--step-height-m',
                 '0.1', '--keep-bags', str(bags), '--quiet']) == 0
    printed = capsys.readouterr().out
    assert printed.startswith('Walked, not modelled: each gait walked straight ahead')
    assert '(polynomial swing, 0.1 m lift, timing joint_limit, 40 s / (limit in rad/s) each)' \
        in printed
    [row] = [line for line in printed.splitlines() if line.startswith('| 4 | trot |')]
    cells = [cell.strip() for cell in row.strip('|').split('|')]
    assert float(cells[2]) > 0.05 and cells[-1] == 'feasible'  # planned: 0.078 m/s
    assert cells[6] == f'0 of {cells[6].split(" of ")[1]}'  # no ZMP sample outside
    assert '4 rad/s: fastest walked trot' in printed
    assert (bags / 'trot_w4' / 'metadata.yaml').is_file()
    assert (bags / 'robots' / 'robosimian_w4.yaml').is_file()


@pytest.mark.parametrize('arguments, message', [
    (['--joint-vel-limits', '-1'], '--joint-vel-limits must be > 0'),
    (['--gaits', 'gallop'], 'gallop'),
])
def test_crossover_refuses_bad_input_with_exit_2(capsys, arguments, message):
    assert main(['crossover', '--quiet', *arguments]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1
