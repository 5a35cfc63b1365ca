"""No node dies of a failure of its core: a safe hold, an ERROR on /diagnostics, recovery.

A node of the graph runs its core (planning, control, IK, simulation) inside its callbacks. An
exception there (a :class:`gait_nodes.errors.GaitNodesError` such as a swing that leaves the
reach of the limbs, or any other failure of the core call) must not end the process, whatever
the runtime: the node holds a safe stance, reports the failure (ERROR, ``<node>: faults``, with
the callback, the exception and where it was raised), and tries again at its next callback, so
that it recovers as soon as its inputs allow it (OK, ``<node>: faults``, with how long it
failed).

:class:`GuardedNode` runs every timer and subscription callback a node creates under its
:class:`FaultGuard`; the node says what holding means for it (the footstep planner: stop at a
safe stand; the others: no output from the failed callback, on which their consumers hold the
last good one and report it stale).
"""

from __future__ import annotations

import functools
import traceback

from gait_nodes import callback_times
from gait_nodes.diagnostics import ERROR, OK
from gait_nodes.runtime import Node

#: A failure that goes on is reported again at most this often [s] (the first one at once).
REPORT_PERIOD_S = 1.0
NS_PER_S = 1_000_000_000


class FaultGuard:
    """Catches what a node's callbacks raise; holds, reports, and reports the recovery.

    Args:
        node: The node (for its clock and logger).
        diagnostics: Its :class:`gait_nodes.diagnostics.DiagnosticsReporter`.
        hold: ``hold(exc) -> str``: puts the node in its safe stance after ``exc``; returns
            what it holds, for the report. None: the failed callback's output is skipped.
        recovered: ``recovered() -> bool``: whether the node is back to normal once its failed
            callbacks run cleanly again (the planner: it planned past its safe stand). None:
            always.
    """

    def __init__(self, node, diagnostics, hold=None, recovered=None):
        self._node = node
        self._diagnostics = diagnostics
        self._hold = hold
        self._recovered = recovered
        self._failing: set[str] = set()  # names of the callbacks whose last run failed
        self._since_ns: int | None = None
        self._reported: tuple[str, int] | None = None  # (message, time [ns]) of the last ERROR
        self.failures = 0

    @property
    def failing(self) -> bool:
        """Whether the node is holding after a failure it has not recovered from."""
        return self._since_ns is not None

    def wrap(self, callback):
        """``callback`` run under the guard."""
        name = getattr(callback, '__name__', type(callback).__name__).lstrip('_')

        @functools.wraps(callback)
        def guarded(*args):
            try:
                result = callback(*args)
            except Exception as exc:  # noqa: BLE001 (the point: nothing ends the process)
                self.failed(name, exc)
                return None
            if self._since_ns is not None:
                self.succeeded(name)
            return result

        return callback_times.timed(self._node.get_name(), name, guarded)

    def failed(self, name: str, exc: BaseException) -> None:
        """``name`` raised ``exc``: hold, and report it (again at most every REPORT_PERIOD_S)."""
        now_ns = self._node.get_clock().now().nanoseconds
        self.failures += 1
        self._failing.add(name)
        if self._since_ns is None:
            self._since_ns = now_ns
        holding = 'no output from it; tried again at its next call'
        if self._hold is not None:
            try:
                holding = self._hold(exc)
            except Exception as hold_exc:  # noqa: BLE001
                holding = f'holding failed too ({type(hold_exc).__name__}: {hold_exc})'
        frame = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
        where = f'{frame.filename.rsplit("/", 1)[-1]}:{frame.lineno} in {frame.name}' \
            if frame else ''
        message = f'{name} failed: {type(exc).__name__}: {exc}; {holding}'
        last = self._reported
        if last is None or last[0] != message or \
                now_ns - last[1] >= REPORT_PERIOD_S * NS_PER_S:
            self._reported = (message, now_ns)
            self._diagnostics.report('faults', ERROR, message, {
                'callback': name, 'exception': type(exc).__name__, 'where': where,
                'failing_s': (now_ns - self._since_ns) * 1e-9, 'failures': self.failures})

    def succeeded(self, name: str) -> None:
        """``name`` (a callback, or work the node does apart) ran cleanly again."""
        self._failing.discard(name)
        if self._failing or (self._recovered is not None and not self._recovered()):
            return
        now_ns = self._node.get_clock().now().nanoseconds
        failing_s = (now_ns - self._since_ns) * 1e-9
        self._since_ns, self._reported = None, None
        self._diagnostics.report('faults', OK, f'running again after {failing_s:.2f} s of '
                                 f'failures', {'failing_s': failing_s,
                                               'failures': self.failures})


class GuardedNode(Node):
    """A node whose timer and subscription callbacks all run under ``self.faults``.

    The node sets ``self.faults`` (a :class:`FaultGuard`) in its constructor before it creates
    its first timer or subscription.
    """

    faults: FaultGuard | None = None

    def __init__(self, node_name: str, **kwargs):
        super().__init__(node_name, **kwargs)
        # A misspelt parameter is refused now, not after the node's start-up work (its robot
        # model, a value table: seconds to minutes).
        from gait_nodes.node_parameters import parameter_names

        accepted = parameter_names(node_name)
        if accepted is not None:
            self.check_parameter_overrides(accepted)

    def _guarded(self, callback):
        # Before the guard exists only the runtime subscribes for the node (/clock, when
        # use_sim_time is given at start): its own callback, not the node's core.
        return callback if self.faults is None else self.faults.wrap(callback)

    def create_timer(self, timer_period_sec, callback, *args, **kwargs):
        """:meth:`Node.create_timer` with ``callback`` under the node's guard."""
        return super().create_timer(timer_period_sec, self._guarded(callback), *args, **kwargs)

    def create_subscription(self, msg_type, topic, callback, qos_profile, *args, **kwargs):
        """:meth:`Node.create_subscription` with ``callback`` under the node's guard."""
        return super().create_subscription(msg_type, topic, self._guarded(callback),
                                           qos_profile, *args, **kwargs)
