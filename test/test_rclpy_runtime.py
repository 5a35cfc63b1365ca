"""The rclpy runtime on a real ROS 2 Jazzy rclpy: nodes, parameters, signals, bags, interop.

Runs wherever rclpy is importable (a sourced ROS 2 Jazzy install); elsewhere, as in CI, the
whole module is skipped with the reason. Every process of this module uses its own random
ROS_DOMAIN_ID and Cyclone DDS on loopback (``config/cyclonedds_localhost.xml``, for the rmw and
for the dds runtime alike), so that parallel runs do not hear each other and no multicast is
needed.
"""

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

rclpy = pytest.importorskip(
    'rclpy', reason='rclpy is not importable: source a ROS 2 Jazzy install to run the rclpy tier')

from rclpy.parameter import Parameter  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
DOMAIN = random.SystemRandom().randrange(150, 230)
LOOPBACK_DDS = (REPO / 'config' / 'cyclonedds_localhost.xml').as_uri()
NODES = ('footstep_planner', 'com_preview_controller', 'swing_leg_policy', 'whole_body_ik',
         'kinematic_simulator', 'robot_state_publisher')
START_TIMEOUT_S = 120.0


def ros_env(runtime_name: str = 'rclpy', **extra) -> dict[str, str]:
    """Environment of a gait_nodes process of this module."""
    # The sourced install's PYTHONPATH (rclpy, the message packages) stays after the repo.
    python_path = os.pathsep.join(filter(None, [str(REPO), os.environ.get('PYTHONPATH')]))
    env = dict(os.environ, PYTHONPATH=python_path, ROS_DOMAIN_ID=str(DOMAIN),
               CYCLONEDDS_URI=LOOPBACK_DDS, RMW_IMPLEMENTATION='rmw_cyclonedds_cpp',
               GAIT_NODES_RUNTIME=runtime_name, PYTHONUNBUFFERED='1', **extra)
    return env


@pytest.fixture(scope='module')
def ros():
    """An rclpy node of the test itself, on this module's domain, and its executor."""
    os.environ.update(ROS_DOMAIN_ID=str(DOMAIN), CYCLONEDDS_URI=LOOPBACK_DDS,
                      RMW_IMPLEMENTATION='rmw_cyclonedds_cpp')
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('gait_nodes_test_observer', context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)


def spin_until(executor, predicate, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f'timed out after {timeout_s} s waiting for {what}')
        executor.spin_once(timeout_sec=0.05)


class Started:
    """A gait_nodes process started the way a launcher starts it, up and spinning."""

    def __init__(self, tmp_path: Path, args: list[str], runtime_name: str = 'rclpy'):
        self.ready = tmp_path / f'{args[0]}.{time.monotonic_ns()}.ready'
        self.log = tmp_path / f'{args[0]}.{time.monotonic_ns()}.log'
        with self.log.open('w') as log:  # the child writes through its own copy
            self.process = subprocess.Popen(
                [sys.executable, '-m', f'gait_nodes.{args[0]}', *args[1:]], cwd=tmp_path,
                env=ros_env(runtime_name, GAIT_NODES_READY_FILE=str(self.ready)),
                stdout=log, stderr=subprocess.STDOUT, text=True)

    def wait_ready(self) -> None:
        """Wait for the ready file the node writes once it spins."""
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self.ready.exists():
            assert self.process.poll() is None, f'exited {self.process.returncode}:\n{self.text()}'
            assert time.monotonic() < deadline, f'not up after {START_TIMEOUT_S} s:\n{self.text()}'
            time.sleep(0.05)

    def stop(self, signum: int, timeout_s: float = 20.0) -> int:
        """Send ``signum`` as a launcher would; the exit status."""
        self.process.send_signal(signum)
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            pytest.fail(f'still running {timeout_s} s after {signal.Signals(signum).name}:\n'
                        f'{self.text()}')

    def text(self) -> str:
        """What the process printed so far."""
        return self.log.read_text()

    def kill(self) -> None:
        """Make sure it is gone."""
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()


