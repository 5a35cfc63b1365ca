"""Sixth-order swing-foot polynomials with an intermediate via point (Lucy, seed 004).

Vermeulen et al. connect, for each swing-foot coordinate, the position, velocity and
acceleration at lift-off, a position at an intermediate time ``t_i`` and the position, velocity
and acceleration at touch-down with one sixth-order polynomial (seven conditions). The foot is
at rest on the ground at both ends (velocity and acceleration zero). Here the via point is at
mid-swing: the horizontal position and yaw half-way, the height ``step_height_m`` above the
higher of the two footholds. A foot put down from the air (a planner resumed or restarted with
it up there lowers it straight down, :data:`LANDING_TRAVEL_M`) has nothing to clear: its via
point is half-way down, and it descends without first rising ``step_height_m`` (a rise the
walk's swing time does not allow at the joint velocity limit: the foot then lagged and was
still in the air at its touch-down).

The whole-body IK follows the waypoints linearly (:func:`gait_nodes.robot.whole_body_ik.
swing_pose_at`), so the swing is sampled at least every :data:`MAX_WAYPOINT_SPACING_S`, the IK
period: a 0.6 s swing in 21 waypoints (30 ms apart) would be a polygon whose corners are
acceleration impulses of tens of m/s^2 (measured: a biped's multi-body ZMP 0.26 m out of the
sole); sampled at the IK period, the followed path is the polynomial to within 0.1 mm.
"""

from __future__ import annotations

import math

import numpy as np

from gait_nodes.contract import Swing, SwingTrajectory
from gait_nodes.errors import SwingPolicyError

#: Largest time between two waypoints of a polynomial swing [s] (the whole-body IK's period).
MAX_WAYPOINT_SPACING_S = 0.005
#: A swing that descends with at most this horizontal travel puts a foot down from the air [m].
LANDING_TRAVEL_M = 1e-6


def sixth_order_coefficients(start, end, via, duration_s: float, via_time_s: float
                             ) -> np.ndarray:
    """Coefficients ``c`` (7, D) of ``p(t) = sum_k c_k t^k`` through the seven conditions.

    Args:
        start: (D,) position at ``t = 0`` (velocity and acceleration zero).
        end: (D,) position at ``t = duration_s`` (velocity and acceleration zero).
        via: (D,) position at ``t = via_time_s``.
        duration_s: Swing time [s], > 0.
        via_time_s: Via time in (0, duration_s) [s].
    """
    if not duration_s > 0 or not 0 < via_time_s < duration_s:
        raise SwingPolicyError(f'a polynomial swing needs duration > 0 s and a via time inside '
                               f'it, got {duration_s} s and {via_time_s} s')
    T, ti = float(duration_s), float(via_time_s)
    k = np.arange(7)

    def row(t, order):
        coefficient = np.array([math.perm(int(n), order) for n in k], dtype=float)
        power = np.clip(k - order, 0, None)
        return coefficient * np.where(k >= order, t ** power, 0.0)

    matrix = np.array([row(0.0, 0), row(0.0, 1), row(0.0, 2), row(T, 0), row(T, 1), row(T, 2),
                       row(ti, 0)])
    zeros = np.zeros_like(np.asarray(start, dtype=float))
    rhs = np.array([start, zeros, zeros, end, zeros, zeros, via], dtype=float)
    return np.linalg.solve(matrix, rhs)


def evaluate(coefficients: np.ndarray, times_s, order: int = 0) -> np.ndarray:
    """(N, D) ``order``-th time derivative of the polynomial at ``times_s``."""
    t = np.asarray(times_s, dtype=float)[:, None]
    k = np.arange(len(coefficients))
    factor = np.array([math.perm(int(n), order) for n in k], dtype=float)
    power = np.clip(k - order, 0, None)
    terms = factor[None, :] * np.where(k[None, :] >= order, t ** power[None, :], 0.0)
    return terms @ coefficients


def polynomial_swing(swing: Swing, start_ns: int, step_height_m: float, samples: int = 21,
                     max_spacing_s: float = MAX_WAYPOINT_SPACING_S
                     ) -> tuple[SwingTrajectory, np.ndarray]:
    """The sixth-order swing of a planned swing, sampled at evenly spaced waypoints.

    Args:
        swing: Planned swing (lift-off and landing places, yaws and times).
        start_ns: Lift-off time [ns].
        step_height_m: Via height above the higher foothold [m] (none for a foot put down
            from the air: see the module docstring).
        samples: Fewest waypoints (>= 3); more when the swing is longer than
            ``(samples - 1) * max_spacing_s``.
        max_spacing_s: Largest time between waypoints [s], > 0.

    Returns:
        ``(trajectory, coefficients)``: the waypoints and the (7, 4) coefficients of
        (x, y, z, yaw) in time from lift-off.
    """
    if samples < 3:
        raise SwingPolicyError(f'a polynomial swing needs >= 3 samples, got {samples}')
    if not max_spacing_s > 0:
        raise SwingPolicyError(f'max_spacing_s must be > 0 s, got {max_spacing_s}')
    start = np.array([*swing.start_in_world, swing.start_yaw_rad], dtype=float)
    turn = math.remainder(swing.end_yaw_rad - swing.start_yaw_rad, 2 * math.pi)
    end = np.array([*swing.end_in_world, swing.start_yaw_rad + turn], dtype=float)
    via = 0.5 * (start + end)
    if not is_landing(swing):
        via[2] = max(start[2], end[2]) + step_height_m
    duration = swing.duration_s
    coefficients = sixth_order_coefficients(start, end, via, duration, 0.5 * duration)
    samples = max(samples, math.ceil(duration / max_spacing_s - 1e-9) + 1)
    times = np.linspace(0.0, duration, samples)
    values = evaluate(coefficients, times)
    values[0], values[-1] = start, end
    yaws = np.angle(np.exp(1j * values[:, 3]))
    return SwingTrajectory(swing.foot, int(start_ns), times, values[:, :3], yaws), coefficients


def is_landing(swing: Swing) -> bool:
    """Whether ``swing`` puts a foot down from the air: straight down, no horizontal travel."""
    travel = np.asarray(swing.end_in_world[:2], dtype=float) - swing.start_in_world[:2]
    return bool(swing.end_in_world[2] < swing.start_in_world[2]
                and np.hypot(*travel) <= LANDING_TRAVEL_M)
