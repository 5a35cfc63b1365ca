"""The public topic contract's message layouts, as plain data with converters both ways.

Every node and bag tool that reads or writes a gait topic goes through this module, so that a
layout is spelled once (DESIGN.md, "Nodes and the public topic contract"):

``/gait/footsteps`` (trajectory_msgs/MultiDOFJointTrajectory, latched)
    ``header.frame_id`` = ``odom``; ``header.stamp`` = the plan's start time; ``joint_names`` = the
    foot names; one point per contact change, ``time_from_start`` from the plan start, with one
    ``transforms`` entry per foot: where that foot is at that instant (a foot in swing is listed
    at its landing place from the touch-down point on). A foot is in swing over
    ``[t_k, t_{k+1}]`` exactly when its transform differs between points ``k`` and ``k + 1``;
    the planner never emits a zero-length step, so "moved" and "swung" are the same thing.
``/gait/zmp_reference`` (nav_msgs/Path)
    ``header.frame_id`` = ``odom``, ``header.stamp`` = the first sample's time; each pose is one
    sample of the ZMP reference stamped at its own (future) time, ``z`` = the height of the
    plane the ZMP lies on (the lowest foot in contact at that time: 0 on flat ground, the tread
    on stairs, as the ZMP monitor's plane), identity orientation. Between samples the
    reference is linear in time (its x, y).
``/gait/com_reference`` (trajectory_msgs/MultiDOFJointTrajectory)
    ``joint_names`` = ``['com']``; point 0 is the state at ``header.stamp``: COM position in
    ``transforms[0].translation`` with the body yaw in its rotation, velocity in
    ``velocities[0].linear`` (yaw rate in ``angular.z``), acceleration in
    ``accelerations[0].linear``. Further points, if any, are the committed horizon: the COM
    controller publishes, every ``publish_period_s``, its states ``sample_period_s`` apart from
    the latest at or before now to the end of what it has computed (``horizon_s`` ahead of the
    clock). A consumer interpolates between points (quintic Hermite in position, velocity and
    acceleration; cubic Hermite in yaw and yaw rate) and lets a new message replace what it
    holds from the message's first point on.
``/gait/swing_trajectory`` (trajectory_msgs/MultiDOFJointTrajectory)
    ``joint_names`` = ``[foot]``; ``header.stamp`` = lift-off time; one point per waypoint with
    the foot position and yaw (rotation about z) and ``time_from_start`` from lift-off. The first
    point is the lift-off place, the last the landing place.
``/joint_commands`` (trajectory_msgs/JointTrajectory, what a ros2_control
joint_trajectory_controller takes)
    ``header.stamp`` = the absolute time of ``time_from_start`` 0 (a zero stamp: "start when
    received", as the controller); ``joint_names`` = joints of the URDF, unique (every joint in
    the robot's order from whole_body_ik; a subset is allowed: the other joints hold their last
    command); points with ``time_from_start`` strictly increasing and >= 0, ``positions`` one per
    joint, ``velocities`` and ``accelerations`` empty or one per joint (in every point alike),
    ``effort`` empty. Between points a follower interpolates with cubic Hermite polynomials
    (positions and velocities) or linearly (positions only).
``/gait/contact_wrench/<foot>`` (geometry_msgs/WrenchStamped, one topic per foot of the robot
YAML, physics_simulator)
    ``header.frame_id`` = the foot's frame (the robot YAML's ``feet.<foot>.frame``),
    ``header.stamp`` = the end of the interval it averages (one control tick); ``wrench.force``:
    the ground's force on the foot [N], ``wrench.torque``: its moment about the foot frame's
    origin [N m], both in the foot frame, as a force-torque sensor at the sole reports them. Zero
    while the foot is in the air.
``/gait/cop`` (geometry_msgs/PointStamped, physics_simulator)
    ``header.frame_id`` = ``odom``: the centre of pressure of the contact forces over the tick
    ending at ``header.stamp``, on the plane of the lowest contact point (``z`` its height); not
    published without vertical ground force.
``/tf`` (tf2_msgs/TFMessage, many publishers, as tf2 has it)
    The simulator's messages hold one transform, ``odom -> base_link``: the floating base's
    pose, stamped at its instant. robot_state_publisher's hold one transform per moving joint
    of the URDF, parent link -> child link (the URDF's link names), stamped with the
    /joint_states message they come from. A reader picks the transforms it wants by their frame
    ids (:func:`base_transforms`), never by their place in a message.
``/tf_static`` (tf2_msgs/TFMessage, latched), ``/robot_description`` (std_msgs/String, latched)
    robot_state_publisher's, once at start: one message holding every fixed joint's transform
    (and ``base_link -> <root link>`` when the URDF's root link has another name); the URDF's
    text.

Times are integer nanoseconds at the message boundary and float seconds inside the arrays.
Converters from messages validate what they read and raise :class:`ContractError` with the reason;
nodes turn that into a /diagnostics report and drop the message.
"""

from __future__ import annotations

import math
import operator
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import chain, compress, count, repeat

import numpy as np

from gait_nodes.errors import GaitNodesError
from gait_nodes.interfaces import get_constructor

#: World frame of every planned quantity (REP-105).
WORLD_FRAME = 'odom'
#: Body frame of the robot.
BASE_FRAME = 'base_link'
#: Joint name carried by /gait/com_reference.
COM_JOINT_NAME = 'com'
#: Two foot transforms closer than this [m, rad] are "the same place".
SAME_PLACE_TOLERANCE = 1e-9
_NS_PER_S = 1_000_000_000
#: New poses a ZmpReferenceReader decodes one by one in floats (more: as arrays).
_FEW_POSES = 16
#: Largest | |q|^2 - 1 | of a rotation read from a message (tf2's test of a quaternion).
UNIT_QUATERNION_TOLERANCE = 0.01


class ContractError(GaitNodesError):
    """A message breaks the topic contract: shape, frame, ordering or a non-finite value."""


def ns_to_time_msg(stamp_ns: int):
    """builtin_interfaces/Time for integer nanoseconds since the epoch (or since sim start)."""
    return get_constructor('builtin_interfaces/msg/Time')(*divmod(int(stamp_ns), _NS_PER_S))


def time_msg_to_ns(msg) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return int(msg.sec) * 1_000_000_000 + int(msg.nanosec)


def seconds_to_duration_msg(seconds: float):
    """builtin_interfaces/Duration for a non-negative number of seconds, rounded to 1 ns."""
    return get_constructor('builtin_interfaces/msg/Duration')(
        *divmod(int(round(seconds * 1e9)), _NS_PER_S))


def duration_msg_to_seconds(msg) -> float:
    """Seconds of a builtin_interfaces/Duration."""
    return int(msg.sec) + int(msg.nanosec) * 1e-9


