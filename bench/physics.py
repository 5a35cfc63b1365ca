#!/usr/bin/env python3
"""Every scenario walked by the kinematic simulator and by the physics simulator, side by side.

``python bench/physics.py [--scenario NAME ...] [--duration S] [--keep DIR] [--video DIR]``

Without ``--scenario``, every scenario of :data:`SCENARIOS` (the default static crawl first),
each for its own duration or :data:`LEAST_SECONDS` if that is longer (issue 27's 30 s: go2_trot's
20 s become 30 of trotting, biped_walk's 21 s become 30, the last 20 standing after its stop).
Each run is ``python -m gait_nodes run --fast --scenario S --simulator K --record BAG --json``,
one process per run; the figures come from its bag and its summary:

- **distance**: base x, last minus first (/tf); the physics run's over the kinematic run's;
- **ZMP margin**: least signed distance of /gait/zmp to /gait/support_polygon (inspect's): the
  planned ZMP in the feet's discs (kinematic), the ZMP of the simulated motion in the actual
  contact polygon (physics), and the samples outside;
- **CoP margin** (physics): least signed distance of /gait/cop to the contact polygon of the same
  tick (a segment or a point, when the feet in contact are points on a line, has no inside: a
  CoP on it counts 0), median, samples more than 1 um outside;
- **base tracking**: the physics base against the kinematic base at the same stamps (largest
  horizontal and vertical distance) and its largest roll and pitch; a run whose roll or pitch
  passes 10 degrees or whose base drops 0.15 m below the kinematic one **fell** (when is said);
- **feet tracking**: feet at touch-down against /gait/footsteps and each foot's drift over the
  time its plan has it in stance (3-D, so a foot that lands late counts the rest of its way
  down), from the joint states and the base with the full model (inspect's physics
  consistency); and the stance feet's **slip** as the physics simulator measures it (its
  /diagnostics 'contacts' status: how far the foot's material at its contact moved horizontally
  since it touched down, while the ground pushes on it; :mod:`gait_nodes.sim.physics`);
- **torques**: the drives' largest |effort| (/joint_states) over the URDF's effort limit, and the
  share of samples with a drive at its limit;
- **speed**: the inproc real-time factor (simulated over wall time of the walk) and the CPU
  seconds of the whole command (start-up, the walk, the bag read back);
- **issue 27's bounds** (physics): base height within 3 cm of the kinematic run and roll and
  pitch within 3 degrees at every stamp, distance within 5 %, the simulator's slip under 5 mm,
  the CoP inside the contact polygon at every sample, no drive at its effort limit.

The table at the end is Markdown (docs/physics.md's).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from gait_nodes import graph
from gait_nodes.bag.reader import BagReader
from gait_nodes.contract import base_transforms, time_msg_to_ns
from gait_nodes.geometry import signed_distance
from gait_nodes.interfaces import deserialize_message, get_message
from gait_nodes.robot.model import load_robot_model
from gait_nodes.scenarios import get_scenario
from gait_nodes.sim.mujoco_model import urdf_effort_limits

#: The scenarios of issue 27 (the default first).
SCENARIOS = ('robosimian_static_crawl', 'robosimian_crawl', 'robosimian_crawl_polynomial',
             'biped_walk', 'biped_stairs', 'go2_trot', 'online')
#: A run fell when its base rolls or pitches past this [deg] ...
FALL_TILT_DEG = 10.0
#: ... or drops this far below the kinematic run's [m].
FALL_DROP_M = 0.15
#: A CoP this close outside its contact polygon is on it [m] (rounding: a CoP of two point
#: contacts is on their segment).
COP_TOLERANCE_M = 1e-6
#: Issue 27's bounds.
BOUND_HEIGHT_M, BOUND_TILT_DEG, BOUND_DISTANCE, BOUND_SLIP_M = 0.03, 3.0, 0.05, 0.005
#: Issue 27: every scenario walks in physics for at least this long [s] (a shorter scenario's
#: own duration is stretched to it).
LEAST_SECONDS = 30.0


def _rpy(qx, qy, qz, qw):
    roll = math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (qw * qy - qz * qx))))
    return math.degrees(roll), math.degrees(pitch)


def read(bag: Path) -> dict:
    """Base poses, joint efforts, CoP and support polygons of a bag, by stamp."""
    types = {t: graph.TOPICS[t] for t in ('/tf', '/joint_states', '/gait/cop',
                                          '/gait/support_polygon', '/diagnostics')}
    data = {'base': {}, 'effort': [], 'cop': {}, 'polygon': {}, 'names': None, 'slip': None}
    for channel, _, _, payload in BagReader(bag).messages(topics=types):
        msg = deserialize_message(payload, get_message(types[channel.topic]))
        if channel.topic == '/tf':
            for t in base_transforms(msg):
                p, r = t.transform.translation, t.transform.rotation
                data['base'][time_msg_to_ns(t.header.stamp)] = (p.x, p.y, p.z,
                                                               *_rpy(r.x, r.y, r.z, r.w))
        elif channel.topic == '/joint_states':
            data['names'] = list(msg.name)
            if len(msg.effort):
                data['effort'].append(np.abs(np.array(msg.effort)))
        elif channel.topic == '/diagnostics':
            for status in msg.status:
                if status.name.endswith('contacts'):
                    values = {v.key: v.value for v in status.values}
                    if 'max_slip_m' in values:
                        data['slip'] = max(data['slip'] or 0.0, float(values['max_slip_m']))
        elif channel.topic == '/gait/cop':
            data['cop'][time_msg_to_ns(msg.header.stamp)] = (msg.point.x, msg.point.y)
        else:
            data['polygon'][time_msg_to_ns(msg.header.stamp)] = np.array(
                [(p.x, p.y) for p in msg.polygon.points])
    return data


def run(scenario: str, simulator: str, duration: float | None, bag: Path) -> tuple[dict, float]:
    """Walk once: the run's JSON summary and the CPU seconds of the command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--fast', '--scenario', scenario,
               '--simulator', simulator, '--record', str(bag), '--no-plot', '--json']
    if duration:
        command += ['--duration', str(duration)]
    out = subprocess.run(command, check=True, capture_output=True, text=True).stdout
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads(out), cpu


