"""The pure helpers of bench/cpu.py: /proc parsing, stream rates, nominal rates from parameters."""

import importlib.util
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from gait_nodes.bag.writer import BagWriter
from gait_nodes.contract import FootstepPlan
from gait_nodes.interfaces import get_message, serialize_message
from gait_nodes.markers import footsteps_markers
from gait_nodes.paths import node_defaults
from gait_nodes.runtime.qos import QoSProfile, offered_qos_yaml

_SPEC = importlib.util.spec_from_file_location(
    'bench_cpu', Path(__file__).resolve().parent.parent / 'bench' / 'cpu.py')
cpu = importlib.util.module_from_spec(_SPEC)
sys.modules[_SPEC.name] = cpu  # its dataclasses look their module up
_SPEC.loader.exec_module(cpu)


def test_proc_stat_fields_are_counted_from_the_last_parenthesis():
    # A command name may hold spaces and parentheses (proc(5)); ppid, utime, stime follow it.
    line = '4242 (py (x) 1) S 17 4242 4242 0 -1 4194560 100 0 0 0 123 45 6 7 20 0 1 0 99'
    assert cpu.parse_proc_stat(line) == (17, 123, 45)


def test_proc_stat_refuses_other_text():
    with pytest.raises(ValueError):
        cpu.parse_proc_stat('no parentheses here 1 2 3')
    with pytest.raises(ValueError):
        cpu.parse_proc_stat('1 (short) S 2 3')


@pytest.mark.skipif(not Path('/proc/self/stat').exists(), reason='needs Linux /proc')
def test_own_cpu_time_matches_the_kernel_accounting():
    sum(i * i for i in range(2_000_000))  # some CPU to measure
    ppid, utime, stime = cpu.parse_proc_stat(Path('/proc/self/stat').read_text())
    times = os.times()
    assert ppid == os.getppid()
    tick = 1.0 / os.sysconf('SC_CLK_TCK')
    assert (utime + stime) * tick == pytest.approx(times.user + times.system, abs=3 * tick)


def test_stream_rate_counts_intervals_inside_the_window():
    period_ns = 5_000_000  # 200 Hz
    stamps = [i * period_ns for i in range(1000)]
    # Messages outside the window do not count; the rate is (n - 1) / (last - first).
    assert cpu.stream_rate_hz(stamps, 100 * period_ns, 900 * period_ns) == pytest.approx(200.0)
    # One late message in every ten: 9 of 10 periods at 5 ms, one gap of 10 ms.
    late = [t for i, t in enumerate(stamps) if i % 10 != 5]
    assert cpu.stream_rate_hz(late, 0, stamps[-1]) == pytest.approx(200.0 * 899 / 999, rel=1e-3)
    assert cpu.stream_rate_hz([1, 2, 3], 10, 20) is None
    assert cpu.deviation_percent(196.0, 200.0) == pytest.approx(-2.0)
    assert cpu.deviation_percent(None, 200.0) is None


def test_nominal_rates_follow_the_node_parameters():
    defaults = {name: node_defaults(name) for name in
                ('footstep_planner', 'com_preview_controller', 'whole_body_ik',
                 'kinematic_simulator')}
    rates = cpu.nominal_rates(defaults)
    simulator = defaults['kinematic_simulator']
    assert rates['/gait/zmp_reference'] == defaults['footstep_planner']['rate_hz']
    assert rates['/joint_commands'] == defaults['whole_body_ik']['rate_hz']
    for topic in cpu.SIMULATOR_TOPICS:
        assert rates[topic] == simulator['rate_hz']
    assert rates['/gait/markers'] == min(simulator['markers_rate_hz'], simulator['rate_hz'])
    # The COM reference: every publish_period_s when the controller has it, else every dt_s.
    com = dict(defaults['com_preview_controller'])
    com.pop('publish_period_s', None)
    com['dt_s'] = 0.01
    assert cpu.nominal_rates({'com_preview_controller': com})['/gait/com_reference'] == \
        pytest.approx(100.0)
    com['publish_period_s'] = 0.05
    assert cpu.nominal_rates({'com_preview_controller': com})['/gait/com_reference'] == \
        pytest.approx(20.0)
    # /tf: the simulator's base pose every tick, robot_state_publisher's links at its rate.
    links = node_defaults('robot_state_publisher')
    with_links = cpu.nominal_rates({**defaults, 'robot_state_publisher': links})
    assert with_links['/tf'] == simulator['rate_hz'] + links['publish_frequency']
    every = cpu.nominal_rates({**defaults, 'robot_state_publisher': {'publish_frequency': 0.0}})
    assert every['/tf'] == 2 * simulator['rate_hz']
    # Settings sent to every node override the parameters a node has, and only those.
    overridden = cpu.nominal_rates(defaults, {'rate_hz': 100.0, 'publish_markers': False})
    assert overridden['/joint_states'] == 100.0
    assert '/gait/markers' not in overridden


def test_the_markers_rate_is_the_simulators_stream(tmp_path):
    """/gait/markers' plan and swing markers come at no set rate: the bench leaves them out."""
    marker_array = get_message('visualization_msgs/msg/MarkerArray')
    simulator = marker_array(markers=[get_message('visualization_msgs/msg/Marker')(ns='gait')])
    plan = FootstepPlan(0, ('foot',), np.array([0.0]), np.zeros((1, 1, 3)), np.zeros((1, 1)))
    period_ns = 50_000_000  # 20 Hz
    with BagWriter(tmp_path / 'bag') as writer:
        writer.add_topic('/gait/markers', 'visualization_msgs/msg/MarkerArray',
                         [offered_qos_yaml(QoSProfile())])
        for k in range(41):
            writer.write('/gait/markers', serialize_message(simulator), k * period_ns)
            if k % 7 == 3:  # a new plan, between two of the simulator's
                writer.write('/gait/markers', serialize_message(
                    footsteps_markers(plan, k * period_ns + 1, 0.05)), k * period_ns + 1)
    result = cpu.GraphRun('dds', window_ns=(0, 40 * period_ns))
    cpu.read_bag(result, tmp_path / 'bag')
    assert result.problem is None
    assert result.rates_hz['/gait/markers'] == pytest.approx(20.0)


def test_pause_reports_and_json_summary():
    statuses = [(1, 'footstep_planner: walk', 1, 'paused: whole_body_ik stale; holding'),
                (2, 'footstep_planner: walk', 0, 'walking'),
                (3, 'whole_body_ik: inputs', 1, 'paused')]
    assert cpu.pause_reports(statuses) == [1]
    text = '[INFO] node up {not json}\n{\n "a": 1,\n "b": {"c": 2}\n}\ntrailing\n'
    assert cpu.last_json_object(text) == {'a': 1, 'b': {'c': 2}}
    assert cpu.last_json_object('no object') is None
