"""How long a swing must last at the joint velocity limit, and smooth swings to publish.

Thesis 000, eq. (2): the speed of a crawl follows from the swing time the joint velocity limit
allows, ``speed = step / (4 T_swing + (T_swing - T_up - T_down))``. The footstep planner times
its gait with a :class:`SwingTiming` (the least swing time for a foot displacement) so that the
swing-leg policy never has to compress a swing and the joints stay within their limit because
the plan is feasible, not because a limiter clips it.

Two models, both for robots with closed-form limb IK (``extra.limb_ik``, thesis II.C):

* :class:`TableSwingTiming`: the value table's greedy swing (thesis Appendix A) for the step,
  smoothed as below;
* :class:`PolynomialSwingTiming`: the sixth-order swing (Lucy) between the lift-off and landing
  places around the nominal foot position.

Either swing is timed through the whole-body IK, not the limb alone: while a limb (15 % of
RoboSimian's mass) swings, the body moves the other way so that the full-model COM stays on
its reference (thesis III.B.1), which changes the swinging limb's joint speeds. The time is
the least one at which no joint of any limb exceeds its limit, times
``1 + BODY_MOTION_MARGIN`` for what the probe at the nominal stance does not see: the crawl's
sideways sway puts the body off the nominal stance during a swing, the other feet are a part of
a stride off theirs, and the COM keeps walking. The planner probes every planned step where it
happens and retimes a step the model timed short (:mod:`gait_nodes.planning.footsteps`).

The value table's path is a polyline timed with the fastest joint at the limit on every segment:
its velocity jumps at every waypoint, and a foot that changes velocity in one tick makes the
multi-body ZMP jump by metres. :func:`smooth_trajectory` filters it with a triangular kernel of
``SMOOTHING_S``: positions become averages of the polyline's (so the foot never goes below the
ground, never slides on it while the kernel is shorter than the lift, and never leaves the
polyline's convex hull), the velocity is an average of the polyline's velocities (so the
joint speeds stay within the limit to first order: the max-norm ball is convex), and the
acceleration is bounded; the swing lasts ``SMOOTHING_S`` longer. 0.12 s: the foot's speed
changes over 0.12 s at a corner of the path, where the joints' 20 rad/s^2 turn 1 rad/s round in
0.05 s. Narrower, RoboSimian's swings are held back by the acceleration limit more than they
gain (at its 0.77 m stance a 0.2 m stride swing needs 1.365 s at 0.1 s, 1.299 s at 0.12 s,
1.330 s at 0.15 s); wider, by the time the filter adds.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable

import numpy as np

from gait_nodes.contract import Swing, SwingTrajectory
from gait_nodes.errors import SwingPolicyError

#: Relative extra time of a swing probed where it happens (:meth:`SwingTiming.step_s`): the COM
#: drifts a little while the ZMP reference holds still.
STEP_MARGIN = 0.05
#: Samples of a probed planned swing.
STEP_PROBE_SAMPLES = 61
#: Width of the triangular smoothing kernel of value-table swings [s].
SMOOTHING_S = 0.12
#: Fine time step of the smoothing convolution [s].
FINE_STEP_S = 0.001
#: Relative extra swing time for the sway and walk of the body during the swing. Measured on
#: RoboSimian's crawl at its fastest stride (0.22 m, value-table and polynomial swings alike):
#: the planner's probe of each swing where it happens (the COM on the ZMP reference, 0.035 m to
#: the side, the other feet in the crawl's pattern) needs 1.36 times the time probed at the
#: nominal stance; 0.4 leaves 3 %, so that steady steps are not retimed.
BODY_MOTION_MARGIN = 0.4
#: Samples of a probed transfer (the body's move with every foot down).
TRANSFER_PROBE_SAMPLES = 21
#: Peak over mean speed of the COM's move in a transfer (a minimum-jerk move's 15/8): the probe
#: moves it at constant speed.
TRANSFER_PEAK_FACTOR = 1.875
#: Peak acceleration of a minimum-jerk move of length 1 in time 1 (10 / sqrt(3)).
MIN_JERK_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)
#: Relative extra transfer time over the probe at the nominal stance (see steady_transfer_s).
#: Measured on RoboSimian's crawl at its fastest rhythm: the planner's probe of each transfer
#: (the feet staggered by the stride) needs 1.13-1.14 times the time probed at the nominal
#: stance for the same COM move; 0.2 leaves about 5 %, so that steady steps are not retimed.
TRANSFER_MARGIN = 0.2
#: Lattice of the cached table timings: step x, step y [m], turn [rad].
LATTICE = (0.02, 0.02, 0.05)
#: The 8 corners of a lattice cell, as offsets.
_CORNERS = np.array([[(corner >> axis) & 1 for axis in range(3)] for corner in range(8)])
_CORNER_TUPLES = [tuple(int(v) for v in corner) for corner in _CORNERS]
#: Samples of a polynomial swing when its joint speeds are measured.
POLYNOMIAL_PROBE_SAMPLES = 61
#: Sample spacing [s] of a value-table swing whose joint accelerations are measured: the
#: swing's waypoints and the whole-body IK's commands are this far apart, and the smoothed
#: swing changes acceleration within a tenth of a second. On the shape's ~60 samples (25 ms)
#: RoboSimian's hip accelerations read 10 % below what the IK then commands.
ACCELERATION_PROBE_PERIOD_S = 0.005
#: Factor on the polynomial swing's times when they stand in for a value table not built yet
#: (the table's smoothed swings are up to a few per cent slower than the polynomial's).
STAND_IN_FACTOR = 1.25


def smooth_trajectory(trajectory: SwingTrajectory, duration_s: float | None = None,
                      sample_period_s: float = 0.005, kernel_s: float = SMOOTHING_S
                      ) -> tuple[SwingTrajectory, float]:
    """The swing filtered with a triangular kernel, resampled every ``sample_period_s``.

    Args:
        trajectory: Timed waypoints (a polyline with the foot at rest at both ends).
        duration_s: Lift-off to touch-down of the result [s]; the filtered swing (which lasts
            ``kernel_s`` longer than ``trajectory``) is time-scaled to it. None keeps its own.
        sample_period_s: Largest waypoint spacing of the result [s] (evenly spaced).
        kernel_s: Kernel width [s] (two boxes of half the width, so the result is C2).

    Returns:
        ``(smoothed, needed_s)``: the trajectory and the duration the filtered swing has at
        the waypoints' own timing [s].
    """
    times = np.asarray(trajectory.times_s, dtype=float)
    values = np.column_stack([trajectory.positions_in_world,
                              np.unwrap(trajectory.yaws_rad)])
    half = max(int(round(0.5 * kernel_s / FINE_STEP_S)), 1)
    box = np.full(half, 1.0 / half)
    kernel = np.convolve(box, box)
    pad = len(kernel)
    fine_t = np.arange(-pad, int(math.ceil(times[-1] / FINE_STEP_S)) + pad + 1) * FINE_STEP_S
    fine = np.column_stack([np.interp(fine_t, times, values[:, i]) for i in range(4)])
    filtered = np.column_stack([np.convolve(fine[:, i], kernel, mode='valid')
                                for i in range(4)])
    # 'valid' output k averages fine[k : k + len(kernel)], centred on fine_t[k + len//2].
    centres = fine_t[(len(kernel) - 1) // 2:][:len(filtered)]
    extra = 0.5 * (len(kernel) - 1) * FINE_STEP_S
    start, end = -extra, times[-1] + extra
    needed = end - start
    keep = (centres >= start - 1e-12) & (centres <= end + 1e-12)
    local_t = centres[keep] - start
    local = filtered[keep]
    local[0], local[-1] = values[0], values[-1]
    local_t[-1] = needed
    target = needed if duration_s is None else float(duration_s)
    if not target > 0:
        raise SwingPolicyError(f'a swing needs a positive duration, got {target} s')
    scaled_t = local_t * (target / needed)
    count = max(int(math.ceil(target / sample_period_s - 1e-9)), 1)
    out_t = np.linspace(0.0, target, count + 1)
    out = np.column_stack([np.interp(out_t, scaled_t, local[:, i]) for i in range(4)])
    out[0], out[-1] = values[0], values[-1]
    yaws = np.angle(np.exp(1j * out[:, 3]))
    return SwingTrajectory(trajectory.foot, trajectory.start_ns, out_t, out[:, :3], yaws), \
        needed


def evenly_resampled(trajectory: SwingTrajectory, sample_period_s: float) -> SwingTrajectory:
    """``trajectory`` sampled evenly in time, at most ``sample_period_s`` apart (ends kept)."""
    times = np.asarray(trajectory.times_s, dtype=float)
    count = max(int(math.ceil(times[-1] / sample_period_s - 1e-9)), 1)
    out_t = np.linspace(0.0, times[-1], count + 1)
    positions = np.column_stack([np.interp(out_t, times, trajectory.positions_in_world[:, i])
                                 for i in range(3)])
    yaws = np.interp(out_t, times, np.unwrap(trajectory.yaws_rad))
    positions[0], positions[-1] = trajectory.positions_in_world[0], \
        trajectory.positions_in_world[-1]
    yaws[0], yaws[-1] = trajectory.yaws_rad[0], trajectory.yaws_rad[-1]
    return SwingTrajectory(trajectory.foot, trajectory.start_ns, out_t, positions,
                           np.angle(np.exp(1j * yaws)))


class SwingTiming:
    """Least swing time of each foot for a displacement, at the joint velocity limit.

    A subclass gives the swing's shape for a step of the front-right limb (:meth:`shape`:
    foot states in its mirrored base coordinates at normalized times). The shape is timed
    through the whole-body IK: the other feet stand at their nominal places and the full-model
    COM stays where it is at the nominal stance, so the body moves under the swinging limb as
    it does when the robot walks (it compensates the limb's mass: about 15 % of the foot's
    displacement for RoboSimian), and every joint of every limb counts. The probe holds the
    COM's height too (the body bobs against the lifted limb, the joints run faster): an upper
    bound on the walk's IK, which holds a quadruped's body height
    (:func:`gait_nodes.robot.whole_body_ik.walking_vertical`). The
    swing then lasts ``max_j max_u |dq_j / du| / W`` times ``1 + BODY_MOTION_MARGIN``.

    A robot without closed-form limb IK (``family`` None) has a model that probes planned
    swings and transfers only (:meth:`step_s`, :meth:`transfer_s`: a plan's check), not the
    rhythm of a steady walk (:meth:`swing_s` needs the limb's own IK).

    Args:
        robot: The :class:`gait_nodes.robot.model.RobotModel` (with ``extra.limb_ik``, or
            any robot when ``family`` is None).
        family: IK family 0..7, or None.
        joint_velocity_limit_rad_s: The limit [rad/s].
        name: What the times come from (for messages).
    """

    def __init__(self, robot, family: int | None, joint_velocity_limit_rad_s: float,
                 name: str):
        from gait_nodes.robot.whole_body_ik import (
            IkSettings,
            WholeBodyIkSolver,
            nominal_configuration,
        )
        from gait_nodes.swing.kinematics import LimbTiming

        self.robot = robot
        self.family = family
        self.timing = (LimbTiming(robot, family, joint_velocity_limit_rad_s)
                       if family is not None else None)
        self.name = name
        #: Factor on every time (> 1 for a model standing in for slower swings).
        self.factor = 1.0
        feet = robot.description.feet
        if self.timing is not None:
            ik = self.timing.ik
            self._mirrors = [np.asarray(ik.mirrors[ik.foot_index[foot.name]], dtype=float)
                             for foot in feet]
        else:
            self._mirrors = [np.ones(2) for _ in feet]
        self._reference = next(k for k, m in enumerate(self._mirrors) if (m == 1).all())
        self._mirror_floats = [(float(m[0]), float(m[1])) for m in self._mirrors]
        self._swing_s: dict[tuple[float, float, float], float] = {}  # see swing_s
        self._solver = WholeBodyIkSolver(robot, IkSettings(max_iterations=50))
        self._seed_solver = WholeBodyIkSolver(robot, IkSettings(max_iterations=200))
        self._q_nominal = nominal_configuration(robot, family)
        import pinocchio as pin

        self._com = pin.centerOfMass(robot.model, robot.new_data(), self._q_nominal).copy()
        self._feet = robot.nominal_feet_in_world(self._q_nominal[:3], 0.0)
        self._cache: dict[tuple[int, int, int], float] = {}
        self._transfer_cache: dict[tuple[int, int], float] = {}  # see steady_transfer_s
        self._stored_path = ...  # the node times' file, looked up at the first node (_load_stored)

    def shape(self, step_in_base: np.ndarray, turn_rad: float, fine: bool = False,
              foot: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The swing by ``step_in_base`` as ``(u, states)``.

        ``u`` (N,) runs from 0 to 1 in the swing's own time law, evenly; ``states`` (N, 4) are
        the front-right foot's (x, y, z, yaw) in its base frame at the nominal stance (ground
        at ``-body_height_m``). ``fine``: sampled finely enough for the joints' accelerations
        (:data:`ACCELERATION_PROBE_PERIOD_S`), not only their speeds. ``foot``: the limb whose
        swing it is (by name; the front-right one if None), where its time law depends on it.
        """
        raise NotImplementedError

    def raw_s(self, step_in_base: np.ndarray, turn_rad: float) -> float:
        """Swing time [s] of the front-right limb's step with the body compensating its mass."""
        u, states = self.shape(np.asarray(step_in_base, dtype=float), float(turn_rad))
        feet = np.repeat(self._feet[None], len(states), axis=0)
        yaws = np.zeros(feet.shape[:2])
        feet[:, self._reference] = self._q_nominal[:3] + states[:, :3]
        yaws[:, self._reference] = states[:, 3]
        return self._time_through_ik(u, feet, yaws, 0.0, self._com, self._q_nominal)

    def _time_through_ik(self, u, feet, yaws, body_yaw_rad, com, q_start,
                         acceleration: str | None = None, velocity_factor: float = 1.0
                         ) -> float:
        """``velocity_factor max |dq/du| / W`` over every joint, the feet along ``feet``.

        ``feet`` (N, F, 3) are the feet's places at ``u`` (N,).

        The full-model COM follows ``com`` ((3,): held; (N, 3): a path) and the body is level
        at ``body_yaw_rad``. With ``acceleration`` the time is also long enough for the
        joints' acceleration limits A: ``sqrt(max |d2q/du2| / A)`` when ``u`` is the motion's
        own time law (``'path'``), ``sqrt(MIN_JERK_PEAK_ACCELERATION max |dq/du| / A)`` when
        ``u`` is the distance along a path the motion follows in a minimum-jerk time law
        (``'min_jerk'``).
        """
        # What IkTargets would check at every sample, checked once for all of them.
        feet = np.asarray(feet, dtype=float)
        yaws = np.asarray(yaws, dtype=float)
        com = np.asarray(com, dtype=float)
        if feet.shape != (len(u), len(self._feet), 3) or yaws.shape != feet.shape[:2] \
                or com.shape not in ((3,), (len(u), 3)):
            raise ValueError(f'swing probe: feet must be (N, F, 3) with (N, F) yaws and a (3,) '
                             f'or (N, 3) COM, got {feet.shape}, {yaws.shape} and {com.shape}')
        coms = np.broadcast_to(com, (len(u), 3))
        if not (np.isfinite(feet).all() and np.isfinite(yaws).all() and np.isfinite(com).all()
                and math.isfinite(body_yaw_rad)):
            raise ValueError('swing probe targets hold a NaN or infinite value')
        yaw_lists = yaws.tolist()
        solutions = [np.array(q_start, dtype=float)]
        joints = []
        for k in range(len(u)):
            # Started where the last solutions head (as the IK node does): one Newton step.
            result = self._solver.solve_trusted(feet[k], yaw_lists[k], body_yaw_rad,
                                                self._solver.warm_start(solutions[-3:]), coms[k])
            if result.foot_position_errors_m.max() > 1e-4 or result.com_error_m > 1e-4:
                raise SwingPolicyError(f'a swing to {np.round(feet[-1], 3).tolist()} leaves '
                                       f'the reach of the limbs')
            solutions.append(result.q)
            joints.append(self.robot.joint_positions(result.q))
        return joint_path_time_s(self.robot, u, np.array(joints), acceleration,
                                 velocity_factor)

    def world_shape(self, swing: Swing, body_yaw_rad: float,
                    fine: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The swing published for a planned ``swing``, as ``(u, states)``.

        ``u`` runs from 0 to 1 in the swing's time law, evenly; ``states`` (N, 4) are world
        positions and yaws; ``fine`` as in :meth:`shape`.
        """
        raise NotImplementedError

    def step_s(self, swings: dict[int, Swing], feet_in_world: np.ndarray,
               foot_yaws_rad: np.ndarray, body_yaw_rad: float, com_in_world: np.ndarray,
               with_acceleration: bool = False) -> float:
        """Least time [s] of planned swings made together, probed where they happen.

        The whole-body IK follows the swings (as :meth:`world_shape` makes them, each stretched
        to the common duration) with the other feet at ``feet_in_world`` and the full-model COM
        held at ``com_in_world`` (where the ZMP reference holds it during the swing), so the
        body's sway and its compensation of the limbs' mass are those of the walk;
        ``STEP_MARGIN`` covers the COM's drift.

        Args:
            swings: Foot index -> its planned swing (world places and yaws; times unused).
            feet_in_world: (F, 3) contact points of all feet before the swings.
            foot_yaws_rad: (F,) their yaws [rad].
            body_yaw_rad: Body yaw [rad].
            com_in_world: (3,) COM position held during the swings [m].
            with_acceleration: Long enough for the joints' acceleration limits too.
        """
        from gait_nodes.robot.whole_body_ik import IkTargets, seed_configuration

        # Accelerations are read on the swings' own fine samples (ACCELERATION_PROBE_PERIOD_S).
        u = None if with_acceleration else np.linspace(0.0, 1.0, STEP_PROBE_SAMPLES)
        u, feet, yaws = self.swing_feet(swings, feet_in_world, foot_yaws_rad, body_yaw_rad, u,
                                        fine=with_acceleration)
        first = IkTargets(feet[0], yaws[0], body_yaw_rad, com_in_world=np.asarray(com_in_world))
        q = seed_configuration(self.robot, first, self.family)
        q = self._seed_solver.solve(first, q).q
        return (1.0 + STEP_MARGIN) * self.factor * self._time_through_ik(
            u, feet, yaws, body_yaw_rad, com_in_world, q,
            'path' if with_acceleration else None)

    def swing_feet(self, swings: dict[int, Swing], feet_in_world: np.ndarray,
                   foot_yaws_rad: np.ndarray, body_yaw_rad: float, u: np.ndarray | None,
                   fine: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(u, feet, yaws)``: (N, F, 3) feet and (N, F) yaws at ``u`` (N,) of the time law.

        The swinging feet on their swings as :meth:`world_shape` makes them (each stretched
        to the common duration; ``fine`` as there), the others at ``feet_in_world`` (F, 3),
        ``foot_yaws_rad``. ``u`` None: the finest swing's own samples (a swing alone is then
        taken on its samples, not interpolated between them).
        """
        shapes = {foot: self.world_shape(swing, body_yaw_rad, fine)
                  for foot, swing in swings.items()}
        if u is None:
            u = np.linspace(0.0, 1.0, max(len(own_u) for own_u, _ in shapes.values()))
        feet = np.repeat(np.asarray(feet_in_world, dtype=float)[None], len(u), axis=0)
        yaws = np.repeat(np.asarray(foot_yaws_rad, dtype=float)[None], len(u), axis=0)
        for foot, (own_u, states) in shapes.items():
            own_u = own_u / own_u[-1]
            feet[:, foot] = np.column_stack([np.interp(u, own_u, states[:, i])
                                             for i in range(3)])
            yaws[:, foot] = np.interp(u, own_u, states[:, 3])
        return u, feet, yaws

    def transfer_s(self, feet_in_world: np.ndarray, foot_yaws_rad: np.ndarray,
                   body_yaw_rad: float, com_from: np.ndarray, com_to: np.ndarray,
                   with_acceleration: bool = False) -> float:
        """Least time [s] of a transfer: the COM moved from ``com_from`` to ``com_to``.

        Every foot stays down at ``feet_in_world`` ((F, 3), yaws ``foot_yaws_rad``); the
        whole-body IK moves the body so that the full-model COM goes along the segment, and the
        time is that of the fastest joint at the limit with the COM's speed peaking
        :data:`TRANSFER_PEAK_FACTOR` times above its mean (thesis III.C.1: the body's move is
        timed at the joint limit as a swing is).
        """
        from gait_nodes.robot.whole_body_ik import IkTargets, seed_configuration

        u = np.linspace(0.0, 1.0, TRANSFER_PROBE_SAMPLES)
        com_from, com_to = np.asarray(com_from, dtype=float), np.asarray(com_to, dtype=float)
        feet = np.repeat(np.asarray(feet_in_world, dtype=float)[None], len(u), axis=0)
        yaws = np.repeat(np.asarray(foot_yaws_rad, dtype=float)[None], len(u), axis=0)
        first = IkTargets(feet[0], yaws[0], body_yaw_rad, com_in_world=com_from)
        q = self._seed_solver.solve(first, seed_configuration(self.robot, first,
                                                              self.family)).q
        coms = com_from + u[:, None] * (com_to - com_from)
        return self.factor * self._time_through_ik(
            u, feet, yaws, body_yaw_rad, coms, q, 'min_jerk' if with_acceleration else None,
            TRANSFER_PEAK_FACTOR)

    def _lattice_s(self, step_in_base: np.ndarray, turn_rad: float) -> float:
        """:meth:`raw_s` interpolated on :data:`LATTICE` (cached; the planner asks often)."""
        # A swing backwards is the forward one reversed: the same joint speeds, the same time.
        point = (float(step_in_base[0]), float(step_in_base[1]), float(turn_rad))
        if point[0] < 0 or (point[0] == 0 and (point[1] < 0 or (point[1] == 0
                                                                  and point[2] < 0))):
            point = (-point[0], -point[1], -point[2])
        return lattice_interpolated(point, self._node_s)

    def _node_s(self, key: tuple[int, int, int]) -> float:
        """:meth:`raw_s` at lattice node ``key`` (cached; kept on disk, :meth:`_load_stored`)."""
        if key not in self._cache:
            self._load_stored()
        if key not in self._cache:
            node = np.array(key, dtype=float) * LATTICE
            self._cache[key] = self.raw_s(node[:2], float(node[2]))
            self._store()
        return self._cache[key]

    def _load_stored(self) -> None:
        """Add the node times stored for this robot, model and code (the first time only).

        The node times of the rhythm's swings and body moves take a limb IK run each (the ZMP
        crawl's fastest walk, searched at the start of every walk and switch to it, computed
        26 of them: 1.2 s of 2.5 s). They are kept in the cache directory
        (:func:`gait_nodes.swing.cache.node_times_path`), read at the first node asked (a
        subclass's table is known by then) and written as nodes are added.
        """
        if self._stored_path is ...:
            from gait_nodes.swing.cache import node_times_path, read_node_times

            self._stored_path = node_times_path(self, 'timing')
            stored = read_node_times(self._stored_path, ('swing_s', 'transfer_s'))
            if stored is not None:
                self._cache.update(stored['swing_s'])
                self._transfer_cache.update(stored['transfer_s'])

    def _store(self) -> None:
        from gait_nodes.swing.cache import write_node_times

        if self._stored_path is not ... and self._stored_path is not None:
            write_node_times(self._stored_path, {'swing_s': self._cache,
                                                 'transfer_s': self._transfer_cache})

    def swing_s(self, foot: int, step_in_base: np.ndarray, turn_rad: float = 0.0) -> float:
        """Least time [s] of foot ``foot``'s swing by ``step_in_base`` (its own base frame).

        Args:
            foot: Foot index (robot YAML order).
            step_in_base: (2,) landing minus lift-off in the base frame [m].
            turn_rad: Landing yaw minus lift-off yaw [rad].
        """
        # In plain floats (the rhythm's fixed point asks thousands of times): the products are
        # numpy's to the bit (one IEEE multiplication each), and a step asked again (the feet
        # of a straight walk mirror each other) is looked up.
        mx, my = self._mirror_floats[foot]
        x, y = float(step_in_base[0]), float(step_in_base[1])
        key = (x * mx, y * my, (mx * my) * float(turn_rad))
        known = self._swing_s
        if key not in known:
            if len(known) > 4096:
                known.clear()
            known[key] = (1.0 + BODY_MOTION_MARGIN) * self._lattice_s(key[:2], key[2])
        return known[key]

    def steady_transfer_s(self, move_in_base: np.ndarray) -> float:
        """Transfer time [s] of a steady walk whose COM moves ``move_in_base`` (2,) per transfer.

        :meth:`transfer_s` at the nominal stance, the COM moved along x and y by the move's
        sizes (the robot is symmetric), interpolated on :data:`LATTICE` (cached), times
        ``1 + TRANSFER_MARGIN`` for the feet's stagger the nominal stance does not have.
        """
        point = [abs(float(value)) / spacing for value, spacing in
                 zip(move_in_base[:2], LATTICE[:2], strict=True)]
        low = [math.floor(value) for value in point]
        total = 0.0
        for i in (0, 1):
            for j in (0, 1):
                w = (1.0 - abs(point[0] - low[0] - i)) * (1.0 - abs(point[1] - low[1] - j))
                if w == 0.0:
                    continue
                key = (low[0] + i, low[1] + j)
                if key not in self._transfer_cache:
                    self._load_stored()
                if key not in self._transfer_cache:
                    half = 0.5 * np.array([key[0] * LATTICE[0], key[1] * LATTICE[1], 0.0])
                    self._transfer_cache[key] = (0.0 if not half.any() else self.transfer_s(
                        self._feet, np.zeros(len(self._feet)), 0.0, self._com - half,
                        self._com + half))
                    self._store()
                total += w * self._transfer_cache[key]
        return (1.0 + TRANSFER_MARGIN) * total

    def lift_and_lower_s(self) -> float:
        """Swing time [s] of a step in place (the lift and the lowering), with the margin."""
        return (1.0 + BODY_MOTION_MARGIN) * self._lattice_s(np.zeros(2), 0.0)


class TableSwingTiming(SwingTiming):
    """Times of the value table's smoothed greedy swings (what swing_leg_policy publishes).

    Args:
        policy: A :class:`gait_nodes.swing.policy.SwingPolicy`.
        robot: Its RobotModel.
        gait: The gait the swings are walked in: their time law is that gait's
            (:func:`gait_nodes.swing.policy.law_placements`), as swing_leg_policy times them.
    """

    def __init__(self, policy, robot, gait: str):
        table = policy.table
        super().__init__(robot, table.family, table.joint_velocity_limit_rad_s,
                         'the swing value table')
        self.policy = policy
        self.gait = gait

    def shape(self, step_in_base, turn_rad, fine=False, foot=None):
        """The table's greedy path for the step, smoothed, in the fastest time law.

        See :meth:`SwingTiming.shape` and :meth:`gait_nodes.swing.policy.SwingPolicy.
        fastest_swing` (timed for ``foot``'s limb, by name; default the front-right one). The
        path ends on the table's goal; it is moved (as the swing-leg policy moves it onto a
        planned swing) to run from half a step behind to half a step ahead of the nominal foot
        position, where a steady walk makes it: the limbs' speed depends on where they are.
        """
        foot = foot or self.robot.description.feet[self._reference].name
        path, _ = self.policy.fastest_swing(step_in_base, turn_rad, foot, self.gait)
        resampled = evenly_resampled(
            SwingTrajectory('probe', 0, path.times_s, path.states[:, :3], path.states[:, 3]),
            needed_probe_period(path, fine))
        states = np.column_stack([resampled.positions_in_world,
                                  np.unwrap(resampled.yaws_rad)])
        nominal = self.robot.description.feet[self._reference].nominal_position_in_base
        states[:, :2] += np.asarray(nominal[:2]) - 0.5 * (states[0, :2] + states[-1, :2])
        return resampled.times_s / resampled.times_s[-1], states

    def world_shape(self, swing, body_yaw_rad, fine=False):
        """The table swing placed on ``swing`` (see :meth:`SwingTiming.world_shape`)."""
        from gait_nodes.swing.policy import limb_step, place_swing

        ik = self.timing.ik
        mirror = ik.mirrors[ik.foot_index[swing.foot]]
        step, turn = limb_step(swing, mirror, body_yaw_rad)
        path, _ = self.policy.fastest_swing(step, turn, swing.foot, self.gait)
        polyline, _ = place_swing(path, swing, 0, mirror, body_yaw_rad,
                                  self.policy.table.ground_z_m)
        placed = evenly_resampled(polyline, needed_probe_period(path, fine))
        states = np.column_stack([placed.positions_in_world, np.unwrap(placed.yaws_rad)])
        return placed.times_s / placed.times_s[-1], states


def joint_path_time_s(robot, u: np.ndarray, joints: np.ndarray,
                      acceleration: str | float | None = None,
                      velocity_factor: float = 1.0) -> float:
    """Least time [s] of a joint path ``joints`` (N, J) at ``u`` (N,) within the joint limits.

    ``velocity_factor max |dq/du| / W`` over every joint; with ``acceleration`` also long
    enough for the acceleration limits A: ``sqrt(max |d2q/du2| / A)`` when ``u`` is the
    motion's own time law (``'path'``), ``sqrt(MIN_JERK_PEAK_ACCELERATION max |dq/du| / A)``
    when ``u`` is the distance along a path the motion follows in a minimum-jerk time law
    (``'min_jerk'``), or in another whose peak acceleration over a unit move in unit time is
    ``acceleration`` (a number).
    """
    rates = np.abs(np.diff(joints, axis=0)) / np.diff(u)[:, None]
    limits = np.asarray(robot.velocity_limits_rad_s, dtype=float)
    time_s = velocity_factor * float((rates / limits).max())
    if acceleration is None:
        return time_s
    accelerations = np.asarray(robot.acceleration_limits_rad_s2, dtype=float)
    if acceleration == 'path':
        # Three-point second differences: what the commands' own samples show (a gradient of
        # the gradient averages over four spacings and reads a peak low).
        h0, h1 = np.diff(u)[:-1, None], np.diff(u)[1:, None]
        curvature = np.abs(2.0 * (h0 * joints[2:] - (h0 + h1) * joints[1:-1] + h1 * joints[:-2])
                           / (h0 * h1 * (h0 + h1)))
    else:
        peak = MIN_JERK_PEAK_ACCELERATION if acceleration == 'min_jerk' else float(acceleration)
        curvature = peak * rates
    return max(time_s, math.sqrt(float((curvature / accelerations).max())))


def lattice_interpolated(point, node_value: Callable[[tuple[int, int, int]], float]) -> float:
    """Trilinear interpolation on :data:`LATTICE` of ``node_value`` (a node's integer key -> s).

    ``point`` is (step x [m], step y [m], turn [rad]). Plain floats (the planner asks thousands
    of times when it times a velocity): the weights multiply in np.prod's order, so the result is
    the numpy form's to the bit (test_swing_timing). The corners go in _CORNER_TUPLES' order (i
    fastest); those with a zero factor are skipped (a straight walk has no y and no turn: 2
    corners of 8) and never asked of ``node_value``.
    """
    point = [value / spacing for value, spacing in zip(point, LATTICE, strict=True)]
    low = [math.floor(value) for value in point]
    weight = [value - corner for value, corner in zip(point, low, strict=True)]
    fx, fy, fz = [(1.0 - w, w) for w in weight]
    total = 0.0
    for k in (0, 1):
        if fz[k] == 0.0:
            continue
        for j in (0, 1):
            if fy[j] == 0.0:
                continue
            for i in (0, 1):
                w = fx[i] * fy[j] * fz[k]
                if w == 0.0:
                    continue
                total += w * node_value((low[0] + i, low[1] + j, low[2] + k))
    return total


def needed_probe_period(path, fine: bool = False) -> float:
    """Sample spacing [s] for timing a swing: about 60 samples; ``fine``: for accelerations."""
    if fine:
        return ACCELERATION_PROBE_PERIOD_S
    return max(path.duration_s / 60.0, ACCELERATION_PROBE_PERIOD_S)


class PolynomialSwingTiming(SwingTiming):
    """Times of the sixth-order swing, its fastest joint at the limit.

    The swing runs from half a step behind to half a step ahead of the limb's nominal foot
    position (front-right coordinates), ``step_height_m`` high at mid-swing.

    Args:
        robot: The RobotModel.
        family: IK family (None: a robot without closed-form limb IK, probes only).
        joint_velocity_limit_rad_s: The limit [rad/s].
        step_height_m: Via-point height above the ground [m].
        factor: Factor on the times (> 1 when they stand in for slower swings).
    """

    def __init__(self, robot, family: int | None, joint_velocity_limit_rad_s: float,
                 step_height_m: float, factor: float = 1.0):
        super().__init__(robot, family, joint_velocity_limit_rad_s, 'the polynomial swing')
        self.factor = float(factor)
        feet = robot.description.feet
        self.nominal = np.asarray(feet[self._reference].nominal_position_in_base, dtype=float)
        self.step_height_m = float(step_height_m)

    def shape(self, step_in_base, turn_rad, fine=False, foot=None):
        """The sixth-order swing around the nominal foot (see :meth:`SwingTiming.shape`).

        A polynomial: its samples are exact, fine or not; its time law is the same for every
        foot.
        """
        from gait_nodes.swing.polynomial import evaluate, sixth_order_coefficients

        step = np.array([step_in_base[0], step_in_base[1], 0.0, turn_rad])
        centre = np.array([*self.nominal, 0.0])
        start, end = centre - 0.5 * step, centre + 0.5 * step
        via = 0.5 * (start + end)
        via[2] += self.step_height_m
        coefficients = sixth_order_coefficients(start, end, via, 1.0, 0.5)
        u = np.linspace(0.0, 1.0, POLYNOMIAL_PROBE_SAMPLES)
        return u / self.factor, evaluate(coefficients, u)

    def world_shape(self, swing, body_yaw_rad, fine=False):
        """The sixth-order swing of ``swing`` (see :meth:`SwingTiming.world_shape`).

        A polynomial: its samples are exact, fine or not.
        """
        from gait_nodes.swing.polynomial import polynomial_swing

        trajectory, _ = polynomial_swing(swing, 0, self.step_height_m, POLYNOMIAL_PROBE_SAMPLES)
        states = np.column_stack([trajectory.positions_in_world,
                                  np.unwrap(trajectory.yaws_rad)])
        return trajectory.times_s / trajectory.duration_s, states


def swing_timing(robot, method: str, step_height_m: float, gait: str,
                 log: Callable[[str], None] | None = None) -> tuple[SwingTiming | None, str]:
    """The timing model of ``method`` for ``robot`` and why it is (or is not) that one.

    ``value_table`` uses the cached default table (:mod:`gait_nodes.swing.cache`) when it is
    built; when it is not (swing_leg_policy builds it on first use) the polynomial swing's times,
    which are longer, stand in until it is. A robot without closed-form limb IK has no model
    (None): its gait keeps the fixed timing of its parameters.

    Args:
        robot: The RobotModel.
        method: 'value_table' or 'polynomial'.
        step_height_m: Swing height [m].
        gait: The gait walked (a value-table swing is timed in its law:
            :class:`TableSwingTiming`).
        log: Called with a message when the table is not there yet.
    """
    from gait_nodes.errors import GaitNodesError
    from gait_nodes.robot.whole_body_ik import limb_ik_family

    family = limb_ik_family(robot)
    if family is None:
        return None, f'{robot.name} has no closed-form limb IK: fixed timing'
    limit = robot.description.joint_velocity_limit_rad_s
    if method == 'value_table':
        from gait_nodes.swing.cache import default_table_path
        from gait_nodes.swing.policy import SwingPolicy, law_placements
        from gait_nodes.swing.table import load_table

        path = default_table_path(robot, family, step_height_m, limit)
        if path.is_file():
            stat = path.stat()
            key = (id(robot), method, float(step_height_m), str(path), stat.st_mtime_ns,
                   stat.st_size, law_placements(gait))
            known = _known_model(robot, key)
            if known is not None:
                return known
            try:
                table = load_table(path, robot, limit, family)
                if math.isclose(table.step_height_m, step_height_m, abs_tol=1e-9):
                    return _remember(robot, key, (
                        TableSwingTiming(SwingPolicy(table, robot), robot, gait),
                        f'swing times from the value table {path}'))
            except GaitNodesError as exc:
                if log is not None:
                    log(f'{path}: {exc}')
        reason = (f'the swing value table {path} is not built yet: the polynomial swing\'s '
                  f'times x {STAND_IN_FACTOR:g} stand in')
        if log is not None:
            log(reason)
        return PolynomialSwingTiming(robot, family, limit, step_height_m, STAND_IN_FACTOR), \
            reason
    key = (id(robot), method, float(step_height_m))
    return _known_model(robot, key) or _remember(robot, key, (
        PolynomialSwingTiming(robot, family, limit, step_height_m),
        'swing times of the polynomial swing'))


#: Timing models made in this process, newest last: key -> (robot, (model, reason)).
_MODELS: collections.OrderedDict = collections.OrderedDict()
#: How many :data:`_MODELS` keeps.
KNOWN_MODELS = 8


def _known_model(robot, key: tuple) -> tuple[SwingTiming, str] | None:
    """The model :func:`swing_timing` made for ``key`` before (its node times known), or None.

    A model is a function of the robot (a shared, read-only RobotModel:
    :func:`gait_nodes.robot.model.load_robot_model`), the swing and its height, and the table
    file it read: every planner of the process with the same ones shares it, and so its
    lattice nodes, each timed through the limb IK once per process, not once per planner (the
    first plan of a run starts without that second of IK; a test run of many walks saves it
    on each). Like any model it is used by one planning thread at a time.
    """
    known = _MODELS.get(key)
    if known is None or known[0] is not robot:
        return None
    _MODELS.move_to_end(key)
    return known[1]


def _remember(robot, key: tuple, made: tuple[SwingTiming, str]) -> tuple[SwingTiming, str]:
    _MODELS[key] = (robot, made)
    while len(_MODELS) > KNOWN_MODELS:
        _MODELS.popitem(last=False)
    return made