def yaw_to_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by ``yaw_rad`` about z."""
    return (0.0, 0.0, math.sin(0.5 * yaw_rad), math.cos(0.5 * yaw_rad))


def quaternion_to_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw [rad] of a quaternion (the z-y-x Euler angle about z), in (-pi, pi]."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def base_transforms(msg) -> list:
    """The ``odom -> base_link`` transforms of a tf2_msgs/TFMessage: the floating base's pose.

    /tf carries other transforms too (the links' of robot_state_publisher): readers pick the
    base pose by its frame ids.
    """
    return [transform for transform in msg.transforms
            if transform.header.frame_id.lstrip('/') == WORLD_FRAME
            and transform.child_frame_id.lstrip('/') == BASE_FRAME]


def _frozen(array) -> np.ndarray:
    result = np.array(array, dtype=float)
    result.setflags(write=False)
    return result


def _check_finite(values: np.ndarray, what: str) -> None:
    if not np.isfinite(values).all():
        raise ContractError(f'{what} holds a NaN or infinite value')


def _check_frame(header, what: str) -> None:
    if header.frame_id != WORLD_FRAME:
        raise ContractError(f'{what} is in frame {header.frame_id!r}; the contract frame is '
                            f'{WORLD_FRAME!r}')


def _header(stamp_ns: int, frame_id: str = WORLD_FRAME):
    return get_constructor('std_msgs/msg/Header')(ns_to_time_msg(stamp_ns), frame_id)


def _transform(position: Sequence[float], yaw_rad: float):
    x, y, z = position
    return get_constructor('geometry_msgs/msg/Transform')(
        get_constructor('geometry_msgs/msg/Vector3')(float(x), float(y), float(z)),
        get_constructor('geometry_msgs/msg/Quaternion')(*yaw_to_quaternion(float(yaw_rad))))


def _transform_values(msg) -> tuple[list[float], float]:
    t, r = msg.translation, msg.rotation
    x, y, z, w = r.x, r.y, r.z, r.w
    # The yaw formula holds for unit quaternions only; a zero, NaN or infinite one has no yaw.
    if not abs(x * x + y * y + z * z + w * w - 1.0) <= UNIT_QUATERNION_TOLERANCE:
        raise ContractError(f'rotation ({x!r}, {y!r}, {z!r}, {w!r}) is not a unit quaternion: '
                            f'|q|^2 must be within {UNIT_QUATERNION_TOLERANCE:g} of 1')
    return [t.x, t.y, t.z], quaternion_to_yaw(x, y, z, w)


def _twist(linear: Sequence[float], angular_z: float = 0.0):
    vector = get_constructor('geometry_msgs/msg/Vector3')
    x, y, z = linear
    return get_constructor('geometry_msgs/msg/Twist')(vector(float(x), float(y), float(z)),
                                                      vector(0.0, 0.0, float(angular_z)))


# -- /gait/footsteps -------------------------------------------------------------------------


@dataclass(frozen=True)
class Swing:
    """One swing of one foot, read off a :class:`FootstepPlan`.

    Attributes:
        foot: Foot name.
        lift_off_s: Lift-off time from the plan start [s].
        touch_down_s: Touch-down time from the plan start [s].
        start_in_world: Lift-off position (3,) in odom [m].
        end_in_world: Landing position (3,) in odom [m].
        start_yaw_rad: Foot yaw at lift-off [rad].
        end_yaw_rad: Foot yaw at landing [rad].
    """

    foot: str
    lift_off_s: float
    touch_down_s: float
    start_in_world: np.ndarray
    end_in_world: np.ndarray
    start_yaw_rad: float
    end_yaw_rad: float

    @property
    def duration_s(self) -> float:
        """Swing time [s]."""
        return self.touch_down_s - self.lift_off_s


@dataclass(frozen=True)
class FootstepPlan:
    """Planned foot placements at each contact change.

    Attributes:
        start_ns: Plan start time [ns] (ROS time of ``time_from_start = 0``).
        foot_names: Foot names, in the robot YAML's order.
        times_s: (K,) contact-change times from the start [s], non-decreasing.
        positions_in_world: (K, F, 3) foot positions at each time [m].
        yaws_rad: (K, F) foot yaw at each time [rad].
    """

    start_ns: int
    foot_names: tuple[str, ...]
    times_s: np.ndarray
    positions_in_world: np.ndarray
    yaws_rad: np.ndarray
    _swings: tuple[Swing, ...] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        times = _frozen(self.times_s)
        positions = _frozen(self.positions_in_world)
        yaws = _frozen(self.yaws_rad)
        count, feet = len(times), len(self.foot_names)
        if count < 1 or feet < 1:
            raise ContractError(f'a footstep plan needs at least one point and one foot, got '
                                f'{count} points and {feet} feet')
        if positions.shape != (count, feet, 3) or yaws.shape != (count, feet):
            raise ContractError(f'footstep plan shapes disagree: times ({count},), positions '
                                f'{positions.shape}, yaws {yaws.shape} for {feet} feet')
        if len(set(self.foot_names)) != feet:
            raise ContractError(f'foot names repeat: {list(self.foot_names)}')
        _check_finite(times, 'footstep times')
        _check_finite(positions, 'footstep positions')
        _check_finite(yaws, 'footstep yaws')
        if np.any(np.diff(times) < 0):
            raise ContractError('footstep times go backwards')
        object.__setattr__(self, 'foot_names', tuple(self.foot_names))
        object.__setattr__(self, 'times_s', times)
        object.__setattr__(self, 'positions_in_world', positions)
        object.__setattr__(self, 'yaws_rad', yaws)

    @property
    def end_s(self) -> float:
        """Time of the last contact change from the start [s]."""
        return float(self.times_s[-1])

    def moved(self) -> np.ndarray:
        """(K-1, F) booleans: foot ``f`` swings over ``[t_k, t_{k+1}]``."""
        step = np.linalg.norm(np.diff(self.positions_in_world, axis=0), axis=2)
        turn = np.abs(np.angle(np.exp(1j * np.diff(self.yaws_rad, axis=0))))
        return (step > SAME_PLACE_TOLERANCE) | (turn > SAME_PLACE_TOLERANCE)

    def swings(self) -> tuple[Swing, ...]:
        """Every swing in the plan, ordered by lift-off time then foot order."""
        if self._swings is None:
            found = []
            for k, f in zip(*np.nonzero(self.moved()), strict=True):
                found.append(Swing(
                    foot=self.foot_names[f],
                    lift_off_s=float(self.times_s[k]),
                    touch_down_s=float(self.times_s[k + 1]),
                    start_in_world=self.positions_in_world[k, f],
                    end_in_world=self.positions_in_world[k + 1, f],
                    start_yaw_rad=float(self.yaws_rad[k, f]),
                    end_yaw_rad=float(self.yaws_rad[k + 1, f]),
                ))
            found.sort(key=lambda s: (s.lift_off_s, self.foot_names.index(s.foot)))
            object.__setattr__(self, '_swings', tuple(found))
        return self._swings

    def contacts_at(self, t_s: float) -> np.ndarray:
        """(F,) booleans: which feet are on the ground at ``t_s`` from the start.

        At an instant shared by a touch-down and a lift-off both feet count as down.
        """
        down = np.ones(len(self.foot_names), dtype=bool)
        for swing in self.swings():
            if swing.lift_off_s < t_s < swing.touch_down_s:
                down[self.foot_names.index(swing.foot)] = False
        return down

    def index_at(self, t_s: float) -> int:
        """Index of the last point at or before ``t_s`` (0 before the start)."""
        return max(int(np.searchsorted(self.times_s, t_s, side='right')) - 1, 0)

    def stance_positions_at(self, t_s: float) -> np.ndarray:
        """(F, 3) positions: stance feet where they stand, swing feet at their lift-off place."""
        return self.positions_in_world[self.index_at(t_s)]


def footsteps_to_msg(plan: FootstepPlan):
    """trajectory_msgs/MultiDOFJointTrajectory for ``plan`` (layout in the module docstring)."""
    point_type = get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectoryPoint')
    positions, yaws = plan.positions_in_world.tolist(), plan.yaws_rad.tolist()
    points = [point_type([_transform(p, y) for p, y in zip(positions[k], yaws[k], strict=True)],
                         [], [], seconds_to_duration_msg(t_s))
              for k, t_s in enumerate(plan.times_s.tolist())]
    return get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectory')(
        _header(plan.start_ns), list(plan.foot_names), points)


def footsteps_from_msg(msg) -> FootstepPlan:
    """The :class:`FootstepPlan` of a /gait/footsteps message; ContractError if malformed."""
    _check_frame(msg.header, '/gait/footsteps')
    feet = len(msg.joint_names)
    if not msg.points:
        raise ContractError('/gait/footsteps has no points')
    times, positions, yaws = [], [], []
    for k, point in enumerate(msg.points):
        if len(point.transforms) != feet:
            raise ContractError(f'/gait/footsteps point {k} has {len(point.transforms)} '
                                f'transforms for {feet} feet')
        times.append(duration_msg_to_seconds(point.time_from_start))
        row = [_transform_values(t) for t in point.transforms]
        positions.append([p for p, _ in row])
        yaws.append([y for _, y in row])
    return FootstepPlan(time_msg_to_ns(msg.header.stamp), tuple(msg.joint_names),
                        np.array(times), np.array(positions), np.array(yaws))


# -- /gait/zmp_reference ---------------------------------------------------------------------


@dataclass(frozen=True)
class ZmpReference:
    """Samples of the ZMP reference, linear in time between samples.

    Attributes:
        stamps_ns: (N,) sample times [ns], strictly increasing.
        zmp_in_world: (N, 2) ZMP reference in odom [m].
        plane_heights_m: (N,) height of the plane each sample lies on [m] (the lowest contact);
            None: zeros (flat ground).
    """

    stamps_ns: np.ndarray
    zmp_in_world: np.ndarray
    plane_heights_m: np.ndarray | None = None

    def __post_init__(self):
        stamps = np.array(self.stamps_ns, dtype=np.int64)
        stamps.setflags(write=False)
        zmp = _frozen(self.zmp_in_world)
        if len(stamps) < 1:
            raise ContractError('the ZMP reference is empty')
        if zmp.shape != (len(stamps), 2):
            raise ContractError(f'ZMP reference shape {zmp.shape} for {len(stamps)} stamps')
        _check_finite(zmp, 'the ZMP reference')
        if (stamps[1:] <= stamps[:-1]).any():  # (np.diff could overflow int64)
            raise ContractError('ZMP reference stamps are not strictly increasing')
        heights = _frozen(np.zeros(len(stamps)) if self.plane_heights_m is None
                          else self.plane_heights_m)
        if heights.shape != (len(stamps),):
            raise ContractError(f'ZMP reference plane heights shape {heights.shape} for '
                                f'{len(stamps)} stamps')
        _check_finite(heights, 'the ZMP reference plane heights')
        object.__setattr__(self, 'stamps_ns', stamps)
        object.__setattr__(self, 'zmp_in_world', zmp)
        object.__setattr__(self, 'plane_heights_m', heights)

    def followed_by(self, shift: int, stamps_ns: Sequence[int], zmp_in_world,
                    plane_heights_m=None) -> ZmpReference:
        """This reference from its sample ``shift`` on, followed by new samples (a window slid).

        Equal to ``ZmpReference`` of the concatenated arrays (this reference's plane heights,
        zeros for new samples without heights; the same checks in the same order, hence the
        same :class:`ContractError`), but only the new samples and their junction are checked
        (the kept ones were checked when this reference was made), and the arrays are
        read-only views of a buffer the successive windows fill (:class:`_WindowBuffer`): a
        few samples written per window, not the whole window copied. The result remembers
        where it came from, so that :meth:`ZmpReferenceMessages.to_msg` reuses the kept
        samples' poses without comparing them.

        Args:
            shift: Samples dropped at the start, in [0, N].
            stamps_ns: (M,) stamps of the new samples [ns].
            zmp_in_world: (M, 2) their ZMP reference in odom [m].
            plane_heights_m: (M,) their plane heights [m]; None: zeros.
        """
        count = len(self.stamps_ns)
        stamps, flat, heights = _sample_lists(stamps_ns, zmp_in_world, plane_heights_m)
        if not 0 <= shift <= count or (shift == count and not stamps):
            raise ContractError(f'a ZMP reference of {count} samples slid by {shift} with '
                                f'{len(stamps)} new samples')
        if not all(map(math.isfinite, flat)):
            raise ContractError('the ZMP reference holds a NaN or infinite value')
        before = int(self.stamps_ns[-1]) if shift < count else stamps[0] - 1
        for stamp in stamps:
            if stamp <= before:
                raise ContractError('ZMP reference stamps are not strictly increasing')
            before = stamp
        if not all(map(math.isfinite, heights)):
            raise ContractError('the ZMP reference plane heights holds a NaN or infinite value')
        window = self.__dict__.get('_window')
        if window is None or not window[0].can_append(window[2], len(stamps)):
            buffer = _WindowBuffer(4 * (count - shift + len(stamps)))
            buffer.append_arrays(self.stamps_ns[shift:], self.zmp_in_world[shift:],
                                 self.plane_heights_m[shift:])
            start = 0
        else:
            buffer, start, _ = window
            start += shift
        stop = buffer.append(stamps, flat, heights)
        result = object.__new__(ZmpReference)
        # (frozen: the fields set in the instance's dict, as object.__setattr__ would)
        result.__dict__.update(stamps_ns=buffer.stamps_read_only[start:stop],
                               zmp_in_world=buffer.zmp_read_only[start:stop],
                               plane_heights_m=buffer.heights_read_only[start:stop],
                               _window=(buffer, start, stop),
                               _slid_from=(weakref.ref(self), shift))
        return result

    def corners(self, tolerance_m: float = 1e-9) -> ZmpReference:
        """The same reference with only the samples where it bends (and both ends).

        A sample on the straight line of its two neighbours (time against ZMP and plane
        height, within ``tolerance_m`` [m]) says nothing that linear interpolation of the
        others does not: a planner's piecewise-linear reference sampled every 10 ms is a few
        corners per step, which is what goes on the wire (every consumer interpolates
        linearly between the poses of /gait/zmp_reference).
        """
        if len(self.stamps_ns) < 3:
            return self
        t = (self.stamps_ns - self.stamps_ns[0]) * 1e-9
        values = np.column_stack([self.zmp_in_world, self.plane_heights_m])
        weight = (t[1:-1] - t[:-2]) / (t[2:] - t[:-2])
        between = values[:-2] + (values[2:] - values[:-2]) * weight[:, None]
        keep = np.ones(len(t), dtype=bool)
        keep[1:-1] = np.abs(values[1:-1] - between).max(axis=1) > tolerance_m
        if keep.all():
            return self
        return ZmpReference(self.stamps_ns[keep], self.zmp_in_world[keep],
                            self.plane_heights_m[keep])

    @property
    def horizon_s(self) -> float:
        """Time from the first to the last sample [s]."""
        return (int(self.stamps_ns[-1]) - int(self.stamps_ns[0])) * 1e-9

    def sample(self, stamps_ns: np.ndarray) -> np.ndarray:
        """(M, 2) reference at ``stamps_ns``, linear between samples, held beyond the ends."""
        known = self.__dict__.get('_known_s')
        if known is None:  # the samples' times from the first one, worked out once
            known = (self.stamps_ns - self.stamps_ns[0]) * 1e-9
            object.__setattr__(self, '_known_s', known)
        t = (np.asarray(stamps_ns, dtype=np.int64) - self.stamps_ns[0]) * 1e-9
        result = np.empty((len(t), 2))  # (the columns of np.stack, for fewer numpy calls)
        result[:, 0] = np.interp(t, known, self.zmp_in_world[:, 0])
        result[:, 1] = np.interp(t, known, self.zmp_in_world[:, 1])
        return result


def _sample_lists(stamps_ns, zmp_in_world, plane_heights_m
                  ) -> tuple[list[int], list[float], list[float]]:
    """New ZMP reference samples as lists: stamps [ns], flat ``x0, y0, x1, ...`` [m], heights.

    A list of Python ints with a list of (x, y) tuples of Python floats (the planner's slid
    windows, the reader's new poses) is taken as it is; anything else goes through numpy
    (``np.asarray`` with the dtypes of :class:`ZmpReference`), which gives the same values
    for such lists. Shapes are checked (:class:`ContractError`).
    """
    flat = None
    if type(stamps_ns) is list and type(zmp_in_world) is list \
            and len(zmp_in_world) == len(stamps_ns):
        stamps, flat = stamps_ns, []
        for stamp, row in zip(stamps_ns, zmp_in_world, strict=True):
            if type(stamp) is int and type(row) is tuple and len(row) == 2 \
                    and type(row[0]) is float and type(row[1]) is float:
                flat += row
            else:
                flat = None
                break
    if flat is None:
        stamps = np.asarray(stamps_ns, dtype=np.int64).tolist()
        zmp = np.asarray(zmp_in_world, dtype=float)
        if zmp.shape != (len(stamps), 2):
            raise ContractError(f'new ZMP reference samples of shape {zmp.shape} for '
                                f'{len(stamps)} stamps')
        flat = zmp.ravel().tolist()
    if plane_heights_m is None:
        heights = [0.0] * len(stamps)
    elif type(plane_heights_m) is list and len(plane_heights_m) == len(stamps) \
            and all(type(value) is float for value in plane_heights_m):
        heights = plane_heights_m
    else:
        values = np.asarray(plane_heights_m, dtype=float)
        if values.shape != (len(stamps),):
            raise ContractError(f'new ZMP reference plane heights of shape {values.shape} for '
                                f'{len(stamps)} stamps')
        heights = values.tolist()
    return stamps, flat, heights


class _WindowBuffer:
    """Storage of successive windows of a ZMP reference (:meth:`ZmpReference.followed_by`).

    Each window is a slice of the read-only views of these arrays; new samples are written
    past the last window's end, which no earlier window covers, so no window ever changes. A
    window that does not end where the filled part ends (a second slide of the same window) or
    does not fit starts a new buffer.

    Args:
        size: Samples it holds.
    """

    #: Samples written one element at a time (numpy's slice assignment from a list costs
    #: about as much as 20 element assignments).
    _ELEMENTWISE = 8

    def __init__(self, size: int):
        self.stamps_ns = np.empty(size, dtype=np.int64)
        self.zmp_in_world = np.empty((size, 2))
        self.plane_heights_m = np.empty(size)
        self._zmp_flat = self.zmp_in_world.reshape(-1)  # (a view: x0, y0, x1, y1, ...)
        self.stamps_read_only, self.zmp_read_only, self.heights_read_only = (
            self.stamps_ns.view(), self.zmp_in_world.view(), self.plane_heights_m.view())
        for view in (self.stamps_read_only, self.zmp_read_only, self.heights_read_only):
            view.setflags(write=False)  # (and so is every slice of them)
        self.end = 0  # samples written

    def can_append(self, stop: int, count: int) -> bool:
        """Whether ``count`` samples fit after a window ending at ``stop`` (the filled end)."""
        return stop == self.end and self.end + count <= len(self.stamps_ns)

    def append_arrays(self, stamps_ns: np.ndarray, zmp_in_world: np.ndarray,
                      plane_heights_m: np.ndarray) -> int:
        """Write (M,), (M, 2), (M,) arrays at the filled end; the new end."""
        start, stop = self.end, self.end + len(stamps_ns)
        self.stamps_ns[start:stop] = stamps_ns
        self.zmp_in_world[start:stop] = zmp_in_world
        self.plane_heights_m[start:stop] = plane_heights_m
        self.end = stop
        return stop

    def append(self, stamps_ns: list[int], zmp_flat: list[float],
               plane_heights_m: list[float]) -> int:
        """Write samples given as lists (:func:`_sample_lists`) at the filled end; the new end."""
        start, stop = self.end, self.end + len(stamps_ns)
        if len(stamps_ns) <= self._ELEMENTWISE:
            stamps, zmp, heights = self.stamps_ns, self._zmp_flat, self.plane_heights_m
            k = start
            for stamp, height in zip(stamps_ns, plane_heights_m, strict=True):
                stamps[k] = stamp
                heights[k] = height
                k += 1
            k = 2 * start
            for value in zmp_flat:
                zmp[k] = value
                k += 1
        else:
            self.stamps_ns[start:stop] = stamps_ns
            self._zmp_flat[2 * start:2 * stop] = zmp_flat
            self.plane_heights_m[start:stop] = plane_heights_m
        self.end = stop
        return stop


def zmp_reference_to_msg(reference: ZmpReference):
    """nav_msgs/Path for ``reference`` (layout in the module docstring): a new message."""
    return ZmpReferenceMessages(share_constants=False).to_msg(reference)


class ZmpReferenceMessages:
    """Builds the successive /gait/zmp_reference messages of one publisher, sharing poses.

    Consecutive references of a planner share most samples: a pose equal to the previous
    message's at the same stamp (same point, bit for bit) is that same PoseStamped object, not a
    copy, which saves building hundreds of small objects per message. The poses also share one
    identity Quaternion, and the Path's header is its first pose's (the same values). For a
    publisher that never edits a message it built (subscribers treat received messages as
    read-only, the ROS 2 intra-process rule); :func:`zmp_reference_to_msg` gives independent
    messages.

    Args:
        share_constants: Share the identity orientation and the header as above (False: every
            part of a message is its own object; poses are still shared between messages).
    """

    def __init__(self, share_constants: bool = True):
        self._share = share_constants
        self._constructors = (None,)
        self._reference: ZmpReference | None = None  # the last message's reference
        self._poses: list = []  # and its poses

    def to_msg(self, reference: ZmpReference):
        """nav_msgs/Path for ``reference`` (layout in the module docstring)."""
        path = get_constructor('nav_msgs/msg/Path')
        if self._constructors[0] is not path:  # first message, or another runtime's classes
            self._constructors = (path, *map(get_constructor, (
                'geometry_msgs/msg/PoseStamped', 'std_msgs/msg/Header',
                'builtin_interfaces/msg/Time', 'geometry_msgs/msg/Pose',
                'geometry_msgs/msg/Point', 'geometry_msgs/msg/Quaternion')))
            self._identity = self._constructors[-1](0.0, 0.0, 0.0, 1.0)
            self._reference = None
        _, pose_stamped, header, time, pose, point, quaternion = self._constructors
        stamps = reference.stamps_ns
        last = self._reference
        slid = reference.__dict__.get('_slid_from')
        reused = None
        if last is not None and slid is not None and slid[0]() is last:
            # Slid from the last message's reference (ZmpReference.followed_by): its samples
            # from ``shift`` on are this one's first samples, the same values.
            poses = self._poses[slid[1]:]
        elif last is not None:
            # Samples equal to the previous message's from the same stamp on (stamps increase),
            # bit for bit (0.0 and -0.0 are different samples).
            bits = np.column_stack((reference.zmp_in_world, reference.plane_heights_m))
            last_bits = np.column_stack((last.zmp_in_world, last.plane_heights_m))
            reused = np.zeros(len(stamps), dtype=bool)
            offset = int(np.searchsorted(last.stamps_ns, stamps[0]))
            if offset < len(last.stamps_ns):
                overlap = min(len(last.stamps_ns) - offset, len(stamps))
                window = slice(offset, offset + overlap)
                reused[:overlap] = ((last.stamps_ns[window] == stamps[:overlap])
                                    & (last_bits[window].view(np.int64)
                                       == bits[:overlap].view(np.int64)).all(axis=1))
            # The leading run of reused samples is one slice of the previous list.
            run = len(reused) if reused.all() else int(np.argmin(reused))
            poses = self._poses[offset:offset + run]
            reused = reused.tolist()
        else:
            poses = []
        first = len(poses)
        if first < len(stamps):  # the new poses, from the samples as Python ints and floats
            for k, stamp, (x, y), z in zip(
                    count(first), stamps[first:].tolist(),
                    reference.zmp_in_world[first:].tolist(),
                    reference.plane_heights_m[first:].tolist(), strict=False):
                if reused is not None and reused[k]:
                    poses.append(self._poses[offset + k])
                    continue
                poses.append(pose_stamped(
                    header(time(*divmod(stamp, _NS_PER_S)), WORLD_FRAME),
                    pose(point(x, y, z), self._identity if self._share
                         else quaternion(0.0, 0.0, 0.0, 1.0))))
        if self._share:
            top = poses[0].header  # (the Path's stamp is its first sample's)
        else:
            top = header(time(*divmod(int(stamps[0]), _NS_PER_S)), WORLD_FRAME)
        self._reference, self._poses = reference, poses
        return path(top, poses)


def zmp_reference_from_msg(msg) -> ZmpReference:
    """The :class:`ZmpReference` of a /gait/zmp_reference Path; :class:`ContractError` if bad."""
    _check_frame(msg.header, '/gait/zmp_reference')
    poses = msg.poses
    if not poses:
        raise ContractError('/gait/zmp_reference has no poses')
    stamps, zmp, heights = _pose_samples(poses)
    return ZmpReference(stamps, zmp, heights)


def _pose_samples(poses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stamps (N,) [ns], points (N, 2) and plane heights (N,) of /gait/zmp_reference poses.

    Their frames are checked.
    """
    headers = [p.header for p in poses]
    for frame_id in dict.fromkeys(h.frame_id for h in headers):
        if frame_id not in ('', WORLD_FRAME):
            raise ContractError(f'a /gait/zmp_reference pose is in frame {frame_id!r}; the '
                                f'contract frame is {WORLD_FRAME!r}')
    stamps = [h.stamp.sec * _NS_PER_S + h.stamp.nanosec for h in headers]
    points = [p.pose.position for p in poses]
    zmp = np.ascontiguousarray(np.array([[p.x for p in points], [p.y for p in points]]).T)
    return (np.array(stamps, dtype=np.int64), zmp,
            np.array([p.z for p in points], dtype=float))


def _pose_lists(poses) -> tuple[list[int], list[tuple[float, float]], list[float]]:
    """:func:`_pose_samples` as lists (the same values, the same frame check), for a few poses."""
    stamps, zmp, heights = [], [], []
    for pose in poses:
        header = pose.header
        if header.frame_id not in ('', WORLD_FRAME):
            raise ContractError(f'a /gait/zmp_reference pose is in frame {header.frame_id!r}; '
                                f'the contract frame is {WORLD_FRAME!r}')
        stamps.append(header.stamp.sec * _NS_PER_S + header.stamp.nanosec)
        point = pose.pose.position
        zmp.append((point.x, point.y))
        heights.append(point.z)
    return stamps, zmp, heights


class ZmpReferenceReader:
    """Decodes the successive /gait/zmp_reference messages of a subscription, reusing work.

    Gives exactly what :func:`zmp_reference_from_msg` gives (the same reference, the same
    :class:`ContractError`) for any message, but a message whose leading poses are the very
    objects (``is``) of the previous good message's, as :class:`ZmpReferenceMessages` publishes
    them, costs only the decoding of its new tail: those poses were read, checked and found
    good last time. Relies on the rule that a published message is not edited (received
    messages are read-only, as under rclpy's intra-process communication): the previous
    message's pose list is kept, not copied. A message deserialized from the wire never shares
    poses, so it is decoded whole.
    """

    def __init__(self):
        self._poses: Sequence = ()
        self._reference: ZmpReference | None = None

    def read(self, msg) -> ZmpReference:
        """The :class:`ZmpReference` of ``msg``; :class:`ContractError` if bad."""
        _check_frame(msg.header, '/gait/zmp_reference')
        poses = msg.poses
        if not poses:
            raise ContractError('/gait/zmp_reference has no poses')
        previous, run = self._poses, 0
        # Where the first pose was in the previous message, then how far the two stay the same.
        offset = next(compress(count(), map(operator.is_, repeat(poses[0]), previous)), None)
        if offset is not None:
            kept = previous[offset:]
            # (all() over map(is_) first: the usual case, every kept pose the same object,
            # without the new int per pose of counting the run off as it goes)
            run = min(len(poses), len(kept)) if all(map(operator.is_, poses, kept)) \
                else next(compress(count(), map(operator.is_not, poses, kept)))
        if run == 0:
            reference = zmp_reference_from_msg(msg)
        elif offset + run == len(previous) and len(poses) - run <= _FEW_POSES:
            # The usual slid window: the known samples from ``offset`` on, then a few new
            # ones, checked as ZmpReference would check them (followed_by), in plain floats.
            reference = self._reference.followed_by(offset, *_pose_lists(poses[run:]))
        else:
            reference = self._extend(self._reference, offset, run, poses[run:])
        self._poses, self._reference = poses, reference
        return reference

    @staticmethod
    def _extend(known: ZmpReference, offset: int, run: int, tail) -> ZmpReference:
        """``known``'s samples ``offset:offset + run`` followed by the decoded ``tail``."""
        stamps = known.stamps_ns[offset:offset + run]
        zmp = known.zmp_in_world[offset:offset + run]
        heights = known.plane_heights_m[offset:offset + run]
        if len(tail):
            tail_stamps, tail_zmp, tail_heights = _pose_samples(tail)
            tail_zmp = np.array(tail_zmp, dtype=float)
            _check_finite(tail_zmp, 'the ZMP reference')
            if tail_stamps[0] <= stamps[-1] or (tail_stamps[1:] <= tail_stamps[:-1]).any():
                raise ContractError('ZMP reference stamps are not strictly increasing')
            _check_finite(tail_heights, 'the ZMP reference plane heights')
            stamps = np.concatenate((stamps, tail_stamps))
            zmp = np.concatenate((zmp, tail_zmp))
            heights = np.concatenate((heights, tail_heights))
        else:
            stamps, zmp, heights = stamps.copy(), zmp.copy(), heights.copy()
        # Checked samples followed by checked samples later than them: a valid reference.
        stamps.setflags(write=False)
        zmp.setflags(write=False)
        heights.setflags(write=False)
        reference = object.__new__(ZmpReference)
        object.__setattr__(reference, 'stamps_ns', stamps)
        object.__setattr__(reference, 'zmp_in_world', zmp)
        object.__setattr__(reference, 'plane_heights_m', heights)
        return reference


# -- /gait/com_reference ---------------------------------------------------------------------


@dataclass(frozen=True)
class ComState:
    """COM reference at one instant.

    Attributes:
        stamp_ns: Time [ns].
        position_in_world: (3,) COM position [m].
        velocity_in_world: (3,) COM velocity [m/s].
        acceleration_in_world: (3,) COM acceleration [m/s^2].
        yaw_rad: Body yaw [rad].
        yaw_rate_rad_s: Body yaw rate [rad/s].
    """

    stamp_ns: int
    position_in_world: np.ndarray
    velocity_in_world: np.ndarray
    acceleration_in_world: np.ndarray
    yaw_rad: float = 0.0
    yaw_rate_rad_s: float = 0.0

    def __post_init__(self):
        names = ('position_in_world', 'velocity_in_world', 'acceleration_in_world')
        try:  # the usual case at once: three finite 3-vectors (rows of one read-only array)
            rows = np.array([self.position_in_world, self.velocity_in_world,
                             self.acceleration_in_world], dtype=float)
        except (TypeError, ValueError):
            rows = None
        if rows is not None and rows.shape == (3, 3) \
                and all(map(math.isfinite, rows.ravel().tolist())):
            rows.setflags(write=False)
            for name, row in zip(names, rows, strict=True):
                object.__setattr__(self, name, row)
        else:  # one vector at a time, to name the first bad one
            for name in names:
                value = _frozen(getattr(self, name))
                if value.shape != (3,):
                    raise ContractError(f'COM {name} must have 3 components, got '
                                        f'{value.shape}')
                _check_finite(value, f'the COM {name}')
                object.__setattr__(self, name, value)
        if not (math.isfinite(self.yaw_rad) and math.isfinite(self.yaw_rate_rad_s)):
            raise ContractError('the COM reference yaw holds a NaN or infinite value')


def com_reference_to_msg(states: Sequence[ComState]):
    """MultiDOFJointTrajectory with ``states[0]`` at the header stamp and the rest as horizon."""
    if not states:
        raise ContractError('a COM reference needs at least one state')
    point_type = get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectoryPoint')
    start_ns = states[0].stamp_ns
    points = [point_type([_transform(state.position_in_world.tolist(), state.yaw_rad)],
                         [_twist(state.velocity_in_world.tolist(), state.yaw_rate_rad_s)],
                         [_twist(state.acceleration_in_world.tolist())],
                         seconds_to_duration_msg((state.stamp_ns - start_ns) * 1e-9))
              for state in states]
    return get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectory')(
        _header(start_ns), [COM_JOINT_NAME], points)


class ComReferenceMessages:
    """Builds the /gait/com_reference messages of a publisher, from plain floats.

    The controller publishes, every period, the window of its committed states from the
    latest one at or before now to the end of what it has computed: :meth:`window_to_msg`
    gives the message of ``com_reference_to_msg([ComState(...), ...])`` field by field, but
    without the ComStates' arrays and with the message constructors looked up once (a node
    lives in one runtime); :meth:`to_msg` is the one-state case. A non-finite value goes
    through :class:`ComState`, which raises its :class:`ContractError`.

    Parts that do not change are built once and shared by the messages: the joint names, the
    zero ``time_from_start``, the zero angular acceleration (and angular velocity at a zero yaw
    rate), the rotation while the yaw stays the same (bit for bit: -0.0 is another yaw), and
    the transform and twists of a state that the previous message carried at the same stamp
    with the same values (a committed state is in several successive windows; only its
    ``time_from_start`` changes). For a publisher that never edits a message it built (the
    inproc and rclpy intra-process rule; a DDS subscriber gets its own copy), as
    :class:`ZmpReferenceMessages`.
    """

    def __init__(self):
        names = ('trajectory_msgs/msg/MultiDOFJointTrajectory',
                 'trajectory_msgs/msg/MultiDOFJointTrajectoryPoint', 'std_msgs/msg/Header',
                 'builtin_interfaces/msg/Time', 'builtin_interfaces/msg/Duration',
                 'geometry_msgs/msg/Transform', 'geometry_msgs/msg/Twist',
                 'geometry_msgs/msg/Vector3', 'geometry_msgs/msg/Quaternion')
        self._constructors = tuple(map(get_constructor, names))
        _, _, _, _, duration, _, _, vector, _ = self._constructors
        self._joint_names = [COM_JOINT_NAME]
        self._zero_duration = duration(0, 0)
        self._zero = vector(0.0, 0.0, 0.0)
        self._yaw = (math.nan, 0.0)  # (yaw [rad], its sign) of self._rotation
        self._rotation = None
        self._parts: dict[int, tuple] = {}  # stamp [ns] -> (values, point parts) last sent

    def to_msg(self, stamp_ns: int, position_in_world: Sequence[float],
               velocity_in_world: Sequence[float], acceleration_in_world: Sequence[float],
               yaw_rad: float = 0.0, yaw_rate_rad_s: float = 0.0):
        """MultiDOFJointTrajectory with the one state at ``stamp_ns`` [ns] (module docstring).

        Args:
            stamp_ns: Time of the state [ns].
            position_in_world: (x, y, z) COM position [m].
            velocity_in_world: (x, y, z) COM velocity [m/s].
            acceleration_in_world: (x, y, z) COM acceleration [m/s^2].
            yaw_rad: Body yaw [rad].
            yaw_rate_rad_s: Body yaw rate [rad/s].
        """
        values = (*position_in_world, *velocity_in_world, *acceleration_in_world, yaw_rad,
                  yaw_rate_rad_s)
        if len(values) != 11:
            return com_reference_to_msg([ComState(
                stamp_ns, position_in_world, velocity_in_world, acceleration_in_world, yaw_rad,
                yaw_rate_rad_s)])
        return self.window_to_msg([stamp_ns], [values])

    def window_to_msg(self, stamps_ns: Sequence[int], states: Sequence[Sequence[float]]):
        """MultiDOFJointTrajectory of several states, the first at the header stamp.

        Args:
            stamps_ns: (N,) times of the states [ns], strictly increasing, N >= 1.
            states: N rows ``(px, py, pz, vx, vy, vz, ax, ay, az, yaw, yaw_rate)``: COM
                position [m], velocity [m/s], acceleration [m/s^2], body yaw [rad] and yaw
                rate [rad/s].

        Raises:
            ContractError: No state, stamps not strictly increasing, a row of another length
                or a non-finite value (ComState's message).
        """
        if not len(stamps_ns) or len(stamps_ns) != len(states):
            raise ContractError(f'a COM reference needs one state per stamp and at least one, '
                                f'got {len(states)} states for {len(stamps_ns)} stamps')
        trajectory, point, header, time, duration, _, _, _, _ = self._constructors
        start_ns = int(stamps_ns[0])
        previous_ns = start_ns - 1
        known, parts = self._parts, {}
        points = []
        for stamp_ns, values in zip(stamps_ns, states, strict=True):
            stamp_ns = int(stamp_ns)
            if stamp_ns <= previous_ns:
                raise ContractError('COM reference stamps are not strictly increasing')
            previous_ns = stamp_ns
            entry = known.get(stamp_ns)
            if entry is None or entry[0] != values:
                entry = (values, self._point_parts(stamp_ns, values))
            parts[stamp_ns] = entry
            offset_ns = stamp_ns - start_ns
            points.append(point(*entry[1], duration(*divmod(offset_ns, _NS_PER_S))
                                if offset_ns else self._zero_duration))
        self._parts = parts
        return trajectory(header(time(*divmod(start_ns, _NS_PER_S)), WORLD_FRAME),
                          self._joint_names, points)

    def _point_parts(self, stamp_ns: int, values: Sequence[float]) -> tuple[list, list, list]:
        """([transform], [velocity twist], [acceleration twist]) of one checked state."""
        values = tuple(values)
        if len(values) != 11:
            raise ContractError(f'a COM state is 11 values (position, velocity, acceleration, '
                                f'yaw, yaw rate), got {len(values)}')
        if not all(map(math.isfinite, values)):  # ComState names the first bad one
            ComState(stamp_ns, values[0:3], values[3:6], values[6:9], values[9], values[10])
        _, _, _, _, _, transform, twist, vector, quaternion = self._constructors
        px, py, pz, vx, vy, vz, ax, ay, az, yaw_rad, rate = map(float, values)
        yaw = (yaw_rad, math.copysign(1.0, yaw_rad))
        if yaw != self._yaw:
            self._yaw = yaw
            self._rotation = quaternion(0.0, 0.0, math.sin(0.5 * yaw_rad),
                                        math.cos(0.5 * yaw_rad))
        zero = self._zero
        return ([transform(vector(px, py, pz), self._rotation)],
                [twist(vector(vx, vy, vz), zero if rate == 0.0 and math.copysign(1.0, rate) > 0
                       else vector(0.0, 0.0, rate))],
                [twist(vector(ax, ay, az), zero)])


def com_reference_from_msg(msg) -> list[ComState]:
    """The states of a /gait/com_reference message; :class:`ContractError` if malformed."""
    _check_frame(msg.header, '/gait/com_reference')
    if list(msg.joint_names) != [COM_JOINT_NAME]:
        raise ContractError(f'/gait/com_reference joint_names must be [{COM_JOINT_NAME!r}], got '
                            f'{list(msg.joint_names)}')
    if not msg.points:
        raise ContractError('/gait/com_reference has no points')
    start_ns = time_msg_to_ns(msg.header.stamp)
    states = []
    for k, point in enumerate(msg.points):
        if (len(point.transforms), len(point.velocities), len(point.accelerations)) != (1, 1, 1):
            raise ContractError(f'/gait/com_reference point {k} must carry one transform, '
                                f'velocity and acceleration')
        position, yaw = _transform_values(point.transforms[0])
        v, a = point.velocities[0], point.accelerations[0]
        offset = point.time_from_start
        states.append(ComState(
            stamp_ns=start_ns + int(offset.sec) * _NS_PER_S + int(offset.nanosec),
            position_in_world=position,
            velocity_in_world=[v.linear.x, v.linear.y, v.linear.z],
            acceleration_in_world=[a.linear.x, a.linear.y, a.linear.z],
            yaw_rad=yaw,
            yaw_rate_rad_s=v.angular.z,
        ))
        if k and states[-1].stamp_ns <= states[-2].stamp_ns:
            raise ContractError(f'/gait/com_reference point {k} is not later than point {k - 1}: '
                                f'time_from_start must increase strictly')
    return states


# -- /gait/swing_trajectory ------------------------------------------------------------------


@dataclass(frozen=True)
class SwingTrajectory:
    """Timed waypoints of one foot's swing.

    Attributes:
        foot: Foot name.
        start_ns: Lift-off time [ns].
        times_s: (W,) waypoint times from lift-off [s], non-decreasing, first 0.
        positions_in_world: (W, 3) waypoints [m].
        yaws_rad: (W,) foot yaw at each waypoint [rad].
    """

    foot: str
    start_ns: int
    times_s: np.ndarray
    positions_in_world: np.ndarray
    yaws_rad: np.ndarray

    def __post_init__(self):
        times = _frozen(self.times_s)
        positions = _frozen(self.positions_in_world)
        yaws = _frozen(self.yaws_rad)
        if len(times) < 2:
            raise ContractError(f'a swing trajectory needs at least 2 waypoints, got {len(times)}')
        if positions.shape != (len(times), 3) or yaws.shape != (len(times),):
            raise ContractError(f'swing trajectory shapes disagree: times {times.shape}, '
                                f'positions {positions.shape}, yaws {yaws.shape}')
        _check_finite(times, 'swing times')
        _check_finite(positions, 'swing waypoints')
        _check_finite(yaws, 'swing yaws')
        if np.any(np.diff(times) < 0) or times[0] < 0:
            raise ContractError('swing waypoint times must start at >= 0 and not go backwards')
        object.__setattr__(self, 'times_s', times)
        object.__setattr__(self, 'positions_in_world', positions)
        object.__setattr__(self, 'yaws_rad', yaws)

    @property
    def duration_s(self) -> float:
        """Lift-off to touch-down [s]."""
        return float(self.times_s[-1])


def swing_trajectory_to_msg(swing: SwingTrajectory):
    """MultiDOFJointTrajectory for one swing (layout in the module docstring)."""
    point_type, transform, vector, quaternion, duration = map(get_constructor, (
        'trajectory_msgs/msg/MultiDOFJointTrajectoryPoint', 'geometry_msgs/msg/Transform',
        'geometry_msgs/msg/Vector3', 'geometry_msgs/msg/Quaternion',
        'builtin_interfaces/msg/Duration'))
    # Hundreds of waypoints: the constructors looked up once, then _transform's and
    # seconds_to_duration_msg's arithmetic on the list's floats.
    points = [point_type([transform(vector(x, y, z), quaternion(0.0, 0.0, math.sin(0.5 * yaw),
                                                                math.cos(0.5 * yaw)))],
                         [], [], duration(*divmod(int(round(t_s * 1e9)), _NS_PER_S)))
              for t_s, (x, y, z), yaw in zip(swing.times_s.tolist(),
                                             swing.positions_in_world.tolist(),
                                             swing.yaws_rad.tolist(), strict=True)]
    return get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectory')(
        _header(swing.start_ns), [swing.foot], points)


