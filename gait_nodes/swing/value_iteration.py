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
arithmetic, O(A * S), with no per-state gather of 16 corners. Actions that move alike along x
(then x and y, then x, y and z) share those interpolations (:func:`interpolation_tree`).

Unlike the thesis, values start at :data:`INFEASIBLE_S` (not 0) and decrease: states that cannot
reach the goal then keep that value instead of growing without bound, and the sweeps converge.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from gait_nodes.errors import SwingTableError
from gait_nodes.swing.grid import SwingActions, SwingGrid, axis_weights, make_grid
from gait_nodes.swing.kinematics import INFEASIBLE_S, LimbTiming, urdf_sha256
from gait_nodes.swing.table import ValueTable

#: Stop when no value changes by more than this in a sweep [s] (thesis Appendix A).
TOLERANCE_S = 1e-4
#: Points ``s + a`` whose IK :func:`one_step_costs` solves in one batch (8 MB of states), each
#: distinct one once.
IK_BATCH_POINTS = 250_000
#: The thesis' swing planes: 0.7 and 0.6 m below the centre of body [m] (000, IV.B.1).
THESIS_Z_PLANES_M = (-0.7, -0.6)
#: The thesis' goal of the front-right foot: y and z of the swing's start (000, IV.B.3) [m].
THESIS_GOAL_Y_M = -0.5
THESIS_GOAL_Z_M = -0.6
#: The thesis' step heights: the lift and the lowering, straight along z [m] (000, IV.B.5).
THESIS_STEP_HEIGHTS_M = (0.1, 0.06)


def thesis_actions() -> SwingActions:
    """The thesis' actions: points on spheres of several radii with a yaw change (III.C.1).

    Several radii, from half a node spacing to a few, so that small moves near the goal exist
    (thesis IV.B.2, Fig. 13); 16 azimuths; elevations 0 and +-0.5 rad (a move between the two
    swing planes, 0.1 m apart, lands between them and is interpolated); yaw changes of one yaw
    node. The thesis does not give its counts: these are ours.
    """
    return SwingActions(radii_m=(0.025, 0.05, 0.1, 0.2), azimuth_count=16,
                        elevations_rad=(-0.5, 0.0, 0.5), yaw_steps_rad=(-0.15, 0.0, 0.15))


