"""The fastest time law along a swing's path within its joints' velocity and acceleration limits.

A value-table swing's path is a polyline timed with its fastest joint at the velocity limit on
every segment (thesis 000, Appendix A), smoothed into a path the foot can follow
(:func:`gait_nodes.swing.timing.smooth_trajectory`). Stretching that timing uniformly until no
joint exceeds a limit anywhere leaves most of the path below the limits: the corners the
smoothing rounds hold the whole swing to the speed one corner allows. The time-optimal path
parameterization instead moves along the same path as fast as the limits allow at each point
(Bobrow, Dubowsky and Gibson 1985): with ``s`` the path parameter and ``q(s)`` the joints,

    |q'_j(s) s_dot|                     <= W_j     (velocity)
    |q'_j(s) s_ddot + q''_j(s) s_dot^2|  <= A_j     (acceleration)

at rest at both ends. :func:`fastest_times` solves it with TOPP-RA (Pham and Pham 2018, the
``toppra`` library): reachability analysis on a grid of the path, a sequence of small linear
programs in ``(s_dot^2, s_ddot)``. On RoboSimian's static crawl at 1 rad/s a 0.22 m value-table
swing takes 1.17-1.22 s this way, against 1.34-1.49 s stretched uniformly.
"""

from __future__ import annotations

import logging

import numpy as np
import toppra
import toppra.algorithm
import toppra.constraint

from gait_nodes.errors import SwingPolicyError

# Imported with the module, not at the first swing: toppra imports matplotlib's pyplot, about a
# second, which a node must not spend in the callback of its first swing.
logging.getLogger('toppra').setLevel(logging.WARNING)  # it logs every solve at INFO

#: Grid points of the parameterization along the path (8 ms apart on a 1.2 s swing): the
#: limits hold at them, and between them to about 1 % (velocity) and 5 % (acceleration); the
#: callers keep a share of the acceleration limit for that.
GRID_POINTS = 150


def fastest_times(u: np.ndarray, joints: np.ndarray, velocity_limits: np.ndarray,
                  acceleration_limits: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """Times [s] of the fastest rest-to-rest motion along ``joints`` (N, J) at ``u`` (N,).

    ``u`` is any increasing parameter of the path (the samples' times in another time law);
    the joints between the samples follow a cubic spline through them. The limits are (J,)
    (or scalars), positive. Returns the times at ``u``, or at the parameters ``at`` (within
    ``u``'s range) if given.

    Raises:
        SwingPolicyError: The path has fewer than two distinct samples, or the limits admit no
            motion along it.
    """
    u = np.asarray(u, dtype=float)
    joints = np.asarray(joints, dtype=float)
    if len(u) < 2 or not np.all(np.diff(u) > 0):
        raise SwingPolicyError(f'a time law needs an increasing path parameter with at least 2 '
                               f'samples, got {len(u)}')
    count = joints.shape[1]
    velocity = np.broadcast_to(np.asarray(velocity_limits, dtype=float), (count,))
    acceleration = np.broadcast_to(np.asarray(acceleration_limits, dtype=float), (count,))
    path = toppra.SplineInterpolator(u, joints)
    grid = np.linspace(u[0], u[-1], GRID_POINTS)
    solver = toppra.algorithm.TOPPRA(
        [toppra.constraint.JointVelocityConstraint(np.column_stack([-velocity, velocity])),
         toppra.constraint.JointAccelerationConstraint(
             np.column_stack([-acceleration, acceleration]))],
        path, gridpoints=grid)
    _, speed, _ = solver.compute_parameterization(0.0, 0.0)
    if speed is None:
        raise SwingPolicyError('no time law along this path keeps its joints within their '
                               'velocity and acceleration limits')
    # The path's acceleration is constant between grid points (s_dot^2 linear in s): a step
    # from s_i to s takes 2 (s - s_i) / (s_dot_i + s_dot(s)), at the grid points and between.
    squared = np.asarray(speed, dtype=float) ** 2
    grid_times = np.concatenate([[0.0], np.cumsum(2.0 * np.diff(grid)
                                                  / (np.sqrt(squared[:-1])
                                                     + np.sqrt(squared[1:])))])
    at = u if at is None else np.clip(np.asarray(at, dtype=float), u[0], u[-1])
    index = np.clip(np.searchsorted(grid, at, side='right') - 1, 0, len(grid) - 2)
    along = at - grid[index]
    speed_at = np.sqrt(np.maximum(np.interp(at, grid, squared), 0.0))
    with np.errstate(invalid='ignore', divide='ignore'):
        within = np.where(along > 0.0, 2.0 * along / (np.sqrt(squared[index]) + speed_at), 0.0)
    return grid_times[index] + within
