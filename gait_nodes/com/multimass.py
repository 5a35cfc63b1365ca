"""Multi-mass correction of the body trajectory (Kurazume eqs. 26-35; thesis III.B, nine-link).

A COM planned on the cart-table model does not give the planned ZMP on the real robot: legs and
arms have mass, and the body point that the whole-body IK moves is not the COM. Kurazume's
convergent calculation corrects the body trajectory ``X`` with the cart-table relation between
errors (eq. 31, ``e_zmp = e_g - A e_g_dd``), discretized (eq. 32) with a smoothness term of
weight ``k`` (eq. 34), and repeats until the multi-body ZMP (eqs. 26-27) matches the reference::

    e_zmp = X_zmp_ref - multibody_zmp(X)
    e_g   = argmin |D e_g - e_zmp|^2 / (1 + 2 a)^2 + k |L e_g|^2,   a = A / dt^2     (eq. 34)
    X    <- X + e_g                                                                  (eq. 35)

with ``D = tridiag(-a, 1 + 2 a, -a)`` (eq. 32) and ``L = tridiag(-1/2, 1, -1/2)`` (the distance to
the neighbours' mean), the trajectories held constant beyond both ends (at rest before and after
the plan). With ``k = 0`` this is eq. 33 solved exactly.

The multi-body model is a callable, so that the robot model (Pinocchio, with the IK of the plan)
or a synthetic one plugs in::

    multibody_zmp(body_in_world: (N, 2) array) -> (N, 2) array

It receives the horizontal body (base) trajectory sampled every ``dt_s`` (everything else, feet,
swing legs, body height and yaw, is fixed inside the callable) and returns the ZMP of the full
model at the same samples, in odom [m].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from gait_nodes.com.trajectory import GRAVITY_M_S2, check_positive
from gait_nodes.errors import ComPlanningError

MultibodyZmp = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class MultiMassResult:
    """Outcome of :func:`correct_body_trajectory`.

    Attributes:
        body_in_world: (N, 2) corrected body trajectory [m].
        zmp_in_world: (N, 2) multi-body ZMP of the corrected trajectory [m].
        residual_before_m: Max |reference - multi-body ZMP| of the initial trajectory [m].
        residual_after_m: The same after the correction [m].
        rms_before_m: RMS of that error before [m].
        rms_after_m: RMS after [m].
        iterations: Corrections applied.
        history_m: Max residual after each iteration, the initial one first [m].
    """

    body_in_world: np.ndarray
    zmp_in_world: np.ndarray
    residual_before_m: float
    residual_after_m: float
    rms_before_m: float
    rms_after_m: float
    iterations: int
    history_m: tuple[float, ...]


def _tridiagonal(count: int, diagonal: float, off: float) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric tridiagonal with rows summing to ``diagonal + 2 off`` at the ends too.

    The trajectory is held beyond both ends (at rest before and after the plan), so the end
    rows fold the missing neighbour onto the diagonal.
    """
    diagonals = np.full(count, diagonal)
    diagonals[[0, -1]] += off
    if count == 1:
        diagonals[0] = diagonal + 2 * off
    return diagonals, np.full(max(count - 1, 0), off)


def _gram_banded(diagonals: np.ndarray, offs: np.ndarray) -> np.ndarray:
    """Upper banded form (3, N) of T'T = T^2 for a symmetric tridiagonal T."""
    count = len(diagonals)
    bands = np.zeros((3, count))
    left = np.concatenate([[0.0], offs])
    right = np.concatenate([offs, [0.0]])
    bands[2] = diagonals ** 2 + left ** 2 + right ** 2
    bands[1, 1:] = offs * (diagonals[:-1] + diagonals[1:])
    bands[0, 2:] = offs[:-1] * offs[1:]
    return bands


