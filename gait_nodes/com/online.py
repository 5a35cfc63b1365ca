"""Online COM generators behind one interface, for the com_preview_controller node.

Every generator keeps a COM state on its own time grid ``t_k = t_0 + k dt``, takes the latest
ZMP reference window (:class:`gait_nodes.contract.ZmpReference`) and, each tick, returns the
state at ``t_k`` and advances to ``t_k+1``:

* ``preview``: :class:`gait_nodes.com.preview.OnlinePreviewController`;
* ``sway``: :func:`gait_nodes.com.sway.solve_sway` on the reference's path (the ZMP stays on
  the straight pieces between the reference's corners);
* ``polynomial``: :func:`gait_nodes.com.polynomial.fit_quintic_com`.

The last two plan from the current state over the window but its last ``TAIL_S``, which only
sets the divergent component ``c + sqrt(A) c_d`` wanted at the plan's end (the reference
filtered by ``e^(-t / sqrt(A))``). When the sway time law would need the ZMP to run more than
``MAX_SWAY_OVERSHOOT_M`` beyond its segments or miss the divergent component by as much (a
window too short to steer the COM's unstable mode along the path alone, or a ZMP at rest),
that plan is the polynomial one and ``sway_fallbacks`` counts it.
Both re-plan when the reference changes on its overlap with
the previous one, or when half of the plan has passed (a sliding window that only grows at its
end is the same plan).

A new generator starts from the previous one's state (position, velocity, acceleration), so a
method switch or a parameter change does not make the COM jump.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gait_nodes.com.polynomial import fit_quintic_com, reference_knots
from gait_nodes.com.preview import (
    NS_PER_S,
    ComSample,
    OnlinePreviewController,
    PreviewSettings,
)
from gait_nodes.com.sway import path_waypoints, solve_sway
from gait_nodes.errors import ComPlanningError

METHODS = ('preview', 'sway', 'polynomial')
#: The last part of a reference window only sets the divergent component at the plan's end [s].
TAIL_S = 0.8
#: Shortest plan [s].
MIN_PLAN_S = 0.3
#: A plan is re-made from the newest reference once this fraction of it has passed.
REPLAN_FRACTION = 0.5
#: Weight of the end condition (divergent component) against the ZMP terms.
END_WEIGHT = 1e4
#: Largest run of the sway ZMP beyond the ends of its support segments [m].
MAX_SWAY_OVERSHOOT_M = 0.02


def sway_overshoot_m(trajectory) -> float:
    """How far the planned sway ZMP runs beyond the ends of its segments [m]."""
    u = np.linspace(0.0, 1.0, 21)
    sigma = u[None, :] + trajectory.beta[:, None] * (u * u - u)[None, :]
    beyond = np.maximum(sigma - 1.0, 0.0) + np.maximum(-sigma, 0.0)
    lengths = np.linalg.norm(np.diff(trajectory.waypoints_in_world, axis=0), axis=1)
    return float(np.max(beyond.max(axis=1) * lengths)) if len(lengths) else 0.0
#: Two references differing by less than this on their overlap are the same plan [m].
SAME_PLAN_M = 1e-9


@dataclass(frozen=True)
class GeneratorSettings:
    """Settings shared by every method: the preview settings (zc, dt, preview, Q, R)."""

    preview: PreviewSettings
    method: str = 'preview'

    def __post_init__(self):
        if self.method not in METHODS:
            raise ComPlanningError(f'com_method must be one of {list(METHODS)}, got '
                                   f'{self.method!r}')


class ReplanningGenerator:
    """Sway or polynomial COM, re-planned from the current state when the reference changes.

    Args:
        method: ``'sway'`` or ``'polynomial'``.
        settings: Preview settings (only ``com_height_m``, ``dt_s``, gravity are used).
        state: (3, 2) position, velocity, acceleration at ``stamp_ns``.
        stamp_ns: Time of ``state`` [ns].
    """

    def __init__(self, method: str, settings: PreviewSettings, state, stamp_ns: int):
        if method not in ('sway', 'polynomial'):
            raise ComPlanningError(f'no re-planning generator for {method!r}')
        self.method = method
        self.settings = settings
        self._state = np.array(state, dtype=float).reshape(3, 2)
        self._stamp_ns = int(stamp_ns)
        self._reference = None
        self._plan = None
        self._plan_origin_ns = 0
        self._plan_valid_s = 0.0
        self.sway_plans = 0
        self.sway_fallbacks = 0

    @property
    def stamp_ns(self) -> int:
        """Time of the current state [ns]."""
        return self._stamp_ns

    def reset(self, position_in_world, velocity_in_world=(0.0, 0.0),
              acceleration_in_world=(0.0, 0.0), stamp_ns: int | None = None) -> None:
        """Re-initialize from a state; the next tick re-plans from it."""
        self._state = np.array([position_in_world, velocity_in_world, acceleration_in_world],
                               dtype=float)
        if stamp_ns is not None:
            self._stamp_ns = int(stamp_ns)
        self._plan = None

    def retune(self, settings: PreviewSettings) -> None:
        """New settings; re-plan from the current state."""
        self._state = self._current()
        self.settings = settings
        self._plan = None

    def set_reference(self, reference) -> None:
        """Use ``reference``; re-plan only when it differs from the current one."""
        previous, self._reference = self._reference, reference
        if previous is None or self._plan is None:
            self._plan = None
            return
        overlap = reference.stamps_ns[(reference.stamps_ns >= previous.stamps_ns[0])
                                      & (reference.stamps_ns <= previous.stamps_ns[-1])]
        if len(overlap) == 0 or np.max(np.abs(reference.sample(overlap)
                                              - previous.sample(overlap))) > SAME_PLAN_M:
            self._state = self._current()
            self._plan = None

    def _current(self) -> np.ndarray:
        if self._plan is None:
            return self._state
        t = (self._stamp_ns - self._plan_origin_ns) / NS_PER_S
        return np.stack([values[0] for values in self._plan.sample([t])])

    def _replan(self) -> None:
        if self._reference is None:
            raise ComPlanningError(f'the {self.method} generator has no ZMP reference yet')
        s = self.settings
        A = s.com_height_m / s.gravity_m_s2
        origin = self._stamp_ns
        end_s = max((int(self._reference.stamps_ns[-1]) - origin) / NS_PER_S, 0.0)
        horizon_s = end_s - TAIL_S if end_s - TAIL_S >= MIN_PLAN_S else max(end_s, MIN_PLAN_S)
        # The divergent component the reference asks for at the plan's end: the reference
        # ahead, filtered by e^(-t / sqrt(A)) and held beyond its last sample (Kajita's
        # preview in closed form for the cart-table's unstable mode).
        grid = horizon_s + s.dt_s * np.arange(int(np.ceil(max(end_s - horizon_s, 0.0)
                                                          / s.dt_s)) + 1)
        ahead = self._reference.sample(origin + np.round(grid * NS_PER_S).astype(np.int64))
        weights = np.exp(-(grid - horizon_s) / np.sqrt(A))
        kernel = np.diff(-weights, append=0.0)
        kernel[-1] = weights[-1]
        capture = kernel @ ahead
        stamps = self._reference.stamps_ns
        inside = (stamps > origin) & (stamps < origin + int(horizon_s * NS_PER_S))
        times = np.concatenate([[0.0], (stamps[inside] - origin) / NS_PER_S, [horizon_s]])
        zmp = self._reference.sample(origin + np.round(times * NS_PER_S).astype(np.int64))
        state = self._state
        if self.method == 'sway':
            corners = reference_knots(times, zmp, np.inf)
            corners, waypoints = path_waypoints(corners, np.stack(
                [np.interp(corners, times, zmp[:, i]) for i in range(2)], 1))
            # Start from the current cart-table ZMP: acceleration stays continuous.
            waypoints[0] = state[0] - A * state[2]
            sway = solve_sway(waypoints, corners, s.com_height_m, state[0], state[1],
                              end='capture', end_weight=END_WEIGHT, capture_point=capture,
                              gravity_m_s2=s.gravity_m_s2)
            self.sway_plans += 1
            if sway_overshoot_m(sway) <= MAX_SWAY_OVERSHOOT_M \
                    and sway.end_residual_m <= MAX_SWAY_OVERSHOOT_M:
                self._plan = _SwayPlan(sway)
            else:
                # The window does not leave the time law enough freedom: keep the COM on the
                # reference with the polynomial fit for this plan, and count it.
                self.sway_fallbacks += 1
                self._plan = fit_quintic_com(times, zmp, s.com_height_m, state, end='capture',
                                             end_weight=END_WEIGHT, capture_point=capture,
                                             gravity_m_s2=s.gravity_m_s2)
        else:
            self._plan = fit_quintic_com(times, zmp, s.com_height_m, state, end='capture',
                                         end_weight=END_WEIGHT, capture_point=capture,
                                         gravity_m_s2=s.gravity_m_s2)
        self._plan_origin_ns = origin
        self._plan_valid_s = max(REPLAN_FRACTION * horizon_s, s.dt_s)

    def state(self) -> ComSample:
        """The current state, without advancing."""
        current = self._current()
        return ComSample(self._stamp_ns, current[0].copy(), current[1].copy(),
                         current[2].copy())

    def step(self) -> ComSample:
        """Return the state at ``t_k`` and advance to ``t_k + dt``."""
        elapsed = (self._stamp_ns - self._plan_origin_ns) / NS_PER_S
        if self._plan is None or elapsed > self._plan_valid_s:
            self._state = self._current()
            self._replan()
        sample = self.state()
        self._stamp_ns += self.settings.dt_ns
        return sample

    def step_values(self) -> tuple[int, float, float, float, float, float, float]:
        """:meth:`step` as ``(stamp_ns, cx, cy, vx, vy, ax, ay)``.

        The preview controller's form (:meth:`gait_nodes.com.preview.OnlinePreviewController.
        step_values`), which the node publishes from.
        """
        sample = self.step()
        return (sample.stamp_ns, *sample.position_in_world.tolist(),
                *sample.velocity_in_world.tolist(), *sample.acceleration_in_world.tolist())


class _SwayPlan:
    """A SwayTrajectory with the PiecewiseQuintic ``sample`` signature."""

    def __init__(self, trajectory):
        self.trajectory = trajectory

    def sample(self, t):
        return self.trajectory.sample(t)


def make_generator(settings: GeneratorSettings, state, stamp_ns: int, reference=None):
    """A generator of ``settings.method`` starting from ``state`` (3, 2) at ``stamp_ns``."""
    state = np.asarray(state, dtype=float).reshape(3, 2)
    if settings.method == 'preview':
        generator = OnlinePreviewController(settings.preview, state[0], stamp_ns)
        generator.reset(state[0], state[1], state[2], stamp_ns)
    else:
        generator = ReplanningGenerator(settings.method, settings.preview, state, stamp_ns)
    if reference is not None:
        generator.set_reference(reference)
        if settings.method == 'preview':
            generator.match_jerk()
    return generator
