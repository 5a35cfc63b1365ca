"""com_preview_controller node: /gait/zmp_reference in, a stamped /gait/com_reference window out.

``python -m gait_nodes.com_preview_controller --ros-args -p robot:=biped -p com_method:=preview``

Methods (parameter ``com_method``): ``preview`` (Kajita preview control), ``sway`` (Kurazume
sway compensation on the reference's path), ``polynomial`` (fifth-order pieces, Lucy). The COM
height is ``com_height_m``, or the robot YAML's when 0. Switching method or changing a parameter
re-initializes the generator from the current COM state, so the COM does not jump. The body yaw
comes from /gait/footsteps (mean of the planned foot yaws, linear between contact changes);
without a plan it is 0. So does the COM height, with every method: ``com_height_m`` above the
support height of the plan's 3D footholds (:mod:`gait_nodes.com.support_height`: on stairs the
COM climbs with the feet, with continuous velocity and acceleration; on flat ground it is
``com_height_m``); without a plan it is ``com_height_m``.

Time is in the data: the generator steps by ``dt_s`` (5 ms) on its own time grid and runs
``horizon_s`` (0.5 s) ahead of the clock. Every ``publish_period_s`` (0.1 s) the node computes
up to ``now + horizon_s`` and publishes the window of its computed states, ``sample_period_s``
(20 ms) apart, from the latest one at or before now to the last one computed (header stamp: the
first point's time). A consumer that misses a message, or gets it late, still holds the states
it needs (the whole-body IK interpolates them, :class:`gait_nodes.robot.whole_body_ik.ComTrack`,
and lets each message replace its track from the message's first point on). A state at or
before now is never changed; the states ahead are computed again, at once, from the latest one
at or before now when a new ZMP reference changes the plan they previewed (by more than
``REVISED_REFERENCE_M``: a new velocity, a pause, a stop), so that the planner's changes take
effect when it makes them. The generator never computes further than the held ZMP reference's
end minus ``preview_s``: a reference that covers ``preview_s`` but not ``preview_s +
horizon_s`` is used, and the window reaches only as far as it allows (at least one
``publish_period_s`` past now, the reference held at its end as below; a stale reference, held
at its end, the full ``horizon_s``); the planner's
``zmp_horizon_s`` (2.5 s) covers ``preview_s + horizon_s`` and one of its periods.

/gait/zmp_reference is a stream: silent for more than ``stale_after_s`` it is reported stale
(WARN, ``com_preview_controller: inputs``) and the controller keeps running on the last good
reference, held at its end (the walk the other nodes still follow, then a standstill over the
last ZMP). The generator starts from the robot's measured COM (/gait/com, the simulator's
full-model COM, with its velocity from the recent samples) when one is fresh, so that a
controller restarted mid-walk picks up the robot where it is; without one, from the reference.
A controller starved of its timer for less than ``horizon_s`` loses nothing (its published
window still covers the gap) and computes on from where it stopped. When its computed end
falls behind the clock by more than ``MAX_CATCH_UP_TICKS`` ticks (a process starved on an
overloaded machine, a jump in time) the state is carried over to now, never stepped ahead of it
from a stale time, and the gap is reported (WARN, ``com_preview_controller: controller``); so
is a clock that jumped back behind the committed states.

A /gait/zmp_reference with more than one publisher (two graphs on one domain) is refused, not
mixed (:mod:`gait_nodes.single_source`): the controller runs on as with a stale one, ERROR on
``com_preview_controller: inputs``, until one planner is left.

A ZMP reference with a NaN, out-of-order stamps, too short a horizon (< ``preview_s``) or in a
frame other than odom is dropped and reported on /diagnostics; the controller keeps its last good
reference and its state. A parameter change that the controller cannot use (Riccati equation
without a stabilizing solution, horizon shorter than one step, unknown method, a sample period
that is not a whole number of steps) is refused with the reason.
"""

from __future__ import annotations

import bisect
import copy
import math
import sys
from collections import deque

import numpy as np

