"""Height of the support under the COM over a footstep plan, smooth, for walking on stairs.

The horizontal COM comes from the ZMP reference (preview control or the other methods, all on
the cart-table model of height ``zc``); its height is ``zc`` above the *support height*
``h(t)`` of the footstep plan (3D footholds, :class:`gait_nodes.contract.FootstepPlan`), so that
on a staircase the COM climbs with the feet and stays ``zc`` above the plane the cart-table
model and the ZMP monitor work on (:mod:`gait_nodes.sim.zmp_monitor`: the lowest contact).

Between two contact changes ``t_k`` and ``t_k+1`` of the plan the support height moves from
``h_k-1`` to ``h_k``, the height of the *lowest* foot at ``t_k+1`` (a foot in swing counted at
its landing place), along a quintic of zero velocity and acceleration at both ends::

    h(t) = h_k-1 + (h_k - h_k-1) (10 s^3 - 15 s^4 + 6 s^5),   s = (t - t_k) / (t_k+1 - t_k)

so ``h`` and its first two derivatives are continuous (the COM reference's velocity and
acceleration too). Going up, the COM rises only while the lower foot swings up, with the
upper foot as the support: in double support it stays ``zc`` above the lower foot, which a
leg could not reach from a COM already ``zc`` above the upper one. Going down, it descends
while the swing foot moves to the lower tread, so that the swing foot can reach it. On flat
ground ``h = 0`` and nothing changes. Each interval depends only on its two ends, so a plan
re-published with a later start or re-planned future steps gives the same ``h`` where the two
plans overlap in time.
"""

from __future__ import annotations

import bisect

import numpy as np

from gait_nodes.contract import FootstepPlan


class SupportHeight:
    """``h(t)`` of one footstep plan (see the module docstring).

    Args:
        plan: The footstep plan; times are from its start.
    """

    def __init__(self, plan: FootstepPlan):
        times = np.asarray(plan.times_s, dtype=float)
        lowest = plan.positions_in_world[:, :, 2].min(axis=1)
        # Points at one instant: the last one holds the feet after every change at it.
        last = np.r_[times[1:] != times[:-1], True]
        self.times_s = times[last]
        self.heights_m = lowest[last]
        self.start_ns = int(plan.start_ns)
        # Asked every tick: Python floats and bisect (np.searchsorted's 'right' side), with the
        # arithmetic of a numpy version written the same way, hence its result to the bit.
        self._times, self._heights = self.times_s.tolist(), self.heights_m.tolist()

    @property
    def flat(self) -> bool:
        """True when every foothold is at the same height."""
        return bool(np.ptp(self.heights_m) == 0.0)

    def at(self, t_s: float) -> tuple[float, float, float]:
        """``h`` [m], ``dh/dt`` [m/s], ``d2h/dt2`` [m/s^2] at ``t_s`` from the plan start."""
        times, heights = self._times, self._heights
        k = bisect.bisect_right(times, t_s)
        if k == 0 or k == len(times):
            return heights[min(k, len(times) - 1)], 0.0, 0.0
        t0, t1 = times[k - 1], times[k]
        h0, h1 = heights[k - 1], heights[k]
        span = t1 - t0
        s = (t_s - t0) / span
        rise = h1 - h0
        return (h0 + rise * s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s),
                rise * 30.0 * s * s * (1.0 - s) ** 2 / span,
                rise * 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s) / span ** 2)

    def at_ns(self, stamp_ns: int) -> tuple[float, float, float]:
        """:meth:`at` for a ROS time [ns]."""
        return self.at((int(stamp_ns) - self.start_ns) * 1e-9)
