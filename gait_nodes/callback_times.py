"""How long each node's callbacks take, for ``bench/commands.py`` (off unless asked).

With ``GAIT_NODES_CALLBACK_TIMES=DIR`` in a node process's environment, every timer and
subscription callback that runs under a node's :class:`gait_nodes.faults.FaultGuard` is timed
(wall clock, ``time.perf_counter``), and at the process's exit one JSON file per node,
``DIR/<node>-<pid>.json``, holds ``{"node": ..., "callbacks": {callback: [seconds, ...]}}``.
Whatever the runtime: the guard wraps the callback before the runtime (rclpy too) sees it.
"""

from __future__ import annotations

import atexit
import collections
import functools
import json
import os
import time
from pathlib import Path

ENVIRONMENT = 'GAIT_NODES_CALLBACK_TIMES'
#: Most durations kept per callback (a 90 s walk at 100 Hz is 9,000).
KEPT = 200_000

_nodes: dict[str, dict[str, collections.deque]] = {}


def _durations(node_name: str, callback_name: str) -> collections.deque | None:
    directory = os.environ.get(ENVIRONMENT)
    if not directory:
        return None
    if not _nodes:
        atexit.register(_write, Path(directory))
    return _nodes.setdefault(node_name, {}).setdefault(callback_name,
                                                      collections.deque(maxlen=KEPT))


def record(node_name: str, what: str, seconds: float) -> None:
    """Keep a duration measured elsewhere (a worker's job) when the environment asks for it."""
    durations = _durations(node_name, what)
    if durations is not None:
        durations.append(seconds)


def timed(node_name: str, callback_name: str, callback):
    """``callback``, timed when the environment asks for it (else ``callback`` itself)."""
    durations = _durations(node_name, callback_name)
    if durations is None:
        return callback

    @functools.wraps(callback)
    def run(*args):
        start = time.perf_counter()
        try:
            return callback(*args)
        finally:
            durations.append(time.perf_counter() - start)

    return run


def _write(directory: Path) -> None:
    try:
        directory.mkdir(parents=True, exist_ok=True)
        for node, callbacks in _nodes.items():
            path = directory / f'{node.strip("/").replace("/", "_")}-{os.getpid()}.json'
            path.write_text(json.dumps({'node': node, 'callbacks': {
                name: list(durations) for name, durations in callbacks.items()}}))
    except OSError:
        pass  # a benchmark aid: never the reason a node fails to exit