from gait_nodes import contract
from gait_nodes.cli import run_node
from gait_nodes.com.online import GeneratorSettings, make_generator
from gait_nodes.com.preview import PreviewSettings, preview_gains
from gait_nodes.com.support_height import SupportHeight
from gait_nodes.diagnostics import ERROR, OK, WARN, DiagnosticsReporter
from gait_nodes.errors import ComPlanningError, GaitNodesError
from gait_nodes.faults import FaultGuard, GuardedNode
from gait_nodes.graph import node_topic_name
from gait_nodes.interfaces import get_message
from gait_nodes.paths import node_defaults as shipped_node_defaults
from gait_nodes.robot.description import load_robot_description
from gait_nodes.runtime import DurabilityPolicy, QoSProfile, SetParametersResult
from gait_nodes.single_source import SingleSource
from gait_nodes.watchdog import InputWatchdog

NODE_NAME = 'com_preview_controller'
ZMP_TOPIC = '/gait/zmp_reference'
FOOTSTEPS_TOPIC = '/gait/footsteps'
COM_TOPIC = '/gait/com_reference'
MEASURED_COM_TOPIC = '/gait/com'
#: Least span of /gait/com samples a measured COM velocity is taken over [s].
VELOCITY_SPAN_S = 0.02
def node_defaults() -> dict:
    """The declared parameters and their defaults: ``config/com_preview_controller.yaml``."""
    return shipped_node_defaults(NODE_NAME)

#: Most generator steps the controller catches up when its computed end fell behind the clock;
#: further behind, the state is carried over to now.
MAX_CATCH_UP_TICKS = 50
#: A new ZMP reference that differs from the held one by more than this over the span the
#: states ahead of the clock previewed makes them be computed again [m] (references sampled on
#: other grids differ by a few tenths of a millimetre at the corners of the same plan).
REVISED_REFERENCE_M = 1e-3
#: Longest ``horizon_s`` [s].
MAX_HORIZON_S = 5.0
#: Range of ``publish_period_s`` and ``sample_period_s`` [s].
PERIOD_RANGE_S = (0.001, 1.0)


def plan_yaw_means(plan: contract.FootstepPlan) -> np.ndarray:
    """(K,) body yaw [rad] at each contact change: circular mean of the foot yaws, unwrapped."""
    return np.unwrap(np.angle(np.exp(1j * plan.yaws_rad).sum(axis=1)))


def plan_yaw(plan: contract.FootstepPlan, t_s: float,
             means: np.ndarray | None = None) -> tuple[float, float]:
    """Body yaw [rad] and yaw rate [rad/s] of a footstep plan at ``t_s`` from its start.

    The yaw is the circular mean of the planned foot yaws at each contact change, unwrapped and
    linear in time between them (``means``: :func:`plan_yaw_means` of ``plan``, if known).
    """
    return PlanYaw(plan, means).at(t_s)


class PlanYaw:
    """:func:`plan_yaw` of one plan, asked once per tick.

    Keeps the plan's yaw means and the segment between contact changes of the last query, so
    that a query costs a few float operations (``np.interp``'s own formula, hence its result to
    the last bit).
    """

    def __init__(self, plan: contract.FootstepPlan, means: np.ndarray | None = None):
        self.times_s = plan.times_s
        self.means = plan_yaw_means(plan) if means is None else means
        self._times, self._means = self.times_s.tolist(), self.means.tolist()
        self._segment = 0

    def at(self, t_s: float) -> tuple[float, float]:
        """Body yaw [rad] and yaw rate [rad/s] at ``t_s`` [s] from the plan's start."""
        times = self._times
        if len(times) < 2 or t_s <= times[0] or t_s >= times[-1]:
            return float(np.interp(t_s, self.times_s, self.means)), 0.0
        k = self._segment
        if not times[k] <= t_s < times[k + 1]:
            k = self._segment = bisect.bisect_right(times, t_s) - 1
        start_s, end_s = times[k], times[k + 1]
        start, end = self._means[k], self._means[k + 1]
        rate = (end - start) / (end_s - start_s)
        if t_s == start_s:
            return start, rate
        return rate * (t_s - start_s) + start, rate


