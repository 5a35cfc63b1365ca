"""An independent check of a limb's IK: multistart Levenberg-Marquardt on Pinocchio's chain.

Nothing of :mod:`gait_nodes.robot.limb_ik` is used. The forward kinematics of the limb is
composed from the Pinocchio model's joint placements and axes, as any revolute chain (checked
against ``pinocchio.framesForwardKinematics`` at construction); the sole pose (position, level,
yaw) is solved for the limb's joints but its last (the wrist, held at its posture value) from
many random starts at once, by damped least squares with the chain's geometric Jacobian; the
starts that converge are clustered, joint angles modulo 2 pi, into distinct solutions.

A multistart solver finds a solution only if some start falls in its basin: it can miss one
(never invent one: each is checked to 1e-9), so it checks completeness statistically, with
many starts, where :mod:`gait_nodes.robot.limb_ik` proves it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from gait_nodes.errors import ConfigError

#: A start counts as converged below this residual (position [m] and rotation entries).
CONVERGED = 1e-10
#: Two converged starts are one solution when no joint differs by more than this [rad].
SAME_SOLUTION_RAD = 1e-6


def _axis_of(model, joint_id: int, where: str) -> np.ndarray:
    shortname = model.joints[joint_id].shortname()
    if shortname.startswith('JointModelR') and shortname[-1] in 'XYZ':
        axis = np.zeros(3)
        axis['XYZ'.index(shortname[-1])] = 1.0
        return axis
    if shortname == 'JointModelRevoluteUnaligned':
        return np.asarray(model.joints[joint_id].extract().axis, dtype=float)
    raise ConfigError(f'{where}: joint {model.names[joint_id]!r} is not revolute '
                      f'({shortname})')


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


@dataclass(frozen=True)
class LimbChain:
    """A limb as a chain of revolute joints from the base to the sole, vectorized FK.

    Attributes:
        placements: Per joint, its placement ``(rotation (3, 3), translation (3,))`` in its
            parent's frame (the first in the base frame).
        axes: (J, 3) joint axes in their own frames.
        sole: ``(rotation, translation)`` of the sole frame in the last joint's frame.
        held: Posture value of the last joint [rad] (not solved for).
    """

    placements: tuple[tuple[np.ndarray, np.ndarray], ...]
    axes: np.ndarray
    sole: tuple[np.ndarray, np.ndarray]
    held: float

    @classmethod
    def of(cls, robot, foot: str) -> LimbChain:
        """The chain of ``foot``'s joints of a :class:`gait_nodes.robot.model.RobotModel`.

        Raises:
            ConfigError: The joints are not a chain of revolute joints from the base to the
                foot frame.
        """
        model = robot.model
        where = f'{robot.description.path}: foot {foot!r}'
        names = list(robot.description.foot(foot).joints)
        ids = [model.getJointId(name) for name in names]
        parents = [model.parents[j] for j in ids]
        if parents[0] != 1 or parents[1:] != ids[:-1]:
            raise ConfigError(f'{where}: joints {names} are not a chain from the base')
        frame = model.frames[robot.foot_frame_ids[robot.foot_names.index(foot)]]
        if frame.parentJoint != ids[-1]:
            raise ConfigError(f'{where}: the foot frame is not on the last joint {names[-1]!r}')
        placements = tuple((model.jointPlacements[j].rotation.copy(),
                            model.jointPlacements[j].translation.copy()) for j in ids)
        axes = np.array([_axis_of(model, j, where) for j in ids])
        held = float(robot.posture[robot.indices(names)[-1]])
        chain = cls(placements, axes, (frame.placement.rotation.copy(),
                                       frame.placement.translation.copy()), held)
        chain._check(robot, foot, names)
        return chain

    def _check(self, robot, foot: str, names: list[str]) -> None:
        """Sole poses of random angles must be Pinocchio's."""
        rng = np.random.default_rng(0)
        angles = rng.uniform(-math.pi, math.pi, (3, len(self.axes) - 1))
        positions, rotations = self.forward(angles)[:2]
        data = robot.new_data()
        for k, row in enumerate(angles):
            joints = np.array(robot.posture)
            joints[robot.indices(names)[:-1]] = row
            pin.framesForwardKinematics(robot.model, data,
                                        robot.configuration(np.zeros(3), 0.0, joints))
            placement = data.oMf[robot.foot_frame_ids[robot.foot_names.index(foot)]]
            if (np.abs(placement.translation - positions[k]).max() > 1e-9
                    or np.abs(placement.rotation - rotations[k]).max() > 1e-9):
                raise ConfigError(f'{robot.description.path}: foot {foot!r}: the chain '
                                  f'{names} does not reproduce Pinocchio\'s sole pose')

    def forward(self, angles: np.ndarray):
        """Sole position (..., 3), rotation (..., 3, 3), joint axes and origins (..., J-1, 3).

        Args:
            angles: (..., J - 1) angles of every joint but the held last one [rad].
        """
        shape = angles.shape[:-1]
        rotation = np.broadcast_to(np.eye(3), (*shape, 3, 3))
        position = np.zeros((*shape, 3))
        axes, origins = [], []
        values = [angles[..., k] for k in range(angles.shape[-1])] + [np.full(shape, self.held)]
        for (offset_rotation, offset), axis, value in zip(self.placements, self.axes, values,
                                                          strict=True):
            position = position + rotation @ offset
            rotation = rotation @ offset_rotation
            axes.append(rotation @ axis)
            origins.append(position)
            turn = _skew(np.broadcast_to(axis, (*shape, 3)))
            rotation = rotation @ (np.eye(3) + np.sin(value)[..., None, None] * turn
                                   + (1.0 - np.cos(value))[..., None, None] * (turn @ turn))
        sole_rotation, sole_offset = self.sole
        position = position + rotation @ sole_offset
        rotation = rotation @ sole_rotation
        return position, rotation, np.stack(axes[:-1], -2), np.stack(origins[:-1], -2)


