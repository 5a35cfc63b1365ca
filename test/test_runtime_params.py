"""ROS parameters and ``--ros-args`` under the inproc runtime, checked against rclpy's ways."""

import math
import textwrap

import pytest

from gait_nodes import runtime
from gait_nodes.errors import (
    ArgumentError,
    InvalidParameterTypeError,
    ParameterError,
    ParameterNotDeclaredError,
)
from gait_nodes.interfaces import std_msgs
from gait_nodes.runtime import Parameter, SetParametersResult
from gait_nodes.runtime.args import parse_ros_args


@pytest.fixture
def start():
    """``start(*ros_args)`` initializes the inproc runtime; shut down after the test."""

    def start_runtime(*ros_args: str) -> None:
        args = ['test_program', '--ros-args', *ros_args] if ros_args else ['test_program']
        runtime.init(args=args, runtime='inproc', signal_handlers=False)

    yield start_runtime
    runtime.shutdown()


def write(tmp_path, text: str | bytes, name: str = 'params.yaml'):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(textwrap.dedent(text))
    return path


def test_declared_type_follows_the_default(start):
    start()
    node = runtime.Node('talker')
    defaults = {
        'enabled': (True, Parameter.Type.BOOL),
        'count': (3, Parameter.Type.INTEGER),
        'gain': (1.5, Parameter.Type.DOUBLE),
        'robot': ('biped', Parameter.Type.STRING),
        'flags': ([True, False], Parameter.Type.BOOL_ARRAY),
        'ids': ([1, 2, 3], Parameter.Type.INTEGER_ARRAY),
        'weights': ([0.5, 2.0], Parameter.Type.DOUBLE_ARRAY),
        'feet': (['lf', 'rh'], Parameter.Type.STRING_ARRAY),
    }
    for name, (value, expected_type) in defaults.items():
        parameter = node.declare_parameter(name, value)
        assert parameter.type_ == expected_type, name
        assert node.get_parameter(name).value == value
        assert node.describe_parameter(name).type == int(expected_type)
    # rclpy declares use_sim_time on every node.
    assert node.get_parameter('use_sim_time').value is False


def test_command_line_overrides_win_over_defaults(start):
    start('-p', 'gain:=2.5', '-p', 'robot:=quadruped', '-p', 'enabled:=false',
          '-p', 'ids:=[4, 5]', '-p', 'weights:=[1.0, 3.5]')
    node = runtime.Node('talker')
    assert node.declare_parameter('gain', 1.0).value == 2.5
    assert node.declare_parameter('robot', 'biped').value == 'quadruped'
    assert node.declare_parameter('enabled', True).value is False
    assert node.declare_parameter('ids', [1]).value == [4, 5]
    assert node.declare_parameter('weights', [0.0]).value == [1.0, 3.5]
    assert node.declare_parameter('untouched', 7).value == 7


def test_values_are_read_as_rcl_reads_them(start, tmp_path):
    path = write(tmp_path, """\
        talker:
          ros__parameters:
            release: 2024-05-23
            quoted: '42'
        """)
    start('--params-file', str(path), '-p', 'label:=2024-01-01', '-p', 'version:=1.0.0',
          '-p', 'text:="7"', '-p', 'empty:=')
    node = runtime.Node('talker')
    # rcl knows bool, int, double and string scalars: a date is a string, not an error.
    assert node.declare_parameter('label', 'x').value == '2024-01-01'
    assert node.declare_parameter('release', 'x').value == '2024-05-23'
    assert node.declare_parameter('version', 'x').value == '1.0.0'
    assert node.declare_parameter('text', 'x').value == '7'
    assert node.declare_parameter('quoted', 'x').value == '42'
    assert node.declare_parameter('empty', 'x').value == ''


