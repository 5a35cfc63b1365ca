"""``python -m gait_nodes run ...``: start the whole gait graph, stop it cleanly, print a summary.

With --runtime dds every node is its own process (python -m gait_nodes.<node>), as on a
robot; with --runtime inproc all nodes share one process and one lockstep executor, and the
duration is simulated time. The command starts whichever contract nodes are installed. The
summary's message counts and rates come from the bag when recording (over dds the launcher then
subscribes to nothing but /gait/command_status), else from the launcher's own subscriptions.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from gait_nodes import graph
from gait_nodes.cli import (
    LAUNCHER_PID_ENV,
    READY_FILE_ENV,
    ArgumentParser,
    fail,
    node_environment,
    split_args,
)
from gait_nodes.errors import ArgumentError, GaitNodesError, os_error_text
from gait_nodes.foxglove_relay import DEFAULT_HOST, DEFAULT_PORT
from gait_nodes.node_parameters import RECORDER, check_overrides
from gait_nodes.runtime.args import parse_ros_args
from gait_nodes.scenarios import DEFAULT_SCENARIO, SCENARIOS, CommandDriver, get_scenario

PROG = 'python -m gait_nodes'
STOP_TIMEOUT_S = 10.0
#: Longest wait for a node to start (imports, robot model, a value table built on first use).
START_TIMEOUT_S = 900.0
#: Gait cycles of the scenario's first walk planned before the graph starts (its probes kept:
#: :func:`_prepare_first_walk`), past its first step: as far as the footstep planner's first
#: change is checked (gait_nodes.planning.online.CHECK_CYCLES).
FIRST_WALK_CYCLES = 2.0


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise ArgumentError(f'expected a number of seconds, got {text!r}') from None
    if not math.isfinite(value) or value <= 0:
        raise ArgumentError(f'duration must be a finite number > 0 s, got {text!r}')
    return value


def build_parser() -> ArgumentParser:
    """The ``run`` command line."""
    parser = ArgumentParser(prog=PROG, description='Start the whole gait graph, stop it '
                            'cleanly, print a summary.')
    commands = parser.add_subparsers(dest='command', required=True, metavar='run')
    run = commands.add_parser('run', help='start the node graph',
                              description=__doc__.split('\n\n', 1)[1], epilog=parser.epilog)
    run.error = parser.error
    run.add_argument('--runtime', choices=['dds', 'inproc', 'rclpy'], default=None,
                     help='dds: one process per node; inproc: one process, simulated time '
                          '(default: GAIT_NODES_RUNTIME, else rclpy when importable, else dds)')
    run.add_argument('--fast', action='store_true',
                     help='the same as --runtime inproc: one process, simulated time, as fast '
                          'as the machine goes')
    run.add_argument('--scenario', default=DEFAULT_SCENARIO, metavar='NAME',
                     help=f'walk to run: {", ".join(SCENARIOS)} (default {DEFAULT_SCENARIO})')
    run.add_argument('--duration', type=str, default=None,
                     help='seconds to run once every node is up, wall time (dds) or simulated '
                          "time (inproc); default: the scenario's (20 s for most)")
    run.add_argument('--record', metavar='DIR', nargs='?', const='', default=None,
                     help='record every contract topic to a rosbag2 MCAP directory '
                          '(default name bags/gait_<date-time>)')
    run.add_argument('--plot', metavar='DIR', default=None,
                     help='with --record: write the PNG plots into DIR (default: the bag '
                          "directory's name + '_plots')")
    run.add_argument('--no-plot', action='store_true', help='with --record: write no plots')
    run.add_argument('--video', metavar='FILE', default=None,
                     help='with --record: render the recorded walk as FILE (.mp4 or .gif) after '
                          'the summary, as python -m gait_nodes.inspect BAG --video FILE does '
                          '(pip install mujoco "imageio[ffmpeg]")')
    run.add_argument('--robot', default=None,
                     help="robot name in config/robots/ or a robot YAML (default: the "
                          "scenario's)")
    run.add_argument('--gait', default=None,
                     help='gait: biped | crawl | static_crawl | trot | auto')
    run.add_argument('--simulator', choices=list(graph.SIMULATORS),
                     default=graph.DEFAULT_SIMULATOR,
                     help='kinematic: kinematic_simulator, exact and fast (default); physics: '
                          'physics_simulator, the robot in MuJoCo with contacts, joint gains and '
                          'effort limits (pip install mujoco)')
    run.add_argument('--no-state-publisher', action='store_true',
                     help='leave out robot_state_publisher (/robot_description, /tf_static and '
                          "the links' /tf), to run ROS's own robot_state_publisher instead "
                          '(docs/ros_tools.md)')
    run.add_argument('--nodes', default=None,
                     help=f'comma-separated subset of {",".join(graph.NODES)} (with '
                          f'--simulator physics, physics_simulator for kinematic_simulator)')
    run.add_argument('--namespace', metavar='NS', default=None,
                     help='start the graph in ROS namespace NS (e.g. /robot1), as a launch '
                          "file's namespace does: every node process, the recorder included, "
                          'gets -r __ns:=NS, and /tf, /tf_static and /diagnostics are remapped '
                          'into it (/clock stays global), so that graphs in different '
                          'namespaces share a ROS_DOMAIN_ID without mixing')
    run.add_argument('--view', metavar='[HOST:]PORT', nargs='?', const=str(DEFAULT_PORT),
                     default=None,
                     help='with --runtime dds: serve the live graph to Foxglove over its '
                          'WebSocket protocol (python -m gait_nodes.view as one more process); '
                          f'open ws://localhost:PORT in Foxglove (default port {DEFAULT_PORT}, '
                          f'host {DEFAULT_HOST}; 0.0.0.0:PORT serves every interface)')
    run.add_argument('--json', action='store_true', help='print the summary as JSON')
    return parser


def _graph_params(options) -> dict:
    scenario = get_scenario(options.scenario)
    # The launcher re-sends /cmd_vel every 0.5 s (CommandDriver), so the planner may treat a
    # silence of 2 s as a lost teleop and stop the walk, as a robot's velocity watchdog does.
    values = {'robot': options.robot or scenario.robot, 'cmd_vel_timeout_s': 2.0,
              **scenario.settings}
    if options.gait:
        values['gait'] = options.gait
    return {'/**': {'ros__parameters': values}}


def _prepare_value_table(values: dict, names: list[str]) -> None:
    """Build the swing value table the graph walks with before it starts (once: cached).

    The footstep planner times its steps from the table and, while the swing-leg policy builds
    it on first use, stands in with slower times: built first, a walk is the same on a cold
    cache as on a warm one, and a fresh machine's main job walks its real speed from the start.
    Only for the graph's own settings (a ``-p`` override builds its table on first use).
    """
    if values.get('swing') != 'value_table' or not {'footstep_planner',
                                                     'swing_leg_policy'} & set(names):
        return
    from gait_nodes.planning.gait_params import GaitParameters
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.robot.whole_body_ik import limb_ik_family
    from gait_nodes.swing.cache import load_or_build

    robot = load_robot_model(values['robot'])
    family = limb_ik_family(robot)
    if family is None:
        return
    height = values.get('step_height_m', GaitParameters.for_robot(
        robot.description, gait=robot.description.gaits[0]).step_height_m)
    load_or_build(robot, family, float(height), robot.description.joint_velocity_limit_rad_s,
                  log=lambda message: print(f'{PROG}: {message}', file=sys.stderr, flush=True))


def _prepare_first_walk(values: dict, names: list[str], commands) -> None:
    """Search the fastest walk of the scenario's first velocity before the graph starts.

    With joint-limit timing the footstep planner searches, for a direction it has not walked
    yet, the fastest rhythm the joints allow: for the static crawl, a value-table swing timed at
    about a hundred lattice nodes (3-4 s on RoboSimian), then probes the first steps through the
    limb IK (1-2 s). Those times and probes are kept on disk
    (:mod:`gait_nodes.swing.still_body`); planned here once, the planner finds them and plans
    the first walk in a fraction of a second, on a fresh machine as on a warm one. Only for the
    graph's own settings (a ``-p`` override plans in the planner, on first use).
    """
    velocity = next((command.velocity for command in commands
                     if command.velocity is not None and any(command.velocity)), None)
    if velocity is None or 'footstep_planner' not in names:
        return
    from gait_nodes.footstep_planner import GAIT_FIELDS, shipped_defaults
    from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
    from gait_nodes.planning.gait_params import NUMERIC_RANGES, GaitParameters
    from gait_nodes.planning.timing_models import TimingModels
    from gait_nodes.robot.description import load_robot_description
    from gait_nodes.swing.cache import cache_dir
    from gait_nodes.swing.still_body import GAIT, keep_probes, kept_probes, still_body_of

    robot = load_robot_description(values['robot'])
    defaults = {**GaitParameters.robot_defaults(robot), **shipped_defaults(), **values}
    fields = {name: float(defaults[name]) if name in NUMERIC_RANGES else defaults[name]
              for name in GAIT_FIELDS if name in defaults}
    try:
        params = GaitParameters(**fields)
        if params.gait != GAIT or params.timing != 'joint_limit':
            return
        timing, _, final = TimingModels(robot).timing(params)
        if not final or timing.timing is None:
            return
        if not still_body_of(timing).stored:
            print(f'{PROG}: searching the fastest {GAIT} of {robot.name} at its joint limit '
                  f'(once: the swing times are kept under {cache_dir()})', file=sys.stderr,
                  flush=True)
        # And the first steps, whose probes (the limb IK of each swing and body move: a second
        # or two) are kept on disk too: the footstep planner rehearses that walk while it waits
        # for the robot's pose, and walks it when the velocity comes.
        planner = GaitPlanner(robot, params, swing_timing=timing)
        planner.take_probes(kept_probes(timing))
        planner.set_velocity(Twist2D(*velocity), 0.0)
        rhythm = planner.rhythm()
        planner.advance(planner.next_boundary_s(0.0)
                        + FIRST_WALK_CYCLES * (rhythm.cycle_s if rhythm else 0.0))
        keep_probes(timing, planner.probes_to_keep())
    except GaitNodesError:
        return  # the planner says what is wrong with these settings, in the graph


def _selected_nodes(options) -> list[str]:
    available = graph.graph_nodes(options.simulator)
    if options.no_state_publisher:
        available = [name for name in available if name != graph.STATE_PUBLISHER]
    if options.nodes is None:
        return available
    wanted = [name.strip() for name in options.nodes.split(',') if name.strip()]
    if options.no_state_publisher and graph.STATE_PUBLISHER in wanted:
        raise ArgumentError(f'--nodes {graph.STATE_PUBLISHER} and --no-state-publisher '
                            f'contradict each other: choose one')
    for name in wanted:
        if name not in available and name in graph.SIMULATORS.values():
            raise ArgumentError(f'node {name!r} is not the chosen simulator: --simulator '
                                f'{options.simulator} runs {graph.SIMULATORS[options.simulator]}')
        if name not in graph.NODES and name not in graph.ALTERNATIVE_NODES:
            raise ArgumentError(f'unknown node {name!r}: choose from {", ".join(graph.NODES)}')
        if name not in available:
            raise ArgumentError(f'node {name!r} is not installed in this version')
    return wanted


class TopicCounter:
    """Counts the messages on every contract topic, from inside the graph."""

    def __init__(self, node):
        from gait_nodes.interfaces import get_message
        from gait_nodes.runtime import DurabilityPolicy, QoSProfile

        self.counts = {topic: 0 for topic in graph.TOPICS}
        self.first_ns: dict[str, int] = {}
        self.last_ns: dict[str, int] = {}
        self._clock = node.get_clock()
        # A latched topic's message may be older than this node (inproc builds it last).
        latched = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        for topic, type_name in graph.TOPICS.items():
            node.create_subscription(get_message(type_name), graph.node_topic_name(topic),
                                     self._counter(topic),
                                     latched if topic in graph.LATCHED_TOPICS else 100, raw=True)

    def _counter(self, topic: str):
        def count(_data) -> None:
            now = self._clock.now().nanoseconds  # rclpy's Clock has no now_ns
            self.counts[topic] += 1
            self.first_ns.setdefault(topic, now)
            self.last_ns[topic] = now

        return count

    def table(self) -> dict[str, dict]:
        """Per topic: message count and mean rate [Hz]."""
        rows = {}
        for topic, count in self.counts.items():
            if not count:
                continue
            span = (self.last_ns[topic] - self.first_ns[topic]) / 1e9
            rows[topic] = {'messages': count,
                           'rate_hz': round((count - 1) / span, 2) if span > 0 else None}
        return rows


def _recorded_robot(options) -> str | None:
    """The robot whose per-foot topics the recorder records: the physics simulator's."""
    if options.simulator != 'physics':
        return None
    return options.robot or get_scenario(options.scenario).robot


