"""``Node``: the rclpy (jazzy) node API over the active runtime.

With the ``rclpy`` runtime a ``Node`` creates a real ``rclpy.node.Node`` and forwards every call to
it. With ``dds`` and ``inproc`` it implements the same calls itself over the context's transport.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable

from gait_nodes.errors import GaitNodesError, ParameterNotDeclaredError
from gait_nodes.interfaces import get_message, message_type_name
from gait_nodes.runtime import context as context_module
from gait_nodes.runtime.args import unknown_parameters_message
from gait_nodes.runtime.clock import NS_PER_S, Clock, ClockType
from gait_nodes.runtime.endpoints import TopicEndpointTypeEnum
from gait_nodes.runtime.logging import RcutilsLogger
from gait_nodes.runtime.names import expand_topic_name, fully_qualified_node_name
from gait_nodes.runtime.parameters import (
    Parameter,
    ParameterDescriptor,
    ParameterStore,
    SetParametersResult,
)
from gait_nodes.runtime.qos import QoSProfile, ReliabilityPolicy, as_profile
from gait_nodes.runtime.qos import to_rclpy as to_rclpy_qos


def _rclpy_forward(method):
    """Run ``method`` on the wrapped rclpy node when the rclpy runtime is active."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        if self._rclpy_node is not None:
            return getattr(self._rclpy_node, method.__name__)(*args, **kwargs)
        return method(self, *args, **kwargs)

    return wrapper


class Publisher:
    """Publishes messages of one type on one topic."""

    def __init__(self, node: Node, msg_type: type, topic: str, qos_profile: QoSProfile, impl):
        self.msg_type = msg_type
        self.topic_name = topic
        self.qos_profile = qos_profile
        self._node = node
        self._impl = impl

    @property
    def topic(self) -> str:
        """Fully qualified topic name."""
        return self.topic_name

    def publish(self, msg) -> None:
        """Send ``msg`` (an instance of ``msg_type``, or its CDR bytes)."""
        if msg.__class__ is self.msg_type:  # the usual case first: one check per message
            self._impl.publish(msg)
            return
        if isinstance(msg, (bytes, bytearray, memoryview)):
            self._impl.publish_raw(bytes(msg))
            return
        if not isinstance(msg, self.msg_type):
            raise TypeError(f'Expected {self.msg_type.__name__}, got {type(msg).__name__} '
                            f'(publisher on {self.topic_name})')
        self._impl.publish(msg)

    def get_subscription_count(self) -> int:
        """Number of matched subscriptions."""
        return self._impl.subscription_count()

    def destroy(self) -> None:
        """Release the publisher."""
        self._node.destroy_publisher(self)


class Subscription:
    """Receives messages of one type on one topic and calls a callback for each."""

    def __init__(self, node: Node, msg_type: type, topic: str, callback, qos_profile: QoSProfile,
                 raw: bool):
        self.msg_type = msg_type
        self.topic_name = topic
        self.callback = callback
        self.qos_profile = qos_profile
        self.raw = raw
        self._node = node
        self.impl = None

    def destroy(self) -> None:
        """Release the subscription."""
        self._node.destroy_subscription(self)


class Timer:
    """Calls a callback every ``timer_period_ns`` of its clock."""

    def __init__(self, callback, period_ns: int, clock: Clock, autostart: bool = True):
        if period_ns <= 0:
            raise GaitNodesError(f'timer period must be > 0 s, got {period_ns / NS_PER_S} s')
        self.callback = callback
        self.timer_period_ns = period_ns
        self.clock = clock
        self._canceled = not autostart
        self.next_call_ns = clock.now_ns() + period_ns

    def cancel(self) -> None:
        """Stop calling."""
        self._canceled = True

    def is_canceled(self) -> bool:
        """Whether the timer is stopped."""
        return self._canceled

    def reset(self) -> None:
        """Restart: next call one period from now."""
        self._canceled = False
        self.next_call_ns = self.clock.now_ns() + self.timer_period_ns

    def is_ready(self) -> bool:
        """Whether the next call is due."""
        return not self._canceled and self.clock.now_ns() >= self.next_call_ns

    def time_until_next_call(self) -> int | None:
        """Nanoseconds until the next call (None when canceled)."""
        if self._canceled:
            return None
        return self.next_call_ns - self.clock.now_ns()

    def call(self) -> None:
        """Run the callback and schedule the next call on the period grid."""
        now = self.clock.now_ns()
        self.next_call_ns += self.timer_period_ns
        if self.next_call_ns <= now:  # fell behind (or time jumped): do not burst
            periods = (now - self.next_call_ns) // self.timer_period_ns + 1
            self.next_call_ns += periods * self.timer_period_ns
        self.callback()

    def destroy(self) -> None:
        """Stop for good."""
        self._canceled = True


