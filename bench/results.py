"""The results table of docs/benchmarks.md: every scenario walked and inspected.

Runs, with the project's own commands and nothing else:

- ``python -m gait_nodes run --runtime inproc --scenario NAME --record DIR --no-plot --json``
  for each scenario, and reads the gait summary of the bag it recorded (the numbers
  ``python -m gait_nodes.inspect DIR`` prints; definitions in gait_nodes/bag/analysis.py).

The thesis' figures, its step-size sweep among them, come from ``python -m gait_nodes.thesis``.

It prints a Markdown table (also written to ``--out``). Speeds are net speeds, displacement of
base_link in odom over a time, so a crawl's sideways sway does not count as progress: over the
whole run (start-up and stop included), while stepping (from the first executed lift-off
to the last touch-down), and steady (whole gait cycles after the first: inspect's ``steady``);
the commanded speed is the scenario's first /cmd_vel.

    python bench/results.py [--scenarios a,b] [--out results.md] [--json rows.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # this tree's gait_nodes, not an installed one
    sys.path.insert(0, str(REPO))

from gait_nodes.scenarios import SCENARIOS  # noqa: E402


def stepping_speed(bag: Path) -> float | None:
    """Base displacement from the first executed lift-off to the last touch-down, per second."""
    from gait_nodes.bag.analysis import executed_swings, inspect_bag, net_speed

    series = inspect_bag(bag).series
    base = np.array(sorted(series.base))
    if len(base) < 2 or not series.plans:
        return None
    swings = executed_swings(series.plans, int(base[-1, 0]))
    if not swings:
        return None
    return net_speed(base, min(s['lift_off_ns'] for s in swings),
                     max(s['touch_down_ns'] for s in swings))


def run_scenario(name: str, folder: Path) -> dict:
    """Walk scenario ``name`` in inproc with recording; its run summary (JSON)."""
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--scenario',
               name, '--record', str(folder / name), '--no-plot', '--json']
    started = time.perf_counter()
    path = os.environ.get('PYTHONPATH')
    env = dict(os.environ, PYTHONPATH=str(REPO) + (os.pathsep + path if path else ''))
    result = subprocess.run(command, capture_output=True, text=True, env=env, check=False)
    if result.returncode != 0:
        raise SystemExit(f'{" ".join(command)} failed ({result.returncode}):\n{result.stderr}')
    summary = json.loads(result.stdout)
    summary['command_wall_s'] = time.perf_counter() - started
    summary['stepping_speed_m_s'] = stepping_speed(folder / name)
    return summary


def scenario_row(name: str, summary: dict) -> dict:
    """One table row from a run summary."""
    scenario = SCENARIOS[name]
    gait = (summary.get('inspect') or {}).get('gait') or {}
    base = gait.get('base') or {}
    steps = gait.get('steps') or {}
    margin = gait.get('zmp_margin') or {}
    joints = (gait.get('joint_velocity') or {}).get('/joint_states') or {}
    levels = (gait.get('diagnostics') or {}).get('by_level') or {}
    commanded = next((c.velocity[0] for c in scenario.commands if c.velocity), None)
    return {
        'scenario': name, 'robot': scenario.robot,
        'gait': scenario.settings.get('gait', 'auto'),
        'swing': scenario.settings.get('swing', '-'),
        'com': scenario.settings.get('com_method', '-'),
        'commanded_m_s': commanded, 'net_speed_m_s': base.get('net_speed_m_s'),
        'stepping_speed_m_s': summary.get('stepping_speed_m_s'),
        'steady_speed_m_s': (gait.get('steady') or {}).get('net_speed_m_s'),
        'steps': steps.get('count', 0), 'mean_step_m': steps.get('mean_length_m'),
        'margin_min_mm': None if margin.get('min_m') is None else 1000 * margin['min_m'],
        'margin_mean_mm': None if margin.get('mean_m') is None else 1000 * margin['mean_m'],
        'outside_s': margin.get('time_outside_s'),
        'joint_peak_ratio': joints.get('peak_ratio_to_limit'),
        'errors': levels.get('ERROR', 0), 'warnings': levels.get('WARN', 0),
        'real_time_factor': summary.get('real_time_factor'),
    }


def _number(value, digits: int) -> str:
    return '-' if value is None else f'{value:.{digits}f}'


def markdown(rows: list[dict]) -> str:
    """The results as a Markdown table."""
    lines = ['| scenario | robot | gait | swing | COM | commanded [m/s] | speed: run / '
             'stepping / steady [m/s] | steps (mean [m]) | ZMP margin min / mean [mm] '
             '| outside [s] | joint vel. peak / limit | ERROR / WARN | real-time factor |',
             '| --- ' * 13 + '|']
    for r in rows:
        lines.append(
            f'| `{r["scenario"]}` | {r["robot"]} | {r["gait"]} | {r["swing"]} | {r["com"]} '
            f'| {_number(r["commanded_m_s"], 3)} | {_number(r["net_speed_m_s"], 4)} / '
            f'{_number(r["stepping_speed_m_s"], 4)} / {_number(r["steady_speed_m_s"], 4)} '
            f'| {r["steps"]} ({_number(r["mean_step_m"], 3)}) '
            f'| {_number(r["margin_min_mm"], 1)} / {_number(r["margin_mean_mm"], 1)} '
            f'| {_number(r["outside_s"], 3)} | {_number(r["joint_peak_ratio"], 2)} '
            f'| {r["errors"]} / {r["warnings"]} | {_number(r["real_time_factor"], 1)}x |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the scenarios; print (and write) the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenarios', default=','.join(SCENARIOS),
                        help='comma-separated scenario names (default: all)')
    parser.add_argument('--out', default=None, help='also write the Markdown to this file')
    parser.add_argument('--json', default=None, help='write the raw rows as JSON')
    options = parser.parse_args(argv)
    names = [n.strip() for n in options.scenarios.split(',') if n.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        parser.error(f'unknown scenario(s) {unknown}; scenarios: {", ".join(SCENARIOS)}')
    rows = []
    with tempfile.TemporaryDirectory(prefix='gait_results_') as tmp:
        for name in names:
            summary = run_scenario(name, Path(tmp))
            rows.append(scenario_row(name, summary))
            print(f'{name}: ran in {summary["command_wall_s"]:.1f} s', file=sys.stderr)
    text = markdown(rows)
    print(text)
    if options.out:
        Path(options.out).write_text(text + '\n')
    if options.json:
        Path(options.json).write_text(json.dumps({'scenarios': rows}, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
