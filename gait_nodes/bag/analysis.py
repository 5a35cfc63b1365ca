"""What ``inspect`` computes from a bag: topic statistics and, for gait bags, gait metrics.

Every number is recomputed from the recorded messages with the definitions below, so that an
independent reader of the bag can check it:

- ``duration_s``: last minus first log time over all messages; topic ``rate_hz``:
  ``(count - 1) / (last - first log time)`` of that topic.
- ``distance_m``: path length of ``odom -> base_link`` (from ``/tf``) in the ground plane;
  ``displacement_m``: straight-line distance from its first to its last position;
  ``net_speed_m_s``: ``displacement_m`` over the time between those two samples (header
  stamps; :func:`net_speed`), the speed at which the robot advanced, sway excluded;
  ``path_speed_m_s``: ``distance_m`` over the same time (sway included);
  ``rise_m``: height of the last base position above the first (stairs climbed).
- ``steady``: the net speed of the walk without its start: over whole gait cycles, from the
  second lift-off of the foot that swung most (of equals, the last by name) to its last
  lift-off (each foot swings once a cycle, so the interval holds whole cycles, the first one
  excluded); with the robot YAML's ``extra.reference_speed`` (a published figure to compare
  with) when it has one.
- ``steps``: each swing executed by the time the bag ends (the latest /gait/footsteps version of
  it, see :class:`gait_nodes.contract.FootstepPlan`); a step's length is the horizontal distance
  from its lift-off place to its landing place.
- ``zmp_margin``: for each ``/gait/zmp`` sample, the signed distance (positive inside) to the
  latest ``/gait/support_polygon`` stamped at or before it (:func:`gait_nodes.geometry.
  signed_distance`); ``time_outside_s`` sums, over samples outside, the time to the next sample.
- ``joint_velocity``: peak ``|velocity|`` in ``/joint_states`` (and ``/joint_commands``) per
  joint, against the robot YAML's limit when the robot is known (``--robot``, or the
  ``hardware_id`` of the bag's diagnostics). ``/joint_commands`` (JointTrajectory) counts as
  the trajectory a joint_trajectory_controller follows: every point of each message until the
  next message's first point replaces the rest (points at header stamp + time_from_start).
- ``commands``: ``/gait/command_status`` answers per command: decisions (accepted, rejected with
  their reasons, superseded), 'applied' answers, repeats (:func:`command_answers`).
- ``diagnostics``: statuses on ``/diagnostics`` counted by level and by name.
- ``consistency``: the nodes' outputs checked against each other with the robot's full model
  (COM reached vs asked, ZMP by inverse dynamics vs the monitor's, feet vs footsteps, stance
  slip): :mod:`gait_nodes.bag.consistency`.
"""

from __future__ import annotations

import bisect
import itertools
import json
import math
import struct
from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from operator import attrgetter
from pathlib import Path

import numpy as np

from gait_nodes import contract
from gait_nodes.bag.reader import BagReader
from gait_nodes.diagnostics import LEVEL_NAMES, level_value
from gait_nodes.errors import ConfigError, GaitNodesError
from gait_nodes.geometry import convex_hull, signed_distance
from gait_nodes.graph import TOPICS, contract_topics, graph_namespaces
from gait_nodes.interfaces import deserialize_message, get_message

#: Samples of each /gait/zmp_reference window kept in the series: its first 0.2 s (the next
#: window replaces them from its own first sample on) [ns].
ZMP_REFERENCE_KEPT_NS = 200_000_000

#: (x, y) of a point message.
_XY = attrgetter('x', 'y')

#: Topics whose messages inspect decodes (when their type is the contract's).
GAIT_TOPICS = ('/tf', '/gait/zmp', '/gait/com', '/gait/support_polygon', '/gait/footsteps',
               '/gait/zmp_reference', '/gait/com_reference', '/gait/swing_trajectory',
               '/joint_states', '/joint_commands', '/gait/command_status', '/diagnostics',
               '/gait/cop')


@dataclass
class JointSeries:
    """Joint samples of one JointState topic, or the points of a JointTrajectory topic."""

    names: list[str] = field(default_factory=list)
    stamps_ns: list[int] = field(default_factory=list)
    positions: list[list[float]] = field(default_factory=list)
    velocities: list[list[float]] = field(default_factory=list)


