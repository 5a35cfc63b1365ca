"""Reproduce the thesis' results with our models: one table beside the thesis' numbers, PNGs.

``python -m gait_nodes.thesis [--out DIR] [--quick] [--convergence]`` runs, on the shipped
RoboSimian (every PNG marks the thesis' values in black, labelled "thesis", beside ours):

- Fig. 8: largest ZMP error of the simplified models against step size: the full model's ZMP
  (:mod:`gait_nodes.robot.dynamics`) when the body follows the cart-table preview COM, and after
  one multi-mass correction (:mod:`gait_nodes.com.multimass`, our stand-in for the nine-link
  model), ZMP crawl (:mod:`gait_nodes.swing.zmp_gait`'s plan), steady cycles only;
- Fig. 10: largest stance-limb joint speed of that ZMP crawl against step size;
- Fig. 12: the thesis' map over the swing plane (z -0.6 m): the fastest joint's travel per
  metre of a small move along x and along y, with the thesis' grid drawn on it; printed along
  the swing's line too (the thesis' reason for the drop of Fig. 14: the joints move more close
  to the body);
- Figs. 14, 17-19: crawl speed (thesis eq. (2)) against step size from value tables on the
  thesis' setting (:meth:`GridSpec.thesis`), IK families 2 and 7 (the thesis' 3rd and 8th),
  step heights 0.1 and 0.06 m; with ``--convergence`` Fig. 14 again on the finer grids of
  :attr:`Settings.finer_grids`, and whether its optimum stays put (:func:`convergence`);
- Figs. 15-16: the optimal swing's top view against a straight swing, and the share of the
  lift and lowering in the swing time;
- IV.B.7 (Fig. 20): random perturbations of the optimal swing's waypoints;
- Fig. 21: every gait of the robot (RoboSimian: the static crawl, thesis eq. (2) walked; the
  ZMP crawl; the trot) walked by the inproc node graph at joint velocity limits from 0.5 to 4
  rad/s and read back from its bag (:mod:`gait_nodes.walked_crossover`; ``--quick``: 1 and 2.5
  rad/s, shorter walks): walked, not modelled.

The step size of a swing is its x travel; the thesis sets the goal's x "to be different" for each
step (IV.B.3) without saying where: here every swing is centred on the middle of the thesis' x
range, 0.5 m (start ``0.5 - s/2``, goal ``0.5 + s/2``: every step up to 0.6 m fits), and the best
over every goal of the grid is printed too. The ZMP gaits plan with the thesis' step range as
the robot's reach (:func:`thesis_description`). The thesis gives no step period for its ZMP
gait: Figs. 8 and 10 use :data:`ZMP_STEP_PERIODS_S` (both drawn, the first printed). The
one-step costs of the value iteration are cached in ``$XDG_CACHE_HOME/gait_nodes/thesis/`` (a
minute per family on the default grid; 3.5 and 6 minutes for family 2 on the finer grids of
``--convergence``).

Exit status: 0 on success, 2 on bad input (one line on stderr).
"""

from __future__ import annotations

import math
import sys
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gait_nodes.cli import ArgumentParser, fail
from gait_nodes.errors import GaitNodesError
from gait_nodes.swing.value_iteration import THESIS_STEP_HEIGHTS_M

if TYPE_CHECKING:
    from gait_nodes.swing.sweep import SweepTables

PROG = 'python -m gait_nodes.thesis'

#: Step periods [s] of the ZMP crawl of Figs. 8 and 10 (the thesis gives none).
ZMP_STEP_PERIODS_S = (1.0, 2.0)
#: The thesis' IK families compared (its 3rd and 8th; ours count from 0).
FAMILIES = (2, 7)
#: The longest step the thesis' x range (0.2-0.8 m) holds [m].
THESIS_LONGEST_STEP_M = 0.6
#: The thesis' ground below RoboSimian's body [m]: its lower swing plane (II.D).
THESIS_BODY_HEIGHT_M = 0.7
#: The walked gait that is the thesis' value-iteration crawl (Fig. 21), and the ZMP gaits.
VALUE_ITERATION_GAIT = 'static_crawl'
ZMP_GAITS = {'crawl': 'ZMP crawl', 'trot': 'ZMP trot'}
#: The foot's radius: the thesis' bound on a useful ZMP error (IV.A.1) [m].
FOOT_RADIUS_M = 0.055

#: The thesis' numbers (000, section IV), drawn beside ours in the figures.
THESIS_NUMBERS = {
    'fig8_useful_step_m': 0.4,            # IV.A.1: the models useful up to about 0.4 m
    'fig10_step_m': 0.2,                  # IV.A.2: 1 rad/s allows steps slightly below 0.2 m
    'fig10_speed_rad_s': 1.0,
    'fig12_x_m': (0.2, 0.8),              # IV.B.1: the grid chosen from its Fig. 12
    'fig12_y_m': (-0.65, -0.4),
    'fig14_optimum_m': 0.34,              # IV.B.3, family 3, 0.1 m step height
    'fig17_family_3_slower_m': (0.42, 0.54),  # IV.B.4: family 3 slower at these steps
    'overall_step_m': 0.34,               # IV.B.6: family 3, 0.06 m
    'overall_ft_min': 8.542,
    'lift_share': 0.3876,                 # IV.B.5
    # IV.B.7: mean speed lost by perturbing the optimal path [ft/min].
    'perturb_loss_ft_min': {'x': 0.5026, 'y': 0.1513, 'z': 0.1803, 'xyz': 0.4353},
    'fig21_zmp_feasible_rad_s': 1.9,      # IV.C: the ZMP gait infeasible below about 1.9 rad/s
    'fig21_zmp_faster_rad_s': 2.4,        # and faster than value iteration above about 2.4
}
_N = THESIS_NUMBERS

