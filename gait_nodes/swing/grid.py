"""The swing-leg state grid (x, y, z, yaw of the foot in the base frame) and the action set.

Thesis 000, section III.C.1: the states are the sole position and yaw of the swinging foot
relative to the centre of body, on a 4-D mesh; the actions move the foot to points on spheres of
several radii around the state (distance x azimuth x elevation) with a yaw change. A state plus
an action that leaves the mesh is brought back to its edge ("looped back to be at the edge of
the grid"), and values between nodes are interpolated (multilinear).

Everything is in the front-right limb's frame; the other limbs use mirrored coordinates
(thesis III.A, :mod:`gait_nodes.robot.limb_ik`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import SwingTableError

AXIS_NAMES = ('x_m', 'y_m', 'z_m', 'yaw_rad')


def _axis(values, name: str) -> np.ndarray:
    axis = np.array(values, dtype=float).reshape(-1)
    if len(axis) < 1 or not np.all(np.isfinite(axis)):
        raise SwingTableError(f'grid axis {name} must hold at least one finite value, got '
                              f'{axis.tolist()}')
    if np.any(np.diff(axis) <= 0):
        raise SwingTableError(f'grid axis {name} must be strictly increasing, got '
                              f'{axis.tolist()}')
    axis.setflags(write=False)
    return axis


def axis_weights(axis: np.ndarray, coordinates: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lower node, upper node and upper weight of each coordinate, clamped to the axis.

    Args:
        axis: (n,) strictly increasing node coordinates.
        coordinates: (...) coordinates to interpolate at.

    Returns:
        ``(lo, hi, f)``: node indices and the weight of ``hi`` (``1 - f`` goes to ``lo``).
    """
    t = np.clip(coordinates, axis[0], axis[-1])
    if len(axis) == 1:
        zero = np.zeros(np.shape(t), dtype=np.intp)
        return zero, zero, np.zeros(np.shape(t))
    lo = np.clip(np.searchsorted(axis, t, side='right') - 1, 0, len(axis) - 2)
    f = (t - axis[lo]) / (axis[lo + 1] - axis[lo])
    return lo, lo + 1, f


