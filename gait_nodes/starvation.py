"""One node of the inproc graph starved of CPU, as on overloaded cores (tests, bench/starve.py).

Over DDS a node process can get no CPU for 50-500 ms. It then runs none of its callbacks: its
timers fire once when it is back (on their period grid, no burst) and each subscription hands it
what its history kept (the last ``depth`` messages). :class:`Starvation` does exactly that to one
node of the inproc graph, deterministically. :class:`InprocGraph` is the graph ``run --fast``
starts (the five nodes, the scenario's commands, optionally the recorder); with ``pause`` the
footstep planner follows the nodes' stale-input reports on /diagnostics as it does outside
inproc, so that a starved node that leaves the robot held pauses the walk.
"""

from __future__ import annotations

import collections
import tempfile
from pathlib import Path

import yaml

from gait_nodes import graph, runtime
from gait_nodes.interfaces import get_message
from gait_nodes.scenarios import CommandDriver, get_scenario


class Starvation:
    """Holds back every callback of one inproc node until :meth:`stop`, as a starved process."""

    def __init__(self, node):
        self.node = node
        self.kept = {}
        self.callbacks = {}
        self.deadlines = {}
        for subscription in node._subscriptions:
            kept = collections.deque(maxlen=max(subscription.qos_profile.depth or 1, 1))
            self.kept[subscription] = kept
            self.callbacks[subscription] = subscription.callback
            subscription.callback = kept.append
        for timer in node._timers:
            self.deadlines[timer] = timer.next_call_ns
            timer.next_call_ns = 1 << 62

    def stop(self, now_ns: int) -> None:
        """The node runs again at ``now_ns`` [ns].

        What the histories kept is handled first, then each timer fires on its grid.
        """
        for subscription, callback in self.callbacks.items():
            subscription.callback = callback
        for subscription, kept in self.kept.items():
            for msg in kept:
                subscription.callback(msg)
        for timer, deadline_ns in self.deadlines.items():
            period = timer.timer_period_ns
            timer.next_call_ns = deadline_ns + max(-(-(now_ns - deadline_ns) // period), 0) \
                * period


class InprocGraph:
    """The gait graph of ``scenario`` in one inproc executor, its commands under way.

    Args:
        scenario: Scenario name (:mod:`gait_nodes.scenarios`).
        params: Parameter overrides for every node (on top of the scenario's, as ``run``).
        bag: Record every topic to this rosbag2 directory (None: no recorder).
        pause: The footstep planner follows the stale-input reports on /diagnostics (as
            outside inproc: it pauses the walk while the robot is held).
        prog: Program name given to the runtime.
    """

    def __init__(self, scenario: str, params: dict | None = None, bag: str | None = None,
                 pause: bool = True, prog: str = 'gait_nodes'):
        spec = get_scenario(scenario)
        values = {'robot': spec.robot, 'cmd_vel_timeout_s': 2.0, **spec.settings,
                  **(params or {})}
        with tempfile.TemporaryDirectory() as tmp:
            params_file = Path(tmp) / 'params.yaml'
            params_file.write_text(yaml.safe_dump({'/**': {'ros__parameters': values}}))
            runtime.init(args=[prog, '--ros-args', '--params-file', str(params_file)],
                         runtime='inproc', signal_handlers=False)
        try:
            self.executor = runtime.SingleThreadedExecutor()
            self.nodes = {name: graph.load_class(graph.NODES[name])()
                          for name in graph.available_nodes()}
            for node in self.nodes.values():
                self.executor.add_node(node)
            if bag is not None:
                self.executor.add_node(graph.load_class(graph.RECORDER)(output=str(bag)))
            if pause:
                planner = self.nodes['footstep_planner']
                planner.create_subscription(
                    get_message('diagnostic_msgs/msg/DiagnosticArray'), '/diagnostics',
                    planner.on_diagnostics, 50)
            self.driver_node = runtime.Node('scenario_driver', use_global_arguments=False)
            self.driver = CommandDriver(self.driver_node, spec.commands)
            self.executor.add_node(self.driver_node)
            self.driver.start()
        except BaseException:
            runtime.shutdown()
            raise

    def now_ns(self) -> int:
        """The graph's time [ns]."""
        return runtime.default_context().transport.now_ns

    def spin(self, seconds: float) -> None:
        """Run the graph for ``seconds`` of simulated time."""
        self.executor.spin_for(seconds)

    def starve(self, node_name: str, gap_s: float) -> None:
        """Run the graph for ``gap_s`` with ``node_name`` starved, then let it go."""
        starvation = Starvation(self.nodes[node_name])
        self.executor.spin_for(gap_s)
        starvation.stop(self.now_ns())

    def close(self) -> None:
        """Shut the graph down (the recorder closes its bag)."""
        runtime.shutdown()

    def __enter__(self) -> InprocGraph:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
