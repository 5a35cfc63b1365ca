"""The transforms between a robot's links, as ROS's robot_state_publisher puts them on tf2.

Every joint of the URDF gives one transform, from its parent link to its child link (tf2's
``header.frame_id`` -> ``child_frame_id``), the link names being the frame names:

- a fixed joint's is constant (/tf_static);
- a moving joint's (revolute, continuous, prismatic) depends on the joint's position only
  (/tf, computed for each /joint_states message).

The floating base is not a URDF joint: the simulators publish its pose as ``odom ->
base_link`` (REP-105). When the URDF's root link has another name (``base`` for the Go2), a
fixed identity transform ``base_link -> <root link>`` joins the two trees, since the base pose
the simulators publish is the root link's.

Pinocchio reads the URDF: the link frames (the model's body frames), the joints' placements and
their axes (read from Pinocchio's own joint motion and checked against it at start). For each
/joint_states message the moving joints' transforms are then computed all at once with numpy: a
rotation about the axis (revolute, continuous) or a slide along it (prismatic) after the
joint's placement, as quaternions. No ROS import: the robot_state_publisher node turns these
arrays into messages.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from gait_nodes.errors import ConfigError
from gait_nodes.robot.model import RobotModel


@dataclass(frozen=True)
class LinkTransforms:
    """Transforms parent link -> child link, one row per joint (read-only arrays).

    Attributes:
        joints: The URDF joint of each row ('' for the ``base_link -> root`` bridge).
        parents: Parent frame of each row (tf2's ``header.frame_id``).
        children: Child frame of each row (tf2's ``child_frame_id``).
        translations_m: (K, 3) child frame origin in the parent frame [m].
        rotations_xyzw: (K, 4) unit quaternion (x, y, z, w) of the child frame's axes in the
            parent frame, ``w >= 0``.
    """

    joints: tuple[str, ...]
    parents: tuple[str, ...]
    children: tuple[str, ...]
    translations_m: np.ndarray
    rotations_xyzw: np.ndarray

    def __len__(self) -> int:
        return len(self.joints)


def _read_only(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _shepperd_map() -> np.ndarray:
    """(16, 16): a row-major 4 x 4 homogeneous transform -> Shepperd's 4 x 4 matrix, row-major.

    Entry 15 of a homogeneous transform is 1; entries 0-2, 4-6 and 8-10 are its rotation.
    """
    one, r00, r01, r02, r10, r11, r12, r20, r21, r22 = 15, 0, 1, 2, 4, 5, 6, 8, 9, 10
    terms = {  # (row, column) -> {entry: sign}
        (0, 0): {one: 1, r00: 1, r11: -1, r22: -1}, (1, 1): {one: 1, r00: -1, r11: 1, r22: -1},
        (2, 2): {one: 1, r00: -1, r11: -1, r22: 1}, (3, 3): {one: 1, r00: 1, r11: 1, r22: 1},
        (0, 1): {r01: 1, r10: 1}, (0, 2): {r02: 1, r20: 1}, (1, 2): {r12: 1, r21: 1},
        (0, 3): {r21: 1, r12: -1}, (1, 3): {r02: 1, r20: -1}, (2, 3): {r10: 1, r01: -1},
    }
    linear = np.zeros((16, 16))
    for (row, column), entries in terms.items():
        for entry, sign in entries.items():
            linear[entry, 4 * row + column] = linear[entry, 4 * column + row] = sign
    return linear


_SHEPPERD = _shepperd_map()
_DIAGONAL = np.array([0, 5, 10, 15])


def quaternions_of(transforms: np.ndarray) -> np.ndarray:
    """Unit quaternions of the rotations of homogeneous transforms, all at once.

    Shepperd's method (J. Guidance and Control 1(3), 1978): row i of the symmetric matrix with
    diagonal ``1 + r00 - r11 - r22, 1 - r00 + r11 - r22, 1 - r00 - r11 + r22, 1 + r00 + r11 +
    r22`` (4 x^2, 4 y^2, 4 z^2, 4 w^2) is 4 q_i (x, y, z, w); the row of the largest diagonal
    term divides by the largest |q_i|, so no row loses precision.

    Args:
        transforms: (K, 4, 4) homogeneous transforms (rotation block orthonormal).

    Returns:
        (K, 4) quaternions (x, y, z, w) with ``w >= 0``.
    """
    matrices = np.asarray(transforms, dtype=float).reshape(-1, 16) @ _SHEPPERD
    largest = np.argmax(matrices[:, _DIAGONAL], axis=1)
    chosen = matrices.reshape(-1, 4, 4)[np.arange(len(matrices)), largest]
    chosen /= np.sqrt(np.einsum('ij,ij->i', chosen, chosen))[:, None]
    chosen[chosen[:, 3] < 0] *= -1.0
    return chosen


class LinkPoses:
    """The link transforms of a robot model: the fixed ones, and the moving ones for positions.

    Args:
        robot: The robot (its Pinocchio model, built from the URDF with a free-flyer root).
        base_frame: The REP-105 body frame the simulators publish ``odom ->``; when the URDF's
            root link has another name, the static transforms start with an identity
            ``base_frame -> root link``.

    Raises:
        ConfigError: A URDF joint with more than one degree of freedom (floating, planar: no
            /joint_states entry can carry it) or neither revolute nor prismatic, or
            ``base_frame`` names a link of the URDF that is not its root (the bridge would
            make a loop).
    """

    def __init__(self, robot: RobotModel, base_frame: str = 'base_link'):
        self.robot = robot
        model = robot.model
        frames = model.frames
        self.root_link = frames[robot.base_frame_id].name
        links = {f.name for f in frames if f.type == pin.FrameType.BODY}
        if base_frame != self.root_link and base_frame in links:
            raise ConfigError(f'{robot.description.urdf_path}: link {base_frame!r} is not the '
                              f'root link ({self.root_link!r}): odom -> {base_frame} would not '
                              f'be the pose of the root link')
        fixed, moving = [], []
        for child_id, child in enumerate(frames):
            if child.type != pin.FrameType.BODY or child_id == robot.base_frame_id:
                continue
            joint = frames[child.parentFrame]
            parent = frames[joint.parentFrame]
            if parent.type != pin.FrameType.BODY:
                continue  # a body above the URDF's root (none with one free-flyer root)
            if joint.type == pin.FrameType.FIXED_JOINT:
                fixed.append((joint.name, parent, child))
            else:
                nv = model.joints[joint.parentJoint].nv
                if nv != 1:
                    raise ConfigError(f'{robot.description.urdf_path}: joint {joint.name!r} '
                                      f'has {nv} degrees of freedom; /joint_states moves 1-DOF '
                                      f'joints only (revolute, continuous, prismatic)')
                moving.append((joint.name, parent, child))

        bridge = [('', base_frame, self.root_link, np.eye(4))] \
            if base_frame != self.root_link else []
        placements = [(name, parent.name, child.name,
                       parent.placement.actInv(child.placement).homogeneous)
                      for name, parent, child in fixed]
        self.static = self._transforms(bridge + placements)

        self.moving_joints = tuple(name for name, _, _ in moving)
        self._moving_parents = tuple(parent.name for _, parent, _ in moving)
        self._moving_children = tuple(child.name for _, _, child in moving)
        self._motion = _JointMotions(robot, moving)
        self._selection: tuple[tuple[str, ...], tuple] | None = None

    @staticmethod
    def _transforms(rows) -> LinkTransforms:
        matrices = np.array([matrix for *_, matrix in rows]).reshape(-1, 4, 4)
        return LinkTransforms(
            joints=tuple(r[0] for r in rows), parents=tuple(r[1] for r in rows),
            children=tuple(r[2] for r in rows),
            translations_m=_read_only(matrices[:, :3, 3].copy()),
            rotations_xyzw=_read_only(quaternions_of(matrices)))

    def _select(self, names: tuple[str, ...]) -> tuple:
        """For a message's joint names (the last ones' answer kept: they rarely change).

        Returns:
            (columns in the message of the moving joints named, their joint names, parent
            links, child links, their motions).
        """
        if self._selection is None or self._selection[0] != names:
            column_of = {name: k for k, name in enumerate(names)}
            rows = [k for k, name in enumerate(self.moving_joints) if name in column_of]
            self._selection = (names, (
                np.array([column_of[self.moving_joints[k]] for k in rows], dtype=int),
                tuple(self.moving_joints[k] for k in rows),
                tuple(self._moving_parents[k] for k in rows),
                tuple(self._moving_children[k] for k in rows),
                self._motion.rows(np.array(rows, dtype=int))))
        return self._selection[1]

    def moving(self, names: Sequence[str], positions) -> LinkTransforms:
        """The transforms of the moving joints that ``names`` lists, at ``positions``.

        Joints of ``names`` that the URDF does not move are ignored (as ROS's
        robot_state_publisher does), and the URDF's joints that ``names`` lacks get no row.

        Args:
            names: Joint names, as /joint_states lists them (distinct).
            positions: One position per name [rad or m], finite.

        Returns:
            One row per moving joint named, in the URDF's (Pinocchio's) joint order.
        """
        columns, joint_names, parents, children, motion = self._select(tuple(names))
        translations, rotations = motion.at(np.asarray(positions, dtype=float)[columns])
        return LinkTransforms(joints=joint_names, parents=parents, children=children,
                              translations_m=_read_only(translations),
                              rotations_xyzw=_read_only(rotations))


def _left_product_matrices(quaternions: np.ndarray) -> np.ndarray:
    """(K, 4, 4) matrices L with ``L[k] @ q`` the Hamilton product ``quaternions[k] * q``.

    Quaternions (x, y, z, w).
    """
    x, y, z, w = np.asarray(quaternions, dtype=float).reshape(-1, 4).T
    return np.stack([np.stack([w, -z, y, x], axis=1), np.stack([z, w, -x, y], axis=1),
                     np.stack([-y, x, w, z], axis=1), np.stack([-x, -y, -z, w], axis=1)],
                    axis=1)


@dataclass(frozen=True)
class _Motions:
    """Some moving joints' motions (rows of :class:`_JointMotions`)."""

    #: (K, 4, 4) left products by the rotation parent link -> joint frame at position 0.
    left: np.ndarray
    #: (K, 3) translation parent link -> joint frame (the child link's) at position 0 [m].
    origin_m: np.ndarray
    #: (K, 3) unit rotation axis in the joint frame (zero for a prismatic joint).
    axis: np.ndarray
    #: (K,) half the rotation per unit of position: 0.5 (revolute), 0 (prismatic).
    half_angle_per_unit: np.ndarray
    #: (K, 3) translation per unit of position, in the parent link (zero for a revolute joint).
    slide: np.ndarray

    def at(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K, 3) translations [m] and (K, 4) quaternions (x, y, z, w), w >= 0, at positions."""
        half = positions * self.half_angle_per_unit
        motion = np.empty((len(half), 4))
        motion[:, :3] = self.axis * np.sin(half)[:, None]
        motion[:, 3] = np.cos(half)
        rotations = np.einsum('kij,kj->ki', self.left, motion)
        rotations[rotations[:, 3] < 0] *= -1.0
        return self.origin_m + self.slide * positions[:, None], rotations


class _JointMotions:
    """Each moving joint's transform parent link -> child link as a function of its position.

    ``T(p) = A M(p)``: ``A`` the parent link -> joint frame (Pinocchio's placements), ``M(p)``
    a rotation by ``p`` about the joint's axis (revolute, continuous) or a translation by ``p``
    along it (prismatic). The axes are read from Pinocchio's own joint motion (``data.liMi`` at
    two positions) and checked against it, so any 1-DOF joint model that moves this way is
    taken, and another (helical...) refused.

    Raises:
        ConfigError: A joint whose motion is neither a rotation about nor a slide along an axis,
            or a child link not at its joint's frame.
    """

    #: Positions at which Pinocchio's motion is read, then checked [rad or m].
    PROBE, CHECK = 1.0, -0.7

    def __init__(self, robot: RobotModel, moving):
        model, where = robot.model, robot.description.urdf_path
        joints = [model.getJointId(name) for name, _, _ in moving]
        probed = self._pinocchio_motions(model, joints, self.PROBE)
        axes, halves, slides_local = [], [], []
        for (name, _, child), motion in zip(moving, probed, strict=True):
            if not child.placement.isIdentity(1e-12):
                raise ConfigError(f'{where}: link {child.name!r} is not at the frame of its '
                                  f'joint {name!r}')
            if np.allclose(motion.translation, 0.0, atol=1e-12):
                axes.append(pin.log3(motion.rotation) / self.PROBE)
                halves.append(0.5)
                slides_local.append(np.zeros(3))
            else:
                axes.append(np.zeros(3))
                halves.append(0.0)
                slides_local.append(motion.translation / self.PROBE)
        placements = [parent.placement.actInv(model.jointPlacements[j])
                      for (_, parent, _), j in zip(moving, joints, strict=True)]
        rotations = [placement.rotation for placement in placements]
        self._all = _Motions(
            left=_left_product_matrices(quaternions_of(np.array(
                [placement.homogeneous for placement in placements]).reshape(-1, 4, 4))),
            origin_m=np.array([placement.translation for placement in placements]).reshape(-1, 3),
            axis=np.array(axes).reshape(-1, 3), half_angle_per_unit=np.array(halves),
            slide=np.array([r @ s for r, s in zip(rotations, slides_local, strict=True)]
                           ).reshape(-1, 3))
        # The same motions, from Pinocchio and from the axes, at another position.
        expected = self._pinocchio_motions(model, joints, self.CHECK)
        translations, quaternions = self._all.at(np.full(len(joints), self.CHECK))
        for k, (name, _, _) in enumerate(moving):
            reference = placements[k] * expected[k]
            rotation = pin.Quaternion(quaternions[k][3], *quaternions[k][:3]).toRotationMatrix()
            if not (np.allclose(translations[k], reference.translation, atol=1e-9)
                    and np.allclose(rotation, reference.rotation, atol=1e-9)):
                raise ConfigError(f'{where}: joint {name!r} is neither revolute nor prismatic '
                                  f'({model.joints[joints[k]].shortname()}): its transform is '
                                  f'not published')

    @staticmethod
    def _pinocchio_motions(model, joints, position: float) -> list:
        """Each joint's motion ``M(position)`` (joint frame at 0 -> at ``position``)."""
        q = pin.neutral(model)
        for j in joints:
            joint = model.joints[j]
            if joint.nq == 2:  # continuous: (cos, sin)
                q[joint.idx_q:joint.idx_q + 2] = (np.cos(position), np.sin(position))
            else:
                q[joint.idx_q] = position
        data = model.createData()
        pin.forwardKinematics(model, data, q)
        return [model.jointPlacements[j].actInv(data.liMi[j]) for j in joints]

    def rows(self, rows: np.ndarray) -> _Motions:
        """The motions of the moving joints ``rows`` (indices in the robot's moving joints)."""
        every = self._all
        return _Motions(every.left[rows], every.origin_m[rows], every.axis[rows],
                        every.half_angle_per_unit[rows], every.slide[rows])
