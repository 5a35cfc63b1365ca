"""Bags: independent readers, metadata, damage, inspect numbers, plots, recorder kills, replay."""

import errno
import io
import json
import math
import os
import random
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import gait_bag
import numpy as np
import pytest
import yaml

from gait_nodes import runtime
from gait_nodes.bag.analysis import inspect_bag
from gait_nodes.bag.reader import BagReader, NotABagError
from gait_nodes.bag.writer import BagWriter, ChunkThread, message_appender
from gait_nodes.graph import TOPICS
from gait_nodes.interfaces import get_message, serialize_message, type_hash
from gait_nodes.replay import Replayer, replay_qos

REPO = Path(__file__).resolve().parent.parent
DOMAIN = random.SystemRandom().randrange(200, 230)


@pytest.fixture(scope='module')
def gait_bag_dir(tmp_path_factory):
    # Small chunks, so that truncation and corruption hit many chunk boundaries.
    return gait_bag.write_gait_bag(tmp_path_factory.mktemp('bags') / 'gait', chunk_size=8192)


def written_messages():
    return [(topic, stamp, serialize_message(msg)) for topic, stamp, msg in gait_bag.messages()]


# --- independent readers ----------------------------------------------------------------------

def test_rosbags_reads_every_message(gait_bag_dir):
    from rosbags.highlevel import AnyReader

    expected = written_messages()
    with AnyReader([gait_bag_dir]) as reader:
        assert reader.message_count == len(expected)
        got = [(c.topic, t, reader.deserialize(raw, c.msgtype), raw)
               for c, t, raw in reader.messages()]
    # rosbags yields in time order; ties (several topics per tick) may come in any order.
    assert sorted((topic, stamp, bytes(raw)) for topic, stamp, _, raw in got) == \
        sorted(expected)
    zmp = [msg for topic, _, msg, _ in got if topic == '/gait/zmp']
    assert zmp[550].point.y == pytest.approx(0.4) and zmp[10].point.x == pytest.approx(0.01)
    states = [msg for topic, _, msg, _ in got if topic == '/joint_states']
    assert list(states[0].name) == gait_bag.JOINTS


