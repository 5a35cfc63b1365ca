"""Stale-input watchdog shared by every node that consumes a stream.

A node names the streams it needs (``/gait/zmp_reference``, ``/gait/com_reference``,
``/joint_commands``, ``/cmd_vel``...), calls :meth:`InputWatchdog.heard` from each of their
callbacks and :meth:`InputWatchdog.update` from its timer. An input is *stale* when nothing
has arrived on it for longer than ``timeout_s`` (counted from the node's start while nothing has
arrived yet). :meth:`InputWatchdog.update` says when the set of stale inputs changed, so the node
reports at once; :meth:`InputWatchdog.status` is the ``(aspect, level, message, values)`` entry
of :meth:`gait_nodes.diagnostics.DiagnosticsReporter.publish`: one ``"<node>: inputs"`` status,
WARN naming each stale topic and its age, OK once every input is fresh again. No ROS import:
time comes in as integer nanoseconds.

Some inputs are events rather than streams (one /gait/swing_trajectory per planned swing): an
*event* input is never stale by age; it is stale from :meth:`InputWatchdog.missed` (a message
that was due did not come) until the next :meth:`InputWatchdog.heard`. A stream input can be
switched off (:meth:`InputWatchdog.watch`, e.g. an optional /cmd_vel timeout): it is then never
stale.

An input that more than one node publishes is *refused* (:mod:`gait_nodes.single_source`, given
as ``sources``): while it is, it counts among the stale inputs (the node cannot use it, and
holds), and the status is ERROR, naming its publishers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from gait_nodes.diagnostics import ERROR, OK, WARN
from gait_nodes.errors import ParameterError

ASPECT = 'inputs'


class InputWatchdog:
    """Ages of a node's required input streams.

    Args:
        topics: The watched topics.
        timeout_s: Age above which an input is stale [s], > 0.
        start_ns: The node's start [ns]: an input never heard is as old as the node.
        holding: What the node does while an input is stale, for the WARN message
            (e.g. 'holding the last command').
        events: Event inputs (see the module docstring), watched after ``topics``.
        sources: The node's :class:`gait_nodes.single_source.SingleSource`, whose refused
            inputs are reported here (also settable later as ``sources``).

    Raises:
        ParameterError: No topic, or ``timeout_s`` not a finite number > 0.
    """

    def __init__(self, topics: Sequence[str], timeout_s: float, start_ns: int,
                 holding: str = '', events: Sequence[str] = (), sources=None):
        if not topics and not events:
            raise ParameterError('a watchdog needs at least one topic')
        self.topics = tuple(topics) + tuple(events)
        self.events = tuple(events)
        self.timeout_s = timeout_s
        self.holding = holding
        self._start_ns = int(start_ns)
        self._last_ns: dict[str, int | None] = {topic: None for topic in self.topics}
        self._missed: dict[str, str] = {}
        self._off: set[str] = set()
        self._stale: tuple[str, ...] = ()
        self.sources = sources

    @property
    def timeout_s(self) -> float:
        """Age above which an input is stale [s]."""
        return self._timeout_s

    @timeout_s.setter
    def timeout_s(self, value: float) -> None:
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value) or value <= 0:
            raise ParameterError(f'a stale-input timeout must be a number of seconds > 0, got '
                                 f'{value!r}')
        self._timeout_s = float(value)

    def heard(self, topic: str, now_ns: int) -> None:
        """A good message arrived on ``topic`` at ``now_ns``."""
        if topic not in self._last_ns:
            raise KeyError(f'{topic} is not watched; watched: {list(self.topics)}')
        self._last_ns[topic] = int(now_ns)
        self._missed.pop(topic, None)

    def missed(self, topic: str, what: str) -> None:
        """An event input did not bring ``what`` (e.g. 'the swing of FL at 3.2 s') in time."""
        if topic not in self.events:
            raise KeyError(f'{topic} is not a watched event input; events: {list(self.events)}')
        self._missed[topic] = what

    def watch(self, topic: str, on: bool) -> None:
        """Watch the stream ``topic`` (True) or never report it stale (False)."""
        if topic not in self._last_ns or topic in self.events:
            raise KeyError(f'{topic} is not a watched stream; streams: '
                           f'{[t for t in self.topics if t not in self.events]}')
        if on:
            self._off.discard(topic)
        else:
            self._off.add(topic)

    def ever_heard(self, topic: str) -> bool:
        """Whether anything has arrived on ``topic``."""
        return self._last_ns[topic] is not None

    def age_s(self, topic: str, now_ns: int) -> float:
        """Time since the last message on ``topic`` (since the start if none) [s]."""
        last = self._last_ns[topic]
        return (int(now_ns) - (self._start_ns if last is None else last)) * 1e-9

    @property
    def refused(self) -> dict[str, str]:
        """Inputs refused now for having several publishers: topic -> who publishes."""
        return self.sources.refused if self.sources is not None else {}

    def is_stale(self, topic: str, now_ns: int) -> bool:
        """Whether ``topic`` is stale at ``now_ns`` (too old, event missed, or refused)."""
        if topic in self.refused:
            return True
        if topic in self.events:
            return topic in self._missed
        if topic in self._off:
            return False
        return self.age_s(topic, now_ns) > self._timeout_s + 1e-9

    @property
    def stale(self) -> tuple[str, ...]:
        """The topics stale at the last :meth:`update`."""
        return self._stale

    def update(self, now_ns: int) -> bool:
        """Re-evaluate at ``now_ns``; True when the set of stale inputs changed."""
        stale = tuple(topic for topic in self.topics if self.is_stale(topic, now_ns))
        stale += tuple(topic for topic in self.refused if topic not in stale)
        changed = stale != self._stale
        self._stale = stale
        return changed

    def status(self, now_ns: int) -> tuple[str, int, str, dict]:
        """``('inputs', level, message, values)`` as of the last :meth:`update`."""
        values: dict[str, object] = {'stale_after_s': self._timeout_s}
        for topic in self.topics:
            age = self.age_s(topic, now_ns)
            values[f'{topic} age_s'] = age
            values[f'{topic} received'] = 'yes' if self.ever_heard(topic) else 'no'
            if topic in self._off:
                values[f'{topic} watched'] = 'no'
        values['stale'] = ','.join(self._stale)
        refused = {topic: who for topic, who in self.refused.items() if topic in self._stale}
        if refused:
            values['refused'] = ','.join(refused)
            for topic in refused:
                values[f'{topic} publishers'] = self.sources.publishers.get(topic, 0)
            message = (f'refusing to mix {"; ".join(refused.values())}: '
                       f'{self.sources.holding} until one is left')
            others = [topic for topic in self._stale if topic not in refused]
            if others:
                message += f'; stale too: {", ".join(others)}'
            return ASPECT, ERROR, message, values
        if self._stale:
            parts = []
            for topic in self._stale:
                if topic in self.events:
                    parts.append(f'no {topic} for {self._missed.get(topic, "an expected event")}')
                    continue
                age = self.age_s(topic, now_ns)
                what = 'nothing received on' if not self.ever_heard(topic) else 'no'
                parts.append(f'{what} {topic} for {age:.3g} s (> {self._timeout_s:g} s)')
            message = '; '.join(parts)
            if self.holding:
                message += f': {self.holding}'
            return ASPECT, WARN, message, values
        return ASPECT, OK, f'inputs fresh: {", ".join(self.topics)}', values