#: The thesis' numbers (000, section IV), by row key.
THESIS = {
    'fig8_useful_step': f'about {_N["fig8_useful_step_m"]:g} m (error < foot radius 0.055 m)',
    'fig10_speed_at_0.2': f'about {_N["fig10_speed_rad_s"]:g} rad/s',
    'fig10_largest_step': f'slightly below {_N["fig10_step_m"]:g} m',
    'fig12_travel': 'more joint travel close to the body',
    'fig12_region': (f'smaller in x {_N["fig12_x_m"][0]:g}-{_N["fig12_x_m"][1]:g} m, y '
                     f'{_N["fig12_y_m"][0]:g} to {_N["fig12_y_m"][1]:g} m (its grid)'),
    'fig14_optimum': f'{_N["fig14_optimum_m"]:.2f} m (interior)',
    'fig14_converged': 'not shown (one grid)',
    'fig15_outward': 'curves outward in y',
    'fig16_straight': 'straight is slower',
    'fig16_lift_share': f'{100 * _N["lift_share"]:.2f} %',
    'fig17_families': 'family 3 faster overall',
    'fig18_heights': '0.06 m faster',
    'fig19_overall': (f'family 3, 0.06 m, {_N["overall_step_m"]:.2f} m, '
                      f'{_N["overall_ft_min"]:.3f} ft/min'),
    'fig5_families_differ': 'all joints differ',
    **{f'perturb_{mode}': f'-{loss:.2f} ft/min, all slower'
       for mode, loss in _N['perturb_loss_ft_min'].items()},
    'fig21_zmp_feasible': 'from 1.9 rad/s',
    'fig21_zmp_faster': 'above about 2.4 rad/s',
}
del _N


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
        limits_rad_s: Joint velocity limits the gaits of Fig. 21 are walked at [rad/s].
        walk_at_1_rad_s: Duration of each walk of Fig. 21 at 1 rad/s [s] (over the limit at
            the others).
        trials: Perturbed copies per axis (IV.B.7).
        amplitude_m: Largest perturbation of a waypoint [m].
        step_heights_m: Step heights [m] (the thesis' 0.1 and 0.06 m).
        finer_grids: ``(x, y, yaw)`` node counts of the finer grids Fig. 14 is redone on
            with ``--convergence`` (each with a node at x 0.5 m and y -0.5 m, and yaw 0).
    """

    x_count: int = 31
    y_count: int = 11
    yaw_count: int = 7
    radii_m: tuple[float, ...] = (0.025, 0.05, 0.1, 0.2)
    azimuth_count: int = 16
    zmp_steps_m: tuple[float, ...] = (0.04, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5)
    limits_rad_s: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
    walk_at_1_rad_s: float = 70.0
    trials: int = 40
    amplitude_m: float = 0.02
    step_heights_m: tuple[float, ...] = THESIS_STEP_HEIGHTS_M
    finer_grids: tuple[tuple[int, int, int], ...] = ((41, 16, 9), (61, 21, 13))

    @classmethod
    def quick(cls) -> Settings:
        """A coarse run (about a minute): x every 0.04 m, y every 0.05 m, 5 yaws."""
        return cls(x_count=16, y_count=6, yaw_count=5, radii_m=(0.04, 0.08, 0.16),
                   azimuth_count=8, zmp_steps_m=(0.1, 0.2, 0.3, 0.4),
                   limits_rad_s=(1.0, 2.5), walk_at_1_rad_s=45.0, trials=10,
                   finer_grids=((21, 6, 5), (31, 11, 5)))

    @property
    def counts(self) -> tuple[int, int, int]:
        """``(x, y, yaw)`` node counts of the run's grid."""
        return self.x_count, self.y_count, self.yaw_count

    def grid_spec(self, counts: tuple[int, int, int] | None = None):
        """The thesis' grid at this resolution, or at ``(x, y, yaw)`` node counts."""
        from gait_nodes.swing.value_iteration import GridSpec

        return GridSpec.thesis(*(counts or self.counts))

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


def thesis_robot(robot):
    """``robot`` on the thesis' stance: ground :data:`THESIS_BODY_HEIGHT_M` below its body.

    The thesis' tables and swings are on its swing planes, 0.6 and 0.7 m below the body
    (II.D); a walker may stand otherwise (``bench/stance.py`` walks RoboSimian's static crawl
    at other heights). A robot at another height is copied to the thesis'
    (:func:`gait_nodes.robot.stance.write_stance`, under the cache directory).
    """
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.robot.stance import write_stance
    from gait_nodes.swing.cache import cache_dir

    if math.isclose(robot.description.body_height_m, THESIS_BODY_HEIGHT_M, abs_tol=1e-9):
        return robot
    return load_robot_model(write_stance(robot.description.path, cache_dir() / 'thesis',
                                         THESIS_BODY_HEIGHT_M))


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
    from gait_nodes.swing.zmp_gait import DUTY_FACTORS

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


def build_tables(robot, settings: Settings, centre_x_m: float, log,
                 families=FAMILIES, counts: tuple[int, int, int] | None = None) -> SweepTables:
    """One table per family and goal on the thesis' grid, every step height (Figs. 14-19).

    The goals are the grid's x nodes ahead of ``centre_x_m`` whose mirror about it is a node
    too (each gives one centred step), at the thesis' y and z (:func:`thesis_goal`).

    Args:
        robot: The RobotModel.
        settings: The run's settings.
        centre_x_m: Where the swings are centred [m].
        log: Called with progress messages.
        families: IK families.
        counts: ``(x, y, yaw)`` node counts; None: the settings'.
    """
    from gait_nodes.swing.sweep import centred_goal_xs, sweep_tables
    from gait_nodes.swing.value_iteration import thesis_goal

    spec = settings.grid_spec(counts)
    x_axis = np.linspace(*spec.x_range_m[:2], int(spec.x_range_m[2]))
    goals = [thesis_goal(x) for x in centred_goal_xs(x_axis, centre_x_m)]
    return sweep_tables(robot, families, settings.step_heights_m, spec, settings.actions(),
                        goals, robot.description.joint_velocity_limit_rad_s, log)


#: Fig. 12's map over the swing plane: x and y of the front-right foot [m], every 0.01 m
#: (the thesis maps "a wide range of points"; this holds the limb's reach on that plane).
FIG12_X_M = np.round(np.arange(0.0, 1.0 + 1e-9, 0.01), 6)
FIG12_Y_M = np.round(np.arange(-1.0, 0.0 + 1e-9, 0.01), 6)
#: Fig. 12's axes of the small move: the thesis' top (x) and bottom (y) panels.
FIG12_MOVES = ('x', 'y')


def joint_travel_map(robot, family: int, x_m: np.ndarray, y_m: np.ndarray, move: str,
                     z_m: float = -0.6, step_m: float = 0.01) -> np.ndarray:
    """Thesis Figs. 11-12: largest joint travel per metre of a small move of the foot [rad/m].

    The thesis maps the joint velocity when each node is moved a small amount along x (its top
    panel) or y (bottom) on the plane 0.6 m below the centre of body; ours is the fastest
    joint's travel per metre of foot travel, its speed [rad/s] at a foot speed of 1 m/s.

    Args:
        robot: The RobotModel.
        family: IK family 0..7.
        x_m: (nx,) foot x [m] (base frame, front-right limb).
        y_m: (ny,) foot y [m].
        move: ``'x'`` or ``'y'``: the axis of the small move.
        z_m: Foot z [m] (yaw 0).
        step_m: The small move [m].

    Returns:
        (ny, nx) travel [rad/m]; NaN where the family reaches neither end (the thesis' 0).
    """
    from gait_nodes.swing.kinematics import LimbTiming

    timing = LimbTiming(robot, family, 1.0)
    xx, yy = np.meshgrid(x_m, y_m)
    states = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z_m),
                              np.zeros(xx.size)])
    q, ok = timing.joints(states)
    moved = states.copy()
    moved[:, FIG12_MOVES.index(move)] += step_m
    q_next, ok_next = timing.joints(moved)
    travel = np.abs(q_next - q).max(axis=1) / step_m
    return np.where(ok & ok_next, travel, np.nan).reshape(xx.shape)


