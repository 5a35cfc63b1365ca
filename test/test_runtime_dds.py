"""The dds runtime on a real Cyclone DDS network (loopback), checked from both ends of the wire.

Every process of this module uses its own random ROS_DOMAIN_ID, so parallel test runs on one
machine do not hear each other, and the loopback-only Cyclone configuration, so that the tests
need no multicast.
"""

import json
import os
import random
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from gait_nodes import runtime
from gait_nodes.interfaces import geometry_msgs, raw_twins, std_msgs
from gait_nodes.runtime import qos_profile_latched

REPO = Path(__file__).resolve().parent.parent
_domains = random.SystemRandom().sample(range(100, 200), 2)
DOMAIN = _domains[0]
#: Another domain, for the isolation test.
OTHER_DOMAIN = _domains[1]
NS_PER_S = 1_000_000_000


def dds_env(domain: int = DOMAIN) -> dict[str, str]:
    """Environment of a gait_nodes process on ``domain`` over loopback."""
    env = dict(os.environ)
    env.pop('CYCLONEDDS_URI', None)
    env.update(PYTHONPATH=str(REPO), GAIT_NODES_RUNTIME='dds', ROS_DOMAIN_ID=str(domain),
               GAIT_NODES_DDS_LOCALHOST='1', PYTHONUNBUFFERED='1')
    return env


@pytest.fixture
def dds(monkeypatch):
    """The dds runtime in this process, on this module's domain; shut down after the test."""
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    runtime.init(args=[], runtime='dds', domain_id=DOMAIN, signal_handlers=False)
    yield runtime.default_context().transport
    runtime.shutdown()


