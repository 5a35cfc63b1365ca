"""Step size against crawl speed (thesis 000, IV.B.3-6) and the perturbation test (IV.B.7).

Gait speed of a crawl, thesis eq. (2)::

    speed = step / (4 * T_swing + (T_swing - T_up - T_down))

four swings one after the other plus the body's move, which takes as long as the swing's
horizontal part. For one goal (landing place) the start of the swing is a grid node on the line
through the goal along x (same y and z, thesis IV.B.3), its yaw the best one (Appendix A), and
the step is the x distance. Several goals give several curves; for each step the fastest counts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from gait_nodes.errors import GaitNodesError
from gait_nodes.swing.kinematics import FEASIBLE_BELOW_S
from gait_nodes.swing.policy import SwingPath, SwingPolicy
from gait_nodes.swing.table import ValueTable

#: (ft/min) per (m/s).
FT_PER_MIN = 60.0 / 0.3048
#: How an optimum on the first or last step of a curve is named.
END_OF_RANGE = 'at the end of the range, not an interior optimum'


def gait_speed_m_s(step_m, swing_s, lift_s, lower_s):
    """Crawl speed [m/s] of thesis eq. (2) (works on arrays)."""
    swing_s = np.asarray(swing_s, dtype=float)
    return np.asarray(step_m, dtype=float) / (4.0 * swing_s + (swing_s - lift_s - lower_s))


@dataclass(frozen=True)
class SpeedCurve:
    """Crawl speed against step size for one table.

    Attributes:
        steps_m: (K,) step sizes [m], increasing.
        speeds_m_s: (K,) eq. (2) speeds [m/s].
        swing_s: (K,) whole swing times (lift + move + lowering) [s].
        starts: (K, 4) start states.
    """

    steps_m: np.ndarray
    speeds_m_s: np.ndarray
    swing_s: np.ndarray
    starts: np.ndarray

    @property
    def best(self) -> int:
        """Index of the fastest step."""
        return int(np.argmax(self.speeds_m_s))

    @property
    def best_is_interior(self) -> bool:
        """The fastest step has a step on either side (it is not the first or last one)."""
        return 0 < self.best < len(self.steps_m) - 1


def describe_optimum(curve: SpeedCurve) -> str:
    """``'0.56 m (interior), 8.893 ft/min'``; an optimum at an end says :data:`END_OF_RANGE`."""
    if not len(curve.steps_m) or curve.speeds_m_s[curve.best] <= 0:
        return 'no feasible step'
    k = curve.best
    where = 'interior' if curve.best_is_interior else END_OF_RANGE
    return f'{curve.steps_m[k]:.2f} m ({where}), {curve.speeds_m_s[k] * FT_PER_MIN:.3f} ft/min'


def speed_curve(table: ValueTable) -> SpeedCurve:
    """Speed of every start node behind the goal on the goal's x line (table values only)."""
    grid = table.grid
    ix, iy, iz, _ = grid.nearest_node(table.goal)
    totals = table.total_s[:ix, iy, iz, :]           # (x nodes behind the goal, yaw)
    best_yaw = np.argmin(totals, axis=1)
    rows = np.arange(ix)
    swing = totals[rows, best_yaw]
    lift = table.lift_s[:ix, iy, iz, :][rows, best_yaw]
    steps = table.goal[0] - grid.x_m[:ix]
    feasible = swing < FEASIBLE_BELOW_S
    speeds = np.where(feasible, gait_speed_m_s(steps, swing, lift, table.lower_s), 0.0)
    starts = np.column_stack([grid.x_m[:ix], np.full(ix, grid.y_m[iy]), np.full(ix, grid.z_m[iz]),
                              grid.yaw_rad[best_yaw]])
    order = np.argsort(steps)
    return SpeedCurve(steps[order], speeds[order], swing[order], starts[order])


def envelope(curves: list[SpeedCurve], resolution_m: float = 1e-6) -> SpeedCurve:
    """The fastest curve over several goals, per step size."""
    steps = np.concatenate([c.steps_m for c in curves])
    keys = np.round(steps / resolution_m).astype(np.int64)
    speeds = np.concatenate([c.speeds_m_s for c in curves])
    swing = np.concatenate([c.swing_s for c in curves])
    starts = np.vstack([c.starts for c in curves])
    picked = []
    for key in np.unique(keys):
        rows = np.flatnonzero(keys == key)
        picked.append(rows[int(np.argmax(speeds[rows]))])
    picked = np.array(picked, dtype=int)
    return SpeedCurve(steps[picked], speeds[picked], swing[picked], starts[picked])


