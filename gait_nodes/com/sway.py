"""Sway compensation trajectory (Kurazume, Hasegawa, Yoneda; seeds/003, eqs. 1-22).

The COM at constant height ``z_g`` has the cart-table ZMP ``p = c - A c_dd``, ``A = z_g / g``
(eq. 1). Kurazume keeps the ZMP on the line between the support legs (the diagonal pair of a
trot, the line from foot to foot of a biped, eq. 2) with a COM that is an explicit function of
time per half cycle (eqs. 4-5)::

    c(t) = C1 e^(t / sqrt(A)) + C2 e^(-t / sqrt(A)) + a2 t^2 + a1 t + a0

whose ZMP ``a0 - 2 A a2 + a1 t + a2 t^2`` (eq. 6) is a quadratic in time that stays on the line
when eqs. 7-12 hold, whatever ``C1`` and ``C2`` are. Two forms are provided:

* :func:`kurazume_half_cycle`: the closed form of one half cycle of a straight walk, eqs. 10-22
  (sway width ``D``, line angle ``theta``, speed ``v``, acceleration ``a``, free ``a2^y``);
* :func:`solve_sway`: a whole sequence of support lines (any geometry: trot, biped, curved paths
  after :class:`ArcPath`'s coordinate transformation). Each segment moves the ZMP along its line
  from waypoint ``W_k`` to ``W_k+1`` with Kurazume's quadratic time law (its free coefficient,
  ``a2`` along the line, is ``beta_k``); the homogeneous coefficients ``C1, C2`` of every segment
  are fixed by continuity of the COM position and velocity (the acceleration follows, since
  the ZMP is continuous), the initial COM state, and the end condition (at rest over the last
  waypoint, or its divergent component there), with the ``beta_k`` as small as the end
  condition allows. The ZMP is on the lines by construction, to rounding.

In a steady straight walk at constant speed the two agree (``C1, C2`` of eqs. 13-14, eq. 20); at
start and stop :func:`solve_sway` gives the acceleration from rest and the deceleration to rest
that eqs. 17-19 leave to the boundary conditions, with the half-cycle times of eq. 19 from
:func:`trapezoid_durations`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gait_nodes.com.trajectory import GRAVITY_M_S2, check_positive
from gait_nodes.errors import ComPlanningError

#: End conditions of :func:`solve_sway`.
END_CONDITIONS = ('rest', 'capture')


@dataclass(frozen=True)
class KurazumeHalfCycle:
    """One half cycle of the straight sway compensation trajectory (eqs. 4-5, 10-22).

    Local time ``t`` in ``[0, T / 2]``; x forward, the ZMP moves on the line
    ``x cos(theta) + y sin(theta) = d`` from ``y = D`` to ``y = -D``.

    Attributes:
        A: ``z_g / g`` [s^2].
        half_period_s: ``T / 2`` [s].
        stride_m: ``L = 4 D tan(theta)`` (eq. 22) [m].
        x: (C1, C2, a2, a1, a0) of x_g (eq. 4).
        y: (C1, C2, a2, a1, a0) of y_g (eq. 5).
    """

    A: float
    half_period_s: float
    stride_m: float
    x: tuple[float, float, float, float, float]
    y: tuple[float, float, float, float, float]

    def com(self, t: np.ndarray) -> np.ndarray:
        """(M, 3, 2) COM position, velocity, acceleration at local times ``t``."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        w = 1.0 / math.sqrt(self.A)
        out = np.empty((len(t), 3, 2))
        for axis, (c1, c2, a2, a1, a0) in enumerate((self.x, self.y)):
            grow, decay = c1 * np.exp(w * t), c2 * np.exp(-w * t)
            out[:, 0, axis] = grow + decay + a2 * t * t + a1 * t + a0
            out[:, 1, axis] = w * (grow - decay) + 2 * a2 * t + a1
            out[:, 2, axis] = w * w * (grow + decay) + 2 * a2
        return out

    def zmp(self, t: np.ndarray) -> np.ndarray:
        """(M, 2) ZMP of the COM, eq. 1."""
        state = self.com(t)
        return state[:, 0] - self.A * state[:, 2]


