"""The gait's rhythm from the joint velocity limit (``timing: joint_limit``).

Thesis 000, eq. (2): a crawl cycle is four swings one after the other plus the body's move, which
takes as long as the horizontal part of a swing (``T_swing - T_up - T_down``):

    speed = step / (4 T_swing + (T_swing - T_up - T_down)).

Here every step of a gait (see :mod:`gait_nodes.planning.gait_params`) is a transfer phase (all
feet down, the ZMP moves) followed by its swing slots, two steps a cycle, so each transfer gets
half of the thesis' body move (at least :data:`MIN_TRANSFER_S`, for the sideways sway the
ZMP makes even in place) and each swing lasts what a :class:`gait_nodes.swing.timing.
SwingTiming` says the swing needs at the limit; ``T_body`` is the time the stance limbs need at
the limit to move the body half its cycle displacement (``SwingTiming.steady_transfer_s``):

    T_transfer = max(MIN_TRANSFER_S, (T_swing - T_up - T_down) / 2, T_body),
    step period = T_transfer + slots T_swing,   cycle T = 2 step period,
    duty factor = 1 - T_swing / T.

The commanded velocity sets the stride, the stride sets the swing time and the swing time the
cycle: in steady walking a foot moves the body's displacement over one cycle, so the rhythm is
the fixed point of ``T -> cycle(swing time(displacement in T))``, found by iteration (the swing
time grows more slowly than the stride it covers, so the map contracts at any speed the
robot can walk).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gait_nodes.errors import GaitParameterError
from gait_nodes.planning.gait_params import STEPS_PER_CYCLE, SWING_SLOTS, GaitParameters
from gait_nodes.planning.layout import FootLayout

#: Shortest transfer phase [s]: the ZMP crosses between the support regions of the two sides.
MIN_TRANSFER_S = 0.3
#: The fixed point is found when the cycle changes by less than this [s].
CYCLE_TOLERANCE_S = 1e-6
#: Decimals of the stride [m], swing and transfer [s] a crawl's sway is constructed for.
SWAY_ROUNDING = (3, 2, 2)
#: The body's move is timed again until its time changes by less than this [s].
BODY_MOVE_TOLERANCE_S = 1e-3
#: Longest cycle [s] before a rhythm is declared infeasible.
MAX_CYCLE_S = 2.0 * 60.0
MAX_ITERATIONS = 500


@dataclass(frozen=True)
class Rhythm:
    """Timing of one gait at one velocity.

    Attributes:
        swing_s: Each swing [s].
        transfer_s: Each transfer (all-feet-down) phase [s].
        slots: Swing slots per step.
        source: What the swing times come from.
    """

    swing_s: float
    transfer_s: float
    slots: int
    source: str

    @property
    def step_period_s(self) -> float:
        """One step: the transfer and the swing slots [s]."""
        return self.transfer_s + self.slots * self.swing_s

    @property
    def cycle_s(self) -> float:
        """The gait cycle [s]."""
        return STEPS_PER_CYCLE * self.step_period_s

    @property
    def duty_factor(self) -> float:
        """Stance fraction of the cycle."""
        return 1.0 - self.swing_s / self.cycle_s

    def apply(self, params: GaitParameters) -> GaitParameters:
        """``params`` with this rhythm's step period and duty factor."""
        return params.replace(step_period_s=self.step_period_s, duty_factor=self.duty_factor)


def rhythm_for_swing(gait: str, swing_s: float, in_place_s: float, source: str,
                     body_move_s: float = 0.0) -> Rhythm:
    """The rhythm of ``gait`` whose swings last ``swing_s`` (eq. (2)'s body move per transfer).

    Args:
        gait: Resolved gait.
        swing_s: Swing time [s].
        in_place_s: Swing time of a step in place (lift and lowering) [s].
        source: What the swing times come from.
        body_move_s: Least transfer time for the body's move at the joint limit [s].
    """
    if gait == 'static_crawl':  # the body's move is timed as it is walked, not modelled
        return Rhythm(float(swing_s), float(max(MIN_TRANSFER_S, body_move_s)),
                      SWING_SLOTS[gait], source)
    transfer = max(MIN_TRANSFER_S, 0.5 * (swing_s - in_place_s), body_move_s)
    return Rhythm(float(swing_s), float(transfer), SWING_SLOTS[gait], source)