def test_mcap_library_decodes_every_message_with_ros2_conventions(gait_bag_dir):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    expected = written_messages()
    mcap_file = next(gait_bag_dir.glob('*.mcap'))
    with open(mcap_file, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert (schema.encoding, channel.message_encoding) == ('ros2msg', 'cdr')
            assert schema.name == TOPICS[channel.topic]
            assert channel.metadata['topic_type_hash'] == type_hash(schema.name)
            offered = yaml.safe_load(channel.metadata['offered_qos_profiles'])
            durability = 'transient_local' if channel.topic == '/gait/footsteps' else 'volatile'
            assert offered[0]['durability'] == durability
        decoded = list(reader.iter_decoded_messages(log_time_order=False))
    assert len(decoded) == len(expected)
    for (_, channel, message, _), (topic, stamp, _) in zip(decoded, expected,
                                                                      strict=True):
        assert (channel.topic, message.log_time) == (topic, stamp)
    footsteps = [m for _, c, _, m in decoded if c.topic == '/gait/footsteps'][0]
    assert list(footsteps.joint_names) == ['front_left', 'front_right', 'rear_left', 'rear_right']


def test_schema_text_concatenates_dependencies_the_ros2_way(gait_bag_dir):
    reader = BagReader(gait_bag_dir)
    assert list(reader.messages(topics=())) == []
    channels = {c.topic: c for c in reader.channels.values()}
    text = channels['/gait/footsteps'].schema_text
    sections = text.split('\n' + '=' * 80 + '\n')
    headers = [s.splitlines()[0] for s in sections[1:]]
    assert 'MSG: trajectory_msgs/MultiDOFJointTrajectoryPoint' in headers
    assert 'MSG: std_msgs/Header' in headers and 'MSG: builtin_interfaces/Time' in headers


def test_metadata_yaml_matches_the_file(gait_bag_dir):
    info = yaml.safe_load((gait_bag_dir / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']
    expected = written_messages()
    assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
    assert info['message_count'] == len(expected)
    assert info['relative_file_paths'] == [next(gait_bag_dir.glob('*.mcap')).name]
    stamps = [s for _, s, _ in expected]
    assert info['starting_time']['nanoseconds_since_epoch'] == min(stamps)
    assert info['duration']['nanoseconds'] == max(stamps) - min(stamps)
    counts = {}
    for topic, _, _ in expected:
        counts[topic] = counts.get(topic, 0) + 1
    for entry in info['topics_with_message_count']:
        meta = entry['topic_metadata']
        assert entry['message_count'] == counts.get(meta['name'], 0)
        assert meta['type'] == TOPICS[meta['name']]
        assert meta['type_description_hash'] == type_hash(meta['type'])
        assert meta['serialization_format'] == 'cdr'
    report = inspect_bag(gait_bag_dir).report
    assert report['metadata_check'] == {'matches': True, 'problems': []}


# --- inspect numbers against independent re-computation ----------------------------------------

def test_inspect_numbers_agree_with_the_construction(gait_bag_dir):
    gait = inspect_bag(gait_bag_dir, robot=str(gait_bag.ROBOT)).report['gait']
    samples = gait_bag.SECONDS * gait_bag.RATE_HZ
    times = np.arange(samples) / gait_bag.RATE_HZ
    assert gait['base']['distance_m'] == pytest.approx(0.1 * times[-1], abs=1e-9)
    assert gait['base']['net_speed_m_s'] == pytest.approx(0.1, abs=1e-9)
    assert gait['base']['path_speed_m_s'] == pytest.approx(0.1, abs=1e-9)
    margins = np.array([gait_bag.expected_margin(0.1 * t, gait_bag.zmp_y(t)) for t in times])
    assert gait['zmp_margin']['min_m'] == pytest.approx(margins.min(), abs=1e-6)
    assert gait['zmp_margin']['mean_m'] == pytest.approx(margins.mean(), abs=1e-6)
    assert gait['zmp_margin']['samples_outside'] == int(np.sum(margins < 0)) == 100
    assert gait['zmp_margin']['time_outside_s'] == pytest.approx(1.0, abs=1e-9)
    assert gait['zmp_margin']['first_outside_ns'] == gait_bag.START_NS + 5 * 10**9
    steps = gait['steps']
    assert steps['count'] == 2
    assert (steps['min_length_m'], steps['max_length_m']) == pytest.approx((0.2, 0.3))
    joints = gait['joint_velocity']['/joint_states']
    velocities = np.abs(np.outer(np.cos(2 * times), gait_bag.AMPLITUDES))
    assert joints['peak_rad_s'] == pytest.approx(velocities.max(), abs=1e-9)
    assert joints['peak_joint'] == 'fl_2' and joints['limit_rad_s'] == 1.0
    assert joints['samples_over_limit'] == int(np.sum(velocities > 1.0))
    assert gait['commands']['rejected'] == 1
    assert 'step_length_m' in gait['commands']['rejections'][0]
    assert gait['diagnostics']['by_level'] == {'OK': 8, 'WARN': 1, 'ERROR': 1}


def test_speed_is_the_net_advance_of_the_base_and_says_so():
    """A crawl sways: 6.6 mm/s forward is reported, not the 17 mm/s of its path (issue 25)."""
    from gait_nodes.bag.analysis import GaitSeries, base_metrics
    from gait_nodes.inspect import format_gait

    times = np.arange(0, 20.0, 0.01)
    x = 0.0066 * times
    y = 0.02 * np.sin(2 * np.pi * times / 4.0)  # sway, 20 mm each side, a 4 s cycle
    series = GaitSeries(base=[(int(t * 1e9), xi, yi, 0.5, 0.0) for t, xi, yi in
                              zip(times, x, y, strict=True)])
    base = base_metrics(series)
    elapsed = times[-1] - times[0]
    net = np.hypot(x[-1] - x[0], y[-1] - y[0]) / elapsed
    path = np.sum(np.hypot(np.diff(x), np.diff(y))) / elapsed
    assert base['net_speed_m_s'] == pytest.approx(net, abs=1e-6)
    assert base['path_speed_m_s'] == pytest.approx(path, abs=1e-6) and path > 2 * net
    [line] = format_gait({'base': base})[1:]
    assert f'net speed {net:.4f} m/s' in line, line
    assert f'path {base["distance_m"]:.3f} m (sway included)' in line, line
    assert f'{path:.4f}' not in line  # no other speed to be mistaken for it


def test_inspect_cli_json_text_and_plots(gait_bag_dir, tmp_path, capsys):
    from gait_nodes.inspect import main

    assert main([str(gait_bag_dir), '--json', '--robot', str(gait_bag.ROBOT), '--plot',
                 str(tmp_path / 'plots')]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['message_count'] == len(written_messages())
    assert {Path(p).name for p in report['plots']} == {
        'top_view.png', 'com_zmp_time.png', 'joint_velocities.png'}
    for plot in report['plots']:
        data = Path(plot).read_bytes()
        assert data.startswith(b'\x89PNG\r\n\x1a\n') and len(data) > 10_000
    assert main([str(gait_bag_dir)]) == 0
    text = capsys.readouterr().out
    assert 'metadata.yaml matches' in text and 'rejected: step_length_m' in text


def test_inspect_names_the_plot_directory_it_cannot_write(gait_bag_dir, tmp_path, capsys):
    from gait_nodes.inspect import main

    (tmp_path / 'a_file').write_text('not a directory\n')
    assert main([str(gait_bag_dir), '--plot', str(tmp_path / 'a_file' / 'plots')]) == 2
    [line] = capsys.readouterr().err.splitlines()
    assert f'--plot {tmp_path / "a_file" / "plots"}: cannot write' in line
    assert 'Not a directory' in line and str(gait_bag_dir) not in line


@pytest.mark.parametrize('make', ['text file', 'empty dir', 'missing', 'sqlite bag', 'bad yaml'])
def test_inspect_refuses_what_is_not_a_bag(tmp_path, capsys, make):
    from gait_nodes.inspect import main

    path = tmp_path / 'thing'
    if make == 'text file':
        path.write_text('hello\n')
    elif make == 'empty dir':
        path.mkdir()
    elif make == 'sqlite bag':
        path.mkdir()
        (path / 'metadata.yaml').write_text(yaml.safe_dump({'rosbag2_bagfile_information': {
            'version': 5, 'storage_identifier': 'sqlite3', 'relative_file_paths': ['x.db3']}}))
    elif make == 'bad yaml':
        path.mkdir()
        (path / 'metadata.yaml').write_text('rosbag2_bagfile_information: [\n')
    assert main([str(path)]) == 2
    error = capsys.readouterr().err
    assert error.startswith('python -m gait_nodes.inspect: error: ') and str(path) in error
    assert len(error.strip().splitlines()) == 1


# --- damage -------------------------------------------------------------------------------------

def read_all(path):
    reader = BagReader(path)
    got = [(c.topic, t, data) for c, t, _, data in reader.messages()]
    return got, reader.damage


def test_a_truncated_bag_reads_a_prefix_and_says_what_is_lost(gait_bag_dir, tmp_path):
    expected = written_messages()
    data = next(gait_bag_dir.glob('*.mcap')).read_bytes()
    rng = random.Random(7)
    for cut in sorted(rng.sample(range(20, len(data) - 1), 25)):
        path = tmp_path / f'cut_{cut}.mcap'
        path.write_bytes(data[:cut])
        got, damage = read_all(path)
        assert got == expected[:len(got)], cut
        assert damage and damage[0].offset <= cut, cut
        if damage[0].lost_end_ns is not None and len(got) < len(expected):
            # The lost span covers the first missing message.
            assert damage[0].lost_start_ns <= expected[len(got)][1] <= damage[0].lost_end_ns
    half = tmp_path / 'half.mcap'
    half.write_bytes(data[:len(data) // 2])
    report = inspect_bag(half).report
    assert not report['complete'] and report['damage']
    assert 0 < report['message_count'] < len(expected)


def test_a_corrupted_chunk_is_skipped_and_reported(gait_bag_dir, tmp_path):
    expected = written_messages()
    data = bytearray(next(gait_bag_dir.glob('*.mcap')).read_bytes())
    chunks = []
    position = 8
    while position < len(data):
        opcode, length = struct.unpack_from('<BQ', data, position)
        if opcode == 0x06:
            chunks.append(position)
        if opcode == 0x0F:
            break
        position += 9 + length
    victim = chunks[len(chunks) // 2]
    data[victim + 9 + 60] ^= 0xFF  # inside the compressed records
    path = tmp_path / 'corrupt.mcap'
    path.write_bytes(bytes(data))
    got, damage = read_all(path)
    assert len(damage) == 1 and damage[0].offset == victim
    lost = [m for m in expected if m not in got]
    assert lost and len(got) + len(lost) == len(expected)
    assert all(damage[0].lost_start_ns <= stamp <= damage[0].lost_end_ns for _, stamp, _ in lost)
    assert got[-1] == expected[-1]  # reading went on after the damage


def test_reader_errors_name_the_path(tmp_path):
    with pytest.raises(NotABagError, match='no such file'):
        BagReader(tmp_path / 'nothing')
    (tmp_path / 'fake.mcap').write_bytes(b'not mcap at all')
    with pytest.raises(NotABagError, match='fake.mcap: not an MCAP file'):
        BagReader(tmp_path / 'fake.mcap')


# --- recorder processes over DDS -----------------------------------------------------------------

def dds_env():
    env = dict(os.environ)
    env.pop('CYCLONEDDS_URI', None)
    env.update(PYTHONPATH=str(REPO), GAIT_NODES_RUNTIME='dds', ROS_DOMAIN_ID=str(DOMAIN),
               GAIT_NODES_DDS_LOCALHOST='1', PYTHONUNBUFFERED='1')
    return env


@pytest.fixture
def dds(monkeypatch):
    monkeypatch.delenv('CYCLONEDDS_URI', raising=False)
    monkeypatch.setenv('GAIT_NODES_DDS_LOCALHOST', '1')
    runtime.init(args=[], runtime='dds', domain_id=DOMAIN, signal_handlers=False)
    yield
    runtime.shutdown()


def start_recorder(bag: Path, *topics: str) -> subprocess.Popen:
    command = [sys.executable, '-m', 'gait_nodes.recorder', '-o', str(bag)]
    if topics:
        command += ['-t', *topics]
    return subprocess.Popen(command, env=dds_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def publish_joint_states(seconds: float, until=None) -> list[int]:
    """Publish stamped JointState at 100 Hz; the stamps sent."""
    node = runtime.Node('bag_test_talker')
    publisher = node.create_publisher(get_message('sensor_msgs/msg/JointState'),
                                      '/joint_states', 10)
    sent = []

    def tick():
        msg = get_message('sensor_msgs/msg/JointState')(name=['a'], position=[len(sent)])
        msg.header.stamp = node.get_clock().now().to_msg()
        publisher.publish(msg)
        sent.append(node.get_clock().now().nanoseconds)

    timer = node.create_timer(0.01, tick)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and (until is None or not until()):
        executor.spin_for(0.05)
    timer.cancel()
    node.destroy_node()
    return sent


def wait_for_matched_recorder(*processes, seconds=15.0):
    # The recorder logs once it has subscribed; discovery then takes a moment more.
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        for process in processes:
            if process.poll() is not None:
                pytest.fail(f'recorder exited early: {process.communicate()}')
        time.sleep(0.1)
        if time.monotonic() > deadline - seconds + 2.0:
            return


def test_recorder_killed_with_sigkill_loses_at_most_one_second(dds, tmp_path):
    bag = tmp_path / 'killed'
    recorder = start_recorder(bag, '/joint_states')
    wait_for_matched_recorder(recorder)
    sent = publish_joint_states(4.0)
    killed_at = time.time_ns()
    recorder.send_signal(signal.SIGKILL)
    recorder.communicate(timeout=10)
    assert not (bag / 'metadata.yaml').exists()
    report = inspect_bag(bag).report
    assert not report['complete']
    reader = BagReader(bag)
    stamps = [struct.unpack_from('<iI', data, 4) for _, _, _, data in reader.messages()]
    assert stamps, 'nothing survived the kill'
    last_ns = max(sec * 10**9 + nsec for sec, nsec in stamps)
    assert killed_at - last_ns <= 1_000_000_000, (killed_at - last_ns) / 1e9
    assert sent[-1] <= killed_at
    # An independent reader (the mcap library, streaming, CRCs checked) finds the same
    # messages in what was flushed, up to the cut-off tail.
    from mcap.exceptions import McapError
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    [mcap_file] = bag.glob('*.mcap')
    independent = []
    with open(mcap_file, 'rb') as stream:
        try:
            for record in StreamReader(stream, validate_crcs=True).records:
                if isinstance(record, Message):
                    independent.append(record.data)
        except (McapError, EOFError, ValueError):
            pass  # the unfinished chunk at the end of a killed recording
    assert sorted(independent) == sorted(data for _, _, _, data in reader.messages())


def test_recorder_stopped_cleanly_writes_summary_and_metadata(dds, tmp_path):
    # One stream, two recorders at once: one stopped with SIGINT, the other with SIGTERM.
    from gait_nodes.interfaces import deserialize_message

    bags = {signum: tmp_path / f'clean_{signum.name}' for signum in (signal.SIGINT,
                                                                     signal.SIGTERM)}
    recorders = {signum: start_recorder(bag, '/joint_states') for signum, bag in bags.items()}
    wait_for_matched_recorder(*recorders.values())
    sent = publish_joint_states(2.0)
    time.sleep(0.3)
    for signum, recorder in recorders.items():
        recorder.send_signal(signum)
    for signum, recorder in recorders.items():
        _, stderr = recorder.communicate(timeout=15)
        assert recorder.returncode == 0, (signum.name, stderr)
        report = inspect_bag(bags[signum]).report
        assert report['complete'] and not report['damage'], signum.name
        assert report['metadata_check']['matches'], signum.name
        # Reliable QoS over loopback: everything published after the first message that
        # arrived (discovery takes a moment) is in the bag, in order, up to the last one sent.
        joint_state = get_message('sensor_msgs/msg/JointState')
        indices = [int(deserialize_message(data, joint_state).position[0])
                   for _, _, _, data in BagReader(bags[signum]).messages()]
        assert indices == list(range(indices[0], len(sent))), (signum.name, indices[:3],
                                                                len(sent))
        assert report['message_count'] == len(indices) and indices[0] < len(sent) // 2


# --- replay -------------------------------------------------------------------------------------

def test_replay_qos_follows_the_offered_profiles():
    latched = replay_qos([{'reliability': 'reliable', 'durability': 'transient_local',
                           'depth': 1}])
    assert latched.durability.name == 'TRANSIENT_LOCAL' and latched.depth == 1
    mixed = replay_qos([{'reliability': 1, 'durability': 2, 'depth': 50},
                        {'reliability': 'best_effort', 'durability': 'volatile', 'depth': 5}])
    assert mixed.reliability.name == 'BEST_EFFORT' and mixed.depth == 50
    assert replay_qos([]).depth == 10


@pytest.mark.parametrize('rate', [1.0, 2.5])
def test_replay_in_process_keeps_content_order_and_timing(gait_bag_dir, rate):
    runtime.init(args=[], runtime='inproc')
    try:
        player = runtime.Node('replay')
        listener = runtime.Node('listener')
        got = []
        clock_stamps = []
        for topic in ('/gait/zmp', '/joint_states'):
            listener.create_subscription(
                get_message(TOPICS[topic]), topic,
                lambda msg, topic=topic: got.append(
                    (topic, listener.get_clock().now().nanoseconds, serialize_message(msg))),
                10)
        listener.create_subscription(get_message('rosgraph_msgs/msg/Clock'), '/clock',
                                     lambda msg: clock_stamps.append(msg.clock.sec), 10)
        replayer = Replayer(player, gait_bag_dir, rate=rate, topics=['/gait/zmp',
                                                                     '/joint_states'],
                            clock_hz=10.0)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(player)
        executor.add_node(listener)
        count = replayer.play_once(executor)
    finally:
        runtime.shutdown()
    expected = [(t, s, d) for t, s, d in written_messages() if t in ('/gait/zmp',
                                                                    '/joint_states')]
    assert count == len(expected) == len(got)
    assert [(t, d) for t, _, d in got] == [(t, d) for t, _, d in expected]
    received = np.array([s for _, s, _ in got], dtype=np.int64)
    recorded = np.array([s for _, s, _ in expected], dtype=np.int64)
    np.testing.assert_allclose(np.diff(received), np.diff(recorded) / rate, atol=1)
    assert len(clock_stamps) == pytest.approx(10 * gait_bag.SECONDS, abs=2)
    assert clock_stamps[0] == gait_bag.START_NS // 10**9


def test_replay_over_dds_into_a_recorder(gait_bag_dir, tmp_path):
    bag = tmp_path / 'replayed'
    recorder = start_recorder(bag, '/gait/zmp', '/gait/footsteps')
    wait_for_matched_recorder(recorder)
    replay = subprocess.run(
        [sys.executable, '-m', 'gait_nodes.replay', str(gait_bag_dir), '--rate', '5',
         '--topics', '/gait/zmp', '/gait/footsteps', '--delay', '1.5'],
        env=dds_env(), capture_output=True, text=True, timeout=60)
    assert replay.returncode == 0, replay.stderr
    assert 'replayed 1001 messages' in replay.stderr
    time.sleep(0.5)
    recorder.send_signal(signal.SIGINT)
    recorder.communicate(timeout=15)
    got, damage = read_all(bag)
    assert not damage
    expected = [(t, d) for t, _, d in written_messages() if t in ('/gait/zmp',
                                                                 '/gait/footsteps')]
    # Order is kept per topic (across topics DDS makes no promise).
    # Cyclone hands raw samples over padded to 4 bytes, as rmw_cyclonedds gives them to rosbag2.
    for topic in ('/gait/zmp', '/gait/footsteps'):
        recorded = [d for t, _, d in got if t == topic]
        sent = [d for t, d in expected if t == topic]
        assert len(recorded) == len(sent)
        for data, original in zip(recorded, sent, strict=True):
            assert data == original + b'\0' * (-len(original) % 4)
    stamps = np.array([s for t, s, _ in got if t == '/gait/zmp'])
    # 100 Hz recorded, played at 5x: about 2 ms apart on the wall clock.
    assert np.median(np.diff(stamps)) == pytest.approx(2e6, rel=0.25)


def test_replay_rejects_bad_arguments(gait_bag_dir, capsys):
    from gait_nodes.replay import main

    assert main([str(gait_bag_dir), '--runtime', 'inproc', '--rate', '0']) == 2
    assert '--rate must be > 0' in capsys.readouterr().err
    assert main([str(gait_bag_dir), '--runtime', 'inproc', '--topics', '/nope']) == 2
    assert "topics not in" in capsys.readouterr().err
    assert main(['/no/such/bag', '--runtime', 'inproc']) == 2


def test_writer_refuses_an_existing_directory(tmp_path):
    from gait_nodes.errors import ConfigError

    (tmp_path / 'exists').mkdir()
    with pytest.raises(ConfigError, match='exists already'):
        BagWriter(tmp_path / 'exists')


@pytest.mark.parametrize('compression', ['zstd', 'lz4', 'none'])
def test_fast_message_path_writes_the_bytes_of_mcap_add_message(compression):
    """The recorder's message appender and chunk thread leave the file mcap's own would write.

    Small chunks (many chunk ends, some in the middle of a batch), out-of-order log times,
    channels appearing mid-chunk, empty and large messages, batches of 1 to 40 messages,
    explicit flushes in between; the chunks finished on the caller's thread (mcap's Writer)
    or compressed and written on a ChunkThread.
    """
    import io

    from mcap.writer import CompressionType, Writer

    if compression == 'lz4':
        pytest.importorskip('lz4.frame')
    kind = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
            'none': CompressionType.NONE}[compression]
    messages = written_messages()
    channels = sorted({topic for topic, _, _ in messages})
    outputs = []
    for fast, threaded in ((False, False), (True, False), (True, True)):
        stream = io.BytesIO()
        writer = Writer(stream, chunk_size=4096, compression=kind)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema(name='s', encoding='ros2msg', data=b'')
        ids = {t: writer.register_channel(topic=t, message_encoding='cdr', schema_id=schema)
               for t in channels}
        append = message_appender(writer) if fast else None
        assert not fast or append is not None
        chunk_thread = ChunkThread.attach(writer, stream) if threaded else None
        assert not threaded or chunk_thread is not None
        batch = []
        for k, (topic, stamp, data) in enumerate(messages):
            log_time = stamp - (k % 5) * 1000  # not monotonic
            data = b'' if k % 97 == 0 else data * (1 + (k % 13 == 0) * 20)
            if fast:
                batch.append((ids[topic], log_time, data, stamp, k))
                if len(batch) > k % 41 or k % 301 == 0:
                    append(batch)
                    batch = []
            else:
                writer.add_message(channel_id=ids[topic], log_time=log_time, data=data,
                                   publish_time=stamp, sequence=k)
            if k % 301 == 0:
                if chunk_thread is None:
                    writer.flush()
                else:  # the stream is the thread's until stopped
                    chunk_thread.finish_chunk()
                    chunk_thread.flush()
        if batch:
            append(batch)
        if chunk_thread is not None:
            chunk_thread.finish_chunk()
            chunk_thread.stop()
        writer.finish()
        outputs.append(stream.getvalue())
    assert len(messages) > 500
    from mcap.reader import make_reader

    assert len(make_reader(io.BytesIO(outputs[0])).get_summary().chunk_indexes) > 20
    assert outputs[1] == outputs[0]
    assert outputs[2] == outputs[0]


def test_margin_of_the_fixture_formula_is_consistent():
    # The independent formula used above agrees with geometry at a few hand-checked points.
    assert gait_bag.expected_margin(0.5, 0.0) == pytest.approx(0.3)
    assert gait_bag.expected_margin(0.5, 0.4) == pytest.approx(-0.1)
    assert gait_bag.expected_margin(1.5, 0.7) == pytest.approx(-math.hypot(0.3, 0.4))


def test_chunk_thread_error_is_raised_on_the_callers_thread_and_nothing_hangs():
    """A write failing on the ChunkThread (a full disk) is raised by the next call made there."""
    import io

    from mcap.writer import CompressionType, Writer

    class FullDisk(io.BytesIO):
        def write(self, data):
            if len(data) > 1000:
                raise OSError(28, 'No space left on device')
            return super().write(data)

    stream = FullDisk()
    writer = Writer(stream, chunk_size=4096, compression=CompressionType.ZSTD)
    writer.start(profile='ros2', library='test')
    schema = writer.register_schema(name='s', encoding='ros2msg', data=b'')
    channel = writer.register_channel(topic='/t', message_encoding='cdr', schema_id=schema)
    chunk_thread = ChunkThread.attach(writer, stream)
    # The thread's error surfaces at the first call made after it happened: which one that is
    # depends on the thread's timing, but stop() waits for the thread, so by then at the latest.
    with pytest.raises(OSError, match='No space'):
        for k in range(50):
            writer.add_message(channel_id=channel, log_time=k, data=os.urandom(200),
                               publish_time=k)
        chunk_thread.finish_chunk()
        chunk_thread.stop()
    chunk_thread.stop()  # raised once; the thread is gone


# --- write failures: a full disk, a file system that refuses ---------------------------------

class DiskOf(io.FileIO):
    """A new file on a disk with ``free`` bytes left: what fits is written, then ENOSPC.

    The kernel's behaviour (a short write, then the error), under Python's own buffering.
    """

    def __init__(self, path, free: int):
        super().__init__(path, 'xb')
        self.free = free

    def write(self, data) -> int:
        """Write what fits; ENOSPC when nothing does."""
        if self.free <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written = super().write(memoryview(data)[:self.free])
        self.free -= written
        return written


def disk_of(free: int):
    return lambda path: io.BufferedWriter(DiskOf(path, free))


def write_flushing_every(writer: BagWriter, messages, every: int) -> list[int]:
    """Write ``messages`` with the contract topics, flushing every ``every``; the flush counts."""
    for topic, type_name in TOPICS.items():
        writer.add_topic(topic, type_name, [])
    flushed = [0]
    for k, (topic, stamp, data) in enumerate(messages):
        writer.write(topic, data, stamp)
        if k % every == every - 1:
            writer.flush()
            flushed.append(k + 1)
    writer.close()
    writer.close()
    return flushed


def assert_readable_bag_of(bag: Path, messages) -> None:
    """``bag`` holds exactly ``messages``, complete, and metadata.yaml agrees (us and mcap)."""
    from mcap.reader import make_reader

    assert sorted(p.name for p in bag.iterdir()) == sorted([f'{bag.name}_0.mcap',
                                                            'metadata.yaml'])
    got, damage = read_all(bag)
    assert got == messages and not damage
    report = inspect_bag(bag).report
    assert report['complete'] and report['message_count'] == len(messages)
    assert report['metadata_check'] == {'matches': True, 'problems': []}
    with open(bag / f'{bag.name}_0.mcap', 'rb') as stream:
        assert sum(1 for _ in make_reader(stream).iter_messages()) == len(messages)


@pytest.mark.parametrize('background', [True, False], ids=['chunk-thread', 'inline'])
def test_a_full_disk_closes_the_bag_readable_at_its_last_flush(tmp_path, background):
    expected = written_messages()
    failures = []
    bag = tmp_path / 'full'
    writer = BagWriter(bag, flush_period_s=3600, chunk_size=8192, background=background,
                       on_error=failures.append, open_file=disk_of(40_000))
    flushed = write_flushing_every(writer, expected, 500)  # no call raises
    assert failures == [writer]
    assert writer.error.errno == errno.ENOSPC
    assert str(bag / 'full_0.mcap') in writer.failure
    assert 'No space left on device' in writer.failure and '\n' not in writer.failure
    kept = writer.message_count
    assert kept in flushed and 0 < kept < len(expected)
    assert f'{kept} messages' in writer.failure
    assert_readable_bag_of(bag, expected[:kept])


def test_a_summary_that_does_not_fit_loses_no_message(tmp_path):
    expected = written_messages()
    write_flushing_every(BagWriter(tmp_path / 'whole', chunk_size=8192), expected, 10**9)
    size = (tmp_path / 'whole' / 'whole_0.mcap').stat().st_size
    failures = []
    writer = BagWriter(tmp_path / 'short', chunk_size=8192, on_error=failures.append,
                       open_file=disk_of(size - 200))  # all but the end of the summary
    write_flushing_every(writer, expected, 10**9)
    assert failures == [writer] and writer.message_count == len(expected)
    assert '(0 lost)' in writer.failure
    assert_readable_bag_of(tmp_path / 'short', expected)


def test_a_bag_file_that_cannot_be_started_is_refused_and_nothing_is_left(tmp_path):
    from gait_nodes.errors import ConfigError

    bag = tmp_path / 'new' / 'deeper' / 'bag'
    with pytest.raises(ConfigError, match=r'cannot write bag file .*bag_0\.mcap: \[Errno 28\] '
                                          r'No space left on device'):
        BagWriter(bag, open_file=disk_of(0))
    assert list(tmp_path.iterdir()) == []


def big_joint_state(index: int, stamp):
    """A JointState of ~800 bytes that does not compress, ``position[0] == index``."""
    msg = get_message('sensor_msgs/msg/JointState')(
        name=['a'], position=[float(index)] + [random.random() for _ in range(99)])
    msg.header.stamp = stamp
    return msg


def indices_in(bag: Path) -> list[int]:
    from gait_nodes.interfaces import deserialize_message

    joint_state = get_message('sensor_msgs/msg/JointState')
    return [int(deserialize_message(data, joint_state).position[0])
            for _, _, _, data in BagReader(bag).messages()]


def bag_errors(arrays) -> list:
    from gait_nodes.diagnostics import ERROR, level_value

    return [status for array in arrays for status in array.status
            if status.name == 'recorder: bag' and level_value(status.level) == ERROR]


def test_recorder_on_a_full_disk_reports_stops_and_the_graph_goes_on(tmp_path):
    """In process (inproc): the disk fills; no exception reaches the executor."""
    from gait_nodes.recorder import Recorder

    bag = tmp_path / 'full'
    runtime.init(args=['test', '--ros-args', '-p', 'recorder:flush_period_s:=0.1'],
                 runtime='inproc', signal_handlers=False)
    try:
        talker = runtime.Node('talker')
        publisher = talker.create_publisher(get_message('sensor_msgs/msg/JointState'),
                                            '/joint_states', 10)
        sent = []

        def tick():
            publisher.publish(big_joint_state(len(sent), talker.get_clock().now().to_msg()))
            sent.append(len(sent))

        talker.create_timer(0.01, tick)
        diagnostics = []
        talker.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                   '/diagnostics', diagnostics.append, 10)
        recorder = Recorder(output=str(bag),
                            topics={'/joint_states': 'sensor_msgs/msg/JointState'},
                            open_file=disk_of(60_000))
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(talker)
        executor.add_node(recorder)
        for _ in range(40):  # flushes go by wall time: some between the simulated steps
            executor.spin_for(0.1)
            time.sleep(0.02)
        assert len(sent) == 400  # the graph went on
        errors = bag_errors(diagnostics)
        assert errors, 'no ERROR on /diagnostics'
        assert str(bag / 'full_0.mcap') in errors[0].message
        assert 'No space left on device' in errors[0].message
        assert {v.key: v.value for v in errors[0].values}['path'] == str(bag)
        assert recorder.subscriptions == []  # recording stopped
        kept = recorder.writer.message_count
    finally:
        runtime.shutdown()
    assert 0 < kept < 400
    assert indices_in(bag) == list(range(kept))
    report = inspect_bag(bag).report
    assert report['complete'] and report['metadata_check']['matches']


def test_recorder_process_on_a_full_disk_reports_and_stops_cleanly(dds, tmp_path):
    """Over DDS: the recorder's files are limited to 30 kB (RLIMIT_FSIZE: the kernel's EFBIG).

    Python ignores SIGXFSZ, so a write past the limit fails with an OSError as on a full disk.
    """
    import resource

    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (30_000, 30_000))

    bag = tmp_path / 'limited'
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'gait_nodes.recorder', '-o', str(bag), '-t', '/joint_states',
         '--ros-args', '-p', 'flush_period_s:=0.1'], env=dds_env(), stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, preexec_fn=limit_file_size)
    node = runtime.Node('bag_test_full_disk')
    publisher = node.create_publisher(get_message('sensor_msgs/msg/JointState'),
                                      '/joint_states', 10)
    diagnostics = []
    node.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                             '/diagnostics', diagnostics.append, 10)
    sent = []

    def tick():
        publisher.publish(big_joint_state(len(sent), node.get_clock().now().to_msg()))
        sent.append(len(sent))

    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    wait_for_matched_recorder(recorder)
    timer = node.create_timer(0.01, tick)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and not bag_errors(diagnostics):
        executor.spin_for(0.1)
    timer.cancel()
    executor.spin_for(1.5)  # the ERROR again, once a second
    recorder.send_signal(signal.SIGINT)
    stdout, stderr = recorder.communicate(timeout=15)
    node.destroy_node()
    errors = bag_errors(diagnostics)
    assert len(errors) >= 2, (stdout, stderr)
    assert str(bag / 'limited_0.mcap') in errors[0].message
    assert 'File too large' in errors[0].message
    assert recorder.returncode == 1, stderr
    assert 'Traceback' not in stderr
    logged = [line for line in (stdout + stderr).splitlines() if 'ERROR' in line]
    assert len(logged) == 1 and 'File too large' in logged[0], stdout + stderr
    kept = indices_in(bag)
    assert kept and kept == list(range(kept[0], kept[0] + len(kept)))
    report = inspect_bag(bag).report
    assert report['complete'] and report['metadata_check']['matches']
    assert report['message_count'] == len(kept) < len(sent)