def kurazume_half_cycle(com_height_m: float, sway_width_m: float, line_angle_rad: float,
                        speed_m_s: float, acceleration_m_s2: float = 0.0, a2y: float = 0.0,
                        gravity_m_s2: float = GRAVITY_M_S2,
                        line_offset_m: float = 0.0) -> KurazumeHalfCycle:
    """The closed form of one half cycle (Kurazume eqs. 10-22).

    Args:
        com_height_m: ``z_g`` [m].
        sway_width_m: ZMP sway width ``D`` [m] (the ZMP goes from ``y = D`` to ``y = -D``).
        line_angle_rad: ``theta`` of the support line, in (0, pi/2) [rad].
        speed_m_s: COM speed ``v`` along x at ``t = 0`` [m/s].
        acceleration_m_s2: ``a`` [m/s^2]; the speed at ``T / 2`` is ``v + a T / 2``.
        a2y: The free quadratic coefficient of ``y_g`` [m/s^2].
        gravity_m_s2: Gravity [m/s^2].
        line_offset_m: ``d`` of the support line (eq. 2) [m].

    Raises:
        ComPlanningError: The half period does not exist (``v^2 + 4 a D tan(theta) < 0``) or
            is not positive.
    """
    A = check_positive('com_height_m', com_height_m) / gravity_m_s2
    D = check_positive('sway_width_m', sway_width_m)
    if not 0.0 < line_angle_rad < math.pi / 2:
        raise ComPlanningError(f'line_angle_rad must be in (0, pi/2), got {line_angle_rad}')
    v, a, tan = float(speed_m_s), float(acceleration_m_s2), math.tan(line_angle_rad)
    if a == 0.0:
        if v <= 0.0:
            raise ComPlanningError(f'without acceleration the speed must be > 0, got {v}')
        T = 4.0 * D * tan / v  # eq. 20
    else:
        discriminant = v * v + 4.0 * a * D * tan
        if discriminant < 0.0:
            raise ComPlanningError(f'v^2 + 4 a D tan(theta) = {discriminant:.6g} < 0: the '
                                   f'deceleration {a} m/s^2 stops the COM within the half cycle')
        T = 2.0 * (-v + math.sqrt(discriminant)) / a  # eq. 19
    if not T > 0.0:
        raise ComPlanningError(f'the half cycle has no positive duration (T = {T})')
    rA = math.sqrt(A)
    E_half = math.exp(T / (2.0 * rA))
    E_full = math.exp(T / rA)
    # y: y_dot = 0 at 0 and T / 2, ZMP from D to -D (eqs. 13-16). C1^y and C2^y are solved
    # from those boundary conditions; the transcribed eqs. 13-14 agree with them for
    # a2^y = 0 up to the sign of C2^y, and carry e^(T / sqrt(A)) + 1 where the conditions give
    # e^(T / (2 sqrt(A))) + 1 in the a2^y term.
    c1y = rA * (8 * D * (E_half - 1) - a2y * (E_half + 1) * T * T) / (2 * (E_full - 1) * T)
    c2y = -rA * E_half * (8 * D * (E_half - 1) + a2y * (E_half + 1) * T * T) \
        / (2 * (E_full - 1) * T)
    a0y = 2 * A * a2y + D                                   # eq. 15
    a1y = -4 * D / T - a2y * T / 2                          # eq. 16
    # x: ZMP on the line (eqs. 10-12), velocity v -> v + a T / 2 (eqs. 17-18).
    a2x = -tan * a2y                                        # eq. 12
    a1x = -tan * a1y                                        # eq. 11
    a0x = (line_offset_m - math.sin(line_angle_rad) * a0y) / math.cos(line_angle_rad)  # eq. 10
    c1x = (a + 2 * a2y * tan) / (4 * (E_half - 1)) * rA * T   # eq. 17
    c2x = c1x * E_half                                          # eq. 18
    return KurazumeHalfCycle(A, T / 2.0, 4.0 * D * tan,         # eq. 22
                             (c1x, c2x, a2x, a1x, a0x), (c1y, c2y, a2y, a1y, a0y))


