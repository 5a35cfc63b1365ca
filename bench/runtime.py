#!/usr/bin/env python3
"""Runtime benchmark of gait_nodes: dds latency/overhead against raw cyclonedds, inproc dispatch.

    python bench/runtime.py [--seconds 10] [--rate 1000] [--joints 28] [--reps 3] [--quick]
                            [--profile] [--localhost]

1. ``sensor_msgs/JointState`` (N joints: names, positions, velocities, efforts; header stamp = send
   time in ns) from one process to another over the gait_nodes ``dds`` runtime at ``--rate`` for
   ``--seconds``: delivered fraction, one-way latency (receiver ``time.time_ns()`` minus header
   stamp) median and p99, achieved send rate, receiver CPU per message.
2. The same through raw cyclonedds-python (hand-written ``@final`` IdlStruct types with the ROS 2
   type names, DataWriter / DataReader + WaitSet, same pacing, same QoS: reliable, keep-last 10,
   volatile), and the ours/raw ratios (target <= 1.3x).
3. inproc dispatch rate: one publisher node publishing bursts from a timer callback, one
   subscriber node; delivered messages per wall-clock second for std_msgs/String and JointState
   (target >= 100k/s).

Sender and receiver are separate processes (``--role ...`` runs one of them; the receiver starts
first, the sender waits until the subscription is matched, then 0.5 s more). Every two-process run
uses its own random ROS domain. Each measurement is repeated ``--reps`` times (1 with ``--quick``)
and the medians are printed. Figures only: no thresholds are asserted.
"""

import argparse
import json
import os
import random
import statistics
import subprocess
import sys
import time
from array import array
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

TOPIC = '/joint_states'
DEPTH = 10
MAX_BLOCKING_NS = 100_000_000  # what gait_nodes.runtime.dds sets for reliable writers
GRACE_AFTER_MATCH_S = 0.5
NS = 1_000_000_000

TARGET_RATIO = 1.3
TARGET_INPROC_RATE = 100_000
TARGET_DELIVERED = 1.0


# --------------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------------

def percentile(values, q: float) -> float:
    """Nearest-rank-interpolated percentile (q in 0..100) of a non-empty sequence."""
    data = sorted(values)
    if not data:
        return float('nan')
    k = (len(data) - 1) * q / 100.0
    lo = int(k)
    hi = min(lo + 1, len(data) - 1)
    return data[lo] + (data[hi] - data[lo]) * (k - lo)


def median(values):
    """Median of the values that are not None (nan when none)."""
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else float('nan')


def emit(result: dict) -> None:
    """Child processes report one JSON line on stdout, prefixed so it is easy to find."""
    print('RESULT ' + json.dumps(result), flush=True)


def joint_payload(joints: int):
    """Names, positions, velocities and efforts of ``joints`` joints."""
    names = [f'joint_{i:02d}_{side}' for i, side in
             zip(range(joints), ['hip_yaw', 'hip_roll', 'hip_pitch', 'knee', 'ankle_pitch',
                                 'ankle_roll', 'shoulder', 'elbow'] * joints, strict=False)]
    position = [0.01 * i for i in range(joints)]
    velocity = [0.1 * i for i in range(joints)]
    effort = [1.0 * i for i in range(joints)]
    return names, position, velocity, effort


def measure_sleep_overshoot(samples: int = 200, request_s: float = 0.0005) -> dict:
    """How late ``time.sleep(request)`` returns on this machine [s]."""
    perf = time.perf_counter
    over = []
    for _ in range(samples):
        t = perf()
        time.sleep(request_s)
        over.append(perf() - t - request_s)
    return {'p50': percentile(over, 50), 'p99': percentile(over, 99), 'max': max(over)}


def make_sender(joint_state_type, header_type, payload, publish):
    """``send(i)``: build a JointState stamped with the send time [ns] and hand it to ``publish``.

    The same builder serves our runtime and raw cyclonedds, so both sides do identical work.
    """
    names, position, velocity, effort = payload
    time_ns = time.time_ns

    def send(i):
        msg = joint_state_type(header=header_type(frame_id='base_link'), name=names,
                               position=position, velocity=velocity, effort=effort)
        now = time_ns()
        stamp = msg.header.stamp
        stamp.sec = now // NS
        stamp.nanosec = now % NS
        publish(msg)

    return send


