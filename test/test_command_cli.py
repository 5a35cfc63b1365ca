"""python -m gait_nodes.command.

Value parsing, bad command lines, and the round trip to footstep_planner in the inproc runtime
and over DDS (loopback, a random domain).
"""

import json
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from planning_helpers import BIPED, QUADRUPED

from gait_nodes import runtime
from gait_nodes.command import GaitCommandClient, main, parse_assignments
from gait_nodes.errors import ArgumentError

REPO = Path(__file__).resolve().parent.parent


def test_values_parse_as_json_where_possible():
    assert parse_assignments(['step_length_m=0.3', 'gait=trot', 'duty_factor=1',
                              'swing="value_table"', 'x=true', 'y=']) == {
        'step_length_m': 0.3, 'gait': 'trot', 'duty_factor': 1, 'swing': 'value_table',
        'x': True, 'y': ''}
    for bad in (['gait'], ['=3'], ['a=1', 'a=2']):
        with pytest.raises(ArgumentError):
            parse_assignments(bad)


@pytest.mark.parametrize('args', [[], ['gait'], ['--vel', 'nan', '0', '0'],
                                  ['--vel', '0.1', '0'], ['gait=trot', '--timeout', '-1']])
def test_bad_command_lines_exit_2(args, capsys):
    with pytest.raises(SystemExit) as exit_info:
        sys.exit(main(['--runtime', 'inproc', *args]))
    assert exit_info.value.code == 2
    assert 'error' in capsys.readouterr().err


def test_no_answer_within_the_timeout_exits_2(capsys):
    assert main(['--runtime', 'inproc', 'gait=trot', '--timeout', '1']) == 2
    assert 'no answer' in capsys.readouterr().err


def round_trip(robot_path, command, velocity, **params):
    args = ['test', '--ros-args', '-p', f'robot:={robot_path}']
    for name, value in params.items():
        args += ['-p', f'{name}:={value}']
    runtime.init(args=args, runtime='inproc', signal_handlers=False)
    try:
        from gait_nodes.footstep_planner import FootstepPlanner

        planner = FootstepPlanner()
        client = GaitCommandClient(command, velocity)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(planner)
        executor.add_node(client)
        assert client.run(executor, 5.0)
        return client.result(), planner
    finally:
        runtime.shutdown()


def test_round_trip_inproc_accepted():
    result, planner = round_trip(QUADRUPED, {'gait': 'trot', 'duty_factor': 0.6},
                                 (0.05, 0.0, 0.02))
    assert result['accepted'] is True
    assert result['params']['gait'] == 'trot' and result['params']['duty_factor'] == 0.6
    assert result['velocity']['requested'] == [0.05, 0.0, 0.02]
    assert planner.planner.params.gait == 'trot'


def test_round_trip_inproc_rejected():
    result, planner = round_trip(BIPED, {'gait': 'trot'}, None, duty_factor=0.9)
    assert result['accepted'] is False and 'not possible' in result['reason']
    assert planner.planner.params.gait == 'auto'


def test_round_trip_over_dds(tmp_path):
    env = dict(os.environ)
    env.pop('CYCLONEDDS_URI', None)
    env.update(PYTHONPATH=str(REPO), GAIT_NODES_RUNTIME='dds', GAIT_NODES_DDS_LOCALHOST='1',
               ROS_DOMAIN_ID=str(random.SystemRandom().randrange(100, 200)),
               PYTHONUNBUFFERED='1')
    planner = subprocess.Popen(
        [sys.executable, '-m', 'gait_nodes.footstep_planner', '--ros-args', '-p',
         f'robot:={QUADRUPED}'], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True)
    try:
        def command(*args):
            return subprocess.run([sys.executable, '-m', 'gait_nodes.command', *args,
                                   '--timeout', '20'], env=env, cwd=tmp_path,
                                  capture_output=True, text=True, timeout=60)

        accepted = command('gait=trot', 'duty_factor=0.6', '--vel', '0.05', '0', '0')
        assert accepted.returncode == 0, accepted.stderr
        answer = json.loads(accepted.stdout)
        assert answer['accepted'] and answer['params']['gait'] == 'trot'
        assert answer['velocity']['applied'] == [0.05, 0.0, 0.0]
        rejected = command('duty_factor=0.4')
        assert rejected.returncode == 1, rejected.stderr
        assert json.loads(rejected.stdout)['accepted'] is False
    finally:
        planner.terminate()
        planner.communicate(timeout=20)
