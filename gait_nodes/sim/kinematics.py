"""Kinematic simulation: position-controlled joints and a floating base held by the stance feet.

Every step, :class:`PositionActuators` moves each joint toward its commanded position as a
position-controlled servo with velocity and acceleration limits does: its velocity changes by at
most ``acceleration_limit * dt`` per step, never exceeds ``velocity_limit``, and stops on a still
target without overshoot (each joint saturates on its own); the joint stays inside its URDF
position limits. :class:`KinematicSimulation`
then places the floating base so that the feet in contact stay where they touched down: the
base pose ``B`` minimises, over the stance feet ``k``,

    sum_k |B p_k - w_k|^2  (+ weight^2 |log3(W_k^T R_B R_k)|^2 for flat feet)

where ``p_k, R_k`` is the foot frame in the base frame (forward kinematics of the new joints)
and ``w_k, W_k`` where it was latched at touch-down. Three or more non-collinear stance feet fix
the whole pose, roll and pitch included, from their positions (Kabsch's closed form; the
orientation term is then left out); with fewer, flat feet add their orientation term (one flat
foot fixes the pose) and what the stance still leaves free (the rotation about the line of two
point feet) keeps its previous value: Gauss-Newton on SE(3) from the previous pose with a tiny
Levenberg-Marquardt damping, whose steps do not enter the directions the feet leave free.

Which feet are in contact is the caller's choice (the footstep plan's contact schedule); without
one, a foot is in contact when its contact point is within a tolerance of the ground (a foot in
the air lands there once it stops descending). A foot that touches down is latched where it
lands; a foot that lifts off is released. With the schedule's ground heights, a foot the
schedule puts down while it is still above them by more than the tolerance (a swing running
late) is not a contact until it has come down within the tolerance and stopped descending:
latched in the air, it would hold the base up as the foot is lowered, and tilt it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.linalg import lapack

from gait_nodes.errors import ParameterError
from gait_nodes.robot.model import RobotModel

#: Levenberg-Marquardt damping of the base fit's steps: what the feet leave free does not move
#: (the fixed points, where the gradient vanishes, are not biased by it).
STEP_DAMPING = 1e-9
#: Gauss-Newton stops when the update is below this [m or rad].
BASE_FIT_TOLERANCE = 1e-11
#: Without a contact schedule, a foot still descending more than this per step [m] has not
#: landed yet.
DESCENT_TOLERANCE_M = 1e-7
#: Feet whose second principal spread is below this fraction of the first are collinear.
COLLINEAR_TOLERANCE = 1e-6
BASE_FIT_ITERATIONS = 10
#: Weight [m/rad] of the base orientation of the previous tick in the fit on fewer than three
#: point feet: among the poses that put the feet in place, the fit takes the one closest in
#: orientation to the previous pose. Without it the step of least norm in (v, w) mixes a
#: rotation about the line of the feet into every body translation (that line does not pass
#: through the base origin), and a trot's base pitched 0.09 rad in 20 s.
ORIENTATION_PRIOR_M = 1e-3
#: LAPACK's SVD (divide and conquer), what numpy.linalg.svd runs.
_DGESDD = lapack.dgesdd


def _skew(vectors: np.ndarray) -> np.ndarray:
    """(N, 3, 3) cross-product matrices of (N, 3) vectors."""
    x, y, z = vectors[:, 0], vectors[:, 1], vectors[:, 2]
    zero = np.zeros_like(x)
    return np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1),
                     np.stack([-y, x, zero], -1)], -2)


# Per-tick results are plain (slotted) dataclasses, read-only by convention: a frozen
# dataclass's __init__ sets each field through object.__setattr__, three times the cost.
@dataclass(slots=True)
class ActuatorStep:
    """One step of the position-controlled joints (read-only).

    The step keeps its inputs; the diagnostics (:attr:`demanded_over_limit`, :attr:`saturated`,
    :attr:`clamped_to_limits`) are computed from them when asked.

    Attributes:
        positions_rad: (J,) joint positions after the step [rad or m].
        velocities_rad_s: (J,) mean joint velocities over the step [rad/s or m/s].
        commanded_rad: (J,) the command [rad or m].
        target_rad: (J,) the command clamped to the position limits [rad or m].
        demanded_rad_s: (J,) the mean velocity that would put each joint on its target at the
            end of the step [rad/s or m/s].
        previous_velocities_rad_s: (J,) mean joint velocities over the step before [rad/s].
        velocity_limits_rad_s: (J,) [rad/s or m/s].
        velocity_change_limits_rad_s: (J,) the acceleration limits times the step [rad/s].
        exact: Every joint moved at its demanded velocity (then none saturated).
    """

    positions_rad: np.ndarray
    velocities_rad_s: np.ndarray
    commanded_rad: np.ndarray
    target_rad: np.ndarray
    demanded_rad_s: np.ndarray
    previous_velocities_rad_s: np.ndarray
    velocity_limits_rad_s: np.ndarray
    velocity_change_limits_rad_s: np.ndarray
    exact: bool = False

    @property
    def demanded_velocity_over_limit(self) -> np.ndarray:
        """(J,) demanded velocity over the velocity limit; above 1 the joint saturated."""
        return np.abs(self.demanded_rad_s) / self.velocity_limits_rad_s

    @property
    def demanded_acceleration_over_limit(self) -> np.ndarray:
        """(J,) demanded velocity change over the acceleration limit's; above 1: saturated."""
        return (np.abs(self.demanded_rad_s - self.previous_velocities_rad_s)
                / self.velocity_change_limits_rad_s)

    @property
    def demanded_over_limit(self) -> np.ndarray:
        """(J,) the larger of the two ratios; above 1 the joint lags its command."""
        return np.maximum(self.demanded_velocity_over_limit,
                          self.demanded_acceleration_over_limit)

    @property
    def velocity_saturated(self) -> np.ndarray:
        """(J,) booleans: reaching the target would have taken more than the velocity limit."""
        return self.demanded_velocity_over_limit > 1.0 + 1e-9

    @property
    def acceleration_saturated(self) -> np.ndarray:
        """(J,) booleans: reaching the target would have taken more than the acceleration."""
        return self.demanded_acceleration_over_limit > 1.0 + 1e-9

    @property
    def saturated(self) -> np.ndarray:
        """(J,) booleans: the joint moved at a limit and still lags its command."""
        return self.velocity_saturated | self.acceleration_saturated

    @property
    def clamped_to_limits(self) -> np.ndarray:
        """(J,) booleans: the command was beyond the joint's position limits."""
        return np.abs(self.target_rad - self.commanded_rad) > 1e-12

    @property
    def any_saturated(self) -> bool:
        """Whether any joint saturated (``saturated.any()``)."""
        return not self.exact and bool(np.count_nonzero(self.saturated))

    @property
    def any_clamped(self) -> bool:
        """Whether any command was beyond its joint's limits (``clamped_to_limits.any()``)."""
        # A command the limits did not change is not clamped.
        return (self.target_rad.tobytes() != self.commanded_rad.tobytes()
                and bool(np.count_nonzero(self.clamped_to_limits)))


