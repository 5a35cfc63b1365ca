"""The node graph of the public topic contract (see DESIGN.md): which nodes, which topics."""

from __future__ import annotations

import importlib
import importlib.util

from gait_nodes.errors import GaitNodesError

#: Node name -> "module:Class". A node whose module is not there yet is skipped by ``run``.
NODES: dict[str, str] = {
    'footstep_planner': 'gait_nodes.footstep_planner:FootstepPlanner',
    'com_preview_controller': 'gait_nodes.com_preview_controller:ComPreviewController',
    'swing_leg_policy': 'gait_nodes.swing_leg_policy:SwingLegPolicy',
    'whole_body_ik': 'gait_nodes.whole_body_ik:WholeBodyIk',
    'kinematic_simulator': 'gait_nodes.kinematic_simulator:KinematicSimulator',
    'robot_state_publisher': 'gait_nodes.robot_state_publisher:RobotStatePublisher',
}
#: The node that publishes /robot_description, /tf_static and the links' /tf; ``run
#: --no-state-publisher`` (launch: ``state_publisher:=false``) leaves it out, for ROS's own.
STATE_PUBLISHER = 'robot_state_publisher'
RECORDER = 'gait_nodes.recorder:Recorder'
#: Nodes that can take a node's place in the graph, started only when chosen.
ALTERNATIVE_NODES: dict[str, str] = {
    'physics_simulator': 'gait_nodes.physics_simulator:PhysicsSimulator',
}
#: ``run --simulator`` -> the simulator node: the graph runs exactly one of them.
SIMULATORS: dict[str, str] = {'kinematic': 'kinematic_simulator',
                              'physics': 'physics_simulator'}
DEFAULT_SIMULATOR = 'kinematic'

#: Topic -> message type, the public contract.
TOPICS: dict[str, str] = {
    '/cmd_vel': 'geometry_msgs/msg/Twist',
    '/gait/command': 'std_msgs/msg/String',
    '/gait/command_status': 'std_msgs/msg/String',
    '/gait/footsteps': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    '/gait/zmp_reference': 'nav_msgs/msg/Path',
    '/gait/com_reference': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    '/gait/swing_trajectory': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    '/joint_commands': 'trajectory_msgs/msg/JointTrajectory',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/tf': 'tf2_msgs/msg/TFMessage',
    '/tf_static': 'tf2_msgs/msg/TFMessage',
    '/robot_description': 'std_msgs/msg/String',
    '/gait/zmp': 'geometry_msgs/msg/PointStamped',
    '/gait/com': 'geometry_msgs/msg/PointStamped',
    '/gait/support_polygon': 'geometry_msgs/msg/PolygonStamped',
    '/gait/markers': 'visualization_msgs/msg/MarkerArray',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/gait/cop': 'geometry_msgs/msg/PointStamped',
}
#: Contract topics whose publishers are latched (reliable, transient local, depth 1): a late
#: subscriber gets the last message, and a bag records their QoS so that playback latches them.
LATCHED_TOPICS = ('/gait/footsteps', '/robot_description', '/tf_static')
#: Topic families with one topic per foot of the robot, ``<prefix><foot name>``
#: (``/gait/contact_wrench/front_left``) -> message type.
FOOT_TOPICS: dict[str, str] = {
    '/gait/contact_wrench/': 'geometry_msgs/msg/WrenchStamped',
}


def foot_topics(foot_names) -> dict[str, str]:
    """``{topic: type}`` of the per-foot topic families for a robot's feet."""
    return {prefix + foot: type_name for prefix, type_name in FOOT_TOPICS.items()
            for foot in foot_names}


def node_path(name: str) -> str:
    """The ``module:Class`` of a graph node or of an alternative one (a simulator)."""
    if name in NODES:
        return NODES[name]
    if name in ALTERNATIVE_NODES:
        return ALTERNATIVE_NODES[name]
    raise GaitNodesError(f'unknown node {name!r}; nodes: '
                         f'{", ".join([*NODES, *ALTERNATIVE_NODES])}')


def graph_nodes(simulator: str = DEFAULT_SIMULATOR) -> list[str]:
    """The installed nodes of the graph in graph order, ``simulator``'s in the simulator's place.

    Args:
        simulator: A key of SIMULATORS.
    """
    chosen = SIMULATORS[simulator]
    return [chosen if name in SIMULATORS.values() else name for name in available_nodes()]