def multistart_limb_ik(chain: LimbChain, targets_in_base, yaws_rad, starts: int = 300,
                       seed: int = 0, iterations: int = 80) -> list[np.ndarray]:
    """Distinct IK solutions of each target found from ``starts`` random starts.

    Args:
        chain: The limb.
        targets_in_base: (N, 3) sole positions in the base frame [m].
        yaws_rad: (N,) sole yaws [rad]; the sole is level.
        starts: Random starts per target (joint angles uniform in [-pi, pi]).
        seed: Seed of the starts.
        iterations: Levenberg-Marquardt iterations.

    Returns:
        Per target, (M, J) distinct solutions (joint angles in [-pi, pi), the last joint at its
        held value), each meeting the target to :data:`CONVERGED`.
    """
    targets = np.atleast_2d(np.asarray(targets_in_base, dtype=float))
    yaws = np.broadcast_to(np.asarray(yaws_rad, dtype=float), (len(targets),))
    c, s = np.cos(yaws), np.sin(yaws)
    zero, one = np.zeros_like(c), np.ones_like(c)
    goal_rotation = np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1),
                              np.stack([zero, zero, one], -1)], -2)[:, None]
    goal_position = targets[:, None]
    dof = len(chain.axes) - 1
    rng = np.random.default_rng(seed)
    q = rng.uniform(-math.pi, math.pi, (len(targets), starts, dof))

    def residual(angles):
        position, rotation, axes, origins = chain.forward(angles)
        error = np.concatenate([position - goal_position,
                                (rotation - goal_rotation).reshape(*angles.shape[:-1], 9)],
                               axis=-1)
        return error, position, rotation, axes, origins

    error, position, rotation, axes, origins = residual(q)
    cost = (error * error).sum(axis=-1)
    damping = np.full(cost.shape, 1e-3)
    for _ in range(iterations):
        # d(position)/dq_k = a_k x (p - o_k); d(rotation)/dq_k = [a_k]x R.
        linear = np.cross(axes, position[..., None, :] - origins)
        angular = (_skew(axes) @ rotation[..., None, :, :]).reshape(*axes.shape[:-1], 9)
        jacobian = np.swapaxes(np.concatenate([linear, angular], axis=-1), -1, -2)
        normal = np.swapaxes(jacobian, -1, -2) @ jacobian
        gradient = (np.swapaxes(jacobian, -1, -2) @ error[..., None])[..., 0]
        step = np.linalg.solve(normal + damping[..., None, None] * np.eye(dof),
                               -gradient[..., None])[..., 0]
        trial = residual(q + step)
        trial_cost = (trial[0] * trial[0]).sum(axis=-1)
        better = trial_cost < cost
        q = np.where(better[..., None], q + step, q)
        error, position, rotation, axes, origins = (
            np.where(better.reshape(better.shape + (1,) * (new.ndim - better.ndim)), new, old)
            for new, old in zip(trial, (error, position, rotation, axes, origins), strict=True))
        cost = np.where(better, trial_cost, cost)
        damping = np.clip(np.where(better, damping * 0.3, damping * 10.0), 1e-12, 1e8)
    wrapped = np.mod(q + math.pi, 2.0 * math.pi) - math.pi
    found = []
    for n in range(len(targets)):
        distinct: list[np.ndarray] = []
        for angles in wrapped[n][np.sqrt(cost[n]) < CONVERGED]:
            if not distinct or angle_gap(np.array(distinct), angles).min() > SAME_SOLUTION_RAD:
                distinct.append(angles)
        solutions = np.array(distinct).reshape(-1, dof)
        found.append(np.concatenate([solutions, np.full((len(solutions), 1), chain.held)],
                                    axis=1))
    return found