def trapezoid_durations(distances_m, cruise_speed_m_s: float,
                        acceleration_m_s2: float) -> np.ndarray:
    """Half-cycle durations of a walk that accelerates from rest and decelerates to rest.

    The COM covers ``distances_m[k]`` in half cycle ``k`` under a trapezoidal speed profile
    (constant ``acceleration_m_s2`` up to ``cruise_speed_m_s``, then symmetric braking to rest
    at the end); each duration is eq. 19 (or eq. 20 at cruise) applied piecewise.

    Args:
        distances_m: (K,) distance per half cycle along the path (> 0) [m].
        cruise_speed_m_s: Top speed [m/s].
        acceleration_m_s2: Acceleration and braking magnitude [m/s^2].

    Returns:
        (K,) durations [s].
    """
    distances = np.asarray(distances_m, dtype=float)
    if distances.ndim != 1 or len(distances) < 1 or np.any(distances <= 0):
        raise ComPlanningError(f'half-cycle distances must be > 0, got {distances}')
    v_max = check_positive('cruise_speed_m_s', cruise_speed_m_s)
    a = check_positive('acceleration_m_s2', acceleration_m_s2)
    edges = np.concatenate([[0.0], np.cumsum(distances)])
    total = float(edges[-1])
    ramp = min(v_max * v_max / (2 * a), total / 2)
    v_top = math.sqrt(2 * a * ramp)

    def time_at(s: float) -> float:
        # Time to reach arc length s from rest under the trapezoid.
        if s <= ramp:
            return math.sqrt(2 * s / a)
        t_ramp = v_top / a
        if s <= total - ramp:
            return t_ramp + (s - ramp) / v_top
        remaining = max(total - s, 0.0)
        t_end = 2 * t_ramp + (total - 2 * ramp) / v_top
        return t_end - math.sqrt(2 * remaining / a)

    times = np.array([time_at(s) for s in edges])
    return np.diff(times)