def paced_loop(send, rate: float, seconds: float, spin_margin_s: float) -> dict:
    """Call ``send(i)`` on a ``1/rate`` grid of time.perf_counter for ``seconds``.

    Sleeps until ``spin_margin_s`` before each deadline, then busy-waits. When late it catches up
    (no skipped slots), so exactly rate*seconds messages are sent.
    """
    perf = time.perf_counter
    sleep = time.sleep
    period = 1.0 / rate
    count = int(round(rate * seconds))
    stamps = array('d', bytes(8 * count))
    send_time = array('d', bytes(8 * count))
    cpu0 = time.process_time()
    t0 = perf() + 0.001
    deadline = t0
    for i in range(count):
        while True:
            remaining = deadline - perf()
            if remaining <= 0:
                break
            if remaining > spin_margin_s:
                sleep(remaining - spin_margin_s)
        stamps[i] = start = perf()
        send(i)
        send_time[i] = perf() - start
        deadline += period
    end = perf()
    cpu = time.process_time() - cpu0
    intervals = [stamps[i + 1] - stamps[i] for i in range(count - 1)]
    lateness = [stamps[i] - (t0 + i * period) for i in range(count)]
    elapsed = stamps[-1] - stamps[0] if count > 1 else float('nan')
    return {
        'sent': count,
        'send_rate': (count - 1) / elapsed if count > 1 else float('nan'),
        'interval_p50_us': percentile(intervals, 50) * 1e6,
        'interval_p99_us': percentile(intervals, 99) * 1e6,
        'late_p99_us': percentile(lateness, 99) * 1e6,
        'late_max_us': max(lateness) * 1e6,
        'sender_cpu_us_per_msg': cpu / count * 1e6,  # includes the busy-wait: not comparable
        'send_call_us': percentile(send_time, 50) * 1e6,  # build + stamp + publish, wall
        'wall_s': end - t0,
    }


class LatencyRecorder:
    """Receiver-side bookkeeping shared by both receivers (identical cost on both sides)."""

    def __init__(self, expected: int):
        self.lat = array('q')
        self.count = 0
        self.first_cpu = None
        self.first_thread_cpu = None
        self.last_cpu = 0.0
        self.last_thread_cpu = 0.0
        self.last_rx_ns = 0
        self.expected = expected

    def on_stamp(self, sec: int, nanosec: int) -> None:
        """Record one received message stamped ``sec.nanosec`` (wall clock of the sender)."""
        now = time.time_ns()
        self.lat.append(now - (sec * NS + nanosec))
        self.count += 1
        self.last_rx_ns = now
        if self.first_cpu is None:
            self.first_cpu = time.process_time()
            self.first_thread_cpu = time.thread_time()
        else:
            self.last_cpu = time.process_time()
            self.last_thread_cpu = time.thread_time()

    def done(self, idle_s: float) -> bool:
        """All expected messages seen, or none for ``idle_s`` after the first one."""
        if not self.count:
            return False
        if self.expected and self.count >= self.expected:
            return True
        return time.time_ns() - self.last_rx_ns > idle_s * NS

    def result(self) -> dict:
        """Summary figures of this receiver."""
        lat = self.lat
        n = self.count
        res = {'received': n}
        if n:
            res.update({
                'lat_p50_us': percentile(lat, 50) / 1e3,
                'lat_p99_us': percentile(lat, 99) / 1e3,
                'lat_mean_us': sum(lat) / n / 1e3,
                'lat_max_us': max(lat) / 1e3,
            })
        if n > 1:
            res['recv_cpu_us_per_msg'] = (self.last_cpu - self.first_cpu) / (n - 1) * 1e6
            res['recv_thread_cpu_us_per_msg'] = \
                (self.last_thread_cpu - self.first_thread_cpu) / (n - 1) * 1e6
        return res


def maybe_profile(args):
    """A running cProfile.Profile when --profile is given, else None."""
    if not args.profile:
        return None
    import cProfile

    profiler = cProfile.Profile()
    profiler.enable()
    return profiler


def dump_profile(profiler, label: str) -> None:
    """Print the top functions by own time on stderr (the parent shows them)."""
    if profiler is None:
        return
    import io
    import pstats

    profiler.disable()
    out = io.StringIO()
    stats = pstats.Stats(profiler, stream=out).sort_stats('tottime')
    stats.print_stats(18)
    print(f'PROFILE {label}\n' + out.getvalue(), file=sys.stderr, flush=True)


# --------------------------------------------------------------------------------------------
# gait_nodes runtime roles
# --------------------------------------------------------------------------------------------

def role_ours_recv(args) -> None:
    """Receiver over the gait_nodes dds runtime: Node, subscription, executor.spin_once."""
    from gait_nodes import runtime
    from gait_nodes.interfaces import sensor_msgs

    runtime.init(args=[], runtime='dds', domain_id=args.domain, signal_handlers=False)
    rec = LatencyRecorder(args.expected)
    on_stamp = rec.on_stamp

    def callback(msg):
        stamp = msg.header.stamp
        on_stamp(stamp.sec, stamp.nanosec)

    node = runtime.Node('bench_receiver')
    node.create_subscription(sensor_msgs.msg.JointState, TOPIC, callback, DEPTH)
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    print('READY', flush=True)
    deadline = time.monotonic() + args.deadline
    profiler = maybe_profile(args)
    while time.monotonic() < deadline and not rec.done(args.idle):
        executor.spin_once(timeout_sec=0.1)
    dump_profile(profiler, 'ours receiver')
    emit(rec.result())
    runtime.shutdown()