def thesis_region(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """(ny, nx) True inside the thesis' grid (x 0.2-0.8 m, y -0.65 to -0.4 m)."""
    (x0, x1), (y0, y1) = THESIS_NUMBERS['fig12_x_m'], THESIS_NUMBERS['fig12_y_m']
    xx, yy = np.meshgrid(x_m, y_m)
    return (xx >= x0 - 1e-9) & (xx <= x1 + 1e-9) & (yy >= y0 - 1e-9) & (yy <= y1 + 1e-9)


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
    tables: SweepTables | None = None
    centred: dict = field(default_factory=dict)          # (family, height) -> SpeedCurve
    anywhere: dict = field(default_factory=dict)         # (family, height) -> SpeedCurve
    optimal: dict = field(default_factory=dict)          # Figs. 15-16
    perturbations: list = field(default_factory=list)
    perturbations_of: tuple = ()                         # (family, height) of the path
    families_q: tuple | None = None
    joint_travel: dict = field(default_factory=dict)     # family -> (x, rad/m along x)
    travel_maps: dict = field(default_factory=dict)      # 'x' / 'y' -> (ny, nx) rad/m
    fig14_grids: list = field(default_factory=list)      # GridOptimum, coarsest first
    # Fig. 21: gait_nodes.walked_crossover.WalkedGait rows, read from the walks' bags
    crossover: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)


