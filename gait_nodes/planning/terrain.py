"""The ground under the footholds: flat, or a staircase ahead in odom (Lucy's stairway, seed 004).

A :class:`Staircase` has ``count`` stairs of height ``rise_m`` (negative: a staircase down) and
depth ``tread_m``; the first riser is the line ``x = start_x_m`` of odom and every riser is a
line of constant x (the stairs span every y); the last stair's tread, the landing, goes on
forever. ``count = 0`` is flat ground at ``z = 0``, the default. In Lucy's terms a step from one
tread to the next has the step height ``delta = rise_m`` (the vertical distance between the two
ankles, eqs. (1)-(2)); the example walks ``lambda = 0.3 m``, ``delta = 0.1 m``.

Footholds. A foot reaches ``behind`` and ``ahead`` of its foot frame along x (the robot's
:attr:`~gait_nodes.robot.description.RobotDescription.sole_extent_x_m`: a disc of
``foot_radius_m``, or the sole the YAML gives it, facing +x: the staircase is walked straight up
or down), and it must lie on one tread: the planner keeps each foothold's frame at least
:func:`keep_out_m` before every riser (what the foot reaches ahead) and after it (what it
reaches behind), each plus the larger of :data:`EDGE_MARGIN_M` and the swing's *toe distance*
(:func:`toe_distance_m`): how far the polynomial swing (:mod:`gait_nodes.swing.polynomial`,
sixth order, via point ``step_height_m`` above the higher foothold) moves forward before it is
one stair and :data:`STAIR_CLEARANCE_M` high, at the robot's longest stride. So a swing that
starts just before a riser has lifted over it before its toe gets there, and, by the swing's
symmetry in time, one that lands just past a riser going down has cleared it with its heel
(Lucy's intermediate condition, used
"to lift the foot whenever an obstacle has to be cleared"). A target inside a keep-out zone
moves to the zone's nearer end (the step shortened or lengthened, as Lucy's planner adapts the
step length to the stairway), or to the other end when the nearer one is out of reach
(:meth:`Staircase.foothold_candidates`); :func:`swing_clearance_m` measures what a swing
leaves between the foot and the stairs. (The planner's disc alone put the biped's toe 45 mm
into the first stair, whose edge it landed on in physics: docs/physics.md.)

Only the polynomial swing knows about heights: the value-table swing (thesis, flat ground) is
refused on stairs (:func:`check_walkable`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import TerrainError

#: Least horizontal distance [m] between a foot and a riser at a foothold.
EDGE_MARGIN_M = 0.01
#: Height [m] a swing's foot keeps above a stair's edge as it passes it. With none (the foot
#: exactly one stair high as its toe reaches the riser) the biped's toe caught the stair's
#: nosing in physics; with 0.02 m it still scraped two of six at kp 3000 (its position drives
#: held the foot 2.4 cm under its setpoint there; at the YAML's kp 10000 it clears them), and
#: 0.04 m leaves 0.3 m treads footholds it fell from (docs/physics.md).
STAIR_CLEARANCE_M = 0.02
#: Samples of a swing checked against the stairs (:func:`swing_clearance_m`).
CLEARANCE_SAMPLES = 401
#: Footstep planner parameters of the staircase: name -> (lowest, highest, unit), both included.
STAIRS_PARAMETERS: dict[str, tuple[float, float, str]] = {
    'stairs_start_x_m': (-100.0, 100.0, 'm'),
    'stairs_rise_m': (-0.3, 0.3, 'm'),
    'stairs_tread_m': (0.05, 5.0, 'm'),
    'stairs_count': (0, 50, ''),
}
#: Their defaults: flat ground.
STAIRS_DEFAULTS: dict[str, float | int] = {
    'stairs_start_x_m': 0.5, 'stairs_rise_m': 0.1, 'stairs_tread_m': 0.3, 'stairs_count': 0}


@dataclass(frozen=True)
class Staircase:
    """A straight staircase along odom's x axis, validated (see the module docstring).

    Attributes:
        start_x_m: x of the first riser in odom [m].
        rise_m: Height of each stair [m]; negative for a staircase down.
        tread_m: Depth of each tread [m].
        count: Number of stairs; 0 is flat ground at z = 0.
    """

    start_x_m: float = STAIRS_DEFAULTS['stairs_start_x_m']
    rise_m: float = STAIRS_DEFAULTS['stairs_rise_m']
    tread_m: float = STAIRS_DEFAULTS['stairs_tread_m']
    count: int = 0

    def __post_init__(self):
        for name, value in (('stairs_start_x_m', self.start_x_m),
                            ('stairs_rise_m', self.rise_m), ('stairs_tread_m', self.tread_m),
                            ('stairs_count', self.count)):
            low, high, unit = STAIRS_PARAMETERS[name]
            integer = name == 'stairs_count'
            kind_ok = not isinstance(value, bool) and isinstance(
                value, int if integer else (int, float))
            if not kind_ok:
                raise TerrainError(f'{name} must be {"an integer" if integer else "a number"}, '
                                   f'got {value!r} ({type(value).__name__})')
            if not (math.isfinite(value) and low <= value <= high):
                raise TerrainError(f'{name} = {value!r} is out of range: must be in '
                                   f'[{low:g}, {high:g}]{" " + unit if unit else ""}')
        if self.count > 0 and self.rise_m == 0.0:
            raise TerrainError('stairs_rise_m = 0 with stairs_count > 0: a staircase needs a '
                               'rise in [-0.3, 0) or (0, 0.3] m (stairs_count = 0 for flat '
                               'ground)')
        object.__setattr__(self, 'start_x_m', float(self.start_x_m))
        object.__setattr__(self, 'rise_m', float(self.rise_m))
        object.__setattr__(self, 'tread_m', float(self.tread_m))

    @classmethod
    def from_parameters(cls, values: Mapping[str, object]) -> Staircase:
        """The staircase of the ``stairs_*`` parameters in ``values`` (the others ignored)."""
        return cls(values['stairs_start_x_m'], values['stairs_rise_m'],
                   values['stairs_tread_m'], values['stairs_count'])

    @property
    def flat(self) -> bool:
        """True for flat ground (no stairs)."""
        return self.count == 0

    @property
    def total_rise_m(self) -> float:
        """Height of the landing above the ground before the stairs [m]."""
        return self.count * self.rise_m

    @property
    def risers_x_m(self) -> np.ndarray:
        """(count,) x of each riser in odom [m]."""
        return self.start_x_m + self.tread_m * np.arange(self.count)

    def height_at(self, x_m) -> np.ndarray:
        """Ground height [m] at ``x_m`` (array or number); a riser's x belongs to its tread."""
        x = np.asarray(x_m, dtype=float)
        if self.flat:
            return np.zeros_like(x)
        stair = np.clip(np.floor((x - self.start_x_m) / self.tread_m) + 1.0, 0.0, self.count)
        return stair * self.rise_m + 0.0  # no -0.0 before a staircase down

    def highest_under(self, x_m, behind_m: float, ahead_m: float | None = None) -> np.ndarray:
        """Highest ground [m] under a foot at ``x_m`` reaching ``behind_m`` and ``ahead_m``.

        ``ahead_m`` None: as far as ``behind_m`` (a disc of that radius).
        """
        x = np.asarray(x_m)
        ahead_m = behind_m if ahead_m is None else ahead_m
        return np.maximum(self.height_at(x - behind_m), self.height_at(x + ahead_m))

    def riser_under(self, x_m: float, behind_m: float, ahead_m: float) -> bool:
        """Whether a riser is under a foot at ``x_m`` reaching ``behind_m`` and ``ahead_m``."""
        if self.flat:
            return False
        risers = self.risers_x_m
        return bool(np.any((risers > x_m - behind_m) & (risers < x_m + ahead_m)))

    def foothold_candidates(self, x_m: float, keep_out: tuple[float, float]
                            ) -> tuple[float, float]:
        """``(nearest, other)`` allowed foothold x for a target ``x_m`` [m].

        Both are ``x_m`` when it is at least ``keep_out[0]`` [m] before and ``keep_out[1]``
        after every riser (:func:`keep_out_m`); otherwise the two ends of the riser's keep-out
        zone, the nearer first (ties: the one before the riser, a shorter step forward).
        """
        if self.flat:
            return x_m, x_m
        keep_before, keep_after = keep_out
        for riser in self.risers_x_m:
            before, after = riser - keep_before, riser + keep_after
            if before < x_m < after:
                return (before, after) if x_m - before <= after - x_m else (after, before)
        return x_m, x_m


