"""Reproduce the thesis' results with our models: one table beside the thesis' numbers, PNGs.

``python -m gait_nodes.thesis [--out DIR] [--quick]`` runs, on the shipped RoboSimian:

- Fig. 8: largest ZMP error of the simplified models against step size: the full model's ZMP
  (:mod:`gait_nodes.robot.dynamics`) when the body follows the cart-table preview COM, and after
  one multi-mass correction (:mod:`gait_nodes.com.multimass`, our stand-in for the nine-link
  model), ZMP crawl (:mod:`gait_nodes.swing.crossover`'s plan), steady cycles only;
- Fig. 10: largest stance-limb joint speed of that ZMP crawl against step size;
- Fig. 12: joint travel per metre of a small move along the swing's line (the thesis' reason
  for the drop of Fig. 14: the joints move more close to the body);
- Figs. 14, 17-19: crawl speed (thesis eq. (2)) against step size from value tables on the
  thesis' setting (:meth:`GridSpec.thesis`), IK families 2 and 7 (the thesis' 3rd and 8th),
  step heights 0.1 and 0.06 m;
- Figs. 15-16: the optimal swing's top view against a straight swing, and the share of the
  lift and lowering in the swing time;
- IV.B.7 (Fig. 20): random perturbations of the optimal swing's waypoints;
- Fig. 21: the ZMP crawl against the value-table crawl over joint velocity limits.

The step size of a swing is its x travel; the thesis sets the goal's x "to be different" for each
step (IV.B.3) without saying where: here every swing is centred on the middle of the thesis' x
range, 0.5 m (start ``0.5 - s/2``, goal ``0.5 + s/2``: every step up to 0.6 m fits), and the best
over every goal of the grid is printed too. The ZMP gaits plan with the thesis' step range as
the robot's reach (:func:`thesis_description`). The thesis gives no step period for its ZMP
gait: Figs. 8 and 10 use :data:`ZMP_STEP_PERIODS_S` (both drawn, the first printed). The
one-step costs of the value iteration are cached in ``$XDG_CACHE_HOME/gait_nodes/thesis/`` (a
minute per family on the default grid).

Exit status: 0 on success, 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import hashlib
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gait_nodes.cli import ArgumentParser, fail
from gait_nodes.errors import GaitNodesError
from gait_nodes.swing.value_iteration import THESIS_STEP_HEIGHTS_M

PROG = 'python -m gait_nodes.thesis'

#: Step periods [s] of the ZMP crawl of Figs. 8 and 10 (the thesis gives none).
ZMP_STEP_PERIODS_S = (1.0, 2.0)
#: The thesis' IK families compared (its 3rd and 8th; ours count from 0).
FAMILIES = (2, 7)
#: The longest step the thesis' x range (0.2-0.8 m) holds [m].
THESIS_LONGEST_STEP_M = 0.6
#: Strides of the ZMP crawl of Fig. 21 [m] (the thesis' range; the crossover module's periods).
ZMP_CROSSOVER_STEPS_M = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5)
#: The foot's radius: the thesis' bound on a useful ZMP error (IV.A.1) [m].
FOOT_RADIUS_M = 0.055

#: The thesis' numbers (000, section IV), by row key.
THESIS = {
    'fig8_useful_step': 'about 0.4 m (error < foot radius 0.055 m)',
    'fig10_speed_at_0.2': 'about 1 rad/s',
    'fig10_largest_step': 'slightly below 0.2 m',
    'fig12_travel': 'more joint travel close to the body',
    'fig14_optimum': '0.34 m (interior)',
    'fig15_outward': 'curves outward in y',
    'fig16_straight': 'straight is slower',
    'fig16_lift_share': '38.76 %',
    'fig17_families': 'family 3 faster overall',
    'fig18_heights': '0.06 m faster',
    'fig19_overall': 'family 3, 0.06 m, 0.34 m, 8.542 ft/min',
    'fig5_families_differ': 'all joints differ',
    'perturb_x': '-0.50 ft/min, all slower',
    'perturb_y': '-0.15 ft/min, all slower',
    'perturb_z': '-0.18 ft/min, all slower',
    'perturb_xyz': '-0.44 ft/min, all slower',
    'fig21_zmp_feasible': 'from 1.9 rad/s',
    'fig21_zmp_faster': 'above about 2.4 rad/s',
}


@dataclass(frozen=True)
class Settings:
    """What one run computes (defaults: the full run; :meth:`quick`: a coarse one).

    Attributes:
        x_count: Grid nodes along x (0.2-0.8 m).
        y_count: Grid nodes along y (-0.65 to -0.4 m).
        yaw_count: Grid nodes along yaw (+-0.45 rad).
        radii_m: Action sphere radii [m].
        azimuth_count: Azimuths per sphere.
        zmp_steps_m: Step sizes of Figs. 8 and 10 [m].
        limits_rad_s: Joint velocity limits of Fig. 21 [rad/s].
        trials: Perturbed copies per axis (IV.B.7).
        amplitude_m: Largest perturbation of a waypoint [m].
        step_heights_m: Step heights [m] (the thesis' 0.1 and 0.06 m).
    """

    x_count: int = 31
    y_count: int = 11
    yaw_count: int = 7
    radii_m: tuple[float, ...] = (0.025, 0.05, 0.1, 0.2)
    azimuth_count: int = 16
    zmp_steps_m: tuple[float, ...] = (0.04, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5)
    limits_rad_s: tuple[float, ...] = tuple(np.round(np.arange(1.0, 3.01, 0.1), 2))
    trials: int = 40
    amplitude_m: float = 0.02
    step_heights_m: tuple[float, ...] = THESIS_STEP_HEIGHTS_M

    @classmethod
    def quick(cls) -> Settings:
        """A coarse run (about a minute): x every 0.04 m, y every 0.05 m, 5 yaws."""
        return cls(x_count=16, y_count=6, yaw_count=5, radii_m=(0.04, 0.08, 0.16),
                   azimuth_count=8, zmp_steps_m=(0.1, 0.2, 0.3, 0.4),
                   limits_rad_s=(1.0, 1.5, 2.0, 2.5, 3.0), trials=10)

    def grid_spec(self):
        """The thesis' grid at this resolution."""
        from gait_nodes.swing.value_iteration import GridSpec

        return GridSpec.thesis(self.x_count, self.y_count, self.yaw_count)

    def actions(self):
        """The thesis' kind of action set at this resolution."""
        from dataclasses import replace

        from gait_nodes.swing.value_iteration import thesis_actions

        return replace(thesis_actions(), radii_m=self.radii_m,
                       azimuth_count=self.azimuth_count)


# -- the ZMP gait (thesis IV.A) ----------------------------------------------------------------


@dataclass(frozen=True)
class ZmpErrors:
    """Largest |reference - full-model ZMP| over the steady cycles of a ZMP crawl (Fig. 8).

    Attributes:
        cart_table_m: Body on the cart-table preview COM [m] (inf: the plan is out of reach).
        corrected_m: After one multi-mass correction of the body [m].
    """

    cart_table_m: float
    corrected_m: float


def thesis_description(robot):
    """The robot's description with the thesis' step range as its reach.

    The thesis studies steps up to 0.6 m (its x range); the walker's ``reach`` in the robot
    YAML is what the footstep planner allows, not what the limbs can do, so the ZMP gaits of
    Figs. 8, 10 and 21 plan with a reach of :data:`THESIS_LONGEST_STEP_M` and meet the limbs'
    real limits in the IK (an unreachable walk is infeasible there).
    """
    from dataclasses import replace

    description = robot.description
    reach = replace(description.reach, max_step_length_m=max(
        THESIS_LONGEST_STEP_M, description.reach.max_step_length_m))
    return replace(description, reach=reach)


def zmp_crawl_plan(robot, step_m: float, step_period_s: float, cycles: int):
    """(planner, params) of a straight ZMP crawl at ``step_m`` per swing."""
    from gait_nodes.planning.footsteps import Twist2D, plan_walk
    from gait_nodes.planning.gait_params import GaitParameters
    from gait_nodes.swing.crossover import DUTY_FACTORS

    description = thesis_description(robot)
    params = GaitParameters.for_robot(
        description, gait='crawl', step_length_m=step_m, step_period_s=step_period_s,
        duty_factor=DUTY_FACTORS['crawl'], max_vx_m_s=10.0)
    speed = step_m / params.cycle_s
    planner = plan_walk(description, params, [(0.0, Twist2D(speed, 0.0, 0.0))],
                        (cycles + 1) * params.cycle_s)
    return planner, params


def zmp_model_errors(robot, step_m: float, step_period_s: float, dt_s: float = 0.02,
                     cycles: int = 3) -> ZmpErrors:
    """Fig. 8 at one step size: the simplified models' ZMP error on the full model.

    The thesis plans the COM on the cart table, corrects the body on its nine-link model and
    measures the full model's ZMP against the reference; we measure it with the body on the
    cart-table COM and after one multi-mass correction on the full model (Kurazume), over the
    cycles after the first (the start from rest excluded).
    """
    from gait_nodes.com.multibody import robot_multibody_zmp
    from gait_nodes.com.multimass import correct_body_trajectory
    from gait_nodes.com.preview import PreviewSettings, preview_batch

    try:
        planner, params = zmp_crawl_plan(robot, step_m, step_period_s, cycles)
    except GaitNodesError:
        return ZmpErrors(float('inf'), float('inf'))
    plan = planner.footstep_plan(0.0)
    times = np.arange(0.0, cycles * params.cycle_s, dt_s)
    reference = planner.zmp(times)
    com_height_m = robot.description.com_height_m
    com = preview_batch(reference, PreviewSettings(com_height_m=com_height_m,
                                                   dt_s=dt_s)).positions_in_world
    yaws = np.array([float(np.mean(plan.yaws_rad[plan.index_at(t)])) for t in times])
    model = robot_multibody_zmp(robot, plan, times, dt_s, params.body_height_m, yaws,
                                params.step_height_m)
    steady = times >= params.cycle_s

    def worst(zmp):
        error = float(np.linalg.norm(zmp[steady] - reference[steady], axis=1).max())
        return error if np.isfinite(error) else float('inf')

    cart_table = worst(model(com))
    try:
        corrected = correct_body_trajectory(com, reference, model, com_height_m, dt_s,
                                            max_iterations=1, tolerance_m=0.0)
    except GaitNodesError:
        # The full model leaves the limbs' reach on the way (a NaN ZMP): no such walk.
        return ZmpErrors(cart_table, float('inf'))
    return ZmpErrors(cart_table, worst(corrected.zmp_in_world))


# -- the value tables (thesis III.C, IV.B) -----------------------------------------------------


def cached_costs(robot, family: int, limit_rad_s: float, grid, displacements, log):
    """One-step costs of :func:`one_step_costs`, from the cache when computed before."""
    from gait_nodes.swing.cache import cache_dir, robot_digest
    from gait_nodes.swing.kinematics import LimbTiming
    from gait_nodes.swing.value_iteration import one_step_costs

    key = hashlib.sha256(robot_digest(robot).encode())
    for array in (*grid.axes, displacements, np.array([family, limit_rad_s])):
        key.update(np.ascontiguousarray(array, dtype=float).tobytes())
    path = cache_dir() / 'thesis' / f'costs_{robot.name}_f{family}_{key.hexdigest()[:16]}.npz'
    if path.is_file():
        with np.load(path, allow_pickle=False) as data:
            return data['costs'], data['feasible']
    log(f'one-step costs of family {family}: {grid.size} states x {len(displacements)} '
        f'actions (cached in {path.parent})')
    costs, feasible = one_step_costs(LimbTiming(robot, family, limit_rad_s), grid,
                                     displacements)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_suffix('.part.npz')
    np.savez(partial, costs=costs, feasible=feasible)
    partial.replace(path)
    return costs, feasible


@dataclass
class Tables:
    """Value tables by ``(family, step height, goal x)`` and their speed curves."""

    tables: dict = field(default_factory=dict)
    curves: dict = field(default_factory=dict)
    skipped: list = field(default_factory=list)


def build_tables(robot, settings: Settings, centre_x_m: float, log) -> Tables:
    """One table per family and goal, with the lift and lowering of every step height.

    The goals are the grid's x nodes ahead of ``centre_x_m`` whose mirror about it is a node
    too (each gives one centred step); the one-step costs are shared by every goal.
    """
    from gait_nodes.swing.sweep import speed_curve
    from gait_nodes.swing.value_iteration import (
        THESIS_GOAL_Z_M,
        build_table,
        table_grid,
        thesis_goal,
        with_step_height,
    )

    spec, actions = settings.grid_spec(), settings.actions()
    limit = robot.description.joint_velocity_limit_rad_s
    first = settings.step_heights_m[0]
    grounds = {h: THESIS_GOAL_Z_M - h for h in settings.step_heights_m}
    x_axis = table_grid(robot, first, spec, thesis_goal(0.8), grounds[first]).x_m
    goal_xs = [x for x in x_axis if x > centre_x_m + 1e-9
               and np.min(np.abs(x_axis - (2 * centre_x_m - x))) < 1e-9]
    result = Tables()
    for family in FAMILIES:
        grid = table_grid(robot, first, spec, thesis_goal(goal_xs[0]), grounds[first])
        costs = cached_costs(robot, family, limit, grid, actions.displacements(), log)
        started = time.perf_counter()
        for goal_x in goal_xs:
            try:
                table, _ = build_table(robot, family, first, limit, spec, actions,
                                       thesis_goal(goal_x), ground_z_m=grounds[first],
                                       costs=costs)
            except GaitNodesError as exc:
                result.skipped.append((family, goal_x, str(exc)))
                continue
            for height in settings.step_heights_m:
                try:
                    tab = with_step_height(table, robot, height, grounds[height])
                except GaitNodesError as exc:
                    result.skipped.append((family, goal_x, str(exc)))
                    continue
                result.tables[family, height, goal_x] = tab
                result.curves[family, height, goal_x] = speed_curve(tab)
        log(f'family {family}: {len(goal_xs)} goals in {time.perf_counter() - started:.1f} s')
    return result


def joint_travel_along_x(robot, family: int, step_m: float = 0.01
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Thesis Figs. 11-12: largest joint travel per metre of a small move along x [rad/m].

    At y -0.5 m, z -0.6 m (the swing's line), yaw 0, x from 0.2 to 0.8 m every 0.01 m; NaN
    where the family does not reach either end.
    """
    from gait_nodes.swing.kinematics import LimbTiming
    from gait_nodes.swing.value_iteration import THESIS_GOAL_Y_M, THESIS_GOAL_Z_M

    timing = LimbTiming(robot, family, 1.0)
    x = np.round(np.arange(0.2, 0.8 + 1e-9, 0.01), 6)
    states = np.column_stack([x, np.full_like(x, THESIS_GOAL_Y_M),
                              np.full_like(x, THESIS_GOAL_Z_M), np.zeros_like(x)])
    q, ok = timing.joints(states)
    moved = states + np.array([step_m, 0.0, 0.0, 0.0])
    q_next, ok_next = timing.joints(moved)
    travel = np.abs(q_next - q).max(axis=1) / step_m
    return x, np.where(ok & ok_next, travel, np.nan)


def straight_swing(start: np.ndarray, goal: np.ndarray, spacing_m: float = 0.01) -> np.ndarray:
    """(W, 4) waypoints on the straight line from ``start`` to ``goal``, yaw interpolated."""
    count = max(int(np.ceil(np.linalg.norm(goal[:3] - start[:3]) / spacing_m)), 1)
    s = np.linspace(0.0, 1.0, count + 1)[:, None]
    return start + s * (goal - start)


# -- the whole run -----------------------------------------------------------------------------


@dataclass
class Results:
    """Everything the table and the figures show."""

    settings: Settings
    zmp_errors: dict = field(default_factory=dict)       # (period, step) -> ZmpErrors
    zmp_joint_speeds: dict = field(default_factory=dict)  # (period, step) -> rad/s
    centre_x_m: float = 0.0
    tables: Tables | None = None
    centred: dict = field(default_factory=dict)          # (family, height) -> SpeedCurve
    anywhere: dict = field(default_factory=dict)         # (family, height) -> SpeedCurve
    optimal: dict = field(default_factory=dict)          # Figs. 15-16
    perturbations: list = field(default_factory=list)
    perturbations_of: tuple = ()                         # (family, height) of the path
    families_q: tuple | None = None
    joint_travel: dict = field(default_factory=dict)     # family -> (x, rad/m along x)
    # (limit, value-table crawl, ZMP crawl limited by its stance limbs, by every limb) [m/s]
    crossover: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)


def run(robot, settings: Settings, log) -> Results:
    """Compute every figure's data (see the module docstring)."""
    from gait_nodes.swing.crossover import zmp_gait_joint_speed, zmp_gait_table_for
    from gait_nodes.swing.policy import SwingPolicy
    from gait_nodes.swing.sweep import centred, envelope, perturbation_test

    results = Results(settings)
    started = time.perf_counter()
    for period in ZMP_STEP_PERIODS_S:
        for step in settings.zmp_steps_m:
            results.zmp_errors[period, step] = zmp_model_errors(robot, step, period)
            results.zmp_joint_speeds[period, step] = zmp_gait_joint_speed(
                robot, 'crawl', step, period, FAMILIES[0], stance_only=True,
                description=thesis_description(robot))
    results.seconds['zmp'] = time.perf_counter() - started
    log(f'Figs. 8 and 10 in {results.seconds["zmp"]:.1f} s')

    started = time.perf_counter()
    results.centre_x_m = float(np.mean(settings.grid_spec().x_range_m[:2]))
    results.tables = tables = build_tables(robot, settings, results.centre_x_m, log)
    for family in FAMILIES:
        for height in settings.step_heights_m:
            curves = [c for (f, h, _), c in tables.curves.items()
                      if f == family and h == height]
            if curves:
                results.centred[family, height] = centred(curves, results.centre_x_m)
                results.anywhere[family, height] = envelope(curves)
    results.seconds['tables'] = time.perf_counter() - started

    family, height = FAMILIES[0], settings.step_heights_m[0]
    results.optimal = optimal_swing(robot, tables, results.centred[family, height],
                                    family, height)
    best_key = max(results.centred, key=lambda k: _best_speed(results.centred[k]))
    best = results.centred[best_key]
    table = owner(tables, best_key, best)
    policy = SwingPolicy(table, robot)
    path = policy.path_from(best.starts[best.best])
    results.perturbations = perturbation_test(policy, path, settings.trials,
                                              settings.amplitude_m)
    results.perturbations_of = best_key

    for family in FAMILIES:
        results.joint_travel[family] = joint_travel_along_x(robot, family)
    ik = policy.timing.ik
    point = np.array([[0.6, -0.54, -0.6]])
    results.families_q = tuple(ik.solve(point, 0.0, f)[0][0, :6] for f in FAMILIES)

    started = time.perf_counter()
    per_limit = _best_speed(best) / robot.description.joint_velocity_limit_rad_s
    stance, every = (zmp_gait_table_for(robot, 'crawl', FAMILIES[0], 0.1,
                                        ZMP_CROSSOVER_STEPS_M, stance_only=stance_only,
                                        description=thesis_description(robot))
                     for stance_only in (True, False))
    for limit in settings.limits_rad_s:
        fastest = [table.fastest(limit) for table in (stance, every)]
        results.crossover.append((float(limit), per_limit * limit,
                                  *(f[0] if f else 0.0 for f in fastest)))
    results.seconds['crossover'] = time.perf_counter() - started
    return results


def _best_speed(curve) -> float:
    return float(curve.speeds_m_s[curve.best]) if len(curve.speeds_m_s) else 0.0


def owner(tables: Tables, key, curve):
    """The table of the curve's best point (its goal: start x + step)."""
    family, height = key
    goal_x = curve.starts[curve.best, 0] + curve.steps_m[curve.best]
    for (f, h, gx), table in tables.tables.items():
        if f == family and h == height and abs(gx - goal_x) < 1e-9:
            return table
    raise GaitNodesError(f'no table with goal x {goal_x:.3f} m for family {family}, step '
                         f'height {height} m')


def optimal_swing(robot, tables: Tables, curve, family: int, height: float) -> dict:
    """Figs. 15-16: the optimal swing, a straight one between the same places, their times."""
    from gait_nodes.swing.policy import SwingPolicy

    table = owner(tables, (family, height), curve)
    policy = SwingPolicy(table, robot)
    path = policy.path_from(curve.starts[curve.best])
    swing = path.swing_states
    straight = policy.timed_path(straight_swing(swing[0], swing[-1]))
    line_y = np.interp(swing[:, 0], [swing[0, 0], swing[-1, 0]], [swing[0, 1], swing[-1, 1]])
    q_path, _ = policy.timing.joints(path.states)
    q_straight, _ = policy.timing.joints(straight.states)
    return {
        'path': path, 'straight': straight, 'step_m': float(curve.steps_m[curve.best]),
        'outward_m': float(np.min(swing[:, 1] - line_y)),
        'lift_share': (path.lift_s + path.lower_s) / path.duration_s,
        'joint_travel_rad': np.abs(np.diff(q_path[:, :6], axis=0)).sum(axis=0),
        'straight_joint_travel_rad': np.abs(np.diff(q_straight[:, :6], axis=0)).sum(axis=0),
    }


# -- the printed table -------------------------------------------------------------------------


def _ft(speed_m_s: float) -> str:
    from gait_nodes.swing.sweep import FT_PER_MIN

    return f'{speed_m_s * FT_PER_MIN:.3f} ft/min'


def _metres(value: float) -> str:
    return f'{value:.3f} m' if np.isfinite(value) else 'out of reach'


def _optimum_text(curve) -> str:
    if not len(curve.steps_m) or _best_speed(curve) <= 0:
        return 'no feasible step'
    k = curve.best
    where = 'interior' if 0 < k < len(curve.steps_m) - 1 else 'at the edge of the steps'
    return f'{curve.steps_m[k]:.2f} m ({where}), {_ft(curve.speeds_m_s[k])}'


def rows(results: Results) -> list[tuple[str, str, str, str]]:
    """``(figure, quantity, ours, thesis)`` rows of the printed table."""
    from gait_nodes.swing.sweep import FT_PER_MIN

    s = results.settings
    period = ZMP_STEP_PERIODS_S[0]
    out = []
    errors = {step: results.zmp_errors[period, step] for step in s.zmp_steps_m}
    useful = [step for step, e in errors.items() if e.corrected_m < FOOT_RADIUS_M]
    step_04 = min(s.zmp_steps_m, key=lambda v: abs(v - 0.4))
    e04 = errors[step_04]
    out.append(('Fig. 8', f'max ZMP error at {step_04:g} m (T {period:g} s)',
                f'cart-table {_metres(e04.cart_table_m)}, corrected {_metres(e04.corrected_m)}',
                '-'))
    out.append(('Fig. 8', 'largest step with error < 0.055 m (corrected)',
                f'{max(useful):g} m' if useful else 'none', THESIS['fig8_useful_step']))
    speeds = {step: results.zmp_joint_speeds[period, step] for step in s.zmp_steps_m}
    step_02 = min(s.zmp_steps_m, key=lambda v: abs(v - 0.2))
    within = [step for step, w in speeds.items() if w <= 1.0]
    out.append(('Fig. 10', f'stance joint speed at {step_02:g} m (T {period:g} s)',
                f'{speeds[step_02]:.2f} rad/s', THESIS['fig10_speed_at_0.2']))
    out.append(('Fig. 10', 'largest step within 1 rad/s',
                f'{max(within):g} m' if within else 'none', THESIS['fig10_largest_step']))
    x, travel = results.joint_travel[FAMILIES[0]]
    peak = int(np.nanargmax(np.where(x < 0.6, travel, np.nan)))
    behind = np.nanmax(travel[x <= 0.3 + 1e-9])
    ahead = np.nanmedian(travel[(x >= 0.45) & (x <= 0.75)])
    out.append(('Fig. 12', f'joint travel per metre along x, family {FAMILIES[0]}, y -0.5 z '
                '-0.6', f'peak {travel[peak]:.1f} rad/m at x {x[peak]:.2f} m; <= '
                f'{behind:.1f} at x <= 0.3 m; median {ahead:.1f} at x 0.45-0.75 m',
                THESIS['fig12_travel']))
    family, height = FAMILIES[0], s.step_heights_m[0]
    out.append(('Fig. 14', f'optimal step, family {family} (thesis {family + 1}), '
                f'{height:g} m, centred', _optimum_text(results.centred[family, height]),
                THESIS['fig14_optimum']))
    out.append(('Fig. 14', 'same, best over every goal of the grid',
                _optimum_text(results.anywhere[family, height]), '-'))
    o = results.optimal
    out.append(('Fig. 15', f'optimal swing ({o["step_m"]:.2f} m): largest y outward of the '
                'straight line', f'{-o["outward_m"]:.3f} m', THESIS['fig15_outward']))
    out.append(('Fig. 16', 'swing time optimal / straight',
                f'{o["path"].duration_s:.2f} s / {o["straight"].duration_s:.2f} s',
                THESIS['fig16_straight']))
    out.append(('Fig. 16', 'lift and lowering share of the swing time',
                f'{100 * o["lift_share"]:.2f} %', THESIS['fig16_lift_share']))
    best_by_family = {f: max(_best_speed(results.centred[f, h]) for h in s.step_heights_m)
                      for f in FAMILIES}
    out.append(('Fig. 17', 'best speed family 2 / 7 (thesis 3 / 8)',
                ' / '.join(_ft(best_by_family[f]) for f in FAMILIES), THESIS['fig17_families']))
    best_by_height = {h: max(_best_speed(results.centred[f, h]) for f in FAMILIES)
                      for h in s.step_heights_m}
    out.append(('Fig. 18', 'best speed step height ' + ' / '.join(
        f'{h:g}' for h in s.step_heights_m) + ' m',
        ' / '.join(_ft(best_by_height[h]) for h in s.step_heights_m), THESIS['fig18_heights']))
    key = max(results.centred, key=lambda k: _best_speed(results.centred[k]))
    curve = results.centred[key]
    out.append(('Fig. 19', 'optimal overall', f'family {key[0]} (thesis {key[0] + 1}), '
                f'{key[1]:g} m, {_optimum_text(curve)}', THESIS['fig19_overall']))
    q2, q7 = results.families_q
    out.append(('Fig. 5', 'families 2 and 7 at (0.6, -0.54, -0.6): joints differing > 0.01 rad',
                f'{int(np.sum(np.abs(q2 - q7) > 0.01))} of 6 (largest '
                f'{np.abs(q2 - q7).max():.2f} rad)', THESIS['fig5_families_differ']))
    family, height = results.perturbations_of
    curve = results.centred[family, height]
    path_text = f'family {family}, {height:g} m, {curve.steps_m[curve.best]:.2f} m step'
    for result in results.perturbations:
        out.append(('IV.B.7', f'optimal swing ({path_text}) perturbed in {result.mode} '
                    f'(+-{s.amplitude_m:g} m, {len(result.speeds_m_s)} copies): mean change',
                    f'{-result.mean_loss_m_s * FT_PER_MIN:+.3f} ft/min, '
                    f'{100 * result.slower_fraction:.0f} % slower',
                    THESIS[f'perturb_{result.mode}']))
    for column, limbs in ((2, 'stance limbs'), (3, 'every limb')):
        feasible = [c[0] for c in results.crossover if c[column] > 0]
        faster = [c[0] for c in results.crossover if c[column] > c[1]]
        never = f'never up to {s.limits_rad_s[-1]:g} rad/s'
        out.append(('Fig. 21', f'ZMP crawl ({limbs} limited) feasible',
                    f'from {min(feasible):g} rad/s' if feasible else never,
                    THESIS['fig21_zmp_feasible']))
        out.append(('Fig. 21', f'ZMP crawl ({limbs} limited) faster than the value-table '
                    'crawl', f'from {min(faster):g} rad/s' if faster else never,
                    THESIS['fig21_zmp_faster']))
    return out


def format_table(table_rows) -> str:
    """The rows as a Markdown table."""
    lines = ['| figure | quantity | ours | thesis |', '| --- | --- | --- | --- |']
    lines += [f'| {a} | {b} | {c} | {d} |' for a, b, c, d in table_rows]
    return '\n'.join(lines)


# -- figures -----------------------------------------------------------------------------------


def write_figures(results: Results, out_dir: Path) -> list[Path]:
    """Every figure as a PNG in ``out_dir``; returns the paths."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from gait_nodes.swing.sweep import FT_PER_MIN

    out_dir.mkdir(parents=True, exist_ok=True)
    s = results.settings
    written = []

    def save(figure, name):
        figure.tight_layout()
        path = out_dir / name
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)

    def finite(values):
        values = np.asarray(values, dtype=float)
        return np.where(np.isfinite(values), values, np.nan)

    steps = np.array(s.zmp_steps_m)
    figure, axes = plt.subplots(figsize=(7, 4.5))
    for period in ZMP_STEP_PERIODS_S:
        errors = [results.zmp_errors[period, v] for v in steps]
        axes.plot(steps, finite([e.cart_table_m for e in errors]), 'o--',
                  label=f'cart-table COM, T {period:g} s')
        axes.plot(steps, finite([e.corrected_m for e in errors]), 'o-',
                  label=f'+ one multi-mass correction, T {period:g} s')
    axes.axhline(FOOT_RADIUS_M, color='k', lw=0.8, ls=':', label='foot radius 0.055 m')
    # Log scale: where the full model's IK loses a foot the error jumps by orders.
    axes.set_yscale('log')
    axes.set(xlabel='step size [m]', ylabel='max |ZMP ref - full-model ZMP| [m]',
             title='Fig. 8: ZMP error of the simplified models (ZMP crawl)')
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3)
    save(figure, 'fig08_zmp_error.png')

    figure, axes = plt.subplots(figsize=(7, 4.5))
    for period in ZMP_STEP_PERIODS_S:
        axes.plot(steps, finite([results.zmp_joint_speeds[period, v] for v in steps]), 'o-',
                  label=f'step period {period:g} s')
    axes.axhline(1.0, color='k', lw=0.8, ls=':', label='RoboSimian limit 1 rad/s')
    axes.set(xlabel='step size [m]', ylabel='max stance joint speed [rad/s]',
             title='Fig. 10: step size vs. joint speed of the ZMP crawl')
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3)
    save(figure, 'fig10_joint_speed.png')

    figure, axes = plt.subplots(figsize=(7, 4.5))
    for family, (x, travel) in results.joint_travel.items():
        axes.plot(x, travel, label=f'family {family} (thesis {family + 1})')
    axes.set_yscale('log')
    axes.set(xlabel='x [m] (y -0.5 m, z -0.6 m, yaw 0)',
             ylabel='max joint travel per metre along x [rad/m]',
             title='Fig. 12: joint travel of a small move along the swing line')
    axes.grid(alpha=0.3)
    axes.legend()
    save(figure, 'fig12_joint_travel.png')

    def speed_plot(name, title, keys):
        figure, axes = plt.subplots(figsize=(7, 4.5))
        for family, height in keys:
            curve = results.centred[family, height]
            ft = np.where(curve.speeds_m_s > 0, curve.speeds_m_s * FT_PER_MIN, np.nan)
            line, = axes.plot(curve.steps_m, ft, 'o-', ms=3,
                              label=f'family {family} (thesis {family + 1}), {height:g} m')
            k = curve.best
            axes.plot(curve.steps_m[k], ft[k], '*', ms=13, color=line.get_color())
            other = results.anywhere[family, height]
            axes.plot(other.steps_m, np.where(other.speeds_m_s > 0,
                                              other.speeds_m_s * FT_PER_MIN, np.nan),
                      ':', color=line.get_color(), lw=1, alpha=0.6)
        axes.set(xlabel='step size [m]', ylabel='gait speed [ft/min] (thesis eq. (2))',
                 title=title)
        axes.set_ylim(bottom=0)
        axes.grid(alpha=0.3)
        axes.legend(fontsize=8, title='solid: centred at x 0.5 m; dotted: any goal',
                    title_fontsize=7)
        save(figure, name)

    f2, f7 = FAMILIES
    h1, h2 = s.step_heights_m
    speed_plot('fig14_step_vs_speed.png', 'Fig. 14: step size vs. gait speed', [(f2, h1)])
    speed_plot('fig17_families.png', 'Fig. 17: IK families', [(f2, h1), (f7, h1)])
    speed_plot('fig18_step_heights.png', 'Fig. 18: step heights', [(f2, h2), (f2, h1)])
    speed_plot('fig19_overall.png', 'Fig. 19: overall',
               [(f, h) for f in FAMILIES for h in s.step_heights_m])

    o = results.optimal
    figure, (side, top) = plt.subplots(2, 1, figsize=(7, 7))
    for label, path, style in (('optimal', o['path'], 'o-'), ('straight', o['straight'], '--')):
        states = path.states
        side.plot(states[:, 0], states[:, 2], style, ms=3, label=f'{label}: '
                  f'{path.duration_s:.2f} s')
        top.plot(states[:, 0], states[:, 1], style, ms=3, label=label)
    swing = o['path'].swing_states
    top.quiver(swing[:, 0], swing[:, 1], np.cos(swing[:, 3]), np.sin(swing[:, 3]),
               angles='xy', scale=25, width=0.004, color='C0', alpha=0.6)
    side.set(xlabel='x [m]', ylabel='z [m]', title=f'Fig. 15: optimal swing, family {f2} '
             f'(thesis {f2 + 1}), {h1:g} m, step {o["step_m"]:.2f} m')
    top.set(xlabel='x [m]', ylabel='y [m] (front-right limb, body frame)',
            title='top view (arrows: foot yaw)')
    top.set_aspect('equal', adjustable='datalim')
    for axes in (side, top):
        axes.grid(alpha=0.3)
        axes.legend(fontsize=8)
    save(figure, 'fig15_optimal_swing.png')

    figure, axes = plt.subplots(figsize=(7, 4.5))
    joints = np.arange(1, 7)
    axes.bar(joints - 0.2, o['joint_travel_rad'], 0.4, label='optimal')
    axes.bar(joints + 0.2, o['straight_joint_travel_rad'], 0.4, label='straight')
    axes.set(xlabel='joint', ylabel='joint travel over the swing [rad]',
             title=f'Fig. 16: curved vs. straight (lift and lowering '
             f'{100 * o["lift_share"]:.1f} % of the optimal swing)')
    axes.legend()
    axes.grid(alpha=0.3, axis='y')
    save(figure, 'fig16_curved_vs_straight.png')

    figure, grid_axes = plt.subplots(2, 2, figsize=(8, 6))
    for axes, result in zip(grid_axes.ravel(), results.perturbations, strict=False):
        axes.plot(result.speeds_m_s * FT_PER_MIN, 'o', ms=3, label='perturbed')
        axes.axhline(result.optimal_m_s * FT_PER_MIN, color='k', label='value-table swing')
        axes.set(title=f'perturbed in {result.mode}', xlabel='copy', ylabel='ft/min')
        axes.grid(alpha=0.3)
        axes.legend(fontsize=7)
    save(figure, 'fig20_perturbations.png')

    figure, axes = plt.subplots(figsize=(7, 4.5))
    limits = np.array([c[0] for c in results.crossover])
    axes.plot(limits, np.array([c[1] for c in results.crossover]) * FT_PER_MIN, 'o-',
              label='value-table crawl')
    for column, label in ((2, 'ZMP crawl, stance limbs limited'),
                          (3, 'ZMP crawl, every limb limited')):
        zmp = np.array([c[column] for c in results.crossover])
        axes.plot(limits, np.where(zmp > 0, zmp * FT_PER_MIN, np.nan), 's-', label=label)
    axes.set(xlabel='joint velocity limit [rad/s]', ylabel='gait speed [ft/min]',
             title='Fig. 21: ZMP based vs. value iteration based')
    axes.grid(alpha=0.3)
    axes.legend()
    save(figure, 'fig21_zmp_vs_value_iteration.png')
    return written


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.thesis [--out DIR] [--quick]``."""
    parser = ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0], epilog=None)
    parser.add_argument('--out', default='thesis_figures', help='directory of the PNG figures '
                        '(default ./thesis_figures)')
    parser.add_argument('--quick', action='store_true', help='a coarse run (about a minute)')
    parser.add_argument('--robot', default='robosimian', help='robot name or YAML path')
    options = parser.parse_args(args)
    out_dir = Path(options.out).expanduser()
    if out_dir.exists() and not out_dir.is_dir():
        parser.error(f'--out {out_dir} exists and is not a directory')
    try:  # before the minutes of work, not after
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        parser.error(f'--out {out_dir}: cannot create the directory ({exc.strerror})')

    def log(message: str) -> None:
        print(f'{PROG}: {message}', file=sys.stderr, flush=True)

    started = time.perf_counter()
    try:
        from gait_nodes.robot.model import load_robot_model

        robot = load_robot_model(options.robot)
        settings = Settings.quick() if options.quick else Settings()
        results = run(robot, settings, log)
    except GaitNodesError as exc:
        return fail(PROG, exc)
    for family, goal_x, reason in results.tables.skipped:
        log(f'family {family}, goal x {goal_x:.2f} m skipped: {reason}')
    print(format_table(rows(results)))
    paths = write_figures(results, out_dir)
    print(f'\nfigures: {", ".join(str(p) for p in paths)}')
    print(f'{"quick" if options.quick else "full"} run in {time.perf_counter() - started:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
