"""IK of RoboSimian's 7-DOF limb with the foot level, in 8 families, vectorized over many targets.

The limb (config/robots/robosimian.urdf, from the figures in tools/make_robot_urdfs.py) is,
base to foot, seven revolute joints that alternate about the link's long axis ``x`` (joints 1,
3, 5, 7) and a bending axis ``y`` (joints 2, 4, 6). Each long-axis joint meets the next bending
joint in one point, so the limb is three "universal joints" at ``P1``, ``P3``, ``P5``, linked by
L-shaped links that reach ``a`` along and ``b`` across (0.2865 m and -0.117 m), and a last link
to joint 7 (0.1925 m along, -0.117 m across) that carries the foot on joint 7's axis. Joint 1's
axis is vertical. Joint 7, the wrist, is ignored for walking (held at its posture value, thesis
000, II.C).

Geometry (with ``x_k``, ``y_k`` the axes of link ``k``; ``y_2`` is joint 2's axis and so on)::

    P3 = P1 + a x2 + b y2,  y2 _|_ x1 (joint 1's axis)
    P5 = P3 + a x4 + b y4,  y4 _|_ x2 (joints 3 and 4 meet at right angles)
    sole = P5 + R6 (0.1925, -0.117, 0) + R7 (foot offset),  y6 _|_ x4

With the foot level (thesis III.A: the end effectors only yaw), the target's position and yaw
fix ``R6`` (``x6`` straight down, ``y6`` turned by the yaw) and so the point ``P5``. Then ``P3``
lies on two spheres, of radius ``|(a, b)|`` about ``P1`` and about ``P5`` (the thesis' blue and
red spheres, its Figure 5): a circle. On that circle (angle ``phi``):

- the base pair (joints 1, 2) reaches ``P3`` only where its height along joint 1's axis is at
  most ``a``, and then in two ways, ``sin(q2)`` of either sign (the first choice);
- the wrist pair (joints 5, 6) reaches ``P3`` from ``P5`` only where its component along ``y6``
  is at most ``|b|``, and then in two ways, ``sin(q5)`` of either sign (the second choice);
- the two must meet at right angles, ``g(phi) = x2 . y4 = 0`` (the thesis' "orthogonal
  intersection between the blue and red links"): on each of the four sheets that the first two
  choices make, ``g`` crosses zero along the admissible arc, in the workspace twice, once rising
  and once falling (the third choice): the two solutions have opposite signs of ``det(J)``, the
  determinant of the sole pose's 6x6 Jacobian in joints 1-6.

So up to 2^3 = 8 solutions, numbered by three bits (the thesis' "k-th family" is ``k - 1``; its
3rd family, 010, is ``2``, its 8th, 111, is ``7``; they differ in every joint). As in the
thesis' construction ("the binary representations of 0~7 ... determine which solution to
choose for each of the joints"), a 0 digit takes the principal, positive option::

    bit 2 (4): base:    0 sin(q2) > 0, 1 sin(q2) < 0
    bit 1 (2): wrist:   0 sin(q5) > 0, 1 sin(q5) < 0
    bit 0 (1): meeting: 0 det(J) > 0,  1 det(J) < 0

(angles and Jacobian of the front-right limb; a mirrored limb is in the family of its mirror
image).

Families coincide only where a choice has no second option, at singular configurations:
``sin(q2) = 0`` (link 2 along joint 1's axis, where the base sheets join: families ``f`` and
``f ^ 4`` meet), ``sin(q5) = 0`` (joint 4's axis parallel to joint 6's, where the wrist sheets
join: ``f`` and ``f ^ 2`` meet; near it q4 and q6 run fast in opposite directions, their
sum does not) and ``det(J) = 0`` with both sines non-zero (two crossings
merge at a fold of the workspace's boundary: ``f`` and ``f ^ 1`` meet). A motion through one of
them passes from one family to the other, and near them a family may not exist (the target has
6 or 7 real solutions instead of 8). Anywhere else no two families give the same configuration
(tested). The real limb is not the thesis' idealization everywhere, though: in about 5 % of the
workspace's positions and yaws (more at yaws near 0 for the front-right foot's families 1 and
6), a sheet holds a second crossing of the same direction, a 9th and 10th solution. There the
family takes the crossing farthest from the sheet's edges, and its solution can jump between the
two: :func:`continuity_breaks` and :func:`trajectory_ik` catch it. Families 2 and 7, the
thesis' pair, have none in the walking stance's neighbourhood.

Each solution is found by sampling ``g`` on the circle, bracketing the family's crossing (a
sample pair that straddles a sheet's edge is cut at the edge) and polishing it to machine
precision; the joint angles then follow in closed form from the link frames, and forward
kinematics of the result meets the target to about 1e-12 m. The whole thesis swing workspace
(x 0.2-0.8 m, y -0.65 to -0.4 m, z -0.7 to -0.6 m for the front-right foot) is reached by every
family at some yaw, except its far corner (x > 0.77 m with y < -0.62 m), beyond the limb's
reach from joint 1's axis.

Targets are sole positions and yaws in the base frame (the thesis' "local limb positions" with
the centre of body at the origin). As in the thesis the front-right limb is solved and the other
limbs use mirrored coordinates: the four limbs are identical and mounted so that the left-front
and right-rear limbs at negated angles, and the left-rear limb at the same angles, are the
front-right limb's mirror images (checked against Pinocchio at load).

Within a family the solution is continuous except through the singularities above. Each joint
is returned within pi of its value at the family's nominal solution, so a smooth motion inside
the workspace never wraps. :func:`continuity_breaks` tests a whole trajectory ("testing
trajectories IK for smoothness is always a necessity", thesis II.C).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from gait_nodes.errors import ConfigError

FAMILIES = tuple(range(8))
#: What a family number means (see the module docstring); part of cached tables' identity.
FAMILY_NUMBERING = 'robosimian limb: bits sin(q2), sin(q5), det(J) of joints 1-6; 0 positive'
#: Default largest joint step between consecutive trajectory samples counted as continuous.
MAX_JOINT_STEP_RAD = 0.25
#: Samples of the circle of ``P3`` that bracket the roots (two roots closer than 2 pi / this are
#: near a fold, where the family is about to vanish).
CIRCLE_SAMPLES = 96
#: Targets solved at once (the sampled circle of a chunk stays in the CPU's cache).
CHUNK = 2048
_EPS = 1e-9
_SINGULAR = 1e-6
_UP = np.array([0.0, 0.0, 1.0])


def family_bits(family: int) -> tuple[int, int, int]:
    """(base, wrist, meeting) bits of a family number 0..7."""
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


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum('...i,...i->...', u, v)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _pair_angles(before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(alpha, beta)`` with ``before^T after = Rx(alpha) Ry(beta)`` (a long-axis, bend pair)."""
    m = np.swapaxes(before, -1, -2) @ after
    return np.arctan2(m[..., 2, 1], m[..., 1, 1]), np.arctan2(m[..., 0, 2], m[..., 0, 0])


