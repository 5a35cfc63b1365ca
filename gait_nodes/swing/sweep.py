"""Step size against crawl speed (thesis 000, IV.B.3-6) and the perturbation test (IV.B.7).

Gait speed of a crawl, thesis eq. (2)::

    speed = step / (4 * T_swing + (T_swing - T_up - T_down))

four swings one after the other plus the body's move, which takes as long as the swing's
horizontal part. For one goal (landing place) the start of the swing is a grid node on the line
through the goal along x (same y and z, thesis IV.B.3), its yaw the best one (Appendix A), and
the step is the x distance. Several goals give several curves; for each step the fastest counts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gait_nodes.swing.kinematics import FEASIBLE_BELOW_S
from gait_nodes.swing.policy import SwingPath, SwingPolicy
from gait_nodes.swing.table import ValueTable

#: (ft/min) per (m/s).
FT_PER_MIN = 60.0 / 0.3048


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
