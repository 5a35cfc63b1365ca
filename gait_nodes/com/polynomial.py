"""Fifth-order polynomial COM (hip) trajectories (Vermeulen et al., "Lucy", seeds/004, sec. 2-3).

Lucy's planner connects the hip states ``(X, X_d, X_dd)`` at the phase boundaries (impact
``t_+``, end of double support ``t_D``, end of single support ``t_S``) with fifth-order
polynomials, one per phase and coordinate, so that position, velocity and acceleration are
continuous. Its inputs are objective locomotion parameters: the mean hip velocity ``v`` in single
support, the step length ``lambda`` and the step height ``delta``. Phase times follow from them:

    T_S = (X_H(t_S) - X_H(t_D)) / v          (eq. 13)
    T_D = (X_H(t_D) - X_H(t_+)) / X_H_d(t_+)  (eq. 8)

and the boundary accelerations put the ZMP at the stance ankle at the start and the end of single
support (eq. 25); here with the cart-table ZMP of the hip mass,
``X - (Y - Y_ankle) X_dd / (Y_dd + g)``.

Lucy's split of the step between the phases (``X_H(t_D) - X_FS(t_D)`` and ``X_H_d(t_+)``) comes
from the angular-momentum conditions of its multi-body model (eqs. 18-24), whose masses are not in
the paper; :class:`LucyObjective` takes the double-support hip advance as a parameter and, by
default, the boundary hip velocity for which the cart-table hip with its ZMP held at the ankle
covers single support in ``T_S`` (then the quintic keeps the ZMP within millimetres of the
ankle). The start from rest and the stop are ours (the paper plans steady steps): their ZMP is a
least-squares fit and goes up to about 0.1 m behind the rear ankle at the start of a 0.3 m step.

:func:`fit_quintic_com` is the same C2 piecewise-quintic COM made to follow a ZMP reference
(knots at the reference's phase changes, the cart-table ZMP equal to the reference at the knots,
least squares in between); the com_preview_controller node runs it as ``com_method=polynomial``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gait_nodes.com.trajectory import GRAVITY_M_S2, check_positive
from gait_nodes.errors import ComPlanningError

# Quintic Hermite basis on u in [0, 1], rows: p0, h v0, h^2 a0, p1, h v1, h^2 a1; columns u^0..u^5.
_HERMITE = np.array([
    [1, 0, 0, -10, 15, -6],
    [0, 1, 0, -6, 8, -3],
    [0, 0, 0.5, -1.5, 1.5, -0.5],
    [0, 0, 0, 10, -15, 6],
    [0, 0, 0, -4, 7, -3],
    [0, 0, 0, 0.5, -1, 0.5],
], dtype=float)


def _basis(u: np.ndarray, h: np.ndarray, order: int) -> np.ndarray:
    """(M, 6) weights of (p0, v0, a0, p1, v1, a1) in the ``order``-th derivative at ``u``."""
    u = np.asarray(u, dtype=float)
    coefficients = _HERMITE.copy()
    for _ in range(order):
        coefficients = coefficients[:, 1:] * np.arange(1, coefficients.shape[1])
    monomials = u[:, None] ** np.arange(coefficients.shape[1])
    values = monomials @ coefficients.T
    h = np.asarray(h, dtype=float)[:, None]
    scale = np.concatenate([np.ones_like(h), h, h * h, np.ones_like(h), h, h * h], axis=1)
    return values * scale / h ** order


@dataclass(frozen=True)
class PiecewiseQuintic:
    """C2 piecewise fifth-order trajectory through knot states.

    Attributes:
        knot_times_s: (M + 1,) strictly increasing knot times [s].
        knot_states: (M + 1, 3, D) position, velocity, acceleration at each knot.
    """

    knot_times_s: np.ndarray
    knot_states: np.ndarray

    def __post_init__(self):
        times = np.array(self.knot_times_s, dtype=float)
        states = np.array(self.knot_states, dtype=float)
        if times.ndim != 1 or len(times) < 2 or np.any(np.diff(times) <= 0):
            raise ComPlanningError('quintic knots need >= 2 strictly increasing times')
        if states.ndim != 3 or states.shape[:2] != (len(times), 3):
            raise ComPlanningError(f'knot states must be ({len(times)}, 3, D), got '
                                   f'{states.shape}')
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(states))):
            raise ComPlanningError('quintic knots hold a NaN or infinite value')
        for array in (times, states):
            array.setflags(write=False)
        object.__setattr__(self, 'knot_times_s', times)
        object.__setattr__(self, 'knot_states', states)

    def sample(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity, acceleration (M, D) at ``t`` (clamped to the knot range)."""
        t = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), self.knot_times_s[0],
                    self.knot_times_s[-1])
        k = np.clip(np.searchsorted(self.knot_times_s, t, side='right') - 1, 0,
                    len(self.knot_times_s) - 2)
        h = self.knot_times_s[k + 1] - self.knot_times_s[k]
        u = (t - self.knot_times_s[k]) / h
        ends = np.concatenate([self.knot_states[k], self.knot_states[k + 1]], axis=1)
        return tuple(np.einsum('mj,mjd->md', _basis(u, h, order), ends) for order in range(3))


