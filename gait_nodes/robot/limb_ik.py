"""Closed-form IK of the RoboSimian-like 7-DOF limb, vectorized over many foot targets.

The limb (config/robots/robosimian.urdf, made by tools/make_robot_urdfs.py) is, base to foot:
shoulder roll (x) and pitch (y) about one point ``S``, a thigh of length ``L1``, knee pitch (y),
a shin of length ``L2``, a spherical wrist (twist z, pitch y, roll x) about one point ``W``, and
the 7th joint, a foot yaw (z), ignored for walking (held at its posture value, thesis II.C). The
sole is ``d`` below ``W`` along the last link.

With the foot kept level (thesis III.A: end effectors change yaw only), the sole pose is
``(x, y, z, yaw)`` and ``W`` is straight above the sole, so the first three joints place ``W``
and the wrist orients the sole. Each step has two solutions, which gives the thesis' 8 families,
numbered 0..7 by three bits (the thesis' "k-th family" is ``k - 1``; its 3rd family, 010, is
``2``)::

    bit 2 (4): shoulder: 0 roll near 0, 1 roll near pi (the limb's plane turned over)
    bit 1 (2): knee: 0 knee ahead of the shoulder-wrist line, 1 behind it (front-right limb;
               mirrored for the others)
    bit 0 (1): wrist: 0 wrist pitch in (-pi/2, pi/2), 1 flipped (pitch beyond pi/2)

Targets are sole positions and yaws in the base frame (the thesis' "local limb positions" with
the centre of body at the origin). As in the thesis the front-right limb is solved and the other
limbs use mirrored coordinates: the URDF makes them mirror images, so the same joint angles give
the mirrored pose.

Within a family the solution is continuous except through singularities (shoulder: wrist centre
on the roll axis; knee: straight or folded leg; wrist: pitch at +-pi/2), where the family's
branches meet. Each joint is returned within pi of its value at the family's nominal solution,
so a smooth motion inside the workspace never wraps. :func:`continuity_breaks` tests a whole
trajectory ("testing trajectories IK for smoothness is always a necessity", thesis II.C).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from gait_nodes.errors import ConfigError

FAMILIES = tuple(range(8))
#: Default largest joint step between consecutive trajectory samples counted as continuous.
MAX_JOINT_STEP_RAD = 0.25
_EPS = 1e-9
_SINGULAR = 1e-6


def family_bits(family: int) -> tuple[int, int, int]:
    """(shoulder, knee, wrist) bits of a family number 0..7."""
    if isinstance(family, bool) or not isinstance(family, (int, np.integer)) \
            or not 0 <= family <= 7:
        raise ConfigError(f'IK family must be an integer in [0, 7], got {family!r}')
    return (int(family) >> 2) & 1, (int(family) >> 1) & 1, int(family) & 1


def _rx(angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def _ry(angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def _rz(angles: np.ndarray) -> np.ndarray:
    c, s = np.cos(angles), np.sin(angles)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


@dataclass(frozen=True)
class LimbGeometry:
    """Dimensions of the front-right limb, read off the URDF.

    Attributes:
        shoulder_in_base: (3,) shoulder point ``S`` in the base frame [m].
        thigh_m: Shoulder to knee [m].
        shin_m: Knee to wrist centre [m].
        wrist_to_sole_m: Wrist centre to sole, along the last link [m].
    """

    shoulder_in_base: np.ndarray
    thigh_m: float
    shin_m: float
    wrist_to_sole_m: float


class RoboSimianLimbIk:
    """Closed-form IK and FK of the four RoboSimian-like limbs of a :class:`RobotModel`.

    Args:
        robot: A :class:`gait_nodes.robot.model.RobotModel` whose limbs have the structure in
            the module docstring (checked against Pinocchio's forward kinematics at load).

    Raises:
        ConfigError: A limb does not have 7 joints or the RoboSimian-like structure.
    """

    def __init__(self, robot):
        self.robot = robot
        model = robot.model
        where = f'{robot.description.path}: extra.limb_ik'
        feet = robot.description.feet
        if any(len(f.joints) != 7 for f in feet):
            raise ConfigError(f'{where}: the RoboSimian limb IK needs 7 joints per limb, got '
                              f'{[len(f.joints) for f in feet]}')
        data = model.createData()
        q0 = robot.configuration(np.zeros(3), 0.0, np.zeros(len(robot.joint_names)))
        pin.framesForwardKinematics(model, data, q0)
        shoulders = np.array([data.oMi[model.getJointId(f.joints[0])].translation
                              for f in feet])
        # Mirror of each limb onto the front-right one (x > 0, y < 0).
        self.mirrors = np.sign(shoulders) * np.array([1.0, -1.0, 0.0]) + np.array([0, 0, 1.0])
        if np.any(self.mirrors == 0):
            raise ConfigError(f'{where}: a shoulder lies on a symmetry plane of the base')
        self.foot_index = {f.name: k for k, f in enumerate(feet)}
        reference = int(np.flatnonzero((self.mirrors == 1).all(axis=1))[0]) \
            if (self.mirrors == 1).all(axis=1).any() else 0
        joints = feet[reference].joints
        points = [self.mirrors[reference] * data.oMi[model.getJointId(j)].translation
                  for j in joints]
        sole = self.mirrors[reference] * data.oMf[robot.foot_frame_ids[reference]].translation
        self.geometry = LimbGeometry(
            shoulder_in_base=np.array(points[0]),
            thigh_m=float(np.linalg.norm(points[2] - points[1])),
            shin_m=float(np.linalg.norm(points[3] - points[2])),
            wrist_to_sole_m=float(np.linalg.norm(points[3] - sole)),
        )
        q_index = robot.indices(joints)
        self.lower_limits = np.array(robot.lower_limits[q_index])
        self.upper_limits = np.array(robot.upper_limits[q_index])
        self.wrist_yaw_rad = float(robot.posture[q_index[6]])
        self._check_structure(where)
        nominal = (self.mirrors[reference]
                   * robot.description.feet[reference].nominal_position_in_base)
        self.centers = np.zeros((8, 7))
        for family in FAMILIES:
            principal = self._solve_reference(nominal[None], np.zeros(1), family, wrap=False)[0]
            self.centers[family] = np.angle(np.exp(1j * principal[0]))

    def _check_structure(self, where: str) -> None:
        """Closed-form FK must equal Pinocchio's FK for every limb at random angles."""
        rng = np.random.default_rng(0)
        angles = rng.uniform(-math.pi, math.pi, (5, 7))
        model, data = self.robot.model, self.robot.model.createData()
        for foot, k in self.foot_index.items():
            positions, rotations = self.forward(angles, foot, rotations=True)
            for n, row in enumerate(angles):
                joints = np.array(self.robot.posture)
                joints[self.robot.indices(self.robot.description.feet[k].joints)] = row
                q = self.robot.configuration(np.zeros(3), 0.0, joints)
                pin.framesForwardKinematics(model, data, q)
                placement = data.oMf[self.robot.foot_frame_ids[k]]
                if (np.abs(placement.translation - positions[n]).max() > 1e-9
                        or np.abs(placement.rotation - rotations[n]).max() > 1e-9):
                    raise ConfigError(f'{where}: limb {foot!r} does not have the RoboSimian-like '
                                      f'structure (roll-pitch shoulder, knee, spherical wrist, '
                                      f'foot yaw, parallel frames at zero)')

    # -- forward kinematics --------------------------------------------------------------------

    def _mirror(self, foot: str) -> np.ndarray:
        try:
            return self.mirrors[self.foot_index[foot]]
        except KeyError:
            raise ConfigError(f'no foot {foot!r}; feet: {list(self.foot_index)}') from None

    def forward(self, joint_angles, foot: str = 'front_right', rotations: bool = False):
        """Sole positions in the base frame (N, 3) [m] and yaws (N,) [rad] of limb angles.

        Args:
            joint_angles: (N, 7) limb joint angles, base to foot [rad].
            foot: Which limb.
            rotations: Return (N, 3, 3) sole rotations instead of yaws.
        """
        q = np.atleast_2d(np.asarray(joint_angles, dtype=float))
        g = self.geometry
        down = np.array([0.0, 0.0, -1.0])
        r1 = _rx(q[:, 0])
        thigh = _ry(q[:, 1]) @ down * g.thigh_m
        r23 = _ry(q[:, 1] + q[:, 2])
        wrist = g.shoulder_in_base + np.einsum('nij,nj->ni', r1, thigh + r23 @ down * g.shin_m)
        r06 = r1 @ r23 @ _rz(q[:, 3]) @ _ry(q[:, 4]) @ _rx(q[:, 5])
        sole = wrist - g.wrist_to_sole_m * r06[:, :, 2]
        rotation = r06 @ _rz(q[:, 6])
        s = self._mirror(foot)
        sole = sole * s
        rotation = rotation * s[None, :, None] * s[None, None, :]
        if rotations:
            return sole, rotation
        return sole, np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0])

    # -- inverse kinematics --------------------------------------------------------------------

    def solve(self, targets_in_base, yaws_rad, family: int, foot: str = 'front_right'
              ) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles that put the sole at each target, level, with the target yaw.

        Args:
            targets_in_base: (N, 3) sole positions in the base frame [m].
            yaws_rad: (N,) sole yaws relative to the base [rad].
            family: IK family 0..7 (see the module docstring).
            foot: Which limb (the targets are that limb's own, not mirrored).

        Returns:
            ``(q, feasible)``: (N, 7) joint angles [rad] (never NaN; an unreachable target gets
            the limb stretched towards it) and (N,) booleans: reachable, away from singularities
            and within the joint limits.
        """
        family_bits(family)
        targets = np.atleast_2d(np.asarray(targets_in_base, dtype=float))
        yaws = np.broadcast_to(np.asarray(yaws_rad, dtype=float), (len(targets),))
        s = self._mirror(foot)
        sign = float(s[0] * s[1])  # a reflection turns yaw the other way
        return self._solve_reference(targets * s, yaws * sign, family, wrap=True)

    def _solve_reference(self, targets: np.ndarray, yaws: np.ndarray, family: int,
                         wrap: bool) -> tuple[np.ndarray, np.ndarray]:
        g = self.geometry
        shoulder_bit, knee_bit, wrist_bit = family_bits(family)
        finite = np.isfinite(targets).all(axis=1) & np.isfinite(yaws)
        targets = np.where(finite[:, None], targets, 0.0)
        yaws = np.where(finite, yaws, 0.0)
        u = targets + np.array([0.0, 0.0, g.wrist_to_sole_m]) - g.shoulder_in_base
        rho = np.hypot(u[:, 1], u[:, 2]) * (1.0 if shoulder_bit else -1.0)
        side = np.where(rho >= 0, 1.0, -1.0)
        theta1 = np.arctan2(-u[:, 1] * side, u[:, 2] * side)
        a, b = -u[:, 0], -rho
        l1, l2 = g.thigh_m, g.shin_m
        c3_raw = (a * a + b * b - l1 * l1 - l2 * l2) / (2.0 * l1 * l2)
        c3 = np.clip(c3_raw, -1.0, 1.0)
        knee_sign = -1.0 if knee_bit ^ shoulder_bit else 1.0
        theta3 = knee_sign * np.arccos(c3)
        theta2 = np.arctan2(a, b) - np.arctan2(l2 * np.sin(theta3), l1 + l2 * np.cos(theta3))
        r03 = _rx(theta1) @ _ry(theta2 + theta3)
        m = np.swapaxes(r03, 1, 2) @ _rz(yaws)
        pitch = np.arcsin(np.clip(-m[:, 2, 0], -1.0, 1.0))
        theta5 = math.pi - pitch if wrist_bit else pitch
        c5 = np.cos(theta5)
        flip = np.where(c5 >= 0, 1.0, -1.0)
        theta4 = np.arctan2(m[:, 1, 0] * flip, m[:, 0, 0] * flip)
        theta6 = np.arctan2(m[:, 2, 1] * flip, m[:, 2, 2] * flip)
        q = np.stack([theta1, theta2, theta3, theta4, theta5, theta6,
                      np.full_like(theta1, self.wrist_yaw_rad)], axis=1)
        if wrap:
            center = self.centers[family]
            q[:, :6] = center[:6] + np.mod(q[:, :6] - center[:6] + math.pi, 2 * math.pi) - math.pi
        feasible = (finite & (np.abs(c3_raw) <= 1.0) & (np.abs(rho) > _SINGULAR)
                    & (np.abs(c5) > _SINGULAR) & (1.0 - np.abs(c3) > _SINGULAR)
                    & np.all((q >= self.lower_limits - _EPS) & (q <= self.upper_limits + _EPS),
                             axis=1))
        return q, feasible

    def family_of(self, joint_angles, foot: str = 'front_right', tolerance_rad: float = 1e-6,
                  likely: int | None = None) -> np.ndarray:
        """(N,) family of each row of limb angles (-1 where none matches within tolerance).

        Families are tried in order, ``likely`` first (the one the caller expects: a limb that
        is in it costs one IK instead of eight), until every row has one.
        """
        q = np.atleast_2d(np.asarray(joint_angles, dtype=float))
        positions, yaws = self.forward(q, foot)
        result = np.full(len(q), -1)
        order = FAMILIES if likely is None else (likely, *(f for f in FAMILIES if f != likely))
        for family in order:
            candidate, _ = self.solve(positions, yaws, family, foot)
            gap = np.abs(np.angle(np.exp(1j * (candidate[:, :6] - q[:, :6])))).max(axis=1)
            result[(result < 0) & (gap < tolerance_rad)] = family
            if (result >= 0).all():
                break
        return result


def continuity_breaks(joint_path, max_step_rad: float = MAX_JOINT_STEP_RAD) -> np.ndarray:
    """(T-1,) booleans: a joint jumps by more than ``max_step_rad`` between samples.

    Args:
        joint_path: (T, J) joint angles along a trajectory [rad], sampled finely enough that
            a smooth motion moves every joint by less than ``max_step_rad`` per sample.
        max_step_rad: Largest per-sample step of a continuous motion [rad].
    """
    path = np.asarray(joint_path, dtype=float)
    if path.ndim != 2 or len(path) < 1:
        raise ValueError(f'joint_path must be (T, J), got shape {path.shape}')
    return np.abs(np.diff(path, axis=0)).max(axis=1, initial=0.0) > max_step_rad


@dataclass(frozen=True)
class TrajectoryIk:
    """IK of a sampled swing trajectory in one family.

    Attributes:
        joint_angles: (T, 7) limb angles [rad].
        feasible: (T,) each sample reachable, non-singular and within limits.
        breaks: (T-1,) a joint jumps between samples ``k`` and ``k + 1``.
    """

    joint_angles: np.ndarray
    feasible: np.ndarray
    breaks: np.ndarray

    @property
    def ok(self) -> bool:
        """Every sample feasible and no jump: the trajectory can be followed in this family."""
        return bool(self.feasible.all() and not self.breaks.any())


def trajectory_ik(limb_ik: RoboSimianLimbIk, targets_in_base, yaws_rad, family: int,
                  foot: str = 'front_right', max_step_rad: float = MAX_JOINT_STEP_RAD
                  ) -> TrajectoryIk:
    """Solve a whole trajectory in one family and check that it stays continuous."""
    q, feasible = limb_ik.solve(targets_in_base, yaws_rad, family, foot)
    return TrajectoryIk(q, feasible, continuity_breaks(q, max_step_rad))


def limb_ik(targets_in_base, yaws_rad, family: int, foot: str = 'front_right',
            robot: str = 'robosimian') -> tuple[np.ndarray, np.ndarray]:
    """:meth:`RoboSimianLimbIk.solve` for a shipped robot (model and solver cached).

    Args:
        targets_in_base: (N, 3) sole positions in the base frame [m].
        yaws_rad: (N,) sole yaws relative to the base [rad].
        family: IK family 0..7.
        foot: Which limb.
        robot: Robot name or YAML path (a robot with ``extra.limb_ik``).

    Returns:
        ``(q, feasible)``: (N, 7) limb angles [rad] and (N,) booleans.
    """
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.robot.whole_body_ik import robosimian_limb_ik

    return robosimian_limb_ik(load_robot_model(robot)).solve(targets_in_base, yaws_rad, family,
                                                             foot)