def test_numbers_and_bools_are_typed_as_rcl_types_them(start, tmp_path):
    # rcl_yaml_param_parser: rcl's bool words, then C's strtol (base 0), then strtod, else a
    # string; YAML 1.1 would read 1e-8 as a string (its floats need a dot) and 1_000 as 1000.
    path = write(tmp_path, """\
        talker:
          ros__parameters:
            weight: 1e-8
            enabled: y
        """)
    start('--params-file', str(path), '-p', 'gain:=1.0e8', '-p', 'tiny:=-2E-3',
          '-p', 'mask:=0x1f', '-p', 'mode:=017', '-p', 'grouped:=1_000', '-p', 'clock:=1:30',
          '-p', 'limit:=.inf', '-p', 'verbose:=off', '-p', 'huge:=1e999')
    node = runtime.Node('talker')
    assert node.declare_parameter('weight', 1.0).value == 1e-8
    assert node.declare_parameter('enabled', False).value is True
    assert node.declare_parameter('gain', 1.0).value == 1e8
    assert node.declare_parameter('tiny', 1.0).value == -2e-3
    assert node.declare_parameter('mask', 0).value == 31
    assert node.declare_parameter('mode', 0).value == 15  # octal, as strtol reads 017
    assert node.declare_parameter('grouped', 'x').value == '1_000'
    assert node.declare_parameter('clock', 'x').value == '1:30'
    assert node.declare_parameter('limit', 1.0).value == math.inf
    assert node.declare_parameter('verbose', True).value is False
    assert node.declare_parameter('huge', 'x').value == '1e999'  # strtod's ERANGE: a string


def test_node_targeted_override_reaches_only_that_node(start):
    start('-p', 'talker:gain:=3.0', '-p', 'listener:gain:=9.0')
    talker = runtime.Node('talker')
    listener = runtime.Node('listener')
    other = runtime.Node('other')
    assert talker.declare_parameter('gain', 1.0).value == 3.0
    assert listener.declare_parameter('gain', 1.0).value == 9.0
    assert other.declare_parameter('gain', 1.0).value == 1.0
    executor = runtime.SingleThreadedExecutor()
    # Overrides aimed at other nodes are not this node's unknown parameters.
    for node in (talker, listener, other):
        executor.add_node(node)


def test_params_file_sections_wildcard_and_nested_names(start, tmp_path):
    path = write(tmp_path, """\
        /**:
          ros__parameters:
            robot: biped
            belongs_to_another_node: 3
        talker:
          ros__parameters:
            gain: 4.0
            limits:
              hip: 1.2
              knee:
                max_rad: 2.0
        listener:
          ros__parameters:
            gain: 8.0
        """)
    start('--params-file', str(path))
    node = runtime.Node('talker')
    assert node.declare_parameter('gain', 1.0).value == 4.0
    assert node.declare_parameter('robot', 'quadruped').value == 'biped'
    assert node.declare_parameter('limits.hip', 0.0).value == 1.2
    assert node.declare_parameter('limits.knee.max_rad', 0.0).value == 2.0
    assert set(node.get_parameters_by_prefix('limits')) == {'hip', 'knee.max_rad'}
    # An unknown key in the /** section is some other node's parameter: no complaint.
    runtime.SingleThreadedExecutor().add_node(node)
    other = runtime.Node('listener')
    assert other.declare_parameter('gain', 1.0).value == 8.0
    assert other.declare_parameter('robot', 'quadruped').value == 'biped'


def test_params_file_namespace_sections(start, tmp_path):
    path = write(tmp_path, """\
        /robot1:
          talker:
            ros__parameters:
              gain: 6.0
        /robot2/talker:
          ros__parameters:
            gain: 7.0
        """)
    start('--params-file', str(path))
    assert runtime.Node('talker', namespace='/robot1').declare_parameter('gain', 1.0).value == 6.0
    assert runtime.Node('talker', namespace='/robot2').declare_parameter('gain', 1.0).value == 7.0
    assert runtime.Node('talker').declare_parameter('gain', 1.0).value == 1.0


def test_command_line_value_after_params_file_wins(start, tmp_path):
    path = write(tmp_path, """\
        talker:
          ros__parameters:
            gain: 4.0
            robot: biped
        """)
    start('--params-file', str(path), '-p', 'gain:=5.0')
    node = runtime.Node('talker')
    assert node.declare_parameter('gain', 1.0).value == 5.0
    assert node.declare_parameter('robot', 'quadruped').value == 'biped'


def test_rejected_change_keeps_the_old_value_and_says_why(start):
    start()
    node = runtime.Node('talker')
    node.declare_parameter('gain', 1.0)
    seen = []

    def validate(parameters):
        seen.extend(p.name for p in parameters)
        for parameter in parameters:
            if parameter.name == 'gain' and parameter.value < 0.0:
                return SetParametersResult(successful=False,
                                           reason=f'gain must be >= 0, got {parameter.value}')
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(validate)
    [result] = node.set_parameters([Parameter('gain', value=-2.0)])
    assert not result.successful
    assert result.reason == 'gain must be >= 0, got -2.0'
    assert node.get_parameter('gain').value == 1.0
    [result] = node.set_parameters([Parameter('gain', value=2.0)])
    assert result.successful
    assert node.get_parameter('gain').value == 2.0
    assert seen == ['gain', 'gain']
    # Atomic sets are all-or-nothing.
    node.declare_parameter('offset', 0.5)
    result = node.set_parameters_atomically(
        [Parameter('offset', value=0.7), Parameter('gain', value=-1.0)])
    assert not result.successful
    assert node.get_parameter('offset').value == 0.5
    assert node.get_parameter('gain').value == 2.0


