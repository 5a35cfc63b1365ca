#!/usr/bin/env python3
"""CPU budget of the node graph, per node and whole, and how the walk went (issue 18, 2 and 3).

    python bench/cpu.py [--runtimes dds,rclpy] [--duration 40] [--runs 3] [--busy N]
                        [--scenario NAME] [--settle 10] [--inproc-durations 10 60] [--keep DIR]

1. Steady CPU per node: ``python -m gait_nodes run --runtime R --scenario S --duration D
   --record BAG`` (one process per node), and each node process's own CPU time (utime + stime
   from /proc/PID/stat, its children excluded) read at two instants of the walk: ``--settle``
   seconds after the walk starts (the launcher starts the walk once every node has written its
   ready file; this script watches the same files) and 3 s before its end. Printed: CPU-seconds
   per second walked for each node, the graph without the recorder and with it, and the
   launcher's own (it counts every topic: harness, not graph). Medians of ``--runs`` runs.
2. The same under rclpy when rclpy is importable (source a ROS 2 Jazzy first), in a column beside
   dds; otherwise the reason it is absent.
3. The inproc graph beside them: ``python -m gait_nodes run --runtime inproc --duration D`` for
   two simulated durations; wall and CPU time per simulated second from their difference (start-up
   cancels), and the real-time factor of the longer run.
4. Stream rates from each bag (recorder log times, between the two CPU instants), against the
   nominal rates read from the node parameter defaults (``config/*.yaml`` plus the scenario's
   settings), with the deviation in %. /gait/markers counts the simulator's arrays only: the
   footstep planner's and the swing policy's come with each plan and each swing, at no rate
   a parameter sets.
5. The walk, from the launcher's own inspection of the bag (:mod:`gait_nodes.bag.analysis`): ZMP
   samples outside the support polygon, the worst excursion beyond it against the robot's foot
   radius, ERROR and WARN statuses by name, distance walked, and whether the planner paused.
   ``--busy N`` runs N competing busy processes for the whole bench (``stress-ng --cpu N`` when
   installed, else N Python busy loops at this script's nice value).

Every run uses this script's environment: set ``ROS_DOMAIN_ID`` and ``CYCLONEDDS_URI`` so that
other graphs on the machine do not mix with the measured one. The tree this script is in goes
first on the nodes' PYTHONPATH. Figures only: no thresholds are asserted. Timing on a shared
machine is noisy: compare runs made side by side.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from gait_nodes.cli import READY_FILE_ENV  # noqa: E402
from gait_nodes.scenarios import DEFAULT_SCENARIO, SCENARIOS, get_scenario  # noqa: E402

NS = 1_000_000_000
#: CPU window ends this long before the walk does [s] (the launcher stops the nodes then).
END_MARGIN_S = 3.0
#: Longest wait for the graph to start [s] (a swing value table may be built on first use).
START_TIMEOUT_S = 900.0
#: Time after its end for the launcher to stop the nodes and inspect the bag [s].
FINISH_TIMEOUT_S = 600.0
#: A stream this far below its nominal rate [%] means its node fell behind its period.
SATURATED_PERCENT = 2.0
#: Streams the simulator publishes once a tick (rate_hz).
SIMULATOR_TOPICS = ('/joint_states', '/tf', '/gait/zmp', '/gait/com', '/gait/support_polygon')


# --------------------------------------------------------------------------------------------
# pure helpers
# --------------------------------------------------------------------------------------------

def parse_proc_stat(text: str) -> tuple[int, int, int]:
    """(ppid, utime, stime) from the text of /proc/PID/stat, times in clock ticks.

    The command name (field 2) is in parentheses and may hold spaces and parentheses itself,
    so the fields are counted from its last closing parenthesis (proc(5)).

    Raises:
        ValueError: The text is not a /proc/PID/stat line.
    """
    head, sep, tail = text.rpartition(')')
    fields = tail.split()
    if not sep or '(' not in head or len(fields) < 13:
        raise ValueError(f'not a /proc/PID/stat line: {text[:80]!r}')
    # proc(5) numbering: 3 state, 4 ppid, ..., 14 utime, 15 stime; tail starts at field 3.
    return int(fields[1]), int(fields[11]), int(fields[12])


def median(values) -> float | None:
    """Median of the values that are not None (None when there are none)."""
    kept = [v for v in values if v is not None]
    return statistics.median(kept) if kept else None


def stream_rate_hz(log_times_ns, start_ns: int, end_ns: int) -> float | None:
    """Mean rate [Hz] of a stream between two instants: (n - 1) / (last - first) inside them.

    None when fewer than two messages fall in ``[start_ns, end_ns]``.
    """
    inside = sorted(t for t in log_times_ns if start_ns <= t <= end_ns)
    if len(inside) < 2 or inside[-1] == inside[0]:
        return None
    return (len(inside) - 1) * NS / (inside[-1] - inside[0])


def deviation_percent(measured_hz: float | None, nominal_hz: float | None) -> float | None:
    """Signed deviation of a measured rate from the nominal one [%]."""
    if measured_hz is None or not nominal_hz:
        return None
    return 100.0 * (measured_hz - nominal_hz) / nominal_hz


def nominal_rates(defaults: dict[str, dict], settings: dict | None = None) -> dict[str, float]:
    """Nominal rate [Hz] of each periodic stream, from the nodes' parameters.

    Args:
        defaults: Node name -> its parameter values (``config/<node>.yaml``).
        settings: Values sent to every node (the scenario's ``/**`` section); they override the
            defaults of the parameters a node has.

    The COM controller publishes every ``publish_period_s`` when it has that parameter, else
    every ``dt_s``. The simulator's markers come at ``markers_rate_hz``, at most one per
    simulator tick (the planner's and the swing policy's on /gait/markers have no nominal rate:
    :func:`read_bag` leaves them out).
    /tf carries the simulator's base pose every tick and, with robot_state_publisher, its links'
    at ``publish_frequency`` (0: every tick), at most one per tick.
    """
    settings = settings or {}

    def value(node: str, name: str):
        params = defaults.get(node) or {}
        if name not in params:
            return None
        return settings.get(name, params[name])

    rates = {}
    planner = value('footstep_planner', 'rate_hz')
    if planner:
        rates['/gait/zmp_reference'] = float(planner)
    period = value('com_preview_controller', 'publish_period_s') or \
        value('com_preview_controller', 'dt_s')
    if period:
        rates['/gait/com_reference'] = 1.0 / float(period)
    ik = value('whole_body_ik', 'rate_hz')
    if ik:
        rates['/joint_commands'] = float(ik)
    simulator = value('kinematic_simulator', 'rate_hz')
    if simulator:
        for topic in SIMULATOR_TOPICS:
            rates[topic] = float(simulator)
        if value('kinematic_simulator', 'publish_clock'):
            rates['/clock'] = float(simulator)
        markers = value('kinematic_simulator', 'markers_rate_hz')
        if markers and value('kinematic_simulator', 'publish_markers') is not False:
            rates['/gait/markers'] = min(float(markers), float(simulator))
        links = value('robot_state_publisher', 'publish_frequency')
        if links is not None:
            rates['/tf'] += min(float(links), float(simulator)) if links else float(simulator)
    return rates


def pause_reports(statuses) -> list[int]:
    """Stamps [ns] of the planner's 'paused' reports among ``(stamp_ns, name, level, message)``."""
    return [stamp for stamp, name, level, message in statuses
            if name.endswith('footstep_planner: walk') and level >= 1
            and message.startswith('paused')]


def last_json_object(text: str) -> dict | None:
    """The last JSON object in ``text`` that starts on a line of its own (None if none)."""
    decoder = json.JSONDecoder()
    starts = [i for i in range(len(text)) if text[i] == '{' and (i == 0 or text[i - 1] == '\n')]
    for start in reversed(starts):
        try:
            value, _ = decoder.raw_decode(text, start)
        except json.JSONDecodeError:
            continue
        if isinstance(value, dict):
            return value
    return None


# --------------------------------------------------------------------------------------------
# processes
# --------------------------------------------------------------------------------------------

def process_cpu_s(pid: int) -> float | None:
    """Own CPU time (user + system, children excluded) of a live process [s]; None if gone."""
    try:
        _, utime, stime = parse_proc_stat(Path(f'/proc/{pid}/stat').read_text())
    except (OSError, ValueError):
        return None
    return (utime + stime) / os.sysconf('SC_CLK_TCK')


def child_processes(parent: int) -> dict[int, str]:
    """PID -> node name (``gait_nodes.<name>`` of its command line) of ``parent``'s children."""
    children = {}
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid, _, _ = parse_proc_stat((entry / 'stat').read_text())
            if ppid != parent:
                continue
            argv = (entry / 'cmdline').read_bytes().decode(errors='replace').split('\0')
        except (OSError, ValueError):
            continue
        module = next((a for a in argv if a.startswith('gait_nodes.')), None)
        if module:
            children[int(entry.name)] = module.split('.', 1)[1]
    return children


def ready_file(pid: int) -> Path | None:
    """The ready file the launcher gave a node (its environment's READY_FILE_ENV)."""
    try:
        environ = Path(f'/proc/{pid}/environ').read_bytes().split(b'\0')
    except OSError:
        return None
    prefix = READY_FILE_ENV.encode() + b'='
    entry = next((e for e in environ if e.startswith(prefix)), None)
    return Path(entry[len(prefix):].decode()) if entry else None


class BusyLoad:
    """N competing busy processes: ``stress-ng --cpu N`` if installed, else Python loops.

    The Python loops inherit this process's nice value, as the graph's nodes do.
    """

    def __init__(self, count: int):
        self.count = count
        self.processes: list[subprocess.Popen] = []
        self.kind = 'none'
        if count and shutil.which('stress-ng'):
            self.kind = f'stress-ng --cpu {count}'
        elif count:
            self.kind = f'{count} Python busy loop(s)'

    def __enter__(self) -> BusyLoad:
        if self.count and shutil.which('stress-ng'):
            self.processes.append(subprocess.Popen(
                ['stress-ng', '--cpu', str(self.count), '--quiet'], start_new_session=True))
        else:
            for _ in range(self.count):
                self.processes.append(subprocess.Popen(
                    [sys.executable, '-c', 'while True: pass'], start_new_session=True))
        return self

    def __exit__(self, *exc) -> None:
        for process in self.processes:
            # stress-ng forks its workers into its own session: stop the whole group we made.
            try:
                os.killpg(process.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for process in self.processes:
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


def child_env() -> dict[str, str]:
    """This environment with the tree of this script first on PYTHONPATH."""
    path = os.environ.get('PYTHONPATH')
    return dict(os.environ, PYTHONPATH=str(REPO) + (os.pathsep + path if path else ''))


def rclpy_absent_reason() -> str | None:
    """Why the rclpy column cannot be measured here (None when rclpy imports)."""
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        return f'rclpy is not importable ({exc}); source a ROS 2 Jazzy to add the column'
    return None


# --------------------------------------------------------------------------------------------
# one graph run
# --------------------------------------------------------------------------------------------

@dataclass
class GraphRun:
    """What one ``python -m gait_nodes run`` over processes measured."""

    runtime: str
    walked_s: float = 0.0
    cpu_per_s: dict[str, float | None] = field(default_factory=dict)
    window_ns: tuple[int, int] = (0, 0)
    rates_hz: dict[str, float | None] = field(default_factory=dict)
    summary: dict = field(default_factory=dict)
    pauses_ns: list[int] = field(default_factory=list)
    problem: str | None = None


def _sleep_until(deadline: float, launcher: subprocess.Popen) -> bool:
    """Sleep until the monotonic ``deadline``; False if the launcher exits first."""
    while time.monotonic() < deadline:
        if launcher.poll() is not None:
            return False
        time.sleep(min(0.05, max(deadline - time.monotonic(), 0.0)))
    return True


def _sample(pids: dict[int, str]) -> dict[str, float | None]:
    return {name: process_cpu_s(pid) for pid, name in pids.items()}


def _wait_walk_start(launcher: subprocess.Popen, expected: int) -> dict[int, str] | None:
    """Node PIDs once every node is ready (the walk starts then); None if the launcher exits."""
    deadline = time.monotonic() + START_TIMEOUT_S
    files: dict[int, Path | None] = {}
    while time.monotonic() < deadline and launcher.poll() is None:
        children = child_processes(launcher.pid)
        for pid in children:
            if files.get(pid) is None:
                files[pid] = ready_file(pid)
        if len(children) >= expected and all(
                files.get(pid) is not None and files[pid].exists() for pid in children):
            return children
        time.sleep(0.02)
    return None


def run_graph(runtime: str, scenario: str, duration_s: float, settle_s: float,
              bag: Path, log: Path) -> GraphRun:
    """Walk the graph once as processes, sampling each node's CPU inside the walk."""
    from gait_nodes import graph

    result = GraphRun(runtime)
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', runtime,
               '--scenario', scenario, '--duration', str(duration_s), '--record', str(bag),
               '--no-plot', '--json']
    expected = len(graph.available_nodes()) + 1  # and the recorder
    with open(log, 'w') as stderr, tempfile.TemporaryFile('w+') as stdout:
        launcher = subprocess.Popen(command, stdout=stdout, stderr=stderr, env=child_env(),
                                    start_new_session=True)
        try:
            pids = _wait_walk_start(launcher, expected)
            started = time.monotonic()
            samples = []
            if pids is not None:
                pids[launcher.pid] = 'launcher'
                for at_s in (settle_s, duration_s - END_MARGIN_S):
                    if not _sleep_until(started + at_s, launcher):
                        break
                    samples.append((time.time_ns(), time.monotonic(), _sample(pids)))
            launcher.wait(timeout=duration_s + FINISH_TIMEOUT_S)
        finally:
            if launcher.poll() is None:  # this script was stopped: stop the graph as Ctrl-C
                os.killpg(launcher.pid, signal.SIGINT)
                launcher.wait()
        stdout.seek(0)
        result.summary = last_json_object(stdout.read()) or {}
    if len(samples) < 2:
        result.problem = (f'the walk did not last to the second CPU sample (launcher exit '
                          f'{launcher.returncode}; log {log})')
        return result
    (wall0, mono0, cpu0), (wall1, mono1, cpu1) = samples
    result.walked_s = mono1 - mono0
    result.window_ns = (wall0, wall1)
    result.cpu_per_s = {name: (cpu1[name] - cpu0[name]) / result.walked_s
                        if cpu0.get(name) is not None and cpu1.get(name) is not None else None
                        for name in cpu0}
    if any(code for code in (result.summary.get('exit_codes') or {}).values()):
        result.problem = f'nodes exited with {result.summary["exit_codes"]} (log {log})'
    read_bag(result, bag)
    return result


def read_bag(result: GraphRun, bag: Path) -> None:
    """Stream rates in the CPU window and the planner's pause reports, from the bag."""
    from gait_nodes.bag.reader import BagReader
    from gait_nodes.diagnostics import level_value
    from gait_nodes.errors import GaitNodesError
    from gait_nodes.interfaces import deserialize_message, get_message
    from gait_nodes.markers import from_simulator

    times: dict[str, list[int]] = {}
    statuses = []
    array = get_message('diagnostic_msgs/msg/DiagnosticArray')
    marker_array = get_message('visualization_msgs/msg/MarkerArray')
    try:
        for channel, log_ns, _, data in BagReader(bag).messages():
            if channel.topic == '/gait/markers' and not from_simulator(
                    deserialize_message(data, marker_array)):
                continue  # a plan's or a swing's markers: not the periodic stream
            times.setdefault(channel.topic, []).append(log_ns)
            if channel.topic == '/diagnostics':
                msg = deserialize_message(data, array)
                statuses.extend((log_ns, s.name, level_value(s.level), s.message)
                                for s in msg.status)
    except GaitNodesError as exc:
        result.problem = f'{bag}: {exc}'
    start_ns, end_ns = result.window_ns
    result.rates_hz = {topic: stream_rate_hz(t, start_ns, end_ns) for topic, t in times.items()}
    result.pauses_ns = pause_reports(statuses)


def run_inproc(scenario: str, duration_s: float) -> dict:
    """One inproc run: its summary plus the CPU seconds of the whole process (start-up too)."""
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--scenario',
               scenario, '--duration', str(duration_s), '--json']
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, env=child_env(), check=False)
    elapsed = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    summary = last_json_object(done.stdout) or {}
    return {'cpu_s': (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
            'process_wall_s': elapsed, 'spin_wall_s': summary.get('wall_s'),
            'simulated_s': summary.get('simulated_s'),
            'real_time_factor': summary.get('real_time_factor'),
            'problem': None if done.returncode == 0 else
            f'exit {done.returncode}: {done.stderr.strip()[-300:]}'}


def inproc_figures(scenario: str, durations_s: tuple[float, float], runs: int) -> dict:
    """Wall and CPU per simulated second (longer minus shorter run) and the real-time factor."""
    short, long = durations_s
    rows = []
    for _ in range(runs):
        first, second = run_inproc(scenario, short), run_inproc(scenario, long)
        problem = first['problem'] or second['problem']
        simulated = (second['simulated_s'] or 0.0) - (first['simulated_s'] or 0.0)
        if problem or simulated <= 0:
            rows.append({'problem': problem or 'no simulated time'})
            continue
        rows.append({'cpu_per_s': (second['cpu_s'] - first['cpu_s']) / simulated,
                     'wall_per_s': (second['spin_wall_s'] - first['spin_wall_s']) / simulated,
                     'real_time_factor': second['real_time_factor'], 'problem': None})
    return {key: median(r.get(key) for r in rows)
            for key in ('cpu_per_s', 'wall_per_s', 'real_time_factor')} | {
        'problems': [r['problem'] for r in rows if r['problem']]}


# --------------------------------------------------------------------------------------------
# report
# --------------------------------------------------------------------------------------------

def _fmt(value, spec: str = '.3f', width: int = 0) -> str:
    text = '-' if value is None else format(value, spec)
    return f'{text:>{width}}' if width else text


def print_cpu_table(results: dict[str, list[GraphRun]], inproc: dict | None) -> None:
    """CPU-seconds per second walked: per node, graph, recorder, launcher."""
    from gait_nodes import graph

    nodes = [n for n in graph.NODES if any(n in r.cpu_per_s for rs in results.values()
                                           for r in rs)]
    runtimes = list(results)
    print('\nCPU-seconds per second walked (median of the runs; each run in brackets)')
    print(f'{"":30s}' + ''.join(f'{rt:>34s}' for rt in runtimes))

    def row(label: str, value_of) -> None:
        cells = []
        for rt in runtimes:
            values = [value_of(r) for r in results[rt] if r.cpu_per_s]
            each = ' '.join(_fmt(v, '.3f') for v in values)
            cells.append(f'{_fmt(median(values))} [{each}]')
        print(f'{label:30s}' + ''.join(f'{c:>34s}' for c in cells))

    def total(run: GraphRun, names) -> float | None:
        values = [run.cpu_per_s.get(n) for n in names]
        return None if any(v is None for v in values) else sum(values)

    for name in nodes:
        row(name, lambda r, name=name: r.cpu_per_s.get(name))
    row('graph without the recorder', lambda r: total(r, nodes))
    row('recorder', lambda r: r.cpu_per_s.get('recorder'))
    row('graph with the recorder', lambda r: total(r, [*nodes, 'recorder']))
    row('launcher (harness, not graph)', lambda r: r.cpu_per_s.get('launcher'))
    if inproc is not None:
        print(f'inproc (one process, simulated time): {_fmt(inproc["cpu_per_s"])} CPU-s and '
              f'{_fmt(inproc["wall_per_s"])} wall-s per simulated second, real-time factor '
              f'{_fmt(inproc["real_time_factor"], ".1f")}x'
              + (f'; problems: {inproc["problems"]}' if inproc['problems'] else ''))


def print_rate_table(results: dict[str, list[GraphRun]], nominal: dict[str, float]) -> None:
    """Each stream's rate in the CPU window against its nominal rate."""
    from gait_nodes import graph

    runtimes = list(results)
    print('\nStream rates in the CPU window (recorder log times; median of the runs) [Hz]')
    print(f'{"topic":24s}{"nominal":>9s}' + ''.join(f'{rt:>10s}{"dev %":>8s}' for rt in runtimes))
    topics = [t for t in graph.TOPICS if t in nominal or any(
        r.rates_hz.get(t) is not None for rs in results.values() for r in rs)]
    for topic in topics:
        cells = ''
        for rt in runtimes:
            rate = median(r.rates_hz.get(topic) for r in results[rt])
            deviation = deviation_percent(rate, nominal.get(topic))
            cells += f'{_fmt(rate, ".2f", 10)}{_fmt(deviation, "+.1f", 8)}'
        print(f'{topic:24s}{_fmt(nominal.get(topic), ".1f", 9)}{cells}')


def print_walk_table(results: dict[str, list[GraphRun]], foot_radius_m: float | None) -> None:
    """How each walk went, from the launcher's inspection of its bag."""
    radius = f'{foot_radius_m:.3f} m' if foot_radius_m is not None else 'unknown'
    print(f'\nThe walks (inspect definitions; a negative margin is the ZMP beyond the support '
          f'polygon, ! beyond it by more than the foot radius {radius})')
    print(f'{"runtime":8s}{"run":>4s}{"ZMP outside":>14s}{"least margin [m]":>18s}'
          f'{"ERROR":>7s}{"WARN":>6s}{"walked [m]":>12s}  paused')
    names: dict[tuple[str, str], int] = {}
    for rt, runs in results.items():
        for index, run in enumerate(runs):
            gait = (run.summary.get('inspect') or {}).get('gait') or {}
            margin = gait.get('zmp_margin') or {}
            diagnostics = gait.get('diagnostics') or {}
            levels = diagnostics.get('by_level') or {}
            outside = (f'{margin["samples_outside"]}/{margin["samples"]}' if margin else '-')
            worst = margin.get('min_m')
            # Beyond the polygon by more than a foot's radius: outside the foot itself.
            flag = ' !' if worst is not None and foot_radius_m is not None and \
                -worst > foot_radius_m else ''
            pauses = (f'yes, {len(run.pauses_ns)} report(s), first at '
                      f'{(run.pauses_ns[0] - run.window_ns[0]) / NS:+.1f} s of the CPU window'
                      if run.pauses_ns else 'no')
            print(f'{rt:8s}{index + 1:>4d}{outside:>14s}{_fmt(worst, "+.4f", 16)}{flag:2s}'
                  f'{levels.get("ERROR", 0):>7d}{levels.get("WARN", 0):>6d}'
                  f'{_fmt((gait.get("base") or {}).get("distance_m"), ".3f", 12)}  {pauses}')
            if run.problem:
                print(f'{"":12s}problem: {run.problem}')
            for name, counts in (diagnostics.get('by_name') or {}).items():
                for level in ('ERROR', 'WARN'):
                    if counts.get(level):
                        key = (f'{rt} {name}', level)
                        names[key] = names.get(key, 0) + counts[level]
    if names:
        print('ERROR/WARN statuses by name (summed over the runs):')
        for (name, level), count in sorted(names.items()):
            print(f'  {level:5s} {count:5d}  {name}')


def main() -> None:
    """Command line: measure, print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runtimes', default='dds,rclpy',
                        help='comma-separated process runtimes; rclpy is skipped, with the '
                             'reason, when not importable (default dds,rclpy)')
    parser.add_argument('--scenario', default=DEFAULT_SCENARIO,
                        help=f'{", ".join(SCENARIOS)} or default ({DEFAULT_SCENARIO})')
    parser.add_argument('--duration', type=float, default=40.0,
                        help='walk duration of each run [s] (default 40)')
    parser.add_argument('--settle', type=float, default=10.0,
                        help='first CPU sample this long after the walk starts [s] (default 10)')
    parser.add_argument('--runs', type=int, default=3, help='runs per runtime (default 3)')
    parser.add_argument('--busy', type=int, default=0, choices=(0, 1, 2),
                        help='competing busy processes during the whole bench (default 0)')
    parser.add_argument('--inproc-durations', type=float, nargs=2, default=(10.0, 60.0),
                        metavar=('SHORT', 'LONG'),
                        help='simulated seconds of the two inproc runs (default 10 60)')
    parser.add_argument('--no-inproc', action='store_true', help='skip the inproc figure')
    parser.add_argument('--keep', metavar='DIR', default=None,
                        help='keep the bags and logs in DIR (default: a temporary directory)')
    args = parser.parse_args()
    scenario = DEFAULT_SCENARIO if args.scenario == 'default' else args.scenario
    get_scenario(scenario)
    if args.duration - END_MARGIN_S <= args.settle + 1.0:
        parser.error(f'--duration {args.duration} s leaves no CPU window after --settle '
                     f'{args.settle} s and the last {END_MARGIN_S} s; give at least '
                     f'{args.settle + END_MARGIN_S + 1.0:g} s')

    from gait_nodes.paths import node_defaults
    from gait_nodes.robot.description import load_robot_description

    runtimes = [r.strip() for r in args.runtimes.split(',') if r.strip()]
    notes = []
    if 'rclpy' in runtimes and (reason := rclpy_absent_reason()):
        runtimes.remove('rclpy')
        notes.append(f'rclpy column absent: {reason}')
    workdir = Path(args.keep or tempfile.mkdtemp(prefix='bench_cpu_'))
    workdir.mkdir(parents=True, exist_ok=True)
    defaults = {}
    for node in ('footstep_planner', 'com_preview_controller', 'whole_body_ik',
                 'kinematic_simulator', 'robot_state_publisher'):
        defaults[node] = node_defaults(node)
    nominal = nominal_rates(defaults, get_scenario(scenario).settings)
    foot_radius = load_robot_description(get_scenario(scenario).robot).foot_radius_m

    load_at_start = os.getloadavg()
    results: dict[str, list[GraphRun]] = {rt: [] for rt in runtimes}
    inproc = None
    with BusyLoad(args.busy) as load:
        print(f'bench/cpu.py: scenario {scenario}, {args.duration:g} s walks, {args.runs} run(s)'
              f' per runtime ({", ".join(runtimes) or "none"}), busy load: {load.kind}, CPU '
              f'window from {args.settle:g} s to {args.duration - END_MARGIN_S:g} s of each '
              f'walk; ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "unset")}; bags in '
              f'{workdir}', flush=True)
        import gait_nodes

        print(f'gait_nodes from {Path(gait_nodes.__file__).parent}; Python '
              f'{sys.version.split()[0]}'
              + (f'; RMW_IMPLEMENTATION={os.environ.get("RMW_IMPLEMENTATION", "unset")}'
                 if 'rclpy' in runtimes else ''), flush=True)
        for note in notes:
            print(note, flush=True)
        for index in range(args.runs):
            for rt in runtimes:  # alternated, so that a drift of the machine hits both
                tag = f'{rt}_{index + 1}'
                run = run_graph(rt, scenario, args.duration, args.settle,
                                workdir / f'bag_{tag}', workdir / f'log_{tag}.txt')
                results[rt].append(run)
                graph_cpu = sum(v for k, v in run.cpu_per_s.items()
                                if v is not None and k not in ('launcher', 'recorder'))
                print(f'  {tag}: graph {graph_cpu:.3f} CPU-s/s over {run.walked_s:.1f} s'
                      + (f'; {run.problem}' if run.problem else ''), flush=True)
        if not args.no_inproc:
            inproc = inproc_figures(scenario, tuple(args.inproc_durations), args.runs)
    print_cpu_table(results, inproc)
    print_rate_table(results, nominal)
    print_walk_table(results, foot_radius)
    late = sorted({rt for rt, runs in results.items() for run in runs for topic, rate in
                   run.rates_hz.items() if (deviation_percent(rate, nominal.get(topic)) or 0.0)
                   < -SATURATED_PERCENT})
    if late:
        print(f'\nNote: streams ran more than {SATURATED_PERCENT:g} % below nominal under '
              f'{", ".join(late)}: their nodes fell behind their periods (too little CPU, or '
              f'late timers), so those CPU figures are what the nodes used, not what they '
              f'would need at the nominal rates.')
    print('Load average (1, 5, 15 min) at the start: '
          + ' '.join(f'{v:.2f}' for v in load_at_start)
          + '; at the end: ' + ' '.join(f'{v:.2f}' for v in os.getloadavg())
          + f' ({os.cpu_count()} CPUs; other jobs on the machine count too)')


if __name__ == '__main__':
    main()