def role_ours_send(args) -> None:
    """Sender over the gait_nodes dds runtime: Node, publisher, paced publish()."""
    from gait_nodes import runtime
    from gait_nodes.interfaces import sensor_msgs, std_msgs

    runtime.init(args=[], runtime='dds', domain_id=args.domain, signal_handlers=False)
    JointState = sensor_msgs.msg.JointState
    Header = std_msgs.msg.Header
    node = runtime.Node('bench_sender')
    publisher = node.create_publisher(JointState, TOPIC, DEPTH)
    matched = wait_for_match(publisher.get_subscription_count, args.min_matched)
    names, position, velocity, effort = joint_payload(args.joints)
    overshoot = measure_sleep_overshoot()
    margin = spin_margin(overshoot)
    send = make_sender(JointState, Header, (names, position, velocity, effort),
                       publisher.publish)

    profiler = maybe_profile(args)
    result = paced_loop(send, args.rate, args.seconds, margin)
    dump_profile(profiler, 'ours sender')
    result.update({'matched_after_s': matched, 'sleep_overshoot_us': overshoot['p50'] * 1e6,
                   'sleep_overshoot_p99_us': overshoot['p99'] * 1e6,
                   'spin_margin_us': margin * 1e6,
                   'msg_bytes': len(JointState(name=names, position=position, velocity=velocity,
                                               effort=effort,
                                               header=Header(frame_id='base_link')).serialize())})
    time.sleep(0.3)  # let the reliable writer flush before the participant goes away
    emit(result)
    runtime.shutdown()


def role_timer_probe(args) -> None:
    """Achieved rate and jitter of a 1/rate runtime timer (dds runtime, executor spin_for)."""
    from gait_nodes import runtime

    runtime.init(args=[], runtime='dds', domain_id=args.domain, signal_handlers=False)
    node = runtime.Node('bench_timer_probe')
    stamps = array('d')
    perf = time.perf_counter
    node.create_timer(1.0 / args.rate, lambda: stamps.append(perf()))
    executor = runtime.SingleThreadedExecutor()
    executor.add_node(node)
    cpu0 = time.process_time()
    executor.spin_for(args.seconds)
    cpu = time.process_time() - cpu0
    intervals = [stamps[i + 1] - stamps[i] for i in range(len(stamps) - 1)]
    emit({
        'calls': len(stamps),
        'rate': (len(stamps) - 1) / (stamps[-1] - stamps[0]) if len(stamps) > 1 else 0.0,
        'interval_p50_us': percentile(intervals, 50) * 1e6,
        'interval_p99_us': percentile(intervals, 99) * 1e6,
        'interval_max_us': max(intervals) * 1e6 if intervals else float('nan'),
        'cpu_fraction': cpu / args.seconds,
    })
    runtime.shutdown()


# --------------------------------------------------------------------------------------------
# raw cyclonedds-python roles
# --------------------------------------------------------------------------------------------

def raw_types():
    """Hand-written JointState and its dependencies, named as ROS 2 names them on the wire."""
    from dataclasses import dataclass, field

    import cyclonedds.idl.types as t
    from cyclonedds.idl import IdlStruct
    from cyclonedds.idl.annotations import final

    @final
    @dataclass
    class Time(IdlStruct, typename='builtin_interfaces::msg::dds_::Time_'):
        sec: t.int32 = 0
        nanosec: t.uint32 = 0

    @final
    @dataclass
    class Header(IdlStruct, typename='std_msgs::msg::dds_::Header_'):
        stamp: Time = field(default_factory=Time)
        frame_id: str = ''

    @final
    @dataclass
    class JointState(IdlStruct, typename='sensor_msgs::msg::dds_::JointState_'):
        header: Header = field(default_factory=Header)
        name: t.sequence[str] = field(default_factory=list)
        position: t.sequence[t.float64] = field(default_factory=list)
        velocity: t.sequence[t.float64] = field(default_factory=list)
        effort: t.sequence[t.float64] = field(default_factory=list)

    return Time, Header, JointState


def message_types(args):
    """(Header, JointState) for the raw roles: hand-written, or gait_nodes' generated classes."""
    if args.types == 'generated':
        from gait_nodes.interfaces import generated_class

        return (generated_class('std_msgs/msg/Header'),
                generated_class('sensor_msgs/msg/JointState'))
    _, header, joint_state = raw_types()
    return header, joint_state


