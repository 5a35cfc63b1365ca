"""Shared helpers of the swing tests: a tiny value table, built once per process."""

import functools

import numpy as np

from gait_nodes.robot.model import load_robot_model
from gait_nodes.swing.grid import SwingActions
from gait_nodes.swing.value_iteration import GridSpec, build_table

#: A grid of 216 states around the default goal (0.65, -0.525, swing plane, yaw 0).
TINY_GRID = GridSpec(x_range_m=(0.35, 0.75, 9), y_range_m=(-0.6, -0.45, 4), z_levels=2,
                     z_spacing_m=0.05, yaw_range_rad=(-0.15, 0.15, 3))
TINY_ACTIONS = SwingActions(radii_m=(0.05, 0.1), azimuth_count=8, elevations_rad=(-0.6, 0.0, 0.6),
                            yaw_steps_rad=(-0.15, 0.0, 0.15))
STEP_HEIGHT_M = 0.1
FAMILY = 2


def robot():
    """The shipped RoboSimian model."""
    return load_robot_model('robosimian')


@functools.lru_cache(maxsize=4)
def tiny_table(limit_rad_s: float = 1.0):
    """(table, report) of the tiny grid at a joint velocity limit."""
    return build_table(robot(), FAMILY, STEP_HEIGHT_M, limit_rad_s, TINY_GRID, TINY_ACTIONS)


def fine_time(timing, states, samples_per_segment: int = 40) -> float:
    """Time [s] to follow straight segments between states, sampled finely, at the limit."""
    points = []
    for a, b in zip(states[:-1], states[1:], strict=True):
        s = np.linspace(0.0, 1.0, samples_per_segment, endpoint=False)[:, None]
        points.append(a + s * (b - a))
    points.append(states[-1:])
    times, feasible = timing.path_times(np.vstack(points))
    assert feasible
    return float(times.sum())
