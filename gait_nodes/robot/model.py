"""A robot description loaded into Pinocchio: names checked, limits, kinematics helpers.

:class:`RobotModel` builds the URDF with a free-flyer base and checks every name the robot YAML
uses against it (a missing frame or joint is refused with the valid names listed). Joint position
limits come from the URDF, joint velocity limits from the YAML. A configuration ``q`` is
Pinocchio's (``q[:3]`` base position in the world, ``q[3:7]`` base quaternion x, y, z, w, then
the joints); a *joint vector* is one value per name of :attr:`RobotModel.joint_names` (every 1-DOF
joint of the URDF, in Pinocchio's order).

IK settings read from the YAML's ``extra`` mapping (all optional)::

    extra:
      foot_orientation: yaw     # yaw: the IK keeps each sole flat (roll = pitch = 0) and turns it
                                # to the foot's yaw; free: position only (point feet).
                                # Default: yaw when every limb has >= 6 IK joints, else free.
      foot_frame_height_m: 0.0  # height of the foot frame above the contact point (the centre
                                # of a spherical foot); the contact point is straight below it.
      posture: {joint: rad}     # IK seed, and the position of every joint the IK does not move
                                # (arms, head...); unlisted joints: 0 clipped to their limits.
      locked_joints: [names]    # limb joints the IK leaves at their posture value (e.g. the
                                # RoboSimian wrist, ignored for walking).
      limb_ik: {kind: robosimian, family: 2}   # closed-form limb IK, gait_nodes.robot.limb_ik
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pinocchio as pin

from gait_nodes.errors import ConfigError
from gait_nodes.robot.description import RobotDescription, load_robot_description

FOOT_ORIENTATIONS = ('yaw', 'free')
#: URDF limits beyond this are "unlimited" (Pinocchio stores huge numbers for them) [rad or m].
UNLIMITED = 1e9


def yaw_rotation(yaw_rad: float) -> np.ndarray:
    """(3, 3) rotation by ``yaw_rad`` about z."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def yaw_of(rotation: np.ndarray) -> float:
    """Yaw [rad] of a rotation matrix (z-y-x Euler angle about z)."""
    return math.atan2(rotation[1, 0], rotation[0, 0])


def _frozen(array) -> np.ndarray:
    result = np.array(array, dtype=float)
    result.setflags(write=False)
    return result