@pytest.fixture
def started(tmp_path):
    processes = []

    def start(*args, runtime_name='rclpy') -> Started:
        process = Started(tmp_path, list(args), runtime_name)
        processes.append(process)
        process.wait_ready()
        return process

    yield start
    for process in processes:
        process.kill()


def node_names(node) -> set[str]:
    return {name for name, _namespace in node.get_node_names_and_namespaces()}


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.parametrize('name', NODES)
def test_each_node_starts_is_seen_by_ros_and_stops_cleanly(ros, started, name, signum):
    node, executor = ros
    process = started(name)
    spin_until(executor, lambda: name in node_names(node), 20, f'/{name} in the ROS graph')
    assert process.stop(signum) == 0, process.text()
    log = process.text()
    assert 'Traceback' not in log, log
    spin_until(executor, lambda: name not in node_names(node), 20, f'/{name} to leave the graph')


def test_parameters_are_set_and_refused_as_ros2_param_does(ros, started):
    node, executor = ros
    process = started('footstep_planner')
    client = AsyncParameterClient(node, 'footstep_planner')
    assert client.wait_for_services(timeout_sec=20)

    def call(future):
        spin_until(executor, future.done, 20, 'a parameter service answer')
        return future.result()

    names = [result for result in call(client.list_parameters()).result.names]
    assert {'step_period_s', 'step_height_m', 'gait', 'use_sim_time'} <= set(names)
    before = call(client.get_parameters(['step_height_m'])).values[0].double_value

    accepted = call(client.set_parameters([Parameter('step_height_m', value=0.08)])).results[0]
    assert accepted.successful, accepted.reason
    assert call(client.get_parameters(['step_height_m'])).values[0].double_value == 0.08

    refused = call(client.set_parameters([Parameter('step_height_m', value=-1.0)])).results[0]
    assert not refused.successful
    assert 'step_height_m' in refused.reason and '-1' in refused.reason, refused.reason
    assert call(client.get_parameters(['step_height_m'])).values[0].double_value == 0.08
    assert before != 0.08
    assert process.stop(signal.SIGINT) == 0, process.text()


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_recorder_finishes_its_bag_on_a_signal(ros, started, tmp_path, signum):
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader
    from std_msgs.msg import String

    node, executor = ros
    bag = tmp_path / 'bag'
    recorder = started('recorder', '-o', str(bag), '-t', '/test/chatter:std_msgs/msg/String')
    publisher = node.create_publisher(String, '/test/chatter', 10)
    spin_until(executor, lambda: publisher.get_subscription_count() > 0, 20,
               'the recorder to subscribe')
    # Our writer has matched the recorder's reader; the reader matching our writer (the other
    # half of discovery) comes a moment later, and drops what comes before it.
    time.sleep(1.0)
    sent = 40
    for k in range(sent):
        publisher.publish(String(data=f'message {k}'))
        executor.spin_once(timeout_sec=0.01)
    time.sleep(1.0)
    assert recorder.stop(signum) == 0, recorder.text()
    assert 'Traceback' not in recorder.text()
    node.destroy_publisher(publisher)

    assert (bag / 'metadata.yaml').exists(), recorder.text()
    with Reader(bag) as reader:
        assert reader.message_count == sent
        texts = [data for _, _, data in reader.messages()]
    assert len(texts) == sent
    (mcap_path,) = bag.glob('*.mcap')
    with mcap_path.open('rb') as stream:
        mcap = make_reader(stream)
        summary = mcap.get_summary()  # the footer and summary are written: a finished file
        assert summary is not None
        assert sum(summary.statistics.channel_message_counts.values()) == sent
        assert mcap.get_header().profile == 'ros2'


