"""Sampled COM trajectories and the cart-table ZMP, shared by every COM generator.

The cart-table model (Kajita et al. 2003, eq. (1); thesis II.A) puts the whole mass at a constant
height ``zc`` above flat ground; its ZMP is ``p = c - zc / g * c_dd`` in each horizontal axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import ComPlanningError

#: Standard gravity [m/s^2].
GRAVITY_M_S2 = 9.81


def cart_table_zmp(positions: np.ndarray, accelerations: np.ndarray, com_height_m: float,
                   gravity_m_s2: float = GRAVITY_M_S2) -> np.ndarray:
    """ZMP of the cart-table model, ``c - zc / g * c_dd`` (Kajita 2003, eq. (1)).

    Args:
        positions: (..., 2) horizontal COM positions [m].
        accelerations: (..., 2) horizontal COM accelerations [m/s^2].
        com_height_m: COM height above the ground ``zc`` [m].
        gravity_m_s2: Gravity [m/s^2].

    Returns:
        (..., 2) ZMP [m].
    """
    return np.asarray(positions) - com_height_m / gravity_m_s2 * np.asarray(accelerations)


def check_positive(name: str, value: float, high: float = math.inf) -> float:
    """``value`` as a float when finite and in (0, high]; ComPlanningError naming it otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) \
            or not math.isfinite(value) or not 0.0 < value <= high:
        raise ComPlanningError(f'{name} must be a number in (0, {high}], got {value!r}')
    return float(value)


@dataclass(frozen=True)
class ComTrajectory:
    """Horizontal COM samples on a uniform time grid.

    Attributes:
        dt_s: Sample period [s].
        positions_in_world: (N, 2) COM position [m].
        velocities_in_world: (N, 2) COM velocity [m/s].
        accelerations_in_world: (N, 2) COM acceleration [m/s^2].
        start_s: Time of sample 0 [s].
    """

    dt_s: float
    positions_in_world: np.ndarray
    velocities_in_world: np.ndarray
    accelerations_in_world: np.ndarray
    start_s: float = 0.0

    def __post_init__(self):
        for name in ('positions_in_world', 'velocities_in_world', 'accelerations_in_world'):
            array = np.array(getattr(self, name), dtype=float)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def __len__(self) -> int:
        return len(self.positions_in_world)

    @property
    def times_s(self) -> np.ndarray:
        """(N,) sample times [s]."""
        return self.start_s + self.dt_s * np.arange(len(self))

    def zmp(self, com_height_m: float, gravity_m_s2: float = GRAVITY_M_S2) -> np.ndarray:
        """(N, 2) cart-table ZMP of these samples [m]."""
        return cart_table_zmp(self.positions_in_world, self.accelerations_in_world,
                              com_height_m, gravity_m_s2)