def stopping_velocity(error: np.ndarray, velocity_change: np.ndarray,
                      dt_s: float) -> np.ndarray:
    """Fastest velocity [rad/s] toward a target ``|error|`` away that can still stop on it.

    A joint whose velocity changes by at most ``velocity_change`` = ``a_max * dt`` per step of
    ``dt_s`` moves at ``v`` for one step and then brakes as hard as it may: it covers
    ``v dt + D(v)`` with ``D(v) = dt (v - c) + D(v - c)`` (``c`` = ``velocity_change``, D = 0
    below ``c``). This is the largest ``v`` with ``v dt + D(v) <= |error|``, in closed form:
    with ``E = |error| / (c dt)`` and ``m`` the largest integer with ``m (m + 1) / 2 <= E``,
    ``v = c (m + f)`` where ``f = (E - m (m + 1) / 2) / (m + 1)``. Moving at most this fast,
    the joint stops on the target without overshoot (the discrete form of
    ``sqrt(2 a_max |error|)``); below ``c dt`` of error it is ``|error| / dt``, the step that
    lands on the target.

    Args:
        error: (J,) distances to the targets [rad]; the sign is ignored.
        velocity_change: (J,) ``a_max * dt`` [rad/s], > 0.
        dt_s: Step in [s].

    Returns:
        (J,) velocities >= 0 [rad/s].
    """
    e = np.abs(error) / (velocity_change * dt_s)
    m = np.floor((np.sqrt(8.0 * e + 1.0) - 1.0) * 0.5)
    m -= m * (m + 1.0) * 0.5 > e  # the square root rounded up across an integer
    f = np.minimum((e - m * (m + 1.0) * 0.5) / (m + 1.0), 1.0)
    return velocity_change * (m + f)


