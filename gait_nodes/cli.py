"""Command-line plumbing shared by every node and tool: ``--runtime``, ``--ros-args``, exit codes.

Exit status: 0 on success and on a clean stop (Ctrl-C, SIGTERM), 2 on bad input (one line on
stderr, no traceback), 1 when a tool reports a negative outcome (e.g. a rejected command).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from gait_nodes.errors import GaitNodesError
from gait_nodes.runtime.args import split_ros_args
from gait_nodes.runtime.selection import RUNTIMES

ROS_ARGS_EPILOG = (
    'ROS arguments (after --ros-args, as with any ROS 2 node): -p name:=value, '
    '--params-file FILE (node_name: {ros__parameters: ...}, /** for every node), '
    '-r from:=to, --log-level LEVEL. Runtime: --runtime or GAIT_NODES_RUNTIME '
    f'({"|".join(RUNTIMES)}; default rclpy when importable, else dds).'
)


#: A launcher (``run``) names a file here; the node writes it once it is up and spinning.
READY_FILE_ENV = 'GAIT_NODES_READY_FILE'
#: A launcher puts its pid here; the node stops (SIGTERM, a clean stop) when that process dies.
LAUNCHER_PID_ENV = 'GAIT_NODES_LAUNCHER_PID'
#: prctl option: signal delivered to this process when its parent dies (Linux).
_PR_SET_PDEATHSIG = 1
#: Environment defaults of node processes (the launchers' ``run`` and ``gait.launch.py``): one
#: BLAS thread. The nodes' linear algebra is small (the sway and polynomial COM plans solve
#: 45x45 KKT systems ten times a second); with OpenBLAS's worker threads on a loaded machine such
#: a solve took 13 ms instead of 0.03 ms, and the workers spinning between calls cost go2_trot's
#: COM controller 0.5 core (2 cores, another job running, Jazzy's numpy 1.26; the newer numpy
#: of the default venv showed the same spikes, up to 0.3 s for one 180x180 solve). BLAS reads
#: these when it loads, so they are set for the process, not in it; a value
#: already in the environment wins.
NODE_ENVIRONMENT_DEFAULTS = {'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1',
                             'MKL_NUM_THREADS': '1'}


def node_environment(environment: dict, **extra: str) -> dict:
    """``environment`` for a node process: the BLAS defaults under it, ``extra`` over it."""
    return {**NODE_ENVIRONMENT_DEFAULTS, **environment, **extra}


def stop_with_launcher() -> bool:
    """Arrange a SIGTERM for this node when the launcher named in the environment dies.

    Nodes run in their own sessions (a Ctrl-C reaches the launcher only, which stops them in
    order); without this, a launcher killed outright would leave its graph running. Linux only
    (prctl); elsewhere a no-op.

    Returns:
        False when the launcher is already gone (the node should not start), else True.
    """
    launcher = os.environ.get(LAUNCHER_PID_ENV)
    if not launcher or not sys.platform.startswith('linux'):
        return True
    import ctypes
    import signal

    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    return str(os.getppid()) == launcher.strip()


class ArgumentParser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2) and the ROS-args epilog."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault('epilog', ROS_ARGS_EPILOG)
        super().__init__(*args, **kwargs)

    def error(self, message: str):
        """Print ``prog: error: message`` on one line and exit 2."""
        self.exit(2, f'{self.prog}: error: {message}\n')


def add_runtime_argument(parser: argparse.ArgumentParser) -> None:
    """``--runtime NAME`` (validated at init, so that the error names the allowed values)."""
    parser.add_argument('--runtime', metavar='|'.join(RUNTIMES), default=None,
                        help='runtime to use (default: GAIT_NODES_RUNTIME, else rclpy when '
                             'importable, else dds)')


def fail(prog: str, error: BaseException) -> int:
    """Report a bad-input error on one line; exit status 2."""
    print(f'{prog}: error: {error}', file=sys.stderr)
    return 2


def split_args(args: list[str] | None) -> tuple[list[str], list[str]]:
    """``(user arguments, ['--ros-args', ...])`` from ``args`` (default ``sys.argv[1:]``)."""
    argv = sys.argv[1:] if args is None else list(args)
    user, ros = split_ros_args(argv)
    return user, (['--ros-args', *ros] if ros else [])


def run_node(node_factory, args: list[str] | None = None, *, prog: str,
             description: str, add_arguments=None) -> int:
    """Entry point of a node: parse, init the runtime, spin until stopped, shut down cleanly.

    Args:
        node_factory: ``factory(options) -> Node``; ``options`` is the argparse namespace.
        args: Command-line arguments without the program name (default ``sys.argv[1:]``).
        prog: Program name for messages.
        description: One-paragraph help text.
        add_arguments: Optional ``f(parser)`` adding node-specific options.

    Returns:
        The process exit status.
    """
    from gait_nodes import runtime

    user, ros = split_args(args)
    parser = ArgumentParser(prog=prog, description=description)
    add_runtime_argument(parser)
    if add_arguments is not None:
        add_arguments(parser)
    options = parser.parse_args(user)
    if not stop_with_launcher():
        print(f'{prog}: the launcher that started this node is gone; not starting',
              file=sys.stderr)
        return 0
    try:
        runtime.init(args=[prog, *ros], runtime=options.runtime)
    except GaitNodesError as exc:
        return fail(prog, exc)
    try:
        node = node_factory(options)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(node)
        ready_file = os.environ.get(READY_FILE_ENV)
        if ready_file:
            Path(ready_file).write_text(f'{os.getpid()}\n')
        executor.spin()
    except GaitNodesError as exc:
        return fail(prog, exc)
    except KeyboardInterrupt:
        pass
    finally:
        runtime.shutdown()
    return 0