def swing_trajectory_from_msg(msg) -> SwingTrajectory:
    """The :class:`SwingTrajectory` of a /gait/swing_trajectory message; ContractError if bad."""
    _check_frame(msg.header, '/gait/swing_trajectory')
    if len(msg.joint_names) != 1:
        raise ContractError(f'/gait/swing_trajectory names one foot, got {list(msg.joint_names)}')
    times, positions, yaws = [], [], []
    for k, point in enumerate(msg.points):
        if len(point.transforms) != 1:
            raise ContractError(f'/gait/swing_trajectory point {k} must carry one transform')
        position, yaw = _transform_values(point.transforms[0])
        times.append(duration_msg_to_seconds(point.time_from_start))
        positions.append(position)
        yaws.append(yaw)
    return SwingTrajectory(msg.joint_names[0], time_msg_to_ns(msg.header.stamp),
                           np.array(times), np.array(positions).reshape(-1, 3), np.array(yaws))


# -- /joint_commands -------------------------------------------------------------------------


@dataclass(frozen=True)
class JointTrajectoryCommand:
    """A /joint_commands trajectory, validated (layout in the module docstring).

    Attributes:
        stamp_ns: ``header.stamp`` [ns]: the absolute time of ``time_from_start`` 0; 0 means
            "start when received".
        joint_names: The joints the trajectory commands, unique.
        times_from_start_ns: (N,) int64, strictly increasing, >= 0 [ns].
        positions_rad: (N, J) positions, one row per point [rad or m], read-only.
        velocities_rad_s: (N, J) velocities [rad/s or m/s], read-only, or None (positions only).
        accelerations_rad_s2: (N, J) accelerations [rad/s^2 or m/s^2], read-only, or None.
    """

    stamp_ns: int
    joint_names: tuple[str, ...]
    times_from_start_ns: np.ndarray
    positions_rad: np.ndarray
    velocities_rad_s: np.ndarray | None = None
    accelerations_rad_s2: np.ndarray | None = None

    def times_ns(self, received_ns: int) -> np.ndarray:
        """(N,) absolute times of the points [ns]; a zero stamp counts from ``received_ns``."""
        return self.times_from_start_ns + (self.stamp_ns if self.stamp_ns else received_ns)


