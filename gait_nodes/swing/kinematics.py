"""Swing-leg timing at a joint velocity limit, from the closed-form IK of one family.

Thesis 000, III.C.1: "the time was measured by saturating the fastest joint in the movement" at
the joint velocity limit: a move between two foot states takes ``max_j |q_j(b) - q_j(a)| / W``
with ``q`` the IK of the chosen family at both ends (the wrist, the 7th joint, is ignored for
walking and held fixed).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from gait_nodes.errors import ConfigError, SwingTableError
from gait_nodes.robot.limb_ik import family_bits

#: Cost [s] of a move from or to an infeasible state (IK fails, singular, beyond limits).
INFEASIBLE_S = 1.0e6
#: Values at or above this [s] touched an infeasible state: no real swing takes that long.
FEASIBLE_BELOW_S = 1.0e3
#: Longest vertical sub-segment of the lift and lowering moves [m].
LIFT_SEGMENT_M = 0.02


def urdf_sha256(path: str | Path) -> str:
    """SHA-256 of the URDF file's bytes (the table's robot identity)."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class LimbTiming:
    """IK of swing-foot states in one family and move times at a joint velocity limit.

    Args:
        robot: A :class:`gait_nodes.robot.model.RobotModel` with RoboSimian's limbs
            (``extra.limb_ik``).
        family: IK family 0..7 (the thesis' k-th family is ``k - 1``).
        joint_velocity_limit_rad_s: The limit ``W`` every joint saturates at [rad/s].
        ground_z_m: Ground height in the base frame [m] (where lifts start and lowerings
            end); None: ``-body_height_m`` of the robot YAML.

    Raises:
        SwingTableError: The robot has no closed-form limb IK, or a bad family or limit.
    """

    def __init__(self, robot, family: int, joint_velocity_limit_rad_s: float,
                 ground_z_m: float | None = None):
        from gait_nodes.robot.whole_body_ik import robosimian_limb_ik

        try:
            family_bits(family)
        except ConfigError as exc:
            raise SwingTableError(str(exc)) from None
        if not (isinstance(joint_velocity_limit_rad_s, (int, float))
                and math.isfinite(joint_velocity_limit_rad_s)
                and joint_velocity_limit_rad_s > 0):
            raise SwingTableError(f'joint velocity limit must be > 0 rad/s, got '
                                  f'{joint_velocity_limit_rad_s!r}')
        if robot.description.extra.get('limb_ik') is None:
            raise SwingTableError(f'robot {robot.name!r} has no closed-form limb IK '
                                  f'(extra.limb_ik in {robot.description.path}); the swing value '
                                  f'table needs one (use swing: polynomial)')
        try:
            self.ik = robosimian_limb_ik(robot)
        except ConfigError as exc:
            raise SwingTableError(f'robot {robot.name!r}: {exc}') from None
        self.robot = robot
        self.family = int(family)
        self.joint_velocity_limit_rad_s = float(joint_velocity_limit_rad_s)
        if ground_z_m is None:
            ground_z_m = -float(robot.description.body_height_m)
        if not (isinstance(ground_z_m, (int, float)) and math.isfinite(ground_z_m)
                and ground_z_m < 0):
            raise SwingTableError(f'ground height must be finite and < 0 m (below the body), '
                                  f'got {ground_z_m!r}')
        self.ground_z_m = float(ground_z_m)

    def joints(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 6) walking joints [rad] and (N,) feasibility of (N, 4) front-right states."""
        states = np.atleast_2d(np.asarray(states, dtype=float))
        q, feasible = self.ik.solve(states[:, :3], states[:, 3], self.family)
        return q[:, :6], feasible

    def move_time(self, q_from: np.ndarray, q_to: np.ndarray) -> np.ndarray:
        """Time [s] of each move with the fastest joint saturated: ``max |dq| / W``."""
        return np.abs(q_to - q_from).max(axis=-1) / self.joint_velocity_limit_rad_s

    def path_times(self, states: np.ndarray) -> tuple[np.ndarray, bool]:
        """(W-1,) segment times [s] of a waypoint path and whether every waypoint is feasible."""
        q, feasible = self.joints(states)
        return self.move_time(q[:-1], q[1:]), bool(feasible.all())

    def vertical_path(self, state: np.ndarray) -> np.ndarray:
        """(K, 4) states from the ground straight up to ``state`` (yaw held), lowest first."""
        state = np.asarray(state, dtype=float)
        height = state[2] - self.ground_z_m
        if height < -1e-9:
            raise SwingTableError(f'state z = {state[2]:.4f} m is below the ground '
                                  f'({self.ground_z_m:.4f} m)')
        count = max(int(math.ceil(height / LIFT_SEGMENT_M - 1e-9)), 1)
        path = np.repeat(state[None], count + 1, axis=0)
        path[:, 2] = np.linspace(self.ground_z_m, state[2], count + 1)
        return path

    def vertical_times(self, states: np.ndarray) -> np.ndarray:
        """(N,) time [s] to move each state's foot straight down to the ground (or up from it).

        Infeasible anywhere on the way, or below the ground: :data:`INFEASIBLE_S`.
        """
        states = np.atleast_2d(np.asarray(states, dtype=float))
        result = np.full(len(states), INFEASIBLE_S)
        heights = np.round(states[:, 2], 12)
        for height in np.unique(heights[heights >= self.ground_z_m - 1e-9]):
            rows = np.flatnonzero(heights == height)
            template = self.vertical_path(states[rows[0]])
            paths = np.repeat(template[None], len(rows), axis=0)
            paths[:, :, [0, 1, 3]] = states[rows][:, None, [0, 1, 3]]
            q, feasible = self.joints(paths.reshape(-1, 4))
            q = q.reshape(len(rows), len(template), -1)
            times = self.move_time(q[:, :-1], q[:, 1:]).sum(axis=1)
            ok = feasible.reshape(len(rows), -1).all(axis=1)
            result[rows] = np.where(ok, times, INFEASIBLE_S)
        return result