class Node:
    """A ROS 2 node: publishers, subscriptions, timers, parameters, logger and clock."""

    def __init__(self, node_name: str, *, context=None, cli_args=None, namespace=None,
                 use_global_arguments: bool = True, enable_rosout: bool = True,
                 start_parameter_services: bool = True, parameter_overrides=None,
                 allow_undeclared_parameters: bool = False,
                 automatically_declare_parameters_from_overrides: bool = False):
        ctx = context or context_module.default_context()
        if not ctx.ok():
            raise GaitNodesError('the runtime is not initialized: call init() before '
                                 'creating a node')
        self.context = ctx
        self._rclpy_node = None
        self._wrapped_callbacks: dict = {}
        if ctx.runtime == 'rclpy':
            from rclpy.node import Node as RclpyNode

            self._rclpy_node = RclpyNode(
                node_name, context=ctx.rclpy_context, cli_args=cli_args, namespace=namespace,
                use_global_arguments=use_global_arguments, enable_rosout=enable_rosout,
                start_parameter_services=start_parameter_services,
                parameter_overrides=parameter_overrides,
                allow_undeclared_parameters=allow_undeclared_parameters,
                automatically_declare_parameters_from_overrides=(
                    automatically_declare_parameters_from_overrides),
            )
            ctx.register_node(self)  # shutdown destroys it (a recorder finishes its bag then)
            return
        ros_args = ctx.ros_args if use_global_arguments else None
        if cli_args:
            from gait_nodes.runtime.args import parse_ros_args, split_ros_args

            _, local = split_ros_args(list(cli_args))
            local_args = parse_ros_args(local)
            if ros_args is not None:
                merged = context_module.merge_ros_args(ros_args, local_args)
                ros_args = merged
            else:
                ros_args = local_args
        if ros_args is None:
            from gait_nodes.runtime.args import RosArguments

            ros_args = RosArguments()
        self._name = ros_args.node_name(node_name)
        self._namespace = ros_args.namespace(namespace, node_name)
        # rcl expands both sides of a rule in the node's namespace before matching, so that
        # `chatter:=other` also remaps `/chatter` and always yields an absolute name.
        self._remaps = {
            expand_topic_name(source, self._name, self._namespace):
                expand_topic_name(target, self._name, self._namespace)
            for source, target in ros_args.topic_remaps(self._name).items()
        }
        self._ros_args = ros_args
        overrides, addressed = ros_args.overrides_for(self._name, self._namespace)
        for parameter in parameter_overrides or []:
            overrides[parameter.name] = parameter.value
            addressed.add(parameter.name)
        self._parameters = ParameterStore(self.get_fully_qualified_name(), overrides,
                                          allow_undeclared_parameters, addressed)
        self._transport = ctx.transport
        self._clock = Clock(clock_type=ClockType.ROS_TIME, source=self._transport.sim_time_source)
        self._logger = RcutilsLogger(self._name, self._clock)
        self._publishers: list[Publisher] = []
        self._subscriptions: list[Subscription] = []
        self._timers: list[Timer] = []
        self._clock_subscription = None
        self._last_clock_ns = 0
        self._parameters.post_callbacks.append(self._on_use_sim_time)
        self.declare_parameter('use_sim_time', False)
        if automatically_declare_parameters_from_overrides:
            for name, value in overrides.items():
                if name not in self._parameters.parameters:
                    self.declare_parameter(name, value)
        ctx.register_node(self)

    # --- identity, logging, time ------------------------------------------------------------

    @_rclpy_forward
    def get_name(self) -> str:
        """Node name."""
        return self._name

    @_rclpy_forward
    def get_namespace(self) -> str:
        """Node namespace."""
        return self._namespace

    @_rclpy_forward
    def get_fully_qualified_name(self) -> str:
        """``/namespace/name``."""
        return fully_qualified_node_name(self._name, self._namespace)

    @_rclpy_forward
    def get_logger(self) -> RcutilsLogger:
        """The node's logger."""
        return self._logger

    def get_clock(self) -> Clock:
        """The node's clock (ROS time: simulated under inproc or use_sim_time)."""
        # _rclpy_forward spelled out: nodes ask for their clock many times per tick.
        if self._rclpy_node is not None:
            return self._rclpy_node.get_clock()
        return self._clock

    @property
    def rclpy_node(self):
        """The wrapped ``rclpy.node.Node`` (rclpy runtime only), else None."""
        return self._rclpy_node

    def _on_use_sim_time(self, parameters: list[Parameter]) -> None:
        for parameter in parameters:
            if parameter.name == 'use_sim_time':
                self._set_sim_time(bool(parameter.value))

    def _set_sim_time(self, enabled: bool) -> None:
        if self._transport.sim_time_source is not None:
            return  # inproc: time is always the executor's simulated clock
        if enabled and self._clock_subscription is None:
            clock_type = get_message('rosgraph_msgs/msg/Clock')
            self._clock_subscription = self.create_subscription(
                clock_type, '/clock', self._on_clock,
                QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
            self._clock.set_source(lambda: self._last_clock_ns)
        elif not enabled and self._clock_subscription is not None:
            self.destroy_subscription(self._clock_subscription)
            self._clock_subscription = None
            self._clock.set_source(None)

    def _on_clock(self, msg) -> None:
        self._last_clock_ns = msg.clock.sec * NS_PER_S + msg.clock.nanosec

    # --- communication ------------------------------------------------------------------------

    def _resolve(self, topic: str) -> str:
        name = expand_topic_name(topic, self._name, self._namespace)
        return self._remaps.get(name, name)

    @_rclpy_forward
    def resolve_topic_name(self, topic: str, *, only_expand: bool = False) -> str:
        """``topic`` expanded in the node's namespace and, unless ``only_expand``, remapped."""
        if only_expand:
            return expand_topic_name(topic, self._name, self._namespace)
        return self._resolve(topic)

    def create_publisher(self, msg_type, topic: str, qos_profile, *, callback_group=None,
                         event_callbacks=None, qos_overriding_options=None,
                         publisher_class=None) -> Publisher:
        """Publisher of ``msg_type`` on ``topic``; an int QoS is a keep-last depth."""
        message_type_name(msg_type)  # rejects non-message classes with a clear error
        if self._rclpy_node is not None:
            return self._rclpy_node.create_publisher(
                msg_type, topic, to_rclpy_qos(qos_profile), callback_group=callback_group,
                event_callbacks=event_callbacks, qos_overriding_options=qos_overriding_options,
                **({'publisher_class': publisher_class} if publisher_class else {}))
        profile = as_profile(qos_profile)
        name = self._resolve(topic)
        publisher = Publisher(self, msg_type, name, profile, None)
        publisher._impl = self._transport.create_publisher(self, msg_type, name, profile)
        self._publishers.append(publisher)
        return publisher

    def create_subscription(self, msg_type, topic: str, callback, qos_profile, *,
                            callback_group=None, event_callbacks=None,
                            qos_overriding_options=None, raw: bool = False) -> Subscription:
        """Subscription calling ``callback(msg)`` (``callback(bytes)`` when raw)."""
        message_type_name(msg_type)
        if self._rclpy_node is not None:
            return self._rclpy_node.create_subscription(
                msg_type, topic, callback, to_rclpy_qos(qos_profile),
                callback_group=callback_group, event_callbacks=event_callbacks,
                qos_overriding_options=qos_overriding_options, raw=raw)
        profile = as_profile(qos_profile)
        subscription = Subscription(self, msg_type, self._resolve(topic), callback, profile, raw)
        subscription.impl = self._transport.create_subscription(self, subscription)
        self._subscriptions.append(subscription)
        return subscription

    def create_timer(self, timer_period_sec: float, callback, callback_group=None, clock=None,
                     autostart: bool = True) -> Timer:
        """Timer calling ``callback()`` every ``timer_period_sec`` of ROS time.

        ``clock`` may be a clock of this runtime (under rclpy: one of the same type is made).
        """
        if not (isinstance(timer_period_sec, (int, float)) and math.isfinite(timer_period_sec)):
            raise GaitNodesError(f'timer period must be a finite number of seconds, '
                                 f'got {timer_period_sec!r}')
        if self._rclpy_node is not None:
            if isinstance(clock, Clock):
                from rclpy.clock import Clock as RclpyClock
                from rclpy.clock import ClockType as RclpyClockType

                clock = RclpyClock(clock_type=RclpyClockType(int(clock.clock_type)))
            return self._rclpy_node.create_timer(timer_period_sec, callback, callback_group,
                                                 clock, autostart)
        timer = Timer(callback, int(round(timer_period_sec * NS_PER_S)), clock or self._clock,
                      autostart)
        self._timers.append(timer)
        self._transport.timers_version += 1
        self._transport.notify()
        return timer

    @_rclpy_forward
    def destroy_publisher(self, publisher: Publisher) -> bool:
        """Release a publisher."""
        if publisher not in self._publishers:
            return False
        self._publishers.remove(publisher)
        publisher._impl.destroy()
        return True

    @_rclpy_forward
    def destroy_subscription(self, subscription: Subscription) -> bool:
        """Release a subscription."""
        if subscription not in self._subscriptions:
            return False
        self._subscriptions.remove(subscription)
        subscription.impl.destroy()
        return True

    @_rclpy_forward
    def destroy_timer(self, timer: Timer) -> bool:
        """Release a timer."""
        if timer not in self._timers:
            return False
        self._timers.remove(timer)
        self._transport.timers_version += 1
        timer.destroy()
        return True

    @property
    def publishers(self) -> list[Publisher]:
        """Publishers of this node."""
        return list(self._rclpy_node.publishers) if self._rclpy_node else list(self._publishers)

    @property
    def subscriptions(self) -> list[Subscription]:
        """Subscriptions of this node."""
        if self._rclpy_node:
            return list(self._rclpy_node.subscriptions)
        return list(self._subscriptions)

    @property
    def timers(self) -> list[Timer]:
        """Timers of this node."""
        return list(self._rclpy_node.timers) if self._rclpy_node else list(self._timers)

    @_rclpy_forward
    def count_subscribers(self, topic_name: str) -> int:
        """Subscriptions on ``topic_name`` in the graph (expanded, not remapped, as rclpy)."""
        return self._transport.count(self.resolve_topic_name(topic_name, only_expand=True),
                                     TopicEndpointTypeEnum.SUBSCRIPTION)

    @_rclpy_forward
    def count_publishers(self, topic_name: str) -> int:
        """Publishers on ``topic_name`` in the graph (expanded, not remapped, as rclpy).

        Every runtime counts the whole graph: this process's endpoints and, over DDS, every
        participant's on the domain (the built-in DCPSPublication topic), this node's own
        publishers included.
        """
        return self._transport.count(self.resolve_topic_name(topic_name, only_expand=True),
                                     TopicEndpointTypeEnum.PUBLISHER)

    @_rclpy_forward
    def get_publishers_info_by_topic(self, topic_name: str, no_mangle: bool = False) -> list:
        """:class:`TopicEndpointInfo` of every publisher on ``topic_name`` (remapped, as rclpy).

        ``no_mangle``: ``topic_name`` is a DDS topic name (``rt/...``) as it is.
        """
        return self._endpoints(topic_name, no_mangle, TopicEndpointTypeEnum.PUBLISHER)

    @_rclpy_forward
    def get_subscriptions_info_by_topic(self, topic_name: str, no_mangle: bool = False) -> list:
        """:class:`TopicEndpointInfo` of every subscription on ``topic_name``."""
        return self._endpoints(topic_name, no_mangle, TopicEndpointTypeEnum.SUBSCRIPTION)

    def _endpoints(self, topic_name: str, no_mangle: bool, kind) -> list:
        if not no_mangle:
            return self._transport.endpoints(self._resolve(topic_name), kind)
        # A DDS name: only the ROS convention's (rt/<name>) carries ROS topics here.
        if not topic_name.startswith('rt/'):
            return []
        return self._transport.endpoints(topic_name[2:], kind)

    @_rclpy_forward
    def destroy_node(self) -> None:
        """Release everything the node holds."""
        for publisher in list(self._publishers):
            self.destroy_publisher(publisher)
        for subscription in list(self._subscriptions):
            self.destroy_subscription(subscription)
        for timer in list(self._timers):
            self.destroy_timer(timer)
        self.context.unregister_node(self)

    # --- parameters ---------------------------------------------------------------------------

    @_rclpy_forward
    def declare_parameter(self, name: str, value=None, descriptor=None,
                          ignore_override: bool = False) -> Parameter:
        """Declare ``name``; its type is fixed by the default. Overrides win over the default."""
        return self._parameters.declare(name, value, descriptor, ignore_override)

    @_rclpy_forward
    def declare_parameters(self, namespace: str, parameters, ignore_override: bool = False):
        """Declare ``(name, value[, descriptor])`` tuples under ``namespace``."""
        declared = []
        for entry in parameters:
            name = f'{namespace}.{entry[0]}' if namespace else entry[0]
            value = entry[1] if len(entry) > 1 else None
            descriptor = entry[2] if len(entry) > 2 else None
            declared.append(self._parameters.declare(name, value, descriptor, ignore_override))
        return declared

    @_rclpy_forward
    def has_parameter(self, name: str) -> bool:
        """Whether ``name`` is declared."""
        return name in self._parameters.parameters

    @_rclpy_forward
    def get_parameter(self, name: str) -> Parameter:
        """A declared parameter."""
        return self._parameters.get(name)

    @_rclpy_forward
    def get_parameter_or(self, name: str, alternative_value=None) -> Parameter:
        """A declared parameter, or ``alternative_value`` when not declared."""
        if name not in self._parameters.parameters:
            return alternative_value
        return self._parameters.parameters[name]

    @_rclpy_forward
    def get_parameters(self, names) -> list[Parameter]:
        """Several declared parameters."""
        return [self._parameters.get(name) for name in names]

    @_rclpy_forward
    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        """Declared parameters under ``prefix.``, keyed without the prefix."""
        start = prefix + '.' if prefix else ''
        return {name[len(start):]: parameter
                for name, parameter in self._parameters.parameters.items()
                if name.startswith(start)}

    @_rclpy_forward
    def describe_parameter(self, name: str) -> ParameterDescriptor:
        """Descriptor of a declared parameter."""
        self._parameters.get(name)
        return self._parameters.descriptors[name]

    def set_parameters(self, parameter_list) -> list[SetParametersResult]:
        """Set each parameter on its own; each result says whether it was accepted and why not."""
        if self._rclpy_node is not None:
            return self._rclpy_node.set_parameters(_to_rclpy_parameters(parameter_list))
        return [self._parameters.set_atomically([parameter]) for parameter in parameter_list]

    def set_parameters_atomically(self, parameter_list) -> SetParametersResult:
        """Set all parameters or none."""
        if self._rclpy_node is not None:
            return self._rclpy_node.set_parameters_atomically(
                _to_rclpy_parameters(parameter_list))
        return self._parameters.set_atomically(list(parameter_list))

    def add_on_set_parameters_callback(self, callback) -> None:
        """Call ``callback(parameters) -> SetParametersResult`` before any change is applied."""
        if self._rclpy_node is not None:
            wrapped = _wrap_for_rclpy(callback)
            self._wrapped_callbacks[callback] = wrapped
            self._rclpy_node.add_on_set_parameters_callback(wrapped)
            return
        self._parameters.callbacks.insert(0, callback)

    def remove_on_set_parameters_callback(self, callback) -> None:
        """Stop calling ``callback``."""
        if self._rclpy_node is not None:
            wrapped = self._wrapped_callbacks.pop(callback)
            self._rclpy_node.remove_on_set_parameters_callback(wrapped)
            return
        self._parameters.callbacks.remove(callback)

    @_rclpy_forward
    def add_post_set_parameters_callback(self, callback) -> None:
        """Call ``callback(parameters)`` after a change was applied."""
        self._parameters.post_callbacks.append(callback)

    def unused_parameter_overrides(self) -> list[str]:
        """Overrides addressed to this node (``-p``, its params-file section) never declared.

        Overrides for every node (the ``/**`` section of a params file) are not counted: each
        node takes the ones it declares.
        """
        if self._rclpy_node is None:
            return self._parameters.unused_overrides()
        # rclpy keeps no record of which overrides named this node: read the same arguments.
        _, addressed = self.context.ros_args.overrides_for(self.get_name(),
                                                           self.get_namespace())
        return sorted(name for name in addressed if not self._rclpy_node.has_parameter(name))

    def check_parameter_overrides(self, accepted: Iterable[str] = ()) -> None:
        """Raise when an override names a parameter this node does not declare.

        Args:
            accepted: Names the node will declare later (a check before its start-up work).
        """
        accepted = set(accepted)
        unknown = [name for name in self.unused_parameter_overrides() if name not in accepted]
        if unknown:
            declared = set(self._rclpy_node.get_parameters_by_prefix('') if self._rclpy_node
                           else self._parameters.parameters)
            ros_args = self.context.ros_args if self._rclpy_node else self._ros_args
            sources = ros_args.override_sources(self.get_name(), self.get_namespace())
            raise ParameterNotDeclaredError(unknown_parameters_message(
                self.get_fully_qualified_name(), unknown, sources, sorted(declared | accepted)))


def _to_rclpy_parameters(parameter_list) -> list:
    """Our Parameters as rclpy's own (rclpy's pass as they are)."""
    from rclpy.parameter import Parameter as RclpyParameter

    return [RclpyParameter(parameter.name, value=parameter.value)
            if isinstance(parameter, Parameter) else parameter for parameter in parameter_list]


def _wrap_for_rclpy(callback):
    """Adapt a callback returning our SetParametersResult to rclpy's message type."""

    def wrapped(parameters):
        result = callback(parameters)
        if isinstance(result, SetParametersResult):
            from rcl_interfaces.msg import SetParametersResult as RclResult

            return RclResult(successful=result.successful, reason=result.reason)
        return result

    return wrapped
