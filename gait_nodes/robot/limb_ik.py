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
  intersection between the blue and red links"). Each zero of ``g`` on one of the four sheets
  that the first two choices make is a solution, and the direction in which ``g`` crosses zero
  there (the third choice) is the sign of ``det(J)``, the determinant of the sole pose's 6x6
  Jacobian in joints 1-6.

So 2^3 = 8 families, numbered by three bits (the thesis' "k-th family" is ``k - 1``; its
3rd family, 010, is ``2``, its 8th, 111, is ``7``; they differ in every joint). As in the
thesis' construction ("the binary representations of 0~7 ... determine which solution to
choose for each of the joints"), a 0 digit takes the principal, positive option::

    bit 2 (4): base:    0 sin(q2) > 0, 1 sin(q2) < 0
    bit 1 (2): wrist:   0 sin(q5) > 0, 1 sin(q5) < 0
    bit 0 (1): meeting: 0 det(J) > 0,  1 det(J) < 0

(angles and Jacobian of the front-right limb; a mirrored limb is in the family of its mirror
image).

In the thesis' idealization each sheet holds two crossings, one rising and one falling: 8
solutions, one per family. The real limb does not quite. Over the thesis swing workspace (x
0.2-0.8 m, y -0.65 to -0.4 m, z -0.7 to -0.6 m for the front-right foot) at walking yaws (|yaw|
<= 0.45 rad), of 200,000 random targets 38.5 % have 8 solutions, 29.2 % 6, 15.7 % 4, 0.9 % 2,
0.02 % 10 and 15.7 % none (60 % of those more than 0.5 m from joint 1's axis, near the end
of the limb's reach, the others mostly at positive yaws; every family reaches every position at
some yaw but the far corner, x > 0.77 m with y < -0.62 m). In 11.3 % of the targets a family
holds two or three solutions: a sheet with a second crossing of the same direction, one that has
come over from the neighbouring sheet through its edge (families 1 and 6, 10 % each; families 2
and 7, the thesis' pair, 0.01 % and 0.04 %), and another family is then empty (in 9.3 % of the
targets one is with 8 solutions all the same: at x 0.305 m, y -0.434 m, z -0.7 m, yaw 0.037
rad families 1 and 6 hold two each, 3 and 4 none). :meth:`RoboSimianLimbIk.solutions` returns
every solution and its family; :meth:`RoboSimianLimbIk.solve` returns a family's principal
solution, its crossing farthest from the sheets' edges (the one a motion inside the family
keeps; the family's solution can still jump between two, which :func:`continuity_breaks` and
:func:`trajectory_ik` catch). ``python -m gait_nodes.swing_table ik-check`` counts them over the
workspace and checks them against an independent solver.