class RobotModel:
    """A robot description with its Pinocchio model (free-flyer base).

    Args:
        description: The validated robot YAML.

    Raises:
        ConfigError: The URDF cannot be parsed, or the YAML names a frame or joint the URDF
            lacks (the message lists the valid names), or an ``extra`` IK setting is invalid.
    """

    def __init__(self, description: RobotDescription):
        self.description = description
        self.name = description.name
        where = f'{description.path}'
        try:
            self.model = pin.buildModelFromUrdf(str(description.urdf_path),
                                                pin.JointModelFreeFlyer())
        except (RuntimeError, ValueError) as exc:
            raise ConfigError(f'{description.urdf_path}: cannot build a Pinocchio model: '
                              f'{exc}'.splitlines()[0]) from exc
        model = self.model
        self.mass_kg = float(pin.computeTotalMass(model))
        frame_names = [f.name for f in model.frames]
        joint_names_all = list(model.names)[2:]

        def frame_id(name: str, key: str) -> int:
            if not model.existFrame(name):
                valid = sorted({f.name for f in model.frames
                                if f.type != pin.FrameType.JOINT} - {'universe'})
                raise ConfigError(f'{where}: {key}: frame {name!r} is not in '
                                  f'{description.urdf_path.name}; valid frames: {valid}')
            return model.getFrameId(name)

        self.base_frame_id = frame_id(description.base_frame, 'base_frame')
        base = model.frames[self.base_frame_id]
        if base.parentJoint != 1 or not base.placement.isIdentity(1e-9):
            raise ConfigError(f'{where}: base_frame: {description.base_frame!r} is not the root '
                              f'link of {description.urdf_path.name} (root link: '
                              f'{frame_names[2] if len(frame_names) > 2 else "?"})')
        self.foot_frame_ids = tuple(frame_id(f.frame, f'feet.{f.name}.frame')
                                    for f in description.feet)

        # 1-DOF joints: the joint vector.
        names, q_idx, v_idx = [], [], []
        for j in range(2, model.njoints):
            joint = model.joints[j]
            if joint.nv == 1:
                names.append(model.names[j])
                q_idx.append(joint.idx_q)
                v_idx.append(joint.idx_v)
        self.joint_names: tuple[str, ...] = tuple(names)
        self._q_index = np.array(q_idx, dtype=int)
        self._v_index = np.array(v_idx, dtype=int)
        self._position_in_vector = {name: k for k, name in enumerate(names)}
        self._scalar = np.array([model.joints[model.getJointId(n)].nq == 1 for n in names])
        # Index arrays of the joint vector <-> q maps, computed once (used every tick).
        self._continuous = np.flatnonzero(~self._scalar)
        self._scalar_q_index = self._q_index[self._scalar]
        self._all_scalar = bool(self._scalar.all())

        for foot in description.feet:
            supports = set(model.supports[model.frames[
                self.foot_frame_ids[description.foot_names.index(foot.name)]].parentJoint])
            for joint in foot.joints:
                if joint not in self._position_in_vector:
                    raise ConfigError(f'{where}: feet.{foot.name}.joints: joint {joint!r} is not '
                                      f'a 1-DOF joint of {description.urdf_path.name}; valid '
                                      f'joints: {joint_names_all}')
                if model.getJointId(joint) not in supports:
                    raise ConfigError(f'{where}: feet.{foot.name}.joints: joint {joint!r} does '
                                      f'not move frame {foot.frame!r}')
        self.limb_joint_names = description.joint_names

        lower = model.lowerPositionLimit[self._q_index].copy()
        upper = model.upperPositionLimit[self._q_index].copy()
        lower[~self._scalar | (lower < -UNLIMITED)] = -np.inf
        upper[~self._scalar | (upper > UNLIMITED)] = np.inf
        self.lower_limits = _frozen(lower)
        self.upper_limits = _frozen(upper)
        self.velocity_limits_rad_s = _frozen([description.velocity_limit_rad_s(n)
                                              if n in description.joint_names
                                              else description.joint_velocity_limit_rad_s
                                              for n in names])
        model.velocityLimit[self._v_index] = self.velocity_limits_rad_s
        self.acceleration_limits_rad_s2 = _frozen([
            description.acceleration_limit_rad_s2(n) if n in description.joint_names
            else description.joint_acceleration_limit_rad_s2 for n in names])

        self._read_extra(where)
        self._data = model.createData()
        q = self.configuration([0.0, 0.0, description.body_height_m], 0.0)
        pin.framesForwardKinematics(model, self._data, q)
        base_rotation = self._data.oMf[self.base_frame_id].rotation
        self.foot_rotation_offsets = _frozen([base_rotation.T @ self._data.oMf[f].rotation
                                              for f in self.foot_frame_ids])

    def _read_extra(self, where: str) -> None:
        extra = self.description.extra
        feet = self.description.feet
        locked = extra.get('locked_joints', [])
        if not isinstance(locked, list) or any(j not in self.limb_joint_names for j in locked):
            raise ConfigError(f'{where}: extra.locked_joints: must list limb joints, got '
                              f'{locked!r}; limb joints: {list(self.limb_joint_names)}')
        self.locked_joints = tuple(locked)
        self.ik_joint_names = tuple(j for j in self.limb_joint_names if j not in locked)
        self.ik_joints_by_foot = tuple(tuple(j for j in f.joints if j not in locked)
                                       for f in feet)
        fewest = min(len(joints) for joints in self.ik_joints_by_foot)
        orientation = extra.get('foot_orientation', 'yaw' if fewest >= 6 else 'free')
        if orientation not in FOOT_ORIENTATIONS:
            raise ConfigError(f'{where}: extra.foot_orientation: must be one of '
                              f'{list(FOOT_ORIENTATIONS)}, got {orientation!r}')
        if orientation == 'yaw' and fewest < 6:
            raise ConfigError(f'{where}: extra.foot_orientation: yaw needs 6 IK joints per '
                              f'limb, a limb has {fewest}; use free')
        self.foot_orientation = orientation
        height = extra.get('foot_frame_height_m', 0.0)
        if isinstance(height, bool) or not isinstance(height, (int, float)) \
                or not 0.0 <= height <= 0.5:
            raise ConfigError(f'{where}: extra.foot_frame_height_m: must be a number in '
                              f'[0, 0.5], got {height!r}')
        self.foot_frame_height_m = float(height)
        posture = extra.get('posture', {})
        if not isinstance(posture, Mapping):
            raise ConfigError(f'{where}: extra.posture: must be a mapping joint -> angle')
        values = np.clip(np.zeros(len(self.joint_names)), self.lower_limits, self.upper_limits)
        for joint, value in posture.items():
            if joint not in self._position_in_vector:
                raise ConfigError(f'{where}: extra.posture: {joint!r} is not a 1-DOF joint; '
                                  f'valid joints: {list(self.joint_names)}')
            k = self._position_in_vector[joint]
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not self.lower_limits[k] <= value <= self.upper_limits[k]:
                raise ConfigError(f'{where}: extra.posture.{joint}: must be a number in '
                                  f'[{self.lower_limits[k]}, {self.upper_limits[k]}], '
                                  f'got {value!r}')
            values[k] = float(value)
        self.posture = _frozen(values)

    # -- names and vectors ---------------------------------------------------------------------

    @property
    def foot_names(self) -> tuple[str, ...]:
        """Foot names, in YAML order."""
        return self.description.foot_names

    def new_data(self) -> pin.Data:
        """A fresh Pinocchio data for this model (one per thread or user)."""
        return self.model.createData()

    def indices(self, joint_names: Sequence[str]) -> np.ndarray:
        """Positions of ``joint_names`` in the joint vector; ConfigError on an unknown name."""
        try:
            return np.array([self._position_in_vector[n] for n in joint_names], dtype=int)
        except KeyError as exc:
            raise ConfigError(f'{self.name}: no joint {exc.args[0]!r}; joints: '
                              f'{list(self.joint_names)}') from None

    def q_indices(self, joint_names: Sequence[str]) -> np.ndarray:
        """Indices of ``joint_names`` in a configuration ``q`` (1-DOF revolute/prismatic)."""
        return self._q_index[self.indices(joint_names)]

    def v_indices(self, joint_names: Sequence[str]) -> np.ndarray:
        """Indices of ``joint_names`` in a velocity ``v``."""
        return self._v_index[self.indices(joint_names)]

    def configuration(self, base_position_in_world, base_yaw_rad: float,
                      joint_positions=None) -> np.ndarray:
        """Pinocchio ``q`` of a level base at a position and yaw with the given joints.

        Args:
            base_position_in_world: (3,) base origin in the world [m].
            base_yaw_rad: Base yaw [rad] (roll and pitch are zero).
            joint_positions: Joint vector (one value per :attr:`joint_names`) [rad], or a
                mapping name -> value over the posture, or None for the posture.
        """
        q = pin.neutral(self.model)
        q[:3] = base_position_in_world
        q[3:7] = (0.0, 0.0, math.sin(0.5 * base_yaw_rad), math.cos(0.5 * base_yaw_rad))
        values = np.array(self.posture)
        if isinstance(joint_positions, Mapping):
            values[self.indices(list(joint_positions))] = list(joint_positions.values())
        elif joint_positions is not None:
            values = np.asarray(joint_positions, dtype=float)
            if values.shape != (len(self.joint_names),):
                raise ValueError(f'a joint vector has {len(self.joint_names)} values, got '
                                 f'{values.shape}')
        self.set_joint_positions(q, values)
        return q

    def set_joint_positions(self, q: np.ndarray, joint_positions: np.ndarray) -> None:
        """Write a joint vector into ``q`` in place."""
        if self._all_scalar:
            q[self._q_index] = joint_positions
            return
        q[self._scalar_q_index] = joint_positions[self._scalar]
        for k in self._continuous:  # continuous joints: (cos, sin)
            q[self._q_index[k]:self._q_index[k] + 2] = (math.cos(joint_positions[k]),
                                                        math.sin(joint_positions[k]))

    def joint_positions(self, q: np.ndarray) -> np.ndarray:
        """The joint vector of ``q`` [rad]."""
        values = np.array(q[self._q_index], dtype=float)
        for k in self._continuous:
            values[k] = math.atan2(q[self._q_index[k] + 1], q[self._q_index[k]])
        return values

    def velocity(self, base_linear_velocity_in_world, base_yaw_rate_rad_s: float,
                 joint_velocities, q: np.ndarray) -> np.ndarray:
        """Pinocchio ``v`` (base twist in the base frame, as the free-flyer wants) at ``q``."""
        v = np.zeros(self.model.nv)
        rotation = pin.Quaternion(np.asarray(q[3:7])).toRotationMatrix()
        v[:3] = rotation.T @ np.asarray(base_linear_velocity_in_world, dtype=float)
        v[3:6] = rotation.T @ np.array([0.0, 0.0, base_yaw_rate_rad_s])
        v[self._v_index] = joint_velocities
        return v

    def within_limits(self, joint_positions: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
        """Booleans: each joint within its URDF position limits."""
        return ((joint_positions >= self.lower_limits - tolerance)
                & (joint_positions <= self.upper_limits + tolerance))

    # -- kinematics ----------------------------------------------------------------------------

    def foot_poses(self, q: np.ndarray, data: pin.Data | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Contact points (F, 3) in the world [m] and foot yaws (F,) [rad] at ``q``."""
        data = data or self._data
        pin.framesForwardKinematics(self.model, data, q)
        return self.foot_poses_from_data(data)

    def foot_poses_from_data(self, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`foot_poses`, from frame placements already in ``data``."""
        positions = np.empty((len(self.foot_frame_ids), 3))
        yaws = np.empty(len(self.foot_frame_ids))
        for k, frame in enumerate(self.foot_frame_ids):
            placement = data.oMf[frame]
            positions[k] = placement.translation
            yaws[k] = yaw_of(placement.rotation @ self.foot_rotation_offsets[k].T)
        positions[:, 2] -= self.foot_frame_height_m
        return positions, yaws

    def foot_rotations(self, q: np.ndarray, data: pin.Data | None = None) -> np.ndarray:
        """(F, 3, 3) foot frame rotations in the world, offsets removed (identity = level)."""
        data = data or self._data
        pin.framesForwardKinematics(self.model, data, q)
        return np.array([data.oMf[f].rotation @ self.foot_rotation_offsets[k].T
                         for k, f in enumerate(self.foot_frame_ids)])

    def feet_in_base(self, q: np.ndarray, data: pin.Data | None = None) -> np.ndarray:
        """(F, 3) contact points in the base frame [m]."""
        data = data or self._data
        positions, _ = self.foot_poses(q, data)
        base = data.oMf[self.base_frame_id]
        return (positions - base.translation) @ base.rotation

    def com(self, q: np.ndarray, data: pin.Data | None = None) -> np.ndarray:
        """(3,) centre of mass of the full model in the world [m]."""
        return pin.centerOfMass(self.model, data or self._data, q).copy()

    def com_jacobian(self, q: np.ndarray, data: pin.Data | None = None) -> np.ndarray:
        """(3, nv) COM Jacobian (d com / d v, with Pinocchio's free-flyer velocity)."""
        return pin.jacobianCenterOfMass(self.model, data or self._data, q).copy()

    def nominal_feet_in_world(self, base_position_in_world=None, base_yaw_rad: float = 0.0,
                              gait: str | None = None) -> np.ndarray:
        """(F, 3) nominal contact points for a base at a position (default: standing at origin).

        ``gait``'s own stance if the robot gives it one (``gait_stances``).
        """
        if base_position_in_world is None:
            base_position_in_world = (0.0, 0.0, self.description.body_height_m)
        stance = self.description.nominal_stance_in_base(gait)
        return np.asarray(base_position_in_world) + stance @ yaw_rotation(base_yaw_rad).T


@functools.lru_cache(maxsize=16)
def _load_cached(path: Path, mtime_ns: int) -> RobotModel:
    return RobotModel(load_robot_description(path))


def load_robot_model(name_or_path: str | os.PathLike) -> RobotModel:
    """The :class:`RobotModel` of a shipped robot name or robot YAML path (cached per file).

    The returned model is shared between callers: treat it as read-only.
    """
    from gait_nodes.robot.description import robot_yaml_path

    path = robot_yaml_path(name_or_path).resolve()
    return _load_cached(path, path.stat().st_mtime_ns)