def _record_args(options, ros_parameters: list[str] = ()) -> list[str]:
    ros = [*options.namespace_args, *ros_parameters]
    robot = _recorded_robot(options)
    return ['-o', options.record, *(['--robot', robot] if robot else []),
            *(['--ros-args', *ros] if ros else [])]


def _monitor(options, runtime):
    """The launcher's own node: in the graph's namespace, none of the user's -p/-r."""
    namespace = options.namespace_args
    return runtime.Node('gait_run_monitor', use_global_arguments=False,
                        cli_args=['--ros-args', *namespace] if namespace else None)


def _check_bag_directory(path: str) -> None:
    """Refuse at once a bag directory that exists or cannot be created (nothing is made).

    The test is the real thing: a directory is created, and removed, in the nearest existing
    ancestor, so that a read-only file system, missing permissions or a full disk all show.
    """
    if os.path.lexists(path):
        raise ArgumentError(f'--record {path}: exists already; choose a new directory (a bag '
                            f'is never overwritten)')
    ancestor = Path(os.path.abspath(path)).parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ArgumentError(f'--record {path}: {ancestor} is not a directory')
    try:
        os.rmdir(tempfile.mkdtemp(prefix='.gait_nodes_probe_', dir=ancestor))
    except OSError as exc:
        raise ArgumentError(f'--record {path}: cannot create a directory in {ancestor}: '
                            f'{os_error_text(exc)}') from None


