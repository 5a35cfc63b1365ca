"""Multi-body ZMP of the full robot model from the rate of change of its momentum (Pinocchio).

With the centroidal momentum ``h = (m c_dot, L_c)`` and its rate ``h_dot`` (Pinocchio's
``computeCentroidalMomentumTimeVariation``), the contact wrench that the ground must supply is,
about the world origin O::

    f     = m c_ddot - m g                    (g = (0, 0, -9.81) m/s^2)
    tau_O = L_c_dot + c x f

and the ZMP on the ground plane z = 0 is the point about which the horizontal moment vanishes::

    p_x = -tau_O_y / f_z,    p_y = tau_O_x / f_z

This is Kurazume's eqs. (26)-(27) (the sum over links of m_i (z_i_dd + g) x_i - m_i x_i_dd z_i
minus the rotational terms), written with the whole model's momentum instead of a link sum.
A static robot gives ``p = (c_x, c_y)``; a point mass gives the cart-table formula
``p = c - z_c / (z_c_dd + g) c_dd``.
"""

from __future__ import annotations

import numpy as np

from gait_nodes.robot.model import RobotModel
from gait_nodes.sim.zmp_monitor import ZmpMonitor, central_differences


def zmp_from_momentum(robot: RobotModel, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                      monitor: ZmpMonitor | None = None) -> tuple[np.ndarray, np.ndarray]:
    """ZMP on z = 0 and COM of the full model at one instant (the ZMP monitor's computation).

    Args:
        robot: The robot model.
        q: Configuration (Pinocchio's, free-flyer base).
        v: Velocity [m/s, rad/s] (Pinocchio's, base twist in the base frame).
        a: Acceleration, same convention [m/s^2, rad/s^2].
        monitor: A monitor of ``robot`` to reuse (a new one when None).

    Returns:
        ``(zmp_in_world (2,), com_in_world (3,))`` [m]; the ZMP is NaN when the motion would
        need the ground to pull.
    """
    monitor = monitor or ZmpMonitor(robot.model, robot.description.foot_radius_m)
    com, zmp, _ = monitor.com_and_zmp(q, v, a)
    return zmp[:2], com


def finite_difference_motion(robot: RobotModel, configurations: np.ndarray, dt_s: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations of a sampled configuration trajectory.

    Central differences on the configuration manifold (the monitor's
    :func:`~gait_nodes.sim.zmp_monitor.central_differences`); the trajectory is taken at rest
    before and after it.

    Args:
        robot: The robot model.
        configurations: (N, nq) configurations every ``dt_s``.
        dt_s: Sample period [s].

    Returns:
        ``(v (N, nv), a (N, nv))``.
    """
    count = len(configurations)
    velocities = np.zeros((count, robot.model.nv))
    accelerations = np.zeros((count, robot.model.nv))
    for k in range(count):
        before = configurations[max(k - 1, 0)]
        after = configurations[min(k + 1, count - 1)]
        velocities[k], accelerations[k] = central_differences(
            robot.model, before, configurations[k], after, dt_s)
    return velocities, accelerations


def multibody_zmp_trajectory(robot: RobotModel, configurations: np.ndarray, dt_s: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) ZMP and (N, 3) COM of a sampled configuration trajectory [m]."""
    velocities, accelerations = finite_difference_motion(robot, configurations, dt_s)
    monitor = ZmpMonitor(robot.model, robot.description.foot_radius_m)
    zmp = np.zeros((len(configurations), 2))
    com = np.zeros((len(configurations), 3))
    for k, q in enumerate(configurations):
        zmp[k], com[k] = zmp_from_momentum(robot, q, velocities[k], accelerations[k], monitor)
    return zmp, com
