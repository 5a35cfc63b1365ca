"""Footsteps, contact schedule and ZMP reference of a walk driven online by (vx, vy, wz).

The body follows a reference path integrated from the commanded twist (body frame, constant
between commands): a straight line, a circular arc, or a side step. Each foot lands where the
body will be at the middle of its coming stance phase, at its nominal offset (the stance
``step_width_m`` wide), with the body's yaw: the footholds follow the curved path and, in steady
walking, every foot moves ``v T`` per swing (Kurazume's coordinate transformation of the straight
gait). The gait's rhythm is fixed by ``step_period_s`` and ``duty_factor``
(see :mod:`gait_nodes.planning.gait_params`); the ZMP reference of each step comes from
:mod:`gait_nodes.planning.zmp_reference`.

Online changes (:meth:`GaitPlanner.set_velocity`, :meth:`GaitPlanner.set_parameters`) take effect
at the next step boundary: the step under way is kept, the later ones are planned again from the
state it ends in. From standstill the first step starts with an extra weight-shift phase of one
step period; a zero twist ends the walk with closing steps that bring every foot to its nominal
place under the last landing pose, then the ZMP settles between the feet.

Terrain (:mod:`gait_nodes.planning.terrain`): on a staircase each foothold's height is the
ground's under it, and a foothold that would lie across a riser (or too close to it for the
swing to clear it) is moved along x onto one tread, the step shortened or lengthened
(:meth:`GaitPlanner.set_terrain`, :meth:`Staircase.foothold_candidates`).

All times here are float seconds from the planner's origin (the node maps them to ROS time).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import math
import operator
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gait_nodes.contract import FootstepPlan, ZmpReference
from gait_nodes.errors import GaitParameterError, TerrainError
from gait_nodes.planning import rhythm as rhythm_module
from gait_nodes.planning import support, zmp_reference
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.layout import FootLayout
from gait_nodes.planning.rhythm import Rhythm
from gait_nodes.planning.terrain import FLAT, Staircase, check_walkable
from gait_nodes.robot.description import RobotDescription

#: A foot closer than this to its target [m, rad] does not step (no zero-length steps).
ALREADY_THERE = 1e-6
#: Longest weight shift before the first step from standstill [s] (at most one step period).
START_SHIFT_S = 1.0
#: Part of that weight shift during which the ZMP reference holds still (the COM controller's
#: preview of the shift).
START_HOLD_FRACTION = 0.5
#: Swing timing models whose rhythm and velocity caches a plan and its forks keep.
MODELS_CACHED = 8
#: A step re-timed for swings longer than its rhythm's gets this much more than they need (for
#: the COM's drift over the longer swing); at most MAX_RETIMING times.
RETIMING_ALLOWANCE = 0.02
MAX_RETIMING = 4
#: Time from a measured start with feet in the air to their landing swing's lift-off [s].
LANDING_LEAD_S = 0.2
#: Largest spacing of a static crawl's ZMP reference samples [s]. The reference is the
#: cart-table ZMP of the full model's COM with the body still, by second differences on these
#: samples, and the preview controller turns it back into the COM the whole-body IK holds:
#: at 0.05 s the swing's quick changes of acceleration were smeared, and the body moved up to
#: 1.4 mm at 7.7 mm/s under a swing (at a 0.5 rad/s limit the IK slowed swings for it); at
#: 0.01 s, 0.4 mm at 4 mm/s, for about 2 % more of the planner's time.
STILL_SAMPLE_S = 0.01
#: Sample spacing of a static crawl body move's full-model ZMP check [s].
MULTIBODY_SAMPLE_S = 0.02
#: Samples of a swing in that check: the swing shape's own (gait_nodes.swing.timing.
#: needed_probe_period: about 60 over the swing).
SWING_SHAPE_SAMPLES = 60
#: A measured foot on the ground further than this from it [m] is planned where it is (its
#: measured height kept) until it first steps: a foothold put this much lower in one tick would
#: jolt the stance.
KEPT_HEIGHT_M = 1e-5
NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Twist2D:
    """Planar body twist in the body frame.

    Attributes:
        vx_m_s: Forward speed [m/s].
        vy_m_s: Leftward speed [m/s].
        wz_rad_s: Turn rate, counter-clockwise [rad/s].
    """

    vx_m_s: float = 0.0
    vy_m_s: float = 0.0
    wz_rad_s: float = 0.0

    def is_zero(self) -> bool:
        """True when the twist asks for no motion."""
        return self.vx_m_s == 0.0 and self.vy_m_s == 0.0 and self.wz_rad_s == 0.0

    def scaled(self, factor: float) -> Twist2D:
        """The twist times ``factor``."""
        return Twist2D(self.vx_m_s * factor, self.vy_m_s * factor, self.wz_rad_s * factor)

    def as_tuple(self) -> tuple[float, float, float]:
        """(vx, vy, wz)."""
        return (self.vx_m_s, self.vy_m_s, self.wz_rad_s)


def integrate_pose(pose: np.ndarray, twist: Twist2D, duration_s: float) -> np.ndarray:
    """Pose (x, y, yaw) reached from ``pose`` after ``duration_s`` of the constant ``twist``."""
    x, y, yaw = pose
    w = twist.wz_rad_s
    turn = w * duration_s
    if abs(turn) < 1e-9:
        dx, dy = twist.vx_m_s * duration_s, twist.vy_m_s * duration_s
    else:
        sin_t, cos_t = math.sin(turn), math.cos(turn)
        dx = (twist.vx_m_s * sin_t + twist.vy_m_s * (cos_t - 1.0)) / w
        dy = (twist.vx_m_s * (1.0 - cos_t) + twist.vy_m_s * sin_t) / w
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * dx - s * dy, y + s * dx + c * dy, yaw + turn])


def place(pose: np.ndarray, offsets_in_base: np.ndarray) -> np.ndarray:
    """(N, 2) world positions of base-frame ``offsets_in_base`` for the body at ``pose``."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rotation = np.array([[c, -s], [s, c]])
    return offsets_in_base @ rotation.T + pose[:2]


def centred_pose(positions: np.ndarray, offsets_in_base: np.ndarray, yaw: float) -> np.ndarray:
    """Pose (x, y, yaw) whose stance ``offsets_in_base`` is centred on the (F, 2) ``positions``.

    Where a walk's path starts from feet that are not at their nominal places (a measured
    stance): the body's yaw, the footholds' centre.
    """
    centre = np.asarray(positions, dtype=float)[:, :2].mean(axis=0) \
        - place(np.array([0.0, 0.0, yaw]), offsets_in_base).mean(axis=0)
    return np.array([centre[0], centre[1], yaw])


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


class _Unnamed:
    """What :func:`_probe_name` cannot name (a model, a terrain but flat ground)."""


def _probe_name(key: tuple, timing, terrain) -> str | None:
    """The name of a step's probe ``key`` (:meth:`GaitPlanner._probed`), or None.

    Another process planning the same step with an alike swing timing model names it alike;
    None: a probe not on flat ground (not kept).
    """
    def plain(value):
        if value is timing:
            return 'timing'
        if value is terrain:
            return 'flat' if terrain.flat else _Unnamed
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return (type(value).__name__, plain(dataclasses.astuple(value)))
        if isinstance(value, tuple):
            items = tuple(plain(item) for item in value)
            return _Unnamed if _Unnamed in items else items
        if value is None or isinstance(value, (str, bytes, bool, int, float)):
            return value
        return _Unnamed

    named = plain(key)
    return None if named is _Unnamed else hashlib.sha256(repr(named).encode()).hexdigest()[:40]


def _encoded(value):
    """A probe (numbers, arrays, tuples and lists of them) as a JSON value."""
    if isinstance(value, np.ndarray):
        return {'array': value.tolist()}
    if isinstance(value, tuple):
        return {'tuple': [_encoded(item) for item in value]}
    if isinstance(value, list):
        return [_encoded(item) for item in value]
    return float(value)


def _decoded(value):
    """The probe of :func:`_encoded`'s JSON value."""
    if isinstance(value, dict):
        if 'array' in value:
            return np.array(value['array'], dtype=float)
        return tuple(_decoded(item) for item in value['tuple'])
    if isinstance(value, list):
        return [_decoded(item) for item in value]
    return float(value)


def _rounded(values) -> bytes:
    """``values`` to 1e-9 (metres, radians, seconds) as a memo key.

    A step planned from another time (a change joining later) finds its feet where the first
    planning put them but for the last bits of the path's arithmetic.
    """
    return (np.round(np.asarray(values, dtype=float), 9) + 0.0).tobytes()


def _shared_times(planned: Sequence[float], needed: Sequence[float],
                  first: bool = False) -> tuple[float, ...]:
    """A static-crawl step's phase times: its body move's and each swing slot's [s].

    The step keeps its planned period when what its phases need fits in it, each getting a
    share of it in proportion to its need (so the path and the rhythm keep their pace: every
    phase ends up equally far from its limit); when it does not fit, each phase gets what it
    needs and ``RETIMING_ALLOWANCE`` more (and the path waits for the time added). So does the
    ``first`` step from standstill, whose swings go to the crawl's stance, a part of a stride:
    held to the rhythm's period, RoboSimian stood 1.3 s longer in it; the path starts earlier
    by what it saves.
    """
    period, total = float(sum(planned)), float(sum(needed))
    if total <= 0.0:
        return tuple(float(t) for t in planned)
    scale = period / total if total <= period and not first else 1.0 + RETIMING_ALLOWANCE
    return tuple(float(n) * scale for n in needed)


