"""The rclpy-shaped runtime of gait_nodes: one API, three backends (rclpy, dds, inproc).

Node code imports from here what it would import from rclpy::

    from gait_nodes import runtime
    from gait_nodes.runtime import Node, QoSProfile, SetParametersResult

    runtime.init(args=args)
    node = Talker()
    runtime.spin(node)
    runtime.shutdown()

The backend is chosen by :func:`gait_nodes.runtime.selection.select_runtime`: ``--runtime`` or
``GAIT_NODES_RUNTIME``, else ``rclpy`` when importable, else ``dds``.
"""

from __future__ import annotations

from gait_nodes.runtime.clock import Clock, ClockType, Duration, Time
from gait_nodes.runtime.context import (
    Context,
    default_context,
    install_signal_handlers,
    restore_signal_handlers,
)
from gait_nodes.runtime.executors import SingleThreadedExecutor
from gait_nodes.runtime.node import Node, Publisher, Subscription, Timer
from gait_nodes.runtime.parameters import Parameter, ParameterDescriptor, SetParametersResult
from gait_nodes.runtime.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_latched,
    qos_profile_sensor_data,
)
from gait_nodes.runtime.selection import RUNTIMES, active_runtime, select_runtime

__all__ = [
    'RUNTIMES', 'Clock', 'ClockType', 'Context', 'DurabilityPolicy', 'Duration', 'HistoryPolicy',
    'Node', 'Parameter', 'ParameterDescriptor', 'Publisher', 'QoSProfile', 'ReliabilityPolicy',
    'SetParametersResult', 'SingleThreadedExecutor', 'Subscription', 'Time', 'Timer',
    'active_runtime', 'create_node', 'get_global_executor', 'init', 'ok', 'qos_profile_latched',
    'qos_profile_sensor_data', 'select_runtime', 'shutdown', 'spin', 'spin_once', 'try_shutdown',
]

_global_executor: SingleThreadedExecutor | None = None


def init(*, args=None, context: Context | None = None, domain_id: int | None = None,
         runtime: str | None = None, signal_handlers: bool = True) -> None:
    """Start the runtime (``rclpy.init``); ``runtime`` overrides the default choice."""
    ctx = context or default_context()
    ctx.init(args=args, runtime=runtime, domain_id=domain_id)
    if signal_handlers:
        # Under rclpy too: rclpy's own handlers would raise KeyboardInterrupt wherever the
        # signal lands (inside its message conversion, say) or shut the context down under the
        # executor; ours ask the executor to return, and shutdown() then destroys the nodes
        # (a recorder finishes its bag) before the rclpy context goes.
        install_signal_handlers(ctx)


def ok(*, context: Context | None = None) -> bool:
    """Whether the runtime is initialized and not shut down."""
    return (context or default_context()).ok()


def shutdown(*, context: Context | None = None) -> None:
    """Stop the runtime: destroy nodes, close the transport, restore signal handlers."""
    global _global_executor
    ctx = context or default_context()
    ctx.shutdown()
    if ctx is default_context():
        _global_executor = None
    restore_signal_handlers()


def try_shutdown(*, context: Context | None = None) -> None:
    """Like :func:`shutdown`, without complaint when already shut down."""
    shutdown(context=context)


def create_node(node_name: str, **kwargs) -> Node:
    """A plain :class:`Node` (``rclpy.create_node``)."""
    return Node(node_name, **kwargs)


def get_global_executor() -> SingleThreadedExecutor:
    """The executor used by :func:`spin` and :func:`spin_once`."""
    global _global_executor
    if _global_executor is None:
        _global_executor = SingleThreadedExecutor()
    return _global_executor


def spin(node: Node, executor: SingleThreadedExecutor | None = None) -> None:
    """Run ``node``'s callbacks until shutdown (``rclpy.spin``)."""
    executor = executor or get_global_executor()
    executor.add_node(node)
    try:
        executor.spin()
    finally:
        executor.remove_node(node)


def spin_once(node: Node, *, executor: SingleThreadedExecutor | None = None,
              timeout_sec: float | None = None) -> None:
    """Run at most one unit of ``node``'s work (``rclpy.spin_once``)."""
    executor = executor or get_global_executor()
    executor.add_node(node)
    try:
        executor.spin_once(timeout_sec=timeout_sec)
    finally:
        executor.remove_node(node)