@dataclass(frozen=True)
class LimbGeometry:
    """The front-right limb's kinematics, read off the URDF (base frame, zero joint angles).

    Attributes:
        shoulder_in_base: (3,) ``P1``, where joints 1 and 2 meet [m].
        link_1_rotation: (3, 3) link 1's frame at ``q1 = 0`` in the base frame.
        upper_offset_m: ``(a, b)`` from ``P1`` to ``P3`` in link 2's frame [m].
        lower_offset_m: ``(a, b)`` from ``P3`` to ``P5`` in link 4's frame [m].
        hand_offset_m: ``(a, b)`` from ``P5`` to joint 7 in link 6's frame [m].
        sole_in_link_7: (3,) the sole (foot frame origin) in link 7's frame [m].
        sole_rotation_in_link_7: (3, 3) the foot frame in link 7's frame.
        axis_signs: (7,) +1 or -1: joint ``k`` turns about ``+-x`` (odd k) or ``+-y`` (even).
    """

    shoulder_in_base: np.ndarray
    link_1_rotation: np.ndarray
    upper_offset_m: tuple[float, float]
    lower_offset_m: tuple[float, float]
    hand_offset_m: tuple[float, float]
    sole_in_link_7: np.ndarray
    sole_rotation_in_link_7: np.ndarray
    axis_signs: np.ndarray

    @property
    def reach_m(self) -> float:
        """Largest distance from ``P1`` to ``P5`` [m]."""
        return float(np.hypot(*self.upper_offset_m) + np.hypot(*self.lower_offset_m))