@dataclass
class GaitSeries:
    """Decoded time series of a gait bag, for metrics and plots (stamps in [ns])."""

    base: list[tuple[int, float, float, float, float]] = field(default_factory=list)
    base_poses: list[tuple[int, float, float, float, float, float, float, float]] = field(
        default_factory=list)
    zmp_plane_height_m: float | None = None
    zmp_plane_heights_m: dict[int, float] = field(default_factory=dict)
    zmp: list[tuple[int, float, float]] = field(default_factory=list)
    com: list[tuple[int, float, float, float]] = field(default_factory=list)
    cop: list[tuple[int, float, float, float]] = field(default_factory=list)
    polygons: list[tuple[int, np.ndarray]] = field(default_factory=list)
    zmp_reference: list[tuple[int, float, float]] = field(default_factory=list)
    zmp_reference_last: contract.ZmpReference | None = None
    com_reference: list[tuple[int, float, float, float]] = field(default_factory=list)
    plans: list[contract.FootstepPlan] = field(default_factory=list)
    swings: list[contract.SwingTrajectory] = field(default_factory=list)
    joints: dict[str, JointSeries] = field(default_factory=dict)
    statuses: list[dict] = field(default_factory=list)
    diagnostics: list[tuple[int, str, int, str, str]] = field(default_factory=list)
    undecodable: Counter = field(default_factory=Counter)


def _stamp(header) -> int:
    return contract.time_msg_to_ns(header.stamp)


