"""Start the gait_nodes graph on a ROS 2 Jazzy machine.

Usage::

    ros2 launch gait_nodes gait.launch.py robot:=robosimian gait:=crawl
    ros2 launch gait_nodes gait.launch.py record:=bags/walk   # also record to an MCAP bag
    ros2 launch gait_nodes gait.launch.py robot:=biped gait:=biped swing:=polynomial
    ros2 launch gait_nodes gait.launch.py namespace:=robot1 use_sim_time:=false  # a second robot
    ros2 launch gait_nodes gait.launch.py simulator:=physics  # in MuJoCo (pip install mujoco)
    ros2 launch gait_nodes gait.launch.py state_publisher:=false  # for ROS's robot_state_publisher

The robot walks when it is asked to: ``ros2 topic pub /cmd_vel geometry_msgs/msg/Twist
"{linear: {x: 0.04}}"`` or ``python -m gait_nodes.command --vel 0.04 0 0``.

Each node loads ``share/gait_nodes/config/<node>.yaml`` when the package ships one, then the
launch arguments. Without ROS, ``python -m gait_nodes run`` starts the same graph.

Our robot_state_publisher puts the robot's URDF on /robot_description and its links on
/tf_static and /tf, for RViz (``rviz2 -d share/gait_nodes/config/gait.rviz``) and Foxglove
(``config/foxglove_layout.json``). With ``state_publisher:=false`` it is left out, to run ROS's
own robot_state_publisher with the URDF instead (docs/ros_tools.md).

``namespace`` puts the whole graph, the recorder included, in a ROS namespace with launch_ros'
own mechanism (``/robot1/gait/footsteps``, ``/robot1/footstep_planner``; the launch file may
also be included under a PushRosNamespace). /tf, /tf_static and /diagnostics are remapped into
it, as nav2 does for a robot of several; /clock stays global, so two simulated robots on one
domain run with ``use_sim_time:=false`` (two simulators' /clock would mix their times).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, SetEnvironmentVariable
from launch.conditions import IfCondition
from launch.substitutions import (
    EnvironmentVariable,
    EqualsSubstitution,
    LaunchConfiguration,
    NotEqualsSubstitution,
)
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from gait_nodes.cli import NODE_ENVIRONMENT_DEFAULTS
from gait_nodes.graph import ROBOT_TOPICS, SIMULATORS

PACKAGE = 'gait_nodes'

#: Nodes of the walking pipeline, in data-flow order.
GAIT_NODES = (
    'footstep_planner',
    'com_preview_controller',
    'swing_leg_policy',
    'whole_body_ik',
    'kinematic_simulator',
)
#: /robot_description, /tf_static and the links' /tf (the state_publisher argument).
STATE_PUBLISHER = 'robot_state_publisher'
#: The simulator argument's values -> the simulator node it starts (one of them runs).
SIMULATOR_NODES = dict(SIMULATORS)


def _params_file(node_name):
    """Shipped params file of ``node_name`` as a list of zero or one path."""
    path = os.path.join(get_package_share_directory(PACKAGE), 'config', f'{node_name}.yaml')
    return [path] if os.path.exists(path) else []


def generate_launch_description():
    """Declare the launch arguments and the gait nodes, plus the recorder when asked."""
    # Typed, so that a robot or gait name is never read as YAML (`on` -> true).
    robot = ParameterValue(LaunchConfiguration('robot'), value_type=str)
    gait = ParameterValue(LaunchConfiguration('gait'), value_type=str)
    swing = ParameterValue(LaunchConfiguration('swing'), value_type=str)
    use_sim_time = ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)
    record = LaunchConfiguration('record')
    simulator = LaunchConfiguration('simulator')
    namespace = LaunchConfiguration('namespace')
    # The robot's own absolute topics go into its namespace with it (no-ops without one).
    remappings = [(topic, topic.lstrip('/')) for topic in ROBOT_TOPICS]

    arguments = [
        DeclareLaunchArgument(
            'robot',
            default_value='robosimian',
            description='Robot name: config/robots/<robot>.yaml and its URDF.',
        ),
        DeclareLaunchArgument(
            'gait',
            default_value='crawl',
            description='Initial gait of the footstep planner (crawl, trot, ...), and of the '
                        'swing-leg policy\'s time law.',
        ),
        DeclareLaunchArgument(
            'swing',
            default_value='value_table',
            description='Swing of the planner and the swing policy: value_table (robots with '
                        'closed-form limb IK; others fall back to polynomial) or polynomial.',
        ),
        DeclareLaunchArgument(
            'simulator',
            default_value='kinematic',
            description='kinematic: kinematic_simulator (exact, fast); physics: '
                        'physics_simulator (MuJoCo: contacts, gains, effort limits).',
        ),
        DeclareLaunchArgument(
            'use_sim_time',
            default_value='true',
            description='Follow /clock, published by the simulator.',
        ),
        DeclareLaunchArgument(
            'namespace',
            default_value='',
            description='ROS namespace of the graph (e.g. robot1): its topics, nodes and '
                        'recorder go under it; empty: none.',
        ),
        DeclareLaunchArgument(
            'state_publisher',
            default_value='true',
            description='Start our robot_state_publisher (/robot_description, /tf_static, '
                        "the links' /tf); false: leave it out, to run ROS's own.",
        ),
        DeclareLaunchArgument(
            'record',
            default_value='',
            description='Output bag directory of the recorder; empty: do not record.',
        ),
    ]

    # One BLAS thread per node unless the environment says otherwise (see gait_nodes.cli).
    environment = [SetEnvironmentVariable(name, EnvironmentVariable(name, default_value=value))
                   for name, value in NODE_ENVIRONMENT_DEFAULTS.items()]
    nodes = []
    simulator_of = {node: kind for kind, node in SIMULATOR_NODES.items()}
    for node_name in dict.fromkeys((*GAIT_NODES, *SIMULATOR_NODES.values())):
        overrides = {'use_sim_time': use_sim_time, 'robot': robot}
        if node_name in ('footstep_planner', 'swing_leg_policy'):
            overrides['gait'] = gait  # the policy times the gait's swings in its time law
        if node_name in ('footstep_planner', 'swing_leg_policy'):
            overrides['swing'] = swing
        condition = None
        if node_name in simulator_of:
            # The simulator owns simulated time: it publishes the /clock the others follow.
            overrides['publish_clock'] = use_sim_time
            condition = IfCondition(EqualsSubstitution(simulator, simulator_of[node_name]))
        nodes.append(
            Node(
                package=PACKAGE,
                executable=node_name,
                name=node_name,
                namespace=namespace,
                output='screen',
                parameters=[*_params_file(node_name), overrides],
                remappings=remappings,
                condition=condition,
            )
        )

    nodes.append(
        Node(
            package=PACKAGE,
            executable=STATE_PUBLISHER,
            name=STATE_PUBLISHER,
            namespace=namespace,
            output='screen',
            parameters=[*_params_file(STATE_PUBLISHER),
                        {'use_sim_time': use_sim_time, 'robot': robot}],
            remappings=remappings,
            condition=IfCondition(LaunchConfiguration('state_publisher')),
        )
    )
    nodes.append(
        Node(
            package=PACKAGE,
            executable='recorder',
            name='recorder',
            namespace=namespace,
            output='screen',
            remappings=remappings,
            # The robot's per-foot topics (/gait/contact_wrench/<foot>) too: physics_simulator's.
            arguments=['-o', record, '--robot', LaunchConfiguration('robot')],
            parameters=[*_params_file('recorder'), {'use_sim_time': use_sim_time}],
            condition=IfCondition(NotEqualsSubstitution(record, '')),
        )
    )

    return LaunchDescription(arguments + environment + nodes)