class ComPreviewController(GuardedNode):
    """Generates the COM reference from the ZMP reference (see the module docstring)."""

    def __init__(self):
        super().__init__(NODE_NAME)
        self._defaults = node_defaults()
        values = {name: self.declare_parameter(name, default).value
                  for name, default in self._defaults.items()}
        self._robot = load_robot_description(values['robot'])
        self._values = values
        self._settings = self._make_settings(values, self._robot)  # raises when invalid
        preview_gains(self._settings.preview)
        self.diagnostics = DiagnosticsReporter(self, self._robot.name)
        self.faults = FaultGuard(self, self.diagnostics)
        self.inputs = InputWatchdog([ZMP_TOPIC], values['stale_after_s'],
                                    self.get_clock().now().nanoseconds,
                                    holding='running on the last reference, held at its end')
        # ZMP references from two planners (two graphs on one domain) are refused, as stale.
        self.sources = SingleSource(self, [ZMP_TOPIC], 'running on the last reference, held '
                                    'at its end', watchdog=self.inputs)
        self._measured_com: deque = deque(maxlen=50)  # (received [ns], stamp [ns], (x, y))
        self._started_ns = self.get_clock().now().nanoseconds
        self._publisher = self.create_publisher(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'), node_topic_name(COM_TOPIC),
            10)
        self.create_subscription(get_message('nav_msgs/msg/Path'), node_topic_name(ZMP_TOPIC),
                                 self._on_zmp_reference, 10)
        self.create_subscription(
            get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
            node_topic_name(FOOTSTEPS_TOPIC),
            self._on_footsteps, QoSProfile(depth=1,
                                           durability=DurabilityPolicy.TRANSIENT_LOCAL))
        # Only where the generator starts: dropped once it runs (see _tick).
        self._measured_com_subscription = self.create_subscription(
            get_message('geometry_msgs/msg/PointStamped'), node_topic_name(MEASURED_COM_TOPIC),
            self._on_measured_com, 10)
        # The incremental reader relies on poses shared by identity between the planner's
        # successive messages, which holds within one process (inproc) only. Over DDS the
        # samples' objects are not ours to rely on (with the reader the DDS walk recorded ZMP
        # excursions of metres at contact changes, none without it), so every message is read
        # whole there.
        self._zmp_reader = contract.ZmpReferenceReader() \
            if self.context.runtime == 'inproc' else None
        self._reference = None
        self._plan = None
        self._plan_yaw: PlanYaw | None = None
        self._support = None
        self._generator = None
        self._last_published = None
        self._messages = contract.ComReferenceMessages()
        # The computed states on the sample grid, oldest first: (stamp [ns], (px, py, pz,
        # vx, vy, vz, ax, ay, az, yaw, yaw rate), the generator about to step to it); from the
        # latest at or before now on.
        self._points: deque = deque()
        self._grid_origin_ns = 0  # the sample grid: this stamp + k sample_period_s
        # A horizon made shorter at run time leaves committed states further ahead than the
        # new one: they are waited for, not taken for a clock that jumped back.
        self._committed_ahead_ns = 0
        self._timer = self.create_timer(values['publish_period_s'], self._tick)
        self._status_timer = self.create_timer(values['status_period_s'], self._report_status)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.get_logger().info(
            f'{self._settings.method} COM at {self._settings.preview.com_height_m:.3f} m for '
            f'{self._robot.name}, {1.0 / self._settings.preview.dt_s:.0f} Hz, '
            f'{values["horizon_s"]:g} s ahead, published at {1.0 / values["publish_period_s"]:g} '
            f'Hz')

    # --- settings -----------------------------------------------------------------------------

    @staticmethod
    def _make_settings(values: dict, robot) -> GeneratorSettings:
        for name in ('com_height_m', 'status_period_s'):
            if isinstance(values[name], bool) or not isinstance(values[name], (int, float)):
                raise ComPlanningError(f'{name} must be a number, got {values[name]!r}')
        height = values['com_height_m'] or robot.com_height_m
        if values['com_height_m'] < 0:
            raise ComPlanningError(f'com_height_m must be >= 0 (0: the robot YAML), got '
                                   f'{values["com_height_m"]}')
        # (a status timer of 5e-324 s has no period in nanoseconds)
        if not 0.001 <= values['status_period_s'] <= 60:
            raise ComPlanningError(f'status_period_s must be in [0.001, 60] s, got '
                                   f'{values["status_period_s"]}')
        stale = values['stale_after_s']
        if isinstance(stale, bool) or not isinstance(stale, (int, float)) \
                or not 0 < stale <= 60:
            raise ComPlanningError(f'stale_after_s must be in (0, 60] s, got {stale!r}')
        preview = PreviewSettings(com_height_m=height, dt_s=values['dt_s'],
                                  preview_s=values['preview_s'], q_weight=values['Q'],
                                  r_weight=values['R'])
        horizon = values['horizon_s']
        if isinstance(horizon, bool) or not isinstance(horizon, (int, float)) \
                or not 0 <= horizon <= MAX_HORIZON_S:
            raise ComPlanningError(f'horizon_s must be in [0, {MAX_HORIZON_S:g}] s, got '
                                   f'{horizon!r}')
        low, high = PERIOD_RANGE_S
        for name in ('publish_period_s', 'sample_period_s'):
            value = values[name]
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not low <= value <= high:
                raise ComPlanningError(f'{name} must be in [{low:g}, {high:g}] s, got {value!r}')
        sample_ns = round(values['sample_period_s'] * 1e9)
        if sample_ns % preview.dt_ns:
            raise ComPlanningError(f'sample_period_s must be a whole number of generator steps '
                                   f'(dt_s = {preview.dt_s:g} s), got '
                                   f'{values["sample_period_s"]!r}')
        return GeneratorSettings(preview, values['com_method'])

    def _on_set_parameters(self, parameters) -> SetParametersResult:
        values = dict(self._values)
        values.update({p.name: p.value for p in parameters if p.name in self._defaults})
        try:
            robot = self._robot if values['robot'] == self._values['robot'] \
                else load_robot_description(values['robot'])
            settings = self._make_settings(values, robot)
            preview_gains(settings.preview)
        except GaitNodesError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        old, old_values = self._settings, self._values
        self._robot, self._values, self._settings = robot, values, settings
        self.inputs.timeout_s = values['stale_after_s']
        if values['publish_period_s'] != old_values['publish_period_s']:
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(values['publish_period_s'], self._tick)
        lookahead = max(old_values['horizon_s'], old_values['publish_period_s'])
        if max(values['horizon_s'], values['publish_period_s']) < lookahead:
            self._committed_ahead_ns = round(lookahead * 1e9)
        if values['status_period_s'] != old_values['status_period_s']:
            self.destroy_timer(self._status_timer)
            self._status_timer = self.create_timer(values['status_period_s'],
                                                   self._report_status)
        if self._generator is not None and settings != old:
            self._switch_generator()
            # The generators kept to compute states again have the old settings.
            self._points = deque(point[:2] + (None,) for point in self._points)
        if self._generator is not None and (
                settings.preview.dt_s != old.preview.dt_s
                or values['sample_period_s'] != old_values['sample_period_s']):
            self._grid_origin_ns = self._generator.stamp_ns  # (the sample grid from here)
        self.diagnostics.report('settings', OK, f'{settings.method} COM, zc '
                                f'{settings.preview.com_height_m:.3f} m',
                                {'com_method': settings.method, 'dt_s': settings.preview.dt_s,
                                 'preview_s': settings.preview.preview_s,
                                 'Q': settings.preview.q_weight,
                                 'R': settings.preview.r_weight,
                                 'horizon_s': values['horizon_s'],
                                 'publish_period_s': values['publish_period_s'],
                                 'sample_period_s': values['sample_period_s']})
        return SetParametersResult(successful=True)

    def _switch_generator(self) -> None:
        current = self._generator.state()
        state = np.array([current.position_in_world, current.velocity_in_world,
                          current.acceleration_in_world])
        self._generator = make_generator(self._settings, state, current.stamp_ns,
                                         self._reference)

    # --- inputs -------------------------------------------------------------------------------

    def _on_zmp_reference(self, msg) -> None:
        if self.sources.refuses(ZMP_TOPIC):
            return
        try:
            reference = self._zmp_reader.read(msg) if self._zmp_reader is not None \
                else contract.zmp_reference_from_msg(msg)
        except contract.ContractError as exc:
            self.diagnostics.drop(ZMP_TOPIC, str(exc))
            return
        preview = self._settings.preview
        if reference.horizon_s < preview.preview_s - 0.5 * preview.dt_s:
            self.diagnostics.drop(ZMP_TOPIC, f'horizon {reference.horizon_s:.3f} s is shorter '
                                             f'than preview_s = {preview.preview_s} s')
            return
        if self._reference is not None and \
                int(reference.stamps_ns[0]) < int(self._reference.stamps_ns[0]):
            self.diagnostics.drop(ZMP_TOPIC, 'stamped before the previous reference '
                                             '(out of order)')
            return
        previous, self._reference = self._reference, reference
        now_ns = self.get_clock().now().nanoseconds
        self.inputs.heard(ZMP_TOPIC, now_ns)
        if self._generator is None:
            return
        if self._points and self._latest_point(now_ns)[2] is not None \
                and self._revised(previous, reference, now_ns):
            self._recompute_ahead(now_ns)
        else:
            self._generator.set_reference(reference)

    def _revised(self, previous, reference, now_ns: int) -> bool:
        """Whether ``reference`` changes ``previous`` where the states ahead of now looked."""
        preview = self._settings.preview
        start_ns = max(self._latest_point(now_ns)[0], int(reference.stamps_ns[0]))
        end_ns = self._generator.stamp_ns + preview.dt_ns * preview.preview_steps
        stamps = reference.stamps_ns
        stamps = stamps[(stamps >= start_ns) & (stamps <= end_ns)]
        if not len(stamps):
            return False
        return float(np.max(np.abs(reference.sample(stamps) - previous.sample(stamps)))) \
            > REVISED_REFERENCE_M

    def _recompute_ahead(self, now_ns: int) -> None:
        """Compute the states after the latest at or before now again, on the new reference."""
        points = self._points
        stamp_ns, _, generator = self._latest_point(now_ns)
        while points and points[-1][0] >= stamp_ns:
            points.pop()
        self._generator = copy.copy(generator)  # (the one about to step to that state)
        self._generator.set_reference(self._reference)
        self._compute_and_publish(now_ns)

    def _compute_and_publish(self, now_ns: int) -> None:
        """Compute up to the end the reference allows, publish the window from now."""
        try:
            self._compute(self._end_ns(now_ns))
        except ComPlanningError as exc:
            self.diagnostics.report('generator', ERROR, f'{self._settings.method}: {exc}')
            return
        self._publish(now_ns)

    def _latest_point(self, now_ns: int) -> tuple:
        """The computed state on the sample grid latest at or before ``now_ns`` (or the first)."""
        points = self._points
        while len(points) > 1 and points[1][0] <= now_ns:
            points.popleft()
        return points[0]

    def _on_footsteps(self, msg) -> None:
        try:
            plan = contract.footsteps_from_msg(msg)
        except contract.ContractError as exc:
            self.diagnostics.drop(FOOTSTEPS_TOPIC, str(exc))
            return
        self._plan, self._plan_yaw = plan, PlanYaw(plan)
        self._support = SupportHeight(plan)

    def _on_measured_com(self, msg) -> None:
        if self._generator is not None:
            return  # the measured COM only sets where the generator starts
        xy = (msg.point.x, msg.point.y)
        if msg.header.frame_id.lstrip('/') != contract.WORLD_FRAME \
                or not all(math.isfinite(v) for v in xy):
            return  # only a start hint: a bad sample is simply not used
        self._measured_com.append((self.get_clock().now().nanoseconds,
                                   contract.time_msg_to_ns(msg.header.stamp), xy))

    def _waiting_for_the_robot(self, now_ns: int) -> bool:
        """Whether to wait for the measured COM before the first reference (dds, rclpy).

        Started into a running graph (a restart), the controller must begin where the robot's
        COM is, not at the ZMP reference, which may be a body shift away; it waits up to two
        ``stale_after_s`` for /gait/com, then starts from the reference. Under inproc every
        node starts together and nothing is waited for.
        """
        if self.context.runtime == 'inproc':
            return False
        fresh = any((now_ns - s[0]) * 1e-9 <= self._values['stale_after_s']
                    for s in self._measured_com)
        return not fresh and (now_ns - self._started_ns) * 1e-9 < 2 * self._values[
            'stale_after_s']

    def _start_state(self, now_ns: int) -> np.ndarray:
        """(3, 2) position, velocity, acceleration the generator starts from."""
        samples = [s for s in self._measured_com
                   if (now_ns - s[0]) * 1e-9 <= self._values['stale_after_s']]
        if not samples:
            start = self._reference.sample(np.array([now_ns], dtype=np.int64))[0]
            return np.array([start, (0.0, 0.0), (0.0, 0.0)])
        _, last_ns, last = samples[-1]
        velocity = np.zeros(2)
        for _, stamp_ns, xy in samples:
            span_s = (last_ns - stamp_ns) * 1e-9
            if span_s >= VELOCITY_SPAN_S:
                velocity = (np.array(last) - np.array(xy)) / span_s
            else:
                break
        return np.array([last, velocity, (0.0, 0.0)])

    # --- output -------------------------------------------------------------------------------

    def _tick(self) -> None:
        """Compute up to ``horizon_s`` ahead, then publish the committed window."""
        now_ns = self.get_clock().now().nanoseconds
        if self.inputs.update(now_ns):
            self.diagnostics.publish([self.inputs.status(now_ns)])
        if self._reference is None:
            return
        if self._generator is None:
            if self._waiting_for_the_robot(now_ns):
                return
            self._generator = make_generator(self._settings, self._start_state(now_ns), now_ns,
                                             self._reference)
            self._grid_origin_ns = now_ns
            # The measured COM only sets where the generator starts, and it never stops: a
            # 200 Hz subscription would cost a callback per sample for nothing.
            self.destroy_subscription(self._measured_com_subscription)
            self._measured_com.clear()
        self._keep_to_the_clock(now_ns)
        self._compute_and_publish(now_ns)

    def _end_ns(self, now_ns: int) -> int:
        """The last instant to compute: ``horizon_s`` ahead, within the held reference."""
        preview = self._settings.preview
        ahead_ns = round(self._values['horizon_s'] * 1e9)
        if ZMP_TOPIC in self.inputs.stale:
            # The planner is gone: the reference held at its end is all there will be, and
            # the IK needs the full horizon to finish the swings in the air (a window one
            # publication long ends before the IK's next knot: the robot froze mid-swing).
            return now_ns + ahead_ns
        covered_ns = int(self._reference.stamps_ns[-1]) - preview.dt_ns * preview.preview_steps
        # At least through the next publication (the reference held at its end).
        return max(min(now_ns + ahead_ns, covered_ns),
                   now_ns + round(self._values['publish_period_s'] * 1e9))

    def _keep_to_the_clock(self, now_ns: int) -> None:
        """Carry the state over to now when the computed end is far off the clock."""
        preview = self._settings.preview
        computed_ns = self._generator.stamp_ns - preview.dt_ns  # the last state computed
        lookahead_ns = round(max(self._values['horizon_s'],
                                 self._values['publish_period_s']) * 1e9)
        if computed_ns <= now_ns + lookahead_ns:
            self._committed_ahead_ns = 0  # (a shorter horizon has caught up)
        allowed_ns = max(lookahead_ns, self._committed_ahead_ns)
        behind_s = (now_ns - computed_ns) * 1e-9
        if behind_s <= MAX_CATCH_UP_TICKS * preview.dt_s \
                and computed_ns <= now_ns + allowed_ns + preview.dt_ns:
            return
        # Far behind (a process starved of its ticks on an overloaded machine) or ahead (a
        # jump back in time): carry the state over to now; stepping the missed ticks from
        # the stale state would publish a COM that lags the clock by as much.
        current = self._generator.state()
        self._generator.reset(current.position_in_world, current.velocity_in_world,
                              current.acceleration_in_world, stamp_ns=now_ns)
        self._generator.set_reference(self._reference)
        self._grid_origin_ns = now_ns
        if behind_s < 0:
            self._points.clear()  # committed for a time the clock has not reached (again)
        self._committed_ahead_ns = 0
        self.diagnostics.report(
            'controller', WARN, f'{abs(behind_s):.3f} s '
            f'{"behind" if behind_s > 0 else "ahead of"} the clock (more than '
            f'{MAX_CATCH_UP_TICKS} ticks behind, or beyond horizon_s ahead): the COM state '
            f'carried over to now',
            {'behind_s': behind_s, 'max_catch_up_ticks': MAX_CATCH_UP_TICKS})

    def _compute(self, end_ns: int) -> None:
        """Step the generator up to ``end_ns``; keep the states on the sample grid."""
        generator, points = self._generator, self._points
        sample_ns = round(self._values['sample_period_s'] * 1e9)
        height_m = self._settings.preview.com_height_m
        origin_ns = self._grid_origin_ns
        while generator.stamp_ns <= end_ns:
            if (generator.stamp_ns - origin_ns) % sample_ns:
                generator.step_values()
                continue
            before = copy.copy(generator)  # (to compute the states after this one again)
            stamp_ns, px, py, vx, vy, ax, ay = generator.step_values()
            yaw, yaw_rate = 0.0, 0.0
            if self._plan is not None:
                yaw, yaw_rate = self._plan_yaw.at((stamp_ns - self._plan.start_ns) * 1e-9)
                yaw = math.remainder(yaw, 2 * math.pi)
            height, climb, climb_rate = (0.0, 0.0, 0.0) if self._support is None \
                else self._support.at_ns(stamp_ns)
            while points and points[-1][0] >= stamp_ns:
                points.pop()  # (a state carried over to now replaces what it overlaps)
            points.append((stamp_ns, (px, py, height_m + height, vx, vy, climb, ax, ay,
                                      climb_rate, yaw, yaw_rate), before))

    def _publish(self, now_ns: int) -> None:
        """Publish the committed states from the latest at or before ``now_ns`` on."""
        points = self._points
        if not points:
            return
        self._latest_point(now_ns)
        stamps, states, _ = zip(*points, strict=True)
        self._publisher.publish(self._messages.window_to_msg(stamps, states))
        self._last_published = points[0][:2]

    def _report_status(self) -> None:
        self.diagnostics.publish([self.inputs.status(self.get_clock().now().nanoseconds)])
        if self._last_published is None:
            self.diagnostics.report('controller', WARN, f'waiting for {ZMP_TOPIC}')
            return
        stamp_ns, (px, py, _, _, _, _, ax, ay, _, _, _) = self._last_published
        preview = self._settings.preview
        zmp = np.array((px, py)) - preview.com_height_m / preview.gravity_m_s2 \
            * np.array((ax, ay))
        reference = self._reference.sample(np.array([stamp_ns], dtype=np.int64))[0]
        values = {
            'com_method': self._settings.method,
            'zmp_error_m': float(np.linalg.norm(zmp - reference)),
            'dropped_references': self.diagnostics.dropped.get(ZMP_TOPIC, 0),
        }
        if hasattr(self._generator, 'sway_fallbacks') and self._settings.method == 'sway':
            values['sway_plans'] = self._generator.sway_plans
            values['sway_fallbacks_to_polynomial'] = self._generator.sway_fallbacks
        self.diagnostics.report('controller', OK, f'{self._settings.method} COM running',
                                values)


def main(args: list[str] | None = None) -> int:
    """Entry point: ``python -m gait_nodes.com_preview_controller [--ros-args ...]``."""
    return run_node(lambda options: ComPreviewController(), args,
                    prog='python -m gait_nodes.com_preview_controller',
                    description=__doc__.split('\n\n')[0])


if __name__ == '__main__':
    sys.exit(main())
