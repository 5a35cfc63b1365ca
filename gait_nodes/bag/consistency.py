"""Physics consistency of a recorded walk, recomputed from the bag with the full robot model.

Each node publishes what it computed; this module checks them against each other from the
recorded joint angles alone, the way an outside reviewer would:

- ``com``: the COM of the full model at each ``/joint_states`` sample (base pose from ``/tf``)
  against the ``/gait/com_reference`` the COM planner asked for (interpolated linearly to the
  sample's stamp: what the IK achieved) and against the ``/gait/com`` the monitor reported.
- ``zmp``: the ZMP recomputed by inverse dynamics (Pinocchio's RNEA: the free-flyer's wrench is
  the total contact wrench, a different route from the monitor's momentum rate), with
  velocities and accelerations by central differences of the recorded configurations, against
  ``/gait/zmp``, on the plane each ``/gait/zmp`` sample is on (its z: the lowest contact's
  height, on stairs); samples where the ground force is not positive are counted, not compared.
- ``footholds``: each executed swing's landing place in ``/gait/footsteps`` against the foot's
  contact point (forward kinematics) at the first ``/joint_states`` sample at or after its
  planned touch-down.
- ``stance_slip``: the largest displacement of a foot over a planned stance interval.

All distances in [m]; ``None`` where the bag lacks the topics.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from gait_nodes.bag.analysis import GaitSeries, executed_swings
from gait_nodes.robot.model import RobotModel

#: A touch-down sample farther than this from the planned time is not compared [ns].
MAX_TOUCH_DOWN_DELAY_NS = 50_000_000


def _round(value) -> float | None:
    return None if value is None or not np.isfinite(value) else round(float(value), 6)


def configurations(robot: RobotModel, series: GaitSeries
                   ) -> tuple[np.ndarray, list[np.ndarray]]:
    """(stamps [ns], q) of every /joint_states sample with a /tf base pose of the same stamp."""
    states = series.joints.get('/joint_states')
    if states is None or not series.base_poses or not states.names:
        return np.zeros(0, dtype=np.int64), []
    bases = {stamp: pose for stamp, *pose in series.base_poses}
    known = [n for n in states.names if n in set(robot.joint_names)]
    columns = [states.names.index(n) for n in known]
    indices = robot.indices(known)
    stamps, qs = [], []
    for stamp, positions in zip(states.stamps_ns, states.positions, strict=True):
        pose = bases.get(stamp)
        if pose is None:
            continue
        q = pin.neutral(robot.model)
        q[:7] = pose
        q[3:7] /= np.linalg.norm(q[3:7])
        joints = robot.joint_positions(q)
        joints[indices] = np.asarray(positions)[columns]
        robot.set_joint_positions(q, joints)
        stamps.append(stamp)
        qs.append(q)
    return np.array(stamps, dtype=np.int64), qs


def _interpolate(samples: Sequence[tuple], stamps: np.ndarray) -> np.ndarray | None:
    """Samples ``(stamp, x, y, z)`` linearly interpolated at ``stamps`` (NaN outside)."""
    if len(samples) < 2:
        return None
    table = np.array(sorted(set(samples)), dtype=float)
    out = np.stack([np.interp(stamps, table[:, 0], table[:, k], left=np.nan, right=np.nan)
                    for k in range(1, table.shape[1])], axis=1)
    return out


def _error_stats(errors: np.ndarray) -> dict | None:
    errors = errors[np.isfinite(errors)]
    if len(errors) == 0:
        return None
    return {'samples': int(len(errors)), 'max_m': _round(errors.max()),
            'rms_m': _round(np.sqrt(np.mean(errors ** 2)))}


def inverse_dynamics_zmp(model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray,
                         a: np.ndarray, ground_height_m: float) -> tuple[np.ndarray, float]:
    """ZMP (2,) on the plane ``z = ground_height_m`` [m] and vertical ground force [N].

    The free-flyer rows of ``rnea(q, v, a)`` are the wrench the ground must apply, in the base
    frame about the base origin; rotated to the world and moved to the point ``(0, 0, z0)``.
    """
    tau = pin.rnea(model, data, q, v, a)
    rotation = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
    force = rotation @ tau[:3]
    # (q[:3] - (0, 0, z0)) x force written out, as np.cross computes it (the same products and
    # differences, so the same bits) without its cost: more than the rest of this function.
    x, y, z = q[0], q[1], q[2] - ground_height_m
    fx, fy, fz = force.tolist()
    moment = rotation @ tau[3:6] + np.array([y * fz - z * fy, z * fx - x * fz, x * fy - y * fx])
    if force[2] <= 1e-6:
        return np.full(2, np.nan), float(force[2])
    return np.array([-moment[1] / force[2], moment[0] / force[2]]), float(force[2])


def com_check(robot: RobotModel, series: GaitSeries, stamps: np.ndarray,
              qs: list[np.ndarray]) -> dict | None:
    """The model COM against the planner's reference and the monitor's report."""
    if not qs:
        return None
    data = robot.new_data()
    com = np.array([pin.centerOfMass(robot.model, data, q) for q in qs])
    result = {}
    reference = _interpolate(series.com_reference, stamps)
    if reference is not None:
        result['vs_reference'] = _error_stats(np.linalg.norm((com - reference)[:, :2], axis=1))
        result['vs_reference_height'] = _error_stats(np.abs(com[:, 2] - reference[:, 2]))
    reported = {stamp: xyz for stamp, *xyz in series.com}
    matched = [i for i, s in enumerate(stamps) if int(s) in reported]
    if matched:
        monitor = np.array([reported[int(stamps[i])] for i in matched])
        result['vs_monitor'] = _error_stats(np.linalg.norm(com[matched] - monitor, axis=1))
    return result or None


def zmp_check(robot: RobotModel, series: GaitSeries, stamps: np.ndarray,
              qs: list[np.ndarray]) -> dict | None:
    """The monitor's ZMP against inverse dynamics of the recorded motion."""
    if len(qs) < 3 or not series.zmp:
        return None
    reported = {stamp: (x, y) for stamp, x, y in series.zmp}
    default_plane = series.zmp_plane_height_m if series.zmp_plane_height_m is not None else 0.0
    data = robot.new_data()
    errors, no_force = [], 0
    for i in range(1, len(qs) - 1):
        if int(stamps[i]) not in reported:
            continue
        h1, h2 = (stamps[i] - stamps[i - 1]) * 1e-9, (stamps[i + 1] - stamps[i]) * 1e-9
        if h1 <= 0 or h2 <= 0:
            continue
        d1 = pin.difference(robot.model, qs[i - 1], qs[i])
        d2 = pin.difference(robot.model, qs[i], qs[i + 1])
        v = (d1 * (h2 / h1) + d2 * (h1 / h2)) / (h1 + h2)
        a = 2.0 * (d2 / h2 - d1 / h1) / (h1 + h2)
        plane = series.zmp_plane_heights_m.get(int(stamps[i]), default_plane)
        zmp, force = inverse_dynamics_zmp(robot.model, data, qs[i], v, a, plane)
        if force <= 1e-6:
            no_force += 1
            continue
        errors.append(float(np.linalg.norm(zmp - reported[int(stamps[i])])))
    stats = _error_stats(np.array(errors))
    if stats is None:
        return None
    stats['samples_without_ground_force'] = no_force
    return stats


