"""The full robot model as the multi-body ZMP of the multi-mass correction (thesis nine-link idea).

:func:`robot_multibody_zmp` turns a footstep plan and a robot model into the callable that
:func:`gait_nodes.com.multimass.correct_body_trajectory` iterates on: for a horizontal body
(base) trajectory it places the base there (height and yaw from the plan), puts the stance feet
where the plan has them and the swing feet on their swing (the whole-body IK's fallback swing,
the same the IK node uses without a swing-leg policy), solves the limb IK at every sample, and
returns the ZMP of the whole model from its momentum rate (:mod:`gait_nodes.robot.dynamics`).

:func:`correct_plan` runs the whole chain for a plan: ZMP reference -> preview-control COM ->
multi-mass correction, and reports the residual before and after.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gait_nodes.com.multimass import MultibodyZmp, MultiMassResult, correct_body_trajectory
from gait_nodes.com.preview import PreviewSettings, preview_batch
from gait_nodes.contract import FootstepPlan
from gait_nodes.robot.dynamics import multibody_zmp_trajectory
from gait_nodes.robot.model import RobotModel
from gait_nodes.robot.whole_body_ik import (
    IkSettings,
    IkTargets,
    WholeBodyIkSolver,
    current_swing,
    fallback_swing_pose,
    seed_configuration,
    walking_vertical,
)

#: Most IK solves spent on the first sample of a trajectory.
FIRST_SAMPLE_SOLVES = 20


def planned_feet(robot: RobotModel, plan: FootstepPlan, times_s: np.ndarray,
                 step_height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(N, F, 3) foot targets and (N, F) yaws at ``times_s`` from the plan start."""
    order = [plan.foot_names.index(name) for name in robot.foot_names]
    feet = np.zeros((len(times_s), len(order), 3))
    yaws = np.zeros((len(times_s), len(order)))
    for k, t_s in enumerate(times_s):
        index = plan.index_at(t_s)
        feet[k] = plan.positions_in_world[index][order]
        yaws[k] = plan.yaws_rad[index][order]
        for f, name in enumerate(robot.foot_names):
            swing = current_swing(plan, name, t_s)
            if swing is not None:
                feet[k, f], yaws[k, f] = fallback_swing_pose(swing, t_s, step_height_m)
    return feet, yaws


def robot_multibody_zmp(robot: RobotModel, plan: FootstepPlan, times_s: np.ndarray,
                        dt_s: float, body_height_m: float, body_yaws_rad: np.ndarray,
                        step_height_m: float) -> MultibodyZmp:
    """The callable ``body (N, 2) -> multi-body ZMP (N, 2)`` for a plan sampled at ``times_s``.

    Args:
        robot: The robot model.
        plan: The footstep plan (feet and swings).
        times_s: (N,) sample times from the plan start, every ``dt_s`` [s].
        dt_s: Sample period [s].
        body_height_m: Base height above the ground [m].
        body_yaws_rad: (N,) base yaw at each sample [rad].
        step_height_m: Swing apex height of the fallback swing [m].
    """
    feet, foot_yaws = planned_feet(robot, plan, times_s, step_height_m)
    solver = WholeBodyIkSolver(robot, IkSettings(vertical=walking_vertical(robot)))

    def multibody_zmp(body_in_world: np.ndarray) -> np.ndarray:
        configurations = np.zeros((len(times_s), robot.model.nq))
        q = None
        for k, (x, y) in enumerate(np.asarray(body_in_world, dtype=float)):
            targets = IkTargets(feet[k], foot_yaws[k], float(body_yaws_rad[k]),
                                base_position_in_world=np.array([x, y, body_height_m]))
            if q is None:
                # Converge the first sample fully: a start still converging over the next
                # samples would read as a violent motion to the finite differences. Seeded by
                # the closed-form limb IK where the robot has one (its default family).
                q = seed_configuration(robot, targets)
                for _ in range(FIRST_SAMPLE_SOLVES):
                    result = solver.solve(targets, q)
                    q = result.q
                    if result.converged:
                        break
            q = solver.solve(targets, q).q
            configurations[k] = q
        zmp, _ = multibody_zmp_trajectory(robot, configurations, dt_s)
        return zmp

    return multibody_zmp


@dataclass(frozen=True)
class PlanCorrection:
    """Preview-control COM and its multi-mass correction for one plan.

    Attributes:
        times_s: (N,) sample times from the plan start [s].
        zmp_reference: (N, 2) ZMP reference [m].
        preview_com: (N, 2) COM of the cart-table preview control [m].
        result: The multi-mass correction, started from ``preview_com``.
    """

    times_s: np.ndarray
    zmp_reference: np.ndarray
    preview_com: np.ndarray
    result: MultiMassResult


def correct_plan(robot: RobotModel, plan: FootstepPlan, zmp_reference: np.ndarray,
                 dt_s: float, body_height_m: float, step_height_m: float,
                 settings: PreviewSettings | None = None, smoothness_k: float = 0.0,
                 max_iterations: int = 10, tolerance_m: float = 1e-3) -> PlanCorrection:
    """Preview control on the cart table, then the multi-mass correction on the full model.

    Args:
        robot: The robot model.
        plan: The footstep plan the reference was made for.
        zmp_reference: (N, 2) reference, sample ``k`` at ``k * dt_s`` from the plan start [m].
        dt_s: Sample period [s].
        body_height_m: Base height [m].
        step_height_m: Swing apex height [m].
        settings: Preview settings (default: the robot's COM height, ``dt_s``, 1.6 s preview).
        smoothness_k: Kurazume's smoothness weight ``k`` (eq. 34).
        max_iterations: Largest number of corrections.
        tolerance_m: Stop when the largest ZMP residual is below this [m].
    """
    com_height_m = robot.description.com_height_m
    settings = settings or PreviewSettings(com_height_m=com_height_m, dt_s=dt_s)
    reference = np.asarray(zmp_reference, dtype=float)
    times_s = np.arange(len(reference)) * dt_s
    preview_com = preview_batch(reference, settings).positions_in_world
    yaws = np.array([float(np.mean(plan.yaws_rad[plan.index_at(t)])) for t in times_s])
    model_zmp = robot_multibody_zmp(robot, plan, times_s, dt_s, body_height_m, yaws,
                                    step_height_m)
    result = correct_body_trajectory(preview_com, reference, model_zmp, com_height_m, dt_s,
                                     smoothness_k=smoothness_k, max_iterations=max_iterations,
                                     tolerance_m=tolerance_m)
    return PlanCorrection(times_s, reference, preview_com, result)
