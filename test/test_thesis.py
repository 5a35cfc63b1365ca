"""``python -m gait_nodes.thesis --quick``: the thesis' results from our models (issue 19.4).

One coarse run per module: the command prints every row and writes every figure; the physics
the thesis found is checked on what it computed (an interior optimal step, perturbed swings no
faster than the value-table swing, two IK families that differ), not its numbers.
"""

import contextlib
import io
import re

import numpy as np
import pytest

from gait_nodes import thesis

FIGURES = ('fig08_zmp_error.png', 'fig10_joint_speed.png', 'fig12_joint_travel.png',
           'fig14_step_vs_speed.png',
           'fig15_optimal_swing.png', 'fig16_curved_vs_straight.png', 'fig17_families.png',
           'fig18_step_heights.png', 'fig19_overall.png', 'fig20_perturbations.png',
           'fig21_zmp_vs_value_iteration.png')


@pytest.fixture(scope='module')
def quick_cache(tmp_path_factory):
    """``XDG_CACHE_HOME`` of the module: the quick grid's one-step costs, computed once."""
    return tmp_path_factory.mktemp('cache')


@pytest.fixture(scope='module')
def quick_run(tmp_path_factory, quick_cache, tiny_crossover):
    """(exit status, stdout, results, figure directory) of one ``--quick`` run.

    Fig. 21's walks are the session's tiny walked crossover (every gait at 2.5 rad/s: see
    test_walked_crossover.py), not the quick run's own two limits (a minute of walking).
    """
    out_dir = tmp_path_factory.mktemp('figures')
    recorded = {}
    original = thesis.run
    walks = []

    def recording(*args, **kwargs):
        recorded['results'] = original(*args, **kwargs)
        return recorded['results']

    def tiny_walks(robot, settings, log):
        walks.append(settings.limits_rad_s)
        return tiny_crossover[1]

    stdout = io.StringIO()
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv('XDG_CACHE_HOME', str(quick_cache))
        patch.setattr(thesis, 'run', recording)
        patch.setattr(thesis, 'walk_gaits', tiny_walks)
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(io.StringIO()):
            status = thesis.main(['--quick', '--out', str(out_dir)])
    assert walks == [thesis.Settings.quick().limits_rad_s]
    return status, stdout.getvalue(), recorded['results'], out_dir


def test_the_command_prints_every_row_and_writes_every_figure(quick_run):
    status, stdout, results, out_dir = quick_run
    assert status == 0
    for figure, quantity, ours, reference in thesis.rows(results):
        assert f'| {figure} | {quantity} | {ours} | {reference} |' in stdout
    for key in thesis.THESIS:
        assert thesis.THESIS[key] in stdout
    for name in FIGURES:
        path = out_dir / name
        assert path.stat().st_size > 10_000, name
        assert path.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_every_figure_marks_the_thesis_values(quick_run, tmp_path, monkeypatch):
    import matplotlib.figure

    labels = {}
    original = matplotlib.figure.Figure.savefig

    def recording(figure, path, *args, **kwargs):
        texts = [t.get_text() for t in figure.texts]
        for axes in figure.axes:
            texts += axes.get_legend_handles_labels()[1] + [axes.get_title()]
            texts += [t.get_text() for t in axes.texts]
            texts += [t.get_text() for t in axes.get_xticklabels()]
        labels[path.name] = texts
        return original(figure, path, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, 'savefig', recording)
    _, _, results, _ = quick_run
    thesis.write_figures(results, tmp_path)
    assert set(labels) == set(FIGURES)
    for name, texts in labels.items():
        # "thesis: ...", "thesis' ..." (not "family 2 (thesis 3)": our family, their name).
        assert any(re.search(r"thesis(:|'|\n)", text) for text in texts), name
    # Fig. 21 says its gaits are walked, not modelled.
    assert any('walked, not modelled' in text for text in labels[
        'fig21_zmp_vs_value_iteration.png'])
    assert any(text.startswith('optimum not checked') for text in labels[
        'fig14_step_vs_speed.png'])


def test_fig12_maps_the_joint_travel_over_the_swing_plane(quick_run):
    _, _, results, _ = quick_run
    shape = (len(thesis.FIG12_Y_M), len(thesis.FIG12_X_M))
    for move in thesis.FIG12_MOVES:
        travel = results.travel_maps[move]
        assert travel.shape == shape
        # Out of reach (NaN, the thesis' 0 rad/s) far from the limb, in reach on the goal.
        assert np.isnan(travel[0, -1])  # x 1.0 m, y -1.0 m
        goal = (np.argmin(np.abs(thesis.FIG12_Y_M + 0.5)), np.argmin(np.abs(thesis.FIG12_X_M
                                                                            - 0.6)))
        assert np.isfinite(travel[goal])
    # The line along the swing (Fig. 12's row at y -0.5 m) is the map's row.
    x, line = results.joint_travel[2]
    row = results.travel_maps['x'][np.argmin(np.abs(thesis.FIG12_Y_M + 0.5))]
    np.testing.assert_array_equal(line, row[np.isin(thesis.FIG12_X_M, x)])