#: Contract topics that the nodes name absolutely, as ROS libraries do: tf2 (``/tf``,
#: ``/tf_static``), diagnostic_updater (``/diagnostics``) and rclpy's time source (``/clock``).
#: Every other topic is named relative (``gait/footsteps``), so that a node's namespace
#: (``--ros-args -r __ns:=/robot1``) puts it under ``/robot1``.
ABSOLUTE_TOPICS = ('/tf', '/tf_static', '/diagnostics', '/clock')
#: The absolute topics that belong to one robot: a launcher that starts a robot in a namespace
#: remaps them into it (``-r /tf:=tf``), as nav2's multi-robot launch files do. ``/clock`` stays
#: global: one time for the domain, as ROS has it.
ROBOT_TOPICS = ('/tf', '/tf_static', '/diagnostics')


def node_topic_name(topic: str) -> str:
    """How the nodes name contract topic ``topic``: relative unless in ABSOLUTE_TOPICS."""
    return topic if topic in ABSOLUTE_TOPICS else topic.lstrip('/')


def namespace_arguments(namespace: str | None) -> list[str]:
    """ROS arguments (inside ``--ros-args``) that start a node in ``namespace`` as a robot's.

    ``-r __ns:=NS`` and, for the topics of ROBOT_TOPICS, ``-r /tf:=tf``: empty without one.
    """
    if namespace in (None, '', '/'):
        return []
    from gait_nodes.runtime.args import absolute_namespace

    arguments = ['-r', f'__ns:={absolute_namespace(namespace)}']
    for topic in ROBOT_TOPICS:
        arguments += ['-r', f'{topic}:={topic.lstrip("/")}']
    return arguments


def contract_topics(topics, namespace: str = '/') -> dict[str, str]:
    """``{topic: contract topic}`` for the topics of a graph run in ``namespace``.

    ``/robot1/gait/footsteps`` is ``/gait/footsteps`` of namespace ``/robot1``; an absolute
    topic of ABSOLUTE_TOPICS (``/tf`` not remapped into the namespace) counts too, unless the
    namespace has its own. Topics of other namespaces are left out.
    """
    prefix = '' if namespace == '/' else namespace.rstrip('/')
    names: dict[str, str] = {}
    for topic in topics:
        if prefix and topic.startswith(prefix + '/') and topic[len(prefix):] in TOPICS:
            names[topic] = topic[len(prefix):]
    taken = set(names.values())
    for topic in topics:
        if topic in TOPICS and topic not in taken and (not prefix or topic in ABSOLUTE_TOPICS):
            names[topic] = topic
    return names


def graph_namespaces(topics) -> dict[str, int]:
    """The namespaces whose contract topics are among ``topics``: ``{namespace: count}``.

    ``/r1/gait/zmp`` counts for ``/r1``, ``/gait/zmp`` for ``/``; the absolute topics of
    ABSOLUTE_TOPICS count for ``/`` only when no namespace has other contract topics.
    """
    counts: dict[str, int] = {}
    for topic in topics:
        for contract in TOPICS:
            if topic.endswith(contract) and (len(topic) == len(contract)
                                             or topic[-len(contract) - 1] != '/'):
                namespace = topic[:-len(contract)] or '/'
                if namespace == '/' and contract in ABSOLUTE_TOPICS:
                    continue
                counts[namespace] = counts.get(namespace, 0) + 1
    if not counts and any(topic in ABSOLUTE_TOPICS for topic in topics):
        counts['/'] = 1
    return counts


def module_exists(path: str) -> bool:
    """Whether the module of a ``module:Class`` path is installed."""
    module = path.split(':')[0]
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


def available_nodes() -> list[str]:
    """Contract nodes whose modules exist, in graph order."""
    return [name for name, path in NODES.items() if module_exists(path)]


def load_class(path: str) -> type:
    """The class named by ``module:Class``."""
    module_name, _, class_name = path.partition(':')
    module = importlib.import_module(module_name)
    try:
        return getattr(module, class_name)
    except AttributeError as exc:
        raise GaitNodesError(f'{module_name} has no node class {class_name}') from exc