FLAT = Staircase()


def toe_distance_m(rise_m: float, step_height_m: float, stride_m: float,
                   clearance_m: float = 0.0) -> float:
    """How far [m] the polynomial swing moves forward before it is ``|rise_m| + clearance_m`` high.

    The swing of :func:`gait_nodes.swing.polynomial.polynomial_swing` over ``stride_m`` up one
    stair of ``|rise_m|``, via point ``step_height_m`` above the upper foothold at mid-swing; the
    same distance is what a swing down one stair still has to go after it has dropped below the
    upper tread (the swing reversed in time).
    """
    from gait_nodes.swing.polynomial import evaluate, sixth_order_coefficients

    rise = abs(rise_m)
    if rise == 0.0 or stride_m <= 0.0:
        return 0.0
    coefficients = sixth_order_coefficients(
        [0.0, 0.0], [stride_m, rise], [0.5 * stride_m, rise + step_height_m], 1.0, 0.5)
    path = evaluate(coefficients, np.linspace(0.0, 1.0, 2001))
    high = np.flatnonzero(path[:, 1] >= rise + clearance_m)
    if not len(high):
        raise TerrainError(f'a swing {step_height_m:g} m above a stair of {rise:g} m never '
                           f'clears it by {clearance_m:g} m')
    return float(path[high[0], 0])


