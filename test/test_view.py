"""The live view (python -m gait_nodes.view) seen by a Foxglove WebSocket client.

A view process serves a dds graph (this test process publishes on it); a client speaking the
Foxglove WebSocket protocol checks the advertised channels, subscribes and decodes the
message-data frames, with the advertised schema text (mcap_ros2, as Foxglove decodes ros2msg)
and with our CDR code. Every process uses this module's own ROS_DOMAIN_ID over loopback.
"""

from __future__ import annotations

import json
import queue
import random
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

import pytest
from test_runtime_dds import dds_env

from gait_nodes import runtime
from gait_nodes.interfaces import definition_text, geometry_msgs, sensor_msgs, std_msgs
from gait_nodes.runtime import qos_profile_latched
from gait_nodes.view import view_topics

DOMAIN = random.SystemRandom().randrange(200, 233)
#: The subprotocol names of the Foxglove WebSocket protocol: foxglove-sdk servers answer to
#: the second, servers of the older ws-protocol libraries to the first.
SUBPROTOCOLS = ['foxglove.websocket.v1', 'foxglove.sdk.v1']
#: Opcode of a server's message-data frame (binary): subscription id, log time, payload.
MESSAGE_DATA = 0x01
FRAME_HEADER = struct.Struct('<BIQ')
TIMEOUT_S = 10.0

websockets_client = pytest.importorskip('websockets.sync.client')


@pytest.fixture
def graph(monkeypatch):
    """A node of the dds runtime in this process, on this module's domain."""
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    runtime.init(args=[], runtime='dds', domain_id=DOMAIN, signal_handlers=False)
    yield runtime.Node('view_test_talker')
    runtime.shutdown()


class ViewProcess:
    """``python -m gait_nodes.view --port 0 ...`` and the URL it logs once it serves."""

    def __init__(self, *args: str):
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'gait_nodes.view', '--port', '0', *args],
            env=dds_env(DOMAIN), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.lines: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()
        self.output: list[str] = []
        self.url = self._wait_for('ws://').split(' at ')[1].split()[0]

    def _read(self) -> None:
        for line in self.process.stdout:
            self.lines.put(line)
        self.lines.put(None)

    def _wait_for(self, text: str) -> str:
        deadline = time.monotonic() + TIMEOUT_S
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                continue
            if line is None:
                break
            self.output.append(line)
            if text in line:
                return line
        pytest.fail(f'the view did not log {text!r}:\n{"".join(self.output)}')

    def stop(self, signum: int) -> int:
        """Send ``signum``; the exit status (the process is killed after TIMEOUT_S)."""
        self.process.send_signal(signum)
        try:
            return self.process.wait(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            pytest.fail(f'the view ignored signal {signum}')

    def kill(self) -> None:
        """Kill the process if it still runs."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


@pytest.fixture
def start_view():
    views = []

    def start(*args: str) -> ViewProcess:
        views.append(ViewProcess(*args))
        return views[-1]

    yield start
    for view in views:
        view.kill()


class Publishing:
    """Publishes each ``(publisher, message)`` every 50 ms on a thread until closed."""

    def __init__(self, pairs):
        self.pairs = pairs
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        while not self.stopped.wait(0.05):
            for publisher, message in self.pairs:
                publisher.publish(message)

    def close(self) -> None:
        """Stop publishing (safe twice)."""
        self.stopped.set()
        self.thread.join()


def connect(url: str):
    return websockets_client.connect(url, subprotocols=SUBPROTOCOLS, open_timeout=TIMEOUT_S)


def advertised(ws, wanted, channels=None) -> dict[str, dict]:
    """Read the server's JSON messages until every topic of ``wanted`` is advertised.

    Returns:
        ``{topic: channel}`` of every channel advertised (and not withdrawn) meanwhile.
    """
    channels = {} if channels is None else channels
    deadline = time.monotonic() + TIMEOUT_S
    while not set(wanted) <= set(channels):
        assert time.monotonic() < deadline, f'advertised {sorted(channels)}, not {wanted}'
        message = ws.recv(timeout=TIMEOUT_S)
        if isinstance(message, bytes):
            continue
        message = json.loads(message)
        if message['op'] == 'advertise':
            channels.update((channel['topic'], channel) for channel in message['channels'])
        elif message['op'] == 'unadvertise':
            gone = set(message['channelIds'])
            channels = {t: c for t, c in channels.items() if c['id'] not in gone}
    return channels


def received(ws, subscriptions: dict[int, str], count: int) -> dict[str, list]:
    """``count`` message-data frames of each subscription: ``{topic: [(log time, payload)]}``."""
    frames = {topic: [] for topic in subscriptions.values()}
    deadline = time.monotonic() + TIMEOUT_S
    while min(map(len, frames.values())) < count:
        assert time.monotonic() < deadline, {t: len(f) for t, f in frames.items()}
        message = ws.recv(timeout=TIMEOUT_S)
        if isinstance(message, str):
            continue
        opcode, subscription, log_time_ns = FRAME_HEADER.unpack_from(message)
        assert opcode == MESSAGE_DATA
        frames[subscriptions[subscription]].append(
            (log_time_ns, message[FRAME_HEADER.size:]))
    return frames


def decode_with_schema(channel: dict, payload: bytes):
    """The payload decoded with the channel's advertised schema text, as Foxglove does."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    schema = Schema(id=1, name=channel['schemaName'], encoding=channel['schemaEncoding'],
                    data=channel['schema'].encode())
    return DecoderFactory().decoder_for(channel['encoding'], schema)(payload)