class _Collector:
    """Decodes the gait topics of a bag into a :class:`GaitSeries`."""

    def __init__(self):
        self.series = GaitSeries()
        self._classes = {}
        #: The vertices (their bytes) of the last support polygon read and its hull (None:
        #: not a polygon).
        self._last_polygon: tuple[bytes, np.ndarray | None] | None = None

    def message(self, topic: str, type_name: str, data: bytes) -> None:
        if TOPICS.get(topic) != type_name:
            return
        cls = self._classes.get(type_name)
        if cls is None:
            cls = self._classes[type_name] = get_message(type_name)
        try:
            msg = deserialize_message(data, cls)
            getattr(self, '_' + topic.strip('/').replace('/', '_'))(msg)
        except (GaitNodesError, ValueError, IndexError, UnicodeDecodeError, struct.error,
                TypeError):
            self.series.undecodable[topic] += 1

    def _tf(self, msg) -> None:
        for transform in contract.base_transforms(msg):
            t, r = transform.transform.translation, transform.transform.rotation
            stamp = _stamp(transform.header)
            self.series.base.append((stamp, t.x, t.y, t.z,
                                     contract.quaternion_to_yaw(r.x, r.y, r.z, r.w)))
            self.series.base_poses.append((stamp, t.x, t.y, t.z, r.x, r.y, r.z, r.w))

    def _gait_zmp(self, msg) -> None:
        stamp = _stamp(msg.header)
        self.series.zmp.append((stamp, msg.point.x, msg.point.y))
        # The plane follows the contacts (stairs): each sample's z is its plane's height.
        self.series.zmp_plane_height_m = msg.point.z
        self.series.zmp_plane_heights_m[stamp] = msg.point.z

    def _gait_com(self, msg) -> None:
        self.series.com.append((_stamp(msg.header), msg.point.x, msg.point.y, msg.point.z))

    def _gait_cop(self, msg) -> None:
        self.series.cop.append((_stamp(msg.header), msg.point.x, msg.point.y, msg.point.z))

    def _gait_support_polygon(self, msg) -> None:
        # The polygon changes with the contacts only (a few times a cycle, published at
        # 100 Hz): a message with the very same vertices as the last one, bit for bit, shares
        # its hull, computed once (or its refusal, for a NaN or infinite vertex).
        xy = np.fromiter(itertools.chain.from_iterable(map(_XY, msg.polygon.points)), float)
        key = xy.tobytes()
        if self._last_polygon is None or self._last_polygon[0] != key:
            vertices = xy.reshape(-1, 2)
            usable = len(vertices) and np.all(np.isfinite(vertices))
            self._last_polygon = (key, convex_hull(vertices) if usable else None)
        hull = self._last_polygon[1]
        if hull is not None:
            self.series.polygons.append((_stamp(msg.header), hull))

    def _gait_zmp_reference(self, msg) -> None:
        reference = contract.zmp_reference_from_msg(msg)
        # Each window's samples up to the next window's first (the planner publishes at
        # 10 Hz: its first samples alone would miss the corners in between).
        series = self.series.zmp_reference
        first_ns = int(reference.stamps_ns[0])
        while series and series[-1][0] >= first_ns:
            series.pop()
        stamps = reference.stamps_ns.tolist()
        until = bisect.bisect_right(stamps, first_ns + ZMP_REFERENCE_KEPT_NS)
        series.extend((stamp, x, y) for stamp, (x, y) in zip(
            stamps[:until], reference.zmp_in_world[:until].tolist(), strict=True))
        self.series.zmp_reference_last = reference

    def _gait_com_reference(self, msg) -> None:
        # A window of committed states: it replaces what is held from its first state on, as
        # the whole-body IK takes it (older windows' states stay).
        states = contract.com_reference_from_msg(msg)
        series = self.series.com_reference
        while series and series[-1][0] >= states[0].stamp_ns:
            series.pop()
        series.extend((state.stamp_ns, *state.position_in_world) for state in states)

    def _gait_footsteps(self, msg) -> None:
        self.series.plans.append(contract.footsteps_from_msg(msg))

    def _gait_swing_trajectory(self, msg) -> None:
        self.series.swings.append(contract.swing_trajectory_from_msg(msg))

    def _joints(self, name: str, msg) -> None:
        series = self.series.joints.setdefault(name, JointSeries())
        names = list(msg.name)
        if series.names and names != series.names:
            return  # a different joint set: keep the first one consistent
        series.names = names
        series.stamps_ns.append(_stamp(msg.header))
        series.positions.append(list(msg.position))
        series.velocities.append(list(msg.velocity))

    def _joint_states(self, msg) -> None:
        self._joints('/joint_states', msg)

    def _joint_commands(self, msg) -> None:
        """The commanded trajectory as followed: a message replaces it from its first point on.

        (ros2_control's rule; a zero header stamp, "start when received", is read as time 0.)
        Bags from before /joint_commands was a trajectory hold JointState setpoints.
        """
        if not hasattr(msg, 'points'):
            self._joints('/joint_commands', msg)
            return
        series = self.series.joints.setdefault('/joint_commands', JointSeries())
        names = list(msg.joint_names)
        if not msg.points or (series.names and names != series.names):
            return  # nothing, or a different joint set: keep the first one consistent
        series.names = names
        start_ns = _stamp(msg.header)
        times_ns = [start_ns + contract.time_msg_to_ns(p.time_from_start) for p in msg.points]
        stamps = series.stamps_ns
        kept = len(stamps)
        while kept and stamps[kept - 1] >= times_ns[0]:
            kept -= 1
        for values in (stamps, series.positions, series.velocities):
            del values[kept:]
        stamps.extend(times_ns)
        series.positions.extend(list(p.positions) for p in msg.points)
        series.velocities.extend(list(p.velocities) for p in msg.points)

    def _gait_command_status(self, msg) -> None:
        try:
            status = json.loads(msg.data)
        except json.JSONDecodeError:
            status = {'accepted': None, 'reason': 'status is not JSON', 'raw': msg.data}
        self.series.statuses.append(status if isinstance(status, dict) else {'raw': status})

    def _diagnostics(self, msg) -> None:
        stamp = _stamp(msg.header)
        for status in msg.status:
            self.series.diagnostics.append((stamp, status.name, level_value(status.level),
                                            status.message, status.hardware_id))