def _rotate(vectors: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return vectors @ np.array([[c, -s], [s, c]]).T


def cycle_displacements(layout: FootLayout, params: GaitParameters, twist, cycle_s: float,
                        gait: str | None = None) -> tuple[np.ndarray, float]:
    """(F, 2) displacement of each foot over one cycle in the body frame [m], and the turn.

    Steady walking: a foot moves, per swing, what the body moves in one cycle (the footholds
    follow the body's path); the displacement is expressed in the body frame half-way through
    the turn (the frame the swing happens in).
    """
    from gait_nodes.planning.footsteps import integrate_pose, place

    offsets = layout.offsets(params.step_width_m, gait)
    pose = integrate_pose(np.zeros(3), twist, cycle_s)
    moved = place(pose, offsets) - offsets
    return _rotate(moved, -0.5 * pose[2]), float(pose[2])


def swing_time_s(timing, displacements: np.ndarray, turn_rad: float,
                 feet: range | list[int] | None = None, combine=max,
                 shifts: np.ndarray | None = None) -> float:
    """Longest (or ``combine``'s) least swing time [s] over ``feet`` (default all).

    ``shifts``: (F, 2) each swing's centre off its stance place [m] (a static crawl's,
    :meth:`gait_nodes.swing.still_body.StillBody.steady_shifts`).
    """
    feet = range(len(displacements)) if feet is None else feet
    times = [timing.swing_s(f, displacements[f], turn_rad) if shifts is None
             else timing.swing_s(f, displacements[f], turn_rad, shifts[f]) for f in feet]
    return float(combine(times)) if times else timing.lift_and_lower_s()


def steady_lag(displacements: np.ndarray, rhythm: Rhythm) -> np.ndarray:
    """(2,) the path's advance between a step's swing slots in steady walking [m], body frame.

    A foothold is placed on the path at its touch-down, so a step's later slot lands what the
    path moves in one swing further along (a static crawl's fore foot ahead of its hind one).
    """
    return np.asarray(displacements, dtype=float).mean(axis=0) * (rhythm.swing_s
                                                                 / rhythm.cycle_s)


def transfer_move(gait: str, layout: FootLayout, params: GaitParameters, twist,
                  rhythm: Rhythm, memo: dict | None = None) -> np.ndarray:
    """(2,) the COM's move in one transfer of steady walking at ``rhythm``, body frame [m].

    Half the body's cycle displacement (two transfers a cycle); a crawl's ZMP also sways
    between the diagonals (:func:`gait_nodes.planning.zmp_reference.steady_crawl_zmp_move`,
    for a straight crawl of the same stride, its stride and times rounded to
    :data:`SWAY_ROUNDING`, so that ``memo`` (a dict kept between calls) can keep it: the
    construction takes milliseconds and every new velocity command asks it often).
    """
    from gait_nodes.planning.zmp_reference import steady_crawl_zmp_move

    move = 0.5 * rhythm.cycle_s * np.array([twist.vx_m_s, twist.vy_m_s])
    if gait != 'crawl':
        return move
    stride_m, swing_s, transfer_s = (round(value, digits) for value, digits in zip(
        (2.0 * float(np.hypot(*move)), rhythm.swing_s, rhythm.transfer_s), SWAY_ROUNDING,
        strict=True))
    key = (params, stride_m, swing_s, transfer_s)
    memo = {} if memo is None else memo
    if key not in memo:
        if len(memo) > 4096:
            memo.clear()
        steady = Rhythm(swing_s, transfer_s, rhythm.slots, rhythm.source).apply(params)
        memo[key] = steady_crawl_zmp_move(layout, steady, stride_m)
    return memo[key]


def walking_rhythm(gait: str, layout: FootLayout, params: GaitParameters, twist,
                   timing, memo: dict | None = None) -> Rhythm:
    """The steady rhythm of ``gait`` at ``twist`` (the fixed point, see the module docstring).

    ``memo``: kept between calls for :func:`transfer_move`.

    Raises:
        GaitParameterError: No rhythm exists (the cycle grows without bound: a velocity the
            joints cannot reach at any stride), or a swing leaves the reach of the limb IK.
    """
    from gait_nodes.errors import SwingPolicyError

    in_place = timing.lift_and_lower_s()
    rhythm = rhythm_for_swing(gait, in_place, in_place, timing.name)
    # The body's move is timed at each fixed point of the swings (a crawl's sway costs a
    # milliseconds-long geometric construction), then the swings' fixed point is found again
    # with it, until it no longer changes.
    body_move_s = 0.0
    for _ in range(MAX_ITERATIONS):
        displacements, turn = cycle_displacements(layout, params, twist, rhythm.cycle_s, gait)
        try:
            if gait == 'static_crawl':
                # Its swings each take their own time (the planner shares a step's period
                # among them): its cycle holds their mean. Each is timed, and the body's move,
                # where the steady walk has the feet (a stride's stagger, the slots' lag).
                lag = steady_lag(displacements, rhythm)
                swing_s = swing_time_s(timing, displacements, turn, combine=np.mean,
                                       shifts=timing.steady_shifts(lag))
            else:
                lag = None
                swing_s = swing_time_s(timing, displacements, turn)
            following = rhythm_for_swing(gait, swing_s, in_place, timing.name, body_move_s)
            if abs(following.cycle_s - rhythm.cycle_s) < CYCLE_TOLERANCE_S:
                move = transfer_move(gait, layout, params, twist, following, memo)
                needed = (timing.steady_transfer_s(move) if lag is None
                          else timing.steady_transfer_s(move, lag))
                if abs(needed - body_move_s) < BODY_MOVE_TOLERANCE_S:
                    return following
                body_move_s = needed
                following = rhythm_for_swing(gait, swing_s, in_place, timing.name, needed)
        except SwingPolicyError as exc:
            raise GaitParameterError(f'no gait rhythm walks {twist.as_tuple()}: {exc}') from None
        if following.cycle_s > MAX_CYCLE_S:
            break
        rhythm = following
    raise GaitParameterError(f'no gait rhythm reaches the velocity {twist.as_tuple()} within '
                             f'the joint velocity limit ({timing.name})')