def test_fig12_travel_is_a_derivative_the_small_move_does_not_change(quick_run):
    # Travel per metre of a small move is |dq/dp|: halving the move changes it by little away
    # from the singular curves (where the joints turn by orders more per metre).
    from gait_nodes.robot.model import load_robot_model

    robot = load_robot_model('robosimian')
    x, y = np.arange(0.3, 0.76, 0.05), np.arange(-0.6, -0.44, 0.05)
    for move in thesis.FIG12_MOVES:
        coarse = thesis.joint_travel_map(robot, 2, x, y, move, step_m=0.002)
        fine = thesis.joint_travel_map(robot, 2, x, y, move, step_m=0.001)
        ratio = (fine / coarse)[np.isfinite(coarse) & np.isfinite(fine) & (coarse < 40)]
        assert len(ratio) > 0.5 * coarse.size
        assert np.median(np.abs(ratio - 1)) < 0.02, move


def _grid(counts, spacing, best_step, speed=0.04):
    from gait_nodes.swing.sweep import SpeedCurve

    steps = np.arange(1, 31) * 2 * spacing
    speeds = speed * np.exp(-((steps - best_step) / 0.2) ** 2)
    return thesis.GridOptimum(counts, spacing, SpeedCurve(steps, speeds, steps, np.zeros((30, 4))),
                              1.0)


def test_convergence_is_judged_on_the_two_finest_grids():
    one = [_grid((31, 11, 7), 0.02, 0.56)]
    assert thesis.convergence(one)[0] is None
    assert 'not checked' in thesis.convergence(one)[1]
    # Centred steps lie 2 dx apart: within one step of the coarser grid is converged.
    converged, text = thesis.convergence([_grid((16, 6, 5), 0.04, 0.44),
                                          _grid((41, 16, 9), 0.015, 0.54),
                                          _grid((61, 21, 13), 0.01, 0.56)])
    assert converged and text.startswith('converged: 0.54 m on 41x16x9, 0.56 m on 61x21x13;')
    # The flat top around the optimum: every step within 5 % of the best speed.
    assert 'within 5 % of the best on 61x21x13: 0.52-0.60 m' in text
    converged, text = thesis.convergence([_grid((41, 16, 9), 0.015, 0.6),
                                          _grid((61, 21, 13), 0.01, 0.8)])
    assert converged and text.startswith(
        'converged, at the end of the range, not an interior optimum: 0.60 m on 41x16x9')
    converged, text = thesis.convergence([_grid((41, 16, 9), 0.015, 0.45),
                                          _grid((61, 21, 13), 0.01, 0.56)])
    assert converged is False
    assert text.startswith('not converged: 0.45 m on 41x16x9, 0.56 m on 61x21x13;')
    assert '(moves +0.11 m, more than one step of the coarser grid, 0.030 m)' in text


def test_fig14_on_a_finer_grid_is_printed_with_its_verdict(quick_run, quick_cache,
                                                            monkeypatch):
    from dataclasses import replace

    from gait_nodes.robot.model import load_robot_model

    monkeypatch.setenv('XDG_CACHE_HOME', str(quick_cache))
    _, _, results, _ = quick_run
    finer = thesis.fig14_on_grid(load_robot_model('robosimian'), results.settings,
                                 results.centre_x_m, (21, 4, 3), lambda message: None)
    assert finer.x_spacing_m == pytest.approx(0.03)
    # Centred steps: twice the spacing apart, centred on x 0.5 m.
    np.testing.assert_allclose(np.diff(finer.curve.steps_m), 0.06, atol=1e-9)
    np.testing.assert_allclose(finer.curve.starts[:, 0] + finer.curve.steps_m / 2, 0.5)
    with_finer = replace(results, fig14_grids=[*results.fig14_grids, finer])
    printed = thesis.format_table(thesis.rows(with_finer))
    assert '| Fig. 14 | same, centred, finer grid 21x4x3 (x every 0.030 m) |' in printed
    verdict = thesis.convergence(with_finer.fig14_grids)[1]
    assert verdict.startswith(('converged: ', 'not converged: '))
    assert f'| optimum converged over grids 16x6x5, 21x4x3 | {verdict} |' in printed


def test_the_sweep_command_gives_the_thesis_commands_optimum_on_its_grid(quick_run, quick_cache,
                                                                        monkeypatch, capsys):
    from gait_nodes.swing.sweep import describe_optimum
    from gait_nodes.swing_table import main as swing_table

    monkeypatch.setenv('XDG_CACHE_HOME', str(quick_cache))
    _, _, results, _ = quick_run
    s = results.settings
    assert swing_table(['sweep', '--families', '2', '--step-heights-m', '0.1', '--x-range',
                        '0.2', '0.8', str(s.x_count), '--y-range', '-0.65', '-0.4',
                        str(s.y_count), '--yaw-range', '-0.45', '0.45', str(s.yaw_count),
                        '--radii-m', *map(str, s.radii_m), '--azimuths', str(s.azimuth_count),
                        '--quiet']) == 0
    printed = capsys.readouterr().out
    assert (f'swings centred at x 0.50 m: optimal step '
            f'{describe_optimum(results.centred[2, 0.1])},') in printed
    assert (f'best over every goal: optimal step '
            f'{describe_optimum(results.anywhere[2, 0.1])},') in printed