def quintic(t0: float, t1: float, start, end) -> PiecewiseQuintic:
    """The fifth-order polynomial from state ``start`` at ``t0`` to ``end`` at ``t1``.

    Args:
        t0: Start time [s].
        t1: End time [s], > t0.
        start: (3, D) or (3,) position, velocity, acceleration at ``t0``.
        end: Same at ``t1``.
    """
    start = np.asarray(start, dtype=float).reshape(3, -1)
    end = np.asarray(end, dtype=float).reshape(3, -1)
    return PiecewiseQuintic(np.array([t0, t1]), np.stack([start, end]))


@dataclass(frozen=True)
class LucyObjective:
    """Objective locomotion parameters of Lucy's planner, validated.

    Attributes:
        hip_velocity_m_s: Mean horizontal hip velocity in single support ``v`` [m/s].
        step_length_m: Step length ``lambda`` [m].
        step_height_m: Step height ``delta`` (stairs; 0 on flat ground) [m].
        hip_height_m: Hip (COM) height above the stance ankle at the phase boundaries [m].
        double_support_advance_m: Hip advance in double support ``X_H(t_D) - X_H(t_+)`` [m].
        boundary_velocity_m_s: Hip velocity at the phase boundaries ``X_H_d(t_+)``
            (0: use ``v``) [m/s].
        single_support_start_offset_m: ``X_H(t_D) - X_FS(t_D)``; None: centred over the
            ankle, ``-(lambda - advance) / 2`` [m].
        start_s: Duration of the first double support, from rest [s].
        stop_s: Duration of the last double support, to rest [s].
        rest_fraction: Where the hip rests between the two ankles at the start, as a fraction
            of the step from the rear ankle (at the end: from the front ankle backwards); the
            hip must start behind the middle to reach single support's speed from rest.
    """

    hip_velocity_m_s: float
    step_length_m: float
    step_height_m: float = 0.0
    hip_height_m: float = 0.814
    double_support_advance_m: float = 0.07
    boundary_velocity_m_s: float = 0.0
    single_support_start_offset_m: float | None = None
    start_s: float = 1.0
    stop_s: float = 1.0
    rest_fraction: float = 0.2

    def __post_init__(self):
        check_positive('hip_velocity_m_s', self.hip_velocity_m_s, 10.0)
        check_positive('step_length_m', self.step_length_m, 5.0)
        check_positive('hip_height_m', self.hip_height_m, 10.0)
        check_positive('start_s', self.start_s, 60.0)
        check_positive('stop_s', self.stop_s, 60.0)
        check_positive('rest_fraction', self.rest_fraction, 0.5)
        advance = check_positive('double_support_advance_m', self.double_support_advance_m)
        if not advance < self.step_length_m:
            raise ComPlanningError(f'double_support_advance_m = {advance} must be below the '
                                   f'step length {self.step_length_m} m')
        if not (np.isfinite(self.step_height_m) and abs(self.step_height_m) < 1.0):
            raise ComPlanningError(f'step_height_m must be in (-1, 1) m, got '
                                   f'{self.step_height_m}')
        if self.boundary_velocity_m_s != 0.0:
            check_positive('boundary_velocity_m_s', self.boundary_velocity_m_s, 10.0)

    def entry_velocity_m_s(self, gravity_m_s2: float = GRAVITY_M_S2) -> float:
        """Hip velocity at the phase boundaries, ``X_H_d(t_+)`` [m/s].

        By default the velocity with which the cart-table hip, its ZMP held at the ankle,
        goes from ``X_H(t_D)`` to ``X_H(t_S)`` in ``T_S`` (for a centred single support,
        ``dX_S / 2 (1 + cosh(w T_S)) / (sinh(w T_S) / w)``, ``w = sqrt(g / h)``).
        """
        if self.boundary_velocity_m_s:
            return self.boundary_velocity_m_s
        w = float(np.sqrt(gravity_m_s2 / self.hip_height_m))
        start = self.start_offset_m
        end = start + self.step_length_m - self.double_support_advance_m
        tau = w * self.single_support_s
        # x(t) = start cosh(w t) + v / w sinh(w t) reaches end at T_S; v enters and leaves.
        return float((end - start * np.cosh(tau)) * w / np.sinh(tau))

    @property
    def single_support_s(self) -> float:
        """``T_S = (lambda - advance) / v`` (eq. 13) [s]."""
        return (self.step_length_m - self.double_support_advance_m) / self.hip_velocity_m_s

    def double_support_s(self, gravity_m_s2: float = GRAVITY_M_S2) -> float:
        """``T_D = advance / X_H_d(t_+)`` (eq. 8) [s]."""
        return self.double_support_advance_m / self.entry_velocity_m_s(gravity_m_s2)

    @property
    def start_offset_m(self) -> float:
        """``X_H(t_D) - X_FS(t_D)`` [m]."""
        if self.single_support_start_offset_m is not None:
            return float(self.single_support_start_offset_m)
        return -(self.step_length_m - self.double_support_advance_m) / 2.0