def raw_qos():
    """The QoS gait_nodes' dds runtime gives a depth-10 profile (reliable, keep-last, volatile)."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    return Qos(Policy.Reliability.Reliable(duration(nanoseconds=MAX_BLOCKING_NS)),
               Policy.History.KeepLast(DEPTH), Policy.Durability.Volatile)


def role_raw_recv(args) -> None:
    """Receiver over raw cyclonedds-python: DataReader, ReadCondition, WaitSet, take()."""
    from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState, WaitSet
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    _, JointState = message_types(args)
    participant = DomainParticipant(args.domain)
    topic = Topic(participant, 'rt' + TOPIC, JointState)
    reader = DataReader(participant, topic, qos=raw_qos())
    condition = ReadCondition(reader, SampleState.Any | ViewState.Any | InstanceState.Any)
    waitset = WaitSet(participant)
    waitset.attach(condition)
    rec = LatencyRecorder(args.expected)
    on_stamp = rec.on_stamp
    slice_ns = duration(milliseconds=50)
    print('READY', flush=True)
    deadline = time.monotonic() + args.deadline
    profiler = maybe_profile(args)
    while time.monotonic() < deadline and not rec.done(args.idle):
        waitset.wait(slice_ns)
        for sample in reader.take(N=DEPTH):
            if not sample.sample_info.valid_data:
                continue
            stamp = sample.header.stamp
            on_stamp(stamp.sec, stamp.nanosec)
    dump_profile(profiler, 'raw receiver')
    emit(rec.result())


def role_raw_send(args) -> None:
    """Sender over raw cyclonedds-python: DataWriter, paced write()."""
    from cyclonedds.domain import DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic

    Header, JointState = message_types(args)
    participant = DomainParticipant(args.domain)
    topic = Topic(participant, 'rt' + TOPIC, JointState)
    writer = DataWriter(participant, topic, qos=raw_qos())
    matched = wait_for_match(lambda: len(writer.get_matched_subscriptions()),
                             args.min_matched)
    names, position, velocity, effort = joint_payload(args.joints)
    overshoot = measure_sleep_overshoot()
    margin = spin_margin(overshoot)
    send = make_sender(JointState, Header, (names, position, velocity, effort), writer.write)

    profiler = maybe_profile(args)
    result = paced_loop(send, args.rate, args.seconds, margin)
    dump_profile(profiler, 'raw sender')
    result.update({'matched_after_s': matched, 'sleep_overshoot_us': overshoot['p50'] * 1e6,
                   'sleep_overshoot_p99_us': overshoot['p99'] * 1e6,
                   'spin_margin_us': margin * 1e6})
    time.sleep(0.3)
    emit(result)


def wait_for_match(count_fn, need: int = 1, timeout_s: float = 15.0) -> float:
    """Seconds until ``count_fn() >= need`` (-1 on timeout), then a grace period."""
    start = time.monotonic()
    while count_fn() < need:
        if time.monotonic() - start > timeout_s:
            return -1.0
        time.sleep(0.005)
    matched = time.monotonic() - start
    time.sleep(GRACE_AFTER_MATCH_S)
    return matched


def spin_margin(overshoot: dict) -> float:
    """Busy-wait window before each deadline: median sleep overshoot + 100 us, in [0.1, 0.4] ms.

    The median, not the p99: on a loaded machine the p99 overshoot is a scheduling stall that a
    longer busy-wait cannot prevent, only pay for with a whole core (which the receiver needs).
    The grid (see paced_loop) keeps the average rate exact anyway.
    """
    return min(max(overshoot['p50'] + 100e-6, 100e-6), 400e-6)


# --------------------------------------------------------------------------------------------
# inproc dispatch
# --------------------------------------------------------------------------------------------

def role_inproc(args) -> None:
    """Dispatch rate of the inproc runtime for std_msgs/String and JointState."""
    from gait_nodes import runtime
    from gait_nodes.interfaces import sensor_msgs, std_msgs

    names, position, velocity, effort = joint_payload(args.joints)
    cases = [
        ('std_msgs/String', std_msgs.msg.String, lambda: std_msgs.msg.String(data='hello gait')),
        ('sensor_msgs/JointState', sensor_msgs.msg.JointState,
         lambda: sensor_msgs.msg.JointState(name=names, position=position, velocity=velocity,
                                            effort=effort)),
    ]
    results = {}
    profiler = maybe_profile(args)
    for label, msg_type, make in cases:
        results[label] = inproc_case(runtime, msg_type, make, args.messages, args.burst)
    dump_profile(profiler, 'inproc')
    emit(results)


def inproc_case(runtime, msg_type, make, messages: int, burst: int) -> dict:
    """One publisher node (bursts from a 1 ms timer), one subscriber node; wall-clock rate."""
    runtime.init(args=[], runtime='inproc', signal_handlers=False)
    try:
        pub_node = runtime.Node('bench_inproc_pub')
        sub_node = runtime.Node('bench_inproc_sub')
        publisher = pub_node.create_publisher(msg_type, '/bench', 10)
        received = [0]

        def on_msg(msg):
            received[0] += 1

        sub_node.create_subscription(msg_type, '/bench', on_msg, 10)
        prebuilt = make()
        publish = publisher.publish
        sent = [0]
        limit = [0]

        def tick():
            n = min(burst, limit[0] - sent[0])
            for _ in range(n):
                publish(prebuilt)
            sent[0] += n

        pub_node.create_timer(0.001, tick)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(pub_node)
        executor.add_node(sub_node)
        # warm-up
        limit[0] = min(messages // 10, 5 * burst)
        while received[0] < limit[0]:
            executor.spin_once()
        sent[0] = received[0] = 0
        limit[0] = messages
        cpu0 = time.process_time()
        t0 = time.perf_counter()
        while received[0] < messages:
            executor.spin_once()
        wall = time.perf_counter() - t0
        cpu = time.process_time() - cpu0
        # publish only (no subscriber matched): where the time goes
        t1 = time.perf_counter()
        lone = pub_node.create_publisher(msg_type, '/nobody', 10).publish
        for _ in range(messages // 4):
            lone(prebuilt)
        publish_only = (messages // 4) / (time.perf_counter() - t1)
        return {'delivered': received[0], 'wall_s': wall, 'rate': received[0] / wall,
                'cpu_us_per_msg': cpu / received[0] * 1e6,
                'publish_only_rate': publish_only}
    finally:
        runtime.shutdown()


# --------------------------------------------------------------------------------------------
# orchestration
# --------------------------------------------------------------------------------------------

def child_env(args) -> dict:
    """Environment of the child processes: this checkout on PYTHONPATH, no ROS_DOMAIN_ID."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO), env.get('PYTHONPATH')]))
    env.pop('ROS_DOMAIN_ID', None)
    env['GAIT_NODES_RUNTIME'] = 'dds'
    if args.localhost and not env.get('CYCLONEDDS_URI'):
        env['CYCLONEDDS_URI'] = (REPO / 'gait_nodes/runtime/cyclonedds_localhost.xml').as_uri()
    return env