def clamp_velocity(twist: Twist2D, params: GaitParameters, robot: RobotDescription,
                   layout: FootLayout, cycle_of=None, fastest: dict | None = None,
                   kept: dict | None = None) -> tuple[Twist2D, list[str]]:
    """The twist the planner walks for a commanded ``twist``, and why it was reduced.

    Each component is clamped to its configured maximum; then the whole twist is scaled down so
    that no foot moves more than one stride (``step_length_m`` along x,
    ``reach.max_step_width_m`` along y) and the body turns at most ``reach.max_turn_rad`` in a
    cycle.

    Args:
        twist: The commanded twist.
        params: Gait parameters.
        robot: Robot description (reach).
        layout: Foot layout.
        cycle_of: Gait cycle [s] of a twist when the rhythm depends on it (``timing:
            joint_limit``); raises GaitParameterError for a twist the joints cannot walk.
            None: ``params.cycle_s``.
        fastest: A dict kept between calls: the fastest feasible twist is searched along the
            command's direction (the twist scaled until a component reaches its maximum), so
            every command in that direction (a forward one, whatever its speed) reuses it.
        kept: Searches kept on disk (:meth:`GaitPlanner.probes_to_keep`), found by name.
    """
    notes = []
    values = list(twist.as_tuple())
    names = ('vx', 'vy', 'wz')
    limits = (params.max_vx_m_s, params.max_vy_m_s, params.max_wz_rad_s)
    settings = ('max_vx_m_s', 'max_vy_m_s', 'max_wz_rad_s')
    units = ('m/s', 'm/s', 'rad/s')
    for i in range(3):
        if abs(values[i]) > limits[i]:
            clamped = math.copysign(limits[i], values[i])
            notes.append(f'{names[i]} {values[i]:g} {units[i]} clamped to {clamped:g} '
                         f'({settings[i]})')
            values[i] = clamped
    result = Twist2D(*values)
    gait = params.resolved_gait(robot)
    offsets = layout.offsets(params.step_width_m, gait)
    stride = min(params.step_length_m, robot.max_step_length_m(gait))

    def fits(candidate: Twist2D) -> bool:
        try:
            cycle = params.cycle_s if cycle_of is None else cycle_of(candidate)
        except GaitParameterError:
            return False
        if abs(candidate.wz_rad_s) * cycle > robot.reach.max_turn_rad + 1e-12:
            return False
        moved = place(integrate_pose(np.zeros(3), candidate, cycle), offsets) - offsets
        return bool(np.all(np.abs(moved[:, 0]) <= stride + 1e-12)
                    and np.all(np.abs(moved[:, 1]) <= robot.reach.max_step_width_m + 1e-12))

    if not fits(result):
        size = max(abs(value) / limit for value, limit in zip(values, limits, strict=True)
                   if value != 0.0)
        # (Rounded: twists along one direction find its search, whatever their size.)
        direction = Twist2D(*(round(v, 12) for v in result.scaled(1.0 / size).as_tuple()))
        fastest = {} if fastest is None else fastest
        kept = (kept or {}).get(_probe_name(('fastest', direction, params), None, None))
        if (direction, params) not in fastest and isinstance(kept, float):
            fastest[direction, params] = kept
        if (direction, params) not in fastest:
            if len(fastest) > 256:
                fastest.clear()
            low, high = 0.0, 1.0
            # Each test of a joint-limit rhythm solves its fixed point: stop at 3e-9 of the
            # component limits.
            for _ in range(50 if cycle_of is None else 28):
                middle = 0.5 * (low + high)
                low, high = (middle, high) if fits(direction.scaled(middle)) else (low, middle)
            fastest[direction, params] = low
        reduced = direction.scaled(fastest[direction, params])
        low = fastest[direction, params] / size
        cycle = params.cycle_s if cycle_of is None else cycle_of(reduced)
        rhythm = ('' if cycle_of is None else
                  ' at the fastest rhythm the joint velocity limit allows')
        own = '' if stride == params.step_length_m else f', {gait} at most {stride:g} m'
        notes.append(f'twist ({result.vx_m_s:g}, {result.vy_m_s:g}, {result.wz_rad_s:g}) '
                     f'scaled by {low:.3f} to ({reduced.vx_m_s:.4g}, {reduced.vy_m_s:.4g}, '
                     f'{reduced.wz_rad_s:.4g}) to keep each swing within one stride{rhythm} '
                     f'(step_length_m {params.step_length_m:g} m{own}, reach.max_step_width_m '
                     f'{robot.reach.max_step_width_m:g} m, reach.max_turn_rad '
                     f'{robot.reach.max_turn_rad:g} rad per {cycle:.4g} s cycle)')
        result = reduced
    return result, notes


@dataclass(frozen=True)
class SwingSlot:
    """Feet that swing together.

    Attributes:
        lift_off_s: Lift-off time [s].
        touch_down_s: Touch-down time [s].
        feet: Indices of the swinging feet (each really moves).
        positions_after: (F, 2) all foot positions after the touch-down [m].
        yaws_after: (F,) all foot yaws after the touch-down [rad].
    """

    lift_off_s: float
    touch_down_s: float
    feet: tuple[int, ...]
    positions_after: np.ndarray
    yaws_after: np.ndarray


@dataclass(frozen=True)
class _State:
    """What the next step is planned from (the end of the previous one)."""

    time_s: float
    positions: np.ndarray
    yaws: np.ndarray
    zmp: np.ndarray
    mode: str  # 'standing' | 'walking' | 'stopping'
    next_group: int
    rest_pose: np.ndarray
    last_anchor: np.ndarray
    path_start_s: float = 0.0
    path_pose: np.ndarray | None = None
    path_twist: Twist2D = Twist2D()
    # Feet still where a MeasuredStart found them: each waits while it is ahead of its foothold.
    measured: frozenset[int] = frozenset()


@dataclass(frozen=True)
class Step:
    """One step: all feet down while the ZMP moves, then the swing slots.

    Attributes:
        gait: The gait walked (resolved, never 'auto').
        kind: 'walk' (has swings) or 'stand'.
        start_s: Step start [s].
        end_s: Step end [s] (the next step's start).
        positions_start: (F, 2) foot positions at the start [m].
        yaws_start: (F,) foot yaws at the start [rad].
        slots: Swing slots in time order.
        zmp_times_s: (K,) ZMP knot times [s].
        zmp_points: (K, 2) ZMP knots in odom [m].
        zmp_margin_kept_m: Margin [m] the step's ZMP keeps by construction inside the support
            polygon, the hull of the stance feet's discs (biped and trot: on the support line,
            i.e. the foot radius; crawl: its depth in the contact-point triangles plus that).
        params: Parameters the step was planned with.
        twist: Twist the step was planned with.
        settings: Which settings (parameters, swing timing, terrain) the step was planned
            with: :attr:`GaitPlanner.settings` then (see :meth:`GaitPlanner.settings_from_s`).
        bases: A static crawl's base positions (x, y, z) before its body move and during its
            swings [m] (None for the other gaits).
    """

    gait: str
    kind: str
    start_s: float
    end_s: float
    positions_start: np.ndarray
    yaws_start: np.ndarray
    slots: tuple[SwingSlot, ...]
    zmp_times_s: np.ndarray
    zmp_points: np.ndarray
    zmp_margin_kept_m: float
    params: GaitParameters
    twist: Twist2D
    state_after: _State = dataclasses.field(repr=False, compare=False)
    settings: int = 0
    bases: tuple[np.ndarray, np.ndarray] | None = dataclasses.field(default=None, repr=False,
                                                                    compare=False)

    @property
    def positions_end(self) -> np.ndarray:
        """(F, 2) foot positions at the end [m]."""
        return self.slots[-1].positions_after if self.slots else self.positions_start

    @property
    def yaws_end(self) -> np.ndarray:
        """(F,) foot yaws at the end [rad]."""
        return self.slots[-1].yaws_after if self.slots else self.yaws_start