@dataclass(frozen=True)
class SwingGrid:
    """The 4-D state mesh.

    Attributes:
        x_m: (nx,) forward sole positions in the base frame [m].
        y_m: (ny,) lateral sole positions (front-right limb: negative) [m].
        z_m: (nz,) sole heights in the base frame [m] (the ground is at ``-body_height_m``).
        yaw_rad: (nyaw,) sole yaws relative to the base [rad].
    """

    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    yaw_rad: np.ndarray

    def __post_init__(self):
        for name in AXIS_NAMES:
            object.__setattr__(self, name, _axis(getattr(self, name), name))
        shape = tuple(len(getattr(self, name)) for name in AXIS_NAMES)
        strides = [math.prod(shape[d + 1:]) for d in range(4)]
        # Per axis, for interpolation: nodes, 1 / spacing and the flat-index stride.
        lookup = tuple((getattr(self, name), 1.0 / np.diff(getattr(self, name)), stride)
                       for name, stride in zip(AXIS_NAMES, strides, strict=True))
        object.__setattr__(self, '_lookup', lookup)
        object.__setattr__(self, '_box', (np.array([a[0] for a, _, _ in lookup]),
                                          np.array([a[-1] for a, _, _ in lookup])))

    @property
    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The four axes, in state order."""
        return self.x_m, self.y_m, self.z_m, self.yaw_rad

    @property
    def shape(self) -> tuple[int, int, int, int]:
        """Nodes per axis."""
        return tuple(len(a) for a in self.axes)

    @property
    def size(self) -> int:
        """Number of states."""
        return math.prod(self.shape)

    @property
    def lower(self) -> np.ndarray:
        """(4,) first node of each axis."""
        return np.array([a[0] for a in self.axes])

    @property
    def upper(self) -> np.ndarray:
        """(4,) last node of each axis."""
        return np.array([a[-1] for a in self.axes])

    def points(self) -> np.ndarray:
        """(S, 4) every node, C order over (x, y, z, yaw)."""
        mesh = np.meshgrid(*self.axes, indexing='ij')
        return np.stack([m.reshape(-1) for m in mesh], axis=1)

    def clamp(self, states: np.ndarray) -> np.ndarray:
        """States brought back onto the mesh's box (thesis III.C.1)."""
        return np.clip(states, self.lower, self.upper)

    def contains(self, state: np.ndarray, tolerance: float = 1e-9) -> bool:
        """The state lies within the mesh's box."""
        state = np.asarray(state, dtype=float)
        return bool(np.all(state >= self.lower - tolerance)
                    and np.all(state <= self.upper + tolerance))

    def nearest_node(self, state: np.ndarray) -> tuple[int, int, int, int]:
        """Index of the node nearest to ``state`` along each axis."""
        return tuple(int(np.argmin(np.abs(a - v))) for a, v in zip(self.axes, state,
                                                                     strict=True))

    def interpolate(self, values: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Multilinear interpolation of node ``values`` at ``states`` (clamped to the mesh).

        Args:
            values: (nx, ny, nz, nyaw, ...) values at the nodes (trailing axes interpolated
                alike).
            states: (N, 4) states.

        Returns:
            (N, ...) interpolated values.
        """
        states = np.atleast_2d(np.asarray(states, dtype=float))
        count = len(states)
        lower, upper = self._box
        clamped = np.minimum(np.maximum(states, lower), upper)
        base = np.zeros(count, dtype=np.intp)
        offsets = np.zeros((count, 1), dtype=np.intp)
        weights = np.ones((count, 1))
        for d, (axis, inverse_spacing, stride) in enumerate(self._lookup):
            if len(axis) == 1:
                continue
            t = clamped[:, d]
            lo = np.minimum(np.searchsorted(axis, t, side='right') - 1, len(axis) - 2)
            f = (t - axis[lo]) * inverse_spacing[lo]
            base += lo * stride
            offsets = np.concatenate([offsets, offsets + stride], axis=1)
            weights = np.concatenate([weights * (1.0 - f)[:, None], weights * f[:, None]],
                                     axis=1)
        values = np.asarray(values)
        flat = values.reshape(self.size, -1)
        result = np.einsum('nck,nc->nk', flat[base[:, None] + offsets], weights)
        return result.reshape(count, *values.shape[4:])


def make_grid(x_range_m, y_range_m, z_levels: int, z_spacing_m: float, yaw_range_rad,
              swing_height_z_m: float, goal: np.ndarray | None = None,
              z_planes_m=None) -> SwingGrid:
    """A mesh from ranges, with the swing plane as its lowest z level.

    Args:
        x_range_m: ``(min, max, count)`` of the x axis [m].
        y_range_m: ``(min, max, count)`` of the y axis [m].
        z_levels: Number of z levels from the swing plane up.
        z_spacing_m: Spacing of the z levels [m].
        yaw_range_rad: ``(min, max, count)`` of the yaw axis [rad].
        swing_height_z_m: Height of the swing plane in the base frame [m] (ground + step height).
        goal: Optional (4,) state; the node nearest to it on each axis is moved onto it so that
            the goal is a node (the value iteration holds its value at zero).
        z_planes_m: Explicit z levels in the base frame [m] (strictly increasing), instead of
            ``z_levels`` from the swing plane up (the thesis' planes 0.7 and 0.6 m below the
            centre of body); None: ``z_levels`` and ``z_spacing_m``.

    Raises:
        SwingTableError: A range is empty or reversed, a count below 1, or the goal outside.
    """
    axes = []
    for name, spec in (('x', x_range_m), ('y', y_range_m), ('yaw', yaw_range_rad)):
        low, high, count = spec
        if int(count) != count or count < 1 or (count > 1 and not high > low):
            raise SwingTableError(f'{name} range must be (min < max, count >= 1), got '
                                  f'{tuple(spec)}')
        axes.append(np.linspace(low, high, int(count)) if count > 1 else np.array([low]))
    if int(z_levels) != z_levels or z_levels < 1 or not z_spacing_m > 0:
        raise SwingTableError(f'z levels must be >= 1 with a spacing > 0 m, got {z_levels} '
                              f'levels at {z_spacing_m} m')
    if z_planes_m is None:
        z = swing_height_z_m + z_spacing_m * np.arange(int(z_levels))
    else:
        z = np.array(_axis(z_planes_m, 'z_m'))
    x, y, yaw = axes
    if goal is not None:
        goal = np.asarray(goal, dtype=float)
        fixed = []
        for name, axis, value in zip(AXIS_NAMES, (x, y, z, yaw), goal, strict=True):
            if not axis[0] - 1e-9 <= value <= axis[-1] + 1e-9:
                raise SwingTableError(f'goal {name} = {value:.4f} is outside the grid '
                                      f'[{axis[0]:.4f}, {axis[-1]:.4f}]')
            axis = axis.copy()
            axis[int(np.argmin(np.abs(axis - value)))] = value
            fixed.append(axis)
        x, y, z, yaw = fixed
    return SwingGrid(x, y, z, yaw)


@dataclass(frozen=True)
class SwingActions:
    """Moves to points on spheres of several radii with a yaw change (thesis III.C.1).

    Attributes:
        radii_m: Sphere radii [m] (several, so that small moves near the goal exist: thesis
            IV.B.2, Fig. 13).
        azimuth_count: Azimuths per sphere, evenly spaced over a full turn.
        elevations_rad: Elevations above the horizontal [rad].
        yaw_steps_rad: Yaw changes [rad].
    """

    radii_m: tuple[float, ...] = (0.03, 0.06, 0.12)
    azimuth_count: int = 8
    elevations_rad: tuple[float, ...] = (-0.5, 0.0, 0.5)
    yaw_steps_rad: tuple[float, ...] = (-0.15, 0.0, 0.15)

    def __post_init__(self):
        for name in ('radii_m', 'elevations_rad', 'yaw_steps_rad'):
            values = tuple(float(v) for v in getattr(self, name))
            if not values or not all(math.isfinite(v) for v in values):
                raise SwingTableError(f'actions: {name} must hold finite values, got {values}')
            object.__setattr__(self, name, values)
        if any(r <= 0 for r in self.radii_m):
            raise SwingTableError(f'actions: radii must be > 0 m, got {self.radii_m}')
        if any(abs(e) > math.pi / 2 for e in self.elevations_rad):
            raise SwingTableError(f'actions: elevations must be in [-pi/2, pi/2], got '
                                  f'{self.elevations_rad}')
        if int(self.azimuth_count) != self.azimuth_count or self.azimuth_count < 1:
            raise SwingTableError(f'actions: azimuth_count must be an integer >= 1, got '
                                  f'{self.azimuth_count}')
        object.__setattr__(self, 'azimuth_count', int(self.azimuth_count))

    def displacements(self) -> np.ndarray:
        """(A, 4) state changes (dx, dy, dz, dyaw), duplicates removed, no null action."""
        azimuths = 2 * math.pi * np.arange(self.azimuth_count) / self.azimuth_count
        moves = [np.zeros(3)]
        for radius in self.radii_m:
            for elevation in self.elevations_rad:
                for azimuth in azimuths:
                    moves.append(radius * np.array([math.cos(elevation) * math.cos(azimuth),
                                                    math.cos(elevation) * math.sin(azimuth),
                                                    math.sin(elevation)]))
        result = np.array([[*move, dyaw] for move in moves for dyaw in self.yaw_steps_rad])
        result = np.unique(np.round(result, 12), axis=0)
        return result[np.any(result != 0.0, axis=1)]

    @property
    def max_radius_m(self) -> float:
        """Largest sphere radius [m]."""
        return max(self.radii_m)

    @property
    def max_yaw_step_rad(self) -> float:
        """Largest yaw change [rad]."""
        return max(abs(v) for v in self.yaw_steps_rad)