def child_cmd(role: str, args, **extra) -> list[str]:
    """Command line running this script in child role ``role``."""
    cmd = [sys.executable, str(Path(__file__).resolve()), '--role', role,
           '--seconds', str(args.seconds), '--rate', str(args.rate), '--joints', str(args.joints)]
    if args.profile:
        cmd.append('--profile')
    for key, value in extra.items():
        cmd += ['--' + key.replace('_', '-'), str(value)]
    return cmd


def parse_result(text: str, stderr: str, what: str) -> dict:
    """The RESULT line of a child's output."""
    for line in reversed(text.splitlines()):
        if line.startswith('RESULT '):
            return json.loads(line[len('RESULT '):])
    raise RuntimeError(f'{what}: no result\n--- stdout\n{text}\n--- stderr\n{stderr}')


def show_profiles(stderr: str) -> None:
    """Print the profile a child wrote on stderr."""
    if 'PROFILE ' in stderr:
        print(stderr[stderr.index('PROFILE '):])


def fresh_domain(used_domains: set) -> int:
    """A random ROS domain id not used before in this benchmark."""
    domain = random.choice([d for d in range(1, 233) if d not in used_domains])
    used_domains.add(domain)
    return domain


def run_pair(kind: str, args, used_domains: set) -> dict:
    """One sender/receiver run on a fresh random domain.

    ``kind``: 'ours' (gait_nodes dds runtime), 'raw' (cyclonedds-python, hand-written types) or
    'rawgen' (cyclonedds-python with gait_nodes' generated message classes).
    """
    domain = fresh_domain(used_domains)
    env = child_env(args)
    expected = int(round(args.rate * args.seconds))
    role = 'ours' if kind == 'ours' else 'raw'
    types = {'types': 'generated'} if kind == 'rawgen' else {}
    recv = subprocess.Popen(
        child_cmd(f'{role}-recv', args, domain=domain, expected=expected,
                  deadline=args.seconds + 40, **types),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = recv.stdout.readline()
        if line.strip() != 'READY':
            out, err = recv.communicate(timeout=10)
            raise RuntimeError(f'{kind} receiver did not start: {line}{out}\n{err}')
        send = subprocess.run(child_cmd(f'{role}-send', args, domain=domain, **types),
                              capture_output=True, text=True, env=env,
                              timeout=args.seconds * 3 + 60)
        sender = parse_result(send.stdout, send.stderr, f'{kind} sender')
        out, err = recv.communicate(timeout=args.seconds + 60)
        receiver = parse_result(out, err, f'{kind} receiver')
        if args.profile:
            show_profiles(send.stderr)
            show_profiles(err)
    finally:
        if recv.poll() is None:
            recv.kill()
            recv.wait()
    result = dict(sender)
    result.update(receiver)
    result['domain'] = domain
    result['delivered'] = receiver['received'] / sender['sent'] if sender['sent'] else 0.0
    return result


AB_KINDS = ('ours', 'raw', 'rawgen')


def run_ab(args, used_domains: set) -> dict:
    """Three receivers (ours, raw, raw + our CDR) at once on one domain, one ours sender.

    The receivers see the same messages at the same moments, so machine load hits all three
    alike: the fairest comparison of the receive path on a busy machine.
    """
    domain = fresh_domain(used_domains)
    env = child_env(args)
    expected = int(round(args.rate * args.seconds))
    receivers = {}
    try:
        for kind in AB_KINDS:
            role = 'ours' if kind == 'ours' else 'raw'
            types = {'types': 'generated'} if kind == 'rawgen' else {}
            receivers[kind] = subprocess.Popen(
                child_cmd(f'{role}-recv', args, domain=domain, expected=expected,
                          deadline=args.seconds + 40, **types),
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        for kind, proc in receivers.items():
            line = proc.stdout.readline()
            if line.strip() != 'READY':
                out, err = proc.communicate(timeout=10)
                raise RuntimeError(f'A/B {kind} receiver did not start: {line}{out}\n{err}')
        send = subprocess.run(child_cmd('ours-send', args, domain=domain,
                                        min_matched=len(AB_KINDS)),
                              capture_output=True, text=True, env=env,
                              timeout=args.seconds * 3 + 60)
        sender = parse_result(send.stdout, send.stderr, 'A/B sender')
        result = {'domain': domain, 'sent': sender['sent']}
        for kind, proc in receivers.items():
            out, err = proc.communicate(timeout=args.seconds + 60)
            result[kind] = parse_result(out, err, f'A/B {kind} receiver')
    finally:
        for proc in receivers.values():
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    return result


def run_timer_probe(args, used_domains: set) -> dict:
    """Run the runtime-timer probe in a child process."""
    domain = fresh_domain(used_domains)
    # a later --seconds wins in argparse: the probe runs at most 3 s
    proc = subprocess.run(child_cmd('timer-probe', args, domain=domain)
                          + ['--seconds', str(min(args.seconds, 3.0))],
                          capture_output=True, text=True, env=child_env(args), timeout=60)
    return parse_result(proc.stdout, proc.stderr, 'timer probe')


def run_inproc(args) -> dict:
    """Run the inproc dispatch measurement in a child process."""
    cmd = [sys.executable, str(Path(__file__).resolve()), '--role', 'inproc',
           '--joints', str(args.joints), '--messages', str(args.messages),
           '--burst', str(args.burst)]
    if args.profile:
        cmd.append('--profile')
    proc = subprocess.run(cmd, capture_output=True, text=True, env=child_env(args), timeout=600)
    if args.profile:
        show_profiles(proc.stderr)
    return parse_result(proc.stdout, proc.stderr, 'inproc')


def fmt(value, digits: int = 1) -> str:
    """Number with thousands separators, 'n/a' for None or nan."""
    if value is None or (isinstance(value, float) and value != value):
        return 'n/a'
    if isinstance(value, float):
        return f'{value:,.{digits}f}'
    return f'{value:,}'


def main(argv=None) -> None:
    """Parse the options; run one child role, or the whole benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--joints', type=int, default=28)
    parser.add_argument('--reps', type=int, default=None, help='repetitions (default 3, 1 quick)')
    parser.add_argument('--quick', action='store_true', help='1 repetition, 3 s, fewer messages')
    parser.add_argument('--profile', action='store_true',
                        help='cProfile the children (adds overhead; figures then not comparable)')
    parser.add_argument('--localhost', action='store_true',
                        help='loopback-only Cyclone config (unicast discovery on 127.0.0.1)')
    parser.add_argument('--messages', type=int, default=None, help='inproc messages per case')
    parser.add_argument('--burst', type=int, default=1000, help='inproc messages per timer call')
    parser.add_argument('--skip-dds', action='store_true')
    parser.add_argument('--skip-inproc', action='store_true')
    # child-process options
    parser.add_argument('--role', help=argparse.SUPPRESS)
    parser.add_argument('--domain', type=int, help=argparse.SUPPRESS)
    parser.add_argument('--expected', type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument('--deadline', type=float, default=60.0, help=argparse.SUPPRESS)
    parser.add_argument('--idle', type=float, default=2.0, help=argparse.SUPPRESS)
    parser.add_argument('--types', default='hand', help=argparse.SUPPRESS)
    parser.add_argument('--min-matched', type=int, default=1, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    roles = {'ours-recv': role_ours_recv, 'ours-send': role_ours_send,
             'raw-recv': role_raw_recv, 'raw-send': role_raw_send,
             'timer-probe': role_timer_probe, 'inproc': role_inproc}
    if args.role:
        roles[args.role](args)
        return

    if args.quick:
        args.seconds = min(args.seconds, 3.0)
    reps = args.reps or (1 if args.quick else 3)
    if args.messages is None:
        args.messages = 50_000 if args.quick else 200_000
    import platform
    from importlib import metadata

    config = 'loopback' if args.localhost else os.environ.get('CYCLONEDDS_URI') or 'default'
    print(f'gait_nodes runtime benchmark  python {platform.python_version()}  '
          f'cyclonedds-python {metadata.version("cyclonedds")}  '
          f'{os.cpu_count()} CPUs  {platform.machine()}')
    print(f'  load average {" ".join(f"{x:.2f}" for x in os.getloadavg())}')
    print(f'  JointState {args.joints} joints, {args.rate:g} Hz x {args.seconds:g} s, '
          f'{reps} repetition(s), QoS reliable keep-last {DEPTH} volatile, '
          f'cyclone config: {config}')
    if args.profile:
        print('  NOTE: --profile is on; timings include cProfile overhead')

    used: set = set()
    summary = {}
    if not args.skip_dds:
        probe = run_timer_probe(args, used)
        print(f'\n[pacing] runtime 1/{args.rate:g} s timer (dds executor, spin_for): '
              f'{fmt(probe["rate"])} calls/s, interval p50 {fmt(probe["interval_p50_us"])} us, '
              f'p99 {fmt(probe["interval_p99_us"])} us, max {fmt(probe["interval_max_us"])} us, '
              f'CPU {probe["cpu_fraction"] * 100:.0f}%')
        kinds = ('ours', 'raw', 'rawgen')
        runs = {kind: [] for kind in kinds}
        for rep in range(reps):
            for kind in kinds if rep % 2 == 0 else kinds[::-1]:
                r = run_pair(kind, args, used)
                runs[kind].append(r)
                print(f'[{kind:6s} rep {rep + 1}] domain {r["domain"]:3d}  '
                      f'delivered {r["received"]}/{r["sent"]} ({r["delivered"] * 100:.2f}%)  '
                      f'latency p50 {fmt(r.get("lat_p50_us"))} us  '
                      f'p99 {fmt(r.get("lat_p99_us"))} us  max {fmt(r.get("lat_max_us"))} us  '
                      f'send {fmt(r["send_rate"])} Hz  '
                      f'recv CPU {fmt(r.get("recv_cpu_us_per_msg"))} us/msg '
                      f'(main thread {fmt(r.get("recv_thread_cpu_us_per_msg"))})  '
                      f'send call {fmt(r["send_call_us"])} us', flush=True)
        first = runs['ours'][0]
        print(f'[pacing] hybrid sleep/busy-wait pacer (ours rep 1): sleep(0.5 ms) overshoot '
              f'p50 {fmt(first["sleep_overshoot_us"])} us '
              f'(p99 {fmt(first["sleep_overshoot_p99_us"])} us) -> busy-wait the last '
              f'{fmt(first["spin_margin_us"])} us; send interval p50 '
              f'{fmt(first["interval_p50_us"])} us p99 {fmt(first["interval_p99_us"])} us, '
              f'lateness p99 {fmt(first["late_p99_us"])} us; '
              f'message {first.get("msg_bytes")} B CDR')
        shortfall = 1 - probe['rate'] / args.rate
        verdict = 'is' if shortfall > 0.005 else 'is not'
        print(f'[pacing] -> the runtime timer {verdict} too coarse here '
              f'({shortfall * 100:.1f}% of periods lost: a timer late by more than one '
              f'period skips it); the pacer is used for all sends')
        keys = ['delivered', 'lat_p50_us', 'lat_p99_us', 'lat_max_us', 'send_rate',
                'recv_cpu_us_per_msg', 'recv_thread_cpu_us_per_msg', 'send_call_us']
        for kind in runs:
            summary[kind] = {k: median([r.get(k) for r in runs[kind]]) for k in keys}
        summary['probe'] = probe

        ab_runs = []
        for rep in range(reps):
            ab = run_ab(args, used)
            ab_runs.append(ab)
            print(f'[A/B    rep {rep + 1}] domain {ab["domain"]:3d}  one ours sender, three '
                  f'receivers on the same traffic:')
            for kind in AB_KINDS:
                r = ab[kind]
                print(f'    {kind:6s} received {r["received"]}/{ab["sent"]}  latency p50 '
                      f'{fmt(r.get("lat_p50_us"))} us  p99 {fmt(r.get("lat_p99_us"))} us  '
                      f'recv CPU {fmt(r.get("recv_cpu_us_per_msg"))} us/msg (main thread '
                      f'{fmt(r.get("recv_thread_cpu_us_per_msg"))})', flush=True)
        summary['ab'] = {
            kind: {k: median([ab[kind].get(k) for ab in ab_runs])
                   for k in ('lat_p50_us', 'lat_p99_us', 'recv_cpu_us_per_msg',
                             'recv_thread_cpu_us_per_msg')}
            for kind in AB_KINDS}

    if not args.skip_inproc:
        inproc_runs = [run_inproc(args) for _ in range(reps)]
        summary['inproc'] = {}
        for label in inproc_runs[0]:
            summary['inproc'][label] = {
                k: median([r[label][k] for r in inproc_runs])
                for k in ('rate', 'cpu_us_per_msg', 'publish_only_rate')}
            for i, r in enumerate(inproc_runs):
                print(f'[inproc rep {i + 1}] {label:24s} {r[label]["delivered"]:,} msgs in '
                      f'{r[label]["wall_s"]:.3f} s = {r[label]["rate"]:,.0f} msg/s '
                      f'(publish alone, no subscriber: {r[label]["publish_only_rate"]:,.0f}/s)')

    print_table(summary, args, reps)


def print_table(summary: dict, args, reps: int) -> None:
    """The compact summary table."""
    rows = []
    if 'ours' in summary:
        ours, raw, rawgen = summary['ours'], summary['raw'], summary['rawgen']

        def ratio(key, other):
            value = ours[key] / other[key] if other.get(key) else float('nan')
            return 'n/a' if value != value else f'{value:.2f}x'

        def row(label, key, target='', digits=1, with_ratio=True):
            return (label, fmt(ours[key], digits), fmt(raw[key], digits),
                    fmt(rawgen[key], digits), ratio(key, raw) if with_ratio else '',
                    ratio(key, rawgen) if with_ratio else '', target)

        rows += [
            ('delivered fraction', f'{ours["delivered"] * 100:.2f}%',
             f'{raw["delivered"] * 100:.2f}%', f'{rawgen["delivered"] * 100:.2f}%', '', '',
             f'{TARGET_DELIVERED * 100:.0f}%'),
            row('latency median [us]', 'lat_p50_us', f'ratio <= {TARGET_RATIO}x'),
            row('latency p99 [us]', 'lat_p99_us', f'ratio <= {TARGET_RATIO}x'),
            row('latency max [us]', 'lat_max_us'),
            row('send rate [Hz]', 'send_rate', f'{args.rate:g}', with_ratio=False),
            row('recv CPU/msg, process [us]', 'recv_cpu_us_per_msg', f'ratio <= {TARGET_RATIO}x'),
            row('recv CPU/msg, main thread [us]', 'recv_thread_cpu_us_per_msg'),
            row('send call (build+publish) [us]', 'send_call_us'),
            (f'runtime {1000 / args.rate:g} ms timer [calls/s]', fmt(summary['probe']['rate']),
             '', '', '', '', f'{args.rate:g}'),
        ]
    if 'ab' in summary:
        ab = summary['ab']

        def ab_row(label, key, target=''):
            ours, raw, rawgen = ab['ours'][key], ab['raw'][key], ab['rawgen'][key]
            return (label, fmt(ours), fmt(raw), fmt(rawgen),
                    f'{ours / raw:.2f}x' if raw else 'n/a',
                    f'{ours / rawgen:.2f}x' if rawgen else 'n/a', target)

        rows += [
            ab_row('A/B same traffic: latency median [us]', 'lat_p50_us',
                   f'ratio <= {TARGET_RATIO}x'),
            ab_row('A/B same traffic: latency p99 [us]', 'lat_p99_us',
                   f'ratio <= {TARGET_RATIO}x'),
            ab_row('A/B same traffic: recv CPU/msg [us]', 'recv_cpu_us_per_msg',
                   f'ratio <= {TARGET_RATIO}x'),
            ab_row('A/B same traffic: main thread [us]', 'recv_thread_cpu_us_per_msg'),
        ]
    for label, r in summary.get('inproc', {}).items():
        rows.append((f'inproc {label} [msg/s]', f'{r["rate"]:,.0f}', '', '', '', '',
                     f'>= {TARGET_INPROC_RATE:,}'))
    if not rows:
        return
    header = (f'metric (median of {reps})', 'gait_nodes', 'raw cdds', 'raw+our CDR',
              'ours/raw', 'ours/raw+CDR', 'target')
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    print('\n' + '  '.join(h.ljust(w) if i == 0 else h.rjust(w)
                           for i, (h, w) in enumerate(zip(header, widths, strict=True))))
    print('  '.join('-' * w for w in widths))
    for r in rows:
        print('  '.join(str(c).ljust(w) if i == 0 else str(c).rjust(w)
                        for i, (c, w) in enumerate(zip(r, widths, strict=True))))
    print('raw cdds = cyclonedds-python with hand-written IdlStruct types (its generic CDR '
          'codec); raw+our CDR = the same raw DataWriter/DataReader/WaitSet code with '
          "gait_nodes' generated message classes (isolates the runtime layer).")
    print(f'load average at end: {" ".join(f"{x:.2f}" for x in os.getloadavg())} '
          f'(other jobs on this machine disturb the tails)')

if __name__ == '__main__':
    main()
