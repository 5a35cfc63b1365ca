"""Bag speed: recorder throughput (against the raw rosbags writer), inspect time per million.

Run from the repository root::

    .venv/bin/python bench/bags.py [--messages N] [--repeats R] [--dds-seconds S]

The message mix is what a gait graph records: a 28-joint JointState at 200 Hz and a 200-pose
nav_msgs/Path (the ZMP reference window) at 50 Hz, i.e. 80 % / 20 %, pre-serialized once.

1. Writer: our BagWriter (zstd chunks, 0.5 s flush period, as the recorder runs it) against the
   rosbags rosbag2 MCAP writer given the same bytes, alternated ``--repeats`` times; medians.
2. Recorder node, in-process: a publisher node and the Recorder node in the inproc runtime, the
   whole subscription -> bag path; messages per second of wall time.
3. Recorder node over DDS: a separate publisher process writing the mix as fast as it can over
   loopback, the recorder process recording; recorded messages per second.
4. Inspect: ``inspect_bag`` (topic statistics plus decoding of every gait topic) on a bag of the
   mix; seconds per million messages.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from gait_nodes.bag.writer import BagWriter  # noqa: E402
from gait_nodes.interfaces import get_message, serialize_message  # noqa: E402
from gait_nodes.runtime.qos import QoSProfile, offered_qos_yaml  # noqa: E402

JOINTS = [f'limb{i}_joint{j}' for i in range(4) for j in range(7)]
TOPICS = {'/joint_states': 'sensor_msgs/msg/JointState',
          '/gait/zmp_reference': 'nav_msgs/msg/Path'}


def joint_state(k: int):
    """A 28-joint JointState."""
    msg = get_message('sensor_msgs/msg/JointState')()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(k * 5_000_000, 1_000_000_000)
    msg.name = list(JOINTS)
    msg.position = [0.01 * k + j for j in range(28)]
    msg.velocity = [0.5] * 28
    return msg


def zmp_path(k: int):
    """A 200-pose ZMP reference Path."""
    msg = get_message('nav_msgs/msg/Path')()
    msg.header.frame_id = 'odom'
    pose_type = get_message('geometry_msgs/msg/PoseStamped')
    poses = []
    for i in range(200):
        pose = pose_type()
        pose.header.frame_id = 'odom'
        pose.header.stamp.sec, pose.header.stamp.nanosec = divmod((k + i) * 10_000_000,
                                                                  1_000_000_000)
        pose.pose.position.x = 0.001 * (k + i)
        pose.pose.orientation.w = 1.0
        poses.append(pose)
    msg.poses = poses
    return msg


def mix(count: int) -> list[tuple[str, int, bytes]]:
    """``count`` messages: 4 JointState then 1 Path, repeated, 5 ms apart."""
    joint_bytes = [serialize_message(joint_state(k)) for k in range(8)]
    path_bytes = [serialize_message(zmp_path(k)) for k in range(4)]
    out = []
    for k in range(count):
        stamp = 1_700_000_000_000_000_000 + k * 4_000_000
        if k % 5 == 4:
            out.append(('/gait/zmp_reference', stamp, path_bytes[k % 4]))
        else:
            out.append(('/joint_states', stamp, joint_bytes[k % 8]))
    return out


def write_ours(path: Path, messages) -> float:
    """Seconds for our BagWriter to write ``messages``."""
    start = time.perf_counter()
    with BagWriter(path, flush_period_s=0.5) as writer:
        for topic, type_name in TOPICS.items():
            writer.add_topic(topic, type_name, [offered_qos_yaml(QoSProfile())])
        for topic, stamp, data in messages:
            writer.write(topic, data, stamp)
    return time.perf_counter() - start


def write_rosbags(path: Path, messages) -> float:
    """Seconds for rosbags' rosbag2 MCAP writer to write ``messages``."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    start = time.perf_counter()
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {topic: writer.add_connection(topic, type_name, typestore=typestore)
                       for topic, type_name in TOPICS.items()}
        for topic, stamp, data in messages:
            writer.write(connections[topic], stamp, data)
    return time.perf_counter() - start


def bench_writers(messages, repeats: int, folder: Path) -> None:
    """Both writers side by side, alternated, medians."""
    ours, theirs = [], []
    for r in range(repeats):
        ours.append(write_ours(folder / f'ours_{r}', messages))
        theirs.append(write_rosbags(folder / f'rosbags_{r}', messages))
    n = len(messages)
    ours_rate = n / statistics.median(ours)
    theirs_rate = n / statistics.median(theirs)
    size_ours = sum(f.stat().st_size for f in (folder / 'ours_0').glob('*.mcap'))
    size_theirs = sum(f.stat().st_size for f in (folder / 'rosbags_0').glob('*.mcap'))
    print(f'writer, {n} messages (80 % JointState, 20 % Path), median of {repeats}:')
    print(f'  gait_nodes BagWriter: {ours_rate:12,.0f} msg/s   file {size_ours / 1e6:7.1f} MB')
    print(f'  rosbags Writer      : {theirs_rate:12,.0f} msg/s   file {size_theirs / 1e6:7.1f} MB')
    print(f'  ratio ours / rosbags: {ours_rate / theirs_rate:.2f}')