class PositionActuators:
    """Position-controlled joints with velocity and acceleration limits (one per joint).

    Each step the mean velocity of a joint changes by at most ``a_max * dt`` and stays within
    ``v_max``; toward its target it moves with the target's own velocity (the feed-forward of a
    trajectory being tracked) plus the correction of the remaining error, that correction never
    faster than :func:`stopping_velocity` of the error: a joint stops on a still target without
    overshoot, and a target that moves within the limits is followed exactly (on the tick grid).

    Args:
        robot: The robot (joint order, position, velocity and acceleration limits).
    """

    def __init__(self, robot: RobotModel):
        self.robot = robot
        model = robot.model
        self.continuous = np.array([model.joints[model.getJointId(name)].nq == 2
                                    for name in robot.joint_names])
        self._any_continuous = bool(self.continuous.any())
        self.lower = np.array(robot.lower_limits)
        self.upper = np.array(robot.upper_limits)
        self.velocity_limits_rad_s = np.array(robot.velocity_limits_rad_s)
        self.acceleration_limits_rad_s2 = np.array(robot.acceleration_limits_rad_s2)
        # (dt, a_max dt, a_max dt^2): the velocity change and the error a step may close.
        self._change: tuple[float, np.ndarray, np.ndarray] = (math.nan, self.lower, self.lower)

    def step(self, positions_rad: np.ndarray, velocities_rad_s: np.ndarray,
             commanded_rad: np.ndarray, dt_s: float,
             commanded_velocities_rad_s: np.ndarray | None = None) -> ActuatorStep:
        """Move joints at ``positions_rad`` (moving at ``velocities_rad_s``) for ``dt_s`` [s].

        Args:
            positions_rad: (J,) positions at the start of the step [rad or m].
            velocities_rad_s: (J,) mean velocities over the step before [rad/s or m/s].
            commanded_rad: (J,) where the joints should be at the end of the step; beyond a
                joint's position limits it is clamped to them; continuous joints turn the
                short way round.
            dt_s: Step [s].
            commanded_velocities_rad_s: (J,) the command's velocity at the end of the step
                (feed-forward), or None for a still command.
        """
        if not dt_s > 0.0:
            raise ParameterError(f'dt_s must be > 0 s, got {dt_s!r}')
        commanded_rad = np.asarray(commanded_rad, dtype=float)
        target = np.clip(commanded_rad, self.lower, self.upper)
        delta = target - positions_rad
        if self._any_continuous:
            wrapped = (delta + math.pi) % (2.0 * math.pi) - math.pi
            delta = np.where(self.continuous, wrapped, delta)
        cached_dt, change, one_step = self._change
        if dt_s != cached_dt:
            change = self.acceleration_limits_rad_s2 * dt_s
            one_step = change * dt_s
            self._change = (dt_s, change, one_step)
        demanded = delta / dt_s
        if commanded_velocities_rad_s is None:
            feed_forward = 0.0
            correction = delta
        else:
            # A clamped command does not move: no feed-forward beyond the position limits.
            feed_forward = np.where(target == commanded_rad, commanded_velocities_rad_s, 0.0)
            correction = delta - feed_forward * dt_s
        # The error beyond the feed-forward, closed no faster than the joint can stop on it
        # (exactly, where the error is within one step of the acceleration limit).
        # (np.minimum/np.maximum: np.clip's dispatch costs more than the arithmetic here.)
        magnitude = np.abs(correction)
        if np.less_equal(magnitude, one_step).all():
            wanted = demanded  # every joint closes its error this step (tracking)
        else:
            stopping = stopping_velocity(correction, change, dt_s)
            closes = (magnitude <= one_step) | (magnitude <= stopping * dt_s)
            wanted = np.where(closes, demanded, feed_forward + np.copysign(stopping, correction))
        previous = np.asarray(velocities_rad_s, dtype=float)
        limit = self.velocity_limits_rad_s
        velocity = np.minimum(np.maximum(np.minimum(np.maximum(wanted, previous - change),
                                                    previous + change), -limit), limit)
        # Where nothing limited the step, every joint moved as demanded (bit for bit).
        exact = velocity.tobytes() == demanded.tobytes()
        positions = np.minimum(np.maximum(positions_rad + velocity * dt_s, self.lower),
                               self.upper)
        velocities = (positions - positions_rad) / dt_s
        return ActuatorStep(positions, velocities, commanded_rad, target, demanded, previous,
                            limit, change, exact)


def kabsch(points_in_base: np.ndarray, points_in_world: np.ndarray) -> pin.SE3 | None:
    """Rigid transform ``B`` minimising ``sum_k |B p_k - w_k|^2`` (Kabsch), or None.

    None when the points do not fix the rotation (fewer than three, or collinear).
    """
    count = len(points_in_base)
    if count < 3:
        return None
    centre_world = np.add.reduce(points_in_world, 0) / count
    return _kabsch_centred(points_in_base, points_in_world - centre_world, centre_world)


def _kabsch_centred(points_in_base: np.ndarray, centred_world: np.ndarray,
                    centre_world: np.ndarray) -> pin.SE3 | None:
    """:func:`kabsch` with the world side already centred.

    The simulation keeps the centred world side per stance: the latched feet do not move.
    """
    centre_base = _mean_of_rows(points_in_base.tolist())
    # ndarray.dot: the products of matmul (@) with less overhead per call on 3x3 matrices.
    u, singular, vt = svd3((points_in_base - centre_base).T.dot(centred_world))
    largest, second, _ = singular.tolist()
    if second <= COLLINEAR_TOLERANCE * (1e-300 if 1e-300 > largest else largest):  # max()
        return None
    # Kabsch: R = V diag(1, 1, d) U^T with d = det(V U^T) = +-1 (no reflection).
    v = vt.T
    rotation = v.dot(u.T)
    if _det3(rotation) < 0.0:
        u[:, 2] *= -1.0  # u diag(1, 1, -1)
        rotation = v.dot(u.T)
    # Identity and assignments: cheaper than SE3(R, t)'s overload resolution, the same pose.
    pose = pin.SE3.Identity()
    pose.rotation = rotation
    pose.translation = centre_world - rotation.dot(centre_base)
    return pose


