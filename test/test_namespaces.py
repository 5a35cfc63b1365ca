"""ROS namespaces and single-publisher inputs, in one process (inproc): names, graph, launchers.

Names resolve as rclpy resolves them (rcl_expand_topic_name, then the remap rules); the graph
API counts and names the publishers of a topic; a node's single-source input refuses a second
publisher; ``run --namespace`` and the launch file put every node under the namespace.
"""

from __future__ import annotations

import ast
import importlib.util
import sys
import types
from pathlib import Path

import pytest

from gait_nodes import graph, runtime
from gait_nodes.bag.analysis import bag_namespace
from gait_nodes.diagnostics import ERROR, OK
from gait_nodes.errors import ArgumentError, GaitNodesError
from gait_nodes.interfaces import std_msgs
from gait_nodes.runtime.endpoints import TopicEndpointTypeEnum, node_of
from gait_nodes.runtime.names import InvalidTopicNameError, expand_topic_name
from gait_nodes.single_source import SingleSource
from gait_nodes.watchdog import InputWatchdog

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def start():
    """``start(*ros_args)``: init the inproc runtime with ``--ros-args ...``."""
    started = []

    def init(*ros_args):
        runtime.init(args=['test', '--ros-args', *ros_args] if ros_args else ['test'],
                     runtime='inproc', signal_handlers=False)
        started.append(True)

    yield init
    if started:
        runtime.shutdown()


@pytest.mark.parametrize(('topic', 'namespace', 'expected'), [
    ('chatter', '/', '/chatter'),
    ('chatter', '/robot1', '/robot1/chatter'),
    ('gait/footsteps', '/robot1', '/robot1/gait/footsteps'),
    ('gait/footsteps', '/a/b', '/a/b/gait/footsteps'),
    ('/tf', '/robot1', '/tf'),
    ('/gait/footsteps', '/robot1', '/gait/footsteps'),
    ('~', '/robot1', '/robot1/talker'),
    ('~/state', '/robot1', '/robot1/talker/state'),
    ('~/state', '/', '/talker/state'),
    ('{node}/out', '/robot1', '/robot1/talker/out'),
    ('{ns}/out', '/robot1', '/robot1/out'),
    ('{namespace}/out', '/', '/out'),
])
def test_names_expand_as_rcl_expands_them(topic, namespace, expected):
    assert expand_topic_name(topic, 'talker', namespace) == expected


@pytest.mark.parametrize('topic', ['', '~x', 'a/~/b', '1chatter', 'a//b', 'a/', 'a b',
                                   'gait/2d', '{nope}/x', '{node'])
def test_names_rcl_refuses_are_refused(topic):
    with pytest.raises(InvalidTopicNameError):
        expand_topic_name(topic, 'talker', '/robot1')


def test_a_node_under_ns_remap_resolves_relative_names_in_it_and_keeps_absolute_ones(start):
    start('-r', '__ns:=/robot1', '-r', '/tf:=tf')
    node = runtime.Node('talker')
    assert node.get_namespace() == '/robot1'
    assert node.get_fully_qualified_name() == '/robot1/talker'
    relative = node.create_publisher(std_msgs.msg.String, 'gait/footsteps', 10)
    absolute = node.create_publisher(std_msgs.msg.String, '/diagnostics', 10)
    private = node.create_publisher(std_msgs.msg.String, '~/state', 10)
    remapped = node.create_publisher(std_msgs.msg.String, '/tf', 10)
    assert relative.topic_name == '/robot1/gait/footsteps'
    assert absolute.topic_name == '/diagnostics'
    assert private.topic_name == '/robot1/talker/state'
    assert remapped.topic_name == '/robot1/tf'  # '/tf:=tf': the target expands in the namespace
    assert node.resolve_topic_name('/tf') == '/robot1/tf'
    assert node.resolve_topic_name('/tf', only_expand=True) == '/tf'


def test_a_node_specific_ns_remap_moves_that_node_only(start):
    start('-r', 'talker:__ns:=/robot2')
    assert runtime.Node('talker').get_namespace() == '/robot2'
    assert runtime.Node('listener').get_namespace() == '/'


