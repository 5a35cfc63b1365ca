"""Full-model ZMP monitor: COM, multi-body ZMP, support polygon and signed stability margin.

The ZMP comes from the rate of change of the robot's momentum (Pinocchio's centroidal dynamics,
every body with its mass and rotational inertia). With ``h_G = (m c_dot, L_G)`` the momentum at
the COM ``c`` and ``dh_G`` its time derivative, the ground must supply the force and the moment
about a point ``O`` of the ground plane (height ``z0``)

    f = m (c_ddot - g),        tau_O = dL_G + (c - O) x f,

and the ZMP is the point of the plane about which the horizontal moment vanishes:

    p_x = O_x - tau_O_y / f_z,        p_y = O_y + tau_O_x / f_z.

This is Kurazume, Hasegawa and Yoneda's multi-mass ZMP (eqs. 26-27) with the rotational terms
of every body: for point masses ``dL_G + c x f`` reduces to their sum of ``m_i r_i x (r_i_ddot -
g)``. For a static robot it is the COM's ground projection; for a single point mass it is the
cart-table ZMP ``c - (c_z - z0) / g c_ddot``.

The ground plane follows the contacts (stairs): it is at the height of the lowest contact point,
i.e. the stance foot's in single support and, with feet at different heights in double support,
the lower one's (the plane the COM reference keeps its nominal height above,
:mod:`gait_nodes.com.support_height`); without contacts it is ``ground_height_m``. The ZMP is
published with that height as its z. The support polygon is the horizontal projection of the
contacts.

The support polygon is the convex hull of discs of the robot's foot radius around the contact
points (:func:`gait_nodes.geometry.foot_discs_polygon` for drawing it); the stability margin is
the exact signed distance of the ZMP to it (as :func:`gait_nodes.geometry.disc_support_margin`:
the distance to the hull of the contact centres plus the radius; the hulls are kept while the
contacts do not change), positive inside. Velocities and accelerations come from the integrated
configurations by central differences on the configuration manifold
(:func:`central_differences`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from gait_nodes.com.trajectory import GRAVITY_M_S2
from gait_nodes.geometry import (
    convex_hull,
    foot_discs_polygon,
    point_signed_distance,
    polygon_edge_list,
)

#: The project's one gravity (the cart-table planners' and Pinocchio's default model gravity),
#: so that the monitor judges the planned motion with the planners' physics.
STANDARD_GRAVITY_M_S2 = GRAVITY_M_S2
#: Vertices per foot disc in the published support polygon: the drawn polygon circumscribes
#: the discs, so a margin read off it (as ``inspect`` does) exceeds the exact one by at most
#: ``r (1 / cos(pi / 64) - 1)`` = 0.07 mm for a 0.055 m foot.
POLYGON_SEGMENTS_PER_FOOT = 64
#: Below this vertical ground force [N] the ZMP is undefined (the robot is falling freely).
MIN_NORMAL_FORCE_N = 1e-6


def central_differences(model: pin.Model, q_before: np.ndarray, q: np.ndarray,
                        q_after: np.ndarray, dt_before_s: float,
                        dt_after_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration at ``q`` from the configurations before and after it.

    ``q_before`` is ``dt_before_s`` [s] earlier, ``q_after`` ``dt_after_s`` [s] (default the
    same) later.
    With ``d1 = q (-) q_before`` and ``d2 = q_after (-) q`` (``pin.difference``: the free-flyer
    part in the base frame, as Pinocchio's ``v`` is) and steps ``h1``, ``h2``:
    ``v = (d1 h2 / h1 + d2 h1 / h2) / (h1 + h2)``, ``a = 2 (d2 / h2 - d1 / h1) / (h1 + h2)``,
    second-order accurate, exact for joint motions of constant acceleration.
    """
    v, a, _ = _from_differences(pin.difference(model, q_before, q),
                                pin.difference(model, q, q_after), dt_before_s, dt_after_s)
    return v, a


