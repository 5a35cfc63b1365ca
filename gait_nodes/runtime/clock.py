"""Time, Duration and Clock with rclpy's shapes; integer nanoseconds throughout."""

from __future__ import annotations

import enum
import time as _time

from gait_nodes.errors import GaitNodesError

NS_PER_S = 1_000_000_000


class ClockType(enum.IntEnum):
    """Clock kinds, numbered as rcl's."""

    UNINITIALIZED = 0
    ROS_TIME = 1
    SYSTEM_TIME = 2
    STEADY_TIME = 3


class Duration:
    """A span of time in integer nanoseconds."""

    __slots__ = ('nanoseconds',)

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0):
        self.nanoseconds = int(round(seconds * NS_PER_S)) + int(nanoseconds)

    def to_msg(self):
        """``builtin_interfaces/msg/Duration``."""
        from gait_nodes.interfaces import get_message

        sec, nanosec = divmod(self.nanoseconds, NS_PER_S)
        return get_message('builtin_interfaces/msg/Duration')(sec=sec, nanosec=nanosec)

    @classmethod
    def from_msg(cls, msg) -> Duration:
        """From ``builtin_interfaces/msg/Duration``."""
        return cls(nanoseconds=msg.sec * NS_PER_S + msg.nanosec)

    def __eq__(self, other):
        return isinstance(other, Duration) and self.nanoseconds == other.nanoseconds

    def __lt__(self, other):
        return self.nanoseconds < other.nanoseconds

    def __repr__(self):
        return f'Duration(nanoseconds={self.nanoseconds})'


class Time:
    """A point in time of one clock type, integer nanoseconds since its epoch."""

    __slots__ = ('nanoseconds', 'clock_type')

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0,
                 clock_type: ClockType = ClockType.SYSTEM_TIME):
        total = int(round(seconds * NS_PER_S)) + int(nanoseconds)
        if total < 0:
            raise GaitNodesError(f'time must be >= 0 ns, got {total}')
        self.nanoseconds = total
        self.clock_type = clock_type

    def seconds_nanoseconds(self) -> tuple[int, int]:
        """``(sec, nanosec)``."""
        return divmod(self.nanoseconds, NS_PER_S)

    def to_msg(self):
        """``builtin_interfaces/msg/Time``."""
        from gait_nodes.interfaces import get_message

        sec, nanosec = divmod(self.nanoseconds, NS_PER_S)
        return get_message('builtin_interfaces/msg/Time')(sec=sec, nanosec=nanosec)

    @classmethod
    def from_msg(cls, msg, clock_type: ClockType = ClockType.ROS_TIME) -> Time:
        """From ``builtin_interfaces/msg/Time``."""
        return cls(nanoseconds=msg.sec * NS_PER_S + msg.nanosec, clock_type=clock_type)

    def __add__(self, other: Duration) -> Time:
        return Time(nanoseconds=self.nanoseconds + other.nanoseconds, clock_type=self.clock_type)

    def __sub__(self, other):
        if isinstance(other, Time):
            return Duration(nanoseconds=self.nanoseconds - other.nanoseconds)
        return Time(nanoseconds=self.nanoseconds - other.nanoseconds, clock_type=self.clock_type)

    def __eq__(self, other):
        return isinstance(other, Time) and self.nanoseconds == other.nanoseconds

    def __lt__(self, other):
        return self.nanoseconds < other.nanoseconds

    def __le__(self, other):
        return self.nanoseconds <= other.nanoseconds

    def __repr__(self):
        return f'Time(nanoseconds={self.nanoseconds}, clock_type={self.clock_type.name})'


class Clock:
    """A node's clock: system time, or ROS time driven by /clock or by the inproc executor."""

    def __init__(self, *, clock_type: ClockType = ClockType.SYSTEM_TIME, source=None):
        self.clock_type = clock_type
        self._source = source  # callable -> int ns, or None for the wall clock

    @property
    def ros_time_is_active(self) -> bool:
        """Whether time comes from a simulated source."""
        return self._source is not None

    def set_source(self, source) -> None:
        """Take time from ``source()`` (ns), or from the wall clock when None."""
        self._source = source

    def now_ns(self) -> int:
        """Current time in integer nanoseconds."""
        if self._source is not None:
            return self._source()
        if self.clock_type == ClockType.STEADY_TIME:
            return _time.monotonic_ns()
        return _time.time_ns()

    def now(self) -> Time:
        """Current time."""
        source = self._source  # now_ns() inline for a simulated source (many calls per tick)
        nanoseconds = source() if source is not None else self.now_ns()
        if type(nanoseconds) is not int or nanoseconds < 0:
            return Time(nanoseconds=nanoseconds, clock_type=self.clock_type)
        # The common case without Time.__init__'s conversions (called many times per tick).
        time = object.__new__(Time)
        time.nanoseconds = nanoseconds
        time.clock_type = self.clock_type
        return time
