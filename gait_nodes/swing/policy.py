"""Swing paths from a value table: best start, greedy descent to the goal, timed waypoints.

Thesis 000, Appendix A: the initial state is the argmin of the total value (lift + cost-to-go +
lowering) over the start region; from there the action with the lowest one-step cost plus
interpolated value is taken until the goal is reached. Each segment between waypoints takes
``max_j |dq_j| / W`` (IK of the table's family at both ends). The path starts on the ground below
the initial state (the lift, straight up) and ends on the ground below the goal (the lowering).

:func:`place_swing` maps such a body-relative path onto a planned swing: the table's goal goes to
the landing place, the path is rotated with the body and mirrored for the limb, and what the
grid could not represent (a start clamped onto the grid, a landing yaw other than the goal's)
is spread along the path so that it starts exactly at the lift-off place and ends exactly at the
landing place.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gait_nodes.contract import Swing, SwingTrajectory
from gait_nodes.errors import SwingPolicyError
from gait_nodes.swing.kinematics import FEASIBLE_BELOW_S, INFEASIBLE_S, LimbTiming
from gait_nodes.swing.table import ValueTable
from gait_nodes.swing.time_law import fastest_times

#: A state this close to the goal on every axis is the goal.
GOAL_TOLERANCE = 1e-9
#: Most greedy steps before a descent is declared stuck.
MAX_STEPS = 500
#: Where around its place in the stance a swing is timed, outwards along the limb's x [m]: the
#: time law is the fastest that keeps the joints within their limits with the swing moved by
#: each of these (:meth:`SwingPolicy.fastest_swing`). The swing-leg policy does not know where
#: the body will stand under a swing; the static crawl places it for the COM and its footholds
#: on the path, which leaves RoboSimian's steady swings 1.5 (hind) to 3.5 cm (fore) outwards of
#: the stance (the fore foot lands a swing's worth of path further along than the hind one).
#: A law timed at the stance place alone runs some joint at its limit nearly everywhere, so
#: the planner's probe where the swing happens stretched it by 7 % (rear feet, 0.22 m) to 57 %
#: (fore feet, 0.28 m); over a spread of places, by 1 % for 4-5 % more time. Three places
#: keep the joints within their limits at the places between them too (test_time_law); a
#: swing walked outside them (the first steps, 0.3 m to catch up with the path) is stretched
#: by the planner's probe as far as it needs. Spread from 2 cm inwards to 6 cm outwards (as
#: until session 22), the steady swings took 3 % longer. The static crawl's law
#: (:func:`law_placements`).
LAW_PLACEMENTS_M = (0.0, 0.02, 0.04)
#: The law's places for the gaits whose body moves under a swing (the ZMP crawl, the trot):
#: their swings happen inwards of the static crawl's stance as well as outwards (the ZMP
#: crawl's stance puts RoboSimian's front feet 4 cm inside it, its rear feet 6 cm outside, and
#: the body moves on under every swing). Timed with the static crawl's law, the planner's probe
#: stretched their swings: the ZMP crawl under commands (robosimian_commands) walked
#: 0.0086/0.0085/0.0091 m/s where it walks 0.0088/0.0100/0.0105 with these.
MOVING_BODY_LAW_PLACEMENTS_M = (-0.02, 0.02, 0.06)
#: Spacing of the smoothed path's samples in the table's timing, which the fastest time law
#: re-times (:meth:`SwingPolicy.fastest_swing`) [s]: ~250 on a swing, 5 ms apart as the
#: swing-leg policy sends them.
LAW_SAMPLE_PERIOD_S = 0.005
#: Every how many of those samples the limb's joints are solved for the time law (a cubic
#: spline runs through them): 30 ms apart, where the smoothing changes the path over 120 ms.
LAW_JOINT_STRIDE = 6
#: Points of the law per sample of the path, where it is inverted (time -> place): near rest a
#: sample's time step is long, and a place interpolated linearly in time there would jerk.
LAW_DENSITY = 4
#: Share of the joints' acceleration limits the law plans with: it meets them at its grid
#: points (:data:`gait_nodes.swing.time_law.GRID_POINTS`), and the IK's joints between them
#: (through a spline of samples 30 ms apart) read up to 5 % higher on RoboSimian's swings
#: sampled 5 ms apart with 0.9.
LAW_ACCELERATION_SHARE = 0.85


def law_placements(gait: str) -> tuple[float, ...]:
    """Where a swing walked in ``gait`` is timed, outwards of its place in the stance [m].

    :data:`LAW_PLACEMENTS_M` for the static crawl (the body still under every swing),
    :data:`MOVING_BODY_LAW_PLACEMENTS_M` for the other gaits.
    """
    from gait_nodes.swing.still_body import GAIT

    return LAW_PLACEMENTS_M if gait == GAIT else MOVING_BODY_LAW_PLACEMENTS_M


def _wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle, dtype=float)))


@dataclass(frozen=True)
class SwingPath:
    """A timed swing in the front-right limb's body-relative coordinates.

    Attributes:
        states: (W, 4) waypoints (x, y, z, yaw) in the base frame [m, rad], ground to ground.
        times_s: (W,) time of each waypoint from lift-off at the joint velocity limit [s].
        lift_s: Time of the lift from the ground to the first grid state [s].
        lower_s: Time of the lowering from the goal to the ground [s].
        predicted_s: The table's total value at the start state [s].
        grid_first: Index of the first waypoint on the grid (the top of the lift).
        grid_last: Index of the last waypoint on the grid (the goal).
    """

    states: np.ndarray
    times_s: np.ndarray
    lift_s: float
    lower_s: float
    predicted_s: float
    grid_first: int
    grid_last: int

    @property
    def duration_s(self) -> float:
        """Lift-off to touch-down at the limit [s]."""
        return float(self.times_s[-1])

    def reversed(self) -> SwingPath:
        """The same path run backwards (same segment times: ``max |dq| / W`` is symmetric)."""
        last = len(self.states) - 1
        return SwingPath(self.states[::-1].copy(), self.times_s[-1] - self.times_s[::-1],
                         self.lower_s, self.lift_s, self.predicted_s, last - self.grid_last,
                         last - self.grid_first)

    @property
    def swing_states(self) -> np.ndarray:
        """The waypoints on the grid (without the vertical lift and lowering)."""
        return self.states[self.grid_first:self.grid_last + 1]


class SwingPolicy:
    """Greedy lookups in a :class:`ValueTable` (thesis Appendix A).

    The one-step time of each candidate move needs the joint angles at the candidate. With
    ``exact_lookahead`` they come from the closed-form IK (as in the value iteration); otherwise
    from multilinear interpolation of the IK at the grid nodes, interpolated in the same call as
    the value (several times faster; joint angles are smooth within a family, so the choice
    rarely differs). Either way the returned path is timed by the exact IK of its waypoints.

    Args:
        table: The converged table.
        robot: The RobotModel it was built for (checked by its URDF hash).
        exact_lookahead: Use the IK for the candidates' joint angles.
    """

    def __init__(self, table: ValueTable, robot, exact_lookahead: bool = False):
        table.check_for(robot)
        self.table = table
        self.robot = robot
        self.timing = LimbTiming(robot, table.family, table.joint_velocity_limit_rad_s,
                                 table.ground_z_m)
        self.displacements = table.actions.displacements()
        self.exact_lookahead = exact_lookahead
        self._fastest: dict[tuple, tuple[SwingPath, float]] = {}  # see fastest_swing
        reference = next(f for f in robot.description.feet
                         if (np.asarray(self.timing.ik.mirrors[self.timing.ik.foot_index[f.name]])
                             == 1).all())
        walking = robot.indices(reference.joints)[:6]
        self._acceleration_limits = np.asarray(robot.acceleration_limits_rad_s2)[walking]
        q_nodes, _ = self.timing.joints(table.grid.points())
        #: Per node: the value, then the 6 walking joint angles.
        self._node_data = np.concatenate([table.values_s[..., None],
                                          q_nodes.reshape(*table.grid.shape, -1)], axis=-1)

    def _lookahead(self, candidates: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Values, joint angles and feasibility at candidate states."""
        if self.exact_lookahead:
            q, feasible = self.timing.joints(candidates)
            return self.value(candidates), q, feasible
        data = self.table.grid.interpolate(self._node_data, candidates)
        return data[:, 0], data[:, 1:], data[:, 0] < FEASIBLE_BELOW_S

    # -- values --------------------------------------------------------------------------------

    def value(self, states: np.ndarray) -> np.ndarray:
        """Interpolated cost-to-go [s] at (N, 4) states (clamped to the grid)."""
        return self.table.grid.interpolate(self.table.values_s, states)

    def total(self, states: np.ndarray) -> np.ndarray:
        """Interpolated whole swing time (lift + cost-to-go + lowering) [s] at (N, 4) states."""
        return self.table.grid.interpolate(self.table.total_s, states)

    def start_state(self, x_m: float, y_m: float, yaw_rad: float | None = None) -> np.ndarray:
        """Best initial state above a lift-off place: argmin of the total over z (and yaw).

        Args:
            x_m: Lift-off x in the base frame (front-right coordinates) [m].
            y_m: Lift-off y [m].
            yaw_rad: Foot yaw at lift-off relative to the base [rad]; None lets the yaw be
                chosen too, as in the thesis' Appendix A.
        """
        grid = self.table.grid
        yaws = grid.yaw_rad if yaw_rad is None else np.array([yaw_rad])
        zz, ww = np.meshgrid(grid.z_m, yaws, indexing='ij')
        candidates = np.stack([np.full(zz.size, x_m), np.full(zz.size, y_m), zz.ravel(),
                               ww.ravel()], axis=1)
        candidates = grid.clamp(candidates)
        return candidates[int(np.argmin(self.total(candidates)))]

    # -- descent -------------------------------------------------------------------------------

    def descend(self, start: np.ndarray, max_steps: int = MAX_STEPS) -> np.ndarray:
        """(W, 4) greedy waypoints from ``start`` (clamped to the grid) to the goal.

        Each step takes the action minimizing one-step time + interpolated value; the move
        straight to the goal is one of the candidates once the goal is within one action. A
        move that the grid's edge clamps back onto the current state is not a candidate.

        Raises:
            SwingPolicyError: The start is infeasible or the descent does not reach the goal.
        """
        table, grid = self.table, self.table.grid
        goal = table.goal
        current = grid.clamp(np.asarray(start, dtype=float))
        value, q_current, ok = self._lookahead(current[None])
        if not ok[0] or value[0] >= FEASIBLE_BELOW_S:
            raise SwingPolicyError(f'no feasible swing from {np.round(current, 4).tolist()} in '
                                   f'IK family {table.family}')
        path = [current]
        reach = table.actions.max_radius_m + 1e-12
        turn = table.actions.max_yaw_step_rad + 1e-12
        for _ in range(max_steps):
            if np.all(np.abs(current - goal) <= GOAL_TOLERANCE):
                return np.array(path)
            candidates = grid.clamp(current + self.displacements)
            to_goal = goal - current
            if np.linalg.norm(to_goal[:3]) <= reach and abs(to_goal[3]) <= turn:
                candidates = np.vstack([candidates, goal])
            values, q_next, feasible = self._lookahead(candidates)
            cost = self.timing.move_time(q_current, q_next) + values
            # A move clamped back onto the current state costs nothing and leads nowhere.
            stays = np.all(np.abs(candidates - current) <= GOAL_TOLERANCE, axis=1)
            cost[~feasible | stays] = INFEASIBLE_S
            k = int(np.argmin(cost))
            current, q_current = candidates[k], q_next[k:k + 1]
            path.append(current)
        raise SwingPolicyError(f'the greedy descent from {np.round(path[0], 4).tolist()} did '
                               f'not reach the goal {np.round(goal, 4).tolist()} in '
                               f'{max_steps} steps')

    def timed_path(self, swing_states: np.ndarray) -> SwingPath:
        """Add the vertical lift and lowering to grid waypoints and time every segment."""
        timing = self.timing
        lift = timing.vertical_path(swing_states[0])
        lower = timing.vertical_path(swing_states[-1])[::-1]
        states = np.vstack([lift[:-1], swing_states, lower[1:]])
        segments, feasible = timing.path_times(states)
        if not feasible:
            raise SwingPolicyError('a waypoint of the swing (or of its lift or lowering) is '
                                   f'infeasible in IK family {self.table.family}')
        times = np.concatenate([[0.0], np.cumsum(segments)])
        lift_s = float(times[len(lift) - 1])
        lower_s = float(times[-1] - times[-len(lower)])
        predicted = float(self.total(swing_states[:1])[0])
        return SwingPath(states, times, lift_s, lower_s, predicted, len(lift) - 1,
                         len(states) - len(lower))

    def path_from(self, start: np.ndarray) -> SwingPath:
        """The timed greedy swing from a start state."""
        return self.timed_path(self.descend(start))

    def fastest_swing(self, step_in_base: np.ndarray, step_yaw_rad: float,
                      foot: str, gait: str) -> tuple[SwingPath, float]:
        """The swing of :meth:`path_for_step`, smoothed and moved along in the fastest time law.

        The path is smoothed (:func:`gait_nodes.swing.timing.smooth_trajectory`) and timed by
        :func:`gait_nodes.swing.time_law.fastest_times` for ``foot``'s limb swinging around its
        place in the static crawl's stance (:meth:`law_centre`), moved by each of
        :func:`law_placements` of the ``gait`` it is walked in: the limb's speed depends on
        where it swings, and the swing-leg policy, which does not know where the body will be,
        and the footstep planner, which probes the swing where it happens and stretches it as
        far as that needs, time it alike. Cached.

        Returns:
            ``(path, clamped_m)``: the smoothed path in front-right coordinates, sampled
            ``LAW_SAMPLE_PERIOD_S`` apart in its fastest time law (its ``lift_s``, ``lower_s``
            and ``predicted_s`` are the table path's, in the table's timing), and
            :meth:`path_for_step`'s clamp.
        """
        from scipy.interpolate import CubicSpline

        from gait_nodes.swing.timing import smooth_trajectory

        centre = self.law_centre(foot)
        placements = law_placements(gait)
        key = (round(float(step_in_base[0]), 6), round(float(step_in_base[1]), 6),
               round(float(step_yaw_rad), 6), *centre, placements)
        known = self._fastest.get(key)
        if known is not None:
            return known
        path, clamped = self.path_for_step(step_in_base, step_yaw_rad)
        polyline = SwingTrajectory('swing', 0, path.times_s, path.states[:, :3],
                                   path.states[:, 3])
        smoothed, _ = smooth_trajectory(polyline, None, LAW_SAMPLE_PERIOD_S)
        states = np.column_stack([smoothed.positions_in_world, np.unwrap(smoothed.yaws_rad)])
        solved = np.unique(np.r_[np.arange(0, len(states), LAW_JOINT_STRIDE), len(states) - 1])
        offsets = np.asarray(centre) - 0.5 * (states[0, :2] + states[-1, :2])
        placed = np.repeat(states[solved][None], len(placements), axis=0)
        placed[..., :2] += offsets
        placed[..., 0] += np.asarray(placements)[:, None]
        q, feasible = self.timing.joints(placed.reshape(-1, 4))
        # The places the limb reaches all along (a long step far out may not be reachable at
        # all of them); at none, the smoothed path keeps the table's timing, which the planner's
        # probe stretches as far as it needs.
        reached = feasible.reshape(len(placements), -1).all(axis=1)
        u = smoothed.times_s
        if not reached.any():
            timed = SwingPath(states, u - u[0], path.lift_s, path.lower_s, path.predicted_s, 0,
                              len(u) - 1)
            self._remember(key, (timed, clamped))
            return timed, clamped
        # Each place's joints side by side: the law keeps every one within the limits.
        q = q.reshape(len(placements), len(solved), -1)[reached].transpose(1, 0, 2)
        dense = np.linspace(u[0], u[-1], LAW_DENSITY * len(u))
        dense_times = fastest_times(u[solved], q.reshape(len(solved), -1),
                                    self.table.joint_velocity_limit_rad_s,
                                    np.tile(LAW_ACCELERATION_SHARE * self._acceleration_limits,
                                            int(reached.sum())),
                                    at=dense)
        # The path sampled evenly in its new time (what is played is interpolated in time).
        count = max(int(math.ceil(dense_times[-1] / LAW_SAMPLE_PERIOD_S)), 1)
        times = np.linspace(0.0, dense_times[-1], count + 1)
        along = np.interp(times, dense_times, dense)
        # A cubic spline through the path's samples: linear pieces would bend at every sample,
        # which the joints' accelerations on the 5 ms ticks read as kinks.
        timed_states = CubicSpline(u, states)(along)
        timed_states[:, 2] = np.maximum(timed_states[:, 2], self.table.ground_z_m)
        timed_states[0], timed_states[-1] = states[0], states[-1]
        timed = SwingPath(timed_states, times, path.lift_s, path.lower_s, path.predicted_s, 0,
                          len(times) - 1)
        self._remember(key, (timed, clamped))
        return timed, clamped

    def _remember(self, key: tuple, swing: tuple[SwingPath, float]) -> None:
        if len(self._fastest) > 4096:
            self._fastest.clear()
        self._fastest[key] = swing

    def law_centre(self, foot: str) -> tuple[float, float]:
        """Where ``foot``'s swings are centred when timed, in front-right base coordinates [m].

        The foot's place in the static crawl's stance (the value table's gait, thesis eq. (2);
        the robot YAML's ``gait_stances``, else its nominal stance), mirrored.
        """
        from gait_nodes.swing.still_body import GAIT

        description = self.robot.description
        index = [f.name for f in description.feet].index(foot)
        place = description.nominal_stance_in_base(GAIT)[index, :2]
        mirror = self.timing.ik.mirrors[self.timing.ik.foot_index[foot]]
        return (round(float(place[0] * mirror[0]), 9), round(float(place[1] * mirror[1]), 9))

    def path_for_step(self, step_in_base: np.ndarray, step_yaw_rad: float = 0.0,
                      free_yaw: bool = False) -> tuple[SwingPath, float]:
        """The swing that lands on the goal after a given displacement.

        A step backwards in front-right coordinates (a rear limb walking forwards: its x is
        mirrored) is the reverse of the forwards step: the table's path to the goal, run from
        the goal back (the one-step cost is symmetric, so the reversed path is as fast).

        Args:
            step_in_base: (2,) landing minus lift-off, front-right coordinates in the base
                frame [m].
            step_yaw_rad: Landing yaw minus lift-off yaw [rad].
            free_yaw: Choose the start yaw by the table (thesis Appendix A) instead.

        Returns:
            ``(path, clamped_m)``: the path and how far the lift-off place lies off the grid [m].
        """
        step_in_base = np.asarray(step_in_base, dtype=float)
        if step_in_base[0] < 0:
            path, clamped = self.path_for_step(-step_in_base, -step_yaw_rad, free_yaw)
            return path.reversed(), clamped
        goal = self.table.goal
        start_xy = goal[:2] - np.asarray(step_in_base, dtype=float)
        start = self.start_state(start_xy[0], start_xy[1],
                                 None if free_yaw else float(goal[3] - step_yaw_rad))
        return self.path_from(start), float(np.linalg.norm(start[:2] - start_xy))


