"""A parameter a node does not declare is refused before the node's start-up work (issue 25).

``gait_nodes.node_parameters`` knows each node's parameters without building it; these tests
check that against what every node declares, and that nodes, the recorder and ``run`` refuse
an unknown name at once: one line naming the params file, the name and the accepted names.
"""

import importlib
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from gait_nodes import graph, runtime
from gait_nodes.errors import ParameterNotDeclaredError
from gait_nodes.node_parameters import RECORDER, parameter_names

REPO = Path(__file__).resolve().parent.parent


def write(folder: Path, text: str, name: str = 'params.yaml') -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


def start(*ros_args: str) -> None:
    runtime.init(args=['test', '--ros-args', *ros_args], runtime='inproc',
                 signal_handlers=False)


@pytest.fixture
def cheap_graph(tmp_path):
    """The biped with polynomial swings: every node builds in well under a second."""
    start('--params-file', str(write(tmp_path, """\
        /**:
          ros__parameters:
            robot: biped
        swing_leg_policy:
          ros__parameters:
            swing: polynomial
        """)))
    yield
    runtime.shutdown()


def test_the_names_known_before_start_are_those_each_node_declares(cheap_graph, tmp_path):
    from gait_nodes.recorder import Recorder

    for name, path in graph.NODES.items():
        node = graph.load_class(path)()
        assert set(node._parameters.parameters) == parameter_names(name), name
    recorder = Recorder(output=str(tmp_path / 'bag'))
    assert set(recorder._parameters.parameters) == parameter_names(RECORDER)
    assert parameter_names('not_a_graph_node') is None


@pytest.mark.parametrize('name', list(graph.NODES))
def test_a_node_refuses_an_unknown_parameter_before_its_start_up(tmp_path, monkeypatch, name):
    module = importlib.import_module(graph.NODES[name].partition(':')[0])
    started = []
    for loader in ('load_robot_description', 'load_robot_model'):
        if hasattr(module, loader):  # the first of the start-up work: the robot
            monkeypatch.setattr(module, loader, lambda *args, **kw: started.append(args))
    params = write(tmp_path, f"""\
        {name}:
          ros__parameters:
            robot: biped
            no_such: 1
        """)
    start('--params-file', str(params))
    try:
        with pytest.raises(ParameterNotDeclaredError) as refused:
            graph.load_class(graph.NODES[name])()
    finally:
        runtime.shutdown()
    assert started == []
    message = str(refused.value)
    assert f"'no_such' (params file {params})" in message
    assert f'/{name} accepts: ' in message and 'robot' in message and '\n' not in message


def run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    env.pop('GAIT_NODES_RUNTIME', None)
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=120)


def assert_refused(result: subprocess.CompletedProcess, *words: str) -> None:
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert result.stdout == '' and 'Traceback' not in result.stderr
    [line] = result.stderr.splitlines()  # no node logged its start
    assert 'error' in line
    for word in words:
        assert word in line, line


def test_node_entry_point_refuses_an_unknown_parameter_of_a_params_file(tmp_path):
    params = write(tmp_path, 'whole_body_ik: {ros__parameters: {no_such: 1}}\n')
    result = run(['-m', 'gait_nodes.whole_body_ik', '--runtime', 'inproc', '--ros-args',
                  '--params-file', str(params)], tmp_path)
    assert_refused(result, str(params), 'no_such', 'position_tolerance_m', 'use_sim_time')


def test_recorder_refuses_an_unknown_parameter_before_making_its_bag(tmp_path):
    params = write(tmp_path, 'recorder: {ros__parameters: {flush_period: 0.2}}\n')
    result = run(['-m', 'gait_nodes.recorder', '--runtime', 'inproc', '-o', 'bag',
                  '--ros-args', '--params-file', str(params)], tmp_path)
    assert_refused(result, str(params), 'flush_period', 'flush_period_s', 'output')
    assert not (tmp_path / 'bag').exists()


@pytest.mark.parametrize('runtime_name', ['dds', 'inproc'])
def test_run_refuses_an_unknown_parameter_before_starting_any_node(tmp_path, runtime_name):
    params = write(tmp_path, 'whole_body_ik: {ros__parameters: {no_such: 1}}\n')
    result = run(['-m', 'gait_nodes', 'run', '--runtime', runtime_name, '--record', 'bag',
                  '--ros-args', '--params-file', str(params)], tmp_path)
    assert_refused(result, str(params), '/whole_body_ik', 'no_such', 'position_tolerance_m')
    assert not (tmp_path / 'bag').exists()


def test_run_names_a_command_line_override_it_refuses(tmp_path):
    result = run(['-m', 'gait_nodes', 'run', '--fast', '--ros-args', '-p',
                  'footstep_planner:step_lenght_m:=0.2'], tmp_path)
    assert_refused(result, '/footstep_planner', "'step_lenght_m' (-p step_lenght_m:=...)",
                   'step_length_m', 'stairs_count')


def test_run_accepts_every_parameter_of_the_shipped_params_files(tmp_path):
    """The shipped config files address each node by name: every key in them is accepted."""
    from gait_nodes.node_parameters import check_overrides
    from gait_nodes.paths import config_file
    from gait_nodes.runtime.args import parse_ros_args

    for name in graph.NODES:
        ros_args = parse_ros_args(['--params-file', str(config_file(f'{name}.yaml'))])
        check_overrides(name, ros_args)