def test_callback_rejection_at_declaration_raises(start):
    start('-p', 'gain:=-1.0')
    node = runtime.Node('talker')
    node.add_on_set_parameters_callback(
        lambda params: SetParametersResult(all(p.value >= 0 for p in params), 'must be >= 0'))
    with pytest.raises(ParameterError, match='must be >= 0'):
        node.declare_parameter('gain', 1.0)


def test_wrong_type_on_set_is_refused(start):
    start()
    node = runtime.Node('talker')
    node.declare_parameter('gain', 1.0)
    [result] = node.set_parameters([Parameter('gain', value='fast')])
    assert not result.successful
    assert result.reason.startswith('Wrong parameter type')
    # The reason names the types, as rclpy's does.
    assert 'DOUBLE' in result.reason and 'STRING' in result.reason
    assert node.get_parameter('gain').value == 1.0


def test_wrong_type_override_raises_at_declaration(start):
    start('-p', 'gain:=abc')
    node = runtime.Node('talker')
    with pytest.raises(InvalidParameterTypeError, match='gain'):
        node.declare_parameter('gain', 1.0)


def test_unknown_command_line_override_is_refused_by_add_node(start):
    start('-p', 'nope:=1')
    node = runtime.Node('talker')
    node.declare_parameter('gain', 1.0)
    with pytest.raises(ParameterNotDeclaredError, match='nope'):
        runtime.SingleThreadedExecutor().add_node(node)


def test_unknown_key_in_named_section_is_refused_by_add_node(start, tmp_path):
    path = write(tmp_path, """\
        talker:
          ros__parameters:
            gian: 2.0
        """)
    start('--params-file', str(path))
    node = runtime.Node('talker')
    node.declare_parameter('gain', 1.0)
    with pytest.raises(ParameterNotDeclaredError, match='gian'):
        runtime.SingleThreadedExecutor().add_node(node)


@pytest.mark.parametrize('text', [
    'talker: {ros__parameters: {gain: [1.0, 2.0}}\n',  # bad YAML
    '- gain\n- 1.0\n',  # not a mapping
    '',  # empty
    'talker:\n  gain: 1.0\n',  # no ros__parameters
    'talker:\n  ros__parameters: [gain, 1.0]\n',  # ros__parameters not a mapping
    'talker:\n  ros__parameters:\n    ids: [1, two, 3]\n',  # mixed-type list
    'talker:\n  ros__parameters:\n    ids: [1, 2.5]\n',  # int and float mixed, as rcl refuses
    'talker:\n  ros__parameters:\n    gain:\n',  # no value
    b'\xff\xfetalker: {}',  # not UTF-8
], ids=['bad-yaml', 'not-mapping', 'empty', 'no-ros-parameters', 'parameters-not-mapping',
        'mixed-list', 'int-float-list', 'no-value', 'not-utf8'])
def test_malformed_params_file_names_the_path(start, tmp_path, text):
    path = write(tmp_path, text, 'broken_params.yaml')
    with pytest.raises(ParameterError, match='broken_params.yaml'):
        start('--params-file', str(path))
    with pytest.raises(ParameterError, match='broken_params.yaml'):
        parse_ros_args(['--params-file', str(path)])


def test_missing_params_file_names_the_path(tmp_path):
    missing = tmp_path / 'missing_params.yaml'
    with pytest.raises(ParameterError, match='missing_params.yaml'):
        parse_ros_args(['--params-file', str(missing)])


def test_bad_command_line_value_is_reported_on_one_line():
    with pytest.raises(ArgumentError) as caught:
        parse_ros_args(['-p', 'gain:=[1.0, 2.0'])
    assert '\n' not in str(caught.value)
    assert 'gain' in str(caught.value)


@pytest.mark.parametrize('args', [
    ['--bogus'],
    ['-p'],
    ['-p', 'gain=1.0'],
    ['-p', ':=1.0'],
    ['-r', 'chatter'],
    ['--log-level', 'loud'],
    ['--params-file'],
])
def test_parse_ros_args_rejects_malformed_arguments(args):
    with pytest.raises(ArgumentError):
        parse_ros_args(args)