@dataclass(frozen=True)
class GridOptimum:
    """Fig. 14 (family 2, 0.1 m step height, centred swings) on one grid.

    Attributes:
        counts: ``(x, y, yaw)`` node counts.
        x_spacing_m: Node spacing along x [m] (centred steps lie twice that apart).
        curve: The centred speed curve.
        seconds: Wall time of its value tables, one-step costs included [s].
    """

    counts: tuple[int, int, int]
    x_spacing_m: float
    curve: object
    seconds: float

    @classmethod
    def of(cls, settings: Settings, counts, curve, seconds: float) -> GridOptimum:
        """The optimum of ``curve`` on the settings' grid with ``counts`` nodes."""
        low, high, count = settings.grid_spec(counts).x_range_m
        return cls(tuple(counts), (high - low) / (count - 1), curve, seconds)

    @property
    def name(self) -> str:
        """``'31x11x7'``: nodes along x, y and yaw."""
        return 'x'.join(str(c) for c in self.counts)

    @property
    def step_m(self) -> float:
        """The optimal step [m]."""
        return float(self.curve.steps_m[self.curve.best])


def convergence(grids: list[GridOptimum]) -> tuple[bool | None, str]:
    """Whether Fig. 14's optimum stays put on the two finest grids, and a sentence saying so.

    Converged: the optimal step on the finest grid is within one step of the coarser grid of
    the two (twice its x spacing: centred steps lie that far apart) of the coarser one's. An
    optimum on the longest or shortest step is said to be at the end of the range, and the
    steps within 5 % of the best speed are named (a flat top moves its argmax easily).

    Returns:
        ``(converged, text)``; ``converged`` None with one grid (not checked).
    """
    from gait_nodes.swing.sweep import END_OF_RANGE

    if len(grids) < 2:
        return None, 'not checked: one grid (--convergence redoes it on finer grids)'
    coarse, fine = grids[-2], grids[-1]
    tolerance = 2 * coarse.x_spacing_m
    shift = fine.step_m - coarse.step_m
    speed = _best_speed(fine.curve) / _best_speed(coarse.curve) - 1
    near = fine.curve.steps_m[fine.curve.speeds_m_s >= 0.95 * _best_speed(fine.curve)]
    both = (f'{coarse.step_m:.2f} m on {coarse.name}, {fine.step_m:.2f} m on {fine.name}; '
            f'steps within 5 % of the best on {fine.name}: {near.min():.2f}-{near.max():.2f} m')
    if abs(shift) > tolerance + 1e-9:
        return False, (f'not converged: {both} (moves {shift:+.2f} m, more than one step of the '
                       f'coarser grid, {tolerance:.3f} m)')
    where = '' if fine.curve.best_is_interior else f', {END_OF_RANGE}'
    return True, (f'converged{where}: {both} (within one step of the coarser grid, '
                  f'{tolerance:.3f} m; best speed {100 * speed:+.1f} %)')


def fig14_on_grid(robot, settings: Settings, centre_x_m: float, counts, log) -> GridOptimum:
    """Fig. 14's centred curve on the thesis' grid with ``counts`` nodes."""
    started = time.perf_counter()
    family, height = FAMILIES[0], settings.step_heights_m[0]
    tables = build_tables(robot, settings, centre_x_m, log, families=(family,), counts=counts)
    return GridOptimum.of(settings, counts, tables.centred(family, height, centre_x_m),
                          time.perf_counter() - started)


