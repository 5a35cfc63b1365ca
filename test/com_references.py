"""ZMP references built from first principles for the COM generator tests.

The biped walk is Lucy-style (Vermeulen et al., section 3): the ZMP stays at the stance ankle in
single support and moves linearly from the rear to the front ankle in double support.
"""

from __future__ import annotations

import numpy as np

from gait_nodes.contract import ZmpReference

NS_PER_S = 1_000_000_000


def biped_walk_vertices(steps: int = 8, step_m=0.3, width_m: float = 0.1,
                        single_s: float = 0.6, double_s: float = 0.2, rest_before_s: float = 2.0,
                        rest_after_s: float = 3.0, origin=(0.0, 0.0)):
    """Vertices ``(times (V,), zmp (V, 2))`` of the piecewise-linear reference of a straight walk.

    Both feet start side by side at x = 0 (y = +-width); the right foot is the first stance foot
    and step ``i`` lands its swing foot ``step_m`` (a number, or one per step) ahead of the
    previous landing; after the last step the ZMP moves to the middle of the two feet and stays.
    """
    lengths = np.broadcast_to(np.asarray(step_m, dtype=float), (steps,))
    origin = np.asarray(origin, dtype=float)
    times, points = [0.0, rest_before_s], [np.zeros(2), np.zeros(2)]
    t = rest_before_s
    stance = np.array([0.0, -width_m])
    t += double_s
    times.append(t)
    points.append(stance)
    for i in range(1, steps + 1):
        t += single_s
        times.append(t)
        points.append(stance)
        landing = np.array([lengths[:i].sum(), width_m if i % 2 else -width_m])
        t += double_s
        times.append(t)
        if i < steps:
            points.append(landing)
            stance = landing
        else:
            points.append((stance + landing) / 2.0)
    t += rest_after_s
    times.append(t)
    points.append(points[-1])
    return np.array(times), np.array(points) + origin


def sample_vertices(times, points, sample_times):
    """(M, 2) linear interpolation of the vertices at ``sample_times`` (held beyond the ends)."""
    return np.stack([np.interp(sample_times, times, points[:, i]) for i in range(2)], axis=1)


def biped_walk(dt_s: float, **kwargs):
    """``(times (N,), reference (N, 2))`` of :func:`biped_walk_vertices` sampled every ``dt_s``."""
    times, points = biped_walk_vertices(**kwargs)
    count = int(round(times[-1] / dt_s)) + 1
    sample_times = dt_s * np.arange(count)
    return sample_times, sample_vertices(times, points, sample_times)


def window(times, points, start_ns: int, horizon_s: float, period_s: float) -> ZmpReference:
    """The ZmpReference a planner on a ``period_s`` grid publishes at ``start_ns``.

    Samples sit on multiples of ``period_s`` and cover ``[start_ns, start_ns + horizon_s]``.
    """
    period_ns = int(round(period_s * NS_PER_S))
    first = start_ns // period_ns
    last = -(-(start_ns + int(round(horizon_s * NS_PER_S))) // period_ns)
    stamps = np.arange(first, last + 1, dtype=np.int64) * period_ns
    return ZmpReference(stamps, sample_vertices(times, points, stamps * 1e-9))
