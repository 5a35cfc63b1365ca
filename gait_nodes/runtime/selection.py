"""Which runtime serves this process: ``rclpy``, ``dds`` or ``inproc``.

Chosen by ``--runtime`` (the entry points set it through :func:`select_runtime`), else by the
``GAIT_NODES_RUNTIME`` environment variable, else ``rclpy`` when it is importable (a sourced ROS 2
install), else ``dds``.
"""

from __future__ import annotations

import importlib.util
import os

from gait_nodes.errors import RuntimeSelectionError

RUNTIMES = ('rclpy', 'dds', 'inproc')
ENV_VAR = 'GAIT_NODES_RUNTIME'

_selected: str | None = None


def rclpy_available() -> bool:
    """Whether the real rclpy can be imported here."""
    return importlib.util.find_spec('rclpy') is not None


def validate_runtime(name: str) -> str:
    """Check a runtime name; raise with the allowed names and the reason if it cannot run."""
    if name not in RUNTIMES:
        raise RuntimeSelectionError(
            f'unknown runtime {name!r}: choose one of {", ".join(RUNTIMES)}')
    if name == 'rclpy' and not rclpy_available():
        raise RuntimeSelectionError(
            'runtime rclpy requested but rclpy is not importable: source a ROS 2 Jazzy install '
            '(source /opt/ros/jazzy/setup.bash) or use --runtime dds|inproc')
    return name


def default_runtime() -> str:
    """The runtime used when none is chosen explicitly."""
    env = os.environ.get(ENV_VAR, '').strip()
    if env:
        return validate_runtime(env)
    return 'rclpy' if rclpy_available() else 'dds'


def select_runtime(name: str | None) -> str:
    """Fix the runtime of this process (``None``: the default) and return its name."""
    global _selected
    _selected = validate_runtime(name) if name else default_runtime()
    return _selected


def active_runtime() -> str:
    """The runtime selected for this process, deciding the default on first use."""
    return _selected if _selected is not None else select_runtime(None)
