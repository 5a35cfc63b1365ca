"""Send a gait command and/or a velocity to footstep_planner and print its answer.

``python -m gait_nodes.command key=value ... [--vel VX VY WZ] [--timeout S]``

Each ``key=value`` becomes one key of the /gait/command JSON object; values are read as JSON where
they can be (``step_length_m=0.3`` is a number, ``gait=trot`` a string). ``--vel`` publishes a
geometry_msgs/Twist on /cmd_vel. The command is published again every half second until
footstep_planner answers (a late-joining DDS reader misses the first sample); the answer is
printed as one JSON line: the /gait/command_status message, and for ``--vel`` the velocity the
planner reports on /diagnostics.

Exit status: 0 accepted, 1 rejected, 2 bad command line or no answer within ``--timeout``.
"""

from __future__ import annotations

import json
import math
import sys

from gait_nodes.cli import ArgumentParser, add_runtime_argument, fail, split_args
from gait_nodes.errors import ArgumentError, GaitNodesError
from gait_nodes.interfaces import get_message
from gait_nodes.runtime import Node

PROG = 'python -m gait_nodes.command'
#: Seconds between re-publications while no answer has come.
REPUBLISH_S = 0.5
PLANNER_STATUS_PREFIX = 'footstep_planner: '


def parse_assignments(items: list[str]) -> dict[str, object]:
    """``['step_length_m=0.3', 'gait=trot']`` -> ``{'step_length_m': 0.3, 'gait': 'trot'}``."""
    values: dict[str, object] = {}
    for item in items:
        key, sep, text = item.partition('=')
        if not sep or not key:
            raise ArgumentError(f'expected key=value, got {item!r}')
        if key in values:
            raise ArgumentError(f'{key} is given twice')
        try:
            values[key] = json.loads(text)
        except json.JSONDecodeError:
            values[key] = text
    return values


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(',') if v != '']


class GaitCommandClient(Node):
    """Publishes one command and/or twist and collects footstep_planner's answers.

    Args:
        command: The JSON object to send on /gait/command, or None.
        velocity: (vx, vy, wz) to send on /cmd_vel, or None.
    """

    def __init__(self, command: dict | None, velocity: tuple[float, float, float] | None):
        super().__init__('gait_command', use_global_arguments=False)
        self.command_text = json.dumps(command) if command is not None else None
        self.velocity = velocity
        self.status: dict | None = None
        self.velocity_report: dict | None = None
        string, twist = get_message('std_msgs/msg/String'), get_message('geometry_msgs/msg/Twist')
        self.command_publisher = self.create_publisher(string, '/gait/command', 10)
        self.velocity_publisher = self.create_publisher(twist, '/cmd_vel', 10)
        self.create_subscription(string, '/gait/command_status', self.on_status, 10)
        self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics', self.on_diagnostics, 10)

    @property
    def answered(self) -> bool:
        """Whether every answer expected has come."""
        return ((self.command_text is None or self.status is not None)
                and (self.velocity is None or self.velocity_report is not None))

    def publish(self) -> None:
        """Send what is still unanswered (the command first, so the twist meets its limits)."""
        if self.command_text is not None and self.status is None:
            self.command_publisher.publish(get_message('std_msgs/msg/String')(
                data=self.command_text))
        if self.velocity is not None and self.velocity_report is None:
            msg = get_message('geometry_msgs/msg/Twist')()
            msg.linear.x, msg.linear.y, msg.angular.z = self.velocity
            self.velocity_publisher.publish(msg)

    def on_status(self, msg) -> None:
        """Keep the status that answers our command."""
        try:
            status = json.loads(msg.data)
        except json.JSONDecodeError:
            return
        if isinstance(status, dict) and status.get('command') == self.command_text:
            self.status = status

    def on_diagnostics(self, msg) -> None:
        """Keep footstep_planner's report of the velocity we sent."""
        if self.velocity is None or self.velocity_report is not None:
            return
        for status in msg.status:
            if not status.name.startswith(PLANNER_STATUS_PREFIX):
                continue
            values = {item.key: item.value for item in status.values}
            if 'requested_twist' not in values:
                continue
            requested = _floats(values['requested_twist'])
            if len(requested) == 3 and all(
                    math.isclose(a, b, rel_tol=1e-5, abs_tol=1e-9)
                    for a, b in zip(requested, self.velocity, strict=True)):
                self.velocity_report = {
                    'requested': requested, 'applied': _floats(values.get('applied_twist', '')),
                    'message': status.message}

    def run(self, executor, timeout_s: float) -> bool:
        """Publish and spin ``executor`` until answered or ``timeout_s`` of ROS time passed."""
        clock = self.get_clock()
        start_ns = clock.now().nanoseconds
        next_publish_ns = start_ns
        while not self.answered:
            now_ns = clock.now().nanoseconds
            if now_ns - start_ns >= timeout_s * 1e9:
                return False
            if now_ns >= next_publish_ns:
                self.publish()
                next_publish_ns = now_ns + int(REPUBLISH_S * 1e9)
            executor.spin_for(0.05)
        return True

    def result(self) -> dict:
        """What to print: the command status and/or the velocity report."""
        result = {}
        if self.status is not None:
            result.update(self.status)
        if self.velocity_report is not None:
            result['velocity'] = self.velocity_report
        return result


def main(args: list[str] | None = None) -> int:
    """Entry point of ``python -m gait_nodes.command``."""
    from gait_nodes import runtime

    user, ros = split_args(args)
    parser = ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0])
    add_runtime_argument(parser)
    parser.add_argument('assignments', nargs='*', metavar='key=value',
                        help='gait parameters, e.g. step_length_m=0.3 gait=trot')
    parser.add_argument('--vel', nargs=3, type=float, metavar=('VX', 'VY', 'WZ'),
                        help='also publish this twist on /cmd_vel [m/s, m/s, rad/s]')
    parser.add_argument('--timeout', type=float, default=5.0,
                        help='seconds to wait for the answer (default 5)')
    options = parser.parse_args(user)
    try:
        command = parse_assignments(options.assignments) if options.assignments else None
        if command is None and options.vel is None:
            raise ArgumentError('nothing to send: give key=value pairs and/or --vel VX VY WZ')
        if options.vel is not None and not all(math.isfinite(v) for v in options.vel):
            raise ArgumentError(f'--vel needs finite numbers, got {options.vel}')
        if not (math.isfinite(options.timeout) and options.timeout > 0):
            raise ArgumentError(f'--timeout must be a positive number, got {options.timeout}')
        runtime.init(args=[PROG, *ros], runtime=options.runtime)
    except GaitNodesError as exc:
        return fail(PROG, exc)
    try:
        client = GaitCommandClient(command, tuple(options.vel) if options.vel else None)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(client)
        answered = client.run(executor, options.timeout)
    except GaitNodesError as exc:
        return fail(PROG, exc)
    except KeyboardInterrupt:
        return 2
    finally:
        runtime.shutdown()
    if not answered:
        missing = [name for name, value in (('/gait/command_status', client.status),
                                            ('/diagnostics velocity', client.velocity_report))
                   if value is None and (name.startswith('/gait') and command is not None
                                         or name.startswith('/diag') and options.vel)]
        print(f'{PROG}: error: no answer from footstep_planner on {", ".join(missing)} within '
              f'{options.timeout:g} s', file=sys.stderr)
        return 2
    print(json.dumps(client.result()))
    return 0 if client.status is None or client.status.get('accepted') else 1


if __name__ == '__main__':
    sys.exit(main())
