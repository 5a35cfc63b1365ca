"""The static crawl's kinematics: the body placed, still while a foot swings.

In the static crawl (``gait: static_crawl``, thesis eq. (2) walked) the body stands still while
a foot swings, so the swing is the limb's alone: the value table's path at the time its own
joints need, with no body compensating the limb's mass; the body moves only with every foot
down, rest to rest. The whole-body IK still tracks the full-model COM, so the COM reference of
such a walk is the COM the robot has with its body where the plan puts it and the swinging foot
on its path: :meth:`StillBody.com` computes it, and the footstep planner makes the ZMP
reference its cart-table ZMP, which the COM controller turns back into that COM.

:class:`StillBody` wraps a :class:`gait_nodes.swing.timing.SwingTiming` (the swing's shape and
its placed path, the same the swing-leg policy publishes) and times, through the closed-form
limb IK of its family:

- a swing with the body still (:meth:`StillBody.step_s`: the swinging limb's joints along the
  placed path; the other limbs do not move);
- a body move with every foot down (:meth:`StillBody.transfer_s`: every limb's joints while the
  base runs along the segment in a minimum-jerk time law);
- and, for the rhythm of steady walking (:mod:`gait_nodes.planning.rhythm`), the same where
  the steady walk puts the feet (:meth:`StillBody.swing_s`, :meth:`StillBody.steady_transfer_s`,
  :meth:`StillBody.steady_shifts`): each swing centred off its stance place by the path's
  advance between the step's swing slots (the fore foot, swung a swing later than the hind
  one, lands that much further ahead), the body moving with one side's feet half a stride
  ahead of the other's. Times ``1 + STILL_MARGIN`` for what the model leaves out (the body's
  place over the support triangles; the planner probes every planned step where it happens
  and re-times one timed short).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import weakref
from pathlib import Path

import numpy as np

from gait_nodes.errors import SwingPolicyError
from gait_nodes.planning.layout import FootLayout
from gait_nodes.robot.model import yaw_rotation
from gait_nodes.swing.cache import node_times_path, read_node_times, write_node_times
from gait_nodes.swing.timing import (
    LATTICE,
    TRANSFER_PROBE_SAMPLES,
    joint_path_time_s,
    lattice_interpolated,
)

#: The gait this module times (its stance: ``gait_stances`` in the robot YAML, if given).
GAIT = 'static_crawl'
#: Relative extra time of the steady rhythm's swings and body moves over their probe where the
#: steady walk puts the feet (the planner re-times a planned step that needs more).
STILL_MARGIN = 0.015
#: Spacing [m] of the lattice of foot shifts (a swing's centre off its stance place; the path's
#: advance between swing slots) the steady rhythm's times are interpolated on.
SHIFT_LATTICE_M = 0.01
#: Relative extra time of a probed swing for the whole-body IK's tracking: it holds the full-model
#: COM on the preview controller's COM, which is off the planned one by a millimetre or two, so
#: the body is not quite still under the swing. Measured on RoboSimian's static crawl (0.06 m
#: lift, 0.1 s smoothing): a rear swing planned 1.4 % above its probe made the IK ask 1.0012
#: times the joint limit; 2 % keeps it under. With the ZMP reference sampled finer (the
#: planner's STILL_SAMPLE_S 0.01 s: the body moves under a swing at half the speed it did), 1 %
#: walked the 40 s main job 0.0361 m/s steady instead of 0.0358, but the IK slowed 8 knots at a
#: 0.5 rad/s limit.
TRACKING_MARGIN = 0.02
#: Samples of a probed swing: the smoothed table swing changes speed within 0.05 s; 121 samples
#: over a 1.5 s swing find its joints' peak speed to 0.1 % (61 samples: 0.6 % short).
STILL_PROBE_SAMPLES = 121
#: Gravity [m/s^2] of the cart-table ZMP.
GRAVITY_M_S2 = 9.81
#: Share of a body move spent speeding up (and as much slowing down): the base's speed rises
#: along a half cosine, cruises, and falls the same way (:func:`body_move`). Its speed peaks
#: ``1 / (1 - RAMP_FRACTION)`` times above the mean, where a minimum-jerk move's peaks 1.875
#: times: the move needs that much less time at the joint limit. Shorter ramps need less time
#: at the velocity limit (RoboSimian's steady 0.13 m move: 0.75 s at 0.25, 0.70 s at 0.2) but
#: jerk the ZMP reference more, and the preview controller starts the COM earlier before each
#: move: at 0.2 the body moves at most 2.4 mm under a swing of the default scenario (2.0 mm
#: after the start; 1.5 mm in the gait switch's static crawl), at 0.15 4.4 mm (session 21).
RAMP_FRACTION = 0.2
#: Peak speed over mean speed of :func:`body_move`.
BODY_MOVE_PEAK_FACTOR = 1.0 / (1.0 - RAMP_FRACTION)
#: Peak acceleration of :func:`body_move` over a unit move in unit time.
BODY_MOVE_PEAK_ACCELERATION = math.pi / (2.0 * RAMP_FRACTION * (1.0 - RAMP_FRACTION))


class StillBody:
    """Swing and body-move times, and the full-model COM, with the base placed.

    Args:
        timing: The swing timing model (closed-form limb IK: ``timing.family`` not None) whose
            swing shapes are timed.
    """

    def __init__(self, timing):
        if timing.timing is None:
            raise SwingPolicyError(f'{timing.robot.name} has no closed-form limb IK: the body '
                                   f'cannot be held still under a swing (gait: static_crawl)')
        self.source = timing
        self.robot = timing.robot
        self.family = timing.family
        self.ik = timing.timing.ik
        self.name = f'{timing.name}, body still'
        self._data = self.robot.new_data()
        self._limbs = [(foot.name, self.robot.indices(foot.joints))
                       for foot in self.robot.description.feet]
        #: Lattice node and the swing's centre offset -> least swing time at the node [s].
        self._swing_s: dict[tuple, float] = {}
        self._transfer_s: dict[tuple[int, int, int, int], float] = {}
        self._q_posture = self.robot.joint_positions(
            self.robot.configuration(np.zeros(3), 0.0))
        height = float(self.robot.description.body_height_m)
        self._base = np.array([0.0, 0.0, height])
        # The static crawl's stance (the robot's own for the gait, if it gives one).
        stance = self.robot.description.nominal_stance_in_base(GAIT)
        self._feet = self.robot.nominal_feet_in_world(self._base, 0.0, GAIT)
        # Each foot swings around its own place in that stance: its offset from the place the
        # swing shape is centred on (the front-right limb's nominal one), in that limb's
        # (mirrored) coordinates (a stance need not be a rectangle).
        centre = self.robot.description.feet[timing._reference].nominal_position_in_base[:2]
        self._offsets = [tuple(np.round(stance[k, :2] * mirror - centre, 6).tolist())
                         for k, mirror in enumerate(timing._mirror_floats)]
        #: The gait's steps, each its swing slots in order (the hind foot, then the fore one).
        self._groups = FootLayout.of(self.robot.description).swing_groups(GAIT)
        self._stored = node_times_path(timing, 'still')
        self._found_stored = False
        self._load_stored()

    @property
    def stored(self) -> bool:
        """Whether node times were found on disk for this model (see the module docstring)."""
        return self._found_stored

    @property
    def factor(self) -> float:
        """The wrapped model's factor on every time (> 1 for a stand-in)."""
        return self.source.factor

    # --- kinematics ----------------------------------------------------------------------------

    def joints(self, base_in_world: np.ndarray, body_yaw_rad: float, feet_in_world: np.ndarray,
               foot_yaws_rad: np.ndarray, limbs=None) -> np.ndarray:
        """(N, J) joint vectors with the base at ``base_in_world`` (N, 3) and the feet placed.

        ``feet_in_world`` (N, F, 3) and ``foot_yaws_rad`` (N, F); ``limbs``: the feet whose
        limbs are solved (default all; the others keep the posture).

        Raises:
            SwingPolicyError: A foot out of the reach of its limb in the model's family.
        """
        base = np.asarray(base_in_world, dtype=float)
        feet = np.asarray(feet_in_world, dtype=float)
        yaws = np.asarray(foot_yaws_rad, dtype=float)
        rotation = yaw_rotation(body_yaw_rad)
        joints = np.repeat(self._q_posture[None], len(base), axis=0)
        solved = list(range(len(self._limbs)) if limbs is None else limbs)
        if not solved:
            return joints
        in_base = (feet[:, solved] - base[:, None]) @ rotation
        angles, feasible = self.ik.solve_feet(in_base, yaws[:, solved] - body_yaw_rad,
                                              self.family,
                                              [self._limbs[f][0] for f in solved])
        for k, f in enumerate(solved):
            name, index = self._limbs[f]
            if not feasible[:, k].all():
                where = np.round(feet[int(np.argmin(feasible[:, k])), f], 3).tolist()
                raise SwingPolicyError(f'the {name} foot at {where} leaves the reach of its limb '
                                       f'(IK family {self.family}) with the body still at '
                                       f'{np.round(base[0], 3).tolist()}')
            joints[:, index] = angles[:, k]
        return joints

    def com(self, base_in_world: np.ndarray, body_yaw_rad: float, feet_in_world: np.ndarray,
            foot_yaws_rad: np.ndarray) -> np.ndarray:
        """(N, 3) full-model COM with the base at ``base_in_world`` (N, 3), the feet placed."""
        import pinocchio as pin

        joints = self.joints(base_in_world, body_yaw_rad, feet_in_world, foot_yaws_rad)
        coms = np.empty((len(joints), 3))
        for k, (base, values) in enumerate(zip(np.asarray(base_in_world, dtype=float), joints,
                                               strict=True)):
            q = self.robot.configuration(base, body_yaw_rad, values)
            coms[k] = pin.centerOfMass(self.robot.model, self._data, q)
        return coms

    def multibody_zmp(self, dt_s: float, base_in_world: np.ndarray, body_yaw_rad: float,
                      feet_in_world: np.ndarray, foot_yaws_rad: np.ndarray) -> np.ndarray:
        """(N, 2) ZMP of the full model's motion sampled every ``dt_s``, at rest at both ends.

        The bases (N, 3) and feet (N, F, 3) and yaws (N, F) placed as :meth:`com` takes them;
        the ZMP from the rate of change of the whole model's momentum
        (:func:`gait_nodes.robot.dynamics.multibody_zmp_trajectory`, as the ZMP monitor
        computes it): the swinging limb's angular momentum included, which the cart-table ZMP
        of the COM leaves out.
        """
        from gait_nodes.robot.dynamics import multibody_zmp_trajectory

        base = np.asarray(base_in_world, dtype=float)
        joints = self.joints(base, body_yaw_rad, feet_in_world, foot_yaws_rad)
        configurations = np.array([self.robot.configuration(b, body_yaw_rad, values)
                                   for b, values in zip(base, joints, strict=True)])
        zmp, _ = multibody_zmp_trajectory(self.robot, configurations, dt_s)
        return zmp

    def base_for_com(self, com_xy: np.ndarray, base_z_m: float, body_yaw_rad: float,
                     feet_in_world: np.ndarray, foot_yaws_rad: np.ndarray) -> np.ndarray:
        """(3,) base position whose full-model COM is over ``com_xy``, the feet where they stand.

        A few secant steps (the COM moves with the base less than one for one: the feet stay;
        how much less depends on the stance, so each step takes the ratio the last one met).
        """
        target = np.asarray(com_xy, dtype=float)[:2]
        feet = np.asarray(feet_in_world, dtype=float)[None]
        yaws = np.asarray(foot_yaws_rad, dtype=float)[None]
        base = np.array([*target, base_z_m])
        base[:2] += self._base[:2] - self.com(self._base[None], 0.0, self._feet[None],
                                              np.zeros((1, len(self._feet))))[0, :2]
        gain = 1.4  # the base moves ~1.4 m per metre of COM at RoboSimian's first stance
        previous = None
        for _ in range(12):
            com = self.com(base[None], body_yaw_rad, feet, yaws)[0, :2]
            error = target - com
            if float(np.hypot(*error)) < 1e-7:
                break
            if previous is not None:
                moved_com = com - previous[1]
                if float(moved_com @ moved_com) > 1e-18:
                    gain = float((base[:2] - previous[0]) @ moved_com / (moved_com @ moved_com))
            previous = (base[:2].copy(), com)
            base[:2] += gain * error
        return base

    # --- planned steps -------------------------------------------------------------------------

    def step_s(self, swings: dict, feet_in_world: np.ndarray, foot_yaws_rad: np.ndarray,
               body_yaw_rad: float, base_in_world: np.ndarray,
               with_acceleration: bool = False) -> float:
        """Least time [s] of planned swings made together, the body still at ``base_in_world``.

        The swinging limbs' joints on :data:`STILL_PROBE_SAMPLES` samples (with
        ``with_acceleration``, on the swings' own samples
        :data:`gait_nodes.swing.timing.ACCELERATION_PROBE_PERIOD_S` apart), times
        ``1 + TRACKING_MARGIN`` (the IK's COM tracking moves the body a little).

        Args:
            swings: Foot index -> its planned swing (world places and yaws; times unused).
            feet_in_world: (F, 3) contact points of all feet before the swings.
            foot_yaws_rad: (F,) their yaws [rad].
            body_yaw_rad: Body yaw [rad].
            base_in_world: (3,) the base's position [m].
            with_acceleration: Long enough for the joints' acceleration limits too.
        """
        u = None if with_acceleration else np.linspace(0.0, 1.0, STILL_PROBE_SAMPLES)
        u, feet, yaws = self.source.swing_feet(swings, feet_in_world, foot_yaws_rad,
                                               body_yaw_rad, u, fine=with_acceleration)
        base = np.repeat(np.asarray(base_in_world, dtype=float)[None], len(u), axis=0)
        joints = self.joints(base, body_yaw_rad, feet, yaws, limbs=list(swings))
        return (1.0 + TRACKING_MARGIN) * self.factor * joint_path_time_s(
            self.robot, u, joints, 'path' if with_acceleration else None)

    def transfer_s(self, feet_in_world: np.ndarray, foot_yaws_rad: np.ndarray,
                   body_yaw_rad: float, base_from: np.ndarray, base_to: np.ndarray,
                   with_acceleration: bool = False) -> float:
        """Least time [s] of the body's move from ``base_from`` to ``base_to``, feet down.

        Every limb's joints follow the base along the segment in the time law of
        :func:`body_move` (its speed peaks :data:`BODY_MOVE_PEAK_FACTOR` times above the
        mean).
        """
        u = np.linspace(0.0, 1.0, TRANSFER_PROBE_SAMPLES)
        base_from, base_to = np.asarray(base_from, dtype=float), np.asarray(base_to, dtype=float)
        if np.linalg.norm(base_to - base_from) < 1e-9:
            return 0.0
        base = base_from + u[:, None] * (base_to - base_from)
        feet = np.repeat(np.asarray(feet_in_world, dtype=float)[None], len(u), axis=0)
        yaws = np.repeat(np.asarray(foot_yaws_rad, dtype=float)[None], len(u), axis=0)
        joints = self.joints(base, body_yaw_rad, feet, yaws)
        return self.factor * joint_path_time_s(
            self.robot, u, joints, BODY_MOVE_PEAK_ACCELERATION if with_acceleration else None,
            BODY_MOVE_PEAK_FACTOR)

    # --- the steady rhythm (gait_nodes.planning.rhythm) ----------------------------------------

    def steady_shifts(self, lag_in_base) -> np.ndarray:
        """(F, 2) each foot's swing centre off its stance place in steady walking [m].

        The footholds are placed on the path at their touch-downs, so a step's later swing slot
        lands the path's advance between the slots (``lag_in_base``, body frame) further along
        than the earlier one: the slots' centres are spread around the stance place by it
        (hind -lag/2, fore +lag/2 in a static crawl's step of two slots).
        """
        lag = np.asarray(lag_in_base, dtype=float)[:2]
        shifts = np.zeros((len(self._limbs), 2))
        for group in self._groups:
            for j, slot in enumerate(group):
                for foot in slot:
                    shifts[foot] = (j - 0.5 * (len(group) - 1)) * lag
        return shifts

    def swing_s(self, foot: int, step_in_base: np.ndarray, turn_rad: float = 0.0,
                shift_in_base=(0.0, 0.0)) -> float:
        """Least time [s] of foot ``foot``'s swing by ``step_in_base``, centred off its place.

        ``shift_in_base``: the swing's centre off the foot's stance place, body frame [m]
        (:meth:`steady_shifts`).

        The front-right limb's mirrored step, its shape (:meth:`SwingTiming.shape`) timed
        through its own limb IK, times ``1 + STILL_MARGIN`` and ``1 + TRACKING_MARGIN`` (what a
        probe of the planned swing counts); interpolated between the nodes of
        :data:`LATTICE` and of :data:`SHIFT_LATTICE_M` (each timed once): continuous in the
        step and the shift, so that the rhythm's search of the fastest velocity meets no steps,
        and a handful of limb IK runs serve it.
        """
        mirror = self.source._mirror_floats[foot]
        point = (float(step_in_base[0]) * mirror[0], float(step_in_base[1]) * mirror[1],
                 mirror[0] * mirror[1] * float(turn_rad))
        shift = (float(shift_in_base[0]) * mirror[0], float(shift_in_base[1]) * mirror[1])
        return (1.0 + STILL_MARGIN) * (1.0 + TRACKING_MARGIN) * self.factor * _multilinear(
            shift, (SHIFT_LATTICE_M,) * 2, lambda shift_node: lattice_interpolated(
                point, lambda node: self._node_swing_s(node, foot, shift_node)))

    def _node_swing_s(self, node: tuple[int, int, int], foot: int,
                      shift_node: tuple[int, int] = (0, 0)) -> float:
        """Least swing time [s] of foot ``foot`` at lattice node ``node``, shifted.

        Its centre is off the foot's stance place by the shift lattice's node ``shift_node``
        (in the limb's mirrored frame).
        """
        offset = tuple(round(value + SHIFT_LATTICE_M * k, 6)
                       for value, k in zip(self._offsets[foot], shift_node, strict=True))
        key = (*node, *offset)  # mirrored feet (the same offset) share their times
        if key not in self._swing_s:
            if len(self._swing_s) > 4096:
                self._swing_s.clear()
            step = np.array(node, dtype=float) * LATTICE
            u, states = self.source.shape(step[:2], float(step[2]), fine=True,
                                          foot=self.robot.description.feet[foot].name)
            states[:, :2] += offset
            q, feasible = self.source.timing.joints(states)
            if not feasible.all():
                raise SwingPolicyError(f'a swing by {np.round(step[:2], 3).tolist()} m leaves the '
                                       f'reach of the limb (IK family {self.family})')
            reference = self._limbs[self.source._reference][1][:q.shape[1]]
            self._swing_s[key] = joint_path_time_s(_Limb(self.robot, reference), u, q, 'path')
            self._store()
        return self._swing_s[key]

    def lift_and_lower_s(self) -> float:
        """Swing time [s] of a step in place (the lift and the lowering)."""
        return self.swing_s(self.source._reference, np.zeros(2), 0.0)

    def steady_transfer_s(self, move_in_base: np.ndarray, lag_in_base=(0.0, 0.0)) -> float:
        """Body-move time [s] of a steady walk whose body moves ``move_in_base`` (2,).

        The feet stand where the steady walk has them when the body moves: each at its swing's
        centre (:meth:`steady_shifts` of ``lag_in_base``, the path's advance between a step's
        swing slots), the side that has just swung half a move ahead of it and the other side
        half a move behind (it swung half a cycle earlier); the base moves from half a move
        behind the stance's centre to half a move ahead. :meth:`transfer_s` of the slower of the
        two steps, times ``1 + STILL_MARGIN``; interpolated between the nodes of ``LATTICE`` (the
        move) and :data:`SHIFT_LATTICE_M` (the lag), each timed once.
        """
        point = (float(move_in_base[0]), float(move_in_base[1]), float(lag_in_base[0]),
                 float(lag_in_base[1]))
        return (1.0 + STILL_MARGIN) * _multilinear(
            point, (*LATTICE[:2], SHIFT_LATTICE_M, SHIFT_LATTICE_M), self._node_transfer_s)

    def _node_transfer_s(self, node: tuple[int, int, int, int]) -> float:
        """Body-move time [s] at a node of :meth:`steady_transfer_s`'s lattice.

        ``node``: the move's x and y on ``LATTICE``, the lag's on :data:`SHIFT_LATTICE_M`.
        """
        if node not in self._transfer_s:
            move = np.array([node[0] * LATTICE[0], node[1] * LATTICE[1], 0.0])
            lag = np.array([node[2], node[3]], dtype=float) * SHIFT_LATTICE_M
            centres = self._feet.copy()
            centres[:, :2] += self.steady_shifts(lag)
            times = []
            for group in self._groups:
                swung = np.zeros(len(centres), dtype=bool)
                swung[[foot for slot in group for foot in slot]] = True
                feet = centres + np.where(swung[:, None], 0.5, -0.5) * move
                times.append(self.transfer_s(feet, np.zeros(len(feet)), 0.0,
                                             self._base - 0.5 * move, self._base + 0.5 * move,
                                             True))
            self._transfer_s[node] = max(times)
            self._store()
        return self._transfer_s[node]

    # --- the node times on disk ----------------------------------------------------------------

    def _load_stored(self) -> None:
        """Take the node times stored for this robot, model and code, if there are any."""
        stored = read_node_times(self._stored, ('swing_s', 'transfer_s'))
        if stored is None:
            return
        self._swing_s.update(stored['swing_s'])
        self._transfer_s.update(stored['transfer_s'])
        self._found_stored = bool(stored['swing_s'])

    def _store(self) -> None:
        """Write the node times (see :func:`gait_nodes.swing.cache.write_node_times`)."""
        write_node_times(self._stored, {'swing_s': self._swing_s,
                                        'transfer_s': self._transfer_s})