def _check_view(address: str, runtime_name: str) -> tuple[str, int]:
    """``(host, port)`` of ``run --view``, refused at once if the view could not serve there.

    Args:
        address: ``PORT`` or ``HOST:PORT``.
        runtime_name: The graph's runtime: only a dds graph is served.
    """
    if runtime_name == 'rclpy':
        raise ArgumentError('--view serves a dds graph; under ROS 2 run foxglove_bridge '
                            '(ros2 launch foxglove_bridge foxglove_bridge_launch.xml)')
    if runtime_name != 'dds':
        raise ArgumentError(f'--view serves a graph of node processes over DDS: add --runtime '
                            f'dds (the {runtime_name} graph runs in this process, in '
                            f'simulated time)')
    from gait_nodes.foxglove_relay import import_sdk, parse_address, probe_port, serve_error

    host, port = parse_address(address, '--view')
    import_sdk()
    reason = probe_port(host, port)
    if reason is not None:
        raise serve_error(host, port, reason, '--view [HOST:]PORT')
    return host, port


def _view_command(options, runtime_name: str) -> list[str]:
    """The command of the live view process of ``run --view``: the graph's namespace."""
    host, port = options.view
    robot = _recorded_robot(options)
    return [sys.executable, '-m', 'gait_nodes.view', '--runtime', runtime_name,
            '--host', host, '--port', str(port),
            *(['--namespace', options.namespace] if options.namespace else []),
            *(['--robot', robot] if robot else [])]


