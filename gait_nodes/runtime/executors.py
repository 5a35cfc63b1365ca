"""Executors with rclpy's interface: ``add_node``, ``spin``, ``spin_once``, ``shutdown``.

Under ``dds`` an executor waits on the transport's WaitSet and on the next timer deadline. Under
``inproc`` it drives the simulated clock in lockstep (see :mod:`gait_nodes.runtime.inproc`).
Under ``rclpy`` it wraps rclpy's own SingleThreadedExecutor.
"""

from __future__ import annotations

import contextlib
import gc

from gait_nodes.runtime import context as context_module
from gait_nodes.runtime.clock import NS_PER_S

#: Allocations (less deallocations) of container objects between two collections of the
#: youngest generation while an executor spins (Python's default: 700).
SPIN_GC_THRESHOLD = 10_000


@contextlib.contextmanager
def _fewer_collections():
    """Run Python's cyclic garbage collector less often meanwhile (its thresholds restored after).

    A lockstep graph allocates thousands of short-lived messages per simulated second, and a
    node process (dds, rclpy) hundreds per second. With the default threshold most of them are
    still referenced when a collection of the young generation comes, survive it and age into
    the old generations, whose full collections then walk every object of the process (the
    nodes' models included: 30-90 ms each, one every ~5 s of a walk). Inproc that is ~0.1 ms per
    5 ms tick on average; in a node process it is a stall of the node's ticks: the COM
    controller's, if it falls when the COM moves fastest, makes the IK jump 2 cm at once and the
    ZMP leave the support polygon (the default walk on Python 3.12, whose allocations put the
    stalls there). Collecting the young generation every 10000 allocations lets the messages
    die first: a walk then makes no full collection at all. The collector's results are the
    same, only later.
    """
    thresholds = gc.get_threshold()
    if 0 < thresholds[0] < SPIN_GC_THRESHOLD:
        gc.set_threshold(SPIN_GC_THRESHOLD, *thresholds[1:])
    try:
        yield
    finally:
        gc.set_threshold(*thresholds)


def _deliver(subscription, msg) -> None:
    if subscription.raw and not isinstance(msg, bytes):
        msg = msg.serialize()
    subscription.callback(msg)