@dataclass(frozen=True)
class LucyWalk:
    """A planned sagittal walk: hip trajectory (x, height) and its phases.

    Attributes:
        hip: Piecewise quintic with D = 2 (x, height) [m].
        ankles: (S + 2, 2) ankle positions (x, height) in landing order; 0 and 1 stand at the
            start [m].
        phases: Tuple of ``(kind, start_s, end_s, stance_index)``, kind ``'double'`` or
            ``'single'``; in double support ``stance_index`` is the front ankle.
    """

    hip: PiecewiseQuintic
    ankles: np.ndarray
    phases: tuple


def _zmp_acceleration(x, ankle, height_above_ankle, vertical_acc, gravity):
    # Cart-table ZMP at the ankle: x - h x_dd / (z_dd + g) = ankle (Lucy eq. 25, point mass).
    return (x - ankle) * (vertical_acc + gravity) / height_above_ankle


def _interior_knots(t0: float, t1: float, start: np.ndarray, end: np.ndarray, zmp_start: float,
                    zmp_end: float, height: float, gravity: float, pieces: int = 8,
                    ramp_s: float = 0.3):
    """Knots strictly inside ``(t0, t1)`` joining two (x, height) states, for starts and stops.

    The ZMP is fitted (least squares) to ``zmp_start`` held, then a ``ramp_s`` ramp to
    ``zmp_end`` at the end of a start (at the beginning of a stop: ``ramp_s < 0``).
    """
    knots = np.linspace(t0, t1, pieces + 1)
    ramp = min(abs(ramp_s), (t1 - t0) / 2)
    corner = t1 - ramp if ramp_s > 0 else t0 + ramp
    corner_zmp = zmp_start if ramp_s > 0 else zmp_end
    planar = np.zeros((3, 2))
    x_start, x_end = planar.copy(), planar.copy()
    x_start[:, 0], x_end[:, 0] = start[:, 0], end[:, 0]
    reference = [[zmp_start, 0.0], [corner_zmp, 0.0], [zmp_end, 0.0]]
    fitted = fit_quintic_com([t0, corner, t1], reference, height, x_start, knot_times_s=knots,
                             end='state', end_state=x_end, gravity_m_s2=gravity)
    vertical = quintic(t0, t1, start[:, 1], end[:, 1])
    inner = knots[1:-1]
    states = np.empty((len(inner), 3, 2))
    states[:, :, 0] = fitted.knot_states[1:-1, :, 0]
    states[:, :, 1] = np.stack(vertical.sample(inner), axis=1)[:, :, 0]
    return list(inner), list(states)