def run_inproc(options, names: list[str], ros: list[str], commands=None) -> dict:
    """All nodes in this process under one lockstep executor.

    ``commands``: the :class:`~gait_nodes.scenarios.TimedCommand` s to send (default: the
    scenario's).
    """
    from gait_nodes import runtime

    runtime.init(args=[PROG, *ros], runtime='inproc')
    try:
        executor = runtime.SingleThreadedExecutor()
        for name in names:
            executor.add_node(graph.load_class(graph.node_path(name))())
        recorder = None
        if options.record:
            recorder = graph.load_class(graph.RECORDER)(output=options.record,
                                                        robot=_recorded_robot(options))
            executor.add_node(recorder)
        # The monitor is ours, not the user's: the graph's -p/-r do not address it (as in
        # run_processes, where it never sees them).
        monitor = _monitor(options, runtime)
        counter = TopicCounter(monitor)
        driver = CommandDriver(monitor, get_scenario(options.scenario).commands
                               if commands is None else commands)
        executor.add_node(monitor)
        driver.start()
        start = time.perf_counter()
        executor.spin_for(options.duration)
        wall = time.perf_counter() - start
        sim = runtime.default_context().transport.now_ns / 1e9
    finally:
        runtime.shutdown()  # the recorder closes its bag
    summary = {
        'runtime': 'inproc', 'nodes': names, 'simulated_s': sim, 'wall_s': round(wall, 3),
        'real_time_factor': round(sim / wall, 1) if wall > 0 else None,
        'topics': counter.table(), 'exit_codes': {}, 'commands': driver.statuses,
    }
    if recorder is not None and recorder.failure:
        summary['recording_error'] = recorder.failure
    return summary


