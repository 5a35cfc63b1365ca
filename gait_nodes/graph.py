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
}
RECORDER = 'gait_nodes.recorder:Recorder'

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
    '/gait/zmp': 'geometry_msgs/msg/PointStamped',
    '/gait/com': 'geometry_msgs/msg/PointStamped',
    '/gait/support_polygon': 'geometry_msgs/msg/PolygonStamped',
    '/gait/markers': 'visualization_msgs/msg/MarkerArray',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/clock': 'rosgraph_msgs/msg/Clock',
}


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
