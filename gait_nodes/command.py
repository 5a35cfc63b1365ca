"""Send a gait command and/or a velocity to footstep_planner and print its answer.

``python -m gait_nodes.command key=value ... [--vel VX VY WZ] [--timeout S] [--applied]``

Each ``key=value`` becomes one key of the /gait/command JSON object; values are read as JSON where
they can be (``step_length_m=0.3`` is a number, ``gait=trot`` a string). The command carries an
``id`` (this host, process and a random part, unless ``id=...`` is given), by which its answers
on /gait/command_status are known. It is published once footstep_planner's subscription is
matched (a DDS reader that joins late would miss an earlier sample), and again, with the same
id, only if no answer came within ``RESEND_S``: the planner applies an id once and answers a
repeat with the decision it made. ``--vel`` publishes a geometry_msgs/Twist on /cmd_vel. The
answer is printed as one JSON line: the decision on the command (accepted or rejected, with
when it takes effect), with ``--applied`` the second answer when it took
effect, and for ``--vel`` the velocity the planner reports on /diagnostics.

Exit status: 0 accepted, 1 rejected, 2 bad command line or no answer within
``--timeout``.
"""

from __future__ import annotations

import json
import math
import os
import socket
import sys
import uuid

from gait_nodes.cli import ArgumentParser, add_runtime_argument, fail, split_args
from gait_nodes.errors import ArgumentError, GaitNodesError
from gait_nodes.interfaces import get_message
from gait_nodes.runtime import Node

PROG = 'python -m gait_nodes.command'
#: Seconds without an answer before the command is sent again (same id: applied once).
RESEND_S = 2.0
#: Seconds between re-publications of a twist while no report of it has come.
REPUBLISH_S = 0.5
#: Default seconds to wait for an answer. The decision comes once the change is planned, and a
#: switch to a gait not walked before searches its fastest walk first: RoboSimian's switch to
#: the ZMP crawl was answered 2.7-5.7 s after it was sent beside a busy process (the tool
#: returns as soon as the answer comes; 5 s printed "no answer" for commands then applied).
DEFAULT_TIMEOUT_S = 15.0
#: States of a decision on a command (the first answer); 'applied' comes after 'accepted'.
DECISIONS = ('accepted', 'rejected', 'superseded')
PLANNER_STATUS_PREFIX = 'footstep_planner: '
#: The planner's status that answers a velocity (requested and applied twist).
VELOCITY_STATUS = PLANNER_STATUS_PREFIX + 'velocity'


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


def new_command_id() -> str:
    """An id no other command has: this host, this process and 8 random hex digits."""
    return f'{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:8]}'


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(',') if v != '']


class GaitCommandClient(Node):
    """Publishes one command and/or twist and collects footstep_planner's answers.

    Args:
        command: The JSON object to send on /gait/command (an ``id`` is added unless it has
            one), or None.
        velocity: (vx, vy, wz) to send on /cmd_vel, or None.
        wait_applied: Wait for the answer that an accepted command took effect too.
    """

    def __init__(self, command: dict | None, velocity: tuple[float, float, float] | None,
                 wait_applied: bool = False):
        super().__init__('gait_command', use_global_arguments=False)
        self.command_id = None
        if command is not None:
            self.command_id = str(command.get('id') or new_command_id())
            command = {'id': self.command_id, **command}
        self.command_text = json.dumps(command) if command is not None else None
        self.velocity = velocity
        self.wait_applied = wait_applied
        self.status: dict | None = None
        self.applied: dict | None = None
        self.sent = 0
        self.velocity_report: dict | None = None
        string, twist = get_message('std_msgs/msg/String'), get_message('geometry_msgs/msg/Twist')
        self.command_publisher = self.create_publisher(string, 'gait/command', 10)
        self.velocity_publisher = self.create_publisher(twist, 'cmd_vel', 10)
        self.create_subscription(string, 'gait/command_status', self.on_status, 10)
        self.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics', self.on_diagnostics, 10)

    @property
    def answered(self) -> bool:
        """Whether every answer expected has come."""
        command_done = self.command_text is None or self.status is not None and (
            not self.wait_applied or not self.status.get('accepted')
            or self.applied is not None)
        return command_done and (self.velocity is None or self.velocity_report is not None)

    def publish_command(self) -> bool:
        """Send the command if the planner's subscription is matched; True if sent."""
        if self.command_text is None or self.status is not None \
                or self.command_publisher.get_subscription_count() == 0:
            return False
        self.command_publisher.publish(get_message('std_msgs/msg/String')(
            data=self.command_text))
        self.sent += 1
        return True

    def publish(self) -> None:
        """Send the twist while it is unreported."""
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
        if not isinstance(status, dict) or status.get('id') != self.command_id:
            return
        if status.get('state') in DECISIONS and self.status is None:
            self.status = status
        elif status.get('state') == 'applied':
            self.applied = status
            if self.status is None:  # (the decision was missed: the applied answer implies it)
                self.status = {**status, 'state': 'accepted'}

    def on_diagnostics(self, msg) -> None:
        """Keep footstep_planner's report of the velocity we sent."""
        if self.velocity is None or self.velocity_report is not None:
            return
        for status in msg.status:
            # The planner's answer to a velocity, not its once-a-second state (which says the
            # twist asked for at once, and the one walked until the new one is planned).
            if status.name != VELOCITY_STATUS:
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
        next_publish_ns = next_command_ns = start_ns
        while not self.answered:
            now_ns = clock.now().nanoseconds
            if now_ns - start_ns >= timeout_s * 1e9:
                return False
            if now_ns >= next_command_ns and self.publish_command():
                next_command_ns = now_ns + int(RESEND_S * 1e9)
            if now_ns >= next_publish_ns:
                self.publish()
                next_publish_ns = now_ns + int(REPUBLISH_S * 1e9)
            executor.spin_for(0.02)
        return True

    def result(self) -> dict:
        """What to print: the command status and/or the velocity report."""
        result = {}
        if self.status is not None:
            result.update(self.status)
        if self.applied is not None:
            result['applied'] = self.applied
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
    parser.add_argument('--timeout', type=float, default=DEFAULT_TIMEOUT_S,
                        help=f'seconds to wait for the answer (default {DEFAULT_TIMEOUT_S:g})')
    parser.add_argument('--applied', action='store_true',
                        help='also wait for the answer that the accepted command took effect')
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
        client = GaitCommandClient(command, tuple(options.vel) if options.vel else None,
                                   options.applied)
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
        if client.status is not None and client.applied is None and options.applied:
            missing.append("/gait/command_status (the 'applied' answer; the command was "
                           f"{client.status.get('state')})")
        print(f'{PROG}: error: no answer from footstep_planner on {", ".join(missing)} within '
              f'{options.timeout:g} s', file=sys.stderr)
        return 2
    print(json.dumps(client.result()))
    return 0 if client.status is None or client.status.get('accepted') else 1


if __name__ == '__main__':
    sys.exit(main())