def assert_wire_bytes(payload: bytes, msg) -> None:
    """``payload`` is ``msg`` as ROS 2 sends it: XCDR1 little endian, 4-byte aligned."""
    expected = msg.serialize()
    assert payload[:2] == b'\x00\x01'
    assert payload[4:len(expected)] == expected[4:]
    assert set(payload[len(expected):]) <= {0} and len(payload) % 4 == 0
    assert type(msg).deserialize(payload) == msg


def twist():
    msg = geometry_msgs.msg.Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = 0.25, -0.125, 0.5
    return msg


def joint_state(node):
    msg = sensor_msgs.msg.JointState(name=['hip', 'knee'], position=[0.5, -1.25],
                                     velocity=[1.0, 2.0], effort=[3.0, 4.0])
    msg.header.stamp = node.get_clock().now().to_msg()
    msg.header.frame_id = 'base_link'
    return msg


def test_a_foxglove_client_sees_the_graph_topics_as_ros2_cdr(graph, start_view):
    description = std_msgs.msg.String(data='<robot name="view_test"/>')
    # Latched, and published before the view is there: a late client still gets it.
    graph.create_publisher(std_msgs.msg.String, 'robot_description',
                           qos_profile_latched).publish(description)
    joints = joint_state(graph)
    publishing = Publishing([
        (graph.create_publisher(geometry_msgs.msg.Twist, 'cmd_vel', 10), twist()),
        (graph.create_publisher(sensor_msgs.msg.JointState, 'joint_states', 10), joints)])
    view = start_view()
    assert view.url.startswith('ws://127.0.0.1:')
    types = {'/cmd_vel': 'geometry_msgs/msg/Twist', '/joint_states': 'sensor_msgs/msg/JointState',
             '/robot_description': 'std_msgs/msg/String'}
    try:
        with connect(view.url) as ws:
            assert ws.subprotocol == 'foxglove.sdk.v1'
            info = json.loads(ws.recv(timeout=TIMEOUT_S))
            assert info['op'] == 'serverInfo'
            channels = advertised(ws, types)
            # Every topic of the contract, whether or not it has a publisher yet.
            assert set(channels) == set(view_topics())
            for topic, type_name in types.items():
                channel = channels[topic]
                assert (channel['encoding'], channel['schemaEncoding']) == ('cdr', 'ros2msg')
                assert channel['schemaName'] == type_name
                # rosbag2's MCAP schema text: the definition, then each dependency.
                assert channel['schema'] == definition_text(type_name)
            assert '=' * 80 + '\nMSG: geometry_msgs/Vector3\n' in channels['/cmd_vel']['schema']
            subscriptions = dict(enumerate(types, start=1))
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': sid, 'channelId': channels[topic]['id']}
                for sid, topic in subscriptions.items()]}))
            before_ns = time.time_ns()
            frames = received(ws, subscriptions, count=1)
            after_ns = time.time_ns()
        # Another client subscribes to the latched topic later: it gets the sample too.
        with connect(view.url) as ws:
            channels = advertised(ws, ['/robot_description'])
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 9, 'channelId': channels['/robot_description']['id']}]}))
            [(_, late)] = received(ws, {9: '/robot_description'}, count=1)['/robot_description']
    finally:
        publishing.close()
    assert std_msgs.msg.String.deserialize(late) == description
    expected = {'/cmd_vel': twist(), '/joint_states': joints, '/robot_description': description}
    for topic, msg in expected.items():
        log_time_ns, payload = frames[topic][0]
        assert before_ns - 5e9 < log_time_ns <= after_ns  # the time the view received it
        assert_wire_bytes(payload, msg)
    velocity = decode_with_schema(channels['/cmd_vel'], frames['/cmd_vel'][0][1])
    assert (velocity.linear.x, velocity.linear.y, velocity.angular.z) == (0.25, -0.125, 0.5)
    state = decode_with_schema(channels['/joint_states'], frames['/joint_states'][0][1])
    assert (state.name, list(state.position)) == (['hip', 'knee'], [0.5, -1.25])
    assert state.header.frame_id == 'base_link'
    assert view.stop(signal.SIGINT) == 0