def test_init_rejects_unknown_ros_flag(start):
    with pytest.raises(ArgumentError, match='--bogus'):
        start('--bogus')
    assert not runtime.ok()


def test_parse_ros_args_accepts_rcl_flags():
    parsed = parse_ros_args(['-p', 'a:=1', '--param', 'n:b:=x', '-r', 'x:=y',
                             '--log-level', 'WARN', '--enclave', '/e', '--disable-rosout-logs'])
    assert parsed.params == [(None, 'a', 1), ('n', 'b', 'x')]
    assert parsed.remaps == [(None, 'x', 'y')]
    assert parsed.log_level == 'warn'


@pytest.mark.parametrize('rule', ['__node:=', '__node:=2talker', '__node:=my-node',
                                  '__name:=a/b', '__ns:=', '__ns:=/a//b', '__ns:=/a/',
                                  'chatter:=', 'chatter:=/a//b', 'chatter:=a b',
                                  'chatter:=/1x'])
def test_remap_to_a_name_rcl_would_refuse_is_refused(rule):
    with pytest.raises(ArgumentError, match='is not a'):
        parse_ros_args(['-r', rule])


@pytest.mark.parametrize('rule', ['__node:=talker_2', '__name:=_t', '__ns:=/', '__ns:=/a/b',
                                  '__ns:=a', 'chatter:=other', 'chatter:=/a/b_1',
                                  'chatter:=~/private', 'n:chatter:=x'])
def test_remap_to_a_valid_name_is_taken(rule):
    assert parse_ros_args(['-r', rule]).remaps


def _spin_with_talker(publisher, nodes, seconds=2.0):
    """Spin ``nodes`` while a 1 Hz timer publishes 'hello' on ``publisher``."""
    executor = runtime.SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    nodes[0].create_timer(1.0, lambda: publisher.publish(std_msgs.msg.String(data='hello')))
    executor.spin_for(seconds)


@pytest.mark.parametrize('rule', ['chatter:=other', '/chatter:=/other'])
def test_remap_changes_the_published_topic(start, rule):
    start('-r', rule)
    talker = runtime.Node('talker')
    publisher = talker.create_publisher(std_msgs.msg.String, 'chatter', 10)
    assert publisher.topic_name == '/other'
    listener = runtime.Node('listener')
    received = []
    listener.create_subscription(std_msgs.msg.String, '/other',
                                 lambda msg: received.append(msg.data), 10)
    _spin_with_talker(publisher, [talker, listener])
    assert received == ['hello', 'hello']


def test_node_targeted_remap_changes_only_that_node(start):
    start('-r', 'talker:chatter:=other')
    talker = runtime.Node('talker')
    publisher = talker.create_publisher(std_msgs.msg.String, 'chatter', 10)
    assert publisher.topic_name == '/other'
    received = {'/other': [], '/chatter': []}
    listener = runtime.Node('listener')
    for topic, messages in received.items():
        listener.create_subscription(std_msgs.msg.String, topic,
                                     lambda msg, messages=messages: messages.append(msg.data), 10)
    assert [s.topic_name for s in listener.subscriptions] == ['/other', '/chatter']
    _spin_with_talker(publisher, [talker, listener])
    assert received == {'/other': ['hello', 'hello'], '/chatter': []}


def test_remap_applies_to_relative_and_absolute_names_alike(start):
    start('-r', 'chatter:=other')
    talker = runtime.Node('talker')
    relative = talker.create_publisher(std_msgs.msg.String, 'chatter', 10)
    absolute = talker.create_publisher(std_msgs.msg.String, '/chatter', 10)
    assert relative.topic_name == absolute.topic_name == '/other'
    listener = runtime.Node('listener')
    received = []
    listener.create_subscription(std_msgs.msg.String, '/other',
                                 lambda msg: received.append(msg.data), 10)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(talker)
    executor.add_node(listener)
    relative.publish(std_msgs.msg.String(data='one'))
    absolute.publish(std_msgs.msg.String(data='two'))
    executor.spin_once()
    assert received == ['one', 'two']


def test_remap_in_namespace_resolves_under_it(start):
    start('-r', 'chatter:=other')
    node = runtime.Node('talker', namespace='/robot1')
    publisher = node.create_publisher(std_msgs.msg.String, 'chatter', 10)
    assert publisher.topic_name == '/robot1/other'