def run_processes(options, names: list[str], ros: list[str], runtime_name: str) -> dict:
    """One process per node; this process counts the traffic and stops them cleanly."""
    from gait_nodes import runtime

    # The physics simulator may step slower than the wall clock (rclpy's cost per message, on
    # 2 cores): it owns time, as under the launch file, and the graph follows its /clock, so
    # that a slow tick slows the graph instead of being made up in coarse steps.
    sim_time = ['-p', 'use_sim_time:=true'] if options.simulator == 'physics' else []
    commands = {name: [sys.executable, '-m', f'gait_nodes.{name}', '--runtime', runtime_name,
                       *ros, *(sim_time if name != 'physics_simulator' else [])]
                for name in names}
    if sim_time and 'physics_simulator' in commands:
        commands['physics_simulator'] += ['-p', 'publish_clock:=true']
    if options.record:
        commands['recorder'] = [sys.executable, '-m', 'gait_nodes.recorder', '--runtime',
                                runtime_name, *_record_args(options, sim_time)]
    if options.view:
        commands['view'] = _view_command(options, runtime_name)
    runtime.init(args=[PROG], runtime=runtime_name)
    processes: dict[str, subprocess.Popen] = {}
    exit_codes: dict[str, int] = {}
    try:
        monitor = _monitor(options, runtime)
        # Recording, the traffic is counted from the bag: a subscriber of every stream here
        # would be one more reader each node process sends every message to.
        counter = None if options.record else TopicCounter(monitor)
        driver = CommandDriver(monitor, get_scenario(options.scenario).commands)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(monitor)
        ready_dir = tempfile.mkdtemp(prefix='gait_nodes_ready_')
        ready_files = {name: Path(ready_dir) / f'{name}.ready' for name in commands}
        for name, command in commands.items():
            # Own session: a Ctrl-C in the terminal reaches this launcher only, which then
            # stops the nodes in order (a node interrupted while importing would crash).
            env = node_environment(os.environ, **{READY_FILE_ENV: str(ready_files[name]),
                                                  LAUNCHER_PID_ENV: str(os.getpid())})
            processes[name] = subprocess.Popen(command, env=env, start_new_session=True)
        _wait_ready(processes, ready_files, exit_codes, executor)
        driver.start()
        start = time.perf_counter()
        deadline = start + options.duration
        while time.perf_counter() < deadline and runtime.ok() and \
                not runtime.default_context().shutdown_requested.is_set():
            executor.spin_once(timeout_sec=min(0.1, max(deadline - time.perf_counter(), 0)))
            for name, process in processes.items():
                if process.poll() is not None and name not in exit_codes:
                    exit_codes[name] = process.returncode
                    print(f'{PROG}: node {name} exited early with status {process.returncode}',
                          file=sys.stderr)
        wall = time.perf_counter() - start
    finally:
        exit_codes.update(_stop(processes, exit_codes, ready_files if processes else {}))
        runtime.shutdown()
        if processes:
            shutil.rmtree(ready_dir, ignore_errors=True)
    return {
        'runtime': runtime_name, 'nodes': names, 'simulated_s': None, 'wall_s': round(wall, 3),
        'real_time_factor': None, 'topics': counter.table() if counter else {},
        'exit_codes': exit_codes, 'commands': driver.statuses,
    }


