"""Shared helpers of the planner tests: fixture robots and independent plan re-analysis.

The re-analysis reads only the contract objects (FootstepPlan, sampled ZMP), never the planner's
internals: the contact state between two plan points is "a foot is down unless its transform
changes", and the support polygon is the hull of the stance feet's discs.
"""

from pathlib import Path

import numpy as np

from gait_nodes.planning.support import convex_hull, halfplanes
from gait_nodes.robot.description import load_robot_description

DATA = Path(__file__).resolve().parent / 'data' / 'robots'
QUADRUPED = str(DATA / 'quadruped.yaml')
BIPED = str(DATA / 'biped.yaml')


def robot(name: str):
    """The fixture robot ``quadruped`` or ``biped``."""
    return load_robot_description(QUADRUPED if name == 'quadruped' else BIPED)


def stance_at(plan, times_s):
    """For each time: (F, 2) positions of the feet and (F,) which are down (plan-relative s)."""
    times_s = np.asarray(times_s, dtype=float)
    index = np.clip(np.searchsorted(plan.times_s, times_s, side='right') - 1, 0, None)
    positions = plan.positions_in_world[index][:, :, :2]
    moved = np.vstack([plan.moved(), np.zeros((1, len(plan.foot_names)), dtype=bool)])
    down = ~moved[index]
    # At a contact-change instant every foot that touches down or lifts off counts as down.
    at_point = np.isin(times_s, plan.times_s)
    down[at_point] = True
    return positions, down


def depths(points: np.ndarray, contacts: np.ndarray) -> np.ndarray:
    """Signed depth of each point inside the hull of ``contacts`` (negative outside)."""
    hull = convex_hull(contacts)
    if len(hull) >= 3:
        normals, offsets = halfplanes(hull)
        inside = (offsets[None, :] - points @ normals.T).min(axis=1)
        segments = [(hull[i], hull[(i + 1) % len(hull)]) for i in range(len(hull))]
    elif len(hull) == 2:
        inside = np.full(len(points), -np.inf)
        segments = [(hull[0], hull[1])]
    else:
        return -np.linalg.norm(points - hull[0], axis=1)
    distance = np.full(len(points), np.inf)
    for a, b in segments:
        ab = b - a
        s = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
        distance = np.minimum(distance, np.linalg.norm(points - (a + s[:, None] * ab), axis=1))
    return np.where(inside >= 0, inside, -distance)


def zmp_depths(plan, times_s, zmp):
    """Depth of each ZMP sample inside the contact-point hull of the scheduled stance feet."""
    positions, down = stance_at(plan, times_s)
    result = np.empty(len(times_s))
    keys = np.concatenate([np.searchsorted(plan.times_s, times_s, side='right')[:, None],
                           down], axis=1)
    _, groups = np.unique(keys, axis=0, return_inverse=True)
    for g in np.unique(groups):
        members = np.nonzero(groups.ravel() == g)[0]
        first = members[0]
        result[members] = depths(zmp[members], positions[first][down[first]])
    return result


def zmp_margins(plan, times_s, zmp, foot_radius_m):
    """Margin of each ZMP sample inside the support polygon (hull of the stance feet's discs)."""
    return zmp_depths(plan, times_s, zmp) + foot_radius_m


def check_slid_windows(planner, commands: dict, origin_ns: int, duration_ns: int) -> int:
    """Drive ``planner`` as the footstep_planner node does and compare each slid ZMP window.

    Every 20 ms tick (mostly one on; now and then 3 ticks, or 5 ms off the sample lattice) the
    plan is advanced and pruned, the velocities of ``commands`` ({time [s]: Twist2D}) are set,
    and the window the planner slid from its last one must be, bit for bit, the window computed
    whole (without a last window). Returns how many windows were compared.
    """
    period_ns = 20_000_000
    now_ns, checked = origin_ns, 0
    while now_ns < origin_ns + duration_ns:
        now_s = (now_ns - origin_ns) * 1e-9
        for at_s, twist in commands.items():
            if at_s <= now_s < at_s + 0.02:
                planner.set_velocity(twist, now_s)
        planner.advance(now_s + 2.0 + planner.params.step_period_s)
        planner.prune(now_s)
        reference = planner.zmp_reference(now_ns, origin_ns, 2.0, 0.01)
        last = planner._last_zmp_reference
        planner._last_zmp_reference = None
        whole = planner.zmp_reference(now_ns, origin_ns, 2.0, 0.01)
        planner._last_zmp_reference = last  # the next window slides from the slid one
        for name in ('stamps_ns', 'zmp_in_world', 'plane_heights_m'):
            np.testing.assert_array_equal(getattr(reference, name).view(np.int64),
                                          getattr(whole, name).view(np.int64))
        checked += 1
        now_ns += period_ns * (3 if checked % 37 == 0 else 1) + (5_000_000 * (checked % 53 == 0))
    return checked
