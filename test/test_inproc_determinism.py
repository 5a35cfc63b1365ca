"""The whole inproc graph is deterministic: two runs record byte-identical messages.

The speed work on the inproc runtime and on the nodes' message code (cached message classes,
fewer Python objects per message, messages handed over by reference, the recorder's fast path)
must not change what the graph computes; this is the check that it did not.
"""

from __future__ import annotations

from pathlib import Path

from mcap.reader import make_reader

from gait_nodes import graph, runtime
from gait_nodes.interfaces import get_message

#: Simulated seconds per run: the first swings start within it.
DURATION_S = 4.0


def _recorded(bag: Path) -> list[tuple[str, int, int, bytes]]:
    """(topic, log time [ns], sequence, CDR bytes) of every message, in file order."""
    (mcap_path,) = bag.glob('*.mcap')
    with open(mcap_path, 'rb') as stream:
        return [(channel.topic, message.log_time, message.sequence, bytes(message.data))
                for _, channel, message in make_reader(stream).iter_messages(
                    log_time_order=False)]


def _run_graph(bag: Path) -> list[tuple[str, int, int, bytes]]:
    """Every installed contract node and the recorder, crawling for DURATION_S."""
    runtime.init(args=['test'], runtime='inproc', signal_handlers=False)
    try:
        twist = get_message('geometry_msgs/msg/Twist')
        driver = runtime.Node('velocity_command', use_global_arguments=False)
        publisher = driver.create_publisher(twist, '/cmd_vel', 10)

        def command() -> None:
            msg = twist()
            msg.linear.x = 0.05
            publisher.publish(msg)

        driver.create_timer(0.5, command)
        executor = runtime.SingleThreadedExecutor()
        for name in graph.available_nodes():
            executor.add_node(graph.load_class(graph.NODES[name])())
        executor.add_node(graph.load_class(graph.RECORDER)(output=str(bag)))
        executor.add_node(driver)
        executor.spin_for(DURATION_S)
    finally:
        runtime.shutdown()
    return _recorded(bag)


def test_two_inproc_runs_record_identical_bytes(tmp_path):
    first = _run_graph(tmp_path / 'first')
    second = _run_graph(tmp_path / 'second')
    topics = {topic for topic, *_ in first}
    for topic in ('/gait/footsteps', '/gait/zmp_reference', '/gait/com_reference',
                  '/joint_commands', '/joint_states', '/tf', '/gait/zmp', '/gait/com',
                  '/gait/support_polygon', '/tf_static', '/robot_description'):
        assert topic in topics, f'{topic} was not recorded'
    assert len(first) == len(second)
    for k, (a, b) in enumerate(zip(first, second, strict=True)):
        assert a == b, f'message {k} differs: {a[:3]} vs {b[:3]}'