def test_params_file_keys_name_nodes_as_rclpy_matches_them(start, tmp_path):
    path = tmp_path / 'params.yaml'
    path.write_text('talker:\n  ros__parameters: {gain: 2.0}\n'
                    '/**/listener:\n  ros__parameters: {gain: 3.0}\n')
    start('--params-file', str(path))
    assert runtime.Node('talker').declare_parameter('gain', 1.0).value == 2.0
    # A plain key is /talker: it does not name /robot1/talker (rclpy prepends the '/').
    assert runtime.Node('talker', namespace='/robot1').declare_parameter('gain', 1.0).value \
        == 1.0
    assert runtime.Node('listener', namespace='/robot1').declare_parameter(
        'gain', 1.0).value == 3.0


def test_the_graph_counts_and_names_the_publishers_of_a_topic(start):
    start('-r', '/tf:=tf')
    one = runtime.Node('one', namespace='/r1')
    two = runtime.Node('two', namespace='/r1')
    other = runtime.Node('one', namespace='/r2')
    for node in (one, two, other):
        node.create_publisher(std_msgs.msg.String, 'joint_commands', 10)
    one.create_subscription(std_msgs.msg.String, 'joint_commands', lambda msg: None, 10)
    assert one.count_publishers('joint_commands') == 2
    assert one.count_publishers('/r2/joint_commands') == 1
    assert one.count_subscribers('joint_commands') == 1
    infos = one.get_publishers_info_by_topic('joint_commands')
    assert sorted(node_of(info) for info in infos) == ['/r1/one', '/r1/two']
    assert {info.endpoint_type for info in infos} == {TopicEndpointTypeEnum.PUBLISHER}
    assert {info.topic_type for info in infos} == {'std_msgs/msg/String'}
    two.create_publisher(std_msgs.msg.String, '/tf', 10)
    # count_publishers expands, it does not remap (rclpy); the info query remaps.
    assert two.count_publishers('/tf') == 0
    assert two.count_publishers('tf') == 1
    assert len(two.get_publishers_info_by_topic('/tf')) == 1


def test_an_input_with_two_publishers_is_refused_with_an_error_then_taken_again(start):
    start()
    consumer = runtime.Node('kinematic_simulator', namespace='/robot1')
    now_ns = consumer.get_clock().now().nanoseconds
    inputs = InputWatchdog(['/joint_commands'], 0.5, now_ns)
    sources = SingleSource(consumer, ['/joint_commands'], 'holding the robot',
                           watchdog=inputs)
    assert sources.names == {'/joint_commands': '/robot1/joint_commands'}
    # The consumer's own publisher on the topic is not a second source.
    consumer.create_publisher(std_msgs.msg.String, 'joint_commands', 10)
    publishers = []
    for name in ('ik_a', 'ik_b'):
        node = runtime.Node(name, namespace='/robot1')
        publishers.append((node, node.create_publisher(std_msgs.msg.String,
                                                       'joint_commands', 10)))
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(consumer)
    executor.spin_for(1.2)
    assert sources.refuses('/joint_commands')
    assert inputs.update(consumer.get_clock().now().nanoseconds)
    aspect, level, message, values = inputs.status(consumer.get_clock().now().nanoseconds)
    assert (aspect, level) == ('inputs', ERROR)
    assert '2 publishers on /robot1/joint_commands' in message
    assert '/robot1/ik_a' in message and '/robot1/ik_b' in message
    assert 'holding the robot' in message
    assert values['refused'] == '/joint_commands'
    assert values['/joint_commands publishers'] == 2
    assert '/joint_commands' in values['stale'].split(',')  # a planner pauses on it

    node, publisher = publishers.pop()
    node.destroy_publisher(publisher)
    executor.spin_for(1.0)
    assert not sources.refused
    inputs.heard('/joint_commands', consumer.get_clock().now().nanoseconds)
    inputs.update(consumer.get_clock().now().nanoseconds)
    assert inputs.status(consumer.get_clock().now().nanoseconds)[1] == OK


def test_namespace_arguments_put_a_robot_and_its_tf_and_diagnostics_in_the_namespace():
    assert graph.namespace_arguments(None) == []
    assert graph.namespace_arguments('/') == []
    assert graph.namespace_arguments('robot1') == [
        '-r', '__ns:=/robot1', '-r', '/tf:=tf', '-r', '/tf_static:=tf_static',
        '-r', '/diagnostics:=diagnostics']
    for bad in ('/robot1/', '1robot', '/a//b', 'a b'):
        with pytest.raises(ArgumentError):
            graph.namespace_arguments(bad)
    assert graph.node_topic_name('/gait/footsteps') == 'gait/footsteps'
    assert graph.node_topic_name('/clock') == '/clock'