@dataclass(frozen=True)
class MeasuredStart:
    """The robot's measured state a plan starts from (a planner started into a running walk).

    Attributes:
        feet_in_world: (F, 3) contact points in odom, in layout order [m]; a foot higher than
            ``airborne_m`` above the ground is in the air.
        foot_yaws_rad: (F,) foot yaws [rad].
        zmp_in_world: (2,) where the ZMP reference starts (the measured COM of a robot at
            rest) [m].
        ground_height_m: Height of the ground under each foot in odom [m]: one number, or (F,)
            (stairs: the tread under each foot).
        airborne_m: Height above the ground from which a foot is in the air [m].
    """

    feet_in_world: np.ndarray
    foot_yaws_rad: np.ndarray
    zmp_in_world: np.ndarray
    ground_height_m: float | np.ndarray = 0.0
    airborne_m: float = 0.005

    def airborne(self) -> np.ndarray:
        """(F,) booleans: the feet in the air."""
        heights = np.asarray(self.feet_in_world, dtype=float)[:, 2] - self.ground_height_m
        return heights > self.airborne_m

    def check(self, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(F, 2) footholds, (F,) yaws, (2,) ZMP; raises GaitParameterError if malformed."""
        feet = np.asarray(self.feet_in_world, dtype=float)
        yaws = np.asarray(self.foot_yaws_rad, dtype=float)
        zmp = np.asarray(self.zmp_in_world, dtype=float)
        if feet.shape != (count, 3) or yaws.shape != (count,) or zmp.shape != (2,):
            raise GaitParameterError(f'a measured start needs ({count}, 3) feet, ({count},) '
                                     f'yaws and a (2,) ZMP, got {feet.shape}, {yaws.shape}, '
                                     f'{zmp.shape}')
        if not (np.isfinite(feet).all() and np.isfinite(yaws).all() and np.isfinite(zmp).all()):
            raise GaitParameterError('a measured start must be finite')
        return feet[:, :2].copy(), yaws.copy(), zmp.copy()


class GaitPlanner:
    """Plans footsteps and the ZMP reference online, step by step.

    Args:
        robot: Robot description (feet, foot radius, reach).
        params: Gait parameters (default: :meth:`GaitParameters.for_robot`).
        base_pose: Initial body pose (x [m], y [m], yaw [rad]) in odom; the feet start at their
            nominal places under it.
        start_s: Time of the initial standstill [s].
        swing_timing: Least swing times at the joint velocity limit
            (:class:`gait_nodes.swing.timing.SwingTiming`), used with ``timing: joint_limit``;
            None: every gait keeps the fixed timing of its parameters.
        start: Where the robot really is (:class:`MeasuredStart`, e.g. a planner restarted
            mid-walk): the plan starts from these footholds and this ZMP instead of the nominal
            stance under ``base_pose`` (which stays the pose the walk's path starts from).
        terrain: The ground (default flat); the feet start on it.

    Raises:
        GaitParameterError: ``params`` do not suit the robot, or ``start`` not one foot each.
        TerrainError: ``params`` cannot walk ``terrain``, or a foot starts across a riser.
    """

    def __init__(self, robot: RobotDescription, params: GaitParameters | None = None, *,
                 base_pose: Sequence[float] = (0.0, 0.0, 0.0), start_s: float = 0.0,
                 swing_timing=None, start: MeasuredStart | None = None,
                 terrain: Staircase | None = None):
        self.robot = robot
        self.layout = FootLayout.of(robot)
        params = params or GaitParameters.for_robot(robot)
        params.check_robot(robot)
        self._params = params
        self._settings = 0  # counts the changes of parameters, timing and terrain
        self._terrain = terrain or FLAT
        self._keep_out_m = check_walkable(self._terrain, robot, params)
        self._timing = swing_timing
        self._rhythms: dict = {}
        self._sways: dict = {}  # the steady crawl's sway (rhythm.transfer_move)
        self._clamped: dict = {}
        self._fastest: dict = {}  # the fastest feasible twist by direction (clamp_velocity)
        #: Swing timing model -> its (rhythms, clamped, fastest) caches, shared by the forks: a
        #: change planned again (or after a trial on another fork) with a model the plans have
        #: timed before finds its searches made.
        self._by_model: dict = {swing_timing: (self._rhythms, self._clamped, self._fastest)}
        self._probes: dict = {}  # a step's probes by its geometry (_probed)
        self._kept_probes: dict[str, object] = {}  # probes kept on disk, by name (take_probes)
        self._requested = Twist2D()
        self._twist = Twist2D()
        pose = np.array(base_pose, dtype=float)
        positions = place(pose, self.layout.offsets(params.step_width_m))
        yaws = np.full(self.layout.count, pose[2])
        zmp = zmp_reference.standing_zmp(self.layout, positions, pose[2])
        self._airborne: tuple[np.ndarray, float] | None = None
        self._kept_heights: tuple[np.ndarray, np.ndarray] | None = None
        self._bases: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        if start is not None:
            positions, yaws, zmp = start.check(self.layout.count)
            self._keep_heights(start, positions)
        self._initial = _State(
            time_s=float(start_s), positions=positions, yaws=yaws, zmp=zmp, mode='standing',
            next_group=0, rest_pose=pose, last_anchor=pose,
            measured=frozenset(range(self.layout.count)) if start is not None else frozenset())
        self._steps: list[Step] = []
        self._before: tuple[float, np.ndarray, np.ndarray] | None = None
        self._outputs: tuple = ((), {})  # see _memo
        self._last_zmp_reference = None  # see zmp_reference
        self._halted = False  # see stand
        self._check_footholds(self._terrain, [positions], compare_heights=False)
        if start is not None and start.airborne().any():
            self._steps.append(self._landing_step(start))

    # --- settings ----------------------------------------------------------------------------

    @property
    def params(self) -> GaitParameters:
        """Parameters of the steps planned from the next step boundary on."""
        return self._params

    @property
    def twist(self) -> Twist2D:
        """Twist walked from the next step boundary on (after clamping)."""
        return self._twist

    @property
    def requested_twist(self) -> Twist2D:
        """Twist last commanded, before clamping."""
        return self._requested

    @property
    def swing_timing(self):
        """The swing timing model (None: fixed timing)."""
        return self._timing

    def set_swing_timing(self, swing_timing, now_s: float) -> None:
        """Time the steps from the next step boundary after ``now_s`` with ``swing_timing``."""
        self._use_timing(swing_timing)
        self._twist, _ = self._clamp(self._requested, self._params)
        self._settings += 1
        self._replan(now_s)

    def _use_timing(self, swing_timing) -> None:
        """Time with ``swing_timing`` and its caches (:attr:`_by_model`; new ones the first time).

        Other caches, not emptied ones: a fork (see :meth:`fork`) shares them with the plan it
        came from.
        """
        self._timing = swing_timing
        if swing_timing not in self._by_model:
            if len(self._by_model) >= MODELS_CACHED:
                self._by_model.pop(next(iter(self._by_model)))
            self._by_model[swing_timing] = ({}, {}, {})
        self._rhythms, self._clamped, self._fastest = self._by_model[swing_timing]
        self._kept_probes = {}  # (another model's)

    def anew(self, base_pose: Sequence[float], start: MeasuredStart | None = None
             ) -> GaitPlanner:
        """A plan from scratch at ``base_pose`` (from ``start``, if given), standing.

        The robot, the parameters, the swing timing and the terrain are this plan's, and so are
        the rhythm and velocity caches, which follow from those alone: the new plan walks a
        velocity this one has walked without searching its fastest rhythm again. So are the
        steps' probes, which follow from where the feet go: a plan anew where the robot stood
        in this one (a planner joining a graph, which rehearsed its first walk while it waited
        for the robot's pose) walks that first walk without probing it again.
        """
        fresh = GaitPlanner(self.robot, self._params, base_pose=base_pose,
                            swing_timing=self._timing, start=start, terrain=self._terrain)
        fresh._rhythms, fresh._sways = self._rhythms, self._sways
        fresh._clamped, fresh._fastest = self._clamped, self._fastest
        fresh._by_model = self._by_model
        fresh._probes, fresh._kept_probes = self._probes, self._kept_probes
        fresh._settings = self._settings
        return fresh

    @property
    def settings(self) -> int:
        """Counts the changes of the parameters, the swing timing and the terrain.

        Each step records the count it was planned with (:attr:`Step.settings`).
        """
        return self._settings

    def settings_from_s(self, settings: int) -> float | None:
        """Start [s] of the first planned step with ``settings`` or later ones (None: none yet).

        Where a change is walked from: its step boundary, or an earlier one when a later
        change (a stop, a new velocity, a stand, a plan from scratch) re-planned the steps
        before that boundary with the settings in force.
        """
        for step in self._steps:
            if step.settings >= settings:
                return step.start_s
        return None

    def fork(self) -> GaitPlanner:
        """A copy to plan a change on, or to read while this one plans on.

        The steps are immutable and shared; the copy has its own list of them and its own
        memoized outputs. The rhythm and velocity caches of each swing timing model are shared
        (they hold what follows from the robot, the parameters and the model alone): a fork
        that takes another model finds what any fork searched with it.
        """
        twin = copy.copy(self)
        twin._steps = list(self._steps)
        twin._outputs = ((), {})
        twin._last_zmp_reference = None
        return twin

    def rhythm(self, params: GaitParameters | None = None,
               twist: Twist2D | None = None) -> Rhythm | None:
        """The joint-limit rhythm of steady walking at ``twist`` (default: the walked twist).

        None with ``timing: fixed`` or without a swing timing model.

        Raises:
            GaitParameterError: The joints cannot walk ``twist`` at any stride.
        """
        params = params or self._params
        twist = self._twist if twist is None else twist
        if params.timing != 'joint_limit' or self._timing is None:
            return None
        key = (params, twist)
        if key not in self._rhythms:
            if len(self._rhythms) > 256:
                self._rhythms.clear()
            gait = params.resolved_gait(self.robot)
            try:
                timing = self._still_body() if gait == 'static_crawl' else self._timing
                self._rhythms[key] = rhythm_module.walking_rhythm(gait, self.layout, params,
                                                                  twist, timing, self._sways)
            except GaitParameterError as exc:
                self._rhythms[key] = exc
        result = self._rhythms[key]
        if isinstance(result, GaitParameterError):
            raise result
        return result

    def timed(self, params: GaitParameters, twist: Twist2D) -> GaitParameters:
        """``params`` with the step period and duty factor the steps at ``twist`` walk with."""
        rhythm = self.rhythm(params, twist)
        return params if rhythm is None else rhythm.apply(params)

    def _clamp(self, twist: Twist2D, params: GaitParameters) -> tuple[Twist2D, list[str]]:
        key = (twist, params)
        if key not in self._clamped:
            if len(self._clamped) > 256:
                self._clamped.clear()
            cycle_of = None
            if params.timing == 'joint_limit' and self._timing is not None:
                def cycle_of(candidate):
                    return self.rhythm(params, candidate).cycle_s
            self._clamped[key] = clamp_velocity(twist, params, self.robot, self.layout,
                                                cycle_of, self._fastest, self._kept_probes)
        return self._clamped[key]

    def set_parameters(self, params: GaitParameters, now_s: float,
                       swing_timing: object = ...) -> None:
        """Use ``params`` from the next step boundary after ``now_s``.

        ``swing_timing``, if given, replaces the swing timing model with them (timing the new
        parameters with the old model first would search their rhythm for nothing).

        Raises:
            GaitParameterError: ``params`` do not suit the robot (nothing changes).
            TerrainError: ``params`` cannot walk the terrain (nothing changes).
        """
        params.check_robot(self.robot)
        keep_out_m = check_walkable(self._terrain, self.robot, params)
        if swing_timing is not ... and swing_timing is not self._timing:
            self._use_timing(swing_timing)
        self._keep_out_m = keep_out_m
        twist, _ = self._clamp(self._requested, params)
        self._params, self._twist = params, twist
        self._settings += 1
        self._replan(now_s)

    @property
    def terrain(self) -> Staircase:
        """The ground the steps from the next step boundary on are planned on."""
        return self._terrain

    def check_terrain(self, terrain: Staircase, now_s: float,
                      params: GaitParameters | None = None) -> None:
        """Raise :class:`TerrainError` unless :meth:`set_terrain` would accept ``terrain``.

        ``params`` (default the current ones) must walk it, and the feet where the plan kept
        by ``now_s`` has them (standing, under way, landing) must be on the same ground as now:
        the terrain may change ahead of the robot, not under its feet.
        """
        check_walkable(terrain, self.robot, params or self._params)
        kept = [step for step in self._steps if step.start_s <= now_s]
        placed = [self._before[1] if self._before is not None else
                  kept[0].positions_start if kept else self._state().positions]
        placed += [slot.positions_after for step in kept for slot in step.slots]
        self._check_footholds(terrain, placed, compare_heights=True)

    def set_terrain(self, terrain: Staircase, now_s: float,
                    params: GaitParameters | None = None) -> None:
        """Plan on ``terrain`` (and with ``params``, if given) from the next step boundary.

        Raises:
            GaitParameterError: ``params`` do not suit the robot (nothing changes).
            TerrainError: See :meth:`check_terrain` (nothing changes).
        """
        params = params or self._params
        params.check_robot(self.robot)
        self.check_terrain(terrain, now_s, params)
        self._terrain = terrain
        self._keep_out_m = check_walkable(terrain, self.robot, params)
        self._params = params
        self._twist, _ = self._clamp(self._requested, params)
        self._settings += 1
        self._replan(now_s)

    def _check_footholds(self, terrain: Staircase, placed: Sequence[np.ndarray],
                         compare_heights: bool) -> None:
        behind, ahead = self.robot.sole_extent_x_m
        for positions in placed:
            for foot, (x, y) in zip(self.layout.names, positions, strict=True):
                if terrain.riser_under(x, behind, ahead):
                    raise TerrainError(
                        f'the staircase puts a riser under the {foot} foot (at x = {x:.4g} m, '
                        f'reaching {behind:g} m behind and {ahead:g} m ahead): '
                        f'stairs_start_x_m = {terrain.start_x_m:g} m must leave the feet on a '
                        f'tread')
                if compare_heights:
                    now_m = float(self._terrain.height_at(x))
                    then_m = float(terrain.height_at(x))
                    if abs(now_m - then_m) > 1e-9:
                        raise TerrainError(
                            f'the staircase would move the ground under the {foot} foot (at '
                            f'({x:.4g}, {y:.4g}) m) from {now_m:g} m to {then_m:g} m: the '
                            f'terrain may change ahead of the feet, not under them')

    def set_velocity(self, twist: Twist2D, now_s: float) -> tuple[Twist2D, list[str]]:
        """Walk ``twist`` from the next step boundary after ``now_s``.

        Returns:
            The twist that will be walked and, if it was reduced, why.

        Raises:
            GaitParameterError: A component is NaN or infinite (nothing changes).
        """
        if not all(math.isfinite(v) for v in twist.as_tuple()):
            raise GaitParameterError(f'velocity command {twist.as_tuple()} is not finite')
        applied, notes = self._clamp(twist, self._params)
        self._requested = twist
        if applied != self._twist:
            self._twist = applied
            self._replan(now_s)
        return applied, notes

    # --- planning ----------------------------------------------------------------------------

    @property
    def steps(self) -> tuple[Step, ...]:
        """Planned steps kept in memory, in time order."""
        return tuple(self._steps)

    def _state(self) -> _State:
        return self._steps[-1].state_after if self._steps else self._initial

    def _replan(self, now_s: float) -> None:
        """Drop the steps that have not started by ``now_s``; end a standstill at ``now_s``.

        A step that holds the robot standing has nothing to finish: it is cut at ``now_s`` (its
        ZMP where it is then), so that a command from standstill starts the walk at once. So is
        a step squaring the feet up to stop whose first foot has not lifted yet, when the new
        twist walks: the robot is still standing where it stood (a planner that joined a robot
        mid-walk before its first /cmd_vel arrived would otherwise square up a whole group of
        feet, then start from standstill).
        """
        self._steps = [step for step in self._steps if step.start_s <= now_s]
        if not self._steps or self._steps[-1].end_s <= now_s:
            return
        step = self._steps[-1]
        unlifted_stop = (step.state_after.mode == 'stopping' and step.slots
                         and step.slots[0].lift_off_s > now_s and not self._twist.is_zero())
        if step.kind == 'stand' or unlifted_stop:
            cut = max(now_s, step.start_s)
            zmp = zmp_reference.sample(step.zmp_times_s, step.zmp_points, np.array([cut]))[0]
            # The reference up to the cut as it was planned (and published: a change joins
            # ahead of what the consumers have), every knot before the cut kept.
            before = step.zmp_times_s < cut
            times = np.append(step.zmp_times_s[before], cut)
            points = np.vstack([step.zmp_points[before], zmp])
            if unlifted_stop:
                before = self._steps[-2].state_after if len(self._steps) > 1 else self._initial
                after = dataclasses.replace(before, time_s=cut, zmp=zmp)
                step = dataclasses.replace(
                    step, kind='stand', slots=(),
                    zmp_margin_kept_m=self._all_down_margin(points, step.positions_start))
            else:
                after = dataclasses.replace(step.state_after, time_s=cut, zmp=zmp)
            self._steps[-1] = dataclasses.replace(step, end_s=cut, zmp_times_s=times,
                                                  zmp_points=points, state_after=after)
            if cut == step.start_s:
                self._steps.pop()
                if not self._steps:
                    self._initial = dataclasses.replace(self._initial, time_s=cut, zmp=zmp)

    def next_boundary_s(self, now_s: float) -> float:
        """Time of the first step boundary after ``now_s`` (where a change takes effect)."""
        for step in self._steps:
            if step.start_s > now_s:
                return step.start_s
            if step.end_s > now_s:
                return step.end_s
        return max(self._state().time_s, now_s)

    def advance(self, until_s: float) -> bool:
        """Plan steps until the plan reaches ``until_s``; True if any step was added."""
        added = False
        while self._state().time_s < until_s:
            self._steps.append(self._next_step(self._state()))
            added, self._halted = True, False
        return added

    @property
    def halted(self) -> bool:
        """Whether the plan ends in the stand of :meth:`stand` (no step planned after it)."""
        return self._halted

    def stand(self, now_s: float, hold_s: float) -> None:
        """Stop at a safe stand from ``now_s`` and hold it for ``hold_s`` [s] (a failure's end).

        No foot lifts off after ``now_s``: steps that have not started are dropped, and so are
        the swings of the step under way that have not lifted off (a swing in the air lands
        where it was going, with the ZMP the step planned for it). Then every foot stays down
        while the ZMP moves, over ``hold_s``, to the stance's stand point (inside its support
        polygon), and stays there. :meth:`advance` walks on after that stand, and a new
        velocity at once, from standstill as from a measured stance: the path from the
        footholds' centre, no first step longer than a stride, no foot stepping back.
        """
        self._steps = [step for step in self._steps if step.start_s <= now_s]
        if self._steps and self._steps[-1].end_s > now_s:
            step = self._steps[-1]
            lifted = tuple(slot for slot in step.slots if slot.lift_off_s <= now_s)
            if len(lifted) < len(step.slots) or not step.slots:  # (a stand ends now too)
                cut = lifted[-1].touch_down_s if lifted else max(now_s, step.start_s)
                zmp = zmp_reference.sample(step.zmp_times_s, step.zmp_points,
                                           np.array([cut]))[0]
                before = step.zmp_times_s < cut
                positions = lifted[-1].positions_after if lifted else step.positions_start
                yaws = lifted[-1].yaws_after if lifted else step.yaws_start
                after = dataclasses.replace(step.state_after, time_s=cut, positions=positions,
                                            yaws=yaws, zmp=zmp)
                self._steps[-1] = dataclasses.replace(
                    step, kind='walk' if lifted else 'stand', end_s=cut, slots=lifted,
                    zmp_times_s=np.append(step.zmp_times_s[before], cut),
                    zmp_points=np.vstack([step.zmp_points[before], zmp]), state_after=after)
                if cut == step.start_s:
                    self._steps.pop()
                    if not self._steps:
                        self._initial = dataclasses.replace(self._initial, time_s=cut, zmp=zmp)
        state = self._state()
        yaw = float(np.angle(np.exp(1j * state.yaws).sum()))
        pose = centred_pose(state.positions, self.layout.offsets(self._params.step_width_m),
                            yaw)
        state = dataclasses.replace(state, mode='standing',
                                    measured=frozenset(range(self.layout.count)))
        self._steps.append(self._stand_step(state, self._params.resolved_gait(self.robot), pose,
                                            hold_s))
        self._halted = True

    def prune(self, before_s: float) -> None:
        """Forget steps that ended before ``before_s`` (the last contact change is kept)."""
        while len(self._steps) > 1 and self._steps[0].end_s < before_s:
            step = self._steps.pop(0)
            if step.slots:
                last = step.slots[-1]
                self._before = (last.touch_down_s, last.positions_after, last.yaws_after)

    def _next_step(self, state: _State, timed: tuple | None = None,
                   retimed: int = 0, planned: tuple[dict, float] | None = None) -> Step:
        """The step after ``state``; with ``timed``, its (swing, transfer) times [s].

        ``timed`` may hold a third item: each swing slot's own time [s] (a static crawl's, whose
        swing then is their mean), and a fourth, True when they are not to be shared again
        (slowed for the full model's ZMP).

        With ``timing: joint_limit`` a step whose swings or transfer (the body's move with every
        foot down) need more time than its rhythm gives
        (the first steps, a change of gait or velocity, the closing steps, and every step where
        the body's sway takes the limbs where they are slower than at the nominal stance) is
        planned again with the time they need. The retimed step keeps the footholds of the
        rhythm's plan (``planned``: foot -> (target, yaw, anchor), and the rhythm's step end)
        and the path waits for the time it adds: a longer swing to a foothold further ahead
        would need more time again, and the strides would grow until a swing leaves the reach.
        """
        params, twist = self._params, self._twist
        gait = params.resolved_gait(self.robot)
        groups = self.layout.swing_groups(gait)
        # A gait with its own stance walks it; standing (and the closing steps of a stop) is
        # the nominal stance, which the robot starts from.
        offsets = self.layout.offsets(params.step_width_m, None if twist.is_zero() else gait)
        t0 = state.time_s
        params = self.timed(params, twist)
        if timed is not None:
            params = Rhythm(*timed[:2], len(groups[0]), self._timing.name).apply(params)
        if twist.is_zero():
            rest = state.last_anchor if state.mode == 'walking' else state.rest_pose
            targets = place(rest, offsets)
            targets[:, 0] = [self._terrain.foothold_candidates(x, self._keep_out_m)[0]
                             for x in targets[:, 0]]
            yaws = np.full(self.layout.count, rest[2])
            pending = self._not_there(state, targets, yaws)
            if not pending:
                return self._stand_step(state, gait, rest)
            group_index = next(g % len(groups) for g in range(state.next_group,
                                                              state.next_group + len(groups))
                               if pending & set(sum(groups[g % len(groups)], ())))
            path = dict(path_start_s=state.path_start_s, path_pose=state.path_pose,
                        path_twist=state.path_twist)

            def target_of(foot, touch_down_s):
                return targets[foot], yaws[foot], rest

            mode = 'stopping'
        else:
            cycle, swing = params.cycle_s, params.swing_s
            starting = state.mode != 'walking'
            rest = state.rest_pose
            group_index = ((0 if _leads_left(twist) else 1) if starting
                           else state.next_group % len(groups))
            extra = self._start_shift_s(params, gait) if state.mode == 'standing' else 0.0
            first_touch_down = t0 + params.transfer_s(gait) + extra + swing

            def first_cycle(g):
                return self._first_cycle_path_s(state, groups, g, offsets, params, twist,
                                                first_touch_down)

            if starting and state.measured:
                # From a measured stance: the group whose first cycle lets the path begin
                # soonest (the less it must wait for feet that trail it, the fewer feet ahead
                # of it wait a step); of equals, the one whose feet lag most.
                lagging = self._lagging_group(state, groups, offsets, params, twist)
                group_index = min(range(len(groups)),
                                  key=lambda g: (round(first_cycle(g)[1], 6), g != lagging))
            if starting:
                start, lead = first_cycle(group_index)
                path_pose = state.last_anchor if state.mode == 'stopping' else rest
                if lead > 0.0:
                    path_pose = integrate_pose(path_pose, twist, -lead)
                path = dict(path_start_s=start, path_pose=path_pose, path_twist=twist)
            elif twist != state.path_twist:
                path = dict(path_start_s=t0, path_pose=self._path_pose(state.path_start_s,
                                                                       state.path_pose,
                                                                       state.path_twist, t0),
                            path_twist=twist)
            else:
                path = dict(path_start_s=state.path_start_s, path_pose=state.path_pose,
                            path_twist=state.path_twist)

            def target_of(foot, touch_down_s):
                anchor = self._path_pose(path['path_start_s'], path['path_pose'],
                                         path['path_twist'],
                                         touch_down_s + 0.5 * params.duty_factor * cycle)
                return place(anchor, offsets[foot:foot + 1])[0], anchor[2], anchor

            mode = 'walking'
        if planned is not None:
            footholds = planned[0]

            def target_of(foot, touch_down_s):
                return footholds[foot]
        chosen: dict[int, tuple] = {}
        swing = params.swing_s
        extra = self._start_shift_s(params, gait) if state.mode == 'standing' else 0.0
        t1 = t0 + params.transfer_s(gait) + extra
        positions, foot_yaws = state.positions.copy(), state.yaws.copy()
        slots, last_anchor = [], state.last_anchor
        # From a measured start a foot ahead of its foothold waits until the path is past it:
        # none steps back.
        forward = (_forward(state.rest_pose, offsets, params, twist)
                   if state.measured and mode == 'walking' else None)
        durations = (tuple(timed[2]) if timed is not None and len(timed) > 2
                     else (swing,) * len(groups[group_index]))
        for j, feet in enumerate(groups[group_index]):
            lift_off = t1 + sum(durations[:j])
            touch_down = lift_off + durations[j]
            moving = []
            after, after_yaws = positions.copy(), foot_yaws.copy()
            for foot in feet:
                target, yaw, anchor = chosen[foot] = target_of(foot, touch_down)
                if forward is not None and foot in state.measured \
                        and (target - positions[foot]) @ forward[foot] < 0.0:
                    continue
                target = self._on_tread(positions[foot], self._within_reach(
                    positions[foot], target, yaw, gait), yaw, gait)
                if (np.linalg.norm(target - positions[foot]) > ALREADY_THERE
                        or abs(wrap_angle(yaw - foot_yaws[foot])) > ALREADY_THERE):
                    after[foot], after_yaws[foot] = target, yaw
                    moving.append(foot)
                    last_anchor = anchor
            if moving:
                slots.append(SwingSlot(lift_off, touch_down, tuple(moving), after, after_yaws))
                positions, foot_yaws = after, after_yaws
        t_end = t1 + sum(durations)
        if planned is not None and mode == 'walking':
            # The path waits for the time the retimed step adds.
            path = dict(path, path_start_s=path['path_start_s'] + t_end - planned[1])
        if not slots:
            times = np.array([t0, t_end])
            points = np.array([state.zmp, zmp_reference.standing_zmp(self.layout, positions,
                                                                     rest[2])])
            kept = self._all_down_margin(points, positions)
            kind = 'stand'
        else:
            times = np.array([t0, t1, t_end])
            points, kept = self._zmp_knots(gait, state, slots, times, groups[group_index])
            kind = 'walk'
        after_state = _State(
            time_s=t_end, positions=positions, yaws=foot_yaws, zmp=points[-1], mode=mode,
            next_group=group_index + 1, rest_pose=rest, last_anchor=last_anchor,
            measured=(state.measured.difference(*(slot.feet for slot in slots))
                      if mode == 'walking' else frozenset()), **path)
        # The probes follow from where the feet go, not from when: a step planned again with
        # other times (retimed, below) takes them from the first time.
        geometry = self._step_geometry(gait, state, slots, points, params.com_height_m)
        bases = (self._probed(('bases', geometry),
                              lambda: self._still_bases(state, slots, points[1]))
                 if gait == 'static_crawl' and slots else None)
        # (A static crawl is timed for the joints' acceleration limits too: its swings and
        # moves run at the limits, the limb's own, with nothing else to slow them.)
        still = bases is not None
        needs = self._probed(('needs', still, geometry), lambda: self._slot_needs(
            gait, state, slots, points, params.com_height_m, with_acceleration=still,
            bases=bases))
        needed = max(needs, default=0.0)
        transfer = params.transfer_s(gait)
        needed_transfer = self._probed(('transfer', still, geometry),
                                       lambda: self._needed_transfer_s(
                                           state, points, params.com_height_m,
                                           with_acceleration=still, bases=bases))
        slowed = timed is not None and len(timed) > 3 and timed[3]
        if still and not slowed and len(needs) == len(durations) and retimed < MAX_RETIMING:
            shares = _shared_times((transfer, *durations), (needed_transfer, *needs),
                                   state.mode == 'standing')
            if not np.allclose(shares, (transfer, *durations), rtol=1e-9, atol=1e-12):
                return self._next_step(
                    state, (float(np.mean(shares[1:])), shares[0], tuple(shares[1:])),
                    retimed + 1, planned or (chosen, t_end))
        elif (needed > swing * (1.0 + 1e-9) or needed_transfer > transfer * (1.0 + 1e-9)) \
                and retimed < MAX_RETIMING:
            swing = max(swing, needed * (1.0 + RETIMING_ALLOWANCE))
            in_rhythm = rhythm_module.rhythm_for_swing(gait, swing,
                                                       self._timing.lift_and_lower_s(), '')
            transfer = max(in_rhythm.transfer_s, transfer,
                           needed_transfer * (1.0 + RETIMING_ALLOWANCE))
            return self._next_step(state, (swing, transfer), retimed + 1,
                                   planned or (chosen, t_end))
        hold = self._start_hold_s(extra, gait) if kind == 'walk' else 0.0
        if bases is not None:
            # Sampled on the step's own clock: the same step walked from another time (a change
            # planned again from a later join) takes them from the first planning.
            phases = _rounded([t1 - t0 - hold, *(t - t1 for slot in slots
                                                 for t in (slot.lift_off_s, slot.touch_down_s))])
            times, points, kept, full = self._probed(
                ('zmp', geometry, phases), lambda: self._still_body_zmp(
                    state, slots, bases, t0 + hold, t1, origin_s=t0 + hold))
            times = times + (t0 + hold)
            if full < params.zmp_margin_m and retimed < MAX_RETIMING:
                # The swinging limbs' momentum takes the ZMP off the cart-table one by what
                # scales as 1 / T^2: slower swings bring it back inside the margin.
                off = max(kept - full, 1e-9)
                factor = min(max(math.sqrt(off / max(kept - params.zmp_margin_m, 0.25 * off)),
                                 1.05), 1.5)
                slower = tuple(d * factor for d in durations)
                return self._next_step(state, (float(np.mean(slower)), transfer, slower, True),
                                       retimed + 1, planned or (chosen, t_end))
            kept = min(kept, full)
            if hold > 0.0:
                times, points = np.concatenate([[t0], times]), np.concatenate([points[:1],
                                                                               points])
            after_state = dataclasses.replace(after_state, zmp=points[-1])
        elif hold > 0.0:
            # From standstill the ZMP stays put for part of the weight shift: the plan reaches
            # the COM controller when the command comes, and a ZMP that starts moving at once
            # leaves it no preview for the pendulum's initial counter-move.
            times = np.concatenate([times[:1], [t0 + hold], times[1:]])
            points = np.concatenate([points[:1], points])
        return Step(gait, kind, t0, t_end, state.positions, state.yaws, tuple(slots), times,
                    points, kept, params, twist, after_state, self._settings, bases)

    def _step_geometry(self, gait: str, state: _State, slots: Sequence[SwingSlot],
                       zmp_points: np.ndarray, com_height_m: float) -> tuple:
        """What a step's probes and body placement follow from (its times aside).

        The gait, the feet before the step and after each swing slot, the ZMP knots, the COM
        height, and the planner's swing timing model, terrain and timing setting.
        """
        return (gait, self._timing, self._terrain, self._params.timing, float(com_height_m),
                _rounded(state.positions), _rounded(state.yaws), _rounded(zmp_points),
                tuple((slot.feet, _rounded(slot.positions_after), _rounded(slot.yaws_after))
                      for slot in slots))

    def _probed(self, key: tuple, compute):
        """``compute()``, once per ``key`` (see :meth:`_step_geometry`; shared by forks).

        Or the probe kept on disk by that name (:meth:`take_probes`).
        """
        known = self._probes.get(key)
        if known is None:
            if len(self._probes) > 256:
                self._probes.clear()
            kept = (self._kept_probes.get(_probe_name(key, self._timing, self._terrain))
                    if self._kept_probes else None)
            try:
                known = None if kept is None else _decoded(kept)
            except (TypeError, ValueError, KeyError):
                known = None  # not a probe: computed
            self._probes[key] = known = compute() if known is None else known
        return known

    def probes_to_keep(self) -> dict[str, object]:
        """The probes of the steps planned so far on flat ground, for :meth:`take_probes`.

        And the fastest walks searched (:func:`clamp_velocity`).

        By names another process finds them by (the probe's geometry, its swing timing model
        aside: the caller keeps them per model), as JSON values (exactly: floats in full).
        """
        kept = {_probe_name(('fastest', *key), None, None): float(fraction)
                for key, fraction in self._fastest.items()}
        for key, value in self._probes.items():
            name = _probe_name(key, self._timing, self._terrain)
            if name is not None:
                kept[name] = _encoded(value)
        return kept

    def take_probes(self, kept: dict[str, object]) -> None:
        """Take the probes ``kept`` instead of computing them, for the steps they are of.

        ``kept``: :meth:`probes_to_keep` of a plan with this swing timing model.

        The main job plans its scenario's first walk before the graph starts and keeps its
        probes on disk (:func:`gait_nodes.swing.still_body.keep_probes`); the footstep planner
        then plans that walk, its rehearsal and its first change in a fraction of a second.
        Forks and plans anew share them.
        """
        self._kept_probes = dict(kept)

    def check_joint_speeds(self, probe, from_s: float) -> None:
        """Raise unless the joints can walk every step from ``from_s`` on in its planned time.

        Each step's swings and transfer are probed as :meth:`_next_step` probes them to re-time
        a walk at the joint limit (``probe``: a :class:`gait_nodes.swing.timing.SwingTiming`),
        here to check a plan whose times are fixed (``timing: fixed``), or any plan, against
        the joints' velocity and acceleration limits.

        Raises:
            GaitParameterError: The first step whose swing or transfer needs more time than
                planned: which, how much, and what gives it more.
        """
        for step in self._steps:
            if step.start_s < from_s - 1e-9 or not step.slots:
                continue
            before = _State(time_s=step.start_s, positions=step.positions_start,
                            yaws=step.yaws_start, zmp=step.zmp_points[0], mode='walking',
                            next_group=0, rest_pose=np.zeros(3), last_anchor=np.zeros(3))
            points = step.zmp_points[-3:] if len(step.zmp_points) > 3 else step.zmp_points
            needs = self._slot_needs(step.gait, before, step.slots, points,
                                     step.params.com_height_m, probe, True, step.bases)
            transfer_s = step.slots[0].lift_off_s - step.start_s
            needed_transfer = self._needed_transfer_s(before, points, step.params.com_height_m,
                                                      probe, True, step.bases)
            names = [self.layout.names[f] for f in step.slots[0].feet]
            params = step.params
            checks = [(f'the swing of {[self.layout.names[f] for f in slot.feet]}',
                       slot.lift_off_s, needed_s, slot.touch_down_s - slot.lift_off_s,
                       'a longer period or a lower duty factor gives the swings more time, a '
                       'shorter stride needs less')
                      for slot, needed_s in zip(step.slots, needs, strict=True)]
            checks.append((f'the body\'s move before the swing of {names}', step.start_s,
                           needed_transfer, transfer_s,
                           'a longer period or a higher duty factor gives the body more time'))
            for what, at_s, needed_s, planned_s, more in checks:
                if needed_s > planned_s * (1.0 + 1e-9):
                    raise GaitParameterError(
                        f'the joints cannot follow {what} at {at_s:.2f} s: it needs '
                        f'{needed_s:.3f} s at the joint velocity and acceleration limits, the '
                        f'plan gives {planned_s:.3f} s (step_period_s {params.step_period_s:g} '
                        f's, duty_factor {params.duty_factor:g}: {more})')

    def _slot_needs(self, gait: str, state: _State, slots: Sequence[SwingSlot],
                    zmp_points: np.ndarray, com_height_m: float, probe=None,
                    with_acceleration: bool = False, bases=None) -> list[float]:
        """Time [s] each slot's swings need at the joint limit (none: no model).

        Each swing is probed where it happens (:meth:`gait_nodes.swing.timing.SwingTiming.
        step_s`): the other feet where they stand, the COM over the ZMP reference of the swing
        (held at the step's knot in a crawl or biped step, moving along the diagonal in a trot);
        in a static crawl (``bases`` given), the body still at ``bases[1]``
        (:meth:`gait_nodes.swing.still_body.StillBody.step_s`).
        """
        if probe is None and (self._params.timing != 'joint_limit' or self._timing is None) \
                or not slots:
            return []
        probe = probe or self._timing
        centre = zmp_points[1] if gait != 'trot' else 0.5 * (zmp_points[1] + zmp_points[2])
        needs = []
        for feet, yaws, swings in self._slot_swings(state, slots):
            body_yaw = float(np.angle(np.exp(1j * yaws).sum()))
            if bases is not None:  # a static crawl: the body still at its base
                time_s = self._still_body(probe).step_s(swings, feet, yaws, body_yaw,
                                                        bases[1], with_acceleration)
            else:
                com = np.array([centre[0], centre[1], com_height_m + feet[:, 2].min()])
                time_s = probe.step_s(swings, feet, yaws, body_yaw, com, with_acceleration)
            needs.append(time_s)
        return needs

    def _slot_swings(self, state: _State, slots: Sequence[SwingSlot]):
        """Per slot: the feet (F, 3) and yaws (F,) before it and its swings (foot -> Swing)."""
        from gait_nodes.contract import Swing

        positions, yaws = state.positions, state.yaws
        for slot in slots:
            feet = self._with_heights(positions)
            landing = self._with_heights(slot.positions_after)
            yield feet, yaws, {foot: Swing(self.layout.names[foot], slot.lift_off_s,
                                           slot.touch_down_s, feet[foot], landing[foot],
                                           float(yaws[foot]), float(slot.yaws_after[foot]))
                               for foot in slot.feet}
            positions, yaws = slot.positions_after, slot.yaws_after

    def _still_body(self, probe=None):
        """The body-still view of the swing timing model (the static crawl's).

        Raises:
            GaitParameterError: No swing timing model (the static crawl needs one).
        """
        from gait_nodes.swing.still_body import still_body_of

        probe = probe or self._timing
        if probe is None:
            raise GaitParameterError('gait static_crawl needs a swing timing model (closed-form '
                                     'limb IK): the body is placed under each swing')
        return still_body_of(probe)

    def _still_bases(self, state: _State, slots: Sequence[SwingSlot], knot: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
        """(base before the body's move, base during the swings) of a static-crawl step [m].

        The full-model COM is over the step's first ZMP point with the feet where the step
        starts, and over its knot (:func:`zmp_reference.crawl_knots`, the thesis' ZMP) with the
        feet between the swings.
        """
        key = (state.zmp.tobytes(), state.positions.tobytes(), state.yaws.tobytes(),
               np.asarray(knot, dtype=float).tobytes(), slots[0].positions_after.tobytes(),
               slots[0].yaws_after.tobytes())
        if key not in self._bases:  # (a re-timed step asks again: the same places)
            if len(self._bases) > 64:
                self._bases.clear()
            still = self._still_body()
            feet = self._with_heights(state.positions)
            height = self.robot.body_height_m + feet[:, 2].min()
            yaw = float(np.angle(np.exp(1j * state.yaws).sum()))
            before = still.base_for_com(state.zmp, height, yaw, feet, state.yaws)
            between = still.base_for_com(knot, height, yaw,
                                         self._with_heights(slots[0].positions_after),
                                         slots[0].yaws_after)
            self._bases[key] = (before, between)
        return self._bases[key]

    def _still_body_zmp(self, state: _State, slots: Sequence[SwingSlot],
                        bases: tuple[np.ndarray, np.ndarray], move_from_s: float,
                        move_to_s: float, origin_s: float = 0.0
                        ) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(times, points, margin, full-model margin) of a static-crawl step's ZMP reference.

        The times are counted from ``origin_s``.

        The base moves from ``bases[0]`` to ``bases[1]`` between ``move_from_s`` and
        ``move_to_s`` (:func:`gait_nodes.swing.still_body.body_move`, every foot down) and
        stands still through the swings; the COM of the full model follows (the swinging
        limbs' mass included,
        :meth:`gait_nodes.swing.still_body.StillBody.com`) and the reference is its cart-table
        ZMP, sampled every :data:`STILL_SAMPLE_S` or so. The margin is the least over the
        samples of the distance inside the support polygon of the feet down then (foot discs);
        the full-model margin is that of the ZMP with the limbs' momentum
        (:meth:`_still_body_multibody_margin`).
        """
        from gait_nodes.swing.still_body import body_move, cart_table_zmp

        still = self._still_body()
        yaw = float(np.angle(np.exp(1j * state.yaws).sum()))
        feet = self._with_heights(state.positions)
        count = max(int(math.ceil((move_to_s - move_from_s) / STILL_SAMPLE_S)), 2)
        times = [np.linspace(move_from_s, move_to_s, count + 1)]
        fraction = body_move((times[0] - move_from_s) / (move_to_s - move_from_s))
        base = bases[0] + fraction[:, None] * (bases[1] - bases[0])
        coms = [still.com(base, yaw, np.repeat(feet[None], count + 1, axis=0),
                          np.repeat(state.yaws[None], count + 1, axis=0))]
        stances = [(count + 1) * [state.positions]]
        for (before, yaws, swings), slot in zip(self._slot_swings(state, slots), slots,
                                                strict=True):
            count = max(int(math.ceil((slot.touch_down_s - slot.lift_off_s) / STILL_SAMPLE_S)),
                        2)
            t = np.linspace(slot.lift_off_s, slot.touch_down_s, count + 1)[1:]
            u = (t - slot.lift_off_s) / (slot.touch_down_s - slot.lift_off_s)
            _, placed, placed_yaws = still.source.swing_feet(swings, before, yaws, yaw, u)
            times.append(t)
            coms.append(still.com(np.repeat(bases[1][None], len(t), axis=0), yaw, placed,
                                  placed_yaws))
            stance = [f for f in range(self.layout.count) if f not in slot.feet]
            stances.append(len(t) * [before[stance, :2]])
        times, com = np.concatenate(times), np.concatenate(coms)
        points = cart_table_zmp(times, com, float(com[:, 2].mean() - feet[:, 2].min()))
        times = times - origin_s
        stances = [positions for group in stances for positions in group]
        margin = min(support.support_margin(p, positions, self.robot.foot_radius_m)
                     for p, positions in zip(points, stances, strict=True))
        return times, points, margin, self._still_body_multibody_margin(
            state, slots, bases, move_from_s, move_to_s)

    def _still_body_multibody_margin(self, state: _State, slots: Sequence[SwingSlot],
                                     bases: tuple[np.ndarray, np.ndarray], move_from_s: float,
                                     move_to_s: float) -> float:
        """Least margin [m] of the full model's ZMP (momentum included) over a static step.

        Each phase (the body's move, each swing: rest to rest) sampled every
        :data:`MULTIBODY_SAMPLE_S` (a swing on its shape's :data:`SWING_SHAPE_SAMPLES`) and its
        ZMP computed as the ZMP monitor does
        (:meth:`gait_nodes.swing.still_body.StillBody.multibody_zmp`), inside the support
        polygon of the feet down then: the swinging limb's angular momentum moves it off the
        cart-table ZMP of the COM (by 20-40 mm on RoboSimian's fastest swings).
        """
        from gait_nodes.swing.still_body import body_move

        still = self._still_body()
        yaw = float(np.angle(np.exp(1j * state.yaws).sum()))
        feet = self._with_heights(state.positions)
        radius = self.robot.foot_radius_m
        margin = math.inf
        if move_to_s > move_from_s:
            count = max(int(math.ceil((move_to_s - move_from_s) / MULTIBODY_SAMPLE_S)), 2)
            fraction = body_move(np.linspace(0.0, 1.0, count + 1))
            base = bases[0] + fraction[:, None] * (bases[1] - bases[0])
            zmp = still.multibody_zmp((move_to_s - move_from_s) / count, base, yaw,
                                      np.repeat(feet[None], count + 1, axis=0),
                                      np.repeat(state.yaws[None], count + 1, axis=0))
            margin = min(support.support_margin(p, state.positions, radius) for p in zmp)
        for (before, yaws, swings), slot in zip(self._slot_swings(state, slots), slots,
                                                strict=True):
            # On the swing shape's own samples (needed_probe_period): finer ones would take
            # the finite differences of its linear interpolation for accelerations.
            duration = slot.touch_down_s - slot.lift_off_s
            count = SWING_SHAPE_SAMPLES
            u = np.linspace(0.0, 1.0, count + 1)
            _, placed, placed_yaws = still.source.swing_feet(swings, before, yaws, yaw, u)
            zmp = still.multibody_zmp(duration / count, np.repeat(bases[1][None], len(u), axis=0),
                                      yaw, placed, placed_yaws)
            stance = before[[f for f in range(self.layout.count) if f not in slot.feet], :2]
            margin = min(margin, *(support.support_margin(p, stance, radius) for p in zmp))
        return margin

    def _needed_transfer_s(self, state: _State, zmp_points: np.ndarray,
                           com_height_m: float, probe=None,
                           with_acceleration: bool = False, bases=None) -> float:
        """Least time [s] of the step's transfer, the COM following the ZMP's move (0: none).

        :meth:`gait_nodes.swing.timing.SwingTiming.transfer_s` with the feet where they stand
        and the COM moved from the first ZMP knot to the second (the end of the transfer); in a
        static crawl (``bases`` given) the base moved from ``bases[0]`` to ``bases[1]``
        (:meth:`gait_nodes.swing.still_body.StillBody.transfer_s`).
        """
        if probe is None and (self._params.timing != 'joint_limit' or self._timing is None) \
                or len(zmp_points) < 3:
            return 0.0
        probe = probe or self._timing
        if bases is not None:
            return self._still_body(probe).transfer_s(
                self._with_heights(state.positions), state.yaws,
                float(np.angle(np.exp(1j * state.yaws).sum())), bases[0], bases[1],
                with_acceleration)
        feet = self._with_heights(state.positions)
        height = com_height_m + feet[:, 2].min()
        com_from, com_to = (np.array([*point, height]) for point in zmp_points[:2])
        if np.linalg.norm(com_to - com_from) < ALREADY_THERE:
            return 0.0
        body_yaw = float(np.angle(np.exp(1j * state.yaws).sum()))
        return probe.transfer_s(feet, state.yaws, body_yaw, com_from, com_to,
                                with_acceleration)

    @staticmethod
    def _first_cycle_path_s(state: _State, groups, group_index: int, offsets: np.ndarray,
                            params: GaitParameters, twist: Twist2D, first_touch_down_s: float
                            ) -> tuple[float, float]:
        """(start [s], lead [s of walking]) of a walk's path from standstill.

        The path starts from ``state.rest_pose`` when the foothold of the first cycle's last
        touch-down is one stride ahead of the nominal stance under it: no foot of the first
        cycle, ``groups[group_index]`` first, moves more than a stride. From a measured stance
        a foot behind its nominal place (a walk paused across a contact change: the pose is the
        footholds' centre, and a foot that had not stepped yet trails it) would step that much
        further, beyond the stride the velocity was clamped to (and, re-timed for the longer
        swing it needs, after a foothold that moves on with every re-timing, out of the limbs'
        reach): the path begins as far back as ``lead`` of walking, so that none does (0 from
        the nominal stance).
        """
        span = params.step_period_s + (len(groups[group_index]) - 1) * params.swing_s
        start = first_touch_down_s + 0.5 * params.duty_factor * params.cycle_s + span \
            - params.cycle_s
        if not state.measured:
            return start, 0.0
        rest = state.rest_pose
        nominal = place(rest, offsets)
        motion = place(integrate_pose(rest, twist, params.cycle_s), offsets) - nominal
        speed = np.linalg.norm(motion, axis=1) / params.cycle_s
        behind = ((nominal - state.positions) * _forward(rest, offsets, params, twist)).sum(axis=1)
        lead = 0.0
        for g in range(len(groups)):
            for j, feet in enumerate(groups[(group_index + g) % len(groups)]):
                anchor = (first_touch_down_s + g * params.step_period_s + j * params.swing_s
                          + 0.5 * params.duty_factor * params.cycle_s)
                for foot in feet:
                    if speed[foot] > 1e-12:
                        lead = max(lead, anchor - start + behind[foot] / speed[foot]
                                   - params.cycle_s)
        return start, lead

    @staticmethod
    def _lagging_group(state: _State, groups, offsets: np.ndarray, params: GaitParameters,
                       twist: Twist2D) -> int:
        """The swing group to start a measured start's walk with: the feet furthest behind.

        A robot stopped mid-walk has feet ahead of their nominal places and feet behind; the
        walk goes on with the feet that lag most along the way their footholds move (starting
        with a foot that is ahead would step it back and swing the body back with it).
        """
        rest = state.rest_pose
        now = place(integrate_pose(rest, twist, 0.5 * params.cycle_s), offsets)
        lag = ((now - state.positions) * _forward(rest, offsets, params, twist)).sum(axis=1)
        scores = [float(np.mean([lag[f] for f in group[0]])) for group in groups]
        return int(np.argmax(scores))

    def _keep_heights(self, start: MeasuredStart, positions: np.ndarray) -> None:
        """Plan the measured feet on the ground at their measured heights until they step.

        A foot counts as on the ground up to ``start.airborne_m`` above it (a foot just lifting
        or landing when the walk paused): planned on the ground at once, it would be pushed
        down (or up) that much in one tick, a jolt of the whole stance (the simulated robot's
        ZMP went 51 m out). Its measured height is kept until its first swing lands it.
        """
        heights = np.asarray(start.feet_in_world, dtype=float)[:, 2] \
            - np.broadcast_to(np.asarray(start.ground_height_m, dtype=float), positions.shape[:1])
        kept = ~start.airborne() & (np.abs(heights) > KEPT_HEIGHT_M)
        if kept.any():
            self._kept_heights = (np.where(kept, heights, 0.0), positions.copy())

    def _landing_step(self, start: MeasuredStart) -> Step:
        """First step of a plan started with feet in the air: each is put down straight below.

        The feet in the air swing from where they are to the ground under them (lifting off
        :data:`LANDING_LEAD_S` after the start, so that the swing-leg policy has its lead time),
        for as long as a swing of the walk's rhythm; the ZMP holds where the start puts it, inside
        the feet on the ground. The walk then starts from standstill.
        """
        state = self._initial
        try:
            params = self.timed(self._params, self._twist)
        except GaitParameterError:
            params = self._params
        gait = params.resolved_gait(self.robot)
        feet = tuple(int(f) for f in np.flatnonzero(start.airborne()))
        t0 = state.time_s
        lift_off = t0 + LANDING_LEAD_S
        touch_down = lift_off + params.swing_s
        slot = SwingSlot(lift_off, touch_down, feet, state.positions.copy(), state.yaws.copy())
        grounded = np.delete(state.positions, feet, axis=0)
        points = np.array([state.zmp, state.zmp])
        kept = (self._all_down_margin(points, grounded) if len(grounded)
                else -math.inf)
        heights = np.asarray(start.feet_in_world, dtype=float)[:, 2].copy()
        ground = np.broadcast_to(np.asarray(start.ground_height_m, dtype=float), heights.shape)
        heights[list(feet)] -= ground[list(feet)]
        heights[[f for f in range(self.layout.count) if f not in feet]] = 0.0
        self._airborne = (heights, touch_down)
        after = dataclasses.replace(state, time_s=touch_down)
        return Step(gait, 'walk', t0, touch_down, state.positions, state.yaws, (slot,),
                    np.array([t0, touch_down]), points, kept, self._params, self._twist, after,
                    self._settings)

    @staticmethod
    def _start_shift_s(params: GaitParameters, gait: str) -> float:
        """Weight shift added before the first step from standstill [s].

        In the static crawl, only the part of it that would follow the hold
        (:meth:`_start_hold_s`): the first step's body move, every foot down and rest to rest,
        is its weight shift, and takes that much longer than it needs at the joint limits.
        Moved in what it needs (0.21 s for RoboSimian's first 2.6 cm), the COM controller's
        COM lagged it, and the ZMP's least margin fell from 30 to 15-22 mm at the first
        lift-off after it; stretched by half a second, as it was after the hold, it keeps 30.
        """
        shift = min(params.step_period_s, START_SHIFT_S)
        return (1.0 - START_HOLD_FRACTION) * shift if gait == 'static_crawl' else shift

    @staticmethod
    def _start_hold_s(shift_s: float, gait: str) -> float:
        """Part of a start's weight shift ``shift_s`` the ZMP reference holds still [s].

        None in the static crawl: its ZMP reference is the cart-table ZMP of the COM it walks
        (the body still before its first move), which the COM controller gives back without a
        counter-move ahead of the move.
        """
        return 0.0 if gait == 'static_crawl' else START_HOLD_FRACTION * shift_s

    def _stand_step(self, state: _State, gait: str, rest: np.ndarray,
                    duration_s: float | None = None) -> Step:
        t0 = state.time_s
        t_end = t0 + (self._params.step_period_s if duration_s is None else duration_s)
        settled = zmp_reference.standing_zmp(self.layout, state.positions, rest[2])
        after = dataclasses.replace(state, time_s=t_end, zmp=settled, mode='standing',
                                    rest_pose=rest, last_anchor=rest)
        points = np.array([state.zmp, settled])
        return Step(gait, 'stand', t0, t_end, state.positions, state.yaws, (),
                    np.array([t0, t_end]), points, self._all_down_margin(points, state.positions),
                    self._params, self._twist, after, self._settings)

    def _all_down_margin(self, points: np.ndarray, positions: np.ndarray) -> float:
        return min(support.support_margin(p, positions, self.robot.foot_radius_m)
                   for p in points)

    def _zmp_knots(self, gait, state, slots, times, group) -> tuple[np.ndarray, float]:
        if gait == 'biped':
            stance = next(f for f in range(self.layout.count) if f not in group[0])
            return (zmp_reference.biped_knots(state.positions, stance, times, state.zmp),
                    self.robot.foot_radius_m)
        if gait == 'trot':
            return (zmp_reference.trot_knots(self.layout, state.positions,
                                             slots[-1].positions_after, group[0], times,
                                             state.zmp),
                    self.robot.foot_radius_m)
        before = [state.positions] + [slot.positions_after for slot in slots[:-1]]
        region = [(slot.feet, positions) for slot, positions in zip(slots, before, strict=True)]
        if gait == 'static_crawl':
            # The COM over the middle of the feet between the swings, where every stance limb
            # is as near its nominal place as the stride allows, moved into the region by as
            # little as the margin needs (a sideways move costs RoboSimian's stance limbs
            # twice the joint travel of a forward one). The margin the step keeps is measured
            # on the ZMP it makes (_still_body_zmp).
            target = slots[0].positions_after.mean(axis=0)
            knots, _ = zmp_reference.crawl_knots(self.layout, region, target,
                                                 self._params.zmp_margin_m, state.zmp,
                                                 target_is_point=True)
            return knots, self.robot.foot_radius_m
        knots, kept = zmp_reference.crawl_knots(self.layout, region, slots[0].positions_after,
                                                self._params.zmp_margin_m, state.zmp)
        return knots, kept + self.robot.foot_radius_m

    @staticmethod
    def _path_pose(start_s, pose, twist, t_s) -> np.ndarray:
        return integrate_pose(pose, twist, max(t_s - start_s, 0.0))

    def _not_there(self, state: _State, targets: np.ndarray, yaws: np.ndarray) -> set[int]:
        distance = np.linalg.norm(targets - state.positions, axis=1)
        turn = np.abs(wrap_angle(yaws - state.yaws))
        return {int(f) for f in np.nonzero((distance > ALREADY_THERE)
                                           | (turn > ALREADY_THERE))[0]}

    def _with_heights(self, positions: np.ndarray) -> np.ndarray:
        """(F, 3) ``positions`` with the ground's height under each."""
        return np.column_stack([positions, self._terrain.height_at(positions[:, 0])])

    def _on_tread(self, start: np.ndarray, target: np.ndarray, yaw: float,
                  gait: str) -> np.ndarray:
        """``target`` moved along x out of the risers' keep-out zones (see the module docstring).

        The nearer end of the zone if the step stays within reach, else the other end, else
        (neither in reach) the end nearer to ``start``.
        """
        if self._terrain.flat:
            return target
        candidates = [np.array([x, target[1]]) for x in
                      self._terrain.foothold_candidates(float(target[0]), self._keep_out_m)]
        for candidate in candidates:
            if np.allclose(self._within_reach(start, candidate, yaw, gait), candidate,
                           rtol=0.0, atol=1e-12):
                return candidate
        return min(candidates, key=lambda c: abs(c[0] - start[0]))

    def _within_reach(self, start: np.ndarray, target: np.ndarray, yaw: float,
                      gait: str) -> np.ndarray:
        """``target``, pulled towards ``start`` if the step is longer than ``gait`` reaches."""
        c, s = math.cos(yaw), math.sin(yaw)
        step = target - start
        along, across = c * step[0] + s * step[1], -s * step[0] + c * step[1]
        reach = self.robot.reach
        scale = min(1.0, self.robot.max_step_length_m(gait) / max(abs(along), 1e-15),
                    reach.max_step_width_m / max(abs(across), 1e-15))
        return start + scale * step

    # --- outputs -----------------------------------------------------------------------------

    def _memo(self) -> dict:
        """Outputs computed from the plan as it is now (emptied whenever the plan changes).

        The plan is made of its steps, the last contact change before them, the state after
        them, the airborne start and the terrain; none is ever edited in place (a change
        replaces the object), so the plan is unchanged while they are the same objects.
        """
        parts = (self._before, self._initial, self._airborne, self._kept_heights, self._terrain,
                 *self._steps)
        known, outputs = self._outputs
        if len(known) != len(parts) or not all(map(operator.is_, known, parts)):
            outputs = {}
            self._outputs = (parts, outputs)
        return outputs

    def zmp_knots(self) -> tuple[np.ndarray, np.ndarray]:
        """(K,) times [s] and (K, 2) points of the ZMP reference over the planned steps."""
        memo = self._memo()
        if 'zmp_knots' not in memo:
            knots = self._zmp_knots_now()
            for array in knots:
                array.setflags(write=False)
            memo['zmp_knots'] = knots
        return memo['zmp_knots']

    def _zmp_knot_lists(self) -> tuple[list[float], list[float], list[float]]:
        """:meth:`zmp_knots` as lists of floats: times [s], x [m], y [m]."""
        memo = self._memo()
        if 'zmp_knot_lists' not in memo:
            times, points = self.zmp_knots()
            memo['zmp_knot_lists'] = (times.tolist(), points[:, 0].tolist(),
                                      points[:, 1].tolist())
        return memo['zmp_knot_lists']

    def _zmp_knots_now(self) -> tuple[np.ndarray, np.ndarray]:
        if not self._steps:
            state = self._state()
            return np.array([state.time_s]), state.zmp[None, :]
        times = np.concatenate([step.zmp_times_s for step in self._steps])
        points = np.concatenate([step.zmp_points for step in self._steps])
        keep = np.ones(len(times), dtype=bool)
        keep[1:] = np.diff(times) > 0
        return times[keep], points[keep]

    def zmp(self, times_s: np.ndarray) -> np.ndarray:
        """(N, 2) ZMP reference [m] at ``times_s`` (held beyond the planned steps)."""
        knot_times, knot_points = self.zmp_knots()
        return zmp_reference.sample(knot_times, knot_points, np.asarray(times_s, dtype=float))

    def zmp_reference(self, first_ns: int, origin_ns: int, horizon_s: float,
                      period_s: float) -> ZmpReference:
        """Contract samples from ``first_ns`` over ``horizon_s`` every ``period_s``.

        Args:
            first_ns: Time of the first sample [ns].
            origin_ns: ROS time of the planner's 0 s [ns].
            horizon_s: Time covered after the first sample [s].
            period_s: Sample period [s].
        """
        period_ns = int(round(period_s * NS_PER_S))
        count = int(math.ceil(horizon_s * NS_PER_S / period_ns - 1e-9)) + 1
        knots = self.zmp_knots()
        # (the float times of the samples are (stamp - origin) * 1e-9, as numpy works them out)
        plan = None if self._terrain.flat else self.footstep_plan(
            (first_ns - origin_ns) * 1e-9, origin_ns)
        # The node asks every tick for a window slid by a few samples of the same plan: the
        # samples at the stamps the last window already had are its values (np.interp works
        # sample by sample: the same knots and time give the same bits), only the new tail
        # is sampled. The heights too while the footstep plan they are read from is the same.
        key = (knots, plan, origin_ns, period_ns, count)
        last = self._last_zmp_reference
        shift = count
        if last is not None and last[0][0] is knots and last[0][1] is plan \
                and last[0][2:] == key[2:] and (first_ns - last[1]) % period_ns == 0:
            shift = (first_ns - last[1]) // period_ns
        if 0 <= shift < count and plan is None:
            # The few new samples of a slid window on flat ground in plain floats: numpy's
            # int64 and float64 steps one by one ((stamp - origin) * 1e-9, np.interp's
            # formula), hence its values to the bit (test_zmp_reference).
            times, xs, ys = self._zmp_knot_lists()
            stamps = [first_ns + period_ns * k for k in range(count - shift, count)]
            zmp = [(zmp_reference.interp_floats(t, times, xs),
                    zmp_reference.interp_floats(t, times, ys))
                   for t in [(stamp - origin_ns) * 1e-9 for stamp in stamps]]
            reference = last[2].followed_by(shift, stamps, zmp)
            self._last_zmp_reference = (key, first_ns, reference)
            return reference
        if 0 <= shift < count:
            stamps = first_ns + period_ns * np.arange(count - shift, count, dtype=np.int64)
        else:
            stamps = first_ns + period_ns * np.arange(count, dtype=np.int64)
        times_s = (stamps - origin_ns) * 1e-9
        zmp = zmp_reference.sample(*knots, times_s)
        heights = None if plan is None else self._plane_heights(times_s, origin_ns, plan)
        if 0 <= shift < count:
            reference = last[2].followed_by(shift, stamps, zmp, heights)
        else:
            reference = ZmpReference(stamps, zmp, heights)
        self._last_zmp_reference = (key, first_ns, reference)
        return reference

    def _plane_heights(self, times_s: np.ndarray, origin_ns: int, plan: FootstepPlan
                       ) -> np.ndarray:
        """(N,) height of the lowest foot in contact at ``times_s`` [m] (the ZMP's plane).

        ``plan``: :meth:`footstep_plan` from the window's first sample on.
        """
        relative = times_s - (plan.start_ns - origin_ns) * 1e-9
        index = np.clip(np.searchsorted(plan.times_s, relative, side='right') - 1, 0,
                        len(plan.times_s) - 1)
        heights = plan.positions_in_world[index, :, 2]
        down = contact_schedule(plan, relative)
        return np.where(down, heights, np.inf).min(axis=1)

    def _events(self) -> list[tuple[float, np.ndarray, np.ndarray]]:
        events = []
        if self._before is not None:
            events.append(self._before)
        elif self._steps:
            first = self._steps[0]
            events.append((first.start_s, first.positions_start, first.yaws_start))
        else:
            state = self._state()
            events.append((state.time_s, state.positions, state.yaws))
        for step in self._steps:
            for slot in step.slots:
                lift = (slot.lift_off_s, events[-1][1], events[-1][2])
                if slot.lift_off_s > events[-1][0]:
                    events.append(lift)
                events.append((slot.touch_down_s, slot.positions_after, slot.yaws_after))
        return events

    def footstep_plan(self, now_s: float | None = None, origin_ns: int = 0) -> FootstepPlan:
        """The contract plan: one point per contact change.

        Args:
            now_s: Keep only what matters from ``now_s`` on: the plan starts at the last contact
                change at or before it (so a swing under way is included). None: everything.
            origin_ns: ROS time of the planner's 0 s [ns].
        """
        memo = self._memo()
        if 'events' not in memo:
            memo['events'] = self._events()
        events = memo['events']
        first = 0
        if now_s is not None:
            for k, (t_s, _, _) in enumerate(events):
                if t_s <= now_s:
                    first = k
        key = ('footstep_plan', first, origin_ns)
        if key not in memo:
            memo[key] = self._footstep_plan_from(events[first:], origin_ns)
        return memo[key]

    def _footstep_plan_from(self, events: list, origin_ns: int) -> FootstepPlan:
        start_s = events[0][0]
        start_ns = origin_ns + int(round(start_s * NS_PER_S))
        times = np.array([t for t, _, _ in events]) - start_s
        positions = np.array([self._with_heights(p) for _, p, _ in events])
        if self._airborne is not None:
            # A measured start with feet in the air: they are up there until the landing.
            heights, landed_s = self._airborne
            for k, (t_s, _, _) in enumerate(events):
                if t_s < landed_s - 1e-12:
                    positions[k, :, 2] += heights
        if self._kept_heights is not None:
            # A measured start's feet slightly off the ground: where they are until they step.
            heights, where = self._kept_heights
            unmoved = np.ones(len(heights), dtype=bool)
            for k, (_, xy, _) in enumerate(events):
                unmoved &= (xy == where).all(axis=1)
                positions[k, unmoved, 2] += heights[unmoved]
        yaws = wrap_angle(np.array([y for _, _, y in events]))
        return FootstepPlan(start_ns, self.layout.names, times, positions, yaws)


def _forward(pose: np.ndarray, offsets: np.ndarray, params: GaitParameters,
             twist: Twist2D) -> np.ndarray:
    """(F, 2) unit directions in which the footholds move when the body walks ``twist``."""
    motion = place(integrate_pose(pose, twist, params.cycle_s), offsets) - place(pose, offsets)
    return motion / np.maximum(np.linalg.norm(motion, axis=1), 1e-12)[:, None]


def _leads_left(twist: Twist2D) -> bool:
    if twist.vy_m_s != 0.0:
        return twist.vy_m_s > 0.0
    return twist.wz_rad_s >= 0.0


def contact_schedule(plan: FootstepPlan, times_s: np.ndarray) -> np.ndarray:
    """(N, F) booleans: foot ``f`` is on the ground at ``times_s[n]`` (from the plan start)."""
    times_s = np.asarray(times_s, dtype=float)
    down = np.ones((len(times_s), len(plan.foot_names)), dtype=bool)
    for swing in plan.swings():
        foot = plan.foot_names.index(swing.foot)
        down[(times_s > swing.lift_off_s) & (times_s < swing.touch_down_s), foot] = False
    return down


def plan_walk(robot: RobotDescription, params: GaitParameters | None,
              commands: Sequence[tuple[float, object]], duration_s: float,
              **planner_options) -> GaitPlanner:
    """Plan a whole walk offline (tests, benches, other nodes' checks).

    Args:
        robot: Robot description.
        params: Initial parameters (default for the robot).
        commands: ``(time_s, command)`` in time order, each a :class:`Twist2D` or a
            :class:`GaitParameters`, applied as the node applies them when they arrive.
        duration_s: Plan until this time [s].
        **planner_options: ``base_pose``, ``start_s`` of :class:`GaitPlanner`.

    Returns:
        The planner holding every step (nothing pruned).
    """
    planner = GaitPlanner(robot, params, **planner_options)
    for time_s, command in commands:
        planner.advance(time_s)
        if isinstance(command, Twist2D):
            planner.set_velocity(command, time_s)
        else:
            planner.set_parameters(command, time_s)
    planner.advance(duration_s)
    return planner
