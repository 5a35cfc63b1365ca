"""Node loggers printing the way ROS 2 does: ``[LEVEL] [stamp] [name]: message`` on stderr."""

from __future__ import annotations

import sys
import time

LEVELS = {'debug': 10, 'info': 20, 'warn': 30, 'error': 40, 'fatal': 50}
_default_level = LEVELS['info']


def set_default_level(level: str) -> None:
    """Level of every logger of this process (``--log-level``)."""
    global _default_level
    _default_level = LEVELS[level]


class RcutilsLogger:
    """rclpy's logger interface: debug/info/warning/error/fatal with once, skip_first, throttle."""

    def __init__(self, name: str, clock=None):
        self.name = name
        self._clock = clock
        self._level: int | None = None
        self._once: set[tuple] = set()
        self._last: dict[tuple, int] = {}
        self._seen: set[tuple] = set()

    def get_child(self, name: str) -> RcutilsLogger:
        """Logger named ``<self>.<name>``."""
        return RcutilsLogger(f'{self.name}.{name}', self._clock)

    def set_level(self, level) -> None:
        """Minimum level, by name or number."""
        self._level = LEVELS[level] if isinstance(level, str) else int(level)

    def get_effective_level(self) -> int:
        """The level in force."""
        return self._level if self._level is not None else _default_level

    def is_enabled_for(self, level: str) -> bool:
        """Whether messages of ``level`` are printed."""
        return LEVELS[level] >= self.get_effective_level()

    def _log(self, level: str, message: str, once=False, skip_first=False,
             throttle_duration_sec=None, **_) -> bool:
        if not self.is_enabled_for(level):
            return False
        caller = sys._getframe(2)
        site = (caller.f_code.co_filename, caller.f_lineno)
        if once:
            if site in self._once:
                return False
            self._once.add(site)
        if skip_first and site not in self._seen:
            self._seen.add(site)
            return False
        now_ns = self._clock.now_ns() if self._clock is not None else time.time_ns()
        if throttle_duration_sec is not None:
            last = self._last.get(site)
            if last is not None and now_ns - last < throttle_duration_sec * 1e9:
                return False
            self._last[site] = now_ns
        stamp = f'{now_ns // 1_000_000_000}.{now_ns % 1_000_000_000:09d}'
        label = 'WARN' if level == 'warn' else level.upper()
        print(f'[{label}] [{stamp}] [{self.name}]: {message}', file=sys.stderr, flush=True)
        return True

    def debug(self, message, **kwargs) -> bool:
        """Log at DEBUG."""
        return self._log('debug', message, **kwargs)

    def info(self, message, **kwargs) -> bool:
        """Log at INFO."""
        return self._log('info', message, **kwargs)

    def warning(self, message, **kwargs) -> bool:
        """Log at WARN."""
        return self._log('warn', message, **kwargs)

    warn = warning

    def error(self, message, **kwargs) -> bool:
        """Log at ERROR."""
        return self._log('error', message, **kwargs)

    def fatal(self, message, **kwargs) -> bool:
        """Log at FATAL."""
        return self._log('fatal', message, **kwargs)