def lucy_walk(objective: LucyObjective, steps: int,
              gravity_m_s2: float = GRAVITY_M_S2) -> LucyWalk:
    """Hip trajectory of a ``steps``-step walk from rest to rest (Lucy, sections 2-3).

    The robot starts at rest in double support, rear ankle at x = 0 and front ankle at
    ``lambda``; each single support is followed by a double support on the newly landed foot,
    each landing ``lambda`` ahead and ``delta`` higher; the walk starts and ends at rest between
    two ankles (see ``rest_fraction``). The first and last double supports (from and to rest)
    are split into eight quintics fitted to a held-then-ramped ZMP (least squares; the ZMP can
    leave the support briefly there, see the module docstring).
    """
    if steps < 1:
        raise ComPlanningError(f'steps must be >= 1, got {steps}')
    lam, delta = objective.step_length_m, objective.step_height_m
    height, g = objective.hip_height_m, gravity_m_s2
    T_S, T_D = objective.single_support_s, objective.double_support_s(g)
    b = objective.start_offset_m
    advance_single = lam - objective.double_support_advance_m
    v_b = objective.entry_velocity_m_s(g)
    ankles = np.array([[lam * i, delta * i] for i in range(steps + 2)])
    ankles[0] = [0.0, 0.0]
    rest_start = objective.rest_fraction * lam
    times = [0.0]
    states = [np.array([[rest_start, height], [0.0, 0.0], [0.0, 0.0]])]
    phases = []
    t = 0.0
    for i in range(1, steps + 1):
        stance = ankles[i]
        duration = objective.start_s if i == 1 else T_D
        phases.append(('double', t, t + duration, i))
        t += duration
        for offset in (b, b + advance_single):
            x = stance[0] + offset
            state = np.array([[x, stance[1] + height], [v_b, 0.0],
                              [_zmp_acceleration(x, stance[0], height, 0.0, g), 0.0]])
            if i == 1 and offset == b:
                inner_t, inner_s = _interior_knots(0.0, t, states[0], state, rest_start,
                                                   stance[0], height, g)
                times += inner_t
                states += inner_s
            times.append(t)
            states.append(state)
            if offset == b:
                phases.append(('single', t, t + T_S, i))
                t += T_S
    last, landed = ankles[steps], ankles[steps + 1]
    phases.append(('double', t, t + objective.stop_s, steps + 1))
    rest_end = last[0] + (1.0 - objective.rest_fraction) * lam
    final = np.array([[rest_end, landed[1] + height], [0.0, 0.0], [0.0, 0.0]])
    inner_t, inner_s = _interior_knots(t, t + objective.stop_s, states[-1], final, last[0],
                                       rest_end, height, g, ramp_s=-0.3)
    times += inner_t + [t + objective.stop_s]
    states += inner_s + [final]
    return LucyWalk(PiecewiseQuintic(np.array(times), np.array(states)), ankles, tuple(phases))


def reference_knots(times_s: np.ndarray, zmp: np.ndarray, max_segment_s: float,
                    tolerance_m: float = 1e-6) -> np.ndarray:
    """Knot times of a sampled ZMP reference.

    Its first and last samples, every sample where its slope changes (the phase changes of a
    piecewise-linear reference), and more knots so that no piece is longer than
    ``max_segment_s``.
    """
    times = np.asarray(times_s, dtype=float)
    zmp = np.asarray(zmp, dtype=float)
    if len(times) < 2:
        raise ComPlanningError('a ZMP reference needs at least two samples for knots')
    slopes = np.diff(zmp, axis=0) / np.diff(times)[:, None]
    bends = np.nonzero(np.max(np.abs(np.diff(slopes, axis=0)), axis=1)
                       * np.min(np.diff(times)) > tolerance_m)[0] + 1
    corners = np.unique(np.concatenate([[times[0]], times[bends], [times[-1]]]))
    knots = [corners[0]]
    for t0, t1 in zip(corners[:-1], corners[1:], strict=True):
        pieces = max(1, int(np.ceil((t1 - t0) / max_segment_s - 1e-9)))
        knots.extend(t0 + (t1 - t0) * np.arange(1, pieces + 1) / pieces)
    return np.array(knots)


