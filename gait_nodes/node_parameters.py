"""The parameters each node of the graph declares, known before the node is built.

A node declares its parameters in its constructor (as in ros2/examples), most of them after
seconds of start-up work (the robot model, the IK, a value table). To refuse a misspelt name in
a params file at once, the names are known here without building the node: the
``ros__parameters`` of its ``config/<node>.yaml``, which each graph node declares, plus those it
declares beyond them (``_BEYOND_DEFAULTS``, read from the definitions the node itself declares
from). test_node_parameters builds every node and checks these names against its declarations.
"""

from __future__ import annotations

import dataclasses

from gait_nodes import graph
from gait_nodes.errors import ParameterNotDeclaredError
from gait_nodes.paths import node_defaults
from gait_nodes.runtime.args import RosArguments, unknown_parameters_message

RECORDER = 'recorder'
#: Declared by the runtime for every node (rclpy's Node declares it too).
RUNTIME_PARAMETERS = frozenset({'use_sim_time'})
#: Declared by rclpy's Node (Jazzy) besides use_sim_time.
RCLPY_PARAMETERS = frozenset({'start_type_description_service'})


def _gait_settings_and_terrain() -> set[str]:
    # footstep_planner declares every gait setting (four default to the robot's YAML, so its
    # config file leaves them out) and the staircase.
    from gait_nodes.planning.gait_params import GaitParameters
    from gait_nodes.planning.terrain import STAIRS_DEFAULTS

    return {field.name for field in dataclasses.fields(GaitParameters)} | set(STAIRS_DEFAULTS)


def _recorder_parameters() -> set[str]:
    from gait_nodes.recorder import parameter_defaults

    return set(parameter_defaults())


#: Node -> the names it declares beyond its config/<node>.yaml (imported when asked).
_BEYOND_DEFAULTS = {'footstep_planner': _gait_settings_and_terrain,
                    RECORDER: _recorder_parameters}


def parameter_names(node: str) -> frozenset[str] | None:
    """Every parameter node ``node`` declares (runtime's included), or None if it is not ours.

    Args:
        node: The node's own name (before any ``__node`` remapping): a graph node or the
            recorder.
    """
    graph_node = node in graph.NODES or node in graph.ALTERNATIVE_NODES
    if not graph_node and node != RECORDER:
        return None
    names = set(node_defaults(node)) if graph_node else set()
    if node in _BEYOND_DEFAULTS:
        names |= _BEYOND_DEFAULTS[node]()
    return frozenset(names | RUNTIME_PARAMETERS)


def check_overrides(node: str, ros_args: RosArguments, runtime: str | None = None) -> None:
    """Refuse, before node ``node`` is started, overrides addressed to it that it lacks.

    The same rule the node applies once built (:meth:`gait_nodes.runtime.Node.
    check_parameter_overrides`): ``-p`` values and params-file sections that name the node must
    name its parameters; wildcard sections (``/**``) may hold other nodes' parameters.

    Args:
        node: The node's own name (a graph node or the recorder; others are not checked).
        ros_args: The arguments it will be started with.
        runtime: The runtime it will run on ('rclpy' declares one more parameter).

    Raises:
        ParameterNotDeclaredError: Naming each unknown parameter, where it was given (the
            params file's path, or ``-p``) and the names the node accepts.
    """
    accepted = parameter_names(node)
    if accepted is None:
        return
    if runtime == 'rclpy':
        accepted |= RCLPY_PARAMETERS
    name, namespace = ros_args.node_name(node), ros_args.namespace(None)
    _, addressed = ros_args.overrides_for(name, namespace)
    unknown = sorted(addressed - accepted)
    if unknown:
        full_name = f'{namespace.rstrip("/")}/{name}'
        raise ParameterNotDeclaredError(unknown_parameters_message(
            full_name, unknown, ros_args.override_sources(name, namespace), sorted(accepted)))