@dataclass(frozen=True)
class SwayTrajectory:
    """COM and ZMP of a chain of support-line segments (see :func:`solve_sway`).

    Attributes:
        A: ``z_g / g`` [s^2].
        times_s: (K + 1,) segment boundaries [s].
        waypoints_in_world: (K + 1, 2) ZMP at each boundary [m].
        beta: (K,) quadratic time-law coefficient per segment.
        growing: (K, 2) coefficient of ``e^((s - h) / sqrt(A))`` per segment [m].
        decaying: (K, 2) coefficient of ``e^(-s / sqrt(A))`` per segment [m].
        end_residual_m: Largest violation of the end condition [m or m/s].
    """

    A: float
    times_s: np.ndarray
    waypoints_in_world: np.ndarray
    beta: np.ndarray
    growing: np.ndarray
    decaying: np.ndarray
    end_residual_m: float

    def _locate(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        k = np.clip(np.searchsorted(self.times_s, t, side='right') - 1, 0, len(self.beta) - 1)
        return t, k

    def sample(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """COM position, velocity, acceleration (M, 2) at times ``t`` (extrapolated outside)."""
        t, k = self._locate(t)
        h = np.diff(self.times_s)[k][:, None]
        s = t[:, None] - self.times_s[k][:, None]
        d = self.waypoints_in_world[k + 1] - self.waypoints_in_world[k]
        beta = self.beta[k][:, None]
        w = 1.0 / math.sqrt(self.A)
        grow = self.growing[k] * np.exp(w * (s - h))
        decay = self.decaying[k] * np.exp(-w * s)
        u = s / h
        position = self.waypoints_in_world[k] + d * (u + beta * (u * u - u)) \
            + 2 * self.A * d * beta / (h * h) + grow + decay
        velocity = d * (1.0 + beta * (2 * u - 1)) / h + w * (grow - decay)
        acceleration = d * 2 * beta / (h * h) + w * w * (grow + decay)
        return position, velocity, acceleration

    def zmp(self, t) -> np.ndarray:
        """(M, 2) ZMP of the planned motion, on the segment lines."""
        t, k = self._locate(t)
        h = np.diff(self.times_s)[k][:, None]
        u = (t[:, None] - self.times_s[k][:, None]) / h
        d = self.waypoints_in_world[k + 1] - self.waypoints_in_world[k]
        return self.waypoints_in_world[k] + d * (u + self.beta[k][:, None] * (u * u - u))


def solve_sway(waypoints_in_world, times_s, com_height_m: float, initial_position,
               initial_velocity=(0.0, 0.0), end: str = 'rest',
               gravity_m_s2: float = GRAVITY_M_S2, beta_weight: float = 1.0,
               end_weight: float = 1e8, capture_point=None) -> SwayTrajectory:
    """Sway compensation over a chain of support-line segments.

    Args:
        waypoints_in_world: (K + 1, 2) ZMP waypoints [m]: segment ``k`` keeps the ZMP on the
            line from ``W_k`` to ``W_k+1`` (a dwell when they coincide).
        times_s: (K + 1,) strictly increasing boundary times [s].
        com_height_m: ``z_g`` [m].
        initial_position: (2,) COM position at ``times_s[0]`` [m]. For a continuous
            acceleration, ``W_0`` must be the cart-table ZMP of the initial state.
        initial_velocity: (2,) COM velocity at ``times_s[0]`` [m/s].
        end: ``'rest'``: at rest over ``W_K`` at the end; ``'capture'``: the divergent component
            ``c + sqrt(A) c_d`` equals ``capture_point`` (default ``W_K``) at the end (a
            receding window).
        gravity_m_s2: Gravity [m/s^2].
        beta_weight: Weight of the time-law coefficients (scaled by the segment length
            squared, so that it weighs the ZMP's lead over a uniform motion [m]) against the
            end condition.
        end_weight: Weight of the end condition.
        capture_point: (2,) target of the divergent component for ``end='capture'`` [m].

    Returns:
        The trajectory; ``end_residual_m`` says how well the end condition was met.
    """
    W = np.array(waypoints_in_world, dtype=float)
    T = np.array(times_s, dtype=float)
    if W.ndim != 2 or W.shape[1] != 2 or len(W) < 2 or T.shape != (len(W),):
        raise ComPlanningError(f'sway needs (K + 1, 2) waypoints and (K + 1,) times with K >= 1,'
                               f' got {W.shape} and {T.shape}')
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(T))) or np.any(np.diff(T) <= 0):
        raise ComPlanningError('sway waypoints must be finite and times strictly increasing')
    if end not in END_CONDITIONS:
        raise ComPlanningError(f'end must be one of {END_CONDITIONS}, got {end!r}')
    A = check_positive('com_height_m', com_height_m) / gravity_m_s2
    w = 1.0 / math.sqrt(A)
    K = len(W) - 1
    h = np.diff(T)
    D = np.diff(W, axis=0)
    n = 5 * K  # per segment: growing (x, y), decaying (x, y), beta

    def state_rows(k: int, s: float):
        """Rows (2 axes) of position and velocity of segment k at local time s: (M, const)."""
        u = s / h[k]
        grow, decay = math.exp(w * (s - h[k])), math.exp(-w * s)
        rows, constants = [], []
        for order in (0, 1):
            for axis in (0, 1):
                row = np.zeros(n)
                if order == 0:
                    row[5 * k + axis] = grow
                    row[5 * k + 2 + axis] = decay
                    row[5 * k + 4] = D[k, axis] * (u * u - u + 2 * A / h[k] ** 2)
                    constants.append(W[k, axis] + D[k, axis] * u)
                else:
                    row[5 * k + axis] = w * grow
                    row[5 * k + 2 + axis] = -w * decay
                    row[5 * k + 4] = D[k, axis] * (2 * u - 1) / h[k]
                    constants.append(D[k, axis] / h[k])
                rows.append(row)
        return np.array(rows), np.array(constants)

    # Hard constraints: initial state, continuity of position and velocity.
    G, g = [], []
    rows, constants = state_rows(0, 0.0)
    G.append(rows)
    g.append(np.concatenate([initial_position, initial_velocity]) - constants)
    for k in range(K - 1):
        left, left_c = state_rows(k, h[k])
        right, right_c = state_rows(k + 1, 0.0)
        G.append(left - right)
        g.append(right_c - left_c)
    G, g = np.vstack(G), np.concatenate(g)
    # Soft end condition and small time-law coefficients.
    end_rows, end_constants = state_rows(K - 1, h[-1])
    if end == 'rest':
        J = end_rows
        target = np.concatenate([W[-1], [0.0, 0.0]]) - end_constants
    else:
        J = end_rows[:2] + math.sqrt(A) * end_rows[2:]
        goal = W[-1] if capture_point is None else np.asarray(capture_point, dtype=float)
        target = goal - (end_constants[:2] + math.sqrt(A) * end_constants[2:])
    H = end_weight * J.T @ J
    f = end_weight * J.T @ target
    regular = np.full(n, 1e-12)
    # beta |W_k+1 - W_k| / 4 is how far the ZMP runs ahead of the uniform motion on the line.
    regular[4::5] = beta_weight * (np.sum(D * D, axis=1) + 1e-6)
    H += np.diag(regular)
    # KKT of min 1/2 z'Hz - f'z subject to Gz = g.
    m = len(g)
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n], kkt[:n, n:], kkt[n:, :n] = H, G.T, G
    try:
        solution = np.linalg.solve(kkt, np.concatenate([f, g]))
    except np.linalg.LinAlgError as exc:
        raise ComPlanningError(f'the sway boundary problem is singular: {exc}') from exc
    z = solution[:n].reshape(K, 5)
    residual = float(np.max(np.abs(J @ solution[:n] - target)))
    return SwayTrajectory(A, T, W, z[:, 4].copy(), z[:, 0:2].copy(), z[:, 2:4].copy(),
                          residual)