def limb_step(swing: Swing, mirror: np.ndarray, body_yaw_rad: float) -> tuple[np.ndarray, float]:
    """A planned swing's displacement in front-right base coordinates.

    Args:
        swing: The planned swing.
        mirror: (3,) signs taking this limb's base coordinates to the front-right limb's.
        body_yaw_rad: Body yaw during the swing [rad].

    Returns:
        ``(step, turn)``: (2,) landing minus lift-off [m] and the yaw change [rad], both in the
        front-right limb's mirrored coordinates.
    """
    c, s = math.cos(body_yaw_rad), math.sin(body_yaw_rad)
    step = np.asarray(swing.end_in_world[:2], dtype=float) - swing.start_in_world[:2]
    in_base = np.array([c * step[0] + s * step[1], -s * step[0] + c * step[1]])
    sign = float(mirror[0] * mirror[1])
    turn = sign * math.remainder(swing.end_yaw_rad - swing.start_yaw_rad, 2 * math.pi)
    return in_base * np.asarray(mirror[:2], dtype=float), turn


def place_swing(path: SwingPath, swing: Swing, start_ns: int, mirror: np.ndarray,
                body_yaw_rad: float, ground_z_m: float, duration_s: float | None = None
                ) -> tuple[SwingTrajectory, float]:
    """Map a body-relative path onto a planned swing in odom.

    Args:
        path: The swing in front-right base coordinates.
        swing: The planned swing (lift-off and landing places and yaws).
        start_ns: Lift-off time [ns].
        mirror: (3,) signs taking front-right coordinates to this limb's.
        body_yaw_rad: Body yaw during the swing [rad].
        ground_z_m: Ground height in the base frame of the table [m].
        duration_s: Planned swing time [s]; the timing at the limit is stretched (or, if the plan
            allows less, compressed) to it. None keeps the timing at the limit.

    Returns:
        ``(trajectory, needed_s)``: the swing trajectory and the time it needs at the limit.
    """
    mirror = np.asarray(mirror, dtype=float)
    sign = float(mirror[0] * mirror[1])
    local = path.states[:, :3] * mirror
    c, s = math.cos(body_yaw_rad), math.sin(body_yaw_rad)
    rotation = np.array([[c, -s], [s, c]])
    horizontal = local[:, :2] @ rotation.T
    start, end = np.asarray(swing.start_in_world), np.asarray(swing.end_in_world)
    horizontal += start[:2] - horizontal[0]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(horizontal, axis=0),
                                                          axis=1))])
    fraction = arc / arc[-1] if arc[-1] > 1e-12 else path.times_s / max(path.duration_s, 1e-12)
    horizontal += fraction[:, None] * (end[:2] - horizontal[-1])
    height = path.states[:, 2] - ground_z_m
    height[0], height[-1] = 0.0, 0.0
    z = start[2] + fraction * (end[2] - start[2]) + height
    yaws = body_yaw_rad + sign * path.states[:, 3]
    yaws = yaws + (swing.start_yaw_rad - yaws[0])
    yaws = yaws + fraction * float(_wrap(swing.end_yaw_rad - yaws[-1]))
    positions = np.column_stack([horizontal, z])
    positions[0], positions[-1] = start, end
    needed = path.duration_s
    times = path.times_s
    if duration_s is not None and needed > 0:
        times = times * (duration_s / needed)
    trajectory = SwingTrajectory(swing.foot, int(start_ns), times, positions, _wrap(yaws))
    return trajectory, needed