def thesis_goal(goal_x_m: float) -> np.ndarray:
    """(4,) goal of the thesis' sweep: x given, y -0.5 m, z -0.6 m, yaw 0 (000, IV.B.3)."""
    return np.array([float(goal_x_m), THESIS_GOAL_Y_M, THESIS_GOAL_Z_M, 0.0])


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
        z_planes_m: Explicit z levels in the base frame [m], overriding ``z_levels`` and
            ``z_spacing_m`` (the thesis' two planes, :data:`THESIS_Z_PLANES_M`); None: levels
            from the swing plane up.
    """

    x_range_m: tuple[float, float, int] = (0.2, 0.8, 13)
    y_range_m: tuple[float, float, int] = (-0.65, -0.4, 11)
    z_levels: int = 3
    z_spacing_m: float = 0.05
    yaw_range_rad: tuple[float, float, int] = (-0.3, 0.3, 5)
    z_planes_m: tuple[float, ...] | None = None

    @classmethod
    def thesis(cls, x_count: int = 31, y_count: int = 11, yaw_count: int = 7) -> GridSpec:
        """The thesis' value-iteration mesh for RoboSimian's front-right limb (000, IV.B.1).

        x 0.2-0.8 m and y -0.65 to -0.4 m in the body frame, the two swing planes 0.6 and
        0.7 m below the centre of body (the swing, and the body's move, which is a swing 0.1 m
        lower: thesis IV.B.1), yaw +-0.45 rad. The thesis gives the ranges, not the node
        counts; the defaults put nodes 0.02 m apart in x, 0.025 m in y (so that the goal's
        y = -0.5 m is a node) and 0.15 rad in yaw (one action yaw step).

        Args:
            x_count: Nodes along x.
            y_count: Nodes along y (11 and 6 put a node at the goal's -0.5 m; other counts
                have the nearest node moved onto it by :func:`make_grid`).
            yaw_count: Nodes along yaw.
        """
        return cls(x_range_m=(0.2, 0.8, x_count), y_range_m=(-0.65, -0.4, y_count),
                   yaw_range_rad=(-0.45, 0.45, yaw_count), z_planes_m=THESIS_Z_PLANES_M)


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

    The IK of the clamped ``s + a`` is solved :data:`IK_BATCH_POINTS` points at a time, each
    distinct point of a batch once: many coincide (moves clamped onto the same point at the
    mesh's edges, several actions reaching the same place), and the IK of a point does not
    depend on the others solved with it (but in the last bits: its roots are polished for a
    whole chunk at once), so the costs are those of solving every point. On the default grid
    and actions (2,145 states x 218 actions) 42 % of the points are distinct.

    Returns:
        ``(costs, feasible)``: (A, S) times with the fastest joint at the limit
        (:data:`INFEASIBLE_S` when either end is infeasible) and (S,) booleans.
    """
    from tqdm import tqdm

    states = grid.points()
    q, feasible = timing.joints(states)
    costs = np.empty((len(displacements), len(states)))
    per_batch = max(1, IK_BATCH_POINTS // len(states))
    with tqdm(total=len(displacements), desc='one-step costs', unit='action',
              disable=not progress, leave=False) as bar:
        for first in range(0, len(displacements), per_batch):
            moves = displacements[first:first + per_batch]
            following = grid.clamp(states[None, :, :] + moves[:, None, :]).reshape(-1, 4)
            distinct, inverse = np.unique(following, axis=0, return_inverse=True)
            q_distinct, ok_distinct = timing.joints(distinct)
            inverse = inverse.reshape(len(moves), len(states))
            costs[first:first + len(moves)] = np.where(
                feasible & ok_distinct[inverse],
                timing.move_time(q, q_distinct[inverse]), INFEASIBLE_S)
            bar.update(len(moves))
    return costs, feasible


def _action_weights(grid: SwingGrid, move: np.ndarray) -> list:
    """Per axis: None when ``s + a`` lands on the nodes themselves, else ``(lo, hi, f)``.

    On the nodes themselves: every node's whole weight on that node (also where a move
    clamped at the mesh's edge puts the last node's weight on its upper neighbour: ``f = 1``
    there, 0 elsewhere). Interpolating would then give V itself exactly (V is finite and
    >= 0), so the axis is skipped.
    """
    result = []
    for axis, delta in zip(grid.axes, move, strict=True):
        lo, hi, f = axis_weights(axis, axis + delta)
        identity = np.arange(len(axis))
        if np.all(((f == 0) & (lo == identity)) | ((f == 1) & (hi == identity))):
            result.append(None)
        else:
            result.append((lo, hi, f))
    return result


def interpolation_tree(weights: list) -> dict:
    """The actions' interpolations (:func:`_action_weights`) as a tree over the axes.

    Level ``d`` has one node per distinct way of moving along axes 0..d (x, then y, z and
    yaw): the actions that move alike along x share the interpolation along x, those that also
    move alike along y the one along y, and so on. On the thesis' grid and actions (31 x 11 x 2
    x 7 nodes, 578 actions) a sweep then interpolates 690 arrays instead of 2,312 (254 instead
    of 872 on the default grid and actions), with the same arithmetic: the same values.

    Returns:
        ``{key: [axis_weights, children, actions]}``: ``axis_weights`` None (V itself) or
        ``(axis, lo, hi, 1 - f, f)`` with ``f`` shaped to broadcast along ``axis``;
        ``children`` the next axis' nodes; ``actions`` the indices of the actions whose moves
        end at this node (on the last axis).
    """
    tree = {}
    for action, per_axis in enumerate(weights):
        level = tree
        for d, w in enumerate(per_axis):
            if w is None:
                key = prepared = None
            else:
                lo, hi, f = w
                key = (lo.tobytes(), hi.tobytes(), f.tobytes())
                shape = [1] * len(per_axis)
                shape[d] = -1
                f = f.reshape(shape)
                prepared = (d, lo, hi, 1.0 - f, f)
            node = level.setdefault(key, [prepared, {}, []])
            if d == len(per_axis) - 1:
                node[2].append(action)
            level = node[1]
    return tree


def _interpolate_axis(values: np.ndarray, prepared) -> np.ndarray:
    """V at ``s + a`` along one axis (``prepared``: an :func:`interpolation_tree` node's)."""
    if prepared is None:
        return values
    d, lo, hi, lower_weight, f = prepared
    return np.take(values, lo, axis=d) * lower_weight + np.take(values, hi, axis=d) * f


def bellman_backup(values: np.ndarray, costs: np.ndarray, tree: dict) -> np.ndarray:
    """``min_a {C[a] + V(s + a)}`` at every node (grid-shaped).

    ``V(s + a)``: four 1-D linear interpolations of V, along x, y, z and yaw, shared by the
    actions of each node of ``tree`` (:func:`interpolation_tree`).
    """
    best = np.full(values.shape, np.inf)

    def descend(shifted: np.ndarray, level: dict) -> None:
        for prepared, children, actions in level.values():
            out = _interpolate_axis(shifted, prepared)
            for action in actions:
                np.minimum(best, costs[action].reshape(values.shape) + out, out=best)
            descend(out, children)

    descend(values, tree)
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
                    max_iterations: int = 5000, progress: bool = False,
                    costs: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray, BuildReport]:
    """Converged cost-to-go ``V`` on the grid (see the module docstring).

    Args:
        timing: IK and move times of one family at a limit.
        grid: The state mesh.
        actions: The action set.
        goal_index: The goal's node (its value held at 0).
        tolerance_s: Stop when no value changes by more than this in a sweep [s].
        max_iterations: Most sweeps.
        progress: Show a tqdm progress bar.
        costs: ``(costs, feasible)`` of :func:`one_step_costs` for this timing, grid and
            actions, when already computed (they do not depend on the goal); None: computed.

    Returns:
        ``(values, report)``: grid-shaped V [s] and the build figures.

    Raises:
        SwingTableError: The goal is infeasible, or no convergence within ``max_iterations``.
    """
    from tqdm import tqdm

    started = time.perf_counter()
    displacements = actions.displacements()
    if costs is None:
        costs = one_step_costs(timing, grid, displacements, progress)
    costs, feasible = costs
    if costs.shape != (len(displacements), grid.size):
        raise SwingTableError(f'one-step costs of shape {costs.shape} do not match '
                              f'{len(displacements)} actions x {grid.size} states')
    feasible = feasible.reshape(grid.shape)
    if not feasible[goal_index]:
        raise SwingTableError(f'the goal {grid.points().reshape(*grid.shape, 4)[goal_index]} '
                              f'is not reachable in IK family {timing.family}')
    tree = interpolation_tree([_action_weights(grid, move) for move in displacements])
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
            updated = bellman_backup(values, costs, tree)
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
                progress: bool = False, ground_z_m: float | None = None,
                costs: tuple[np.ndarray, np.ndarray] | None = None,
                lift_s: np.ndarray | None = None) -> tuple[ValueTable, BuildReport]:
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
        ground_z_m: Ground height in the base frame [m], where the lift starts and the
            lowering ends; None: ``-body_height_m`` of the robot YAML. The thesis lifts the
            foot by the step height below the swing plane (``goal z - step height``).
        costs: Precomputed one-step costs for this family, limit, grid and actions
            (:func:`one_step_costs`); they do not depend on the goal.
        lift_s: Precomputed lift times for this family, limit, grid and ground
            (:func:`lift_times`); they do not depend on the goal either.

    Raises:
        SwingTableError: Bad settings, an unreachable goal, or no convergence.
    """
    if not (isinstance(step_height_m, (int, float)) and 0 < step_height_m < 1.0):
        raise SwingTableError(f'step height must be in (0, 1) m, got {step_height_m!r}')
    timing = LimbTiming(robot, family, joint_velocity_limit_rad_s, ground_z_m)
    grid = table_grid(robot, step_height_m, grid_spec, goal, timing.ground_z_m)
    goal = grid_goal(robot, step_height_m, grid, goal)
    goal_index = grid.nearest_node(goal)
    actions = actions or SwingActions()
    values, report = value_iteration(timing, grid, actions, goal_index, tolerance_s,
                                     progress=progress, costs=costs)
    table = ValueTable(
        robot_name=robot.name, urdf_sha256=urdf_sha256(robot.description.urdf_path),
        family=int(family), joint_velocity_limit_rad_s=float(joint_velocity_limit_rad_s),
        step_height_m=float(step_height_m), ground_z_m=timing.ground_z_m, grid=grid,
        actions=actions, goal=goal, values_s=values, lift_s=np.zeros(grid.shape),
        lower_s=0.0, iterations=report.iterations, max_change_s=report.max_change_s)
    return with_step_height(table, robot, step_height_m, timing.ground_z_m, lift_s), report


def table_grid(robot, step_height_m: float, grid_spec: GridSpec | None = None,
               goal: np.ndarray | None = None, ground_z_m: float | None = None) -> SwingGrid:
    """The grid :func:`build_table` lays out (the goal a node), e.g. to share one-step costs.

    Args as :func:`build_table`; ``ground_z_m`` None is ``-body_height_m``.
    """
    grid_spec = grid_spec or GridSpec()
    ground = -float(robot.description.body_height_m) if ground_z_m is None else ground_z_m
    goal = default_goal(robot, step_height_m) if goal is None else np.array(goal, dtype=float)
    if goal.shape != (4,) or not np.all(np.isfinite(goal)):
        raise SwingTableError(f'goal must be 4 finite numbers (x, y, z, yaw), got {goal}')
    return make_grid(grid_spec.x_range_m, grid_spec.y_range_m, grid_spec.z_levels,
                     grid_spec.z_spacing_m, grid_spec.yaw_range_rad, ground + step_height_m,
                     goal, z_planes_m=grid_spec.z_planes_m)


def grid_goal(robot, step_height_m: float, grid: SwingGrid, goal: np.ndarray | None = None
              ) -> np.ndarray:
    """(4,) the goal as the grid's node (default :func:`default_goal`)."""
    goal = default_goal(robot, step_height_m) if goal is None else np.array(goal, dtype=float)
    index = grid.nearest_node(goal)
    return np.array([a[i] for a, i in zip(grid.axes, index, strict=True)])