def _multilinear(point, spacing, node_value) -> float:
    """Multilinear interpolation of ``node_value`` at ``point`` on a lattice of ``spacing``.

    ``node_value`` takes a node's integer key. The corners with a zero weight are never asked
    (a straight walk has no sideways shift).
    """
    scaled = [value / step for value, step in zip(point, spacing, strict=True)]
    low = [math.floor(value) for value in scaled]
    weights = [((0, 1.0 - (value - corner)), (1, value - corner))
               for value, corner in zip(scaled, low, strict=True)]
    total = 0.0
    for corner in itertools.product(*weights):
        weight = math.prod(w for _, w in corner)
        if weight != 0.0:
            total += weight * node_value(tuple(base + k for base, (k, _) in
                                               zip(low, corner, strict=True)))
    return total


class _Limb:
    """The velocity and acceleration limits of one limb's joints (for joint_path_time_s)."""

    def __init__(self, robot, index: np.ndarray):
        self.velocity_limits_rad_s = np.asarray(robot.velocity_limits_rad_s)[index]
        self.acceleration_limits_rad_s2 = np.asarray(robot.acceleration_limits_rad_s2)[index]


def cart_table_zmp(times_s: np.ndarray, com: np.ndarray, height_m: float) -> np.ndarray:
    """(N, 2) cart-table ZMP ``c - (h / g) c''`` of a COM path sampled at ``times_s`` (N,).

    ``c''`` by second differences on the samples' own times (the ends held at rest: the path
    starts and ends still).
    """
    com = np.asarray(com, dtype=float)[:, :2]
    t = np.asarray(times_s, dtype=float)
    acceleration = np.zeros_like(com)
    if len(t) > 2:
        h0, h1 = np.diff(t)[:-1, None], np.diff(t)[1:, None]
        acceleration[1:-1] = 2.0 * ((com[2:] - com[1:-1]) / h1 - (com[1:-1] - com[:-2]) / h0) \
            / (h0 + h1)
    return com - height_m / GRAVITY_M_S2 * acceleration