def bench_recorder_inproc(count: int, folder: Path) -> None:
    """The Recorder node fed by a publisher node in the inproc runtime."""
    from gait_nodes import runtime
    from gait_nodes.recorder import Recorder

    messages = [(joint_state(k), zmp_path(k)) for k in range(4)]
    runtime.init(args=[], runtime='inproc')
    try:
        recorder = Recorder(output=str(folder / 'inproc'), topics=dict(TOPICS))
        source = runtime.Node('source')
        joints = source.create_publisher(get_message(TOPICS['/joint_states']), '/joint_states',
                                         10)
        paths = source.create_publisher(get_message(TOPICS['/gait/zmp_reference']),
                                         '/gait/zmp_reference', 10)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(recorder)
        executor.add_node(source)
        start = time.perf_counter()
        for k in range(count):
            if k % 5 == 4:
                paths.publish(messages[k % 4][1])
            else:
                joints.publish(messages[k % 4][0])
            if k % 100 == 99:
                executor.spin_for(0.0)
        executor.spin_for(0.0)
        elapsed = time.perf_counter() - start
        recorder.destroy_node()
        # Counted once the bag is closed: the writer counts a topic's messages as it appends
        # them to the chunk, in batches, so a count taken before close misses the last batch.
        recorded = recorder.writer.message_count
    finally:
        runtime.shutdown()
    print(f'recorder node, inproc runtime: {recorded / elapsed:12,.0f} msg/s '
          f'({recorded} of {count} recorded)')


PUBLISHER = """\
    import sys, time
    from gait_nodes import runtime
    from gait_nodes.interfaces import get_message
    sys.path.insert(0, {bench!r})
    import bags
    runtime.init(args=[])
    node = runtime.Node('bench_publisher')
    qos = runtime.QoSProfile(depth=1000)
    joints = node.create_publisher(get_message('sensor_msgs/msg/JointState'), '/joint_states', qos)
    paths = node.create_publisher(get_message('nav_msgs/msg/Path'), '/gait/zmp_reference', qos)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    executor.spin_for(2.0)
    messages = bags.mix(1000)
    sent, deadline = 0, time.monotonic() + float(sys.argv[1])
    while time.monotonic() < deadline:
        for topic, _, data in messages:
            (paths if topic == '/gait/zmp_reference' else joints).publish(data)
        sent += len(messages)
    print(sent / float(sys.argv[1]), flush=True)
    executor.spin_for(1.0)
    runtime.shutdown()
    """


def bench_recorder_dds(seconds: float, folder: Path) -> None:
    """A publisher process and the recorder process over loopback DDS."""
    from gait_nodes.bag.reader import BagReader

    env = dict(os.environ, PYTHONPATH=str(REPO), GAIT_NODES_RUNTIME='dds',
               GAIT_NODES_DDS_LOCALHOST='1', ROS_DOMAIN_ID='231')
    env.pop('CYCLONEDDS_URI', None)
    script = folder / 'publisher.py'
    script.write_text(textwrap.dedent(PUBLISHER.format(bench=str(REPO / 'bench'))))
    bag = folder / 'dds'
    recorder = subprocess.Popen([sys.executable, '-m', 'gait_nodes.recorder', '-o', str(bag),
                                 '-t', *TOPICS], env=env, stderr=subprocess.DEVNULL)
    time.sleep(1.0)
    publisher = subprocess.run([sys.executable, str(script), str(seconds)], env=env,
                               capture_output=True, text=True, timeout=seconds + 60)
    recorder.send_signal(signal.SIGINT)
    recorder.wait(timeout=30)
    sent_rate = float(publisher.stdout.strip().splitlines()[-1])
    stamps = [t for _, t, _, _ in BagReader(bag).messages()]
    rate = (len(stamps) - 1) / ((max(stamps) - min(stamps)) * 1e-9)
    print(f'recorder process over DDS (loopback): {rate:12,.0f} msg/s recorded '
          f'({len(stamps)} messages; the publisher offered {sent_rate:,.0f} msg/s)')


def bench_inspect(messages, folder: Path) -> None:
    """Reading and full inspection of the bag written by ``bench_writers``."""
    from gait_nodes.bag.analysis import inspect_bag
    from gait_nodes.bag.reader import BagReader

    bag = folder / 'ours_0'
    start = time.perf_counter()
    for _ in BagReader(bag).messages():
        pass
    scan = time.perf_counter() - start
    start = time.perf_counter()
    inspect_bag(bag)
    full = time.perf_counter() - start
    per_million = 1e6 / len(messages)
    print(f'inspect, {len(messages)} messages: read {scan * per_million:.2f} s per million, '
          f'full gait inspect (every message decoded) {full * per_million:.2f} s per million')


def main() -> None:
    """Run the benchmarks and print their figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--messages', type=int, default=100_000)
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--dds-seconds', type=float, default=5.0)
    options = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix='gait_bench_bags_'))
    try:
        messages = mix(options.messages)
        bench_writers(messages, options.repeats, folder)
        bench_recorder_inproc(min(options.messages, 50_000), folder)
        if options.dds_seconds > 0:
            bench_recorder_dds(options.dds_seconds, folder)
        bench_inspect(messages, folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == '__main__':
    main()