def path_speed_m_s(policy: SwingPolicy, swing_states: np.ndarray) -> float:
    """Eq. (2) speed [m/s] of grid waypoints timed at the limit (lift and lowering added)."""
    path = policy.timed_path(swing_states)
    step = float(swing_states[-1, 0] - swing_states[0, 0])
    return float(gait_speed_m_s(step, path.duration_s, path.lift_s, path.lower_s))


@dataclass(frozen=True)
class PerturbationResult:
    """Speeds of randomly perturbed copies of a path (thesis IV.B.7, Fig. 20).

    Attributes:
        mode: Perturbed axes: 'x', 'y', 'z' or 'xyz'.
        optimal_m_s: Speed of the unperturbed path [m/s].
        speeds_m_s: (N,) speeds of the perturbed paths [m/s].
    """

    mode: str
    optimal_m_s: float
    speeds_m_s: np.ndarray

    @property
    def mean_loss_m_s(self) -> float:
        """Mean speed lost by perturbing [m/s] (positive: the path was better)."""
        return float(self.optimal_m_s - np.mean(self.speeds_m_s))

    @property
    def slower_fraction(self) -> float:
        """Share of the perturbed paths slower than the path."""
        return float(np.mean(self.speeds_m_s < self.optimal_m_s))


PERTURBATION_AXES = {'x': [0], 'y': [1], 'z': [2], 'xyz': [0, 1, 2]}


def perturbation_test(policy: SwingPolicy, path: SwingPath, trials: int = 50,
                      amplitude_m: float = 0.02, seed: int = 0) -> list[PerturbationResult]:
    """Perturb the path's inner waypoints at random in x, y, z and xyz; time each copy.

    The first and last grid waypoints (where the foot is lifted and lowered) stay, so the step
    is unchanged; each inner waypoint moves by a uniform random amount in
    ``[-amplitude_m, amplitude_m]`` along the perturbed axes. Infeasible copies are redrawn.
    """
    rng = np.random.default_rng(seed)
    states = path.swing_states
    optimal = path_speed_m_s(policy, states)
    results = []
    for mode, axes in PERTURBATION_AXES.items():
        speeds = []
        attempts = 0
        while len(speeds) < trials and attempts < 20 * trials:
            attempts += 1
            copy = states.copy()
            noise = rng.uniform(-amplitude_m, amplitude_m, (len(states) - 2, len(axes)))
            copy[1:-1, axes] += noise
            _, feasible = policy.timing.joints(copy)
            if not feasible.all():
                continue
            speeds.append(path_speed_m_s(policy, copy))
        results.append(PerturbationResult(mode, optimal, np.array(speeds)))
    return results


def centred(curves: list[SpeedCurve], centre_x_m: float, tolerance_m: float = 1e-6
            ) -> SpeedCurve:
    """Per step, the swing centred on ``centre_x_m``: start ``c - s/2``, goal ``c + s/2``.

    The thesis sets the goal's x differently for each step size (IV.B.3) without saying where;
    centring every swing on one x (e.g. the middle of the grid's x range) is our reading.
    Curves of several goals give one point each (where their start is the mirror of their goal
    about the centre).
    """
    picked = [c for c in curves if len(c.steps_m)]
    steps = np.concatenate([c.steps_m for c in picked])
    starts = np.vstack([c.starts for c in picked])
    speeds = np.concatenate([c.speeds_m_s for c in picked])
    swing = np.concatenate([c.swing_s for c in picked])
    rows = np.flatnonzero(np.abs(starts[:, 0] + 0.5 * steps - centre_x_m) < tolerance_m)
    rows = rows[np.argsort(steps[rows])]
    return SpeedCurve(steps[rows], speeds[rows], swing[rows], starts[rows])


@dataclass
class SweepTables:
    """Value tables by ``(family, step height, goal x)``, their speed curves, the goals skipped.

    Attributes:
        tables: ``(family, step height [m], goal x [m]) -> ValueTable``.
        curves: Same keys ``-> SpeedCurve`` (:func:`speed_curve`).
        skipped: ``(family, goal x [m], reason)`` of the goals without a table.
    """

    tables: dict = field(default_factory=dict)
    curves: dict = field(default_factory=dict)
    skipped: list = field(default_factory=list)

    def centred(self, family: int, step_height_m: float, centre_x_m: float) -> SpeedCurve:
        """The swings centred on ``centre_x_m`` of one family and step height (:func:`centred`)."""
        return centred(self._curves(family, step_height_m), centre_x_m)

    def anywhere(self, family: int, step_height_m: float) -> SpeedCurve:
        """The fastest swing of each step over every goal (:func:`envelope`)."""
        return envelope(self._curves(family, step_height_m))

    def owner(self, family: int, step_height_m: float, curve: SpeedCurve) -> ValueTable:
        """The table of the curve's fastest step (its goal: start x + step)."""
        goal_x = curve.starts[curve.best, 0] + curve.steps_m[curve.best]
        for (f, h, gx), table in self.tables.items():
            if f == family and h == step_height_m and abs(gx - goal_x) < 1e-9:
                return table
        raise GaitNodesError(f'no table with goal x {goal_x:.3f} m for family {family}, step '
                             f'height {step_height_m:g} m')

    def _curves(self, family, step_height_m):
        curves = [c for (f, h, _), c in self.curves.items()
                  if f == family and h == step_height_m]
        if not curves:
            raise GaitNodesError(f'no value table for family {family}, step height '
                                 f'{step_height_m:g} m')
        return curves


