"""Two graphs on one ROS_DOMAIN_ID over DDS: refused when they would mix, apart in namespaces.

(a) No namespace: two whole_body_ik processes publish /joint_commands to one kinematic_simulator
    (what two graphs started on one domain do). The simulator says ERROR on /diagnostics naming
    the topic and the count, and holds the robot; with one IK left it says OK again, and a
    third publisher's commands are refused, the robot staying where it is.
(b) Namespaces /r1 and /r2: two whole ``run`` graphs on one domain at once each walk their own
    walk: no input refused, each bag holds its own namespace's topics, and each walked as far
    as one graph alone does.

Each test uses its own ROS_DOMAIN_ID and the loopback-only configuration, as test_runtime_dds.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from gait_nodes import graph, runtime
from gait_nodes.bag.analysis import inspect_bag
from gait_nodes.diagnostics import ERROR, OK, level_value
from gait_nodes.interfaces import get_message

REPO = Path(__file__).resolve().parent.parent
DOMAINS = iter(random.SystemRandom().sample(range(60, 100), 4))
START_TIMEOUT_S = 90.0


def _env(domain: int, tmp_path: Path, name: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop('CYCLONEDDS_URI', None)
    env.update(PYTHONPATH=str(REPO), GAIT_NODES_RUNTIME='dds', ROS_DOMAIN_ID=str(domain),
               GAIT_NODES_DDS_LOCALHOST='1', PYTHONUNBUFFERED='1',
               GAIT_NODES_READY_FILE=str(tmp_path / f'{name}.ready'))
    return env


class Observer:
    """This process on the domain: keeps /diagnostics and /joint_states as they come."""

    def __init__(self, domain: int, monkeypatch):
        monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
        monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
        runtime.init(args=[], runtime='dds', domain_id=domain, signal_handlers=False)
        self.node = runtime.Node('mix_observer')
        self.statuses: list[tuple[float, str, int, str, dict]] = []
        self.positions: list[tuple[float, np.ndarray]] = []
        self.joint_names: list[str] = []
        self.node.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                      '/diagnostics', self._on_diagnostics, 100)
        self.node.create_subscription(get_message('sensor_msgs/msg/JointState'),
                                      '/joint_states', self._on_joint_states, 100)
        self.executor = runtime.SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def _on_diagnostics(self, msg) -> None:
        for status in msg.status:
            self.statuses.append((time.monotonic(), status.name, level_value(status.level),
                                  status.message, {v.key: v.value for v in status.values}))

    def _on_joint_states(self, msg) -> None:
        self.positions.append((time.monotonic(), np.array(msg.position, dtype=float)))
        self.joint_names = list(msg.name)

    def spin(self, seconds: float) -> None:
        """Run the observer for ``seconds``."""
        self.executor.spin_for(seconds)

    def wait_for(self, predicate, timeout_s: float, what: str):
        """Spin until ``predicate()`` is truthy; return it (fail after ``timeout_s``)."""
        deadline = time.monotonic() + timeout_s
        while not (found := predicate()):
            if time.monotonic() > deadline:
                pytest.fail(f'no {what} in {timeout_s} s; last statuses: '
                            f'{[s[1:4] for s in self.statuses[-8:]]}')
            self.spin(0.1)
        return found

    def inputs(self, since: float, level: int) -> list:
        """The simulator's input statuses at ``level`` heard since ``since``."""
        return [s for s in self.statuses if s[0] >= since and s[2] == level
                and s[1] == 'kinematic_simulator: inputs']

    def motion_since(self, since: float) -> float:
        """Largest joint position change among the joint states heard since ``since`` [rad]."""
        held = [q for t, q in self.positions if t >= since]
        assert len(held) > 10, 'no joint states'
        return float(np.abs(np.array(held) - held[0]).max())