def test_a_bag_namespace_is_found_from_its_topics_and_two_graphs_need_a_choice():
    one = ['/r1' + topic for topic in graph.TOPICS if topic != '/clock'] + ['/clock']
    assert bag_namespace(one) == '/r1'
    assert bag_namespace(list(graph.TOPICS)) == '/'
    assert bag_namespace(['/rosout']) == '/'
    assert graph.contract_topics(one, '/r1')['/r1/gait/footsteps'] == '/gait/footsteps'
    assert graph.contract_topics(one, '/r1')['/clock'] == '/clock'
    # /tf not remapped into the namespace still counts, unless the namespace has its own.
    assert graph.contract_topics(['/r1/gait/zmp', '/tf'], '/r1')['/tf'] == '/tf'
    assert '/tf' not in graph.contract_topics(['/r1/tf', '/tf'], '/r1')
    two = one + ['/r2' + topic for topic in graph.TOPICS if topic != '/clock']
    with pytest.raises(GaitNodesError, match='--namespace'):
        bag_namespace(two)
    assert bag_namespace(two, 'r2') == '/r2'


def test_run_fast_with_a_namespace_records_the_namespaced_topics(tmp_path, capsys):
    from gait_nodes.__main__ import main
    from gait_nodes.bag.reader import BagReader

    bag = tmp_path / 'bag'
    assert main(['run', '--fast', '--scenario', 'biped_walk', '--duration', '2',
                 '--namespace', 'r1', '--record', str(bag), '--no-plot', '--json']) == 0
    reader = BagReader(bag)
    for _ in reader.messages(topics=()):
        pass
    topics = {channel.topic for channel in reader.channels.values()}
    assert topics == {'/r1' + t for t in graph.TOPICS if t != '/clock'} | {'/clock'}
    out = capsys.readouterr().out
    assert '"namespace": "/r1"' in out
    assert '"/joint_states"' in out  # the summary's topics by contract name


def _fake_launch_modules(captured: list) -> dict:
    """Stand-ins for launch and launch_ros that record what the launch file asks for."""

    def recorder(kind):
        def make(*args, **kwargs):
            captured.append((kind, args, kwargs))
            return (kind, args, kwargs)
        return make

    modules = {}
    for name, attributes in {
        'launch': {'LaunchDescription': recorder('LaunchDescription')},
        'launch.actions': {'DeclareLaunchArgument': recorder('DeclareLaunchArgument'),
                           'SetEnvironmentVariable': recorder('SetEnvironmentVariable')},
        'launch.conditions': {'IfCondition': recorder('IfCondition')},
        'launch.substitutions': {name: recorder(name) for name in (
            'EnvironmentVariable', 'EqualsSubstitution', 'LaunchConfiguration',
            'NotEqualsSubstitution')},
        'launch_ros': {},
        'launch_ros.actions': {'Node': recorder('Node')},
        'launch_ros.parameter_descriptions': {'ParameterValue': recorder('ParameterValue')},
        'ament_index_python': {},
        'ament_index_python.packages': {
            'get_package_share_directory': lambda package: str(REPO)},
    }.items():
        module = types.ModuleType(name)
        module.__dict__.update(attributes)
        modules[name] = module
    return modules


def test_the_launch_file_puts_every_node_and_the_recorder_in_the_namespace(monkeypatch):
    captured = []
    for name, module in _fake_launch_modules(captured).items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location('gait_launch', REPO / 'launch' /
                                                  'gait.launch.py')
    launch_file = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(launch_file)
    launch_file.generate_launch_description()
    nodes = [kwargs for kind, _, kwargs in captured if kind == 'Node']
    assert sorted(node['name'] for node in nodes) == sorted(
        [*launch_file.GAIT_NODES, 'physics_simulator', 'robot_state_publisher', 'recorder'])
    namespace = ('LaunchConfiguration', ('namespace',), {})
    for node in nodes:
        assert node['namespace'] == namespace, node['name']
        assert node['remappings'] == [('/tf', 'tf'), ('/tf_static', 'tf_static'),
                                      ('/diagnostics', 'diagnostics')], node['name']
    tree = ast.parse((REPO / 'launch' / 'gait.launch.py').read_text())
    assert 'namespace' in {call.args[0].value for call in ast.walk(tree)
                           if isinstance(call, ast.Call) and call.args
                           and getattr(call.func, 'id', '') == 'DeclareLaunchArgument'}