def path_waypoints(corner_times_s, corners, same_place_m: float = 1e-6):
    """Sway waypoints of a piecewise-linear ZMP path that dwells at the feet.

    Kurazume's biped ZMP never stops: it moves along the line from one foot to the next over the
    whole half cycle. A reference that holds the ZMP at the stance ankle and moves it in double
    support (Lucy-style) has the same path; each dwell becomes one waypoint at the middle of the
    dwell, the other corners stay.

    Args:
        corner_times_s: (V,) times of the path's corners [s].
        corners: (V, 2) the path's corners [m].
        same_place_m: Corners closer than this are one place [m].

    Returns:
        ``(times (W,), waypoints (W, 2))``, first and last corner kept.
    """
    times = np.asarray(corner_times_s, dtype=float)
    points = np.asarray(corners, dtype=float)
    out_t, out_p = [times[0]], [points[0]]
    k = 1
    while k < len(points) - 1:
        j = k
        while j + 1 < len(points) and np.linalg.norm(points[j + 1] - points[k]) <= same_place_m:
            j += 1
        if j > k and j < len(points) - 1:
            out_t.append(0.5 * (times[k] + times[j]))
        elif j > k:
            out_t.append(times[k])
        else:
            out_t.append(times[k])
        out_p.append(points[k])
        k = j + 1
    if out_t[-1] < times[-1]:
        out_t.append(times[-1])
        out_p.append(points[-1])
    return np.array(out_t), np.array(out_p)


def line_intersection(p1, p2, q1, q2) -> np.ndarray:
    """Intersection of line ``p1 p2`` with line ``q1 q2`` (2-D); ComPlanningError if parallel."""
    p1, p2, q1, q2 = (np.asarray(v, dtype=float)[:2] for v in (p1, p2, q1, q2))
    r, s = p2 - p1, q2 - q1
    cross = r[0] * s[1] - r[1] * s[0]
    if abs(cross) < 1e-12 * max(np.dot(r, r), np.dot(s, s), 1e-300):
        raise ComPlanningError(f'support lines {p1}-{p2} and {q1}-{q2} are parallel')
    t = ((q1 - p1)[0] * s[1] - (q1 - p1)[1] * s[0]) / cross
    return p1 + t * r


def trot_waypoints(diagonals) -> np.ndarray:
    """ZMP waypoints of a trot: where each support diagonal meets the next one.

    Args:
        diagonals: (K, 2, 2) the two stance feet of each half cycle, in order.

    Returns:
        (K - 1, 2) waypoints; segment ``k`` (between waypoints ``k-1`` and ``k``) lies on
        diagonal ``k``.
    """
    lines = np.asarray(diagonals, dtype=float)
    return np.array([line_intersection(*lines[k], *lines[k + 1])
                     for k in range(len(lines) - 1)])


@dataclass(frozen=True)
class ArcPath:
    """Curved-path coordinate transformation: straight-walk ``(s, n)`` to the world.

    Kurazume (section 2.1): the straight trajectories apply to a gradually turning path by a
    coordinate transformation along the moving direction. ``s`` is the arc length along a path
    of constant curvature starting at ``origin`` with heading ``heading_rad``, ``n`` the
    lateral offset to its left.

    Attributes:
        curvature_per_m: Path curvature (> 0 turns left) [1/m].
        origin: (2,) start of the path [m].
        heading_rad: Initial heading [rad].
    """

    curvature_per_m: float
    origin: tuple[float, float] = (0.0, 0.0)
    heading_rad: float = 0.0

    def heading(self, s) -> np.ndarray:
        """Heading at arc length ``s`` [rad]."""
        return self.heading_rad + self.curvature_per_m * np.asarray(s, dtype=float)

    def to_world(self, points_sn) -> np.ndarray:
        """(M, 2) world points of straight-frame points ``(s, n)``."""
        points = np.atleast_2d(np.asarray(points_sn, dtype=float))
        s, lateral = points[:, 0], points[:, 1]
        kappa = self.curvature_per_m
        psi = self.heading(s)
        if abs(kappa) < 1e-12:
            base = np.stack([s * np.cos(self.heading_rad), s * np.sin(self.heading_rad)], 1)
        else:
            base = np.stack([(np.sin(psi) - np.sin(self.heading_rad)) / kappa,
                             (np.cos(self.heading_rad) - np.cos(psi)) / kappa], axis=1)
        normal = np.stack([-np.sin(psi), np.cos(psi)], axis=1)
        return np.asarray(self.origin, dtype=float) + base + lateral[:, None] * normal
