"""Named walks for ``python -m gait_nodes run --scenario NAME``.

Each names a robot, gait settings, and the velocity and gait commands a user would send while
the robot walks.

A scenario's settings go to every node as a ``/**`` params file; its timed commands are published
by the launcher on /cmd_vel and /gait/command, exactly as ``python -m gait_nodes.command`` or
``ros2 topic pub`` would, so the nodes cannot tell a scenario from a person.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from gait_nodes.errors import ArgumentError


@dataclass(frozen=True)
class TimedCommand:
    """One command, ``at_s`` seconds after every node is up.

    Attributes:
        at_s: When to send it [s].
        velocity: (vx [m/s], vy [m/s], wz [rad/s]) for /cmd_vel, or None.
        command: JSON text for /gait/command (valid or deliberately not), or None.
    """

    at_s: float
    velocity: tuple[float, float, float] | None = None
    command: str | None = None


@dataclass(frozen=True)
class Scenario:
    """A walk: robot, settings for every node, commands, default duration."""

    name: str
    description: str
    robot: str
    settings: dict = field(default_factory=dict)
    commands: tuple[TimedCommand, ...] = ()
    duration_s: float = 20.0


def _vel(at_s: float, vx: float, vy: float = 0.0, wz: float = 0.0) -> TimedCommand:
    return TimedCommand(at_s, velocity=(vx, vy, wz))


def _cmd(at_s: float, text_or_object) -> TimedCommand:
    text = text_or_object if isinstance(text_or_object, str) else json.dumps(text_or_object)
    return TimedCommand(at_s, command=text)


SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    # The thesis' optimal crawl, 8.54 ft/min (0.043 m/s), asked: the planner walks the fastest
    # rhythm the 1 rad/s joint limit allows this ZMP-based crawl, its own optimal stride.
    Scenario('robosimian_crawl',
             'RoboSimian, crawl, preview-control COM, value-table swing',
             'robosimian', {'gait': 'crawl', 'swing': 'value_table', 'com_method': 'preview',
                            'timing': 'joint_limit'},
             (_vel(0.0, 0.043),), 40.0),
    # Thesis eq. (2) walked: the body still while a foot swings the value table's path at the
    # limb's own speed (0.06 m lift, the thesis' best), moving only with every foot down.
    Scenario('robosimian_static_crawl',
             'RoboSimian, static crawl (body still under each value-table swing), 0.06 m lift',
             'robosimian', {'gait': 'static_crawl', 'swing': 'value_table',
                            'com_method': 'preview', 'timing': 'joint_limit',
                            'step_height_m': 0.06},
             (_vel(0.0, 0.043),), 40.0),
    Scenario('robosimian_gait_switch',
             'RoboSimian crawl switched to the static crawl while it walks, and back',
             'robosimian', {'gait': 'crawl', 'swing': 'value_table', 'com_method': 'preview',
                            'timing': 'joint_limit'},
             (_vel(0.0, 0.043), _cmd(3.0, {'gait': 'static_crawl'}),
              _cmd(21.0, {'gait': 'crawl'})), 32.0),
    Scenario('robosimian_crawl_polynomial',
             'the same crawl with a polynomial swing, to compare speeds',
             'robosimian', {'gait': 'crawl', 'swing': 'polynomial', 'com_method': 'preview',
                            'timing': 'joint_limit'},
             (_vel(0.0, 0.043),), 40.0),
    Scenario('biped_walk',
             'small humanoid on flat ground: start, walk (Lucy\'s sixth-order swing), stop',
             'biped', {'gait': 'biped', 'swing': 'polynomial', 'com_method': 'preview',
                       'step_height_m': 0.1, 'step_period_s': 1.5, 'duty_factor': 0.72},
             (_vel(0.0, 0.1), _vel(10.0, 0.0)), 21.0),
    # Stride 0.3 m = tread: every other footstep climbs a stair (Lucy's step height delta), and
    # the footholds fall 0.075 m before and after the risers, outside their keep-out zones
    # (foot radius + the swing's toe distance, which the 0.18 m via height keeps short). 0.08 m
    # stairs walk too, but the closing step's swing then puts an ankle on its joint limit.
    Scenario('biped_stairs',
             'small humanoid: start, walk up three 0.05 m stairs (Lucy\'s stairway: footholds '
             'on the treads, the COM climbing with the support), stop on the landing',
             'biped', {'gait': 'biped', 'swing': 'polynomial', 'com_method': 'preview',
                       'step_height_m': 0.14, 'step_period_s': 2.0, 'duty_factor': 0.72,
                       'stairs_start_x_m': 0.45, 'stairs_rise_m': 0.05, 'stairs_tread_m': 0.3,
                       'stairs_count': 3},
             (_vel(0.0, 0.05), _vel(30.0, 0.0)), 40.0),
    Scenario('go2_trot',
             'Unitree Go2 (example-robot-data), trot with sway compensation',
             'go2', {'gait': 'trot', 'swing': 'polynomial', 'com_method': 'sway',
                     'step_length_m': 0.2, 'step_period_s': 0.5, 'duty_factor': 0.6},
             (_vel(0.0, 0.1),)),
    Scenario('online',
             'RoboSimian crawl changed while it walks: step length, velocity, gait, and '
             'invalid commands that must be rejected',
             'robosimian', {'gait': 'crawl', 'swing': 'polynomial', 'com_method': 'preview',
                            'timing': 'joint_limit'},
             (_vel(0.0, 0.05),
              _cmd(4.0, {'step_length_m': 0.2}),
              _cmd(5.0, '{"step_length_m": 0.3'),            # invalid JSON
              _cmd(5.5, {'step_lenght_m': 0.3}),             # unknown key
              _cmd(6.0, {'step_period_s': -1.0}),            # negative duration
              _cmd(6.5, {'duty_factor': 0.5}),               # below a crawl's 0.75
              _cmd(7.0, {'gait': 'biped'}),                  # not a quadruped's gait
              _vel(8.0, 0.08, 0.0, 0.05),
              _cmd(18.0, {'gait': 'trot', 'duty_factor': 0.6}),
              _vel(28.0, 0.0)), 38.0),
)}



def _every_3_s(first: TimedCommand, *commands) -> tuple[TimedCommand, ...]:
    """``first`` at 0 s, then each of ``commands`` 3 s after the one before.

    Each is a dict (a /gait/command) or a tuple (a /cmd_vel twist).
    """
    timed = [first]
    for k, command in enumerate(commands, start=1):
        timed.append(_vel(3.0 * k, *command) if isinstance(command, tuple)
                     else _cmd(3.0 * k, command))
    return tuple(timed)


# Gait commands while walking, one every 3 s from 0 to 84 s (issue 25, bench/commands.py): every
# kind a user sends (step height, length, period, duty factor, gait and swing, speed and
# direction, stop and go), each one the robot can walk: every one must be accepted, walked from a
# step boundary and applied once. The walk lasts until the last has taken effect (RoboSimian's
# steps take up to 8 s). The planner's refusals are tested apart (test_online_commands).
COMMAND_SCENARIOS = (
    Scenario('robosimian_commands',
             'RoboSimian crawl commanded every 3 s: height, length, period, duty factor, swing, '
             'speed, direction, stop and go; a trot it cannot reach refused',
             'robosimian', {'gait': 'crawl', 'swing': 'value_table', 'com_method': 'preview',
                            'timing': 'joint_limit'},
             _every_3_s(_vel(0.0, 0.043),
                        {'step_height_m': 0.08}, {'step_length_m': 0.16}, (0.02,),
                        {'swing': 'polynomial'}, {'step_height_m': 0.1}, (0.0, 0.01),
                        {'swing': 'value_table'}, (0.02, 0.0, 0.02), {'step_length_m': 0.2},
                        (0.0,), (0.043,), {'zmp_margin_m': 0.02}, {'step_period_s': 3.0},
                        {'duty_factor': 0.9}, (-0.01,), {'step_length_m': 0.12},
                        (0.03, 0.0, -0.02), {'swing': 'polynomial', 'step_height_m': 0.08},
                        (0.0,), (0.043,), {'swing': 'value_table', 'step_height_m': 0.1},
                        {'zmp_margin_m': 0.01}, {'step_length_m': 0.2}, (0.03, 0.005),
                        {'step_period_s': 2.0, 'duty_factor': 0.85}, (0.043,),
                        {'step_height_m': 0.08}, {'gait': 'crawl', 'step_height_m': 0.1}),
             105.0),
    Scenario('biped_commands',
             'small humanoid commanded every 3 s: step period, duty factor, height, length, '
             'speed, direction, turn, stop and go',
             'biped', {'gait': 'biped', 'swing': 'polynomial', 'com_method': 'preview',
                       'step_height_m': 0.1, 'step_period_s': 1.5, 'duty_factor': 0.72},
             _every_3_s(_vel(0.0, 0.1),
                        {'step_period_s': 1.7}, {'step_height_m': 0.08}, (0.15,),
                        {'duty_factor': 0.8}, {'step_length_m': 0.2}, (0.05, 0.0, 0.1),
                        {'step_period_s': 1.8}, (0.1, 0.02), {'step_height_m': 0.1},
                        (0.0,), (0.1,), {'zmp_margin_m': 0.02}, {'step_length_m': 0.24},
                        (-0.05,), {'step_period_s': 2.0}, (0.1, -0.03),
                        {'zmp_margin_m': 0.01}, (0.0, 0.0, 0.1), {'step_height_m': 0.09},
                        (0.12,), {'duty_factor': 0.75}, (0.0,), (0.1,),
                        {'step_period_s': 1.5}, (0.08, 0.0, -0.1), {'step_length_m': 0.25},
                        (0.1,), {'step_height_m': 0.08, 'duty_factor': 0.72}),
             90.0),
    Scenario('go2_commands',
             'Unitree Go2 trot commanded every 3 s: period, duty factor, height, length, gait '
             '(trot and crawl), speed, direction, stop and go',
             'go2', {'gait': 'trot', 'swing': 'polynomial', 'com_method': 'sway',
                     'step_length_m': 0.2, 'step_period_s': 0.5, 'duty_factor': 0.6},
             _every_3_s(_vel(0.0, 0.1),
                        {'step_period_s': 0.6}, {'step_height_m': 0.06}, (0.15,),
                        {'duty_factor': 0.65}, {'step_length_m': 0.15}, (0.05, 0.03),
                        {'gait': 'crawl', 'duty_factor': 0.8, 'step_period_s': 0.8},
                        (0.05,), (0.05, 0.0, 0.2), (0.0,), (0.05,),
                        {'gait': 'trot', 'duty_factor': 0.6, 'step_period_s': 0.5},
                        (0.1,), {'step_height_m': 0.08}, (0.1, -0.03), (-0.05,),
                        {'step_period_s': 0.45}, (0.0, 0.0, 0.3), {'step_length_m': 0.2},
                        (0.12,), {'duty_factor': 0.6}, (0.0,), (0.1,),
                        {'zmp_margin_m': 0.01}, (0.08, 0.0, -0.2),
                        {'step_period_s': 0.5}, (0.1,), {'step_height_m': 0.06}),
             90.0),
)
SCENARIOS.update({s.name: s for s in COMMAND_SCENARIOS})

DEFAULT_SCENARIO = 'robosimian_static_crawl'


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``; ArgumentError listing the names otherwise."""
    if name not in SCENARIOS:
        raise ArgumentError(f'unknown scenario {name!r}; scenarios: {", ".join(SCENARIOS)}')
    return SCENARIOS[name]