def test_gait_speed_has_an_interior_maximum_over_step_size(quick_run):
    _, _, results, _ = quick_run
    # Fig. 14 (thesis' 3rd family, 0.1 m step height), swings centred on the stance. On the
    # default grid this optimum lies at 0.56 m, one node short of the longest step
    # (docs/thesis.md).
    curve = results.centred[2, 0.1]
    k = curve.best
    assert 0 < k < len(curve.steps_m) - 1
    assert curve.speeds_m_s[k] > max(curve.speeds_m_s[0], curve.speeds_m_s[-1])
    # Appendix A, one goal: the start is the argmax of eq. (2) along the goal's x line, and
    # starting closer to the body than that is slower (the thesis' reason for Fig. 14's drop).
    for (family, height, goal_x), table_curve in results.tables.curves.items():
        if family == 2 and goal_x >= 0.6:
            k = table_curve.best
            assert 0 < k < len(table_curve.steps_m) - 1, (family, height, goal_x)


def test_every_kind_of_perturbation_is_slower_on_average(quick_run):
    _, _, results, _ = quick_run
    assert [r.mode for r in results.perturbations] == ['x', 'y', 'z', 'xyz']
    for result in results.perturbations:
        assert len(result.speeds_m_s) == results.settings.trials
        # The thesis' claim (IV.B.7) is the mean loss per kind; single copies can win where
        # the value is interpolated across the 0.1 m between the two swing planes (docs/thesis.md).
        assert result.mean_loss_m_s > 0, result.mode
        assert result.slower_fraction > 0.5, result.mode


def test_families_2_and_7_give_different_joint_solutions(quick_run):
    _, _, results, _ = quick_run
    q2, q7 = results.families_q
    assert np.all(np.abs(q2 - q7) > 0.01)


def test_the_optimal_swing_beats_the_straight_one_between_the_same_places(quick_run):
    _, _, results, _ = quick_run
    optimal = results.optimal
    path, straight = optimal['path'], optimal['straight']
    np.testing.assert_allclose(path.states[[0, -1]], straight.states[[0, -1]])
    assert path.duration_s < straight.duration_s
    assert 0 < optimal['lift_share'] < 1


@pytest.mark.parametrize('args', [['--quick', '--bogus'], ['--out']])
def test_bad_arguments_exit_2_with_one_line(args, capsys):
    with pytest.raises(SystemExit) as exit_info:
        thesis.main(args)
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and 'error' in error


def test_an_out_path_that_is_a_file_exits_2(tmp_path, capsys):
    path = tmp_path / 'file'
    path.write_text('')
    with pytest.raises(SystemExit) as exit_info:
        thesis.main(['--quick', '--out', str(path)])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err.count('\n') == 1


def test_an_out_directory_that_cannot_be_made_exits_2_before_any_work(tmp_path, capsys):
    # Under a file: no directory can be made there; refused before the minutes of work.
    parent = tmp_path / 'file'
    parent.write_text('')
    with pytest.raises(SystemExit) as exit_info:
        thesis.main(['--quick', '--out', str(parent / 'figures')])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert error.count('\n') == 1 and 'cannot create the directory' in error


def test_fig21_rows_are_the_walked_gaits_against_the_thesis(quick_run, tiny_crossover):
    _, stdout, results, _ = quick_run
    assert results.crossover == tiny_crossover[1]
    fig21 = [row for row in thesis.rows(results) if row[0] == 'Fig. 21']
    assert [row[1] for row in fig21] == [
        'ZMP crawl feasible (walked)',
        'ZMP crawl faster than the static crawl (the value-iteration crawl; both walked)',
        'ZMP trot feasible (walked)',
        'ZMP trot faster than the static crawl (the value-iteration crawl; both walked)']
    speed = {r.gait: r.speed_m_s for r in tiny_crossover[1]}
    assert fig21[0][2] == 'from 2.5 rad/s' and fig21[2][2] == 'from 2.5 rad/s'
    for row, gait in ((fig21[1], 'crawl'), (fig21[3], 'trot')):
        if speed[gait] > speed['static_crawl']:
            assert row[2] == (f'from 2.5 rad/s ({speed[gait]:.4f} against '
                              f'{speed["static_crawl"]:.4f} m/s there)')
        else:
            assert row[2] == 'never up to 2.5 rad/s'
    assert fig21[0][3] == 'from 1.9 rad/s' and fig21[1][3] == 'above about 2.4 rad/s'