def test_a_namespaced_view_serves_the_topics_of_that_namespace(graph, start_view):
    publishing = Publishing([
        (graph.create_publisher(geometry_msgs.msg.Twist, '/robot1/cmd_vel', 10), twist()),
        (graph.create_publisher(geometry_msgs.msg.Twist, '/cmd_vel', 10), twist())])
    view = start_view('--namespace', 'robot1')
    try:
        with connect(view.url) as ws:
            channels = advertised(ws, ['/robot1/cmd_vel'])
            # /tf, /tf_static and /diagnostics are the robot's, /clock the domain's.
            assert set(channels) == {
                topic if topic == '/clock' else '/robot1' + topic for topic in view_topics()}
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 1, 'channelId': channels['/robot1/cmd_vel']['id']}]}))
            payload = received(ws, {1: '/robot1/cmd_vel'}, count=1)['/robot1/cmd_vel'][0][1]
    finally:
        publishing.close()
    assert_wire_bytes(payload, twist())
    assert view.stop(signal.SIGTERM) == 0


def test_the_view_reads_a_topic_latched_and_reliable_only_when_every_publisher_offers_it():
    from gait_nodes.runtime import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from gait_nodes.runtime.qos import offered_qos_yaml
    from gait_nodes.view import SUBSCRIPTION_DEPTH, subscription_qos

    latched = offered_qos_yaml(qos_profile_latched)
    volatile = offered_qos_yaml(QoSProfile(depth=10))
    best_effort = offered_qos_yaml(QoSProfile(depth=5,
                                              reliability=ReliabilityPolicy.BEST_EFFORT))
    profile = subscription_qos([latched, latched])
    assert profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert profile.reliability == ReliabilityPolicy.RELIABLE
    assert profile.depth == SUBSCRIPTION_DEPTH
    # A transient-local reader does not match a volatile writer, nor a reliable one a
    # best-effort writer: the reader asks for what all of them offer.
    assert subscription_qos([latched, volatile]).durability == DurabilityPolicy.VOLATILE
    assert subscription_qos([volatile, best_effort]).reliability == \
        ReliabilityPolicy.BEST_EFFORT


@pytest.fixture
def view_main(monkeypatch, capsys):
    """``main(args)`` of the view in this process: ``(status, stderr)``."""
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    monkeypatch.setenv('ROS_DOMAIN_ID', str(DOMAIN))
    from gait_nodes.view import main

    def run(*args: str) -> tuple[int, str]:
        status = main(['--runtime', 'dds', *args])
        return status, capsys.readouterr().err

    return run


def test_a_taken_port_is_refused_with_what_to_do(view_main):
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        status, err = view_main('--port', str(port))
    assert status == 2
    [line] = err.strip().splitlines()
    assert f'127.0.0.1:{port}' in line and 'Address already in use' in line
    assert '--port' in line


@pytest.mark.parametrize('args, says', [
    (['--namespace', 'robot 1'], 'robot 1'),
    (['--port', '70000'], '[0, 65535]'),
    (['--host', '192.0.2.1'], '--host'),  # TEST-NET-1: no address of this machine
    (['--runtime', 'inproc'], '--runtime dds'),
])
def test_bad_view_arguments_are_refused(view_main, args, says):
    status, err = view_main(*args)
    assert status == 2
    assert says in err and len(err.strip().splitlines()) == 1


def test_run_view_refuses_a_taken_port_and_a_graph_not_over_dds(capsys):
    from gait_nodes.__main__ import main

    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(['run', '--runtime', 'dds', '--view', str(port)]) == 2
    err = capsys.readouterr().err
    assert f'127.0.0.1:{port}' in err and 'Address already in use' in err
    assert main(['run', '--fast', '--view']) == 2
    assert '--runtime dds' in capsys.readouterr().err
    assert main(['run', '--runtime', 'dds', '--view', 'localhost:port']) == 2
    assert 'HOST:PORT' in capsys.readouterr().err
