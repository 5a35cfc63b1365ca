"""The process-wide runtime context: chosen runtime, parsed ROS arguments, transport, shutdown."""

from __future__ import annotations

import dataclasses
import signal
import threading

from gait_nodes.runtime import logging as node_logging
from gait_nodes.runtime.args import RosArguments, parse_ros_args, split_ros_args
from gait_nodes.runtime.selection import select_runtime


class Context:
    """State of one ``init()``..``shutdown()`` span."""

    def __init__(self):
        self.runtime: str | None = None
        self.ros_args = RosArguments()
        self.transport = None
        self.rclpy_context = None
        self.nodes: list = []
        self._ok = False
        self._on_shutdown: list = []
        self._lock = threading.Lock()
        self.shutdown_requested = threading.Event()
        self._shutdown_asked = False

    def init(self, args=None, runtime: str | None = None, domain_id: int | None = None) -> None:
        """Start the runtime: parse ``--ros-args`` from ``args`` and open the transport."""
        self.runtime = select_runtime(runtime)
        _, ros = split_ros_args(list(args or []))
        self.ros_args = parse_ros_args(ros)
        if self.ros_args.log_level:
            node_logging.set_default_level(self.ros_args.log_level)
        if self.runtime == 'rclpy':
            import rclpy
            from rclpy.signals import SignalHandlerOptions

            self.rclpy_context = rclpy.context.Context()
            rclpy.init(args=list(args or []), context=self.rclpy_context, domain_id=domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
        elif self.runtime == 'dds':
            from gait_nodes.runtime.dds import DdsTransport

            self.transport = DdsTransport(self, domain_id)
        else:
            from gait_nodes.runtime.inproc import InprocTransport

            self.transport = InprocTransport(self)
        self.shutdown_requested.clear()
        self._shutdown_asked = False
        self._ok = True

    def ok(self) -> bool:
        """Whether init() was called and shutdown() not yet."""
        if self.runtime == 'rclpy' and self._ok:
            return self.rclpy_context.ok()
        return self._ok

    def request_shutdown(self) -> None:
        """Ask spinning executors to return (signal-safe).

        Idempotent before it touches a lock: a second signal that interrupts the first one's
        ``Event.set`` (Ctrl-C twice, or SIGINT then SIGTERM from a dying launcher) returns at
        once instead of waiting forever on the lock its own thread holds.
        """
        if self._shutdown_asked:
            return
        self._shutdown_asked = True
        self.shutdown_requested.set()
        if self.transport is not None:
            self.transport.notify()

    def on_shutdown(self, callback) -> None:
        """Call ``callback()`` at shutdown."""
        self._on_shutdown.append(callback)

    def register_node(self, node) -> None:
        """Remember a node, to destroy it at shutdown."""
        self.nodes.append(node)

    def unregister_node(self, node) -> None:
        """Forget a destroyed node."""
        if node in self.nodes:
            self.nodes.remove(node)

    def shutdown(self) -> None:
        """Destroy the nodes, close the transport. Safe to call twice."""
        with self._lock:
            if not self._ok:
                return
            self._ok = False
        self.shutdown_requested.set()
        for callback in self._on_shutdown:
            callback()
        for node in list(self.nodes):
            node.destroy_node()
        if self.runtime == 'rclpy':
            import rclpy

            rclpy.try_shutdown(context=self.rclpy_context)
        elif self.transport is not None:
            self.transport.close()
            self.transport = None


def merge_ros_args(first: RosArguments, second: RosArguments) -> RosArguments:
    """``second``'s arguments after ``first``'s (later ones win)."""
    merged = RosArguments()
    for field in dataclasses.fields(RosArguments):
        a, b = getattr(first, field.name), getattr(second, field.name)
        if isinstance(a, list):
            setattr(merged, field.name, a + b)
        else:
            setattr(merged, field.name, b if b is not None else a)
    return merged


_default = Context()


def default_context() -> Context:
    """The context used when none is given."""
    return _default


_installed_handlers: dict = {}


def install_signal_handlers(context: Context) -> None:
    """SIGINT/SIGTERM ask for a clean shutdown instead of raising KeyboardInterrupt."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        context.request_shutdown()

    for signum in (signal.SIGINT, signal.SIGTERM):
        _installed_handlers.setdefault(signum, signal.getsignal(signum))
        signal.signal(signum, handler)


def restore_signal_handlers() -> None:
    """Put back the handlers that were there before."""
    if threading.current_thread() is not threading.main_thread():
        return
    for signum, previous in _installed_handlers.items():
        signal.signal(signum, previous)
    _installed_handlers.clear()