def _round(value: float, digits: int = 6):
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def net_speed(base: np.ndarray, start_ns: float | None = None,
              end_ns: float | None = None) -> float | None:
    """Net speed of the base [m/s]: its horizontal displacement over the time it took.

    Sway and back-and-forth motion do not count, only where the base got to.

    Args:
        base: Base positions by time, rows ``(stamp [ns], x, y, z)`` sorted by stamp (as
            :attr:`GaitSeries.base`).
        start_ns: Start of the interval [ns] (default: the first sample); positions between
            samples are interpolated linearly.
        end_ns: End of the interval [ns] (default: the last sample).

    Returns:
        The speed, or None when the interval is empty.
    """
    start = base[0, 0] if start_ns is None else start_ns
    end = base[-1, 0] if end_ns is None else end_ns
    if len(base) < 2 or end <= start:
        return None
    x0, x1 = np.interp([start, end], base[:, 0], base[:, 1])
    y0, y1 = np.interp([start, end], base[:, 0], base[:, 2])
    return float(np.hypot(x1 - x0, y1 - y0) / ((end - start) * 1e-9))


def base_metrics(series: GaitSeries) -> dict | None:
    """Distance, displacement and speeds (net and along the path) of the base from /tf."""
    if len(series.base) < 2:
        return None
    base = np.array(sorted(series.base))
    xy = base[:, 1:3]
    distance = float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1)))
    elapsed = (base[-1, 0] - base[0, 0]) * 1e-9
    return {'source': '/tf odom->base_link', 'samples': len(base),
            'distance_m': _round(distance),
            'displacement_m': _round(float(np.linalg.norm(xy[-1] - xy[0]))),
            'time_s': _round(elapsed),
            'net_speed_m_s': _round(net_speed(base)),
            'path_speed_m_s': _round(distance / elapsed) if elapsed > 0 else None,
            'rise_m': _round(float(base[-1, 3] - base[0, 3]))}


def executed_swings(plans: list[contract.FootstepPlan], until_ns: int | None) -> list[dict]:
    """Swings landed by ``until_ns``: each plan's swings until the next plan takes over.

    A plan starts at the last contact change before it was published, so a swing of one plan
    that lifts off at or after the next plan's start was planned again by the next one (and may
    have moved in time: a velocity change re-times the steps not yet started); it is the next
    plan's version that was walked. A swing is identified by its foot and lift-off time (to
    1 ms); a later plan's version of the same swing replaces an earlier one's.
    """
    by_key = {}
    for index, plan in enumerate(plans):
        following = plans[index + 1].start_ns if index + 1 < len(plans) else None
        for swing in plan.swings():
            lift_ns = plan.start_ns + int(round(swing.lift_off_s * 1e9))
            land_ns = plan.start_ns + int(round(swing.touch_down_s * 1e9))
            if (following is not None and lift_ns >= following) or \
                    (until_ns is not None and land_ns > until_ns):
                continue
            by_key[(swing.foot, round(lift_ns / 1e6))] = (lift_ns, land_ns, swing)
    swings = []
    for lift_ns, land_ns, swing in sorted(by_key.values(), key=lambda v: (v[0], v[2].foot)):
        length = float(np.linalg.norm((swing.end_in_world - swing.start_in_world)[:2]))
        swings.append({'foot': swing.foot, 'lift_off_ns': lift_ns, 'touch_down_ns': land_ns,
                       'start': swing.start_in_world.tolist(),
                       'end': swing.end_in_world.tolist(), 'end_yaw_rad': swing.end_yaw_rad,
                       'length_m': length})
    return swings


def step_metrics(series: GaitSeries, until_ns: int | None) -> dict | None:
    """Step count and lengths of the executed swings."""
    if not series.plans:
        return None
    swings = executed_swings(series.plans, until_ns)
    lengths = np.array([s['length_m'] for s in swings])
    per_foot = defaultdict(list)
    for swing in swings:
        per_foot[swing['foot']].append(swing['length_m'])
    return {'count': len(swings),
            'mean_length_m': _round(lengths.mean()) if len(lengths) else None,
            'min_length_m': _round(lengths.min()) if len(lengths) else None,
            'max_length_m': _round(lengths.max()) if len(lengths) else None,
            'per_foot': {foot: {'count': len(v), 'mean_length_m': _round(float(np.mean(v)))}
                         for foot, v in per_foot.items()}}