def keep_out_m(staircase: Staircase, sole_extent_x_m: tuple[float, float],
               step_height_m: float, max_stride_m: float) -> tuple[float, float]:
    """Least distances [m] of a foothold's frame before and after any riser (module docstring).

    Args:
        staircase: The terrain.
        sole_extent_x_m: How far the foot reaches behind and ahead of its frame [m].
        step_height_m: The swing's via height above the higher foothold [m].
        max_stride_m: The longest stride [m] (the toe distance grows with it).
    """
    toe = max(EDGE_MARGIN_M, toe_distance_m(staircase.rise_m, step_height_m, max_stride_m,
                                            STAIR_CLEARANCE_M))
    behind, ahead = sole_extent_x_m
    return ahead + toe, behind + toe


def check_walkable(staircase: Staircase, robot, params) -> tuple[float, float]:
    """Raise :class:`TerrainError` unless ``params`` can walk ``staircase`` on ``robot``.

    Args:
        staircase: The terrain.
        robot: Robot description (the foot's extent, reach).
        params: Gait parameters (swing method, step height).

    Returns:
        The keep-out distances [m] of the footholds' frames before and after each riser
        (:func:`keep_out_m`; 0 on flat ground).
    """
    if staircase.flat:
        return 0.0, 0.0
    if params.swing != 'polynomial':
        raise TerrainError(f'swing = {params.swing!r} cannot walk stairs: the value-table swing '
                           f'is built for flat ground; use swing = polynomial or stairs_count = 0')
    behind, ahead = robot.sole_extent_x_m
    keep_before, keep_after = keep_out_m(staircase, (behind, ahead), params.step_height_m,
                                         robot.reach.max_step_length_m)
    toe = keep_before - ahead
    if staircase.tread_m < keep_before + keep_after:
        raise TerrainError(
            f'stairs_tread_m = {staircase.tread_m:g} is too short for {robot.name}: a foothold '
            f'stays {keep_before:.4g} m before each riser and {keep_after:.4g} m after it (the '
            f'foot reaches {ahead:g} m ahead of its frame and {behind:g} m behind, plus the '
            f'swing\'s toe distance at step_height_m = {params.step_height_m:g} m, at least '
            f'{EDGE_MARGIN_M:g} m), so the tread must be >= {keep_before + keep_after:.4g} m')
    # A stride longer than a tread crosses several risers: the j-th, a toe's keep-out plus
    # (j - 1) treads ahead, must find the foot j stairs high already.
    stride = robot.reach.max_step_length_m
    crossed = math.ceil(stride / staircase.tread_m - 1e-9)
    for j in range(2, crossed + 1):
        needed = toe_distance_m(j * staircase.rise_m, params.step_height_m, stride,
                                STAIR_CLEARANCE_M)
        room = toe + (j - 1) * staircase.tread_m
        if needed > room:
            raise TerrainError(
                f'stairs_tread_m = {staircase.tread_m:g} is too short for {robot.name}\'s '
                f'stride of up to {stride:g} m: a swing over {j} risers reaches the {j}-th '
                f'{room:.4g} m after lift-off but is {j} stairs high only after {needed:.4g} '
                f'm; use a longer tread or a higher step_height_m')
    return keep_before, keep_after


def swing_clearance_m(staircase: Staircase, start_in_world, end_in_world,
                      step_height_m: float, sole_extent_x_m: tuple[float, float],
                      samples: int = CLEARANCE_SAMPLES) -> float:
    """Least height [m] of a polynomial swing's foot above the ground under it.

    The swing is :func:`gait_nodes.swing.polynomial.polynomial_swing`'s path (its timing does
    not change the path); negative: the foot passes through a riser or a tread.

    Args:
        staircase: The terrain.
        start_in_world: (3,) lift-off place [m].
        end_in_world: (3,) landing place [m].
        step_height_m: Via height above the higher foothold [m].
        sole_extent_x_m: How far the foot reaches behind and ahead of its frame [m].
        samples: Points checked along the swing.
    """
    from gait_nodes.swing.polynomial import evaluate, sixth_order_coefficients

    start = np.asarray(start_in_world, dtype=float)
    end = np.asarray(end_in_world, dtype=float)
    via = 0.5 * (start + end)
    via[2] = max(start[2], end[2]) + step_height_m
    coefficients = sixth_order_coefficients(start, end, via, 1.0, 0.5)
    path = evaluate(coefficients, np.linspace(0.0, 1.0, samples))
    return float(np.min(path[:, 2] - staircase.highest_under(path[:, 0], *sole_extent_x_m)))