def _point_rows(rows: list, field_name: str, count: int, required: bool) -> np.ndarray | None:
    """(N, count) read-only array of one field of every point, or None if empty in all.

    Args:
        rows: The field (a sequence of numbers) of each point.
        field_name: Its name, for the errors.
        count: Number of joint names.
        required: Whether the field may be empty (in every point alike).

    Raises:
        ContractError: A point's field is neither ``count`` values nor (where ``required`` is
            False) empty in every point, or a value is NaN or infinite.
    """
    sizes = set(map(len, rows))
    if not required and sizes == {0}:
        return None
    if sizes != {count}:
        k = next(k for k, row in enumerate(rows) if len(row) != count)
        allowed = f'{count}' if required else f'0 (in every point) or {count}'
        raise ContractError(f'point {k} has {len(rows[k])} {field_name} for {count} joint '
                            f'names; allowed: {allowed}')
    # fromiter over the chained rows: half the cost of np.array's look at every nested list.
    array = np.fromiter(chain.from_iterable(rows), float, len(rows) * count).reshape(
        len(rows), count)
    finite = np.isfinite(array)
    if not finite.all():
        k = int(np.flatnonzero(~finite.all(axis=1))[0])
        raise ContractError(f'point {k} {field_name} hold a NaN or infinite value')
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class ContactWrench:
    """One foot's contact wrench (``/gait/contact_wrench/<foot>``).

    Attributes:
        stamp_ns: End of the interval it averages [ns].
        frame: The foot frame it is expressed in.
        force: (3,) ground force on the foot, in the foot frame [N].
        torque: (3,) its moment about the foot frame's origin, in the foot frame [N m].
    """

    stamp_ns: int
    frame: str
    force: np.ndarray
    torque: np.ndarray