def steady_metrics(series: GaitSeries, until_ns: int | None) -> dict | None:
    """Net speed over whole gait cycles after the first (see the module docstring)."""
    if not series.plans or len(series.base) < 2:
        return None
    lift_offs = defaultdict(list)
    for swing in executed_swings(series.plans, until_ns):
        lift_offs[swing['foot']].append(swing['lift_off_ns'])
    if not lift_offs:
        return None
    foot, times = max(lift_offs.items(), key=lambda item: (len(item[1]), item[0]))
    if len(times) < 3:
        return None
    base = np.array(sorted(series.base))
    start, end = times[1], times[-1]
    return {'foot': foot, 'cycles': len(times) - 2, 'from_s': _round((start - base[0, 0]) * 1e-9),
            'to_s': _round((end - base[0, 0]) * 1e-9),
            'net_speed_m_s': _round(net_speed(base, start, end))}


def zmp_margins(series: GaitSeries) -> tuple[np.ndarray, np.ndarray]:
    """(stamps [ns], margins [m]) of each /gait/zmp sample that has a polygon before it."""
    if not series.zmp or not series.polygons:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    zmp = sorted(series.zmp)
    polygons = sorted(series.polygons, key=lambda p: p[0])
    polygon_stamps = np.array([p[0] for p in polygons], dtype=np.int64)
    stamps = np.array([z[0] for z in zmp], dtype=np.int64)
    points = np.array([(z[1], z[2]) for z in zmp])
    which = np.searchsorted(polygon_stamps, stamps, side='right') - 1
    keep = which >= 0
    # The samples of equal polygons (published again and again until the contacts change) in
    # one signed_distance call, under the first copy's index: a point's margin does not
    # depend on the other points.
    first_copy: dict[bytes, int] = {}
    copy_of = np.array([first_copy.setdefault(np.asarray(hull, dtype=float).tobytes(), index)
                        for index, (_, hull) in enumerate(polygons)], dtype=np.intp)
    which = np.where(keep, copy_of[which], -1)
    margins = np.full(len(zmp), np.nan)
    for index in np.unique(which[keep]):
        chosen = which == index
        margins[chosen] = signed_distance(points[chosen], polygons[index][1])
    return stamps[keep], margins[keep]


def margin_metrics(series: GaitSeries) -> dict | None:
    """Min and mean stability margin and the time the ZMP spent outside the support polygon."""
    stamps, margins = zmp_margins(series)
    if len(margins) == 0:
        return None
    durations = np.append(np.diff(stamps), 0) * 1e-9
    outside = margins < 0
    first_outside = int(stamps[np.argmax(outside)]) if outside.any() else None
    return {'samples': len(margins), 'min_m': _round(margins.min()),
            'mean_m': _round(margins.mean()),
            'time_outside_s': _round(float(durations[outside].sum())),
            'samples_outside': int(outside.sum()),
            'first_outside_ns': first_outside}


def robot_limits(robot: str | None) -> tuple[str | None, Callable[[str], float | None]]:
    """The robot's name and a joint -> velocity limit lookup (None when unknown)."""
    if not robot:
        return None, lambda joint: None
    from gait_nodes.robot.description import load_robot_description

    try:
        description = load_robot_description(robot)
    except ConfigError:
        return robot, lambda joint: None
    joints = set(description.joint_names)
    return description.name, lambda joint: (description.velocity_limit_rad_s(joint)
                                            if joint in joints else None)


def reference_speed(robot: str | None) -> dict | None:
    """The robot YAML's ``extra.reference_speed`` (``m_s``, ``ft_min``, ``source``), if any."""
    if not robot:
        return None
    from gait_nodes.robot.description import load_robot_description

    try:
        reference = load_robot_description(robot).extra.get('reference_speed')
    except ConfigError:
        return None
    if not isinstance(reference, dict) or 'ft_min' not in reference:
        return None
    ft_min = float(reference['ft_min'])
    return {'ft_min': ft_min, 'm_s': _round(ft_min * 0.3048 / 60.0),
            'source': str(reference.get('source', ''))}


