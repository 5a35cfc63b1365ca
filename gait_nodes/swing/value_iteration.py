"""Minimum-time swing-leg value iteration under a joint velocity limit (thesis 000, III.C).

Bellman's equation without discount (thesis eq. (1) with gamma = 1)::

    V(s) = min_a { C(s, s') + V(s') },   s' = clamp(s + a),   V(goal) = 0

with ``C(s, s') = max_j |q_j(s') - q_j(s)| / W`` (the fastest joint saturated at the limit ``W``,
IK of one family at both ends), ``V(s')`` interpolated multilinearly between the nodes and
``s + a`` brought back onto the grid. Infeasible states (IK fails, singular, beyond a joint
limit) cost :data:`~gait_nodes.swing.kinematics.INFEASIBLE_S`. The sweeps stop when no value
changes by more than ``tolerance_s`` (1e-4 s, thesis Appendix A). The lift time from the ground
is then computed for every state and the lowering time at the goal (thesis III.C.1).

Implementation: the IK of every node and of every clamped ``s + a`` is computed once, giving the
one-step costs ``C[a, s]``. For one action ``a`` the point ``s + a`` lies at the same offset from
every node along each axis (up to the clamping), so interpolating V at all ``s + a`` is four
1-D linear interpolations of the whole array, one per axis: each sweep is pure array
arithmetic, O(A * S), with no per-state gather of 16 corners.

Unlike the thesis, values start at :data:`INFEASIBLE_S` (not 0) and decrease: states that cannot
reach the goal then keep that value instead of growing without bound, and the sweeps converge.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import SwingTableError
from gait_nodes.swing.grid import SwingActions, SwingGrid, axis_weights, make_grid
from gait_nodes.swing.kinematics import INFEASIBLE_S, LimbTiming, urdf_sha256
from gait_nodes.swing.table import ValueTable

#: Stop when no value changes by more than this in a sweep [s] (thesis Appendix A).
TOLERANCE_S = 1e-4


@dataclass(frozen=True)
class GridSpec:
    """How to lay out the grid around the swing plane (defaults: a build of a few seconds).

    The thesis' region for the front-right foot of RoboSimian is x 0.2-0.8 m, y -0.65 to
    -0.4 m (IV.B.1). Finer options: ``x_range_m=(0.2, 0.8, 31)``, ``y_range_m=(-0.65, -0.4,
    14)``, ``z_levels=7``, ``yaw_range_rad=(-0.45, 0.45, 11)`` (33,418 states).

    Attributes:
        x_range_m: ``(min, max, count)`` [m].
        y_range_m: ``(min, max, count)`` [m].
        z_levels: z levels from the swing plane (ground + step height) up.
        z_spacing_m: Their spacing [m].
        yaw_range_rad: ``(min, max, count)`` [rad].
    """

    x_range_m: tuple[float, float, int] = (0.2, 0.8, 13)
    y_range_m: tuple[float, float, int] = (-0.65, -0.4, 11)
    z_levels: int = 3
    z_spacing_m: float = 0.05
    yaw_range_rad: tuple[float, float, int] = (-0.3, 0.3, 5)


def default_goal(robot, step_height_m: float, step_length_m: float = 0.3) -> np.ndarray:
    """Landing place of the front-right foot in a steady crawl, body-relative (4,).

    Half a stride ahead of the nominal foot position, on the swing plane, yaw 0.
    """
    foot = robot.description.feet[0]
    for candidate in robot.description.feet:
        nominal = candidate.nominal_position_in_base
        if nominal[0] > 0 and nominal[1] < 0:
            foot = candidate
    nominal = np.abs(foot.nominal_position_in_base) * np.array([1.0, -1.0, 1.0])
    return np.array([nominal[0] + 0.5 * step_length_m, nominal[1],
                     -robot.description.body_height_m + step_height_m, 0.0])


def one_step_costs(timing: LimbTiming, grid: SwingGrid, displacements: np.ndarray,
                   progress: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """One-step cost ``C[a, s]`` [s] of every action from every node, and node feasibility.

    Returns:
        ``(costs, feasible)``: (A, S) times with the fastest joint at the limit
        (:data:`INFEASIBLE_S` when either end is infeasible) and (S,) booleans.
    """
    from tqdm import tqdm

    states = grid.points()
    q, feasible = timing.joints(states)
    costs = np.empty((len(displacements), len(states)))
    for a, move in enumerate(tqdm(displacements, desc='one-step costs', unit='action',
                                  disable=not progress, leave=False)):
        q_next, ok = timing.joints(grid.clamp(states + move))
        costs[a] = np.where(feasible & ok, timing.move_time(q, q_next), INFEASIBLE_S)
    return costs, feasible


def _action_weights(grid: SwingGrid, move: np.ndarray) -> list:
    """Per axis: None when ``s + a`` lands on the nodes themselves, else ``(lo, hi, f)``."""
    result = []
    for axis, delta in zip(grid.axes, move, strict=True):
        lo, hi, f = axis_weights(axis, axis + delta)
        identity = np.arange(len(axis))
        if np.all(f == 0) and np.array_equal(lo, identity):
            result.append(None)
        elif np.all(f == 1) and np.array_equal(hi, identity):
            result.append(None)
        else:
            result.append((lo, hi, f))
    return result


def _interpolate_shifted(values: np.ndarray, weights: list) -> np.ndarray:
    """V at ``s + a`` for every node: one 1-D linear interpolation per axis."""
    out = values
    for d, w in enumerate(weights):
        if w is None:
            continue
        lo, hi, f = w
        shape = [1, 1, 1, 1]
        shape[d] = -1
        f = f.reshape(shape)
        out = np.take(out, lo, axis=d) * (1.0 - f) + np.take(out, hi, axis=d) * f
    return out


def bellman_backup(values: np.ndarray, costs: np.ndarray, weights: list) -> np.ndarray:
    """``min_a {C[a] + V(s + a)}`` at every node (grid-shaped)."""
    best = np.full(values.shape, np.inf)
    for a, w in enumerate(weights):
        candidate = costs[a].reshape(values.shape) + _interpolate_shifted(values, w)
        np.minimum(best, candidate, out=best)
    return best


@dataclass(frozen=True)
class BuildReport:
    """Figures of one build.

    Attributes:
        states: Number of grid states.
        actions: Number of actions.
        iterations: Sweeps until convergence.
        max_change_s: Largest value change of the last sweep [s].
        cost_seconds: Wall time of the IK and one-step costs [s].
        iteration_seconds: Wall time of the sweeps [s].
    """

    states: int
    actions: int
    iterations: int
    max_change_s: float
    cost_seconds: float
    iteration_seconds: float

    @property
    def state_actions_per_second(self) -> float:
        """States x actions x sweeps per second of sweeping."""
        return self.states * self.actions * self.iterations / max(self.iteration_seconds, 1e-9)


def value_iteration(timing: LimbTiming, grid: SwingGrid, actions: SwingActions,
                    goal_index: tuple[int, int, int, int], tolerance_s: float = TOLERANCE_S,
                    max_iterations: int = 5000, progress: bool = False
                    ) -> tuple[np.ndarray, BuildReport]:
    """Converged cost-to-go ``V`` on the grid (see the module docstring).

    Returns:
        ``(values, report)``: grid-shaped V [s] and the build figures.

    Raises:
        SwingTableError: The goal is infeasible, or no convergence within ``max_iterations``.
    """
    from tqdm import tqdm

    started = time.perf_counter()
    displacements = actions.displacements()
    costs, feasible = one_step_costs(timing, grid, displacements, progress)
    feasible = feasible.reshape(grid.shape)
    if not feasible[goal_index]:
        raise SwingTableError(f'the goal {grid.points().reshape(*grid.shape, 4)[goal_index]} '
                              f'is not reachable in IK family {timing.family}')
    weights = [_action_weights(grid, move) for move in displacements]
    cost_seconds = time.perf_counter() - started

    started = time.perf_counter()
    values = np.full(grid.shape, INFEASIBLE_S)
    values[goal_index] = 0.0
    change = np.inf
    bar = tqdm(total=max_iterations, desc='value iteration', unit='sweep', disable=not progress,
               leave=False)
    iterations = 0
    try:
        while change > tolerance_s:
            if iterations >= max_iterations:
                raise SwingTableError(f'value iteration did not converge in {max_iterations} '
                                      f'sweeps (last change {change:.3g} s > {tolerance_s} s)')
            updated = bellman_backup(values, costs, weights)
            updated[~feasible] = INFEASIBLE_S
            np.minimum(updated, INFEASIBLE_S, out=updated)
            updated[goal_index] = 0.0
            change = float(np.abs(updated - values).max())
            values = updated
            iterations += 1
            bar.update(1)
            bar.set_postfix(change_s=f'{change:.2e}')
    finally:
        bar.close()
    report = BuildReport(grid.size, len(displacements), iterations, change, cost_seconds,
                         time.perf_counter() - started)
    return values, report


def build_table(robot, family: int, step_height_m: float, joint_velocity_limit_rad_s: float,
                grid_spec: GridSpec | None = None, actions: SwingActions | None = None,
                goal: np.ndarray | None = None, tolerance_s: float = TOLERANCE_S,
                progress: bool = False) -> tuple[ValueTable, BuildReport]:
    """Build a swing-leg value table for a robot, IK family, step height and limit.

    Args:
        robot: :class:`gait_nodes.robot.model.RobotModel` with RoboSimian's limb IK.
        family: IK family 0..7.
        step_height_m: Swing plane above the ground [m] (lift and lowering distance).
        joint_velocity_limit_rad_s: The limit every joint saturates at [rad/s].
        grid_spec: Grid layout (default :class:`GridSpec`).
        actions: Action set (default :class:`SwingActions`).
        goal: (4,) goal (x, y, z, yaw) of the front-right foot in the base frame; default
            :func:`default_goal`. Its z must be on the swing plane or a level above it.
        tolerance_s: Convergence threshold [s].
        progress: Show tqdm progress bars.

    Raises:
        SwingTableError: Bad settings, an unreachable goal, or no convergence.
    """
    if not (isinstance(step_height_m, (int, float)) and 0 < step_height_m < 1.0):
        raise SwingTableError(f'step height must be in (0, 1) m, got {step_height_m!r}')
    timing = LimbTiming(robot, family, joint_velocity_limit_rad_s)
    grid_spec = grid_spec or GridSpec()
    actions = actions or SwingActions()
    swing_z = timing.ground_z_m + step_height_m
    goal = default_goal(robot, step_height_m) if goal is None else np.array(goal, dtype=float)
    if goal.shape != (4,) or not np.all(np.isfinite(goal)):
        raise SwingTableError(f'goal must be 4 finite numbers (x, y, z, yaw), got {goal}')
    grid = make_grid(grid_spec.x_range_m, grid_spec.y_range_m, grid_spec.z_levels,
                     grid_spec.z_spacing_m, grid_spec.yaw_range_rad, swing_z, goal)
    goal_index = grid.nearest_node(goal)
    goal = np.array([a[i] for a, i in zip(grid.axes, goal_index, strict=True)])
    values, report = value_iteration(timing, grid, actions, goal_index, tolerance_s,
                                     progress=progress)
    lift = timing.vertical_times(grid.points()).reshape(grid.shape)
    lower = float(timing.vertical_times(goal[None])[0])
    if lower >= INFEASIBLE_S:
        raise SwingTableError(f'the foot cannot be lowered from the goal {goal.round(4)} to '
                              f'the ground in IK family {family}')
    table = ValueTable(
        robot_name=robot.name, urdf_sha256=urdf_sha256(robot.description.urdf_path),
        family=int(family), joint_velocity_limit_rad_s=float(joint_velocity_limit_rad_s),
        step_height_m=float(step_height_m), ground_z_m=timing.ground_z_m, grid=grid,
        actions=actions, goal=goal, values_s=values, lift_s=lift, lower_s=lower,
        iterations=report.iterations, max_change_s=report.max_change_s)
    return table, report