def contact_wrench_to_msg(stamp_ns: int, frame: str, wrench: Sequence[float]):
    """WrenchStamped of a foot's ``(fx, fy, fz, tx, ty, tz)`` [N, N m] in its ``frame``."""
    new_vector = get_constructor('geometry_msgs/msg/Vector3')
    fx, fy, fz, tx, ty, tz = (float(v) for v in wrench)
    return get_constructor('geometry_msgs/msg/WrenchStamped')(
        _header(stamp_ns, frame), get_constructor('geometry_msgs/msg/Wrench')(
            new_vector(fx, fy, fz), new_vector(tx, ty, tz)))


def contact_wrench_from_msg(msg) -> ContactWrench:
    """The :class:`ContactWrench` of a WrenchStamped; ContactError if not finite or unframed."""
    if not msg.header.frame_id:
        raise ContractError('a contact wrench needs the foot frame in header.frame_id')
    force = _frozen([msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z])
    torque = _frozen([msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z])
    _check_finite(np.concatenate([force, torque]), 'contact wrench')
    return ContactWrench(time_msg_to_ns(msg.header.stamp), msg.header.frame_id, force, torque)


def joint_trajectory_from_msg(msg, known_joints: Sequence[str] | None = None
                              ) -> JointTrajectoryCommand:
    """The validated trajectory of a /joint_commands JointTrajectory.

    The checks are those a ros2_control joint_trajectory_controller makes before it accepts a
    trajectory (a bad message is refused whole).

    Args:
        msg: trajectory_msgs/msg/JointTrajectory.
        known_joints: The joints a follower has; None accepts any names.

    Raises:
        ContractError: No joint names, a repeated or unknown one; no points; ``time_from_start``
            negative or not strictly increasing; positions not one per joint name; velocities
            or accelerations neither empty nor one per joint name; an effort; a NaN or
            infinite value.
    """
    names = tuple(msg.joint_names)
    if not names:
        raise ContractError('a joint trajectory names no joints')
    if len(set(names)) != len(names):
        repeated = sorted({n for n in names if names.count(n) > 1})
        raise ContractError(f'joint names repeat: {repeated}')
    if known_joints is not None and names != tuple(known_joints):
        known = set(known_joints)
        unknown = [n for n in names if n not in known]
        if unknown:
            raise ContractError(f'unknown joints {unknown[:5]}; joints: {list(known_joints)}')
    points = msg.points
    if not len(points):
        raise ContractError('a joint trajectory has no points')
    times, positions, velocities, accelerations = [], [], [], []
    for k, point in enumerate(points):
        duration = point.time_from_start
        times.append(duration.sec * _NS_PER_S + duration.nanosec)
        positions.append(point.positions)
        velocities.append(point.velocities)
        accelerations.append(point.accelerations)
        if len(point.effort):
            raise ContractError(f'point {k} carries efforts; allowed: none (positions, '
                                f'velocities, accelerations)')
    if times[0] < 0:
        raise ContractError(f'time_from_start of point 0 is {times[0] * 1e-9} s; allowed: >= 0')
    for k in range(1, len(times)):
        if times[k] <= times[k - 1]:
            raise ContractError(f'time_from_start not strictly increasing: point {k} at '
                                f'{times[k] * 1e-9} s after point {k - 1} at '
                                f'{times[k - 1] * 1e-9} s')
    count = len(names)
    times_ns = np.array(times, dtype=np.int64)
    times_ns.setflags(write=False)
    return JointTrajectoryCommand(
        time_msg_to_ns(msg.header.stamp), names, times_ns,
        _point_rows(positions, 'positions', count, required=True),
        _point_rows(velocities, 'velocities', count, required=False),
        _point_rows(accelerations, 'accelerations', count, required=False))