def body_move(u: np.ndarray) -> np.ndarray:
    """Fraction of a rest-to-rest body move done at ``u`` (0 to 1) of its time.

    The speed rises along a half cosine over :data:`RAMP_FRACTION` of the time, cruises, and
    falls symmetrically: position, speed and acceleration are continuous (the acceleration
    starts and ends at zero), so the cart-table ZMP has no jump.
    """
    u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
    f, peak = RAMP_FRACTION, BODY_MOVE_PEAK_FACTOR

    def ramp(x):
        return peak * (0.5 * x - f / (2.0 * math.pi) * np.sin(math.pi * x / f))

    return np.where(u < f, ramp(u), np.where(u > 1.0 - f, 1.0 - ramp(1.0 - u),
                                             peak * (0.5 * f + (u - f))))




_VIEWS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


#: Most step probes kept on disk for one swing timing model (:func:`keep_probes`; the oldest
#: go first). A first walk of 20 s keeps about 20.
MAX_KEPT_PROBES = 400


def _kept_probes_path(timing) -> Path | None:
    times = node_times_path(timing, 'still')
    return None if times is None else times.with_name(f'probes_{times.name}')


def kept_probes(timing) -> dict[str, object]:
    """The step probes kept on disk for ``timing``'s plans ({}: none, or an unreadable file).

    See :meth:`gait_nodes.planning.footsteps.GaitPlanner.take_probes`; the file is named, like
    the node times', by what the probes follow from (the package's source among it).
    """
    path = _kept_probes_path(timing)
    if path is None:
        return {}
    try:
        probes = json.loads(path.read_text())['probes']
    except (OSError, ValueError, TypeError, KeyError):
        return {}
    return probes if isinstance(probes, dict) else {}


def keep_probes(timing, probes: dict[str, object]) -> None:
    """Add ``probes`` (:meth:`GaitPlanner.probes_to_keep`) to those kept for ``timing``."""
    path = _kept_probes_path(timing)
    if path is None:
        return
    kept = kept_probes(timing)
    if probes.keys() <= kept.keys():
        return
    kept.update(probes)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f'{path.name}.{os.getpid()}.tmp')
        partial.write_text(json.dumps({'probes': dict(list(kept.items())[-MAX_KEPT_PROBES:])}))
        os.replace(partial, path)
    except OSError:
        pass  # a read-only cache: probed again next time


def still_body_of(timing) -> StillBody:
    """The (cached) :class:`StillBody` view of a swing timing model."""
    view = _VIEWS.get(timing)
    if view is None:
        view = _VIEWS[timing] = StillBody(timing)
    return view
