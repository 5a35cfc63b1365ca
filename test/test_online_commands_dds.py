"""Gait commands over DDS while the robot walks, with a busy process on the cores (issue 25).

The whole graph runs as a user runs it (``python -m gait_nodes run --runtime dds --scenario
biped_commands --record BAG``, one process per node) beside a busy loop. While it walks, from
outside: the command CLI sends a command and waits for its decision (no re-sending), a command
of over 500 characters is answered and the CLI knows it, and a flood of 300 commands arrives in
one burst (planned together as they wait, each answered). Judged from the bag: the full model's
ZMP never leaves the support polygon, no joint command exceeds its limit, every command (the
scenario's, the CLI's, the flood) got exactly one decision and no more than one 'applied'
answer, and the planner never stopped at a safe stand.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gait_nodes import runtime
from gait_nodes.bag.analysis import inspect_bag
from gait_nodes.interfaces import get_message
from gait_nodes.scenarios import get_scenario

REPO = Path(__file__).resolve().parent.parent
DOMAIN = random.SystemRandom().randrange(100, 140)
FLOOD = 300


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop('CYCLONEDDS_URI', None)
    env.update(PYTHONPATH=str(REPO), GAIT_NODES_RUNTIME='dds', ROS_DOMAIN_ID=str(DOMAIN),
               GAIT_NODES_DDS_LOCALHOST='1', PYTHONUNBUFFERED='1')
    return env


def _command(*arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'gait_nodes.command', *arguments,
                           '--timeout', '20'], env=_env(), capture_output=True, text=True,
                          timeout=60, check=False)


def test_commands_over_dds_under_load_are_safe_answered_and_applied_once(tmp_path, monkeypatch):
    bag = tmp_path / 'bag'
    busy = subprocess.Popen([sys.executable, '-c', 'while True: pass'])
    run = subprocess.Popen(
        [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'dds', '--scenario',
         'biped_commands', '--duration', '40', '--record', str(bag), '--no-plot', '--json'],
        env=_env(), cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    runtime.init(args=[], runtime='dds', domain_id=DOMAIN, signal_handlers=False)
    try:
        node = runtime.Node('command_flood')
        string = get_message('std_msgs/msg/String')
        footsteps = []
        node.create_subscription(get_message('trajectory_msgs/msg/MultiDOFJointTrajectory'),
                                 '/gait/footsteps', footsteps.append, 10)
        publisher = node.create_publisher(string, '/gait/command', 1000)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        deadline = time.monotonic() + 120.0
        while len(footsteps) < 3:  # walking
            assert run.poll() is None, run.communicate()[1][-3000:]
            assert time.monotonic() < deadline, 'the graph did not start walking'
            executor.spin_for(0.2)

        done = _command('step_height_m=0.09')
        assert done.returncode == 0, done.stderr
        decision = json.loads(done.stdout)
        assert decision['state'] == 'accepted' and decision['takes_effect_in_s'] > 0

        long_key = 'x' * 600
        done = _command(f'{long_key}=1')
        assert done.returncode == 1, done.stderr  # answered (rejected), not "no answer"
        assert json.loads(done.stdout)['state'] == 'rejected'

        while publisher.get_subscription_count() < 2:  # the planner and the recorder
            executor.spin_for(0.1)
        for k in range(FLOOD):
            publisher.publish(string(data=json.dumps(
                {'id': f'flood-{k}', 'step_length_m': round(0.2 + 0.0001 * k, 4)})))
        executor.spin_for(0.5)
    finally:
        runtime.shutdown()
    out, err = run.communicate(timeout=300)
    busy.kill()
    busy.wait()
    assert run.returncode == 0, err[-3000:]

    report = inspect_bag(bag).report['gait']
    assert report['zmp_margin']['samples'] > 3000
    assert report['zmp_margin']['samples_outside'] == 0, report['zmp_margin']
    joints = report['joint_velocity']['/joint_commands']
    assert joints['samples_over_limit'] == 0 and joints['peak_ratio_to_limit'] <= 1.0 + 1e-9
    commands = report['commands']
    sent = sum(1 for c in get_scenario('biped_commands').commands
               if c.command is not None and c.at_s < 40.0)
    assert commands['answered'] == sent + 2 + FLOOD, commands
    assert commands['most_decisions'] == 1 and commands['most_applied'] == 1
    assert commands['accepted'] + commands['rejected'] == commands['answered']
    assert commands['accepted'] >= 1 and commands['applied'] >= 1
    errors = report['diagnostics']['by_name']
    assert not any('faults' in name and 'ERROR' in levels for name, levels in errors.items()), \
        errors
    if report['diagnostics']['first_error'] is not None:
        pytest.fail(f'an ERROR: {report["diagnostics"]["first_error"]}')