def joint_trajectory_to_msg(joint_names: list[str], times_ns: list[int],
                            positions: list[list[float]],
                            velocities: list[list[float]] | None = None,
                            accelerations: list[list[float]] | None = None):
    """trajectory_msgs/JointTrajectory of knots, as a joint_trajectory_controller takes it.

    Args:
        joint_names: The joints, each once (the list is put in the message as it is).
        times_ns: (N,) knot times [ns], strictly increasing, N >= 1: ``header.stamp`` is the
            first, each point's ``time_from_start`` its time after the first.
        positions: (N, J) joint positions [rad], J = ``len(joint_names)``.
        velocities: (N, J) joint velocities [rad/s], or None (none sent).
        accelerations: (N, J) joint accelerations [rad/s^2], or None (none sent).

    The lists are put in the message as they are (published messages are read-only); the
    caller vouches for the sizes and the order of the times, which this does not check
    (:func:`joint_trajectory_from_msg` does, as a controller would).
    """
    new_duration = get_constructor('builtin_interfaces/msg/Duration')
    new_point = get_constructor('trajectory_msgs/msg/JointTrajectoryPoint')
    start_ns = times_ns[0]
    empty = [[]] * len(times_ns)
    points = [new_point(p, v, a, [], new_duration(*divmod(t - start_ns, _NS_PER_S)))
              for t, p, v, a in zip(times_ns, positions, velocities or empty,
                                    accelerations or empty, strict=True)]
    return get_constructor('trajectory_msgs/msg/JointTrajectory')(
        _header(start_ns, ''), joint_names, points)


def joint_trajectory_command_to_msg(command: JointTrajectoryCommand):
    """trajectory_msgs/JointTrajectory of ``command`` (the inverse of the reader)."""
    def rows(array):
        return None if array is None else array.tolist()

    start_ns = command.stamp_ns
    return joint_trajectory_to_msg(
        list(command.joint_names), (command.times_from_start_ns + start_ns).tolist(),
        command.positions_rad.tolist(), rows(command.velocities_rad_s),
        rows(command.accelerations_rad_s2))