def lift_times(timing: LimbTiming, grid: SwingGrid) -> np.ndarray:
    """Time [s] to lift the foot from the ground straight up to each node (grid-shaped).

    From ``timing``'s ground, in its family and at its limit (:data:`INFEASIBLE_S` where the
    way up is infeasible or the node is below the ground). It does not depend on the goal:
    tables of several goals on one grid share it (:func:`gait_nodes.swing.sweep.sweep_tables`).
    """
    return timing.vertical_times(grid.points()).reshape(grid.shape)


def with_step_height(table: ValueTable, robot, step_height_m: float,
                     ground_z_m: float | None = None,
                     lift_s: np.ndarray | None = None) -> ValueTable:
    """The table with the lift and lowering of another step height (same cost-to-go).

    The cost-to-go does not depend on the step height; the lift (from the ground straight up
    to each state) and the lowering (from the goal straight down) do (thesis III.C.1: they are
    added once V has converged). States below the ground cannot be lift-off states
    (:data:`INFEASIBLE_S`).

    Args:
        table: A converged table.
        robot: Its robot.
        step_height_m: The step height [m].
        ground_z_m: The ground in the base frame [m]; None: ``-body_height_m``.
        lift_s: :func:`lift_times` of the table's family, limit and grid from this ground,
            when already computed (e.g. for another goal on the same grid); None: computed.

    Raises:
        SwingTableError: The foot cannot be lowered from the goal to the ground, or
            ``lift_s`` is not grid-shaped.
    """
    timing = LimbTiming(robot, table.family, table.joint_velocity_limit_rad_s, ground_z_m)
    if lift_s is None:
        lift = lift_times(timing, table.grid)
    else:
        lift = np.asarray(lift_s, dtype=float)
        if lift.shape != table.grid.shape:
            raise SwingTableError(f'lift times of shape {lift.shape} do not match the grid '
                                  f'{table.grid.shape}')
    lower = float(timing.vertical_times(table.goal[None])[0])
    if lower >= INFEASIBLE_S:
        raise SwingTableError(f'the foot cannot be lowered from the goal '
                              f'{table.goal.round(4)} to the ground ({timing.ground_z_m:.3f} m) '
                              f'in IK family {table.family}')
    return replace(table, step_height_m=float(step_height_m), ground_z_m=timing.ground_z_m,
                   lift_s=lift, lower_s=lower, _total=None)