def _mean_of_rows(rows: list) -> np.ndarray:
    """``np.add.reduce(points, 0) / len(points)`` of (N, 3) points given as lists of floats.

    The same sums in the same order (a reduction over the outer axis adds the rows one after
    the other), so the same bits, in scalar arithmetic: numpy's reduction and its division of
    a few floats cost more than the arithmetic (test_kinematic_simulator checks the bits).
    """
    (x, y, z), *others = rows
    for other_x, other_y, other_z in others:
        x += other_x
        y += other_y
        z += other_z
    count = len(rows)
    return np.array([x / count, y / count, z / count])


def svd3(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``numpy.linalg.svd(matrix)`` of a small matrix by calling LAPACK's ``dgesdd`` directly.

    numpy.linalg.svd runs the same LAPACK routine (``dgesdd``, full U and V^T) behind a
    wrapper that costs twice the factorization of a 3x3 matrix; scipy's binding skips it.
    Where numpy and scipy ship the same LAPACK the factors are equal to the bit (they are here:
    test_kinematic_simulator checks them against numpy's to 1e-12 on random, rank-deficient and
    scaled matrices). A failure to converge falls back to numpy (which raises LinAlgError).
    """
    u, singular, vt, info = _DGESDD(matrix)
    if info != 0:
        return np.linalg.svd(matrix)
    return u, singular, vt


def _det3(m: np.ndarray) -> float:
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def fit_base_pose(base_guess: pin.SE3, feet_in_base: list[pin.SE3], feet_in_world: list[pin.SE3],
                  rotation_weight_m: float = 0.0) -> pin.SE3:
    """Base pose that best puts the foot frames ``feet_in_base`` on ``feet_in_world``.

    Three or more non-collinear feet fix the pose from their positions alone: least squares in
    closed form (:func:`kabsch`). Fewer feet: least squares over the positions and, for flat
    feet (``rotation_weight_m`` [m/rad] > 0), the sole orientations, for point feet a weak pull
    (:data:`ORIENTATION_PRIOR_M`) towards the orientation of ``base_guess``: the minimiser
    nearest ``base_guess`` (what :func:`fit_base_pose_gauss_newton`, the reference, finds by
    damped Gauss-Newton on SE(3) from it). What point feet leave free (the rotation about the
    line of two of them) thus keeps its value in ``base_guess``. The cases of a walk have
    cheaper forms, equal to the reference to its convergence tolerance (tested): one flat foot
    and two point feet in closed form, two flat feet by Gauss-Newton on the rotation alone.

    Args:
        base_guess: The previous base pose.
        feet_in_base: Foot frames in the base frame (forward kinematics).
        feet_in_world: Where each of those feet must be in the world.
        rotation_weight_m: Length that turns a sole orientation error [rad] into a residual
            [m]; 0 for point feet.

    Returns:
        The base pose in the world.
    """
    count = len(feet_in_base)
    p = np.array([f.translation for f in feet_in_base]).reshape(count, 3)
    w = np.array([f.translation for f in feet_in_world]).reshape(count, 3)
    closed_form = kabsch(p, w)
    if closed_form is not None:
        return closed_form
    fitted = None
    if count == 1 and rotation_weight_m > 0.0:
        fitted = _fit_one_flat_foot(feet_in_base[0], feet_in_world[0])
    elif count == 2 and rotation_weight_m == 0.0:
        fitted = _fit_two_point_feet(base_guess.rotation, p, w)
    elif count == 2:
        fitted = _fit_two_flat_feet(base_guess.rotation, p, w, feet_in_base, feet_in_world,
                                    rotation_weight_m)
    return fitted if fitted is not None else fit_base_pose_gauss_newton(
        base_guess, feet_in_base, feet_in_world, rotation_weight_m)


def _pose(rotation: np.ndarray, p_mean: np.ndarray, w_mean: np.ndarray) -> pin.SE3:
    """The pose of ``rotation`` that puts the mean of the feet on theirs.

    The least-squares translation of any rotation (the orientation residuals do not depend on
    it).
    """
    pose = pin.SE3.Identity()
    pose.rotation = rotation
    pose.translation = w_mean - rotation.dot(p_mean)
    return pose


def _fit_one_flat_foot(foot_in_base: pin.SE3, foot_in_world: pin.SE3) -> pin.SE3:
    """One flat foot fixes the pose: ``B = W F^-1`` puts both residuals at zero."""
    return foot_in_world * foot_in_base.inverse()


def _fit_two_point_feet(guess_rotation: np.ndarray, p: np.ndarray,
                        w: np.ndarray) -> pin.SE3 | None:
    """The base fit on two point feet, in closed form up to one scalar equation.

    With ``t`` at its least-squares value the cost is ``|R d - e|^2 / 2 + mu^2 theta^2`` where
    ``d = p_1 - p_2`` (base frame), ``e = w_1 - w_2`` (world), ``mu`` =
    :data:`ORIENTATION_PRIOR_M` and ``theta`` the angle of ``S = R_g^T R`` (the prior's
    residual is ``mu log3(S)``). A rotation of angle ``theta`` turns ``d`` by at most
    ``theta``, so among those of one angle the rotation in the plane of ``d`` and
    ``f = R_g^T e`` (axis ``d x f``) brings ``d`` closest to ``f``; along it the cost is
    ``-|d||f| cos(alpha - theta) + mu^2 theta^2`` (+ const), ``alpha`` the angle from ``d``
    to ``f``, stationary where ``|d||f| sin(alpha - theta) = 2 mu^2 theta``: one root in
    ``[0, alpha]``, found by Newton from the linearised one. None (the caller falls back to
    Gauss-Newton) when the feet coincide or ``d`` points against ``f``.
    """
    d = (p[0] - p[1]).tolist()
    f = guess_rotation.T.dot(w[0] - w[1]).tolist()
    dx, dy, dz = d
    fx, fy, fz = f
    ax, ay, az = dy * fz - dz * fy, dz * fx - dx * fz, dx * fy - dy * fx
    sine = math.sqrt(ax * ax + ay * ay + az * az)  # |d||f| sin(alpha)
    cosine = dx * fx + dy * fy + dz * fz  # |d||f| cos(alpha)
    k = math.hypot(sine, cosine)  # |d||f|
    if not k > 0.0 or cosine <= 0.0:
        return None
    p_mean = (p[0] + p[1]) * 0.5
    w_mean = (w[0] + w[1]) * 0.5
    if sine == 0.0:
        return _pose(guess_rotation, p_mean, w_mean)
    alpha = math.atan2(sine, cosine)
    mu2 = 2.0 * ORIENTATION_PRIOR_M * ORIENTATION_PRIOR_M
    theta = alpha * k / (k + mu2)
    for _ in range(BASE_FIT_ITERATIONS):
        residual = k * math.sin(alpha - theta) - mu2 * theta
        change = residual / (k * math.cos(alpha - theta) + mu2)
        theta += change
        if abs(change) <= 1e-17:
            break
    scale = theta / sine
    axis_angle = np.array([ax * scale, ay * scale, az * scale])
    return _pose(guess_rotation.dot(pin.exp3(axis_angle)), p_mean, w_mean)


def _fit_two_flat_feet(guess_rotation: np.ndarray, p: np.ndarray, w: np.ndarray,
                       feet_in_base: list[pin.SE3], feet_in_world: list[pin.SE3],
                       rotation_weight_m: float) -> pin.SE3:
    """The base fit on two flat feet: Gauss-Newton on the rotation alone.

    The translation's least-squares value ``t = w_mean - R p_mean`` is exact for every ``R``,
    so the fit is ``min_R |R d - e|^2 / 2 + mu^2 sum_k |log3(W_k^T R F_k)|^2`` (``d``, ``e``
    as in :func:`_fit_two_point_feet`, ``F_k``, ``W_k`` the sole orientations, ``mu`` =
    ``rotation_weight_m``): the same minimiser as the 6-dof reference with 3x3 normal
    equations, damped and stopped alike (on feet a rigid motion apart, as a walk's are; with
    a near-zero sole weight on feet millimetres apart and millimetres inconsistent, the
    problem has several local minima and the two iterations may stop in different ones).
    """
    half = math.sqrt(0.5)
    # Residuals r = (R d - e, log3(E_1), log3(E_2)) * weights, E_k = W_k^T R F_k; their
    # Jacobian for R exp(step): (-R [d]x, Jlog3(E_k) F_k^T) * weights, stacked (9, 3).
    d_half = (p[0] - p[1]) * half
    e_half = (w[0] - w[1]) * half
    skew_d = pin.skew(d_half)
    weights = np.array([1.0] * 3 + [rotation_weight_m] * 6)
    column_weights = weights[:, None]
    (world_t0, base_r0, base_t0), (world_t1, base_r1, base_t1) = [
        (foot_world.rotation.T, foot_base.rotation, foot_base.rotation.T)
        for foot_base, foot_world in zip(feet_in_base, feet_in_world, strict=True)]
    rotation = guess_rotation
    for _ in range(BASE_FIT_ITERATIONS):
        error0 = world_t0.dot(rotation).dot(base_r0)
        error1 = world_t1.dot(rotation).dot(base_r1)
        residual = np.concatenate((rotation.dot(d_half) - e_half, pin.log3(error0),
                                   pin.log3(error1))) * weights
        jacobian = np.vstack((-rotation.dot(skew_d), pin.Jlog3(error0).dot(base_t0),
                              pin.Jlog3(error1).dot(base_t1))) * column_weights
        jacobian_t = jacobian.T
        step = _solve_damped3(jacobian_t.dot(jacobian).tolist(),
                              jacobian_t.dot(residual).tolist())
        rotation = rotation.dot(pin.exp3(np.array(step)))
        if max(map(abs, step)) < BASE_FIT_TOLERANCE:
            break
    return _pose(rotation, (p[0] + p[1]) * 0.5, (w[0] + w[1]) * 0.5)


def _solve_damped3(hessian: list, gradient: list) -> list:
    """``-(H + STEP_DAMPING I)^-1 g`` for a symmetric positive semi-definite 3x3 ``H``.

    Cramer's rule on floats (the reference's np.linalg.solve is LU with pivoting: the same
    step to rounding for the well-conditioned normal equations of a fit).
    """
    (a, b, c), (_, d, e), (_, _, f) = hessian
    a += STEP_DAMPING
    d += STEP_DAMPING
    f += STEP_DAMPING
    # Cofactors of the symmetric matrix [[a, b, c], [b, d, e], [c, e, f]].
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    gx, gy, gz = gradient
    return [-(c00 * gx + c01 * gy + c02 * gz) / det, -(c01 * gx + c11 * gy + c12 * gz) / det,
            -(c02 * gx + c12 * gy + c22 * gz) / det]


def fit_base_pose_gauss_newton(base_guess: pin.SE3, feet_in_base: list[pin.SE3],
                               feet_in_world: list[pin.SE3],
                               rotation_weight_m: float = 0.0) -> pin.SE3:
    """:func:`fit_base_pose` by damped Gauss-Newton on SE(3) from ``base_guess`` (any count).

    The reference of the closed forms, and the fit of the cases without one.
    """
    count = len(feet_in_base)
    p = np.array([f.translation for f in feet_in_base]).reshape(count, 3)
    w = np.array([f.translation for f in feet_in_world]).reshape(count, 3)
    skews = _skew(p)
    pose = pin.SE3(base_guess)
    for _ in range(BASE_FIT_ITERATIONS):
        rotation, translation = pose.rotation, pose.translation
        residuals = [(p @ rotation.T + translation - w).ravel()]
        position_jacobian = np.zeros((count, 3, 6))
        position_jacobian[:, :, :3] = rotation
        position_jacobian[:, :, 3:] = -np.einsum('ij,njk->nik', rotation, skews)
        jacobians = [position_jacobian.reshape(-1, 6)]
        if rotation_weight_m == 0.0:
            prior = base_guess.rotation.T @ rotation
            prior_block = np.zeros((3, 6))
            prior_block[:, 3:] = ORIENTATION_PRIOR_M * pin.Jlog3(prior)
            residuals.append(ORIENTATION_PRIOR_M * pin.log3(prior))
            jacobians.append(prior_block)
        else:
            for foot_base, foot_world in zip(feet_in_base, feet_in_world, strict=True):
                error = foot_world.rotation.T @ rotation @ foot_base.rotation
                block = np.zeros((3, 6))
                block[:, 3:] = rotation_weight_m * pin.Jlog3(error) @ foot_base.rotation.T
                residuals.append(rotation_weight_m * pin.log3(error))
                jacobians.append(block)
        r = np.concatenate(residuals)
        jacobian = np.vstack(jacobians)
        step = -np.linalg.solve(jacobian.T @ jacobian + STEP_DAMPING * np.eye(6),
                                jacobian.T @ r)
        pose = pose * pin.exp6(step)
        if np.max(np.abs(step)) < BASE_FIT_TOLERANCE:
            break
    return pose


@dataclass(frozen=True)
class SimulationSettings:
    """Settings of :class:`KinematicSimulation`.

    Attributes:
        ground_height_m: Height of the ground plane in the world [m].
        contact_height_tolerance_m: Without a contact schedule, a foot whose contact point is
            at most this far above the ground is in contact; with one and its ground heights,
            a foot due down touches down once this close to them [m].
        rotation_weight_m: Orientation weight of flat feet in the base fit [m/rad] (0: feet
            are points even on a robot whose IK holds the soles' orientation).
    """

    ground_height_m: float = 0.0
    contact_height_tolerance_m: float = 0.005
    rotation_weight_m: float = 0.1

    def __post_init__(self):
        checks = (('ground_height_m', -10.0, 10.0), ('contact_height_tolerance_m', 0.0, 0.5),
                  ('rotation_weight_m', 0.0, 10.0))
        for name, low, high in checks:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or not low <= value <= high:
                raise ParameterError(f'{name} must be a number in [{low}, {high}], got '
                                     f'{value!r}')


@dataclass(slots=True)
class SimulationStep:
    """What one step of :class:`KinematicSimulation` produced (read-only, as ActuatorStep).

    Attributes:
        q: Pinocchio configuration after the step (base pose and joints), read-only.
        actuators: The joint step (velocities, saturation, clamping).
        contacts: (F,) booleans: feet in contact after the step, read-only.
        contact_points_in_world: (F, 3) contact points; NaN for feet in the air [m].
        slip_m: Largest distance of a stance foot frame from where it was latched, after the
            base fit (non-zero only when the commands cannot keep every stance foot still).
        touched_down: Names of the feet latched at this step.
    """

    q: np.ndarray
    actuators: ActuatorStep
    contacts: np.ndarray
    contact_points_in_world: np.ndarray
    slip_m: float
    touched_down: tuple[str, ...]


class KinematicSimulation:
    """Joints integrated as position-controlled actuators; the base held by the stance feet.

    Args:
        robot: The robot.
        q_initial: Starting configuration; every foot starts in contact, latched where it is.
        settings: Ground, contact tolerance and orientation weight.
    """

    def __init__(self, robot: RobotModel, q_initial: np.ndarray,
                 settings: SimulationSettings | None = None):
        self.robot = robot
        self.settings = settings or SimulationSettings()
        self.actuators = PositionActuators(robot)
        self._data = robot.new_data()
        self._flat_feet = robot.foot_orientation == 'yaw'
        self.q = np.array(q_initial, dtype=float)
        # The configuration of the forward kinematics in the base frame: base at the origin.
        self._q_in_base = self.q.copy()
        self._q_in_base[:7] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
        # Whether q is the base pose followed by the joint vector (1-DOF joints in the robot's
        # joint order, as every shipped robot has them): then q is built by one concatenation
        # and the joints written by a slice rather than by robot.set_joint_positions.
        model = robot.model
        self._joints_follow_base = (
            model.nq == 7 + len(robot.joint_names)
            and np.array_equal(robot.q_indices(robot.joint_names), np.arange(7, model.nq)))
        # Feet due down that were still in the air: index -> last height above the ground [m].
        self._late: dict[int, float] = {}
        # The last read-only contacts given to step() (by identity), their copy and its list.
        self._contacts_given: tuple = (None, None, None)
        self.joints = robot.joint_positions(self.q)
        #: (J,) mean joint velocities over the last step [rad/s or m/s] (at rest at the start).
        self.joint_velocities = np.zeros(len(self.joints))
        self.base = pin.XYZQUATToSE3(self.q[:7])
        feet = self._feet_in_base(self.joints)
        self.latched: list[pin.SE3 | None] = [self.base * foot for foot in feet]
        self._heights: np.ndarray | None = None
        # contact_points() and the stance's latched positions, until a foot lands or lifts.
        self._points: np.ndarray | None = None
        self._stance: tuple | None = None

    @property
    def contacts(self) -> np.ndarray:
        """(F,) booleans: feet latched on the ground."""
        return np.array([foot is not None for foot in self.latched])

    def _feet_in_base(self, joints: np.ndarray) -> list[pin.SE3]:
        """Foot frames in the base frame at ``joints`` (updateFramePlacement returns copies)."""
        q = self._q_in_base
        if self._joints_follow_base:
            q[7:] = joints
        else:
            self.robot.set_joint_positions(q, joints)
        model, data = self.robot.model, self._data
        pin.forwardKinematics(model, data, q)
        return [pin.updateFramePlacement(model, data, f) for f in self.robot.foot_frame_ids]

    def _contacts_by_height(self, feet: list[pin.SE3]) -> np.ndarray:
        """Contacts without a schedule, from the foot heights.

        A stance foot stays down while within the tolerance of the ground; a foot in the air
        touches down once within it and no longer descending.
        """
        heights = np.array([(self.base * foot).translation[2] for foot in feet]) \
            - self.robot.foot_frame_height_m - self.settings.ground_height_m
        near = heights <= self.settings.contact_height_tolerance_m
        previous = self._heights if self._heights is not None else heights
        settled = heights >= previous - DESCENT_TOLERANCE_M
        self._heights = heights
        return near & (self.contacts | settled)

    def contact_points(self) -> np.ndarray:
        """(F, 3) contact points of the latched feet; NaN rows for feet in the air [m].

        Read-only, and the same array until a foot lands or lifts: a caller may key what it
        derives from the contacts on the array's identity.
        """
        if self._points is None:
            points = np.full((len(self.latched), 3), np.nan)
            for k, foot in enumerate(self.latched):
                if foot is not None:
                    points[k] = foot.translation
                    points[k, 2] -= self.robot.foot_frame_height_m
            points.flags.writeable = False
            self._points = points
        return self._points

    def _still_in_the_air(self, k: int, height_m: float) -> bool:
        """Whether foot ``k``, due down, ``height_m`` above its ground [m], is not down yet.

        On time (within the tolerance when it is first due) it touches down at once; late (a
        swing running late), once within the tolerance and no longer descending, where it
        comes to rest.
        """
        previous = self._late.get(k)
        if previous is None and height_m <= self.settings.contact_height_tolerance_m:
            return False
        if previous is not None and height_m <= self.settings.contact_height_tolerance_m \
                and height_m >= previous - DESCENT_TOLERANCE_M:
            del self._late[k]
            return False
        self._late[k] = height_m
        return True

    def _latched_stance(self, kept: tuple[int, ...]) -> tuple:
        """``(kept, centred, centre, positions)`` of the latched feet ``kept`` in the world.

        Their positions (F, 3) [m] centred on their ``centre`` (what :func:`kabsch` computes of
        its world side) and as lists of floats: kept while the stance does not change.
        """
        if self._stance is None or self._stance[0] != kept:
            in_world = np.array([self.latched[k].translation for k in kept])
            centre = np.add.reduce(in_world, 0) / len(kept)
            self._stance = (kept, in_world - centre, centre, in_world.tolist())
        return self._stance

    def step(self, commanded_joints: np.ndarray, dt_s: float,
             contacts: np.ndarray | None = None,
             commanded_velocities: np.ndarray | None = None,
             contact_heights_m: np.ndarray | None = None) -> SimulationStep:
        """Advance by ``dt_s`` [s] toward ``commanded_joints`` (joint vector).

        Args:
            commanded_joints: (J,) commanded joint positions at the end of the step, in
                :attr:`RobotModel.joint_names` order [rad or m].
            dt_s: Step [s].
            contacts: (F,) booleans from a contact schedule, or None to decide by foot height.
            commanded_velocities: (J,) the command's velocities at the end of the step [rad/s]
                (a trajectory's feed-forward), or None for a still command.
            contact_heights_m: (F,) with ``contacts``: the height of the ground under each foot
                [m] (the schedule's footholds). A foot not latched yet touches down only once
                its contact point is within ``contact_height_tolerance_m`` of it. None: a
                scheduled foot touches down wherever it is.
        """
        actuators = self.actuators.step(self.joints, self.joint_velocities, commanded_joints,
                                        dt_s, commanded_velocities)
        feet = self._feet_in_base(actuators.positions_rad)
        if contacts is None:
            contacts = self._contacts_by_height(feet)
        given, contacts_copy, down = self._contacts_given
        if contacts is given:
            # A schedule's answer is a read-only array, the same one until the contacts change
            # (PlanContacts): its copy and list are those of the previous step.
            contacts = contacts_copy
        else:
            given = contacts if isinstance(contacts, np.ndarray) and contacts.base is None \
                and not contacts.flags.writeable else None
            contacts = np.array(contacts, dtype=bool)
            contacts.flags.writeable = False
            down = contacts.tolist()
            self._contacts_given = (given, contacts, down)
        latched = self.latched
        kept = tuple(k for k, d in enumerate(down) if d and latched[k] is not None)
        base = self.base
        slip = 0.0
        if kept:
            _, centred_world, centre_world, in_world = self._latched_stance(kept)
            in_base = [feet[k].translation for k in kept]
            # fit_base_pose's closed form, with the world side of the stance kept.
            fitted = (_kabsch_centred(np.array(in_base), centred_world, centre_world)
                      if len(kept) >= 3 else None)
            base = fitted if fitted is not None else fit_base_pose(
                self.base, [feet[k] for k in kept], [latched[k] for k in kept],
                self.settings.rotation_weight_m if self._flat_feet else 0.0)
            squared = []
            for point, (wx, wy, wz) in zip(in_base, in_world, strict=True):
                x, y, z = base.act(point).tolist()
                dx, dy, dz = x - wx, y - wy, z - wz
                squared.append(dx * dx + dy * dy + dz * dz)
            slip = math.sqrt(max(squared))
        touched = []
        in_the_air = False
        for k, d in enumerate(down):
            if not d:
                self._late.pop(k, None)
                if latched[k] is not None:
                    latched[k] = None
                    self._points = self._stance = None
            elif latched[k] is None:
                foot = base * feet[k]
                if contact_heights_m is not None and self._still_in_the_air(
                        k, foot.translation[2] - self.robot.foot_frame_height_m
                        - contact_heights_m[k]):
                    in_the_air = True
                    continue
                latched[k] = foot
                self._points = self._stance = None
                touched.append(self.robot.foot_names[k])
        if in_the_air:
            contacts = self.contacts
            contacts.flags.writeable = False
        self.base = base
        self.joints = actuators.positions_rad
        self.joint_velocities = actuators.velocities_rad_s
        if self._joints_follow_base:
            q = np.concatenate((pin.SE3ToXYZQUAT(base), self.joints))
        else:
            q = self.q.copy()
            q[:7] = pin.SE3ToXYZQUAT(base)
            self.robot.set_joint_positions(q, self.joints)
        q.flags.writeable = False
        self.q = q
        return SimulationStep(q, actuators, contacts, self.contact_points(), slip,
                              tuple(touched))