def run(robot, settings: Settings, log, convergence_grids: bool = False) -> Results:
    """Compute every figure's data (see the module docstring).

    Args:
        robot: The RobotModel.
        settings: What to compute.
        log: Called with progress messages.
        convergence_grids: Redo Fig. 14 on :attr:`Settings.finer_grids` too.
    """
    from gait_nodes.swing.policy import SwingPolicy
    from gait_nodes.swing.sweep import perturbation_test
    from gait_nodes.swing.value_iteration import THESIS_GOAL_Y_M, THESIS_GOAL_Z_M
    from gait_nodes.swing.zmp_gait import zmp_gait_joint_speed

    robot = thesis_robot(robot)
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
            results.centred[family, height] = tables.centred(family, height,
                                                             results.centre_x_m)
            results.anywhere[family, height] = tables.anywhere(family, height)
    results.seconds['tables'] = time.perf_counter() - started
    results.fig14_grids.append(GridOptimum.of(
        settings, settings.counts, results.centred[FAMILIES[0], settings.step_heights_m[0]],
        results.seconds['tables']))
    if convergence_grids:
        for counts in settings.finer_grids:
            grid = fig14_on_grid(robot, settings, results.centre_x_m, counts, log)
            results.fig14_grids.append(grid)
            log(f'Fig. 14 on grid {grid.name}: optimum {grid.step_m:.2f} m in '
                f'{grid.seconds:.0f} s')

    family, height = FAMILIES[0], settings.step_heights_m[0]
    results.optimal = optimal_swing(robot, tables, results.centred[family, height],
                                    family, height)
    best_key = max(results.centred, key=lambda k: _best_speed(results.centred[k]))
    best = results.centred[best_key]
    table = tables.owner(*best_key, best)
    policy = SwingPolicy(table, robot)
    path = policy.path_from(best.starts[best.best])
    results.perturbations = perturbation_test(policy, path, settings.trials,
                                              settings.amplitude_m)
    results.perturbations_of = best_key

    for move in FIG12_MOVES:
        results.travel_maps[move] = joint_travel_map(robot, FAMILIES[0], FIG12_X_M, FIG12_Y_M,
                                                     move, THESIS_GOAL_Z_M)
    row = int(np.argmin(np.abs(FIG12_Y_M - THESIS_GOAL_Y_M)))
    on_grid = (FIG12_X_M >= 0.2 - 1e-9) & (FIG12_X_M <= 0.8 + 1e-9)
    results.joint_travel[FAMILIES[0]] = (FIG12_X_M[on_grid],
                                         results.travel_maps['x'][row, on_grid])
    ik = policy.timing.ik
    point = np.array([[0.6, -0.54, -0.6]])
    results.families_q = tuple(ik.solve(point, 0.0, f)[0][0, :6] for f in FAMILIES)

    started = time.perf_counter()
    results.crossover = walk_gaits(robot, settings, log)
    results.seconds['crossover'] = time.perf_counter() - started
    log(f'Fig. 21: {len(results.crossover)} walks in {results.seconds["crossover"]:.0f} s')
    return results


def walk_gaits(robot, settings: Settings, log) -> list:
    """Fig. 21: each gait of ``robot`` walked at ``settings.limits_rad_s``, from the bags."""
    from gait_nodes.walked_crossover import describe, walked_crossover

    def walked(message: str) -> None:
        log(f'Fig. 21 walked: {message}')

    rows = walked_crossover(settings.limits_rad_s, str(robot.description.path),
                            duration_at_1_rad_s=settings.walk_at_1_rad_s, log=walked)
    for row in rows:
        if not row.feasible:
            log(f'Fig. 21: {row.gait} at {row.limit_rad_s:g} rad/s {describe(row)}')
    return rows


def fig21_from(rows, gait: str, than: str | None = None) -> str:
    """Where walked ``gait`` is feasible (or faster than walked ``than``), in words."""
    limits = sorted({r.limit_rad_s for r in rows})
    speed = {(r.gait, r.limit_rad_s): (r.speed_m_s if r.feasible else 0.0) for r in rows}
    good = [w for w in limits if speed.get((gait, w), 0.0) > 0.0 and
            (than is None or speed[gait, w] > speed.get((than, w), 0.0))]
    if not good:
        return f'never up to {limits[-1]:g} rad/s'
    text = ', '.join(f'{w:g}' for w in good)
    where = (f'from {good[0]:g} rad/s' if good == limits[limits.index(good[0]):] else
             f'at {text} rad/s only')
    if than is not None:
        w = good[0]
        where += (f' ({speed[gait, w]:.4f} against {speed.get((than, w), 0.0):.4f} m/s '
                  f'there)')
    return where


def _best_speed(curve) -> float:
    return float(curve.speeds_m_s[curve.best]) if len(curve.speeds_m_s) else 0.0


def optimal_swing(robot, tables: SweepTables, curve, family: int, height: float) -> dict:
    """Figs. 15-16: the optimal swing, a straight one between the same places, their times."""
    from gait_nodes.swing.policy import SwingPolicy

    table = tables.owner(family, height, curve)
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
    from gait_nodes.swing.sweep import describe_optimum

    return describe_optimum(curve)


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
    inside = thesis_region(FIG12_X_M, FIG12_Y_M)
    medians = [(np.nanmedian(results.travel_maps[m][inside]),
                np.nanmedian(results.travel_maps[m][~inside])) for m in FIG12_MOVES]
    out.append(('Fig. 12', f'map at z -0.6 m (x {FIG12_X_M[0]:g}-{FIG12_X_M[-1]:g}, y '
                f'{FIG12_Y_M[0]:g}-{FIG12_Y_M[-1]:g} m): median joint travel per metre inside '
                "/ outside the thesis' grid, moves along " + ' / '.join(FIG12_MOVES),
                '; '.join(f'{m}: {a:.1f} / {b:.1f} rad/m'
                          for m, (a, b) in zip(FIG12_MOVES, medians, strict=True)),
                THESIS['fig12_region']))
    family, height = FAMILIES[0], s.step_heights_m[0]
    out.append(('Fig. 14', f'optimal step, family {family} (thesis {family + 1}), '
                f'{height:g} m, centred', _optimum_text(results.centred[family, height]),
                THESIS['fig14_optimum']))
    out.append(('Fig. 14', 'same, best over every goal of the grid',
                _optimum_text(results.anywhere[family, height]), '-'))
    for grid in results.fig14_grids[1:]:
        out.append(('Fig. 14', f'same, centred, finer grid {grid.name} (x every '
                    f'{grid.x_spacing_m:.3f} m)', f'{_optimum_text(grid.curve)} '
                    f'({grid.seconds:.0f} s)', '-'))
    out.append(('Fig. 14', 'optimum converged over grids '
                + ', '.join(g.name for g in results.fig14_grids),
                convergence(results.fig14_grids)[1], THESIS['fig14_converged']))
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
    walked = results.crossover
    have = {r.gait for r in walked}
    for gait, name in ZMP_GAITS.items():
        if gait not in have:
            continue
        out.append(('Fig. 21', f'{name} feasible (walked)', fig21_from(walked, gait),
                    THESIS['fig21_zmp_feasible']))
        if VALUE_ITERATION_GAIT in have:
            out.append(('Fig. 21', f'{name} faster than the static crawl (the value-iteration '
                        'crawl; both walked)', fig21_from(walked, gait, VALUE_ITERATION_GAIT),
                        THESIS['fig21_zmp_faster']))
    return out