def zmp_correction(zmp_error: np.ndarray, com_height_m: float, dt_s: float,
                   smoothness_k: float = 0.0, gravity_m_s2: float = GRAVITY_M_S2) -> np.ndarray:
    """COM correction ``e_g`` (N, 2) for a ZMP error (N, 2) (Kurazume eqs. 32-34).

    Both are held constant beyond the ends (the robot rests before and after the plan).
    """
    error = np.asarray(zmp_error, dtype=float)
    a = check_positive('com_height_m', com_height_m) / gravity_m_s2 / \
        check_positive('dt_s', dt_s) ** 2
    if smoothness_k < 0 or not np.isfinite(smoothness_k):
        raise ComPlanningError(f'smoothness_k must be >= 0, got {smoothness_k}')
    count = len(error)
    scale = 1.0 / (1.0 + 2.0 * a) ** 2
    D = _tridiagonal(count, 1.0 + 2.0 * a, -a)                      # eq. 32
    normal = scale * _gram_banded(*D) + smoothness_k * _gram_banded(*_tridiagonal(count, 1.0,
                                                                                 -0.5))
    padded = np.pad(error, ((1, 1), (0, 0)), mode='edge')
    rhs = scale * ((1.0 + 2.0 * a) * error - a * (padded[:-2] + padded[2:]))  # D' e_zmp
    return scipy.linalg.solveh_banded(normal, rhs)


def correct_body_trajectory(body_in_world: np.ndarray, zmp_reference: np.ndarray,
                            multibody_zmp: MultibodyZmp, com_height_m: float, dt_s: float,
                            smoothness_k: float = 0.0, max_iterations: int = 20,
                            tolerance_m: float = 1e-4,
                            gravity_m_s2: float = GRAVITY_M_S2) -> MultiMassResult:
    """Iterate the body trajectory until the multi-body ZMP matches the reference (eq. 35).

    Args:
        body_in_world: (N, 2) initial body trajectory, e.g. the preview controller's COM [m].
        zmp_reference: (N, 2) planned ZMP at the same samples [m].
        multibody_zmp: ``f(body (N, 2)) -> zmp (N, 2)``, the full model's ZMP (module doc).
        com_height_m: Cart-table height ``z_g`` used for the correction [m].
        dt_s: Sample period [s].
        smoothness_k: Weight ``k`` of the smoothness term (eq. 34), >= 0.
        max_iterations: Most corrections applied.
        tolerance_m: Stop when the largest ZMP error is below this [m].
        gravity_m_s2: Gravity [m/s^2].

    Returns:
        The corrected trajectory and the residuals before and after.
    """
    body = np.array(body_in_world, dtype=float)
    reference = np.asarray(zmp_reference, dtype=float)
    if body.ndim != 2 or body.shape[1] != 2 or reference.shape != body.shape:
        raise ComPlanningError(f'body and ZMP reference must both be (N, 2), got {body.shape} '
                               f'and {reference.shape}')

    def evaluate(trajectory):
        zmp = np.asarray(multibody_zmp(trajectory), dtype=float)
        if zmp.shape != trajectory.shape or not np.all(np.isfinite(zmp)):
            raise ComPlanningError(f'multibody_zmp returned {zmp.shape} (finite: '
                                   f'{np.all(np.isfinite(zmp))}) for a {trajectory.shape} body')
        return zmp

    zmp = evaluate(body)
    error = reference - zmp
    before = float(np.max(np.abs(error)))
    rms_before = float(np.sqrt(np.mean(error ** 2)))
    history = [before]
    iterations = 0
    while history[-1] > tolerance_m and iterations < max_iterations:
        body = body + zmp_correction(error, com_height_m, dt_s, smoothness_k, gravity_m_s2)
        zmp = evaluate(body)
        error = reference - zmp
        history.append(float(np.max(np.abs(error))))
        iterations += 1
    body.setflags(write=False)
    zmp.setflags(write=False)
    return MultiMassResult(body, zmp, before, history[-1], rms_before,
                           float(np.sqrt(np.mean(error ** 2))), iterations, tuple(history))
