#!/usr/bin/env python3
"""Gait commands while walking: safe, answered, applied once, and off the control path (issue 25).

    python bench/commands.py [--runtimes dds,rclpy] [--busy 0,2] [--duration S]
                             [--scenarios robosimian_commands,biped_commands,go2_commands]
                             [--keep DIR]

Each run is ``python -m gait_nodes run --runtime R --scenario S --record BAG`` (the scenario's
own duration unless ``--duration``; one
process per node, as a user starts it) with ``--busy N`` competing busy processes on the cores
(``bench/cpu.py``'s BusyLoad). The scenarios send a gait command or a velocity every 3 s
(``gait_nodes.scenarios.COMMAND_SCENARIOS``: step height, length, period, duty factor, gait and
swing, speed and direction, stop and go). Printed per run, from the recorded bag (the launcher's
own inspection, :mod:`gait_nodes.bag.analysis`):

- ZMP samples outside the support polygon (of all), the least margin;
- /joint_commands samples over their velocity limit, the peak ratio to the limit;
- the gait commands: sent, answered, accepted, applied, rejected (with the reasons), superseded,
  the most decisions and 'applied' answers one command got (1: exactly once);
- ERROR statuses by name, and whether the planner paused or stopped at a safe stand;
- the whole-body IK's velocity saturation reports (WARN: joints it had to slow down; the plan
  should never need it);
- the distance walked.

Then, per node and callback (``GAIT_NODES_CALLBACK_TIMES``: every timer and subscription
callback each node runs, and the planning worker's jobs, which run beside them), the median,
p99 and max duration in milliseconds over all runs of that runtime. rclpy is measured when it is
importable (source a ROS 2 Jazzy first); otherwise the reason is printed. Figures only: no
thresholds are asserted.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from cpu import (  # noqa: E402
    REPO,
    BusyLoad,
    child_env,
    last_json_object,
    pause_reports,
    rclpy_absent_reason,
)

sys.path.insert(0, str(REPO))
from gait_nodes.callback_times import ENVIRONMENT  # noqa: E402
from gait_nodes.scenarios import COMMAND_SCENARIOS, get_scenario  # noqa: E402

#: Seconds a run may take beyond its walk (start-up, a value table, the bag's inspection).
EXTRA_S = 240.0
#: The whole-body IK's report of joints it had to slow down.
SATURATION = 'whole_body_ik: velocity saturation'


def run_once(runtime: str, scenario: str, duration_s: float, busy: int, out: Path) -> dict:
    """One walk: its summary, the bag's diagnostics and the callback durations."""
    name = f'{scenario}-{runtime}-busy{busy}'
    bag, times = out / name, out / f'{name}-callbacks'
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', runtime, '--scenario',
               scenario, '--duration', str(duration_s), '--record', str(bag), '--no-plot',
               '--json']
    with BusyLoad(busy), open(out / f'{name}.log', 'w') as log:
        done = subprocess.run(command, stdout=subprocess.PIPE, stderr=log, text=True,
                              env={**child_env(), ENVIRONMENT: str(times)},
                              timeout=duration_s + EXTRA_S, check=False)
    summary = last_json_object(done.stdout) or {}
    result = {'name': name, 'runtime': runtime, 'scenario': scenario, 'busy': busy,
              'exit': done.returncode, 'summary': summary, 'callbacks': {}}
    for path in sorted(times.glob('*.json')) if times.is_dir() else []:
        data = json.loads(path.read_text())
        for callback, durations in data['callbacks'].items():
            result['callbacks'].setdefault((data['node'], callback), []).extend(durations)
    result['errors'], result['pauses'], result['saturated'] = bag_reports(bag)
    return result


def bag_reports(bag: Path) -> tuple[dict[str, int], int, list[str]]:
    """ERROR statuses by name, the planner's pause reports and the IK's saturation WARNs."""
    from gait_nodes.bag.reader import BagReader
    from gait_nodes.diagnostics import ERROR, WARN, level_value
    from gait_nodes.errors import GaitNodesError
    from gait_nodes.interfaces import deserialize_message, get_message

    array = get_message('diagnostic_msgs/msg/DiagnosticArray')
    errors: dict[str, int] = {}
    statuses = []
    saturated = []
    try:
        for _, log_ns, _, data in BagReader(bag).messages(topics=['/diagnostics']):
            for status in deserialize_message(data, array).status:
                level = level_value(status.level)
                statuses.append((log_ns, status.name, level, status.message))
                if level >= ERROR:
                    errors[status.name] = errors.get(status.name, 0) + 1
                if status.name == SATURATION and level >= WARN:
                    saturated.append(status.message)
    except GaitNodesError as exc:
        errors[f'unreadable bag: {exc}'] = 1
    return errors, len(pause_reports(statuses)), saturated