def foothold_check(robot: RobotModel, series: GaitSeries, stamps: np.ndarray,
                   qs: list[np.ndarray]) -> dict | None:
    """Landing places: planned against reached (forward kinematics after touch-down)."""
    if not qs or not series.plans:
        return None
    data = robot.new_data()
    errors, worst = [], None
    for swing in executed_swings(series.plans, int(stamps[-1])):
        if swing['foot'] not in robot.foot_names:
            continue
        k = int(np.searchsorted(stamps, swing['touch_down_ns']))
        if k >= len(stamps) or stamps[k] - swing['touch_down_ns'] > MAX_TOUCH_DOWN_DELAY_NS:
            continue
        feet = robot.foot_poses(qs[k], data)[0]
        error = float(np.linalg.norm(feet[robot.foot_names.index(swing['foot'])]
                                     - np.asarray(swing['end'])))
        errors.append(error)
        if worst is None or error > worst['error_m']:
            worst = {'foot': swing['foot'], 'touch_down_ns': swing['touch_down_ns'],
                     'error_m': _round(error)}
    stats = _error_stats(np.array(errors))
    if stats is not None:
        stats['worst'] = worst
    return stats


def slip_check(robot: RobotModel, series: GaitSeries, stamps: np.ndarray,
               qs: list[np.ndarray]) -> dict | None:
    """Largest drift of a foot over the samples its plan says it stands still."""
    if not qs or not series.plans:
        return None
    plans = series.plans  # in the order they were published
    data = robot.new_data()
    feet = np.array([robot.foot_poses(q, data)[0] for q in qs])
    # The swings executed, as intervals per foot: a foot is in stance outside them.
    swinging = np.zeros((len(stamps), len(robot.foot_names)), dtype=bool)
    for swing in executed_swings(plans, None):
        if swing['foot'] in robot.foot_names:
            inside = (stamps > swing['lift_off_ns']) & (stamps < swing['touch_down_ns'])
            swinging[inside, robot.foot_names.index(swing['foot'])] = True
    worst = 0.0
    for f in range(len(robot.foot_names)):
        edges = np.flatnonzero(np.diff(np.r_[0, (~swinging[:, f]).astype(int), 0]))
        for start, end in zip(edges[::2], edges[1::2], strict=True):
            drift = np.linalg.norm(feet[start:end, f] - feet[start, f], axis=1).max()
            worst = max(worst, float(drift))
    return {'max_m': _round(worst)}


def consistency_report(robot: RobotModel, series: GaitSeries) -> dict | None:
    """Every check the bag has data for (see the module docstring)."""
    stamps, qs = configurations(robot, series)
    if not qs:
        return None
    sections = {'configurations': len(qs),
                'com': com_check(robot, series, stamps, qs),
                'zmp': zmp_check(robot, series, stamps, qs),
                'footholds': foothold_check(robot, series, stamps, qs),
                'stance_slip': slip_check(robot, series, stamps, qs)}
    return {key: value for key, value in sections.items() if value is not None}