def format_table(table_rows) -> str:
    """The rows as a Markdown table."""
    lines = ['| figure | quantity | ours | thesis |', '| --- | --- | --- | --- |']
    lines += [f'| {a} | {b} | {c} | {d} |' for a, b, c, d in table_rows]
    return '\n'.join(lines)


# -- figures -----------------------------------------------------------------------------------


def write_figures(results: Results, out_dir: Path) -> list[Path]:
    """Every figure as a PNG in ``out_dir``, the thesis' values marked in black; the paths."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    from gait_nodes.swing.sweep import FT_PER_MIN
    from gait_nodes.swing.value_iteration import THESIS_GOAL_Y_M

    out_dir.mkdir(parents=True, exist_ok=True)
    s = results.settings
    n = THESIS_NUMBERS
    thesis_style = {'color': 'k', 'zorder': 5}
    written = []

    def save(figure, name, rect=None):
        figure.tight_layout(rect=rect)
        path = out_dir / name
        figure.savefig(path, dpi=110)
        plt.close(figure)
        written.append(path)

    def finite(values):
        values = np.asarray(values, dtype=float)
        return np.where(np.isfinite(values), values, np.nan)

    def feet_per_min(curve):
        return np.where(curve.speeds_m_s > 0, curve.speeds_m_s * FT_PER_MIN, np.nan)

    steps = np.array(s.zmp_steps_m)
    figure, axes = plt.subplots(figsize=(7, 4.5))
    for period in ZMP_STEP_PERIODS_S:
        errors = [results.zmp_errors[period, v] for v in steps]
        axes.plot(steps, finite([e.cart_table_m for e in errors]), 'o--',
                  label=f'cart-table COM, T {period:g} s')
        axes.plot(steps, finite([e.corrected_m for e in errors]), 'o-',
                  label=f'+ one multi-mass correction, T {period:g} s')
    axes.axhline(FOOT_RADIUS_M, color='k', lw=0.8, ls=':', label='foot radius 0.055 m')
    axes.plot(n['fig8_useful_step_m'], FOOT_RADIUS_M, 'X', ms=11, **thesis_style,
              label=f'thesis: useful up to about {n["fig8_useful_step_m"]:g} m')
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
    axes.plot(n['fig10_step_m'], n['fig10_speed_rad_s'], 'X', ms=11, **thesis_style,
              label=f'thesis: about {n["fig10_speed_rad_s"]:g} rad/s at slightly below '
              f'{n["fig10_step_m"]:g} m')
    axes.set(xlabel='step size [m]', ylabel='max stance joint speed [rad/s]',
             title='Fig. 10: step size vs. joint speed of the ZMP crawl')
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3)
    save(figure, 'fig10_joint_speed.png')

    figure, panels = plt.subplots(2, 1, figsize=(7, 9), sharex=True)
    # Capped: along the singular curves the travel runs to hundreds of rad/m and would wash
    # out the 3-30 rad/m that tell the regions apart.
    norm = LogNorm(vmin=2.0, vmax=40.0, clip=False)
    (x0, x1), (y0, y1) = n['fig12_x_m'], n['fig12_y_m']
    for axes, move in zip(panels, FIG12_MOVES, strict=True):
        axes.set_facecolor('0.85')  # unreachable: the thesis' 0 rad/s
        image = axes.pcolormesh(FIG12_X_M, FIG12_Y_M, results.travel_maps[move], norm=norm,
                                cmap='viridis', shading='nearest')
        axes.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, lw=2, ls='--',
                                 label="thesis' grid, chosen from its Fig. 12", **thesis_style))
        axes.axhline(THESIS_GOAL_Y_M, color='w', lw=0.8, ls=':',
                     label=f'the swing line (y {THESIS_GOAL_Y_M:g} m)')
        axes.set(ylabel='y [m]', title=f'small move along {move}', aspect='equal')
        axes.legend(fontsize=8, loc='lower right')
        figure.colorbar(image, ax=axes, extend='max',
                        label='max joint travel per metre [rad/m]')
    panels[-1].set_xlabel('x [m] (front-right foot, base frame; grey: out of reach)')
    figure.suptitle(f'Fig. 12: joint travel of a small move, family {FAMILIES[0]} (thesis '
                    f'{FAMILIES[0] + 1}), z -0.6 m, yaw 0')
    save(figure, 'fig12_joint_travel.png')

    converged, verdict = convergence(results.fig14_grids)
    figure, axes = plt.subplots(figsize=(7.5, 5))
    for grid in results.fig14_grids:
        ft = feet_per_min(grid.curve)
        line, = axes.plot(grid.curve.steps_m, ft, 'o-', ms=3,
                          label=f'grid {grid.name} (x every {grid.x_spacing_m:.3f} m): '
                          f'{grid.step_m:.2f} m')
        axes.plot(grid.step_m, ft[grid.curve.best], '*', ms=13, color=line.get_color())
    axes.axvline(n['fig14_optimum_m'], lw=1.2, ls='--', **thesis_style,
                 label=f'thesis: optimum {n["fig14_optimum_m"]:.2f} m')
    family, height = FAMILIES[0], s.step_heights_m[0]
    axes.set(xlabel='step size [m]', ylabel='gait speed [ft/min] (thesis eq. (2))',
             title=f'Fig. 14: step size vs. gait speed, family {family} (thesis {family + 1}), '
             f'{height:g} m, centred at x {results.centre_x_m:g} m')
    axes.set_ylim(bottom=0)
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8, loc='lower right')
    radii = '/'.join(f'{r:g}' for r in s.radii_m)
    note = '\n'.join(textwrap.fill(text, 62) for text in (
        f'optimum {verdict}',
        f'every grid: actions on spheres of {radii} m, {s.azimuth_count} azimuths'))
    axes.text(0.02, 0.97, note, transform=axes.transAxes, va='top', fontsize=7.5,
              bbox={'facecolor': 'w', 'alpha': 0.85, 'lw': 0.5})
    save(figure, 'fig14_step_vs_speed.png')

    def speed_plot(name, title, keys, marks=()):
        figure, axes = plt.subplots(figsize=(7, 4.5))
        for family, height in keys:
            curve = results.centred[family, height]
            ft = feet_per_min(curve)
            line, = axes.plot(curve.steps_m, ft, 'o-', ms=3,
                              label=f'family {family} (thesis {family + 1}), {height:g} m')
            k = curve.best
            axes.plot(curve.steps_m[k], ft[k], '*', ms=13, color=line.get_color())
            axes.plot(results.anywhere[family, height].steps_m,
                      feet_per_min(results.anywhere[family, height]),
                      ':', color=line.get_color(), lw=1, alpha=0.6)
        for step in marks:
            axes.axvline(step, lw=0.8, ls='--', **thesis_style,
                         label='thesis: family 3 slower here' if step == marks[0] else None)
        axes.plot(n['overall_step_m'], n['overall_ft_min'], 'X', ms=11, **thesis_style,
                  label=f'thesis: optimum overall (family 3, 0.06 m) {n["overall_step_m"]:g} '
                  f'm, {n["overall_ft_min"]:g} ft/min')
        axes.set(xlabel='step size [m]', ylabel='gait speed [ft/min] (thesis eq. (2))',
                 title=title)
        axes.set_ylim(bottom=0)
        axes.grid(alpha=0.3)
        axes.legend(fontsize=7, loc='lower right',
                    title='solid: centred at x 0.5 m; dotted: any goal', title_fontsize=7)
        save(figure, name)

    f2, f7 = FAMILIES
    h1, h2 = s.step_heights_m
    speed_plot('fig17_families.png', 'Fig. 17: IK families', [(f2, h1), (f7, h1)],
               n['fig17_family_3_slower_m'])
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
    # The thesis gives the step, not where it lies: centred like ours (our reading).
    ends = results.centre_x_m + np.array([-0.5, 0.5]) * n['fig14_optimum_m']
    for axes in (side, top):
        for x in ends:
            axes.axvline(x, lw=0.8, ls='--', **thesis_style, label=None if x != ends[0] else
                         f"thesis' {n['fig14_optimum_m']:g} m step (centred at x "
                         f'{results.centre_x_m:g} m)')
    side.set(xlabel='x [m]', ylabel='z [m]', title=f'Fig. 15: optimal swing, family {f2} '
             f'(thesis {f2 + 1}), {h1:g} m, step {o["step_m"]:.2f} m')
    top.set(xlabel='x [m]', ylabel='y [m] (front-right limb, body frame)',
            title='top view (arrows: foot yaw; thesis: curves outward in y)')
    top.set_aspect('equal', adjustable='datalim')
    for axes in (side, top):
        axes.grid(alpha=0.3)
        axes.legend(fontsize=8)
    save(figure, 'fig15_optimal_swing.png')

    figure, (bars, share) = plt.subplots(1, 2, figsize=(9, 4.5),
                                         gridspec_kw={'width_ratios': [3, 1]})
    joints = np.arange(1, 7)
    bars.bar(joints - 0.2, o['joint_travel_rad'], 0.4, label='optimal')
    bars.bar(joints + 0.2, o['straight_joint_travel_rad'], 0.4, label='straight')
    bars.set(xlabel='joint', ylabel='joint travel over the swing [rad]',
             title='Fig. 16: curved vs. straight (thesis: straight needs more)')
    bars.legend()
    bars.grid(alpha=0.3, axis='y')
    share.bar([0, 1], [100 * o['lift_share'], 100 * n['lift_share']], color=['C0', 'k'])
    share.set_xticks([0, 1], [f'ours\n{o["step_m"]:.2f} m step',
                              f'thesis\n{n["fig14_optimum_m"]:g} m step'])
    for x, value in enumerate((100 * o['lift_share'], 100 * n['lift_share'])):
        share.text(x, value, f'{value:.1f} %', ha='center', va='bottom', fontsize=9)
    share.set(ylabel='lift and lowering [% of the swing time]', title='lift share')
    share.grid(alpha=0.3, axis='y')
    save(figure, 'fig16_curved_vs_straight.png')

    figure, grid_axes = plt.subplots(2, 2, figsize=(8, 6.5))
    for axes, result in zip(grid_axes.ravel(), results.perturbations, strict=False):
        optimal = result.optimal_m_s * FT_PER_MIN
        loss = n['perturb_loss_ft_min'][result.mode]
        axes.plot(result.speeds_m_s * FT_PER_MIN, 'o', ms=3, label='perturbed copies')
        axes.axhline(optimal, color='C1', label='value-table swing')
        axes.axhline(optimal - result.mean_loss_m_s * FT_PER_MIN, color='C0', ls=':',
                     label='perturbed copies: mean')
        axes.axhline(optimal - loss, lw=1.2, ls='--', **thesis_style,
                     label="thesis: its mean loss below the optimum")
        axes.set_title(f'perturbed in {result.mode} (thesis: mean -{loss:.2f} ft/min)',
                       fontsize=9)
        axes.set(xlabel='copy', ylabel='ft/min')
        axes.grid(alpha=0.3)
    figure.legend(*grid_axes[0, 0].get_legend_handles_labels(), loc='lower center', ncol=2,
                  fontsize=8)
    figure.suptitle('Fig. 20 (IV.B.7): perturbed copies of the optimal swing')
    save(figure, 'fig20_perturbations.png', rect=(0, 0.08, 1, 1))

    figure, axes = plt.subplots(figsize=(7.5, 5))
    labels = {VALUE_ITERATION_GAIT: 'static crawl (value-iteration crawl)', **ZMP_GAITS}
    for gait in dict.fromkeys(r.gait for r in results.crossover):
        rows_of = [r for r in results.crossover if r.gait == gait]
        limits = np.array([r.limit_rad_s for r in rows_of])
        ft = np.array([r.speed_m_s for r in rows_of]) * FT_PER_MIN
        ok = np.array([r.feasible for r in rows_of])
        line, = axes.plot(limits, np.where(ok, ft, np.nan), 'o-',
                          label=f'{labels.get(gait, gait)}, walked')
        if (~ok).any():
            axes.plot(limits[~ok], ft[~ok], 'x', ms=10, color=line.get_color(),
                      label=f'{labels.get(gait, gait)}: infeasible walk')
    axes.axvline(n['fig21_zmp_feasible_rad_s'], lw=1.2, ls='--', **thesis_style,
                 label=f'thesis: ZMP gait feasible from about {n["fig21_zmp_feasible_rad_s"]:g} '
                 'rad/s')
    axes.axvline(n['fig21_zmp_faster_rad_s'], lw=1.2, ls=':', **thesis_style,
                 label=f'thesis: ZMP gait faster above about {n["fig21_zmp_faster_rad_s"]:g} '
                 'rad/s')
    axes.set(xlabel='joint velocity limit [rad/s]', ylabel='walked speed [ft/min]',
             title='Fig. 21: the gaits walked at each joint velocity limit')
    axes.set_ylim(bottom=0)
    axes.grid(alpha=0.3)
    axes.legend(fontsize=7, loc='upper left')
    axes.text(0.98, 0.03, textwrap.fill(
        'walked, not modelled: the inproc node graph, each speed read from its bag '
        '(steady cycles)', 48), transform=axes.transAxes, ha='right', va='bottom', fontsize=7,
        bbox={'facecolor': 'w', 'alpha': 0.85, 'lw': 0.5})
    save(figure, 'fig21_zmp_vs_value_iteration.png')
    return written


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.thesis [--out DIR] [--quick] [--convergence]``."""
    parser = ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0], epilog=None)
    parser.add_argument('--out', default='thesis_figures', help='directory of the PNG figures '
                        '(default ./thesis_figures)')
    parser.add_argument('--quick', action='store_true', help='a coarse run (about a minute)')
    parser.add_argument('--convergence', action='store_true',
                        help="redo Fig. 14 on two finer grids (Settings.finer_grids; the "
                        'full run then takes about 8 min with the one-step costs cached, 20 '
                        'cold)')
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
        results = run(robot, settings, log, convergence_grids=options.convergence)
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