def test_a_short_graph_walk_under_rclpy_records_a_readable_bag(tmp_path):
    bag = tmp_path / 'walk'
    result = subprocess.run(
        [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'rclpy', '--duration', '30',
         '--record', str(bag), '--no-plot', '--json'],
        env=ros_env(), cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert 'Traceback' not in result.stderr, result.stderr[-3000:]
    summary = json.loads(result.stdout[result.stdout.index('{'):])
    assert summary['runtime'] == 'rclpy'
    assert set(summary['exit_codes'].values()) == {0}, summary['exit_codes']
    for topic in ('/gait/footsteps', '/gait/com_reference', '/joint_states', '/gait/zmp',
                  '/tf', '/tf_static', '/robot_description'):
        assert summary['topics'][topic]['messages'] > 0, topic
    report = json.loads(subprocess.run(
        [sys.executable, '-m', 'gait_nodes.inspect', str(bag), '--json'], env=ros_env(),
        capture_output=True, text=True, timeout=300, check=True).stdout)['gait']
    # Here: it walked forward (bench/commands.py measures how well). 30 s: the planner joins
    # the robot, its first velocity joins that plan from standstill (about 2 s for RoboSimian's
    # crawl: the candidate is planned two cycles ahead), and the crawl's first cycle ramps its
    # strides up (0.05 to 0.16 m, the first swing about 8 s after the start).
    assert report['base']['displacement_m'] > 0.05, report['base']
    assert report['zmp_margin']['samples'] > 0


def test_robot_state_publisher_latches_the_urdf_and_the_fixed_joints_for_ros(ros, started):
    """What ``ros2 topic echo /robot_description`` and RViz get, subscribing after the start."""
    import xml.etree.ElementTree as ET

    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    node, executor = ros
    started('robot_state_publisher')
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    descriptions, statics = [], []
    subscriptions = [
        node.create_subscription(String, '/robot_description', descriptions.append, latched),
        node.create_subscription(TFMessage, '/tf_static', statics.append, latched)]
    try:
        spin_until(executor, lambda: descriptions and statics, 20,
                   '/robot_description and /tf_static from robot_state_publisher')
    finally:
        for subscription in subscriptions:
            node.destroy_subscription(subscription)
    urdf = REPO / 'config' / 'robots' / 'robosimian.urdf'
    assert descriptions[0].data == urdf.read_text()
    fixed = {joint.find('child').get('link')
             for joint in ET.parse(urdf).getroot().findall('joint')
             if joint.get('type') == 'fixed'}
    assert {t.child_frame_id for t in statics[0].transforms} == fixed


def test_rclpy_and_dds_nodes_share_one_graph(ros, started):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    node, executor = ros
    started('footstep_planner', runtime_name='dds')
    footsteps, statuses, diagnostics = [], [], []
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    subscriptions = [
        node.create_subscription(MultiDOFJointTrajectory, '/gait/footsteps', footsteps.append,
                                 latched),
        node.create_subscription(String, '/gait/command_status', statuses.append, 10),
        node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10),
    ]
    command = node.create_publisher(String, '/gait/command', 10)
    try:
        spin_until(executor, lambda: footsteps, 30, '/gait/footsteps from the dds planner')
        assert footsteps[0].joint_names and footsteps[0].points
        spin_until(executor, lambda: command.get_subscription_count() > 0, 20,
                   'the dds planner to subscribe to /gait/command')
        command.publish(String(data=json.dumps({'id': 'ok', 'step_height_m': 0.07})))
        command.publish(String(data=json.dumps({'id': 'bad', 'step_height_m': 'high'})))

        def decisions():
            return {a['id']: a for a in (json.loads(s.data) for s in statuses)
                    if a['state'] != 'applied'}

        spin_until(executor, lambda: {'ok', 'bad'} <= set(decisions()), 20,
                   'a decision on each command')
        answers = decisions()
        assert answers['ok']['state'] == 'accepted'
        assert answers['ok']['params']['step_height_m'] == 0.07
        assert answers['bad']['state'] == 'rejected' and not answers['bad']['accepted']
        assert 'step_height_m' in answers['bad']['reason']
        spin_until(executor, lambda: diagnostics, 20, '/diagnostics from the dds planner')
        assert diagnostics[0].status[0].name.startswith('footstep_planner')
    finally:
        for subscription in subscriptions:
            node.destroy_subscription(subscription)
        node.destroy_publisher(command)