def _read_geometry(model, joint_names: list[str], foot_frame_id: int, where: str
                   ) -> LimbGeometry:
    """The limb's :class:`LimbGeometry` from the Pinocchio model, structure checked."""
    ids = [model.getJointId(name) for name in joint_names]
    placements = [model.jointPlacements[j] for j in ids]
    axes = []
    for k, j in enumerate(ids):
        axis = np.zeros(3)
        shortname = model.joints[j].shortname()
        if shortname.startswith('JointModelR') and shortname[-1] in 'XYZ':
            axis['XYZ'.index(shortname[-1])] = 1.0
        else:
            axis = np.asarray(model.joints[j].extract().axis, dtype=float)
        expected = 0 if k % 2 == 0 else 1
        if abs(abs(axis[expected]) - 1.0) > 1e-9:
            raise ConfigError(f'{where}: joint {joint_names[k]!r} must turn about its link\'s '
                              f'{"xy"[expected]} axis, turns about {axis.tolist()}')
        axes.append(float(np.sign(axis[expected])))
    for k in (1, 2, 3, 4, 5, 6):
        rotation = placements[k].rotation
        offset = placements[k].translation
        if not np.allclose(rotation, np.eye(3), atol=1e-9) or abs(offset[2]) > 1e-9 \
                or (k % 2 == 1 and np.abs(offset).max() > 1e-9):
            raise ConfigError(f'{where}: joint {joint_names[k]!r} is not placed as on '
                              f'RoboSimian (bending joints at their long-axis joint, long-axis '
                              f'joints offset along x and y, parallel frames)')
    data = model.createData()
    q = pin.neutral(model)
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    base = data.oMi[1]
    link_1 = base.actInv(data.oMi[ids[0]])
    sole = data.oMi[ids[6]].actInv(data.oMf[foot_frame_id])
    return LimbGeometry(
        shoulder_in_base=link_1.translation.copy(),
        link_1_rotation=link_1.rotation.copy(),
        upper_offset_m=tuple(float(v) for v in placements[2].translation[:2]),
        lower_offset_m=tuple(float(v) for v in placements[4].translation[:2]),
        hand_offset_m=tuple(float(v) for v in placements[6].translation[:2]),
        sole_in_link_7=sole.translation.copy(),
        sole_rotation_in_link_7=sole.rotation.copy(),
        axis_signs=np.array(axes),
    )