def write_script(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def finish(process: subprocess.Popen, timeout: float) -> tuple[str, str]:
    """Wait for ``process``; kill it (and fail) if it overruns ``timeout``."""
    try:
        stdout, stderr = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        stdout, stderr = process.communicate()
        pytest.fail(f'{process.args} did not finish in {timeout} s\n{stdout}\n{stderr}')
    return stdout, stderr


# --- (a) two gait_nodes processes ------------------------------------------------------------

TALKER = """\
    import sys

    from gait_nodes import runtime
    from gait_nodes.interfaces import sensor_msgs, std_msgs

    runtime.init(args=sys.argv)
    node = runtime.Node('dds_talker')
    chatter = node.create_publisher(std_msgs.msg.String, '/chatter', 10)
    joints = node.create_publisher(sensor_msgs.msg.JointState, '/joint_states', 10)
    count = 0


    def tick():
        global count
        count += 1
        chatter.publish(std_msgs.msg.String(data=f'hello {count}'))
        msg = sensor_msgs.msg.JointState(name=['hip', 'knee'], position=[0.5 * count, -0.25],
                                         velocity=[1.0, 2.0], effort=[3.0, float(count)])
        msg.header.stamp = node.get_clock().now().to_msg()
        msg.header.frame_id = 'base_link'
        joints.publish(msg)


    node.create_timer(0.05, tick)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    executor.spin_for(float(sys.argv[1]))
    runtime.shutdown()
    """

LISTENER = """\
    import json
    import sys
    import threading
    import time

    from gait_nodes import runtime
    from gait_nodes.interfaces import sensor_msgs, std_msgs

    wanted, mode = int(sys.argv[1]), sys.argv[2]
    runtime.init(args=sys.argv)
    node = runtime.Node('dds_listener')
    heard = {'chatter': [], 'joints': []}
    node.create_subscription(std_msgs.msg.String, '/chatter',
                             lambda msg: heard['chatter'].append(msg.data), 10)
    node.create_subscription(
        sensor_msgs.msg.JointState, '/joint_states',
        lambda msg: heard['joints'].append({
            'name': msg.name, 'position': list(msg.position), 'velocity': list(msg.velocity),
            'effort': list(msg.effort), 'frame_id': msg.header.frame_id,
            'stamp_ns': msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec}), 10)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    stdin_closed = threading.Event()
    if mode == 'until-stdin-closes':
        threading.Thread(target=lambda: (sys.stdin.read(), stdin_closed.set()),
                         daemon=True).start()
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline and not stdin_closed.is_set():
        if mode == 'count' and min(len(v) for v in heard.values()) >= wanted:
            break
        executor.spin_for(0.05)
    runtime.shutdown()
    print(json.dumps(heard))
    """


def test_two_processes_exchange_string_and_joint_state(tmp_path):
    talker = write_script(tmp_path, 'talker.py', TALKER)
    listener = write_script(tmp_path, 'listener.py', LISTENER)
    start_ns = time.time_ns()
    listening = subprocess.Popen([sys.executable, str(listener), '5', 'count'], env=dds_env(),
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    talking = subprocess.Popen([sys.executable, str(talker), '30'], env=dds_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        stdout, stderr = finish(listening, 30)
    finally:
        talking.send_signal(signal.SIGTERM)
        talker_out, talker_err = finish(talking, 10)
    assert listening.returncode == 0, stderr
    assert talking.returncode == 0, talker_err
    heard = json.loads(stdout)
    counts = [int(re.fullmatch(r'hello (\d+)', text).group(1)) for text in heard['chatter']]
    assert len(counts) >= 5
    # Reliable, in order, nothing lost once matched.
    assert counts == list(range(counts[0], counts[0] + len(counts)))
    assert len(heard['joints']) >= 5
    for joints in heard['joints']:
        k = joints['effort'][1]
        assert joints['name'] == ['hip', 'knee']
        assert joints['position'] == [0.5 * k, -0.25]
        assert joints['velocity'] == [1.0, 2.0]
        assert joints['frame_id'] == 'base_link'
        assert start_ns <= joints['stamp_ns'] <= time.time_ns()
    assert 'Traceback' not in stderr + talker_err


# --- (b) an independent Cyclone DDS program, written as with Unitree's SDK ----------------------

# Nothing from gait_nodes: hand-written IDL types with the ROS 2 wire names, as
# unitree_sdk2py/idl/ declares them, and plain cyclonedds entities on `rt/` topics.
INDEPENDENT = """\
    import json
    import os
    import sys
    import time
    from dataclasses import dataclass

    import cyclonedds.idl as idl
    import cyclonedds.idl.annotations as annotate
    import cyclonedds.idl.types as types
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration


    @dataclass
    @annotate.final
    @annotate.autoid('sequential')
    class Time_(idl.IdlStruct, typename='builtin_interfaces.msg.dds_.Time_'):
        sec: types.int32
        nanosec: types.uint32


    @dataclass
    @annotate.final
    @annotate.autoid('sequential')
    class Header_(idl.IdlStruct, typename='std_msgs.msg.dds_.Header_'):
        stamp: Time_
        frame_id: str


    @dataclass
    @annotate.final
    @annotate.autoid('sequential')
    class String_(idl.IdlStruct, typename='std_msgs.msg.dds_.String_'):
        data: str


    @dataclass
    @annotate.final
    @annotate.autoid('sequential')
    class Point_(idl.IdlStruct, typename='geometry_msgs.msg.dds_.Point_'):
        x: types.float64
        y: types.float64
        z: types.float64


    @dataclass
    @annotate.final
    @annotate.autoid('sequential')
    class PointStamped_(idl.IdlStruct, typename='geometry_msgs.msg.dds_.PointStamped_'):
        header: Header_
        point: Point_


    wanted = int(sys.argv[1])
    participant = DomainParticipant(int(os.environ['ROS_DOMAIN_ID']))
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
              Policy.History.KeepLast(10), Policy.Durability.Volatile)
    reader = DataReader(participant, Topic(participant, 'rt/gait/zmp', PointStamped_), qos=qos)
    writer = DataWriter(participant, Topic(participant, 'rt/gait/command', String_), qos=qos)
    samples, seq, done_at = [], 0, None
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        seq += 1
        writer.write(String_(data=json.dumps({'step_length_m': 0.3, 'gait': 'trot', 'seq': seq})))
        for sample in reader.take(N=10):
            samples.append({'sec': sample.header.stamp.sec,
                            'nanosec': sample.header.stamp.nanosec,
                            'frame_id': sample.header.frame_id,
                            'xyz': [sample.point.x, sample.point.y, sample.point.z]})
        if done_at is None and len(samples) >= wanted:
            done_at = time.monotonic() + 1.0  # keep commanding a little longer
        if done_at is not None and time.monotonic() >= done_at:
            break
        time.sleep(0.05)
    print(json.dumps(samples))
    """

LOOPBACK_XML = """\
    <CycloneDDS xmlns="https://cdds.io/config">
      <Domain Id="any">
        <General>
          <Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>
          <AllowMulticast>false</AllowMulticast>
        </General>
        <Discovery>
          <ParticipantIndex>auto</ParticipantIndex>
          <MaxAutoParticipantIndex>60</MaxAutoParticipantIndex>
          <Peers><Peer address="127.0.0.1"/></Peers>
        </Discovery>
      </Domain>
    </CycloneDDS>
    """


def zmp_sample(k: int):
    msg = geometry_msgs.msg.PointStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = k, 250_000_000 + k
    msg.header.frame_id = 'odom'
    msg.point.x, msg.point.y, msg.point.z = 0.01 * k, -0.02 * k, 0.8
    return msg


def test_independent_cyclonedds_program_reads_and_writes_our_topics(dds, tmp_path):
    program = write_script(tmp_path, 'unitree_style.py', INDEPENDENT)
    config = write_script(tmp_path, 'loopback.xml', LOOPBACK_XML)
    env = {key: value for key, value in os.environ.items()
           if not key.startswith('GAIT_NODES') and key != 'PYTHONPATH'}
    env.update(ROS_DOMAIN_ID=str(DOMAIN), CYCLONEDDS_URI=config.as_uri())

    node = runtime.Node('zmp_monitor')
    zmp = node.create_publisher(geometry_msgs.msg.PointStamped, '/gait/zmp', 10)
    commands = []
    node.create_subscription(std_msgs.msg.String, '/gait/command',
                             lambda msg: commands.append(json.loads(msg.data)), 10)
    count = 0

    def publish_zmp():
        nonlocal count
        count += 1
        zmp.publish(zmp_sample(count))

    node.create_timer(0.05, publish_zmp)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    process = subprocess.Popen([sys.executable, str(program), '5'], env=env, cwd=tmp_path,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30.0
        while process.poll() is None and time.monotonic() < deadline:
            executor.spin_for(0.05)
        executor.spin_for(0.2)
    finally:
        stdout, stderr = finish(process, 5)
    assert process.returncode == 0, stderr

    # (i) The independent program decoded our PointStamped exactly.
    samples = json.loads(stdout)
    assert len(samples) >= 5
    for sample in samples:
        k = sample['sec']
        expected = zmp_sample(k)
        assert sample['nanosec'] == 250_000_000 + k
        assert sample['frame_id'] == 'odom'
        assert sample['xyz'] == [expected.point.x, expected.point.y, expected.point.z]
    assert [s['sec'] for s in samples] == sorted(s['sec'] for s in samples)

    # (ii) Our subscription received its String commands intact.
    assert len(commands) >= 1
    for command in commands:
        assert command['step_length_m'] == 0.3 and command['gait'] == 'trot'
    seqs = [command['seq'] for command in commands]
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))


# --- (c) what our entities look like on the wire -----------------------------------------------

def _take_raw(reader, timeout_s: float = 5.0) -> list[bytes]:
    """CDR bytes taken by a DataReader on a raw twin's Topic (public cyclonedds API only)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        taken = [sample.data for sample in reader.take(N=10)
                 if sample.sample_info is not None and sample.sample_info.valid_data]
        if taken:
            return taken
        time.sleep(0.01)
    return []


def test_topic_type_qos_and_payload_follow_ros2_conventions(dds):
    from cyclonedds.core import Policy
    from cyclonedds.sub import DataReader

    node = runtime.Node('wire_check')
    publisher = node.create_publisher(geometry_msgs.msg.PointStamped, '/gait/zmp', 10)
    node.create_subscription(std_msgs.msg.String, 'gait/command', lambda msg: None, 10)
    node.create_publisher(std_msgs.msg.String, '/gait/command_status', qos_profile_latched)

    zmp_topic = dds.topics['/gait/zmp', False]
    assert zmp_topic.name == 'rt/gait/zmp'
    assert zmp_topic.typename == 'geometry_msgs::msg::dds_::PointStamped_'
    assert dds.topics['/gait/command', False].name == 'rt/gait/command'
    assert dds.topics['/gait/command', False].typename == 'std_msgs::msg::dds_::String_'

    writer = next(w for w in dds.writers if w.topic.name == 'rt/gait/zmp')
    writer_qos = writer.get_qos()
    user_data = writer_qos[Policy.Userdata].data.decode()
    assert re.fullmatch(r'typehash=RIHS01_[0-9a-f]{64};', user_data)
    # rclpy's int depth: reliable, keep-last 10, volatile.
    assert isinstance(writer_qos[Policy.Reliability], Policy.Reliability.Reliable)
    assert writer_qos[Policy.History] == Policy.History.KeepLast(10)
    assert writer_qos[Policy.Durability] == Policy.Durability.Volatile
    # Plain CDR only: a ROS 2 endpoint does not match XCDR2.
    representation = writer_qos[Policy.DataRepresentation]
    assert representation.use_cdrv0_representation and not (
        representation.use_xcdrv2_representation)

    [reader_entry] = dds.readers
    reader_user_data = reader_entry.reader.get_qos()[Policy.Userdata].data.decode()
    assert reader_user_data.startswith('typehash=RIHS01_') and reader_user_data != user_data

    latched = next(w for w in dds.writers if w.topic.name == 'rt/gait/command_status')
    assert latched.get_qos()[Policy.Durability] == Policy.Durability.TransientLocal
    assert latched.get_qos()[Policy.History] == Policy.History.KeepLast(1)

    # The payload on the wire: XCDR1 little endian (0x0001), the bytes ROS 2 would send.
    from cyclonedds.topic import Topic

    raw_type, _ = raw_twins(geometry_msgs.msg.PointStamped)
    probe = DataReader(dds.participant, Topic(dds.participant, 'rt/gait/zmp', raw_type))
    msg = zmp_sample(3)
    publisher.publish(msg)
    [payload] = _take_raw(probe)
    assert payload[:2] == b'\x00\x01'
    expected = msg.serialize()
    assert payload[4:len(expected)] == expected[4:]
    assert geometry_msgs.msg.PointStamped.deserialize(payload) == msg
    # Publishing serialized bytes puts exactly those on the wire.
    publisher.publish(zmp_sample(4).serialize())
    [payload] = _take_raw(probe)
    assert geometry_msgs.msg.PointStamped.deserialize(payload) == zmp_sample(4)


def test_a_topic_carries_one_type_per_process(dds):
    from gait_nodes.errors import GaitNodesError

    node = runtime.Node('typed')
    node.create_publisher(std_msgs.msg.String, '/chatter', 10)
    with pytest.raises(GaitNodesError, match='/chatter'):
        node.create_publisher(geometry_msgs.msg.PointStamped, '/chatter', 10)


def test_in_process_delivery_over_dds(dds):
    node = runtime.Node('loop')
    publisher = node.create_publisher(std_msgs.msg.String, '/loop', 10)
    received = []
    node.create_subscription(std_msgs.msg.String, '/loop', lambda m: received.append(m.data), 10)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + 5.0
    while not received and time.monotonic() < deadline:
        publisher.publish(std_msgs.msg.String(data='ping'))
        executor.spin_for(0.05)
    assert received and set(received) == {'ping'}


def test_a_spinning_node_process_collects_garbage_less_often(dds):
    """As inproc: a node's ticks are not stalled by full collections (thresholds restored)."""
    import gc

    from gait_nodes.runtime.executors import SPIN_GC_THRESHOLD

    node = runtime.Node('ticker')
    seen = []

    def tick():
        seen.append(gc.get_threshold())
        if len(seen) >= 5:
            raise RuntimeError('callback failure')

    node.create_timer(0.01, tick)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    before = gc.get_threshold()
    try:
        gc.set_threshold(700, 11, 12)
        executor.spin_for(0.025)
        assert 1 <= len(seen) < 5
        assert gc.get_threshold() == (700, 11, 12)
        with pytest.raises(RuntimeError, match='callback failure'):
            executor.spin()
        assert seen == [(SPIN_GC_THRESHOLD, 11, 12)] * 5
        assert gc.get_threshold() == (700, 11, 12)
    finally:
        gc.set_threshold(*before)


# --- (d) ROS_DOMAIN_ID isolation ---------------------------------------------------------------

def test_domains_are_isolated(tmp_path):
    talker = write_script(tmp_path, 'talker.py', TALKER)
    listener = write_script(tmp_path, 'listener.py', LISTENER)
    popen = dict(stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    elsewhere = subprocess.Popen([sys.executable, str(listener), '0', 'until-stdin-closes'],
                                 env=dds_env(OTHER_DOMAIN), stdin=subprocess.PIPE, **popen)
    same = subprocess.Popen([sys.executable, str(listener), '3', 'count'], env=dds_env(DOMAIN),
                            **popen)
    talking = subprocess.Popen([sys.executable, str(talker), '30'], env=dds_env(DOMAIN), **popen)
    try:
        same_out, same_err = finish(same, 30)
        # The other domain has been listening all along; give it a while more.
        time.sleep(1.0)
        assert elsewhere.poll() is None, elsewhere.stderr.read()
        elsewhere_out, elsewhere_err = finish(elsewhere, 10)
    finally:
        for process in (elsewhere, talking):
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        finish(talking, 10)
    assert same.returncode == 0 and elsewhere.returncode == 0, same_err + elsewhere_err
    assert len(json.loads(same_out)['chatter']) >= 3
    assert json.loads(elsewhere_out) == {'chatter': [], 'joints': []}


def test_invalid_ros_domain_id_is_refused(monkeypatch):
    from gait_nodes.errors import RuntimeSelectionError

    monkeypatch.setenv('ROS_DOMAIN_ID', 'seven')
    try:
        with pytest.raises(RuntimeSelectionError, match='ROS_DOMAIN_ID'):
            runtime.init(args=[], runtime='dds', signal_handlers=False)
        with pytest.raises(RuntimeSelectionError, match='0..232'):
            runtime.init(args=[], runtime='dds', domain_id=300, signal_handlers=False)
    finally:
        runtime.shutdown()


# --- (e) clean stop on SIGINT / SIGTERM --------------------------------------------------------

IDLE_NODE = """\
    import sys

    from gait_nodes import runtime
    from gait_nodes.cli import run_node


    class Idle(runtime.Node):
        def __init__(self):
            super().__init__('idle')
            self.declare_parameter('gain', 1.0)
            self.ticks = 0
            self.create_timer(0.05, self.tick)

        def tick(self):
            self.ticks += 1
            if self.ticks == 2:
                print('spinning', flush=True)


    sys.exit(run_node(lambda options: Idle(), prog='idle_node', description='An idle node.'))
    """


def _handles_sigterm(pid: int) -> bool:
    """Whether the process has installed its own SIGTERM handler (Linux /proc)."""
    try:
        status = Path(f'/proc/{pid}/status').read_text()
    except FileNotFoundError:  # already gone
        return False
    caught = int(re.search(r'^SigCgt:\s*([0-9a-f]+)$', status, re.M).group(1), 16)
    return bool(caught & (1 << (signal.SIGTERM - 1)))


def _wait_until(predicate, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail(f'timed out waiting for {what}')
        time.sleep(0.02)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
@pytest.mark.parametrize('program', ['run_node', 'gait_nodes_run'])
def test_signal_stops_a_spinning_process_cleanly(tmp_path, program, signum):
    if program == 'run_node':
        command = [sys.executable, str(write_script(tmp_path, 'idle.py', IDLE_NODE))]
    else:
        command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'dds',
                   '--duration', '30']
    process = subprocess.Popen(command, env=dds_env(), cwd=tmp_path, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        if program == 'run_node':
            first_line = []
            reader = threading.Thread(target=lambda: first_line.append(process.stdout.readline()))
            reader.start()
            reader.join(20)
            assert first_line == ['spinning\n'], 'the node did not start spinning'
        _wait_until(lambda: process.poll() is not None or _handles_sigterm(process.pid), 20,
                    'the signal handlers')
        assert process.poll() is None
        time.sleep(0.2)
        sent = time.monotonic()
        process.send_signal(signum)
        stdout, stderr = finish(process, 10 if program == 'run_node' else 30)
        elapsed = time.monotonic() - sent
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 0, stderr
    # The launcher lets nodes that are still starting (imports, robot model, swing table)
    # come up before it stops them, since a node interrupted mid-import would crash.
    assert elapsed < (3.0 if program == 'run_node' else 25.0)
    assert 'Traceback' not in stderr
    if program == 'gait_nodes_run':
        assert 'runtime dds' in stdout


def _children(pid: int) -> list[int]:
    """Pids of the processes whose parent is ``pid`` (Linux /proc)."""
    children = []
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
            except (FileNotFoundError, ProcessLookupError):
                continue
            if int(fields[1]) == pid:
                children.append(int(entry.name))
    return children


def _alive(pid: int) -> bool:
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state != 'Z'


def test_nodes_stop_when_their_launcher_is_killed(tmp_path):
    """The nodes run in their own sessions; a SIGKILLed launcher must not leave them running."""
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'dds', '--duration', '60',
               '--nodes', 'footstep_planner,com_preview_controller']
    process = subprocess.Popen(command, env=dds_env(), cwd=tmp_path, stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        _wait_until(lambda: len(_children(process.pid)) == 2, 60, 'the two node processes')
        nodes = _children(process.pid)
        _wait_until(lambda: all(_handles_sigterm(pid) for pid in nodes), 60,
                    'the nodes to be up')
        process.kill()
        process.wait()
        _wait_until(lambda: not any(_alive(pid) for pid in nodes), 20,
                    'the orphaned nodes to stop')
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_a_guarded_node_starts_on_sim_time_given_at_start(monkeypatch):
    """use_sim_time:=true at start: the runtime subscribes /clock before the node's guard is up."""
    from gait_nodes.com_preview_controller import ComPreviewController

    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    runtime.init(args=['test', '--ros-args', '-p', 'use_sim_time:=true'], runtime='dds',
                 domain_id=DOMAIN, signal_handlers=False)
    try:
        node = ComPreviewController()
        assert node.get_parameter('use_sim_time').value is True
        assert node.get_clock().ros_time_is_active
    finally:
        runtime.shutdown()


def test_a_node_owning_time_ticks_on_the_steady_clock(monkeypatch):
    """A simulator that owns time: its timer on the steady clock runs, its others follow it.

    Until session 24 the executor compared the timers' next calls as instants: a timer one
    period ahead on the node's own simulated clock (near 0) always came before the steady
    one (the machine's uptime), never became due, and the node never ticked.
    """
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    runtime.init(args=['test'], runtime='dds', domain_id=DOMAIN, signal_handlers=False)
    try:
        node = runtime.Node('owns_time')
        simulated = [0]
        node.get_clock().set_source(lambda: simulated[0])
        ticks, followers = [], []

        def tick():
            simulated[0] += 10_000_000  # 10 ms of simulated time a tick
            ticks.append(time.monotonic())

        node.create_timer(0.01, tick, clock=runtime.Clock(
            clock_type=runtime.ClockType.STEADY_TIME))
        node.create_timer(0.1, lambda: followers.append(simulated[0]))  # on simulated time
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        start = time.monotonic()
        while time.monotonic() - start < 2.0:
            executor.spin_once(timeout_sec=0.1)
        assert len(ticks) >= 150  # 100 Hz over the two seconds, give or take the machine
        assert len(followers) >= 15  # every 0.1 s of the time the ticks made
    finally:
        runtime.shutdown()
