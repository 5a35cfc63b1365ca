"""Build swing-leg value tables and sweep step size against crawl speed (thesis 000, III.C, IV).

``python -m gait_nodes.swing_table build --robot robosimian --family 2 --step-height-m 0.1
--joint-vel-limit 1.0 --out table.npz`` runs the value iteration and writes the table file.
The default grid (x 0.2-0.8 m in 13, y -0.65 to -0.4 m in 11, 3 z levels 0.05 m apart from the
swing plane up, yaw +-0.3 rad in 5: 2,145 states; 3 radii x 8 azimuths x 3 elevations x 3 yaw
steps: 218 actions) builds in about a second; a finer one, e.g. ``--x-range 0.2 0.8 31
--y-range -0.65 -0.4 14 --z-levels 7 --yaw-range -0.45 0.45 11`` (33,418 states), in tens of
seconds.

``python -m gait_nodes.swing_table sweep --families 2 7 --step-heights-m 0.06 0.1 --plot
sweep.png [--perturb]`` builds one table per goal and family, plots step size against the crawl
speed of thesis eq. (2) (thesis Fig. 14, 17-19), prints the optimal step and speed of the swings
centred on the middle of the grid's x range and over every goal, and with ``--perturb``
repeats the optimality test of thesis IV.B.7. Its defaults are the thesis' setting of
``python -m gait_nodes.thesis`` (:meth:`GridSpec.thesis`, :func:`thesis_actions`, goals at y
-0.5 m, z -0.6 m, every x node ahead of the middle whose mirror is a node), on the thesis'
stance as that command's (:func:`gait_nodes.thesis.thesis_robot`): on the same grid both print
the same optima. Steps end where the grid's x range does (0.6 m on x 0.2-0.8 m); an optimum on
the longest or shortest step is printed as "at the end of the range, not an interior optimum".
The one-step costs are cached as the thesis command's, and shared with it: the same robot,
grid and actions are computed once.

``python -m gait_nodes.swing_table crossover [--joint-vel-limits 0.5 1 1.5 2 2.5 3 4] [--quick]
[--keep-bags DIR]`` walks each of the robot's gaits (RoboSimian: the ZMP crawl, the static
crawl, the trot), on the thesis' stance (:func:`gait_nodes.thesis.thesis_robot`: ground 0.7 m
below the body), with the whole inproc node graph at each joint velocity limit and prints what
each walk's bag says (thesis IV.C, Fig. 21; :mod:`gait_nodes.walked_crossover`): net speed of
the steady cycles, step period, ZMP samples outside the support polygon, joints over the limit,
and which gait walked fastest. Every figure is walked, none modelled; about 5 minutes on 2
cores (``--quick``: 1 and 2.5 rad/s, shorter walks, about a minute).

``python -m gait_nodes.swing_table ik-check --robot robosimian`` counts the limb IK's solutions
at every target of the thesis' swing workspace (by default the fine table grid on the two swing
planes and between them: x 0.2-0.8 m in 31, y -0.65 to -0.4 m in 14, z -0.7 to -0.6 m in 3, yaw
+-0.45 rad in 11, front-right foot, 14,322 targets), how many have 10, 8, 6, ... and where a
family holds more than one, and checks 40 random targets of it against an independent multistart
solver (:mod:`gait_nodes.robot.ik_check`); exit status 1 if they disagree.

Exit status: 0 on success, 2 on bad input (one line on stderr), 1 when ik-check finds the
solvers disagree.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from gait_nodes.cli import ArgumentParser, fail
from gait_nodes.errors import ArgumentError, GaitNodesError

PROG = 'python -m gait_nodes.swing_table'


def _add_table_options(parser: argparse.ArgumentParser, single: bool) -> None:
    parser.add_argument('--robot', default='robosimian', help='robot name or YAML path')
    if single:
        parser.add_argument('--family', type=int, default=2,
                            help='IK family 0..7 (thesis k-th family = k - 1; default 2)')
        parser.add_argument('--step-height-m', type=float, default=0.1,
                            help='swing height above the ground [m] (default 0.1)')
        parser.add_argument('--joint-vel-limit', type=float, default=None,
                            help='joint velocity limit [rad/s] (default: the robot YAML\'s)')
    parser.add_argument('--x-range', type=float, nargs=3, metavar=('MIN', 'MAX', 'COUNT'),
                        default=None, help='x axis of the grid [m] (front-right foot, base '
                        'frame)')
    parser.add_argument('--y-range', type=float, nargs=3, metavar=('MIN', 'MAX', 'COUNT'),
                        default=None, help='y axis of the grid [m]')
    parser.add_argument('--z-levels', type=int, default=None,
                        help='z levels from the swing plane up (default 3)')
    parser.add_argument('--z-spacing-m', type=float, default=None,
                        help='spacing of the z levels [m] (default 0.05)')
    parser.add_argument('--yaw-range', type=float, nargs=3, metavar=('MIN', 'MAX', 'COUNT'),
                        default=None, help='yaw axis of the grid [rad]')
    parser.add_argument('--radii-m', type=float, nargs='+', default=None,
                        help='action sphere radii [m] (default 0.03 0.06 0.12)')
    parser.add_argument('--azimuths', type=int, default=None,
                        help='azimuths per sphere (default 8)')
    parser.add_argument('--elevations-rad', type=float, nargs='+', default=None,
                        help='action elevations [rad] (default -0.5 0 0.5)')
    parser.add_argument('--yaw-steps-rad', type=float, nargs='+', default=None,
                        help='action yaw changes [rad] (default -0.15 0 0.15)')
    parser.add_argument('--quiet', action='store_true', help='no progress bars')


def _grid_and_actions(options, base=None, base_actions=None):
    from dataclasses import replace

    from gait_nodes.swing.grid import SwingActions
    from gait_nodes.swing.value_iteration import GridSpec

    spec = base or GridSpec()
    changes = {}
    if options.z_levels is not None or options.z_spacing_m is not None:
        changes['z_planes_m'] = None  # levels from the swing plane up, not fixed planes
    for name, field in (('x_range', 'x_range_m'), ('y_range', 'y_range_m'),
                        ('yaw_range', 'yaw_range_rad')):
        value = getattr(options, name)
        if value is not None:
            changes[field] = (value[0], value[1], value[2])
    if options.z_levels is not None:
        changes['z_levels'] = options.z_levels
    if options.z_spacing_m is not None:
        changes['z_spacing_m'] = options.z_spacing_m
    spec = replace(spec, **changes)
    defaults = base_actions or SwingActions()
    actions = SwingActions(
        tuple(options.radii_m or defaults.radii_m),
        options.azimuths if options.azimuths is not None else defaults.azimuth_count,
        tuple(options.elevations_rad or defaults.elevations_rad),
        tuple(options.yaw_steps_rad or defaults.yaw_steps_rad))
    return spec, actions


def _build(options) -> int:
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.swing.value_iteration import build_table

    robot = load_robot_model(options.robot)
    limit = options.joint_vel_limit or robot.description.joint_velocity_limit_rad_s
    spec, actions = _grid_and_actions(options)
    goal = None
    if options.goal is not None:
        goal = np.array(options.goal, dtype=float)
    table, report = build_table(robot, options.family, options.step_height_m, limit, spec,
                                actions, goal, progress=not options.quiet)
    path = table.save(options.out)
    print(f'{path}: {report.states} states x {report.actions} actions, {report.iterations} '
          f'sweeps to a change of {report.max_change_s:.2e} s; costs {report.cost_seconds:.2f} '
          f's, iteration {report.iteration_seconds:.2f} s '
          f'({report.state_actions_per_second:.3g} state-actions/s)')
    print(f'goal {np.round(table.goal, 4).tolist()}, lowering {table.lower_s:.3f} s, '
          f'{100 * table.feasible_fraction():.1f} % of the states reach the goal, family '
          f'{table.family}, {table.joint_velocity_limit_rad_s:g} rad/s')
    return 0


def _sweep(options) -> int:
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.swing.policy import SwingPolicy
    from gait_nodes.swing.sweep import (
        FT_PER_MIN,
        centred_goal_xs,
        perturbation_test,
        sweep_tables,
    )
    from gait_nodes.swing.value_iteration import GridSpec, thesis_actions, thesis_goal
    from gait_nodes.thesis import THESIS, thesis_robot

    # The thesis' sweep on the thesis' stance, as python -m gait_nodes.thesis sweeps it: one
    # answer for one robot, and its cached one-step costs.
    robot = thesis_robot(load_robot_model(options.robot))
    limit = options.joint_vel_limit or robot.description.joint_velocity_limit_rad_s
    spec, actions = _grid_and_actions(options, GridSpec.thesis(), thesis_actions())
    low, high, count = spec.x_range_m
    centre = 0.5 * (low + high)
    goal_xs = options.goal_x or centred_goal_xs(np.linspace(low, high, int(count)), centre)

    def log(message):
        if not options.quiet:
            print(message, file=sys.stderr, flush=True)

    sweep = sweep_tables(robot, options.families, options.step_heights_m, spec, actions,
                         [thesis_goal(x) for x in goal_xs], limit, log)
    for family, goal_x, reason in sweep.skipped:
        print(f'family {family}, goal x {goal_x:g} m: skipped: {reason}', file=sys.stderr)
    results = []
    for family in options.families:
        for height in options.step_heights_m:
            try:
                anywhere = sweep.anywhere(family, height)
            except GaitNodesError:
                continue
            centred = sweep.centred(family, height, centre)
            results.append((family, height, centred, anywhere))
            for label, curve in ((f'swings centred at x {centre:.2f} m', centred),
                                 ('best over every goal', anywhere)):
                print(f'family {family} (thesis {family + 1}), step height {height:g} m, '
                      f'{label}: {_optimum_line(curve)}')
            if options.perturb:
                best = centred if len(centred.steps_m) else anywhere
                policy = SwingPolicy(sweep.owner(family, height, best), robot)
                path = policy.path_from(best.starts[best.best])
                for result in perturbation_test(policy, path, options.trials,
                                                options.amplitude_m):
                    print(f'  perturbed in {result.mode:>3}: mean speed lost '
                          f'{result.mean_loss_m_s * FT_PER_MIN:+.4f} ft/min, '
                          f'{100 * result.slower_fraction:.0f} % of '
                          f'{len(result.speeds_m_s)} copies slower')
    if not results:
        raise GaitNodesError('no table could be built for the families and step heights given')
    # As the thesis' Fig. 19: the centred swings (any goal when none is centred).
    index = 2 if any(len(r[2].steps_m) for r in results) else 3
    family, height, curve = max(
        ((r[0], r[1], r[index]) for r in results if len(r[index].steps_m)),
        key=lambda r: r[2].speeds_m_s[r[2].best])
    which = f'centred at x {centre:.2f} m' if index == 2 else 'any goal'
    print(f'optimal overall ({which}): family {family}, step height {height:g} m, '
          f'{_optimum_line(curve)} (thesis: {THESIS["fig19_overall"]}, for RoboSimian)')
    if options.plot:
        _plot_sweep(results, options.plot, limit, centre)
        print(f'plot: {options.plot}')
    return 0


def _optimum_line(curve) -> str:
    from gait_nodes.swing.sweep import describe_optimum

    swing = f', swing {curve.swing_s[curve.best]:.3f} s' if len(curve.steps_m) else ''
    return f'optimal step {describe_optimum(curve)}{swing}'


def _plot_sweep(results, path, limit, centre) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from gait_nodes.swing.sweep import FT_PER_MIN
    from gait_nodes.thesis import THESIS_NUMBERS

    def feet_per_min(curve):
        return np.where(curve.speeds_m_s > 0, curve.speeds_m_s * FT_PER_MIN, np.nan)

    figure, axes = plt.subplots(figsize=(8, 5))
    for family, height, centred, anywhere in results:
        line, = axes.plot(centred.steps_m, feet_per_min(centred), marker='o', ms=3,
                          label=f'family {family} (thesis {family + 1}), {height:g} m')
        axes.plot(anywhere.steps_m, feet_per_min(anywhere), ':', color=line.get_color(),
                  lw=1)
        if len(centred.steps_m):
            k = centred.best
            axes.plot(centred.steps_m[k], centred.speeds_m_s[k] * FT_PER_MIN, marker='*',
                      ms=12, color=line.get_color())
    axes.plot(THESIS_NUMBERS['overall_step_m'], THESIS_NUMBERS['overall_ft_min'], 'X', ms=11,
              color='k', label='thesis: optimum overall (family 3, 0.06 m)')
    axes.set_xlabel('step size [m]')
    axes.set_ylabel('gait speed [ft/min] (thesis eq. (2))')
    axes.set_title(f'Step size vs. gait speed at {limit:g} rad/s (solid: centred at x '
                   f'{centre:g} m; dotted: any goal)')
    axes.set_ylim(bottom=0)
    axes.grid(True, alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _crossover(options) -> int:
    import time

    from gait_nodes import walked_crossover as walked

    limits = options.joint_vel_limits or (walked.QUICK_LIMITS_RAD_S if options.quick
                                          else walked.LIMITS_RAD_S)
    duration = options.duration_at_1_rad_s or (walked.QUICK_DURATION_AT_1_RAD_S if options.quick
                                                else walked.DURATION_AT_1_RAD_S)
    settings = {**walked.WALKED_WITH, 'swing': options.swing,
                'step_height_m': options.step_height_m}
    for value, name in [(v, '--joint-vel-limits') for v in limits] + [
            (duration, '--duration-at-1-rad-s'), (options.step_height_m, '--step-height-m')]:
        if not (np.isfinite(value) and value > 0):
            raise ArgumentError(f'{name} must be > 0, got {value:g}')

    def log(message: str) -> None:
        if not options.quiet:
            print(f'{PROG}: {message}', file=sys.stderr, flush=True)

    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.thesis import thesis_robot

    started = time.perf_counter()
    # The thesis' experiment (Fig. 21) on the thesis' stance, as python -m gait_nodes.thesis
    # walks it: one answer for one robot.
    robot = thesis_robot(load_robot_model(options.robot))
    rows = walked.walked_crossover(limits, str(robot.description.path), options.gaits,
                                   duration, options.keep_bags, settings, log)
    print(walked.format_table(rows, settings, duration))
    if options.keep_bags:
        print(f'\nbags: {options.keep_bags}/<gait>_w<limit> (robot copies in '
              f'{options.keep_bags}/robots)')
    print(f'walked in {time.perf_counter() - started:.0f} s')
    return 0


def _ik_check(options) -> int:
    import time

    from gait_nodes.errors import ArgumentError, ConfigError
    from gait_nodes.robot.ik_check import (
        LimbChain,
        compare_solution_sets,
        multistart_limb_ik,
    )
    from gait_nodes.robot.limb_ik import SINGULAR_SINE
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.robot.whole_body_ik import robosimian_limb_ik

    axes = {}
    for name in ('x_range', 'y_range', 'z_range', 'yaw_range'):
        low, high, count = getattr(options, name)
        if not (low <= high and count >= 1 and float(count).is_integer()):
            raise ArgumentError(f'--{name.replace("_", "-")}: MIN <= MAX and an integer COUNT >= '
                                f'1 expected, got {low:g} {high:g} {count:g}')
        axes[name] = (low, high, int(count))
    if options.check_targets < 0 or options.starts < 1:
        raise ArgumentError(f'--check-targets must be >= 0 and --starts >= 1, got '
                            f'{options.check_targets} and {options.starts}')
    robot = load_robot_model(options.robot)
    if robot.description.extra.get('limb_ik') is None:
        raise ConfigError(f'robot {robot.name!r} has no closed-form limb IK (extra.limb_ik in '
                          f'{robot.description.path})')
    ik = robosimian_limb_ik(robot)
    grid = np.meshgrid(*(np.linspace(*axes[name]) for name in axes), indexing='ij')
    targets, yaws = ik.mirror_targets(np.stack([g.ravel() for g in grid[:3]], axis=1),
                                      grid[3].ravel(), options.foot)
    start = time.perf_counter()
    every = ik.solutions(targets, yaws, options.foot)
    seconds = time.perf_counter() - start
    ranges = ', '.join(f'{name.split("_")[0]} {low:g}..{high:g} {unit} ({count})'
                       for (name, (low, high, count)), unit
                       in zip(axes.items(), ('m', 'm', 'm', 'rad'), strict=True))
    print(f'{robot.name} {options.foot} limb IK over the front-right workspace {ranges}: '
          f'{len(targets)} targets solved in {seconds:.2f} s')
    values, counts = np.unique(every.count, return_counts=True)
    print('solutions per target: ' + ', '.join(
        f'{value}: {count} ({100 * count / len(targets):.1f} %)'
        for value, count in zip(values[::-1], counts[::-1], strict=True)))
    family_counts = every.family_counts()
    crowded = family_counts >= 2
    print(f'a family holds more than one solution at {int(crowded.any(axis=1).sum())} targets'
          + ''.join(f'; family {family}: {int(crowded[:, family].sum())}'
                    for family in range(8) if crowded[:, family].any()))
    if not options.check_targets:
        return 0
    rng = np.random.default_rng(options.seed)
    low, high = (np.array([axes[name][k] for name in axes]) for k in (0, 1))
    samples = rng.uniform(low, high, (options.check_targets, 4))
    check_targets, check_yaws = ik.mirror_targets(samples[:, :3], samples[:, 3], options.foot)
    ours = ik.solutions(check_targets, check_yaws, options.foot)
    theirs = multistart_limb_ik(LimbChain.of(robot, options.foot), check_targets, check_yaws,
                                options.starts, options.seed)
    # limb_ik returns no singular solution; the multistart solver's are set aside.
    singular = [np.minimum(np.abs(np.sin(q[:, 1])), np.abs(np.sin(q[:, 4]))) <= SINGULAR_SINE
                for q in theirs]
    theirs = [q[~aside] for q, aside in zip(theirs, singular, strict=True)]
    agreement = compare_solution_sets(
        [ours.joint_angles[k, :ours.count[k]] for k in range(len(check_targets))], theirs)
    print(f'multistart check ({agreement.targets} random targets of the workspace, '
          f'{options.starts} starts each, seed {options.seed}): {agreement.agreeing} of '
          f'{agreement.targets} agree; {int(ours.count.sum())} solutions, '
          f'{agreement.missed_by_first} found only by the multistart solver, '
          f'{agreement.missed_by_second} only by limb_ik ({sum(int(a.sum()) for a in singular)} '
          f'singular ones of the multistart solver, |sin q2| or |sin q5| <= {SINGULAR_SINE:g}, '
          f'set aside)')
    return 0 if agreement.agreeing == agreement.targets else 1


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.swing_table build|sweep|crossover|ik-check ...``."""
    parser = ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0], epilog=None)
    commands = parser.add_subparsers(dest='command', required=True)
    build = commands.add_parser('build', help='run the value iteration, write a table file')
    _add_table_options(build, single=True)
    build.add_argument('--goal', type=float, nargs=4, metavar=('X', 'Y', 'Z', 'YAW'),
                       default=None, help='goal of the front-right foot in the base frame '
                       '(default: half a 0.3 m stride ahead of the nominal foot, on the swing '
                       'plane)')
    build.add_argument('--out', required=True, help='table file to write (.npz)')
    sweep = commands.add_parser('sweep', help='step size against crawl speed (thesis eq. (2))')
    _add_table_options(sweep, single=False)
    sweep.add_argument('--families', type=int, nargs='+', default=[2, 7],
                       help='IK families (default 2 7: the thesis\' 3rd and 8th)')
    sweep.add_argument('--step-heights-m', type=float, nargs='+', default=[0.06, 0.1],
                       help='step heights [m] (default 0.06 0.1)')
    sweep.add_argument('--joint-vel-limit', type=float, default=None,
                       help='joint velocity limit [rad/s] (default: the robot YAML\'s)')
    sweep.add_argument('--goal-x', type=float, nargs='+', default=None,
                       help='goal x positions, one table each [m] (default: every x node ahead '
                       'of the middle of the x range whose mirror about it is a node)')
    sweep.add_argument('--plot', default=None, help='PNG file of the sweep')
    sweep.add_argument('--perturb', action='store_true',
                       help='perturbation test of the optimal path (thesis IV.B.7)')
    sweep.add_argument('--trials', type=int, default=50, help='perturbed copies per axis')
    sweep.add_argument('--amplitude-m', type=float, default=0.02,
                       help='largest perturbation of a waypoint [m]')
    crossover = commands.add_parser('crossover', help='each gait walked at joint velocity '
                                    'limits, read from its bag (thesis IV.C, Fig. 21)')
    crossover.add_argument('--robot', default='robosimian', help='robot name or YAML path')
    crossover.add_argument('--joint-vel-limits', type=float, nargs='+', default=None,
                           help='joint velocity limits [rad/s] (default 0.5 1 1.5 2 2.5 3 4; '
                           '--quick: 1 2.5)')
    crossover.add_argument('--gaits', nargs='+', default=None,
                           help="gaits to walk (default: the robot's)")
    crossover.add_argument('--quick', action='store_true',
                           help='two limits and shorter walks (about a minute)')
    crossover.add_argument('--duration-at-1-rad-s', type=float, default=None,
                           help='walk duration at 1 rad/s [s], divided by the limit at others '
                           '(default 70; --quick: 45)')
    crossover.add_argument('--swing', choices=['value_table', 'polynomial'],
                           default='value_table', help='swing of every gait (default '
                           'value_table)')
    crossover.add_argument('--step-height-m', type=float, default=0.06,
                           help="swing lift [m] (default 0.06, the thesis' best)")
    crossover.add_argument('--keep-bags', metavar='DIR', default=None,
                           help='keep the bags and the robot copies in DIR')
    crossover.add_argument('--quiet', action='store_true', help='no progress lines')
    ik_check = commands.add_parser('ik-check', help='limb IK solutions per target over the '
                                   'swing workspace, checked by a multistart solver')
    ik_check.add_argument('--robot', default='robosimian', help='robot name or YAML path')
    ik_check.add_argument('--foot', default='front_right',
                          help='limb; the workspace is the front-right one, mirrored onto it')
    for name, default, unit in (('x', (0.2, 0.8, 31), 'm'), ('y', (-0.65, -0.4, 14), 'm'),
                                ('z', (-0.7, -0.6, 3), 'm'), ('yaw', (-0.45, 0.45, 11), 'rad')):
        ik_check.add_argument(f'--{name}-range', type=float, nargs=3,
                              metavar=('MIN', 'MAX', 'COUNT'), default=default,
                              help=f'{name} axis of the workspace [{unit}] (default '
                              f'{" ".join(f"{v:g}" for v in default)})')
    ik_check.add_argument('--check-targets', type=int, default=40,
                          help='random targets checked by the multistart solver (0: none)')
    ik_check.add_argument('--starts', type=int, default=400,
                          help='multistart starts per target (default 400)')
    ik_check.add_argument('--seed', type=int, default=0, help='seed of targets and starts')
    options = parser.parse_args(args)
    try:
        return {'build': _build, 'sweep': _sweep, 'crossover': _crossover,
                'ik-check': _ik_check}[options.command](options)
    except GaitNodesError as exc:
        return fail(PROG, exc)


if __name__ == '__main__':
    sys.exit(main())