class RoboSimianLimbIk:
    """IK and FK of the four RoboSimian limbs of a :class:`RobotModel`, foot level.

    Args:
        robot: A :class:`gait_nodes.robot.model.RobotModel` whose limbs have the structure in
            the module docstring (checked against Pinocchio's forward kinematics at load).

    Raises:
        ConfigError: A limb does not have 7 joints or RoboSimian's structure.
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
        shoulders = np.array([data.oMi[model.getJointId(f.joints[0])].translation.copy()
                              for f in feet])
        # Mirror of each limb onto the front-right one (x > 0, y < 0).
        self.mirrors = np.sign(shoulders) * np.array([1.0, -1.0, 0.0]) + np.array([0, 0, 1.0])
        if np.any(self.mirrors == 0):
            raise ConfigError(f'{where}: a shoulder lies on a symmetry plane of the base')
        self.foot_index = {f.name: k for k, f in enumerate(feet)}
        is_reference = (self.mirrors == 1).all(axis=1)
        reference = int(np.flatnonzero(is_reference)[0]) if is_reference.any() else 0
        self.geometry = _read_geometry(model, list(feet[reference].joints),
                                       robot.foot_frame_ids[reference], where)
        q_index = robot.indices(feet[reference].joints)
        self.lower_limits = np.array(robot.lower_limits[q_index])
        self.upper_limits = np.array(robot.upper_limits[q_index])
        self.wrist_yaw_rad = float(robot.posture[q_index[6]])
        down = self.geometry.sole_rotation_in_link_7.T @ np.array([1.0, 0.0, 0.0])
        if np.abs(down - np.array([0.0, 0.0, -1.0])).max() > 1e-9:
            raise ConfigError(f'{where}: the foot frame must be level when the last link points '
                              f'straight down (it has link 7\'s x along {down.tolist()})')
        #: (F,) +1 or -1: limb ``k`` at ``sign * q`` is the front-right limb's mirror image at q.
        self.angle_signs = np.ones(len(feet))
        self._check_structure(where)
        nominal = (self.mirrors[reference]
                   * robot.description.feet[reference].nominal_position_in_base)
        self.centers = np.zeros((8, 7))
        for family in FAMILIES:
            principal, ok = self._solve_reference(nominal[None], np.zeros(1), family, wrap=False)
            if ok[0]:
                self.centers[family] = principal[0]

    def _check_structure(self, where: str) -> None:
        """The FK here must equal Pinocchio's for every limb at random angles.

        Sets :attr:`angle_signs`: the sign (of the two) that makes a limb the mirror image of
        the front-right one.
        """
        rng = np.random.default_rng(0)
        angles = rng.uniform(-math.pi, math.pi, (5, 7))
        model, data = self.robot.model, self.robot.model.createData()
        for foot, k in self.foot_index.items():
            matched = False
            for sign in (1.0, -1.0):
                self.angle_signs[k] = sign
                positions, rotations = self.forward(angles, foot, rotations=True)
                errors = []
                for n, row in enumerate(angles):
                    joints = np.array(self.robot.posture)
                    joints[self.robot.indices(self.robot.description.feet[k].joints)] = row
                    q = self.robot.configuration(np.zeros(3), 0.0, joints)
                    pin.framesForwardKinematics(model, data, q)
                    placement = data.oMf[self.robot.foot_frame_ids[k]]
                    errors.append(max(np.abs(placement.translation - positions[n]).max(),
                                      np.abs(placement.rotation - rotations[n]).max()))
                if max(errors) < 1e-9:
                    matched = True
                    break
            if not matched:
                raise ConfigError(f'{where}: limb {foot!r} is not a mirror image of the '
                                  f'front-right limb at the same or negated joint angles')

    # -- forward kinematics --------------------------------------------------------------------

    def _mirror(self, foot: str) -> np.ndarray:
        try:
            return self.mirrors[self.foot_index[foot]]
        except KeyError:
            raise ConfigError(f'no foot {foot!r}; feet: {list(self.foot_index)}') from None

    def _reference_frames(self, q: np.ndarray):
        """Link frames of the front-right limb at (N, 7) angles: R2, R4, R6, R7 and P1..P7."""
        g = self.geometry
        q = q * g.axis_signs
        r2 = g.link_1_rotation @ _rx(q[:, 0]) @ _ry(q[:, 1])
        r4 = r2 @ _rx(q[:, 2]) @ _ry(q[:, 3])
        r6 = r4 @ _rx(q[:, 4]) @ _ry(q[:, 5])
        r7 = r6 @ _rx(q[:, 6])
        p3 = g.shoulder_in_base + r2 @ np.array([*g.upper_offset_m, 0.0])
        p5 = p3 + r4 @ np.array([*g.lower_offset_m, 0.0])
        p7 = p5 + r6 @ np.array([*g.hand_offset_m, 0.0])
        return r7, p7

    def forward(self, joint_angles, foot: str = 'front_right', rotations: bool = False):
        """Sole positions in the base frame (N, 3) [m] and yaws (N,) [rad] of limb angles.

        Args:
            joint_angles: (N, 7) limb joint angles, base to foot [rad].
            foot: Which limb.
            rotations: Return (N, 3, 3) sole rotations instead of yaws.
        """
        q = np.atleast_2d(np.asarray(joint_angles, dtype=float))
        s = self._mirror(foot)
        r7, p7 = self._reference_frames(q * self.angle_signs[self.foot_index[foot]])
        g = self.geometry
        sole = (p7 + r7 @ g.sole_in_link_7) * s
        rotation = (r7 @ g.sole_rotation_in_link_7) * s[None, :, None] * s[None, None, :]
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
            ``(q, feasible)``: (N, 7) joint angles [rad] (never NaN; where the family has no
            solution, the family's nominal angles) and (N,) booleans: the family reaches the
            target, away from its singularities and within the joint limits.
        """
        family_bits(family)
        targets = np.atleast_2d(np.asarray(targets_in_base, dtype=float))
        yaws = np.broadcast_to(np.asarray(yaws_rad, dtype=float), (len(targets),))
        s = self._mirror(foot)
        sign = float(s[0] * s[1])  # a reflection turns yaw the other way
        q, feasible = self._solve_reference(targets * s, yaws * sign, family, wrap=True)
        return q * self.angle_signs[self.foot_index[foot]], feasible

    def _wrist_frames(self, targets: np.ndarray, yaws: np.ndarray):
        """``R6`` (N, 3, 3) and ``P5`` (N, 3) of a level sole at each target."""
        g = self.geometry
        r7 = _rz(yaws) @ g.sole_rotation_in_link_7.T
        r6 = r7 @ _rx(np.full(len(yaws), -g.axis_signs[6] * self.wrist_yaw_rad))
        p5 = targets - r7 @ g.sole_in_link_7 - r6 @ np.array([*g.hand_offset_m, 0.0])
        return r6, p5

    def _meeting(self, p3, sheet_base, sheet_wrist, p5, r6):
        """Link axes of the two pairs reaching ``p3`` on a sheet, and ``g = x2 . y4``.

        Arrays broadcast over leading dimensions (targets, samples). Returns
        ``(x2, y2, x4, y4, g, admissible, margin)``: ``margin`` is the smaller of the two
        square roots' arguments (0 where the sheets join).
        """
        geo = self.geometry
        a3, b3 = geo.upper_offset_m
        a5, b5 = geo.lower_offset_m
        n = geo.link_1_rotation[:, 0]
        h1 = geo.link_1_rotation[:, 1]
        h2 = np.cross(h1, n)
        # Base pair: u = a3 x2 + b3 y2 with y2 _|_ n, x2 = c n + s (y2 x n).
        u = p3 - geo.shoulder_in_base
        c2 = _dot(u, n) / a3
        base_root = 1.0 - c2 * c2
        s2 = sheet_base * np.sqrt(np.clip(base_root, 0.0, None))
        y2c = (_dot(u, h1) + 1j * _dot(u, h2)) / (b3 + 1j * a3 * s2)
        y2 = y2c.real[..., None] * h1 + y2c.imag[..., None] * h2
        x2 = c2[..., None] * n + s2[..., None] * np.cross(y2, n)
        # Wrist pair: v = a5 x4 + b5 y4 with x4 _|_ y6, y4 = c y6 + t (x4 turned in the plane).
        x6, y6 = r6[..., :, 0], r6[..., :, 1]
        z6 = np.cross(x6, y6)
        v = p5 - p3
        c4 = _dot(v, y6) / b5
        wrist_root = 1.0 - c4 * c4
        t4 = sheet_wrist * np.sqrt(np.clip(wrist_root, 0.0, None))
        x4c = (_dot(v, x6) + 1j * _dot(v, z6)) / (a5 + 1j * b5 * t4)
        x4 = x4c.real[..., None] * x6 + x4c.imag[..., None] * z6
        x4_turned = -x4c.imag[..., None] * x6 + x4c.real[..., None] * z6
        y4 = c4[..., None] * y6 + t4[..., None] * x4_turned
        margin = np.minimum(base_root, wrist_root)
        return x2, y2, x4, y4, _dot(x2, y4), margin > 0.0, margin

    def _meeting_function(self, centre, radius, e1, e2, p5, r6, sheet_base, sheet_wrist):
        """``g = x2 . y4`` and the sheet margin on ``P3``'s circle, of ``(cos(phi), sin(phi))``.

        The arguments broadcast against (N, 1). The same sums as :meth:`_meeting`, in each
        pair's own basis, without 3-vectors: the bracketing samples many angles per target.
        """
        geo = self.geometry
        a3, b3 = geo.upper_offset_m
        a5, b5 = geo.lower_offset_m
        n = geo.link_1_rotation[:, 0]
        h1 = geo.link_1_rotation[:, 1]
        base_axes = np.stack([h1, np.cross(h1, n), n])            # rows: h1, h2, n
        wrist_axes = np.swapaxes(r6, 1, 2)                          # rows: x6, y6, z6
        z6 = np.cross(wrist_axes[:, 0], wrist_axes[:, 1])
        wrist_axes = np.stack([wrist_axes[:, 0], wrist_axes[:, 1], z6], axis=1)
        u0 = (centre - geo.shoulder_in_base) @ base_axes.T             # (N, 3)
        u1 = radius[:, None] * (e1 @ base_axes.T)
        u2 = radius[:, None] * (e2 @ base_axes.T)
        v0 = np.einsum('nj,nij->ni', p5 - centre, wrist_axes)
        v1 = -radius[:, None] * np.einsum('nj,nij->ni', e1, wrist_axes)
        v2 = -radius[:, None] * np.einsum('nj,nij->ni', e2, wrist_axes)
        cross = np.einsum('ij,nkj->nik', base_axes, wrist_axes)     # (N, 3 base, 3 wrist)
        col = [[cross[:, i, j, None] for j in range(3)] for i in range(3)]
        u = [(u0[:, k, None], u1[:, k, None], u2[:, k, None]) for k in range(3)]
        v = [(v0[:, k, None], v1[:, k, None], v2[:, k, None]) for k in range(3)]

        def g_of(cos, sin):
            uh1, uh2, un = (w0 + w1 * cos + w2 * sin for w0, w1, w2 in u)
            vx, vy, vz = (w0 + w1 * cos + w2 * sin for w0, w1, w2 in v)
            c2 = un / a3
            base_root = 1.0 - c2 * c2
            s2 = sheet_base * np.sqrt(np.maximum(base_root, 0.0))
            den2 = b3 * b3 + (a3 * s2) ** 2
            re2 = (uh1 * b3 + uh2 * a3 * s2) / den2
            im2 = (uh2 * b3 - uh1 * a3 * s2) / den2
            x2 = (-s2 * im2, s2 * re2, c2)                         # in (h1, h2, n)
            c4 = vy / b5
            wrist_root = 1.0 - c4 * c4
            t4 = sheet_wrist * np.sqrt(np.maximum(wrist_root, 0.0))
            den4 = a5 * a5 + (b5 * t4) ** 2
            re4 = (vx * a5 + vz * b5 * t4) / den4
            im4 = (vz * a5 - vx * b5 * t4) / den4
            y4 = (-t4 * im4, c4, t4 * re4)                         # in (x6, y6, z6)
            g = sum(x2[i] * col[i][j] * y4[j] for i in range(3) for j in range(3))
            return g, np.minimum(base_root, wrist_root)

        return g_of

    def _solve_reference(self, targets: np.ndarray, yaws: np.ndarray, family: int,
                         wrap: bool) -> tuple[np.ndarray, np.ndarray]:
        if len(targets) <= CHUNK:
            return self._solve_chunk(targets, yaws, family, wrap)
        parts = [self._solve_chunk(targets[k:k + CHUNK], yaws[k:k + CHUNK], family, wrap)
                 for k in range(0, len(targets), CHUNK)]
        return (np.concatenate([q for q, _ in parts]),
                np.concatenate([ok for _, ok in parts]))

    def _solve_chunk(self, targets: np.ndarray, yaws: np.ndarray, family: int,
                     wrap: bool) -> tuple[np.ndarray, np.ndarray]:
        geo = self.geometry
        # The sheets and crossings below are written for 1 = positive; a bit is 1 = negative.
        base_bit, wrist_bit, meeting_bit = (1 - bit for bit in family_bits(family))
        # bit 2: 0 is sin(q2) < 0; s2 is sin of link 2's angle to joint 1's axis, signed
        # as q2 * axis sign.
        sheet_base = (1.0 if base_bit else -1.0) * geo.axis_signs[1]
        sheet_wrist = -1.0 if wrist_bit else 1.0  # s6 = -1: sin(q5) > 0
        # Along the circle, the solution with det(J) > 0 is a rising crossing of g on the
        # sheets with sin(q2) and sin(q5) of opposite signs, a falling one on the others.
        rising = (meeting_bit ^ base_bit ^ wrist_bit) == 1
        count = len(targets)
        finite = np.isfinite(targets).all(axis=1) & np.isfinite(yaws)
        targets = np.where(finite[:, None], targets, 0.0)
        yaws = np.where(finite, yaws, 0.0)
        r6, p5 = self._wrist_frames(targets, yaws)
        # The circle of P3: spheres about P1 and P5.
        r3, r5 = np.hypot(*geo.upper_offset_m), np.hypot(*geo.lower_offset_m)
        span = p5 - geo.shoulder_in_base
        distance = np.linalg.norm(span, axis=1)
        axis = span / np.maximum(distance, 1e-12)[:, None]
        along = (distance ** 2 + r3 ** 2 - r5 ** 2) / (2.0 * np.maximum(distance, 1e-12))
        radius = np.sqrt(np.clip(r3 ** 2 - along ** 2, 0.0, None))
        reachable = finite & (r3 ** 2 - along ** 2 > _SINGULAR ** 2)
        centre = geo.shoulder_in_base + along[:, None] * axis
        e1 = np.cross(axis, _UP)
        e1_norm = np.linalg.norm(e1, axis=1, keepdims=True)
        e1 = np.where(e1_norm > 1e-9, e1 / np.maximum(e1_norm, 1e-12), [1.0, 0.0, 0.0])
        e2 = np.cross(axis, e1)

        def circle(phi):
            c, s = np.cos(phi)[..., None], np.sin(phi)[..., None]
            return centre[:, None] + radius[:, None, None] * (c * e1[:, None] + s * e2[:, None])

        g_of = self._meeting_function(centre, radius, e1, e2, p5, r6, sheet_base, sheet_wrist)
        # Bracket the family's crossing of g = 0 on the sheet. A pair of samples with one end
        # beyond the sheet's edge is cut at the edge (found by bisection), so that a root near
        # a singularity, where the sheets join, is bracketed too.
        samples = np.linspace(-math.pi, math.pi, CIRCLE_SAMPLES + 1)
        g, margin = g_of(np.cos(samples), np.sin(samples))
        inside = margin > 0.0
        phi_lo = np.broadcast_to(samples[:-1], (count, CIRCLE_SAMPLES)).copy()
        phi_hi = np.broadcast_to(samples[1:], (count, CIRCLE_SAMPLES)).copy()
        g_lo, g_hi = g[:, :-1].copy(), g[:, 1:].copy()
        score = np.minimum(margin[:, :-1], margin[:, 1:])
        edge_rows, edge_cols = np.nonzero(inside[:, :-1] != inside[:, 1:])
        if len(edge_rows):
            r = edge_rows
            g_edge_of = self._meeting_function(centre[r], radius[r], e1[r], e2[r], p5[r], r6[r],
                                               sheet_base, sheet_wrist)
            left_inside = inside[edge_rows, edge_cols]
            a, b = samples[edge_cols], samples[edge_cols + 1]
            # To 2 pi / 96 / 2^20 (1e-7 rad): closer to the edge a root is singular anyway.
            for _ in range(20):
                middle = 0.5 * (a + b)
                middle_inside = g_edge_of(np.cos(middle)[:, None],
                                          np.sin(middle)[:, None])[1][:, 0] > 0.0
                move_a = middle_inside == left_inside
                a, b = np.where(move_a, middle, a), np.where(move_a, b, middle)
            edge = np.where(left_inside, a, b)
            g_edge = g_edge_of(np.cos(edge)[:, None], np.sin(edge)[:, None])[0][:, 0]
            phi_hi[edge_rows, edge_cols] = np.where(left_inside, edge,
                                                    phi_hi[edge_rows, edge_cols])
            g_hi[edge_rows, edge_cols] = np.where(left_inside, g_edge, g_hi[edge_rows, edge_cols])
            phi_lo[edge_rows, edge_cols] = np.where(left_inside, phi_lo[edge_rows, edge_cols],
                                                    edge)
            g_lo[edge_rows, edge_cols] = np.where(left_inside, g_lo[edge_rows, edge_cols], g_edge)
            score[edge_rows, edge_cols] = 0.0
        usable = inside[:, :-1] | inside[:, 1:]
        if rising:
            crossing = usable & (g_lo < 0.0) & (g_hi >= 0.0)
        else:
            crossing = usable & (g_lo > 0.0) & (g_hi <= 0.0)
        found = reachable & crossing.any(axis=1)
        # A sheet can hold a second crossing of the same direction near its edge, one that has
        # just come over from the neighbouring sheet (a solution passing the singularity):
        # take the one farthest from the edges, so the family stays with the solution it had.
        first = np.argmax(np.where(crossing, score, -1.0), axis=1)
        rows = np.arange(count)
        lo, hi = phi_lo[rows, first], phi_hi[rows, first]
        g_lo, g_hi = g_lo[rows, first], g_hi[rows, first]
        # Illinois false position: the bracket closes to the root within a few ulps.
        kept_lo = np.zeros(count, dtype=bool)
        kept_hi = np.zeros(count, dtype=bool)
        mid = lo
        for _ in range(40):
            width = g_hi - g_lo
            mid = np.where(width != 0.0, (lo * g_hi - hi * g_lo) / np.where(width != 0.0, width,
                                                                             1.0), lo)
            mid = np.clip(mid, np.minimum(lo, hi), np.maximum(lo, hi))
            g_mid = g_of(np.cos(mid)[:, None], np.sin(mid)[:, None])[0][:, 0]
            same = np.sign(g_mid) == np.sign(g_lo)
            lo, g_lo = np.where(same, mid, lo), np.where(same, g_mid, g_lo)
            hi, g_hi = np.where(same, hi, mid), np.where(same, g_hi, g_mid)
            g_hi = np.where(same & kept_hi, 0.5 * g_hi, g_hi)
            g_lo = np.where(~same & kept_lo, 0.5 * g_lo, g_lo)
            kept_hi, kept_lo = same, ~same
            if not np.any(found & (np.abs(g_mid) > 1e-15) & (np.abs(hi - lo) > 1e-15)):
                break

        def meeting(phi):
            return self._meeting(circle(phi), sheet_base, sheet_wrist, p5[:, None],
                                 r6[:, None])

        phi = mid
        x2, y2, x4, y4, g_root, admissible, margin = (
            value[:, 0] for value in meeting(phi[:, None]))
        frame_2 = np.stack([x2, y2, np.cross(x2, y2)], axis=-1)
        frame_4 = np.stack([x4, y4, np.cross(x4, y4)], axis=-1)
        q12 = _pair_angles(np.broadcast_to(geo.link_1_rotation, frame_2.shape), frame_2)
        q34 = _pair_angles(frame_2, frame_4)
        q56 = _pair_angles(frame_4, r6)
        q = np.stack([*q12, *q34, *q56, np.full(count, 0.0)], axis=1) * geo.axis_signs
        q[:, 6] = self.wrist_yaw_rad
        if wrap:
            center = self.centers[family]
            q[:, :6] = center[:6] + np.mod(q[:, :6] - center[:6] + math.pi, 2 * math.pi) - math.pi
        feasible = (found & admissible & (margin > _SINGULAR) & (np.abs(g_root) < 1e-9)
                    & np.all((q >= self.lower_limits - _EPS) & (q <= self.upper_limits + _EPS),
                             axis=1))
        q = np.where(feasible[:, None], q, self.centers[family])
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
            candidate, feasible = self.solve(positions, yaws, family, foot)
            gap = np.abs(np.angle(np.exp(1j * (candidate[:, :6] - q[:, :6])))).max(axis=1)
            result[(result < 0) & feasible & (gap < tolerance_rad)] = family
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