@pytest.fixture
def processes():
    started: list[subprocess.Popen] = []
    yield started
    for process in started:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
    for process in started:
        try:
            process.wait(15)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def test_two_iks_on_one_simulator_are_refused_until_one_is_left(tmp_path, monkeypatch,
                                                                 processes):
    domain = next(DOMAINS)
    params = tmp_path / 'params.yaml'
    params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {'robot': 'biped'}}}))
    names = ('kinematic_simulator', 'whole_body_ik', 'whole_body_ik_2')
    for name in names:
        module = name.removesuffix('_2')
        log = open(tmp_path / f'{name}.log', 'w')  # noqa: SIM115 (closed with the process)
        processes.append(subprocess.Popen(
            [sys.executable, '-m', f'gait_nodes.{module}', '--ros-args', '--params-file',
             str(params)], env=_env(domain, tmp_path, name), stdout=log,
            stderr=subprocess.STDOUT, start_new_session=True))
    observer = Observer(domain, monkeypatch)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not all((tmp_path / f'{name}.ready').exists() for name in names):
            assert all(p.poll() is None for p in processes), [
                (tmp_path / f'{name}.log').read_text()[-2000:] for name in names]
            assert time.monotonic() < deadline, 'the nodes did not start'
            observer.spin(0.2)
        up = time.monotonic()

        # Two IKs, one simulator: an ERROR naming the topic and the count; the robot held.
        time_, _, _, message, values = observer.wait_for(
            lambda: next(iter(observer.inputs(up, ERROR)), None), 15.0,
            'ERROR from the simulator')
        assert '2 publishers on /joint_commands' in message, message
        assert 'holding the robot' in message
        assert values['refused'] == '/joint_commands'
        assert values['/joint_commands publishers'] == '2'
        observer.spin(2.0)
        assert observer.motion_since(time_ + 0.5) < 1e-9

        # One IK stops: the simulator takes its commands again and says OK.
        processes[2].send_signal(signal.SIGINT)
        assert processes[2].wait(15) == 0
        stopped = time.monotonic()
        observer.wait_for(lambda: observer.inputs(stopped, OK), 10.0, 'OK from the simulator')

        # A second source that commands another posture: refused, the robot does not follow.
        rogue = observer.node.create_publisher(
            get_message('trajectory_msgs/msg/JointTrajectory'), '/joint_commands', 10)
        refused_at = time.monotonic()
        observer.wait_for(lambda: observer.inputs(refused_at, ERROR), 10.0, 'a second ERROR')
        held = observer.positions[-1][1]
        command = get_message('trajectory_msgs/msg/JointTrajectory')()
        command.joint_names = observer.joint_names
        point = get_message('trajectory_msgs/msg/JointTrajectoryPoint')()
        point.positions = (held + 0.3).tolist()
        command.points = [point]
        sent = time.monotonic()
        for _ in range(20):
            rogue.publish(command)
            observer.spin(0.1)
        assert observer.motion_since(sent) < 1e-6, 'the robot followed a refused command'
    finally:
        runtime.shutdown()


def test_two_graphs_in_two_namespaces_on_one_domain_each_walk_their_own_walk(tmp_path):
    domain = next(DOMAINS)
    runs = {}
    for namespace in ('/r1', '/r2'):
        env = _env(domain, tmp_path, 'unused')
        env.pop('GAIT_NODES_READY_FILE')
        bag = tmp_path / f'bag{namespace[1:]}'
        runs[namespace] = (bag, subprocess.Popen(
            [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'dds', '--scenario',
             'biped_walk', '--duration', '12', '--namespace', namespace, '--record', str(bag),
             '--no-plot', '--json'], env=env, cwd=tmp_path, stdout=subprocess.PIPE,
            stderr=subprocess.PIPE, text=True))
    summaries = {}
    for namespace, (_, process) in runs.items():
        out, err = process.communicate(timeout=400)
        assert process.returncode == 0, err[-3000:]
        summaries[namespace] = json.loads(out)
    for namespace, summary in summaries.items():
        assert summary['namespace'] == namespace
        report = summary['inspect']
        bag_topics = set(report['topics'])  # contract names, read under the namespace
        assert '/gait/footsteps' in bag_topics and '/tf' in bag_topics
        inspection = inspect_bag(summary['bag'])
        recorded = {row['topic'] for row in inspection.report['topics']}
        assert recorded == {namespace + t for t in graph.TOPICS if t != '/clock'} | {'/clock'}
        assert inspection.report['namespace'] == namespace
        gait = report['gait']
        # Nothing refused, nothing mixed: no input ERROR in either graph.
        by_name = gait['diagnostics']['by_name']
        refused = {name: counts for name, counts in by_name.items()
                   if name.endswith(': inputs') and counts.get('ERROR')}
        assert not refused, refused
        assert gait['diagnostics']['by_level'].get('ERROR', 0) <= 3, \
            gait['diagnostics']['first_error']
        # Its own walk: the biped walks 0.9 m in 12 s alone (inproc); two mixed graphs made
        # every bag claim the sum of both robots' motion.
        assert 0.3 < gait['base']['displacement_m'] < 1.5, gait['base']
    print({ns: s['inspect']['gait']['base'] for ns, s in summaries.items()})