def fit_quintic_com(times_s, zmp_reference, com_height_m: float, initial_state,
                    knot_times_s=None, max_segment_s: float = 0.2, end: str = 'rest',
                    gravity_m_s2: float = GRAVITY_M_S2, end_weight: float = 1e6,
                    samples_per_segment: int = 12, end_state=None,
                    capture_point=None) -> PiecewiseQuintic:
    """C2 piecewise-quintic COM whose cart-table ZMP follows a ZMP reference.

    The first knot is ``initial_state`` (so a switch to this generator is continuous); at every
    other knot the cart-table ZMP equals the reference (Lucy's ZMP at the ankle at each phase
    boundary); between knots the ZMP error is least squares; at the last knot the COM is at rest
    (``end='rest'``), its divergent component is over the reference (``'capture'``), or it is
    ``end_state`` (``'state'``).

    Args:
        times_s: (N,) reference sample times [s].
        zmp_reference: (N, 2) reference [m], linear between samples.
        com_height_m: COM height [m].
        initial_state: (3, 2) position, velocity, acceleration at ``times_s[0]``.
        knot_times_s: Knot times; default :func:`reference_knots`.
        max_segment_s: Longest polynomial piece for the default knots [s].
        end: ``'rest'``, ``'capture'`` or ``'state'``.
        gravity_m_s2: Gravity [m/s^2].
        end_weight: Weight of the end condition against the ZMP error.
        samples_per_segment: ZMP samples per piece in the least squares.
        end_state: (3, 2) state at the last knot when ``end='state'``.
        capture_point: (2,) target of ``c + sqrt(A) c_d`` at the last knot for
            ``end='capture'`` (default the reference there) [m].
    """
    times = np.asarray(times_s, dtype=float)
    reference = np.asarray(zmp_reference, dtype=float)
    A = check_positive('com_height_m', com_height_m) / gravity_m_s2
    if end not in ('rest', 'capture', 'state'):
        raise ComPlanningError(f"end must be 'rest', 'capture' or 'state', got {end!r}")
    knots = reference_knots(times, reference, max_segment_s) if knot_times_s is None \
        else np.asarray(knot_times_s, dtype=float)
    initial = np.asarray(initial_state, dtype=float).reshape(3, 2)
    M = len(knots) - 1
    if M < 1:
        raise ComPlanningError('the polynomial COM needs at least two knots')

    def ref(t):
        return np.stack([np.interp(t, times, reference[:, i]) for i in range(2)], axis=1)

    n = 3 * (M + 1)  # unknown (p, v, a) per knot, shared by both axes
    # Least-squares rows: cart-table ZMP at samples inside each piece.
    rows, targets = [], []
    u = (np.arange(samples_per_segment) + 0.5) / samples_per_segment
    for k in range(M):
        h = np.full(len(u), knots[k + 1] - knots[k])
        zmp_rows = _basis(u, h, 0) - A * _basis(u, h, 2)
        block = np.zeros((len(u), n))
        block[:, 3 * k:3 * k + 6] = zmp_rows
        rows.append(block)
        targets.append(ref(knots[k] + u * h))
    # End condition rows.
    last = 3 * M
    if end == 'rest':
        end_rows = np.zeros((3, n))
        end_rows[0, last], end_rows[1, last + 1], end_rows[2, last + 2] = 1.0, 1.0, 1.0
        end_targets = np.vstack([ref(knots[-1:]), np.zeros((2, 2))])
    else:
        end_rows = np.zeros((1, n))
        end_rows[0, last], end_rows[0, last + 1] = 1.0, np.sqrt(A)
        end_targets = ref(knots[-1:]) if capture_point is None \
            else np.asarray(capture_point, dtype=float).reshape(1, 2)
    weight = 0.0 if end == 'state' else np.sqrt(end_weight)
    Lm = np.vstack(rows + [weight * end_rows])
    Lt = np.vstack(targets + [weight * end_targets])
    # Hard constraints: initial state; ZMP at the reference at every later knot (or the end
    # state at the last one).
    G = np.zeros((3 + M, n))
    g = np.zeros((3 + M, 2))
    G[:3, :3] = np.eye(3)
    g[:3] = initial
    for k in range(1, M + 1):
        G[2 + k, 3 * k], G[2 + k, 3 * k + 2] = 1.0, -A
        g[2 + k] = ref(knots[k:k + 1])[0]
    if end == 'state':
        final = np.asarray(end_state, dtype=float).reshape(3, 2)
        G = np.vstack([G[:-1], np.eye(3, n, last)])
        g = np.vstack([g[:-1], final])
    H = Lm.T @ Lm + 1e-12 * np.eye(n)
    kkt = np.block([[H, G.T], [G, np.zeros((len(G), len(G)))]])
    solution = np.linalg.solve(kkt, np.vstack([Lm.T @ Lt, g]))
    states = solution[:n].reshape(M + 1, 3, 2)
    return PiecewiseQuintic(knots, states)