def joint_metrics(series: GaitSeries, limit_of: Callable[[str], float | None]) -> dict:
    """Peak joint speed per JointState topic, against the limits."""
    result = {}
    for topic, joints in series.joints.items():
        rows = [v for v in joints.velocities if len(v) == len(joints.names)]
        if not rows or not joints.names:
            continue
        speeds = np.abs(np.array(rows, dtype=float))
        peaks = np.nanmax(speeds, axis=0)
        worst = int(np.nanargmax(peaks))
        limits = [limit_of(name) for name in joints.names]
        ratios = [p / lim if lim else None for p, lim in zip(peaks, limits, strict=True)]
        known = [r for r in ratios if r is not None]
        over = sum(int(np.sum(speeds[:, i] > lim * (1 + 1e-9)))
                   for i, lim in enumerate(limits) if lim)
        result[topic] = {
            'samples': len(rows),
            'peak_rad_s': _round(peaks[worst]), 'peak_joint': joints.names[worst],
            'limit_rad_s': limits[worst],
            'peak_ratio_to_limit': _round(max(known)) if known else None,
            'samples_over_limit': over if known else None,
            'per_joint_peak_rad_s': {n: _round(p) for n, p in zip(joints.names, peaks,
                                                                 strict=True)},
        }
    return result


def command_metrics(series: GaitSeries) -> dict | None:
    """The gait commands' answers (see :func:`command_answers`)."""
    if not series.statuses:
        return None
    return command_answers(series.statuses)


def command_answers(statuses: list[dict]) -> dict:
    """What /gait/command_status said, per command (its ``id``).

    ``answered``: commands answered (distinct ids; a status without an id, from an older bag,
    counts alone); ``accepted``, ``rejected``, ``superseded``: their decisions; ``applied``:
    accepted commands that said they took effect; ``repeated``: answers to a repeated id;
    ``rescheduled``: answers moving an accepted command's boundary (a later stop re-planned it);
    ``most_decisions`` and ``most_applied``: the most decisions (and 'applied' answers) one
    command got, 1 when every command was decided (applied) once; ``rejections``: the
    rejected commands' reasons.
    """
    decisions: dict[object, list[dict]] = {}
    applied: dict[object, int] = {}
    repeated = rescheduled = 0
    for k, status in enumerate(statuses):
        key = status.get('id', ('no id', k))
        state = status.get('state') or ('accepted' if status.get('accepted') else 'rejected')
        if status.get('repeated'):
            repeated += 1
        elif state == 'applied':
            applied[key] = applied.get(key, 0) + 1
        elif state == 'rescheduled':
            rescheduled += 1
        else:
            decisions.setdefault(key, []).append({**status, 'state': state})
    first = [answers[0] for answers in decisions.values()]
    rejected = [s for s in first if s['state'] == 'rejected']
    return {'answered': len(decisions),
            'accepted': sum(1 for s in first if s['state'] == 'accepted'),
            'rejected': len(rejected),
            'superseded': sum(1 for s in first if s['state'] == 'superseded'),
            'applied': len(applied), 'repeated': repeated, 'rescheduled': rescheduled,
            'most_decisions': max((len(a) for a in decisions.values()), default=0),
            'most_applied': max(applied.values(), default=0),
            'rejections': [str(s.get('reason', '')) for s in rejected]}


def diagnostic_metrics(series: GaitSeries) -> dict | None:
    """Diagnostic statuses by level and by name."""
    if not series.diagnostics:
        return None
    by_level = Counter(LEVEL_NAMES.get(level, str(level)) for _, _, level, _, _
                       in series.diagnostics)
    by_name = defaultdict(Counter)
    for _, name, level, _, _ in series.diagnostics:
        by_name[name][LEVEL_NAMES.get(level, str(level))] += 1
    errors = [(stamp, name, message) for stamp, name, level, message, _ in series.diagnostics
              if level == 2]
    return {'by_level': dict(by_level),
            'by_name': {name: dict(counts) for name, counts in sorted(by_name.items())},
            'first_error': ({'stamp_ns': errors[0][0], 'name': errors[0][1],
                             'message': errors[0][2]} if errors else None)}


def hardware_id(series: GaitSeries) -> str | None:
    """The robot named by the bag's diagnostics, if any."""
    names = Counter(hw for *_, hw in series.diagnostics if hw)
    return names.most_common(1)[0][0] if names else None


@dataclass
class Inspection:
    """The result of reading a bag: the JSON report and the series behind it."""

    report: dict
    series: GaitSeries