def sent_commands(scenario: str) -> int:
    """Gait commands the scenario sends."""
    return sum(1 for command in get_scenario(scenario).commands if command.command is not None)


def print_run(result: dict) -> None:
    """One run's line block."""
    gait = (result['summary'].get('inspect') or {}).get('gait') or {}
    zmp, commands = gait.get('zmp_margin') or {}, gait.get('commands') or {}
    joints = (gait.get('joint_velocity') or {}).get('/joint_commands') or {}
    base = gait.get('base') or {}
    print(f'{result["name"]} (exit {result["exit"]})')
    print(f'  ZMP outside: {zmp.get("samples_outside")} of {zmp.get("samples")} samples, least '
          f'margin {1000 * zmp.get("min_m", float("nan")):.1f} mm')
    print(f'  /joint_commands over the limit: {joints.get("samples_over_limit")} of '
          f'{joints.get("samples")}, peak {joints.get("peak_ratio_to_limit")} of the limit')
    print(f'  commands: {sent_commands(result["scenario"])} sent, {commands.get("answered")} '
          f'answered: {commands.get("accepted")} accepted ({commands.get("applied")} applied), '
          f'{commands.get("rejected")} rejected, {commands.get("superseded")} superseded; most '
          f'decisions on one {commands.get("most_decisions")}, most applied '
          f'{commands.get("most_applied")}')
    for reason in commands.get('rejections') or []:
        print(f'    rejected: {reason[:160]}')
    print(f'  ERROR statuses: {result["errors"] or "none"}; planner paused '
          f'{result["pauses"]} time(s)')
    print(f'  IK velocity saturation reports: {len(result["saturated"])}'
          + ''.join(f'\n    {message[:160]}' for message in result['saturated'][:5]))
    print(f'  walked {base.get("displacement_m")} m net in {base.get("time_s")} s')


def print_callbacks(runtime: str, results: list[dict]) -> None:
    """Median, p99 and max duration per node and callback over ``results``."""
    merged: dict[tuple[str, str], list[float]] = {}
    for result in results:
        for key, durations in result['callbacks'].items():
            merged.setdefault(key, []).extend(durations)
    if not merged:
        print(f'{runtime}: no callback durations recorded')
        return
    print(f'\ncallback durations, {runtime} (all runs) [ms]')
    print(f'  {"node":24s} {"callback":28s} {"calls":>7s} {"median":>8s} {"p99":>8s} '
          f'{"max":>9s}')
    for (node, callback), durations in sorted(merged.items()):
        ordered = sorted(durations)
        p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
        print(f'  {node:24s} {callback:28s} {len(ordered):7d} '
              f'{1000 * statistics.median(ordered):8.3f} {1000 * p99:8.3f} '
              f'{1000 * ordered[-1]:9.3f}')


def main() -> None:
    """Run every runtime x scenario x load and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runtimes', default='dds,rclpy')
    parser.add_argument('--scenarios', default=','.join(s.name for s in COMMAND_SCENARIOS))
    parser.add_argument('--busy', default='0,2', help='competing busy processes, per run')
    parser.add_argument('--duration', type=float, help="default: each scenario's own")
    parser.add_argument('--keep', type=Path, help='keep the bags and logs here')
    options = parser.parse_args()
    runtimes = options.runtimes.split(',')
    if 'rclpy' in runtimes and rclpy_absent_reason():
        print(f'rclpy: not measured: {rclpy_absent_reason()}')
        runtimes.remove('rclpy')
    out = options.keep or Path(tempfile.mkdtemp(prefix='gait_commands_'))
    out.mkdir(parents=True, exist_ok=True)
    results: dict[str, list[dict]] = {runtime: [] for runtime in runtimes}
    for runtime in runtimes:
        for scenario in options.scenarios.split(','):
            for busy in (int(b) for b in options.busy.split(',')):
                duration_s = options.duration or get_scenario(scenario).duration_s
                result = run_once(runtime, scenario, duration_s, busy, out)
                results[runtime].append(result)
                print_run(result)
                sys.stdout.flush()
    for runtime, runs in results.items():
        print_callbacks(runtime, runs)
    print(f'\nbags and logs: {out}')


if __name__ == '__main__':
    main()
