#!/usr/bin/env python3
"""A scenario walked by the kinematic simulator and by the physics simulator, side by side.

``python bench/physics.py [--scenario robosimian_crawl] [--duration S] [--keep DIR]``

Each run is ``python -m gait_nodes run --fast --scenario S --simulator K --record BAG``; the
figures come from the bags: the distance walked (base x, last minus first), the base's height,
roll and pitch, the physics base against the kinematic one at the same stamps, the drives'
peak effort against the URDF's limits, the centre of pressure's least margin in the contact
polygon, and the inproc real-time factor.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from gait_nodes import graph
from gait_nodes.bag.reader import BagReader
from gait_nodes.contract import time_msg_to_ns
from gait_nodes.geometry import signed_distance
from gait_nodes.interfaces import deserialize_message, get_message
from gait_nodes.robot.model import load_robot_model
from gait_nodes.scenarios import get_scenario
from gait_nodes.sim.mujoco_model import urdf_effort_limits


def _rpy(qx, qy, qz, qw):
    roll = math.atan2(2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (qw * qy - qz * qx))))
    return math.degrees(roll), math.degrees(pitch)


def read(bag: Path) -> dict:
    """Base poses, joint efforts, CoP and support polygons of a bag, by stamp."""
    types = {t: graph.TOPICS[t] for t in ('/tf', '/joint_states', '/gait/cop',
                                          '/gait/support_polygon')}
    data = {'base': {}, 'effort': [], 'cop': {}, 'polygon': {}, 'names': None}
    for channel, _, _, payload in BagReader(bag).messages():
        if channel.topic not in types:
            continue
        msg = deserialize_message(payload, get_message(types[channel.topic]))
        if channel.topic == '/tf':
            for t in msg.transforms:
                p, r = t.transform.translation, t.transform.rotation
                data['base'][time_msg_to_ns(t.header.stamp)] = (p.x, p.y, p.z,
                                                               *_rpy(r.x, r.y, r.z, r.w))
        elif channel.topic == '/joint_states':
            data['names'] = list(msg.name)
            if len(msg.effort):
                data['effort'].append(np.abs(np.array(msg.effort)))
        elif channel.topic == '/gait/cop':
            data['cop'][time_msg_to_ns(msg.header.stamp)] = (msg.point.x, msg.point.y)
        else:
            data['polygon'][time_msg_to_ns(msg.header.stamp)] = np.array(
                [(p.x, p.y) for p in msg.polygon.points])
    return data


def run(scenario: str, simulator: str, duration: float, bag: Path) -> dict:
    """Walk once; the run's JSON summary."""
    out = subprocess.run([sys.executable, '-m', 'gait_nodes', 'run', '--fast', '--scenario',
                          scenario, '--simulator', simulator, '--duration', str(duration),
                          '--record', str(bag), '--no-plot', '--json'],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def main() -> int:
    """Walk both, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--scenario', default='robosimian_crawl')
    parser.add_argument('--duration', type=float, default=None)
    parser.add_argument('--keep', default=None, help='keep the bags in this directory')
    options = parser.parse_args()
    scenario = get_scenario(options.scenario)
    duration = options.duration or scenario.duration_s
    folder = Path(options.keep or tempfile.mkdtemp(prefix='bench_physics_'))
    runs = {}
    for simulator in ('kinematic', 'physics'):
        bag = folder / f'{options.scenario}_{simulator}'
        summary = run(options.scenario, simulator, duration, bag)
        runs[simulator] = (summary, read(bag))
    robot = load_robot_model(scenario.robot)
    kinematic, physics = runs['kinematic'][1], runs['physics'][1]
    common = sorted(set(kinematic['base']) & set(physics['base']))
    k = np.array([kinematic['base'][t] for t in common])
    p = np.array([physics['base'][t] for t in common])
    print(f'{options.scenario}, {duration:g} s, robot {robot.name}; bags in {folder}')
    print(f'{"":34s}{"kinematic":>14s}{"physics":>14s}')
    for label, values in (('distance [m]', lambda a: a[-1, 0] - a[0, 0]),
                          ('base height range [mm]',
                           lambda a: 1e3 * (a[:, 2].max() - a[:, 2].min())),
                          ('max |roll| [deg]', lambda a: np.abs(a[:, 3]).max()),
                          ('max |pitch| [deg]', lambda a: np.abs(a[:, 4]).max())):
        print(f'{label:34s}{values(k):14.4f}{values(p):14.4f}')
    for name, (summary, _) in runs.items():
        print(f'real-time factor, {name:15s} {summary["real_time_factor"]}x '
              f'(wall {summary["wall_s"]:.1f} s)')
    distance_k, distance_p = k[-1, 0] - k[0, 0], p[-1, 0] - p[0, 0]
    print(f'distance ratio physics / kinematic: {distance_p / distance_k:.3f}')
    print('physics base vs kinematic at the same stamps: '
          f'height max {1e3 * np.abs(p[:, 2] - k[:, 2]).max():.1f} mm '
          f'(mean {1e3 * (p[:, 2] - k[:, 2]).mean():+.1f} mm), '
          f'xy max {1e3 * np.hypot(*(p[:, :2] - k[:, :2]).T).max():.1f} mm, '
          f'roll max {np.abs(p[:, 3] - k[:, 3]).max():.2f} deg, '
          f'pitch max {np.abs(p[:, 4] - k[:, 4]).max():.2f} deg')
    limits = urdf_effort_limits(robot.description.urdf_path.read_text())
    if physics['effort']:
        peak = np.max(physics['effort'], 0)
        ratios = peak / np.array([limits.get(n, math.inf) for n in physics['names']])
        worst = int(np.argmax(ratios))
        print(f'peak effort / limit: {ratios[worst]:.3f} at {physics["names"][worst]} '
              f'({peak[worst]:.1f} N m)')
    margins = [signed_distance(np.array([cop]), physics['polygon'][t])[0]
               for t, cop in physics['cop'].items()
               if t in physics['polygon'] and len(physics['polygon'][t]) >= 3]
    if margins:
        print(f'CoP in the contact polygon: least margin {1e3 * min(margins):.1f} mm, median '
              f'{1e3 * float(np.median(margins)):.1f} mm over {len(margins)} samples')
    return 0


if __name__ == '__main__':
    sys.exit(main())
