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
import pinocchio as pin

from gait_nodes.robot.model import RobotModel


def zmp_from_momentum(robot: RobotModel, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                      data: pin.Data | None = None) -> tuple[np.ndarray, np.ndarray]:
    """ZMP on z = 0 and COM of the full model at one instant.

    Args:
        robot: The robot model.
        q: Configuration (Pinocchio's, free-flyer base).
        v: Velocity [m/s, rad/s] (Pinocchio's, base twist in the base frame).
        a: Acceleration, same convention [m/s^2, rad/s^2].
        data: Pinocchio data to reuse (a fresh one when None).

    Returns:
        ``(zmp_in_world (2,), com_in_world (3,))`` [m].
    """
    model = robot.model
    data = data if data is not None else robot.new_data()
    pin.computeCentroidalMomentumTimeVariation(model, data, q, v, a)
    com = np.array(data.com[0])
    rate = data.dhg
    force = np.array(rate.linear) - robot.mass_kg * np.array(model.gravity.linear)
    torque = np.array(rate.angular) + np.cross(com, force)
    return np.array([-torque[1] / force[2], torque[0] / force[2]]), com


def finite_difference_motion(robot: RobotModel, configurations: np.ndarray, dt_s: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations of a sampled configuration trajectory.

    Central differences on the configuration manifold (``pin.difference``), one-sided at the
    ends; the trajectory is taken at rest before and after it.

    Args:
        robot: The robot model.
        configurations: (N, nq) configurations every ``dt_s``.
        dt_s: Sample period [s].

    Returns:
        ``(v (N, nv), a (N, nv))``.
    """
    model = robot.model
    count = len(configurations)
    steps = np.zeros((count + 1, model.nv))  # steps[k] = (q_k - q_{k-1}) / dt, 0 outside
    for k in range(1, count):
        steps[k] = pin.difference(model, configurations[k - 1], configurations[k]) / dt_s
    velocities = 0.5 * (steps[:-1] + steps[1:])
    accelerations = (steps[1:] - steps[:-1]) / dt_s
    return velocities, accelerations


def multibody_zmp_trajectory(robot: RobotModel, configurations: np.ndarray, dt_s: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) ZMP and (N, 3) COM of a sampled configuration trajectory [m]."""
    velocities, accelerations = finite_difference_motion(robot, configurations, dt_s)
    data = robot.new_data()
    zmp = np.zeros((len(configurations), 2))
    com = np.zeros((len(configurations), 3))
    for k, q in enumerate(configurations):
        zmp[k], com[k] = zmp_from_momentum(robot, q, velocities[k], accelerations[k], data)
    return zmp, com