def _stopping() -> bool:
    from gait_nodes import runtime

    return not runtime.ok() or runtime.default_context().shutdown_requested.is_set()


def _wait_ready(processes, ready_files, exit_codes, executor) -> None:
    """Spin until every node has written its ready file (or exited, or the run is stopped)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    announced = time.monotonic() + 5.0
    while time.monotonic() < deadline and not _stopping():
        waiting = [name for name, process in processes.items()
                   if not ready_files[name].exists() and process.poll() is None]
        if not waiting:
            return
        if time.monotonic() > announced:
            print(f'{PROG}: waiting for {", ".join(waiting)} to start', file=sys.stderr)
            announced = time.monotonic() + 30.0
        executor.spin_once(timeout_sec=0.1)
    for name, process in processes.items():
        if process.poll() is not None and name not in exit_codes:
            exit_codes[name] = process.returncode
            print(f'{PROG}: node {name} exited during start-up with status '
                  f'{process.returncode}', file=sys.stderr)


def _stop(processes: dict[str, subprocess.Popen], done: dict[str, int],
          ready_files: dict[str, Path]) -> dict[str, int]:
    """SIGINT every node, as Ctrl-C would; SIGKILL only what ignores it for STOP_TIMEOUT_S.

    A node still starting up gets its SIGINT once it is up (a few seconds at most), so that
    no node dies in the middle of its imports.
    """
    settle = time.monotonic() + STOP_TIMEOUT_S
    while time.monotonic() < settle and any(
            not ready_files[name].exists() and process.poll() is None
            for name, process in processes.items() if name in ready_files):
        time.sleep(0.05)
    for name, process in processes.items():
        if name not in done and process.poll() is None:
            process.send_signal(signal.SIGINT)
    codes = {}
    deadline = time.monotonic() + STOP_TIMEOUT_S
    for name, process in processes.items():
        try:
            codes[name] = process.wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            process.kill()
            codes[name] = process.wait()
            print(f'{PROG}: node {name} ignored SIGINT for {STOP_TIMEOUT_S} s and was killed',
                  file=sys.stderr)
    return codes


def print_summary(summary: dict, as_json: bool) -> None:
    """Human-readable (or JSON) account of the run."""
    if as_json:
        print(json.dumps(summary, indent=2, sort_keys=True))
        return
    nodes = ', '.join(summary['nodes']) or 'none'
    namespace = summary.get('namespace', '/')
    print(f'gait_nodes run: scenario {summary.get("scenario")}, runtime {summary["runtime"]}, '
          + (f'namespace {namespace}, ' if namespace != '/' else '') + f'nodes: {nodes}')
    if not summary['nodes']:
        print('  no gait nodes are installed in this version yet; the graph ran empty')
    timing = f'  wall time {summary["wall_s"]:.2f} s'
    if summary['simulated_s'] is not None:
        timing += (f', simulated {summary["simulated_s"]:.2f} s, '
                   f'real-time factor {summary["real_time_factor"]}x')
    print(timing)
    for topic, row in summary['topics'].items():
        rate = f'{row["rate_hz"]:.1f} Hz' if row['rate_hz'] else '-'
        print(f'  {topic:28s} {row["messages"]:8d} msgs  {rate}')
    if not summary['topics']:
        print('  no messages on the contract topics')
    statuses = summary.get('commands') or []
    if statuses:
        from gait_nodes.bag.analysis import command_answers

        answers = command_answers(statuses)
        print(f'  gait commands: {answers["accepted"]} accepted ({answers["applied"]} applied), '
              f'{answers["rejected"]} rejected, {answers["superseded"]} superseded')
        for reason in answers['rejections']:
            print(f'    rejected: {reason}')
    for name, code in summary['exit_codes'].items():
        if code != 0:
            print(f'  node {name} exited with status {code}')
    if summary.get('bag'):
        print(f'  recorded: {summary["bag"]}')
        if summary.get('recording_error'):
            print(f'  RECORDING STOPPED EARLY: {summary["recording_error"]}')
        report = summary.get('inspect') or {}
        if 'error' in report:
            print(f'  the bag cannot be read: {report["error"]}')
        else:
            from gait_nodes.inspect import format_gait

            check = report.get('metadata_check') or {}
            print(f'  bag: {report.get("message_count", 0)} messages over '
                  f'{report.get("duration_s", 0.0):.2f} s, '
                  + ('metadata.yaml matches' if check.get('matches') else
                     f'metadata problems: {check.get("problems")}'))
            for damage in report.get('damage', []):
                print(f'  DAMAGE: {damage["description"]}')
            for line in format_gait(report.get('gait')):
                print('  ' + line)
            if report.get('plots'):
                print(f'  plots: {", ".join(report["plots"])}')
            print(f'  details: python -m gait_nodes.inspect {summary["bag"]}')


def _inspect_recording(bag: str, plot_dir: str | None, namespace: str = '/') -> dict:
    """The inspect report of the bag just recorded (an ``error`` entry if it cannot be read).

    Args:
        bag: The bag directory.
        plot_dir: Where to write the PNG plots (none when None).
        namespace: The graph's namespace.
    """
    from gait_nodes.bag.analysis import inspect_bag, robot_limits

    try:
        inspection = inspect_bag(bag, namespace=namespace)
    except GaitNodesError as exc:
        return {'error': str(exc)}
    report = inspection.report
    keep = ('message_count', 'duration_s', 'complete', 'damage', 'metadata_check', 'gait')
    kept = {key: report[key] for key in keep if key in report}
    names = graph.contract_topics([row['topic'] for row in report.get('topics', [])],
                                  report.get('namespace', '/'))
    kept['topics'] = {names[row['topic']]: {'messages': row['count'],
                                            'rate_hz': row['rate_hz']}
                      for row in report.get('topics', [])
                      if row['topic'] in names and row['count']}
    if plot_dir:
        from gait_nodes.bag.plots import write_plots

        robot = report.get('gait', {}).get('robot')
        try:
            written = write_plots(inspection.series, plot_dir, robot_limits(robot)[1])
        except OSError as exc:
            kept['plot_error'] = (f'cannot write the plots to {exc.filename or plot_dir}: '
                                  f'{os_error_text(exc)}')
        else:
            kept['plots'] = [os.path.abspath(p) for p in written]
    return kept


def main(args: list[str] | None = None) -> int:
    """Entry point of ``python -m gait_nodes``."""
    user, ros = split_args(args)
    options = build_parser().parse_args(user)
    try:
        from gait_nodes.runtime.selection import select_runtime

        scenario = get_scenario(options.scenario)
        options.duration = _positive_float(options.duration or str(scenario.duration_s))
        ros_args = parse_ros_args(ros[1:])  # a bad --params-file or -p: before anything starts
        if options.fast:
            if options.runtime not in (None, 'inproc'):
                raise ArgumentError(f'--fast runs the inproc runtime; it cannot be combined '
                                    f'with --runtime {options.runtime}')
            options.runtime = 'inproc'
        runtime_name = select_runtime(options.runtime)
        if options.view is not None:  # a port taken: before anything starts
            options.view = _check_view(options.view, runtime_name)
        names = _selected_nodes(options)
        if options.video is not None:
            if options.record is None:
                raise ArgumentError('--video renders the recorded walk: add --record')
            from gait_nodes.bag.video import check_dependencies, prefer_headless_gl

            prefer_headless_gl()  # before MuJoCo is imported (the physics simulator imports it)
            check_dependencies(options.video)  # before anything starts, as below
        if options.simulator == 'physics':
            from gait_nodes.sim.mujoco_model import import_mujoco

            import_mujoco()  # before anything starts: how to install it, if it is missing
        options.namespace_args = graph.namespace_arguments(options.namespace)
        # Each node would refuse a parameter it does not declare, after its start-up work.
        checked = names + ([RECORDER] if options.record is not None and
                           runtime_name == 'inproc' else [])
        for name in checked:
            check_overrides(name, ros_args, runtime_name)
        if options.record == '':
            options.record = time.strftime('bags/gait_%Y_%m_%d-%H_%M_%S')
        if (options.plot or options.no_plot) and options.record is None:
            raise ArgumentError('--plot and --no-plot apply to a recording: add --record')
        if options.plot and options.no_plot:
            raise ArgumentError('--plot DIR and --no-plot contradict each other: choose one')
        if options.record and not graph.module_exists(graph.RECORDER):
            raise ArgumentError('--record needs the recorder node, not installed in this '
                                'version')
        if options.record:
            _check_bag_directory(options.record)
        graph_params = _graph_params(options)
        _prepare_value_table(graph_params['/**']['ros__parameters'], names)
        _prepare_first_walk(graph_params['/**']['ros__parameters'], names,
                            get_scenario(options.scenario).commands)
        with tempfile.TemporaryDirectory(prefix='gait_nodes_run_') as tmp:
            params_file = Path(tmp) / 'graph_params.yaml'
            params_file.write_text(yaml.safe_dump(graph_params))
            # The namespace first: a user's own -r after it still wins.
            ros = ['--ros-args', '--params-file', str(params_file), *options.namespace_args,
                   *ros[1:]]
            if runtime_name == 'inproc':
                summary = run_inproc(options, names, ros)
            else:
                summary = run_processes(options, names, ros, runtime_name)
    except GaitNodesError as exc:
        return fail(PROG, exc)
    summary['scenario'] = options.scenario
    summary['namespace'] = options.namespace_args[1][len('__ns:='):] \
        if options.namespace_args else '/'
    if options.record:
        summary['bag'] = os.path.abspath(options.record)
        plot_dir = None if options.no_plot else (options.plot or
                                                  options.record.rstrip('/') + '_plots')
        summary['inspect'] = _inspect_recording(options.record, plot_dir,
                                                summary['namespace'])
        if not summary['topics']:
            summary['topics'] = summary['inspect'].get('topics', {})
        if 'plot_error' in summary['inspect']:
            print(f'{PROG}: error: {summary["inspect"]["plot_error"]}', file=sys.stderr)
    video_status = 0
    if options.video is not None and options.json:
        video_status = _render_video(options, summary)
    print_summary(summary, options.json)
    if options.video is not None and not options.json:
        video_status = _render_video(options, summary)
        if 'video' in summary:
            print(f'  video: {summary["video"]["description"]}')
    failed = [name for name, code in summary['exit_codes'].items() if code != 0]
    incomplete = summary.get('recording_error') or 'plot_error' in summary.get('inspect', {})
    return 1 if failed or incomplete or video_status else 0


def _render_video(options, summary: dict) -> int:
    """Render the recorded walk as ``options.video`` (0), or say why not on stderr (1)."""
    from gait_nodes.bag.video import VideoSettings
    from gait_nodes.inspect import render_video, scenario_staircase

    if 'error' in summary.get('inspect', {}):
        print(f'{PROG}: error: --video {options.video}: the bag cannot be read', file=sys.stderr)
        return 1
    staircase = scenario_staircase(get_scenario(options.scenario))
    return render_video(options.record, options.video, (VideoSettings(), staircase),
                        options.robot, summary['namespace'], summary, prog=PROG)


if __name__ == '__main__':
    sys.exit(main())