def at_limit(table: ValueTable, joint_velocity_limit_rad_s: float) -> ValueTable:
    """The table at another joint velocity limit ``W``: every feasible time times ``W0 / W``.

    Every move costs ``max_j |dq_j| / W`` (thesis III.C.1), the lift and the lowering too, so
    the Bellman equation's fixed point at ``W`` is the one at ``W0`` scaled by ``W0 / W`` and
    its policy is the same (the thesis: the gait's speed grows linearly with the limit). A
    table built at ``W`` agrees to the sweeps' tolerance. Infeasible values (at or above
    :data:`~gait_nodes.swing.kinematics.FEASIBLE_BELOW_S`) stay as they are.

    Raises:
        SwingTableError: ``joint_velocity_limit_rad_s`` is not a finite number > 0.
    """
    from gait_nodes.swing.kinematics import FEASIBLE_BELOW_S

    limit = joint_velocity_limit_rad_s
    if not (isinstance(limit, (int, float)) and np.isfinite(limit) and limit > 0):
        raise SwingTableError(f'joint velocity limit must be a finite number > 0 rad/s, got '
                              f'{limit!r}')
    factor = table.joint_velocity_limit_rad_s / float(limit)

    def scaled(times: np.ndarray) -> np.ndarray:
        return np.where(times < FEASIBLE_BELOW_S, times * factor, times)

    return replace(table, joint_velocity_limit_rad_s=float(limit),
                   values_s=scaled(table.values_s), lift_s=scaled(table.lift_s),
                   lower_s=table.lower_s * factor, max_change_s=table.max_change_s * factor,
                   _total=None)