def _gait(summary: dict) -> dict:
    return (summary.get('inspect') or {}).get('gait') or {}


def compare(scenario: str, runs: dict) -> dict:
    """The figures of one scenario (see the module docstring); None where not measured."""
    (k_summary, k_cpu, k), (p_summary, p_cpu, p) = runs['kinematic'], runs['physics']
    robot = load_robot_model(get_scenario(scenario).robot)
    common = sorted(set(k['base']) & set(p['base']))
    kb = np.array([k['base'][t] for t in common])
    pb = np.array([p['base'][t] for t in common])
    t_s = (np.array(common) - common[0]) * 1e-9
    tilt = np.maximum(np.abs(pb[:, 3]), np.abs(pb[:, 4]))
    drop = kb[:, 2] - pb[:, 2]
    fallen = np.flatnonzero((tilt > FALL_TILT_DEG) | (drop > FALL_DROP_M))
    row = {'scenario': scenario, 'robot': robot.name, 'seconds': float(t_s[-1]),
           'fell_at_s': float(t_s[fallen[0]]) if len(fallen) else None}
    row['distance_m'] = (float(kb[-1, 0] - kb[0, 0]), float(pb[-1, 0] - pb[0, 0]))
    row['distance_ratio'] = row['distance_m'][1] / row['distance_m'][0] \
        if abs(row['distance_m'][0]) > 1e-6 else None
    row['base_xy_m'] = float(np.hypot(*(pb[:, :2] - kb[:, :2]).T).max())
    row['base_z_m'] = float(np.abs(pb[:, 2] - kb[:, 2]).max())
    row['roll_pitch_deg'] = (float(np.abs(pb[:, 3]).max()), float(np.abs(pb[:, 4]).max()))
    for name, summary in (('kinematic', k_summary), ('physics', p_summary)):
        gait = _gait(summary)
        margin = gait.get('zmp_margin') or {}
        row[f'zmp_{name}'] = (margin.get('min_m'), margin.get('samples_outside'),
                              margin.get('samples'))
        checks = gait.get('consistency') or {}
        row[f'footholds_{name}_m'] = (checks.get('footholds') or {}).get('max_m')
        row[f'slip_{name}_m'] = (checks.get('stance_slip') or {}).get('max_m')
        row[f'rtf_{name}'] = summary.get('real_time_factor')
        row[f'cpu_{name}_s'] = k_cpu if name == 'kinematic' else p_cpu
    # A segment or a point (point feet on a diagonal) has no inside: a CoP on it has margin 0.
    margins = np.array([signed_distance(np.array([cop]), p['polygon'][t])[0]
                        for t, cop in p['cop'].items() if len(p['polygon'].get(t, ()))])
    row['cop'] = (float(margins.min()), float(np.median(margins)),
                  int((margins < -COP_TOLERANCE_M).sum()), len(margins)) \
        if len(margins) else None
    limits = urdf_effort_limits(robot.description.urdf_path.read_text())
    if p['effort']:
        efforts = np.array(p['effort'])
        ratios = efforts / np.array([limits.get(n, math.inf) for n in p['names']])
        worst = np.unravel_index(int(np.argmax(ratios)), ratios.shape)
        row['effort'] = (float(ratios.max()), p['names'][worst[1]],
                         float((ratios >= 0.999).any(axis=1).mean()))
    else:
        row['effort'] = None
    row['slip_m'] = p['slip']
    slip = row['slip_m']
    row['bounds'] = {
        'height': row['base_z_m'] <= BOUND_HEIGHT_M,
        'tilt': max(row['roll_pitch_deg']) <= BOUND_TILT_DEG,
        'distance': row['distance_ratio'] is not None
        and abs(row['distance_ratio'] - 1) <= BOUND_DISTANCE,
        'slip': slip is not None and slip < BOUND_SLIP_M,
        'cop': row['cop'] is not None and row['cop'][2] == 0,
        'torque': row['effort'] is not None and row['effort'][2] == 0.0,
    }
    return row


