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

Pinocchio computes each moving joint's motion (``data.liMi``, any 1-DOF joint model it knows);
the link frames are placed in the joints' frames as the URDF places them (the model's body
frames), and the products and the quaternions are computed for all joints at once with numpy.
No ROS import: the robot_state_publisher node turns these arrays into messages.
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
            /joint_states entry can carry it), or ``base_frame`` names a link of the URDF that
            is not its root (the bridge would make a loop).
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

        names = [name for name, _, _ in moving]
        self.moving_joints = tuple(names)
        self._moving_parents = tuple(parent.name for _, parent, _ in moving)
        self._moving_children = tuple(child.name for _, _, child in moving)
        self._pinocchio_joints = np.array([model.getJointId(n) for n in names], dtype=int)
        # parent link -> joint frame (in the joint's parent joint) and joint -> child link.
        self._parent_inverse = np.array([parent.placement.inverse().homogeneous
                                         for _, parent, _ in moving]).reshape(-1, 4, 4)
        self._child = np.array([child.placement.homogeneous
                                for _, _, child in moving]).reshape(-1, 4, 4)
        self._child_is_identity = bool(np.array_equal(
            self._child, np.broadcast_to(np.eye(4), self._child.shape)))
        # Each moving joint's place in the robot's joint vector.
        self._in_vector = robot.indices(names) if names else np.zeros(0, dtype=int)
        self._joint_vector = robot.posture.copy()
        self._q = pin.neutral(model)
        self._data = model.createData()
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
            (moving rows named, their columns in the message, their joint names, parent links,
            child links).
        """
        if self._selection is None or self._selection[0] != names:
            column_of = {name: k for k, name in enumerate(names)}
            rows = [k for k, name in enumerate(self.moving_joints) if name in column_of]
            columns = np.array([column_of[self.moving_joints[k]] for k in rows], dtype=int)
            self._selection = (names, (
                np.array(rows, dtype=int), columns, tuple(self.moving_joints[k] for k in rows),
                tuple(self._moving_parents[k] for k in rows),
                tuple(self._moving_children[k] for k in rows)))
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
        rows, columns, joint_names, parents, children = self._select(tuple(names))
        values = np.asarray(positions, dtype=float)
        joints = self._joint_vector
        joints[self._in_vector[rows]] = values[columns]
        self.robot.set_joint_positions(self._q, joints)
        pin.forwardKinematics(self.robot.model, self._data, self._q)
        motions = self._data.liMi
        matrices = np.array([motions[j].homogeneous
                             for j in self._pinocchio_joints[rows].tolist()]).reshape(-1, 4, 4)
        matrices = self._parent_inverse[rows] @ matrices
        if not self._child_is_identity:
            matrices = matrices @ self._child[rows]
        return LinkTransforms(
            joints=joint_names, parents=parents, children=children,
            translations_m=_read_only(matrices[:, :3, 3].copy()),
            rotations_xyzw=_read_only(quaternions_of(matrices)))