def angle_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Largest difference modulo 2 pi between joint vectors (broadcast over rows) [rad]."""
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))).max(axis=-1)


def match_solutions(ours: np.ndarray, theirs: np.ndarray,
                    tolerance_rad: float = SAME_SOLUTION_RAD) -> tuple[np.ndarray, np.ndarray]:
    """``(ours_found, theirs_found)``: which of each set has a match in the other.

    Args:
        ours: (M, J) solutions.
        theirs: (K, J) solutions.
        tolerance_rad: Largest joint difference (modulo 2 pi) of a match [rad].
    """
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    if not len(ours) or not len(theirs):
        return np.zeros(len(ours), dtype=bool), np.zeros(len(theirs), dtype=bool)
    close = angle_gap(ours[:, None], theirs[None]) < tolerance_rad
    return close.any(axis=1), close.any(axis=0)


@dataclass(frozen=True)
class Agreement:
    """How two solvers' solution sets compare over targets (:func:`compare_solution_sets`).

    Attributes:
        targets: Targets compared.
        agreeing: Targets where both sets are the same.
        missed_by_first: Solutions of the second solver the first one lacks.
        missed_by_second: Solutions of the first solver the second one lacks.
    """

    targets: int
    agreeing: int
    missed_by_first: int
    missed_by_second: int


def compare_solution_sets(first: list[np.ndarray], second: list[np.ndarray],
                          tolerance_rad: float = SAME_SOLUTION_RAD) -> Agreement:
    """Compare two solvers' solutions, target by target ((M, J) arrays each)."""
    agreeing = missed_by_first = missed_by_second = 0
    for ours, theirs in zip(first, second, strict=True):
        found_first, found_second = match_solutions(ours, theirs, tolerance_rad)
        missed_by_second += int((~found_first).sum())
        missed_by_first += int((~found_second).sum())
        agreeing += int(found_first.all() and found_second.all())
    return Agreement(len(first), agreeing, missed_by_first, missed_by_second)