def _mm(value) -> str:
    return '-' if value is None else f'{1e3 * value:.1f}'


def _pair(a, b, text=_mm) -> str:
    return f'{text(a)} / {text(b)}'


def table(rows: list[dict]) -> str:
    """The Markdown table of every scenario."""
    lines = ['| scenario (s walked) | distance kin / phys [m] (ratio) | ZMP margin kin / phys '
             '[mm] (samples outside) | CoP margin phys: least / median [mm] (outside) | '
             'base vs kin: xy / z [mm]; roll / pitch [deg] | feet at touch-down vs plan, kin / '
             'phys [mm]; phys: slip / drift in planned stance [mm] | peak effort / limit '
             '(share at limit) | real-time '
             'factor kin / phys; CPU [s] | issue 27 bounds |',
             '| --- | --- | --- | --- | --- | --- | --- | --- | --- |']
    for row in rows:
        k_zmp, p_zmp = row['zmp_kinematic'], row['zmp_physics']
        ratio = f' ({row["distance_ratio"]:.3f})' if row['distance_ratio'] is not None else ''
        cop = row['cop']
        cop_text = (f'{_mm(cop[0])} / {_mm(cop[1])} ({cop[2]} of {cop[3]})' if cop else '-')
        effort = row['effort']
        effort_text = (f'{effort[0]:.2f} at {effort[1]} ({100 * effort[2]:.1f} %)'
                       if effort else '-')
        failed = [name for name, ok in row['bounds'].items() if not ok]
        verdict = 'all held' if not failed else 'not held: ' + ', '.join(failed)
        if row['fell_at_s'] is not None:
            verdict = f'**fell at {row["fell_at_s"]:.1f} s**; ' + verdict
        lines.append(
            f'| {row["scenario"]} ({row["seconds"]:.0f}) '
            f'| {row["distance_m"][0]:.3f} / {row["distance_m"][1]:.3f}{ratio} '
            f'| {_mm(k_zmp[0])} ({k_zmp[1]}) / {_mm(p_zmp[0])} ({p_zmp[1]} of {p_zmp[2]}) '
            f'| {cop_text} '
            f'| {_mm(row["base_xy_m"])} / {_mm(row["base_z_m"])}; '
            f'{row["roll_pitch_deg"][0]:.2f} / {row["roll_pitch_deg"][1]:.2f} '
            f'| {_pair(row["footholds_kinematic_m"], row["footholds_physics_m"])}; '
            f'{_pair(row["slip_m"], row["slip_physics_m"])} '
            f'| {effort_text} '
            f'| {row["rtf_kinematic"]}x / {row["rtf_physics"]}x; '
            f'{row["cpu_kinematic_s"]:.1f} / {row["cpu_physics_s"]:.1f} '
            f'| {verdict} |')
    return '\n'.join(lines)


def main() -> int:
    """Walk every scenario asked for with both simulators; print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', action='append', default=None,
                        help=f'a scenario (repeatable; default all: {", ".join(SCENARIOS)})')
    parser.add_argument('--all', action='store_true', help='every scenario (the default)')
    parser.add_argument('--duration', type=float, default=None,
                        help="seconds walked (default: each scenario's, at least "
                             f"{LEAST_SECONDS:g})")
    parser.add_argument('--keep', default=None, help='keep the bags in this directory')
    parser.add_argument('--json', default=None, metavar='FILE',
                        help='also write the figures as JSON to FILE')
    options = parser.parse_args()
    scenarios = list(SCENARIOS) if options.all or not options.scenario else options.scenario
    folder = Path(options.keep or tempfile.mkdtemp(prefix='bench_physics_'))
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for scenario in scenarios:
        get_scenario(scenario)
        runs = {}
        for simulator in ('kinematic', 'physics'):
            bag = folder / f'{scenario}_{simulator}'
            seconds = options.duration or max(get_scenario(scenario).duration_s, LEAST_SECONDS)
            summary, cpu = run(scenario, simulator, seconds, bag)
            runs[simulator] = (summary, cpu, read(bag))
        row = compare(scenario, runs)
        rows.append(row)
        print(f'{scenario}: walked {row["distance_m"][0]:.3f} m kinematic, '
              f'{row["distance_m"][1]:.3f} m physics'
              + (f', FELL at {row["fell_at_s"]:.1f} s' if row['fell_at_s'] is not None else '')
              + f'; bounds {row["bounds"]}', file=sys.stderr, flush=True)
    print(f'python bench/physics.py {" ".join(sys.argv[1:])}'.rstrip() + f'  (bags in {folder})')
    print()
    print(table(rows))
    if options.json:
        Path(options.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == '__main__':
    sys.exit(main())