def centred_goal_xs(x_axis_m: np.ndarray, centre_x_m: float) -> list[float]:
    """The x nodes ahead of ``centre_x_m`` whose mirror about it is a node too [m].

    Each gives one swing centred on ``centre_x_m`` (:func:`centred`).
    """
    x_axis_m = np.asarray(x_axis_m, dtype=float)
    return [float(x) for x in x_axis_m if x > centre_x_m + 1e-9
            and np.min(np.abs(x_axis_m - (2 * centre_x_m - x))) < 1e-9]


def sweep_tables(robot, families, step_heights_m, grid_spec, actions, goals,
                 joint_velocity_limit_rad_s: float,
                 log: Callable[[str], None] | None = None) -> SweepTables:
    """One value table per family and goal, with the lift and lowering of every step height.

    The thesis' setting (000, IV.B.3-5): the swing plane and the goal are where ``goals`` put
    them, and the foot is lifted from and lowered to the ground ``step height`` below the goal
    (the value iteration, which does not depend on the step height, runs once per goal). The
    one-step costs are shared by every goal on the same grid and cached
    (:func:`~gait_nodes.swing.cache.cached_one_step_costs`); so are the lift times of each
    step height (:func:`~gait_nodes.swing.value_iteration.lift_times`).

    Args:
        robot: The RobotModel.
        families: IK families 0..7.
        step_heights_m: Step heights [m].
        grid_spec: :class:`~gait_nodes.swing.value_iteration.GridSpec`; with ``z_levels``
            (no ``z_planes_m``) the levels start at the goal's z.
        actions: :class:`~gait_nodes.swing.grid.SwingActions`.
        goals: (G, 4) goals (x, y, z, yaw) in the base frame.
        joint_velocity_limit_rad_s: Joint velocity limit [rad/s].
        log: Called with progress messages.
    """
    import time

    from gait_nodes.swing.cache import cached_one_step_costs
    from gait_nodes.swing.kinematics import LimbTiming
    from gait_nodes.swing.value_iteration import (
        build_table,
        lift_times,
        table_grid,
        with_step_height,
    )

    result = SweepTables()
    displacements = actions.displacements()
    lifts = {}

    def lift(family, grid, key, ground_z_m):
        """The grid's lift times (``key``: its axes) from a ground, computed once."""
        if (family, key, ground_z_m) not in lifts:
            lifts[family, key, ground_z_m] = lift_times(
                LimbTiming(robot, family, joint_velocity_limit_rad_s, ground_z_m), grid)
        return lifts[family, key, ground_z_m]

    for family in families:
        started = time.perf_counter()
        costs = {}
        for goal in np.atleast_2d(np.asarray(goals, dtype=float)):
            goal_x = float(goal[0])
            grounds = {h: float(goal[2]) - h for h in step_heights_m}
            first = step_heights_m[0]
            try:
                grid = table_grid(robot, first, grid_spec, goal, grounds[first])
                key = b''.join(axis.tobytes() for axis in grid.axes)
                if key not in costs:
                    costs[key] = cached_one_step_costs(
                        robot, family, joint_velocity_limit_rad_s, grid, displacements, log)
                table, _ = build_table(robot, family, first, joint_velocity_limit_rad_s,
                                       grid_spec, actions, goal, ground_z_m=grounds[first],
                                       costs=costs[key],
                                       lift_s=lift(family, grid, key, grounds[first]))
            except GaitNodesError as exc:
                result.skipped.append((family, goal_x, str(exc)))
                continue
            for height in step_heights_m:
                try:
                    tab = with_step_height(table, robot, height, grounds[height],
                                           lift(family, table.grid, key, grounds[height]))
                except GaitNodesError as exc:
                    result.skipped.append((family, goal_x, str(exc)))
                    continue
                result.tables[family, height, goal_x] = tab
                result.curves[family, height, goal_x] = speed_curve(tab)
        if log is not None:
            log(f'family {family}: {len(goals)} goals in {time.perf_counter() - started:.1f} s')
    return result