def with_id(text: str, command_id: str) -> str:
    """``text`` with ``"id": command_id`` first if it is a JSON object without one.

    Anything else (a deliberately bad command) goes out as written.
    """
    try:
        values = json.loads(text)
    except ValueError:
        return text
    if not isinstance(values, dict) or 'id' in values:
        return text
    return json.dumps({'id': command_id, **values})


class CommandDriver:
    """Publishes a scenario's timed commands from a node, and keeps /cmd_vel streaming.

    /cmd_vel is re-sent every ``repeat_period_s`` (as a teleop does), so a planner that
    joins late still gets the current velocity; a gait command waits until /gait/command has
    a subscriber, so it is not sent into the void.

    Args:
        node: The launcher's node.
        commands: The scenario's commands.
        repeat_period_s: /cmd_vel repetition period [s].
    """

    def __init__(self, node, commands: tuple[TimedCommand, ...], repeat_period_s: float = 0.5):
        from gait_nodes.interfaces import get_message

        self._node = node
        self._twist = get_message('geometry_msgs/msg/Twist')
        self._string = get_message('std_msgs/msg/String')
        self._vel_publisher = node.create_publisher(self._twist, 'cmd_vel', 10)
        self._command_publisher = node.create_publisher(self._string, 'gait/command', 10)
        self._pending = sorted(commands, key=lambda c: c.at_s)
        self._velocity: tuple[float, float, float] | None = None
        self._repeat_ns = int(repeat_period_s * 1e9)
        self._last_vel_ns: int | None = None  # when /cmd_vel was last sent
        self._start_ns: int | None = None
        self.statuses: list[dict] = []
        node.create_subscription(self._string, 'gait/command_status', self._on_status, 1000)
        self._sent = 0
        node.create_timer(0.02, self._tick)

    def start(self) -> None:
        """Count scenario time from now."""
        self._start_ns = self._node.get_clock().now().nanoseconds

    def _on_status(self, msg) -> None:
        try:
            self.statuses.append(json.loads(msg.data))
        except json.JSONDecodeError:
            self.statuses.append({'accepted': None, 'reason': 'unreadable status'})

    def _tick(self) -> None:
        if self._start_ns is None:
            return
        now_ns = self._node.get_clock().now().nanoseconds
        elapsed_s = (now_ns - self._start_ns) * 1e-9
        while self._pending and self._pending[0].at_s <= elapsed_s:
            command = self._pending[0]
            if command.command is not None:
                if self._command_publisher.get_subscription_count() == 0:
                    break  # the planner is not matched yet: try again next tick
                self._sent += 1
                self._command_publisher.publish(self._string(data=with_id(
                    command.command, f'scenario-{self._sent}')))
            if command.velocity is not None:
                self._velocity = command.velocity
                self._last_vel_ns = None  # sent at once
            self._pending.pop(0)
        if self._velocity is not None and (self._last_vel_ns is None
                                           or now_ns - self._last_vel_ns >= self._repeat_ns):
            twist = self._twist()
            twist.linear.x, twist.linear.y, twist.angular.z = (float(v) for v in self._velocity)
            self._vel_publisher.publish(twist)
            self._last_vel_ns = now_ns