def _launch(tmp_path, *arguments: str, nodes=NODES) -> Path:
    """``ros2 launch gait_nodes gait.launch.py`` recording, walked, stopped with Ctrl-C: its bag.

    Every node and the recorder started and finished cleanly.
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    try:
        get_package_share_directory('gait_nodes')
    except PackageNotFoundError:
        pytest.skip('gait_nodes is not in the ament index: colcon build it and source the '
                    'workspace to run `ros2 launch gait_nodes gait.launch.py`')
    bag = tmp_path / 'launched'
    # The log goes to a file (a pipe read only at the end would block the launch once full),
    # and the launch runs in its own process group: if it does not stop on Ctrl-C, the group
    # is killed, nodes included (once, the launch did not stop within a minute, and its nodes,
    # left running, disturbed the next graph on the domain).
    log_path = tmp_path / 'launch.log'
    with log_path.open('w') as log_file:
        launch = subprocess.Popen(['ros2', 'launch', 'gait_nodes', 'gait.launch.py',
                                   f'record:={bag}', 'robot:=robosimian', 'gait:=crawl',
                                   *arguments],
                                  env=ros_env(), cwd=tmp_path, stdout=log_file,
                                  stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        time.sleep(25.0)
        velocity = subprocess.run(
            [sys.executable, '-m', 'gait_nodes.command', '--vel', '0.04', '0', '0'],
            env=ros_env(), capture_output=True, text=True, timeout=60)
        assert velocity.returncode == 0, velocity.stderr
        time.sleep(10.0)
        launch.send_signal(signal.SIGINT)  # Ctrl-C
        launch.wait(timeout=60)
    finally:
        try:  # nothing of the graph left running, whatever happened
            os.killpg(launch.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        launch.wait()
    log = log_path.read_text()
    assert launch.returncode == 0, log[-3000:]
    for name in (*nodes, 'recorder'):
        assert f'[{name}-' in log and 'process has died' not in log, log[-3000:]
    assert log.count('process has finished cleanly') == len(nodes) + 1, log[-3000:]
    assert (bag / 'metadata.yaml').exists()
    return bag


def test_the_launch_file_starts_the_graph_and_stops_it_cleanly(tmp_path):
    _launch(tmp_path)


def test_the_launch_file_walks_the_robot_in_physics(tmp_path):
    """``simulator:=physics``: MuJoCo's robot in the graph, on its own /clock (sim time)."""
    pytest.importorskip('mujoco', reason='the physics simulator needs MuJoCo')
    nodes = tuple('physics_simulator' if n == 'kinematic_simulator' else n for n in NODES)
    bag = _launch(tmp_path, 'simulator:=physics', nodes=nodes)
    report = json.loads(subprocess.run(
        [sys.executable, '-m', 'gait_nodes.inspect', str(bag), '--json'], env=ros_env(),
        capture_output=True, text=True, timeout=300, check=True).stdout)
    counts = {topic['topic']: topic['count'] for topic in report['topics']}
    # What physics measures, recorded: the CoP and each foot's contact wrench, every tick of
    # the simulator's own clock (10 ms of it, however long a tick took on the wall).
    assert counts['/clock'] > 2000
    for topic in ('/gait/cop', '/gait/contact_wrench/front_left', '/joint_states'):
        assert counts.get(topic, 0) >= 0.95 * counts['/clock'], (topic, counts)
    gait = report['gait']
    assert gait['zmp_margin']['samples_outside'] <= 10, gait['zmp_margin']
    assert gait['base']['displacement_m'] > 0.01  # the first steps, 10 s after the command
    assert gait['consistency']['footholds']['max_m'] < 0.03