Families coincide only where a choice has no second option, at singular configurations:
``sin(q2) = 0`` (link 2 along joint 1's axis, where the base sheets join: families ``f`` and
``f ^ 4`` meet), ``sin(q5) = 0`` (joint 4's axis parallel to joint 6's, where the wrist sheets
join: ``f`` and ``f ^ 2`` meet; near it q4 and q6 run fast in opposite directions, their
sum does not) and ``det(J) = 0`` with both sines non-zero (two crossings
merge at a fold of the workspace's boundary: ``f`` and ``f ^ 1`` meet). A motion through one of
them passes from one family to the other, and near them a family may not exist. A solution
with ``|sin(q2)|`` or ``|sin(q5)|`` at most :data:`SINGULAR_SINE` (1e-3) is not returned.
Anywhere else no two families give the same configuration (tested).

Every solution is found, by a search whose completeness is proven, not sampled. On a sheet
``g = (alpha + s beta + t gamma + s t delta) / scale`` with ``s = +-sqrt(1 - c2^2)``,
``t = +-sqrt(1 - c4^2)`` (``c2``, ``c4``: the cosines whose bounds make the sheets' edges) and
``alpha`` .. ``delta`` trigonometric polynomials in ``phi`` (:class:`_Meeting`). The square roots
give ``g`` an unbounded slope at the edges, where no sampling of ``g`` can bound it, and two
crossings closer than the samples cancel (a family's pair near a fold: the former bracketing of
96 samples per sheet missed, for each family, 0.05-0.2 % of the targets in the workspace that
the family reaches, at some targets every family). The product of ``g``'s numerators over the
four sheets, ``H = E^2 - t^2 F^2`` (:func:`_meeting_polynomial`), is free of square roots: a
trigonometric polynomial of degree at most 24 (16 in fact, tested) whose real zeros inside the
edges are the solutions of all four sheets; a simple zero of ``H`` is a simple zero of exactly
one sheet's ``g``. So:

1. ``H``'s Fourier coefficients ``c_k`` come exactly (up to rounding) from
   :data:`MEETING_SAMPLES` = 64 > 2 x 24 samples, and bound its derivatives:
   ``max |H^(j)| <= sum_k k^j |c_k|``. ``H`` is evaluated to degree 16; the coefficients
   above, rounding in fact, count in the rounding allowance.
2. The circle is cut in :data:`ROOT_GRID` arcs. Taylor's theorem at an arc's end, to order
   :data:`TAYLOR_ORDER` with that bound on the remainder and the rounding of every term allowed
   for (with a margin of 100), proves the arc free of zeros of ``H`` (``|H|`` stays above zero)
   or holding one at most (``|H'|`` does). An arc proven neither is cut in
   :data:`ROOT_SPLIT` and tried again, down to :data:`ROOT_WIDTH_RAD` (1e-7 rad).
3. The arcs kept are cut at the sheets' edges (in closed form, where ``c2`` or ``c4`` is +-1).
   On each part inside them, a sheet whose ``g`` changes sign holds a crossing: the one sheet
   with ``H``'s one zero there. False position (Illinois) closes the bracket to a few ulps, and
   the joint angles follow in closed form from the link frames; forward kinematics of the result
   meets the target to about 1e-12 m.

Only an arc of 1e-7 rad about a double (or nearly double) zero of ``H`` is left to the signs of
``g``: two solutions on different sheets there are both found, two on one sheet within 1e-7 rad of
each other (about to merge at a fold, where ``det(J)`` vanishes) can both be missed. Tested against
a multistart solver that shares nothing with this module (:mod:`gait_nodes.robot.ik_check`) over
the thesis workspace. Cost, 10,000 targets, CPU time on one core: 0.3 s for one family, 0.43 s for
every solution of every family (the former bracketing: 0.17 s per family, 1.3 s for all eight).

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
from dataclasses import dataclass, fields, replace

import numpy as np
import pinocchio as pin

from gait_nodes.errors import ConfigError

FAMILIES = tuple(range(8))
#: What a family number means and which of its solutions :meth:`RoboSimianLimbIk.solve` gives
#: (see the module docstring); part of cached tables' identity.
FAMILY_NUMBERING = ('robosimian limb: bits sin(q2), sin(q5), det(J) of joints 1-6; 0 positive; '
                    'every crossing found, the principal one farthest from the sheet edges')
#: Default largest joint step between consecutive trajectory samples counted as continuous.
MAX_JOINT_STEP_RAD = 0.25
#: Degree bound of ``H``, the meeting polynomial (module docstring), and its samples (> 2x).
MEETING_DEGREE = 24
MEETING_SAMPLES = 64
#: Degree to which ``H`` is evaluated: its degree in fact (the coefficients above are rounding,
#: and are counted as such).
EVALUATED_DEGREE = 16
#: Order of the Taylor expansions that decide an arc.
TAYLOR_ORDER = 4
#: Arcs of ``P3``'s circle the root search starts from, and how an undecided arc is cut.
ROOT_GRID = 128
ROOT_SPLIT = 4
#: Narrowest arc cut: two roots of one sheet closer than this are a fold (det(J) ~ 0) [rad].
ROOT_WIDTH_RAD = 1e-7
#: Undecided arcs of one target past which ``H`` is taken as zero all along (a continuum).
ROOT_CROWD = 256
#: Signs of ``(s, t)``, the two square roots, on the four sheets.
SHEETS = ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0))
#: A solution with ``|sin(q2)|`` or ``|sin(q5)|`` at most this is singular (where two families
#: meet) and not returned.
SINGULAR_SINE = 1e-3
#: Targets solved at once (the sampled circle of a chunk stays in the CPU's cache).
CHUNK = 2048
#: Principal solutions kept per family (about 15 MB at most): planning asks for the same
#: targets again and again (a re-timed step probes the footholds it keeps, each walk's swing
#: timing the same lattice), bit for bit; a full memo starts over.
MEMO_SIZE = 50_000
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


def _group_starts(*keys: np.ndarray) -> np.ndarray:
    """Where a run of equal keys starts in arrays sorted by them (booleans)."""
    starts = np.ones(len(keys[0]), dtype=bool)
    for key in keys:
        starts[1:] &= key[1:] == key[:-1]
    starts[1:] = ~starts[1:]
    return starts


def _angle_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Largest wrapped difference of joints 1-6 between limb angles (broadcast) [rad]."""
    return np.abs(np.angle(np.exp(1j * (a[..., :6] - b[..., :6])))).max(axis=-1)


@dataclass(frozen=True)
class LimbIkSolutions:
    """Every solution of the limb IK at each of N targets (:meth:`RoboSimianLimbIk.solutions`).

    Attributes:
        joint_angles: (N, M, 7) limb angles [rad]; target ``n``'s solutions are its first
            ``count[n]`` rows, by family, each family's principal solution first; NaN after.
        families: (N, M) family of each solution, -1 after ``count[n]``.
        principal: (N, M) the solution is its family's principal one, the one
            :meth:`RoboSimianLimbIk.solve` returns.
        count: (N,) number of solutions of each target.
    """

    joint_angles: np.ndarray
    families: np.ndarray
    principal: np.ndarray
    count: np.ndarray

    def family_counts(self) -> np.ndarray:
        """(N, 8) number of solutions of each family at each target."""
        counts = np.zeros((len(self.count), 8), dtype=int)
        rows, columns = np.nonzero(self.families >= 0)
        np.add.at(counts, (rows, self.families[rows, columns]), 1)
        return counts


@dataclass(frozen=True)
class _Circle:
    """``P3``'s circle of N targets: centre, radius, in-plane axes; ``P5`` and ``R6``."""

    centre: np.ndarray
    radius: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    p5: np.ndarray
    r6: np.ndarray
    reachable: np.ndarray

    def take(self, rows) -> _Circle:
        return _Circle(*(getattr(self, f.name)[rows] for f in fields(self)))


@dataclass(frozen=True)
class _Crossings:
    """Brackets ``[lo, hi]`` of a sign change of ``g`` on a sheet, one per crossing."""

    rows: np.ndarray
    sheet_base: np.ndarray
    sheet_wrist: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    g_lo: np.ndarray
    g_hi: np.ndarray
    rising: np.ndarray

    def take(self, which) -> _Crossings:
        return _Crossings(*(getattr(self, f.name)[which] for f in fields(self)))


@dataclass(frozen=True)
class _Found:
    """Feasible solutions, one per row: target index, family, (7,) angles, sheet margin."""

    rows: np.ndarray
    families: np.ndarray
    q: np.ndarray
    margins: np.ndarray


@dataclass(frozen=True)
class _Bounds:
    """Bounds on N targets' ``H``.

    Attributes:
        moments: (m + 2, N) ``sum_k k^j |c_k|``, at least ``max |H^(j)|``.
        rounding: (m + 1, N) rounding of ``H^(j)`` as computed.
    """

    moments: np.ndarray
    rounding: np.ndarray


def _classify(at_lo: np.ndarray, at_hi: np.ndarray, width, moments: np.ndarray,
              rounding: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(empty, simple)``: arcs proven free of roots of ``H``, proven to hold one at most.

    Taylor's theorem at either end of an arc of width ``w``, to order ``m`` with the
    remainder bounded by ``max |H^(m+1)| <= moments[m + 1] w^(m+1) / (m+1)!``, bounds ``|H|``
    from below (no root) or ``|H'|`` (``H`` monotonic: one root at most, none if ``H`` has the
    same sign at both ends). The derivatives at the ends count with their rounding added.

    Args:
        at_lo: (m + 1, ...) ``H^(j)`` at the arcs' starts, ``j = 0..m``.
        at_hi: (m + 1, ...) the same at their ends.
        width: Arc widths, broadcasting against ``(...)`` [rad].
        moments: (m + 2, ...) ``sum_k k^j |c_k|``, a bound of ``|H^(j)|``.
        rounding: (m + 1, ...) rounding of ``H^(j)`` as computed.
    """
    m = len(at_lo) - 1
    powers = [np.ones_like(width)]
    for j in range(1, m + 2):
        powers.append(powers[-1] * width / j)                      # w^j / j!
    remainder = moments[m + 1] * powers[m + 1]
    slope_remainder = moments[m + 1] * powers[m]
    empty, monotonic = False, False
    for at in (at_lo, at_hi):
        tail = remainder + rounding[0]
        slope_tail = slope_remainder + rounding[1]
        for j in range(1, m + 1):
            tail = tail + (np.abs(at[j]) + rounding[j]) * powers[j]
            if j >= 2:
                slope_tail = slope_tail + (np.abs(at[j]) + rounding[j]) * powers[j - 1]
        empty = empty | (np.abs(at[0]) > tail)
        monotonic = monotonic | (np.abs(at[1]) > slope_tail)
    one_sign = ((np.minimum(np.abs(at_lo[0]), np.abs(at_hi[0])) > rounding[0])
                & (at_lo[0] * at_hi[0] > 0.0))
    empty = empty | (monotonic & one_sign)
    return empty, monotonic & ~empty


@dataclass(frozen=True)
class _Arcs:
    """Arcs ``[lo, hi]`` of ``P3``'s circle, (R,), with ``H^(j)`` at both ends, (m + 1, R)."""

    rows: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    at_lo: np.ndarray
    at_hi: np.ndarray

    def take(self, which) -> _Arcs:
        return _Arcs(self.rows[which], self.lo[which], self.hi[which], self.at_lo[:, which],
                     self.at_hi[:, which])

    def classify(self, bounds: _Bounds) -> tuple[np.ndarray, np.ndarray]:
        """:func:`_classify` of each arc."""
        return _classify(self.at_lo, self.at_hi, self.hi - self.lo,
                         bounds.moments[:, self.rows], bounds.rounding[:, self.rows])

    def split(self, taylor_coefficients: np.ndarray) -> _Arcs:
        """Each arc cut in :data:`ROOT_SPLIT` equal arcs (``H`` from its coefficients)."""
        cuts = self.lo[:, None] + (self.hi - self.lo)[:, None] * np.linspace(0.0, 1.0,
                                                                           ROOT_SPLIT + 1)
        cuts[:, -1] = self.hi     # neighbours share their ends exactly
        at = _derivatives(taylor_coefficients[self.rows], cuts)
        orders = len(at)
        return _Arcs(np.repeat(self.rows, ROOT_SPLIT), cuts[:, :-1].ravel(),
                     cuts[:, 1:].ravel(), at[:, :, :-1].reshape(orders, -1),
                     at[:, :, 1:].reshape(orders, -1))


class _Meeting:
    """``g = x2 . y4`` on ``P3``'s circle of N targets, in parts free of square roots.

    On the sheet ``(s, t)``, ``s = +-sqrt(base_root)`` and ``t = +-sqrt(wrist_root)``::

        g = (alpha + s beta + t gamma + s t delta) / scale,   scale > 0

    where ``base_root = 1 - c2^2`` (``c2``: cosine of link 2's angle to joint 1's axis) and
    ``wrist_root = 1 - c4^2`` (``c4 = y4 . y6``). ``c2`` and ``c4`` are of the form
    ``w0 + w1 cos(phi) + w2 sin(phi)``; ``alpha`` .. ``delta`` are trigonometric polynomials of
    degree at most 6, 4, 4 and 2. The same sums as :meth:`RoboSimianLimbIk._meeting`, in each
    pair's own basis, without 3-vectors: the root finder evaluates many angles per target.
    """

    def __init__(self, offsets: tuple[float, float, float, float], u: np.ndarray,
                 v: np.ndarray, cross: np.ndarray):
        self.offsets = offsets
        self.a3, self.b3, self.a5, self.b5 = offsets
        self.u, self.v, self.cross_matrix = u, v, cross
        self.cross = [[cross[:, i, j, None] for j in range(3)] for i in range(3)]

    @classmethod
    def of(cls, geometry: LimbGeometry, circle: _Circle) -> _Meeting:
        """The meeting function of the targets whose circles are given."""
        n = geometry.link_1_rotation[:, 0]
        h1 = geometry.link_1_rotation[:, 1]
        base_axes = np.stack([h1, np.cross(h1, n), n])            # rows: h1, h2, n
        wrist_axes = np.swapaxes(circle.r6, 1, 2)                   # rows: x6, y6, z6
        z6 = np.cross(wrist_axes[:, 0], wrist_axes[:, 1])
        wrist_axes = np.stack([wrist_axes[:, 0], wrist_axes[:, 1], z6], axis=1)
        radius = circle.radius[:, None]
        # P3 - P1 = u0 + u1 cos + u2 sin in (h1, h2, n); P5 - P3 likewise in (x6, y6, z6).
        # (einsum, not a matrix product: its rounding must not depend on how many targets.)
        u = np.stack([np.einsum('nj,kj->nk', circle.centre - geometry.shoulder_in_base,
                                base_axes),
                      radius * np.einsum('nj,kj->nk', circle.e1, base_axes),
                      radius * np.einsum('nj,kj->nk', circle.e2, base_axes)])
        v = np.stack([np.einsum('nj,nij->ni', circle.p5 - circle.centre, wrist_axes),
                      -radius * np.einsum('nj,nij->ni', circle.e1, wrist_axes),
                      -radius * np.einsum('nj,nij->ni', circle.e2, wrist_axes)])
        cross = np.einsum('ij,nkj->nik', base_axes, wrist_axes)     # (N, 3 base, 3 wrist)
        return cls((*geometry.upper_offset_m, *geometry.lower_offset_m), u[..., None],
                   v[..., None], cross)

    def take(self, rows) -> _Meeting:
        """The meeting function of some of the targets (rows may repeat)."""
        return _Meeting(self.offsets, self.u[:, rows], self.v[:, rows], self.cross_matrix[rows])

    def _along(self, w: np.ndarray, k: int, cos, sin):
        return w[0, :, k] + w[1, :, k] * cos + w[2, :, k] * sin

    def roots(self, cos, sin) -> tuple[np.ndarray, np.ndarray]:
        """``(base_root, wrist_root)``; both positive inside the sheets' edges."""
        c2 = self._along(self.u, 2, cos, sin) / self.a3
        c4 = self._along(self.v, 1, cos, sin) / self.b5
        return 1.0 - c2 * c2, 1.0 - c4 * c4

    def terms(self, cos, sin) -> tuple[np.ndarray, ...]:
        """``(alpha, beta, gamma, delta, base_root, wrist_root, scale)`` at angles."""
        a3, b3, a5, b5 = self.a3, self.b3, self.a5, self.b5
        uh1, uh2, un = (self._along(self.u, k, cos, sin) for k in range(3))
        vx, vy, vz = (self._along(self.v, k, cos, sin) for k in range(3))
        # x2 den2 = p + s q in (h1, h2, n), y4 den4 = r + t w in (x6, y6, z6).
        c2 = un / a3
        base_root = 1.0 - c2 * c2
        den2 = b3 * b3 + a3 * a3 * base_root
        p = (uh1 * (a3 * base_root), uh2 * (a3 * base_root), c2 * den2)
        q = (-b3 * uh2, b3 * uh1, None)
        c4 = vy / b5
        wrist_root = 1.0 - c4 * c4
        den4 = a5 * a5 + b5 * b5 * wrist_root
        r = (vx * (b5 * wrist_root), c4 * den4, vz * (b5 * wrist_root))
        w = (-a5 * vz, None, a5 * vx)

        def form(left, right):
            return sum(left[i] * self.cross[i][j] * right[j] for i in range(3)
                       for j in range(3) if left[i] is not None and right[j] is not None)

        return (form(p, r), form(q, r), form(p, w), form(q, w), base_root, wrist_root,
                den2 * den4)

    def edges(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 8) angles in [0, 2 pi) where ``c2`` or ``c4`` is +-1, and (N, 8) which exist."""
        found, exists = [], []
        for w, k, level in ((self.u, 2, self.a3), (self.v, 1, self.b5)):
            w0, w1, w2 = w[0, :, k, 0], w[1, :, k, 0], w[2, :, k, 0]
            amplitude = np.maximum(np.hypot(w1, w2), 1e-300)
            phase = np.arctan2(w2, w1)
            for end in (level, -level):
                ratio = (end - w0) / amplitude
                spread = np.arccos(np.clip(ratio, -1.0, 1.0))
                for side in (1.0, -1.0):
                    found.append(np.mod(phase + side * spread, 2.0 * math.pi))
                    exists.append(np.abs(ratio) <= 1.0)
        return np.stack(found, axis=1), np.stack(exists, axis=1)


def _sheet_value(terms: tuple[np.ndarray, ...], sheet_base, sheet_wrist) -> np.ndarray:
    """``g`` on a sheet from :meth:`_Meeting.terms` (square roots clipped at the edges)."""
    alpha, beta, gamma, delta, base_root, wrist_root, scale = terms
    s = sheet_base * np.sqrt(np.maximum(base_root, 0.0))
    t = sheet_wrist * np.sqrt(np.maximum(wrist_root, 0.0))
    return (alpha + s * beta + t * gamma + s * t * delta) / scale


def _meeting_polynomial(terms: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``H``, the product of ``g``'s numerators over the four sheets, and a bound of each factor.

    The product of the four conjugates ``alpha +- s beta +- t gamma +- s t delta`` is
    ``E^2 - t^2 F^2`` with ``E = alpha^2 + t^2 gamma^2 - s^2 beta^2 - s^2 t^2 delta^2`` and
    ``F = 2 (alpha gamma - s^2 beta delta)``: a polynomial in ``alpha`` .. ``delta``,
    ``s^2 = base_root`` and ``t^2 = wrist_root``, so a trigonometric polynomial of degree at
    most ``2 (2 * 6) = 24`` in ``phi``, defined on the whole circle. ``size``, the fourth power
    of the largest factor's magnitude, bounds its rounding.
    """
    alpha, beta, gamma, delta, base_root, wrist_root, _ = terms
    e = (alpha * alpha + wrist_root * gamma * gamma - base_root * beta * beta
         - base_root * wrist_root * delta * delta)
    f = 2.0 * (alpha * gamma - base_root * beta * delta)
    s, t = np.sqrt(np.abs(base_root)), np.sqrt(np.abs(wrist_root))
    size = (np.abs(alpha) + s * np.abs(beta) + t * np.abs(gamma) + s * t * np.abs(delta)) ** 4
    return e * e - wrist_root * f * f, size


def _derivatives(taylor_coefficients: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(m + 1, R, S) ``H^(j) = Re sum_k c_k (i k)^j e^{i k phi}`` at (R, S) angles.

    Args:
        taylor_coefficients: (R, m + 1, K) ``c_k (i k)^j``.
        angles: (R, S) [rad].
    """
    z = np.exp(1j * angles)[..., None]
    powers = np.cumprod(np.broadcast_to(z, (*angles.shape, taylor_coefficients.shape[2])),
                        axis=-1) / z                                     # z^k, k = 0..K-1
    return np.moveaxis(powers @ np.swapaxes(taylor_coefficients, 1, 2), -1, 0).real


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
        #: family -> {target and yaw bytes: principal solution, or None where infeasible}.
        self._solved: dict[int, dict[bytes, np.ndarray | None]] = {}
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

        Where the family has more than one solution (module docstring), the one farthest from
        the sheets' edges: the family's principal solution, the one a motion inside the family
        keeps. :meth:`solutions` returns all of them.

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
        targets, yaws = self.mirror_targets(targets_in_base, yaws_rad, foot)
        q, feasible = self._solve_principal(targets, yaws, family)
        return q * self.angle_signs[self.foot_index[foot]], feasible

    def solve_feet(self, targets_in_base, yaws_rad, family: int, feet: list[str]
                   ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`solve` of several limbs at once: (N, F, 3) targets and (N, F) yaws.

        Returns (N, F, 7) joint angles and (N, F) feasibility, ``[:, k]`` those of ``feet[k]``.
        """
        family_bits(family)
        targets = np.asarray(targets_in_base, dtype=float)
        yaws = np.asarray(yaws_rad, dtype=float)
        count = targets.shape[0]
        mirrored = [self.mirror_targets(targets[:, k], yaws[:, k], foot)
                    for k, foot in enumerate(feet)]
        q, feasible = self._solve_principal(np.concatenate([m[0] for m in mirrored]),
                                            np.concatenate([m[1] for m in mirrored]), family)
        signs = np.repeat([self.angle_signs[self.foot_index[foot]] for foot in feet], count)
        q = (q * signs[:, None]).reshape(len(feet), count, 7)
        return np.swapaxes(q, 0, 1), feasible.reshape(len(feet), count).T

    def _solve_principal(self, targets: np.ndarray, yaws: np.ndarray, family: int
                         ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_solve_reference` (wrapped) of front-right targets, each solved once."""
        memo = self._solved.setdefault(family, {})
        keys = [row.tobytes() for row in np.column_stack([targets, yaws])]
        found = {key: memo[key] for key in keys if key in memo}
        missing = {}  # key -> its first row
        for k, key in enumerate(keys):
            if key not in found:
                missing.setdefault(key, k)
        if missing:
            rows = list(missing.values())
            q_new, feasible_new = self._solve_reference(targets[rows], yaws[rows], family,
                                                        wrap=True)
            if len(memo) + len(rows) > MEMO_SIZE:
                memo.clear()
            for key, q_row, ok in zip(missing, q_new, feasible_new, strict=True):
                memo[key] = found[key] = q_row if ok else None
        values = [found[key] for key in keys]
        feasible = np.array([value is not None for value in values], dtype=bool)
        q = np.array([self.centers[family] if value is None else value for value in values])
        return q.reshape(len(keys), 7), feasible

    def solutions(self, targets_in_base, yaws_rad, foot: str = 'front_right'
                  ) -> LimbIkSolutions:
        """Every solution of every family at each target (feasible as in :meth:`solve`).

        Args:
            targets_in_base: (N, 3) sole positions in the base frame [m].
            yaws_rad: (N,) sole yaws relative to the base [rad].
            foot: Which limb (the targets are that limb's own, not mirrored).

        Returns:
            The solutions, their families and each target's count.
        """
        targets, yaws = self.mirror_targets(targets_in_base, yaws_rad, foot)
        parts = [_Found(np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros((0, 7)),
                        np.zeros(0))]
        for k in range(0, len(targets), CHUNK):
            found = self._solutions_chunk(targets[k:k + CHUNK], yaws[k:k + CHUNK], None,
                                          wrap=True)
            parts.append(replace(found, rows=found.rows + k))
        found = _Found(*(np.concatenate([getattr(part, f.name) for part in parts])
                         for f in fields(_Found)))
        # By target, then family, the family's principal solution first.
        order = np.lexsort((-found.margins, found.families, found.rows))
        rows, families, q = found.rows[order], found.families[order], found.q[order]
        count = np.bincount(rows, minlength=len(targets))
        rank = np.arange(len(rows)) - (np.cumsum(count) - count)[rows]
        width = int(count.max(initial=0))
        joint_angles = np.full((len(targets), width, 7), np.nan)
        joint_angles[rows, rank] = q * self.angle_signs[self.foot_index[foot]]
        labels = np.full((len(targets), width), -1)
        labels[rows, rank] = families
        principal = np.zeros((len(targets), width), dtype=bool)
        principal[rows, rank] = _group_starts(rows, families)
        return LimbIkSolutions(joint_angles, labels, principal, count)

    def mirror_targets(self, targets_in_base, yaws_rad, foot: str
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Targets and yaws of ``foot`` mirrored onto the front-right limb, and back.

        A mirror is its own inverse: the same call takes front-right targets (the thesis'
        workspace) to ``foot``'s.

        Args:
            targets_in_base: (N, 3) sole positions in the base frame [m].
            yaws_rad: (N,) sole yaws relative to the base [rad].
            foot: Which limb.
        """
        targets = np.atleast_2d(np.asarray(targets_in_base, dtype=float))
        yaws = np.broadcast_to(np.asarray(yaws_rad, dtype=float), (len(targets),))
        s = self._mirror(foot)
        sign = float(s[0] * s[1])  # a reflection turns yaw the other way
        return targets * s, yaws * sign

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


    def _circle(self, targets: np.ndarray, yaws: np.ndarray) -> _Circle:
        """``P3``'s circle (where the two spheres meet) and the wrist frame of each target."""
        geo = self.geometry
        finite = np.isfinite(targets).all(axis=1) & np.isfinite(yaws)
        targets = np.where(finite[:, None], targets, 0.0)
        yaws = np.where(finite, yaws, 0.0)
        r6, p5 = self._wrist_frames(targets, yaws)
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
        return _Circle(centre, radius, e1, e2, p5, r6, reachable)

    def _crossings(self, circle: _Circle, meeting: _Meeting) -> _Crossings:
        """Every crossing of ``g = 0`` on the four sheets, bracketed (module docstring).

        1. ``H``, the product of ``g``'s numerators on the four sheets, a trigonometric
           polynomial of degree at most :data:`MEETING_DEGREE`: its Fourier coefficients from
           :data:`MEETING_SAMPLES` samples, exact, bound ``|H'|`` and ``|H''|``.
        2. The circle is cut at the sheets' edges and in :data:`ROOT_GRID` arcs. An arc is
           dropped where the bounds prove it free of roots of ``H``, kept where they prove it
           holds exactly one, and else cut in :data:`ROOT_SPLIT`, down to
           :data:`ROOT_WIDTH_RAD`.
        3. On a kept arc inside the sheets' edges, a sheet whose ``g`` changes sign holds a
           crossing (one sheet on an arc with one root of ``H``).
        """
        count = len(circle.radius)
        m = TAYLOR_ORDER
        # 1. H's Fourier coefficients, H = Re sum_k c_k e^{i k phi}, and its bounds.
        samples = 2.0 * math.pi * np.arange(MEETING_SAMPLES) / MEETING_SAMPLES
        h, size = _meeting_polynomial(meeting.terms(np.cos(samples), np.sin(samples)))
        spectrum = np.fft.rfft(h, axis=1)[:, :MEETING_DEGREE + 1] / MEETING_SAMPLES
        orders = np.arange(MEETING_DEGREE + 1)
        weights = np.where(orders > 0, 2.0, 1.0)
        magnitudes = weights * np.abs(spectrum)
        moments = (orders ** np.arange(m + 2)[:, None]) @ magnitudes.T
        # Rounding: H's samples are good to a few ulps of size, values from the coefficients
        # to a few ulps of the moments; 1e-12 leaves a margin of 100 or more. H is evaluated
        # to EVALUATED_DEGREE: the rest of its spectrum counts as rounding too.
        kept = EVALUATED_DEGREE + 1
        rounding = (1e-12 * (moments[:m + 1] + float(MEETING_DEGREE) ** np.arange(m + 1)[:, None]
                             * size.max(axis=1))
                    + (orders[kept:] ** np.arange(m + 1)[:, None]) @ magnitudes[:, kept:].T)
        derivative_factors = (1j * orders[:kept]) ** np.arange(m + 1)[:, None]     # (m + 1, K)
        taylor = (weights[:kept] * spectrum[:, :kept])[:, None, :] * derivative_factors
        bounds = _Bounds(moments, rounding)
        # 2. The uniform grid's arcs (H by inverse FFT) that reach inside the sheets' edges.
        padded = np.zeros((count, m + 1, ROOT_GRID // 2 + 1), dtype=complex)
        padded[:, :, :kept] = spectrum[:, None, :kept] * derivative_factors
        at_lo = np.moveaxis(np.fft.irfft(padded, n=ROOT_GRID, axis=2), 1, 0) * ROOT_GRID
        at_hi = np.roll(at_lo, -1, axis=2)
        step = 2.0 * math.pi / ROOT_GRID
        edges, has_edge = meeting.edges()
        crossed = np.zeros((count, ROOT_GRID), dtype=bool)
        edge_rows, edge_cols = np.nonzero(has_edge)
        crossed[edge_rows, np.minimum(edges[edge_rows, edge_cols] // step,
                                      ROOT_GRID - 1).astype(int)] = True
        middle = (np.arange(ROOT_GRID) + 0.5) * step
        base_root, wrist_root = meeting.roots(np.cos(middle), np.sin(middle))
        searched = circle.reachable[:, None] & (crossed | ((base_root > 0.0)
                                                           & (wrist_root > 0.0)))
        empty, simple = _classify(at_lo, at_hi, step, moments[:, :, None], rounding[:, :, None])
        rows, cols = np.nonzero(searched & simple)
        kept = [(rows, cols * step, (cols + 1) * step)]
        rows, cols = np.nonzero(searched & ~simple & ~empty)
        arcs = _Arcs(rows, cols * step, (cols + 1) * step, at_lo[:, rows, cols],
                     at_hi[:, rows, cols])
        while len(arcs.rows):
            # An arc as narrow as ROOT_WIDTH_RAD is kept as it is: H has two roots in it, or a
            # double one. So are the arcs of a row with too many undecided ones (H ~ 0 all
            # along: a continuum of solutions).
            crowded = np.bincount(arcs.rows, minlength=count)[arcs.rows] > ROOT_CROWD
            stop = (arcs.hi - arcs.lo <= ROOT_WIDTH_RAD) | crowded
            kept.append((arcs.rows[stop], arcs.lo[stop], arcs.hi[stop]))
            arcs = arcs.take(~stop).split(taylor)
            empty, simple = arcs.classify(bounds)
            kept.append((arcs.rows[simple], arcs.lo[simple], arcs.hi[simple]))
            arcs = arcs.take(~empty & ~simple)
        rows, lo, hi = (np.concatenate(x) for x in zip(*kept, strict=True))
        # 3. Kept arcs cut at the sheets' edges; the sheets that change sign on a part inside.
        inner = has_edge[rows] & (edges[rows] > lo[:, None]) & (edges[rows] < hi[:, None])
        cut = np.flatnonzero(inner.any(axis=1))
        points = np.sort(np.concatenate([lo[cut, None], np.where(inner[cut], edges[rows[cut]],
                                                                 hi[cut, None]),
                                         hi[cut, None]], axis=1), axis=1)
        rows = np.concatenate([np.delete(rows, cut), np.repeat(rows[cut], points.shape[1] - 1)])
        lo = np.concatenate([np.delete(lo, cut), points[:, :-1].ravel()])
        hi = np.concatenate([np.delete(hi, cut), points[:, 1:].ravel()])
        meeting = meeting.take(rows)
        middle = 0.5 * (lo + hi)[:, None]
        base_root, wrist_root = meeting.roots(np.cos(middle), np.sin(middle))
        within = (hi > lo) & (base_root[:, 0] > 0.0) & (wrist_root[:, 0] > 0.0)
        rows, lo, hi, meeting = rows[within], lo[within], hi[within], meeting.take(within)
        at_lo = meeting.terms(np.cos(lo)[:, None], np.sin(lo)[:, None])
        at_hi = meeting.terms(np.cos(hi)[:, None], np.sin(hi)[:, None])
        found = []
        for sheet_base, sheet_wrist in SHEETS:
            g_lo = _sheet_value(at_lo, sheet_base, sheet_wrist)[:, 0]
            g_hi = _sheet_value(at_hi, sheet_base, sheet_wrist)[:, 0]
            rising = (g_lo < 0.0) & (g_hi >= 0.0)
            k = np.flatnonzero(rising | ((g_lo > 0.0) & (g_hi <= 0.0)))
            found.append(_Crossings(rows[k], np.full(len(k), sheet_base),
                                    np.full(len(k), sheet_wrist), lo[k], hi[k], g_lo[k],
                                    g_hi[k], rising[k]))
        return _Crossings(*(np.concatenate([getattr(part, f.name) for part in found])
                            for f in fields(_Crossings)))

    def _crossing_families(self, crossings: _Crossings) -> np.ndarray:
        """Family of each crossing: its sheets and direction (module docstring)."""
        base = crossings.sheet_base * self.geometry.axis_signs[1] > 0.0   # sin(q2) > 0
        wrist = crossings.sheet_wrist < 0.0                                 # sin(q5) > 0
        positive = crossings.rising ^ base ^ wrist                          # det(J) > 0
        return 4 * (~base) + 2 * (~wrist) + (~positive)

    def _solve_reference(self, targets: np.ndarray, yaws: np.ndarray, family: int,
                         wrap: bool) -> tuple[np.ndarray, np.ndarray]:
        """The family's principal solution (:meth:`solve`) of front-right targets."""
        q = np.broadcast_to(self.centers[family], (len(targets), 7)).copy()
        feasible = np.zeros(len(targets), dtype=bool)
        for k in range(0, len(targets), CHUNK):
            found = self._solutions_chunk(targets[k:k + CHUNK], yaws[k:k + CHUNK], family, wrap)
            order = np.lexsort((-found.margins, found.rows))
            first = order[_group_starts(found.rows[order])]
            q[k + found.rows[first]] = found.q[first]
            feasible[k + found.rows[first]] = True
        return q, feasible

    def _solutions_chunk(self, targets: np.ndarray, yaws: np.ndarray, family: int | None,
                         wrap: bool) -> _Found:
        """The feasible solutions of one family (or all, ``None``) of front-right targets."""
        geo = self.geometry
        circle = self._circle(targets, yaws)
        meeting = _Meeting.of(geo, circle)
        crossings = self._crossings(circle, meeting)
        families = self._crossing_families(crossings)
        if family is not None:
            crossings = crossings.take(families == family)
            families = families[families == family]
        rows = crossings.rows
        circle = circle.take(rows)
        terms = meeting.take(rows).terms
        sheet_base, sheet_wrist = crossings.sheet_base[:, None], crossings.sheet_wrist[:, None]

        def g_of(phi):
            return _sheet_value(terms(np.cos(phi)[:, None], np.sin(phi)[:, None]), sheet_base,
                                sheet_wrist)[:, 0]

        # Illinois false position: the bracket closes to the root within a few ulps. A
        # crossing stops where it closes, so that its root does not depend on the others
        # solved with it (the same target gives the same angles in any call).
        lo, hi, g_lo, g_hi = crossings.lo, crossings.hi, crossings.g_lo, crossings.g_hi
        kept_lo = np.zeros(len(rows), dtype=bool)
        kept_hi = np.zeros(len(rows), dtype=bool)
        mid = lo.copy()
        open_ = np.ones(len(rows), dtype=bool)
        for _ in range(60):
            width = g_hi - g_lo
            step = np.where(width != 0.0, (lo * g_hi - hi * g_lo) / np.where(width != 0.0, width,
                                                                              1.0), lo)
            mid = np.where(open_, np.clip(step, np.minimum(lo, hi), np.maximum(lo, hi)), mid)
            g_mid = g_of(mid)
            same = np.sign(g_mid) == np.sign(g_lo)
            moved_lo, moved_hi = open_ & same, open_ & ~same
            lo, g_lo = np.where(moved_lo, mid, lo), np.where(moved_lo, g_mid, g_lo)
            hi, g_hi = np.where(moved_hi, mid, hi), np.where(moved_hi, g_mid, g_hi)
            g_hi = np.where(moved_lo & kept_hi, 0.5 * g_hi, g_hi)
            g_lo = np.where(moved_hi & kept_lo, 0.5 * g_lo, g_lo)
            kept_hi, kept_lo = np.where(open_, same, kept_hi), np.where(open_, ~same, kept_lo)
            open_ &= (g_mid != 0.0) & (np.abs(hi - lo) > 4.0 * np.spacing(np.abs(mid)))
            if not open_.any():
                break

        phi = mid[:, None]
        p3 = circle.centre[:, None] + circle.radius[:, None, None] * (
            np.cos(phi)[..., None] * circle.e1[:, None] + np.sin(phi)[..., None]
            * circle.e2[:, None])
        x2, y2, x4, y4, g_root, admissible, margin = (
            value[:, 0] for value in self._meeting(p3, sheet_base, sheet_wrist,
                                                   circle.p5[:, None], circle.r6[:, None]))
        frame_2 = np.stack([x2, y2, np.cross(x2, y2)], axis=-1)
        frame_4 = np.stack([x4, y4, np.cross(x4, y4)], axis=-1)
        q12 = _pair_angles(np.broadcast_to(geo.link_1_rotation, frame_2.shape), frame_2)
        q34 = _pair_angles(frame_2, frame_4)
        q56 = _pair_angles(frame_4, circle.r6)
        q = np.stack([*q12, *q34, *q56, np.zeros(len(rows))], axis=1) * geo.axis_signs
        q[:, 6] = self.wrist_yaw_rad
        if wrap:
            center = self.centers[families]
            q[:, :6] = center[:, :6] + np.mod(q[:, :6] - center[:, :6] + math.pi,
                                              2 * math.pi) - math.pi
        # margin = min(sin(q2)^2, sin(q5)^2)
        feasible = (admissible & (margin > SINGULAR_SINE ** 2) & (np.abs(g_root) < 1e-9)
                    & np.all((q >= self.lower_limits - _EPS) & (q <= self.upper_limits + _EPS),
                             axis=1))
        return _Found(rows[feasible], families[feasible], q[feasible], margin[feasible])

    def family_of(self, joint_angles, foot: str = 'front_right', tolerance_rad: float = 1e-6,
                  likely: int | None = None) -> np.ndarray:
        """(N,) family of each row of limb angles (-1 where none matches within tolerance).

        A row matches any solution of its target, principal or not. ``likely`` is the family
        the caller expects: rows that are its principal solution cost one family's IK, the
        others one IK of every family.
        """
        q = np.atleast_2d(np.asarray(joint_angles, dtype=float))
        positions, yaws = self.forward(q, foot)
        result = np.full(len(q), -1)
        if likely is not None:
            candidate, feasible = self.solve(positions, yaws, likely, foot)
            result[feasible & (_angle_gap(candidate, q) < tolerance_rad)] = likely
        rest = np.flatnonzero(result < 0)
        if len(rest):
            every = self.solutions(positions[rest], yaws[rest], foot)
            if every.joint_angles.shape[1]:
                gaps = np.where(every.families >= 0,
                                _angle_gap(np.nan_to_num(every.joint_angles), q[rest, None]),
                                np.inf)
                best = np.argmin(gaps, axis=1)
                close = gaps[np.arange(len(rest)), best] < tolerance_rad
                result[rest[close]] = every.families[close, best[close]]
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