def bag_namespace(topics, namespace: str | None = None) -> str:
    """The namespace of the gait graph whose topics ``topics`` are (``/`` for none).

    ``namespace`` given: that one, made absolute. Otherwise the namespace with the most contract
    topics (``/robot1`` for ``/robot1/gait/footsteps``...).

    Raises:
        GaitNodesError: The topics are those of several graphs in as many namespaces.
    """
    if namespace:
        return namespace if namespace.startswith('/') else '/' + namespace
    counts = graph_namespaces(topics)
    if not counts:
        return '/'
    most = max(counts.values())
    best = sorted(name for name, count in counts.items() if count == most)
    if len(best) > 1:
        raise GaitNodesError(f'the bag holds the gait topics of {len(best)} graphs, in '
                             f'namespaces {", ".join(best)}: choose one with --namespace')
    return best[0]


def _known_topics(reader: BagReader) -> set[str]:
    """The topics a bag declares so far: its channels read and its metadata.yaml's."""
    topics = {channel.topic for channel in reader.channels.values()}
    info = (reader.metadata or {}).get('rosbag2_bagfile_information') or {}
    for entry in info.get('topics_with_message_count') or []:
        name = (entry.get('topic_metadata') or {}).get('name')
        if isinstance(name, str):
            topics.add(name)
    return topics


def inspect_bag(path: str | Path, robot: str | None = None,
                progress: Callable[[int], None] | None = None,
                namespace: str | None = None) -> Inspection:
    """Read a bag once and compute its report (see the module docstring for the definitions).

    Args:
        path: Bag directory or ``.mcap`` file.
        robot: Robot name or YAML for joint limits (default: the diagnostics' hardware_id).
        progress: Called with the number of bytes read since the last call.
        namespace: The ROS namespace of the graph to analyse (``/robot1`` for a bag of
            ``/robot1/gait/...`` topics). Default: the bag's, detected from its topics.

    Raises:
        NotABagError: The path is not a bag.
        GaitNodesError: The bag holds several namespaced graphs and ``namespace`` is None.
    """
    reader = BagReader(path)
    collector = _Collector()
    counts = Counter()
    first, last = {}, {}
    types = {}
    # Bag topic -> contract topic, decided once the bag's channels are known (the first
    # message comes after them in a recorder's bag); a channel that comes later is added.
    names: dict[str, str] | None = None
    for channel, log_ns, _, data in reader.messages(progress=progress):
        topic = channel.topic
        counts[topic] += 1
        if topic not in first:
            first[topic] = log_ns
            types[topic] = channel.type_name
            if names is not None and topic not in names:
                names.update(contract_topics([topic], namespace))
        last[topic] = log_ns
        if names is None:
            namespace = bag_namespace(_known_topics(reader), namespace)
            names = contract_topics(_known_topics(reader), namespace)
        contract = names.get(topic)
        if contract in GAIT_TOPICS and channel.message_encoding == 'cdr':
            collector.message(contract, channel.type_name, data)
    series = collector.series
    for channel in reader.channels.values():
        types.setdefault(channel.topic, channel.type_name)
    start = min(first.values()) if first else None
    end = max(last.values()) if last else None
    topics = []
    for topic in sorted(types):
        count = counts.get(topic, 0)
        span = (last[topic] - first[topic]) * 1e-9 if count else 0.0
        topics.append({'topic': topic, 'type': types[topic], 'count': count,
                       'rate_hz': _round((count - 1) / span, 3) if count > 1 and span > 0
                       else None})
    report = {
        'bag': str(path),
        'files': [str(f) for f in reader.files],
        'complete': all(state.complete for state in reader.file_states),
        'damage': [{'file': str(d.file), 'offset': d.offset, 'reason': d.reason,
                    'lost_bytes': d.lost_bytes,
                    'lost_start_ns': d.lost_start_ns, 'lost_end_ns': d.lost_end_ns,
                    'description': d.describe()} for d in reader.damage],
        'message_count': sum(counts.values()),
        'start_ns': start, 'end_ns': end,
        'duration_s': _round((end - start) * 1e-9) if start is not None else 0.0,
        'topics': topics,
        'metadata_check': metadata_check(reader.metadata, counts, types),
        'namespace': namespace or bag_namespace(_known_topics(reader)),
    }
    gait = gait_report(series, robot)
    if gait:
        report['gait'] = gait
    if series.undecodable:
        report['undecodable'] = dict(series.undecodable)
    return Inspection(report, series)