class SingleThreadedExecutor:
    """Runs the callbacks of its nodes one at a time, in the calling thread."""

    def __init__(self, *, context=None):
        self.context = context or context_module.default_context()
        self._nodes: list = []
        #: Every timer of the nodes, in node then creation order, and what it was built from.
        self._timers: list = []
        self._timers_key = None
        self._nodes_version = 0
        self._rclpy_executor = None
        #: Message class -> its serialize_published (or serialize), for raw subscriptions.
        self._serializers: dict = {}
        if self.context.runtime == 'rclpy':
            from rclpy.executors import SingleThreadedExecutor as RclpyExecutor

            self._rclpy_executor = RclpyExecutor(context=self.context.rclpy_context)

    @property
    def inproc(self) -> bool:
        """Whether this executor drives simulated time."""
        return self.context.runtime == 'inproc'

    def add_node(self, node) -> bool:
        """Add a node; its parameter overrides must all name declared parameters."""
        node.check_parameter_overrides()
        if node in self._nodes:
            return False
        self._nodes.append(node)
        self._nodes_version += 1
        if self._rclpy_executor is not None:
            self._rclpy_executor.add_node(node.rclpy_node)
        return True

    def remove_node(self, node) -> None:
        """Stop running the node's callbacks."""
        if node in self._nodes:
            self._nodes.remove(node)
            self._nodes_version += 1
            if self._rclpy_executor is not None:
                self._rclpy_executor.remove_node(node.rclpy_node)

    def get_nodes(self) -> list:
        """Nodes of this executor."""
        return list(self._nodes)

    def _running(self) -> bool:
        return self.context.ok() and not self.context.shutdown_requested.is_set()

    def _all_timers(self) -> list:
        """The nodes' timers, gathered again only when a node or a timer came or went."""
        key = (getattr(self.context.transport, 'timers_version', None), self._nodes_version)
        if key[0] is None or key != self._timers_key:
            self._timers = [timer for node in self._nodes for timer in node._timers]
            self._timers_key = key
        return self._timers

    def _next_timer(self, by_time_left: bool = False):
        """The first of the timers due soonest (creation order breaks ties), or None.

        ``by_time_left``: compare the time left to each next call, each on its own clock.
        Between processes timers may run on different clocks (a simulator that owns time
        paces itself on the steady clock, while its other timers follow the time it makes),
        whose instants cannot be compared; under inproc every timer is on the executor's.
        """
        best, best_ns = None, 0
        for timer in self._all_timers():
            if timer._canceled:
                continue
            due_ns = timer.time_until_next_call() if by_time_left else timer.next_call_ns
            if best is None or due_ns < best_ns:
                best, best_ns = timer, due_ns
        return best

    # --- one unit of work -----------------------------------------------------------------

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run at most one timer callback or one batch of received messages."""
        if self._rclpy_executor is not None:
            self._rclpy_executor.spin_once(timeout_sec=timeout_sec)
        elif self.inproc:
            self._inproc_step(None)
        else:
            self._dds_step(timeout_sec)

    def _dds_step(self, timeout_sec: float | None) -> bool:
        transport = self.context.transport
        timer = self._next_timer(by_time_left=True)
        called = timer is not None and timer.is_ready()
        if called:
            timer.call()
            # What arrived meanwhile is delivered before the next timer, as rclpy's executor
            # serves every entity of one wait: a node whose timer is always due (one that runs
            # behind) would otherwise never see its subscriptions again.
            ready = transport.wait(0)
        else:
            wait_ns = None if timeout_sec is None else int(timeout_sec * NS_PER_S)
            # Until the next call on a wall or steady clock; a timer on simulated time waits
            # for the /clock message that advances it.
            untils = [t.time_until_next_call() for t in self._all_timers()
                      if not t._canceled and not t.clock.ros_time_is_active]
            if untils:
                until = max(min(untils), 0)
                wait_ns = until if wait_ns is None else min(wait_ns, until)
            ready = transport.wait(wait_ns if wait_ns is not None else 10 * NS_PER_S)
        for subscription, msg in ready:
            if subscription._node in self._nodes:
                _deliver(subscription, msg)
        return called or bool(ready)

    def _inproc_step(self, end_ns: int | None) -> bool:
        """Deliver what is queued, else advance to the next timer and run it.

        Returns False when there is nothing left to do before ``end_ns``.
        """
        transport = self.context.transport
        if transport.queue:
            self._drain()
            return True
        timer = self._next_timer()
        if timer is None or (end_ns is not None and timer.next_call_ns > end_ns):
            return False
        transport.now_ns = max(transport.now_ns, timer.next_call_ns)
        timer.call()
        self._drain()
        return True

    def _drain(self) -> None:
        transport = self.context.transport
        queue = transport.queue
        popleft = queue.popleft
        serializers = self._serializers
        # A message goes to all its subscriptions in a row; raw ones share its one serialization.
        while queue:
            msg, subscriptions = popleft()
            transport.delivered += len(subscriptions)
            data = None
            for subscription in subscriptions:
                if not subscription.raw:
                    subscription.callback(msg)
                    continue
                if data is None:
                    if isinstance(msg, bytes):
                        data = msg
                    else:
                        # A message published under inproc's rule (never edited again) is
                        # serialized by serialize_published, which may reuse earlier work.
                        serialize = serializers.get(msg.__class__)
                        if serialize is None:
                            serialize = serializers[msg.__class__] = getattr(
                                msg.__class__, 'serialize_published', msg.__class__.serialize)
                        data = serialize(msg)
                subscription.callback(data)

    def _spin_inproc(self, end_ns: int | None) -> None:
        """``_inproc_step`` until it returns False or the context stops (spin and spin_for).

        The same steps, in one loop: this runs every timer callback of the graph.
        """
        context = self.context
        transport = context.transport
        queue = transport.queue
        ok, shutdown_requested = context.ok, context.shutdown_requested.is_set
        next_timer, drain = self._next_timer, self._drain
        while ok() and not shutdown_requested():
            if queue:
                drain()
                continue
            timer = next_timer()
            if timer is None or (end_ns is not None and timer.next_call_ns > end_ns):
                return
            if timer.next_call_ns > transport.now_ns:
                transport.now_ns = timer.next_call_ns
            timer.call()
            drain()

    # --- loops ------------------------------------------------------------------------------

    def spin(self) -> None:
        """Run callbacks until shutdown (under inproc: until no timer is left)."""
        with _fewer_collections():
            if self._rclpy_executor is not None:
                self._spin_rclpy(None)
            elif self.inproc:
                self._spin_inproc(None)
            else:
                while self._running():
                    self._dds_step(None)

    def spin_for(self, duration_sec: float) -> None:
        """Run callbacks for ``duration_sec`` of ROS time (simulated under inproc)."""
        with _fewer_collections():
            self._spin_for(duration_sec)

    def _spin_for(self, duration_sec: float) -> None:
        if self._rclpy_executor is not None:
            self._spin_rclpy(duration_sec)
            return
        if self.inproc:
            transport = self.context.transport
            end_ns = transport.now_ns + int(round(duration_sec * NS_PER_S))
            self._spin_inproc(end_ns)
            if self._running():
                transport.now_ns = max(transport.now_ns, end_ns)
            return
        import time

        deadline = time.monotonic() + duration_sec
        while self._running():
            left = deadline - time.monotonic()
            if left <= 0:
                break
            self._dds_step(left)

    def _spin_rclpy(self, duration_sec: float | None) -> None:
        import time

        from rclpy.executors import ExternalShutdownException

        deadline = None if duration_sec is None else time.monotonic() + duration_sec
        # A bounded wait: the signal handlers (Python's, see runtime.init) run between waits.
        while self._running():
            if deadline is not None and time.monotonic() >= deadline:
                break
            try:
                self._rclpy_executor.spin_once(timeout_sec=0.05)
            except ExternalShutdownException:  # rclpy.shutdown() from elsewhere: a clean stop
                break

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Stop and forget the nodes."""
        if self._rclpy_executor is not None:
            self._rclpy_executor.shutdown(timeout_sec)
        self._nodes.clear()
        self._nodes_version += 1
        return True