def _from_differences(d1: np.ndarray, d2: np.ndarray, dt_before_s: float,
                      dt_after_s: float | None, d1_rate: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`central_differences` from its two configuration differences, and ``d2 / h2``.

    ``d2 / h2`` is the next instant's ``d1 / h1`` along a stream of equal steps; ``d1_rate``:
    ``d1 / h1`` if known (the same division, so the same bits).
    """
    h1 = float(dt_before_s)
    h2 = h1 if dt_after_s is None else float(dt_after_s)
    rate1 = d1 / h1 if d1_rate is None else d1_rate
    rate2 = d2 / h2
    if h1 == h2:
        # The same values with a third fewer array operations (a fixed-rate simulation's case):
        # h2 / h1 is exactly 1 and 2 x / (h1 + h2) exactly x / h1 (scaling by 2 is exact).
        return (d1 + d2) / (h1 + h2), (rate2 - rate1) / h1, rate2
    v = (d1 * (h2 / h1) + d2 * (h1 / h2)) / (h1 + h2)
    a = 2.0 * (rate2 - rate1) / (h1 + h2)
    return v, a, rate2


class SlidingDifferences:
    """:func:`central_differences` along a stream of configurations (a simulation's ticks).

    Consecutive instants share a difference: the ``q_after (-) q`` of one call is the
    ``q (-) q_before`` of the next, kept and not computed again when the next call's
    ``q_before`` and ``q`` are the very same arrays (callers must not modify them in place),
    and so is its division by the step when the steps are equal. The values are
    :func:`central_differences`'s, bit for bit.

    Args:
        model: Pinocchio model of the configurations.
    """

    def __init__(self, model: pin.Model):
        self.model = model
        # (q, q_after, q_after (-) q, its step [s], the difference over the step) of the last
        # call.
        self._last: tuple = (None, None, None, None, None)

    def at(self, q_before: np.ndarray, q: np.ndarray, q_after: np.ndarray, dt_before_s: float,
           dt_after_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Velocity and acceleration at ``q`` (:func:`central_differences`)."""
        start, end, difference, step_s, rate = self._last
        if start is not q_before or end is not q:
            difference = pin.difference(self.model, q_before, q)
            rate = None
        elif float(dt_before_s) != step_s:
            rate = None
        after = pin.difference(self.model, q, q_after)
        v, a, after_rate = _from_differences(difference, after, dt_before_s, dt_after_s, rate)
        self._last = (q, q_after, after,
                      float(dt_before_s if dt_after_s is None else dt_after_s), after_rate)
        return v, a


@dataclass(frozen=True)
class Support:
    """The feet in contact at one instant and what the monitor derives from them.

    Built by :meth:`ZmpMonitor.support` once per set of contacts (they change at touch-downs
    and lift-offs, not every tick).

    Attributes:
        contact_points_in_world: (C, 3) contact points of the feet in contact [m].
        plane_height_m: Height of the ZMP's plane [m]: the lowest contact, else the ground.
        polygon: (M, 2) hull of the contact discs, CCW (empty without contacts) [m].
        centres_hull: (H, 2) hull of the contact centres, CCW (empty without contacts) [m].
        centres_hull_edges: :func:`gait_nodes.geometry.polygon_edge_list` of ``centres_hull``.
    """

    contact_points_in_world: np.ndarray
    plane_height_m: float
    polygon: np.ndarray
    centres_hull: np.ndarray
    centres_hull_edges: list


@dataclass(slots=True)
class ZmpState:
    """The monitor's view of one instant (read-only).

    A plain dataclass, one per tick: a frozen one's __init__ costs three times as much.

    Attributes:
        com_in_world: (3,) centre of mass of the full model [m].
        zmp_in_world: (3,) ZMP on the ground plane (z = its height: the lowest contact's) [m];
            NaN without ground force.
        normal_force_n: Vertical ground force ``m (c_ddot_z + g)`` [N].
        margin_m: Signed stability margin of the ZMP in the support polygon [m] (positive
            inside); -inf without contacts or ground force.
        contact_points_in_world: (C, 3) contact points of the feet in contact [m].
    """

    com_in_world: np.ndarray
    zmp_in_world: np.ndarray
    normal_force_n: float
    margin_m: float
    contact_points_in_world: np.ndarray

    @property
    def inside(self) -> bool:
        """Whether the ZMP is inside the support polygon (margin >= 0)."""
        return self.margin_m >= 0.0


class ZmpMonitor:
    """Multi-body ZMP, COM and stability margin of one robot model.

    Args:
        model: Pinocchio model with a free-flyer root.
        foot_radius_m: Radius of each foot's contact disc [m].
        ground_height_m: Height of the ground plane without contacts [m] (with contacts the
            plane is at the lowest contact, see the module docstring).
        gravity_m_s2: Gravity acceleration magnitude [m/s^2] (along -z).
    """

    def __init__(self, model: pin.Model, foot_radius_m: float, ground_height_m: float = 0.0,
                 gravity_m_s2: float = STANDARD_GRAVITY_M_S2):
        self.model = model
        self.data = model.createData()
        self.mass_kg = float(pin.computeTotalMass(model))
        self.foot_radius_m = float(foot_radius_m)
        self.ground_height_m = float(ground_height_m)
        self.gravity = np.array([0.0, 0.0, -gravity_m_s2])
        self._weight = (self.mass_kg * self.gravity).tolist()
        self._support_key = None
        self._support: Support | None = None

    def plane_height_m(self, contact_points_in_world: np.ndarray) -> float:
        """Height [m] of the ZMP's plane: the lowest contact, else ``ground_height_m``."""
        points = np.asarray(contact_points_in_world, dtype=float).reshape(-1, 3)
        return float(points[:, 2].min()) if len(points) else self.ground_height_m

    def com_and_zmp(self, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                    plane_height_m: float | None = None
                    ) -> tuple[np.ndarray, np.ndarray, float]:
        """COM (3,) [m], ZMP (3,) on the plane [m] and vertical ground force [N].

        ``plane_height_m``: height of the plane [m]; None: ``ground_height_m``.
        """
        plane = self.ground_height_m if plane_height_m is None else float(plane_height_m)
        com, zmp, fz = self._com_and_zmp(q, v, a, plane)
        return com, np.full(3, np.nan) if zmp is None else np.array(zmp), fz

    def _com_and_zmp(self, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                     plane: float) -> tuple[np.ndarray, list | None, float]:
        """:meth:`com_and_zmp` with the ZMP as a list of floats, None where undefined."""
        data = self.data
        dhg = pin.computeCentroidalMomentumTimeVariation(self.model, data, q, v, a)
        com = data.com[0].copy()
        # Scalars: numpy's per-call cost exceeds the arithmetic of three components.
        weight_x, weight_y, weight_z = self._weight
        linear_x, linear_y, linear_z, lx, ly, _ = dhg.vector.tolist()
        fx, fy, fz = linear_x - weight_x, linear_y - weight_y, linear_z - weight_z
        cx, cy, cz = com.tolist()
        cz -= plane
        # tau_O = dL_G + (c - O) x f, x and y components.
        tau_x = lx + cy * fz - cz * fy
        tau_y = ly + cz * fx - cx * fz
        if fz <= MIN_NORMAL_FORCE_N:
            return com, None, fz
        return com, [-tau_y / fz, tau_x / fz, plane], fz

    def support(self, contact_points_in_world: np.ndarray, hull: bool = False) -> Support:
        """The :class:`Support` of these contact points (C, 3) [m], kept while they stay.

        ``hull``: the points are already the vertices of their hull, in order (the physics
        simulation's contact points): it is not computed again.
        """
        points = np.asarray(contact_points_in_world, dtype=float).reshape(-1, 3)
        key = (points.tobytes(), self.ground_height_m)
        if key != self._support_key:
            if len(points) == 0:
                centres_hull = polygon = np.zeros((0, 2))
            else:
                centres_hull = points[:, :2].copy() if hull else convex_hull(points[:, :2])
                # Point contacts (the physics simulator's): the polygon is that hull.
                polygon = centres_hull if self.foot_radius_m <= 0.0 else foot_discs_polygon(
                    points[:, :2], self.foot_radius_m, POLYGON_SEGMENTS_PER_FOOT)
            points = points.copy()
            points.flags.writeable = False
            self._support = Support(points, self.plane_height_m(points), polygon, centres_hull,
                                    polygon_edge_list(centres_hull) if len(points) else [])
            self._support_key = key
        return self._support

    def support_polygon(self, contact_points_in_world: np.ndarray) -> np.ndarray:
        """(M, 2) hull of the contact discs, CCW (empty without contacts) [m]."""
        return self.support(contact_points_in_world).polygon

    def margin(self, zmp_in_world: np.ndarray, contact_points_in_world: np.ndarray) -> float:
        """Exact signed margin [m] of the ZMP in the hull of the contact discs."""
        return self._margin(zmp_in_world, self.support(contact_points_in_world))

    def margin_in(self, point_in_world, support: Support) -> float:
        """Exact signed margin [m] of a point (its x, y) in ``support``'s polygon.

        The support is one that :meth:`support` made (kept by the caller while it holds).
        """
        return self._margin_of(float(point_in_world[0]), float(point_in_world[1]), support)

    def _margin(self, zmp_in_world: np.ndarray, support: Support) -> float:
        return self._margin_of(float(zmp_in_world[0]), float(zmp_in_world[1]), support)

    def _margin_of(self, x: float, y: float, support: Support) -> float:
        if not support.centres_hull_edges or not (math.isfinite(x) and math.isfinite(y)):
            return -math.inf
        # geometry.disc_support_margin, with the centres' hull kept between calls.
        return point_signed_distance(x, y, support.centres_hull_edges) + self.foot_radius_m

    def evaluate(self, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                 contact_points_in_world: np.ndarray | Support) -> ZmpState:
        """COM, ZMP and margin at ``(q, v, a)`` with the feet at ``contact_points_in_world``.

        The contacts may be given as their :class:`Support` (what :meth:`support` made of them).
        """
        support = contact_points_in_world if isinstance(contact_points_in_world, Support) \
            else self.support(contact_points_in_world)
        com, zmp, fz = self._com_and_zmp(q, v, a, support.plane_height_m)
        if zmp is None:
            return ZmpState(com, np.full(3, np.nan), fz, -math.inf,
                            support.contact_points_in_world)
        return ZmpState(com, np.array(zmp), fz, self._margin_of(zmp[0], zmp[1], support),
                        support.contact_points_in_world)