def read_gait_series(path: str | Path, namespace: str | None = None,
                     topics: tuple[str, ...] = GAIT_TOPICS) -> GaitSeries:
    """The decoded series of a bag's gait topics, without the report (see :func:`inspect_bag`).

    Args:
        path: Bag directory or ``.mcap`` file.
        namespace: The graph's ROS namespace (default: the bag's, found from its topics).
        topics: The contract topics to decode (of :data:`GAIT_TOPICS`).

    Raises:
        NotABagError: The path is not a bag.
        GaitNodesError: The bag holds several namespaced graphs and ``namespace`` is None.
    """
    reader = BagReader(path)
    collector = _Collector()
    names: dict[str, str] = {}
    seen: set[str] = set()
    wanted = set(topics)
    for channel, _, _, data in reader.messages():
        if channel.topic not in seen:  # the topics known so far decide the names (once)
            seen.add(channel.topic)
            namespace = bag_namespace(_known_topics(reader) | seen, namespace)
            names = contract_topics(_known_topics(reader) | seen, namespace)
        contract_topic = names.get(channel.topic)
        if contract_topic in wanted and channel.message_encoding == 'cdr':
            collector.message(contract_topic, channel.type_name, data)
    return collector.series


def gait_report(series: GaitSeries, robot: str | None = None) -> dict:
    """The gait metrics of the decoded series; keys only for what the bag holds."""
    robot_name, limit_of = robot_limits(robot or hardware_id(series))
    stamps = [s[0] for s in series.base] + [s[0] for s in series.zmp] + \
        [s[0] for s in series.com]
    until = max(stamps) if stamps else None
    sections = {
        'base': base_metrics(series),
        'steps': step_metrics(series, until),
        'steady': steady_metrics(series, until),
        'zmp_margin': margin_metrics(series),
        'joint_velocity': joint_metrics(series, limit_of) or None,
        'commands': command_metrics(series),
        'diagnostics': diagnostic_metrics(series),
    }
    gait = {key: value for key, value in sections.items() if value is not None}
    if gait and robot_name:
        gait['robot'] = robot_name
        reference = reference_speed(robot or hardware_id(series))
        if reference and 'steady' in gait:
            gait['steady']['reference'] = reference
        checks = physics_consistency(series, robot or hardware_id(series))
        if checks:
            gait['consistency'] = checks
    return gait


def physics_consistency(series: GaitSeries, robot: str) -> dict | None:
    """:func:`gait_nodes.bag.consistency.consistency_report` with the robot's full model.

    None when the robot's model cannot be loaded (a robot YAML without kinematics).
    """
    from gait_nodes.bag.consistency import consistency_report
    from gait_nodes.robot.model import load_robot_model

    try:
        model = load_robot_model(robot)
    except GaitNodesError:
        return None
    return consistency_report(model, series)


def metadata_check(metadata: dict | None, counts: Counter, types: dict) -> dict | None:
    """Compare ``metadata.yaml`` with what the MCAP files hold."""
    if metadata is None:
        return None
    info = metadata.get('rosbag2_bagfile_information', {})
    problems = []
    if info.get('version') != 9:
        problems.append(f'metadata version {info.get("version")!r}, expected 9')
    declared_total = info.get('message_count')
    if declared_total != sum(counts.values()):
        problems.append(f'message_count {declared_total} but the files hold '
                        f'{sum(counts.values())}')
    for entry in info.get('topics_with_message_count') or []:
        meta = entry.get('topic_metadata', {})
        name = meta.get('name')
        if entry.get('message_count') != counts.get(name, 0):
            problems.append(f'{name}: message_count {entry.get("message_count")} but the files '
                            f'hold {counts.get(name, 0)}')
        if name in types and meta.get('type') != types[name]:
            problems.append(f'{name}: type {meta.get("type")} but the file says {types[name]}')
    return {'matches': not problems, 'problems': problems}
