"""The static crawl's stance: RoboSimian walked at body heights and feet places.

The walker's stance (``config/robots/robosimian.yaml``: the static crawl's own stance,
``gait_stances.static_crawl``, and the body's height) decides how fast the limbs move their
feet (the limb's own speed map) and how much room the ZMP keeps in the support triangles of
the static crawl's swings. This script walks the default scenario (``robosimian_static_crawl``)
on copies of the robot YAML that differ only in the ground's depth below the body, the rear
feet's lateral place, the static crawl's front feet's place ahead of the base and rear feet's
place behind it and its longest step (``max_step_length_m``: the velocity clamp picks the
fastest stride below it), with the project's own command, one inproc run each
(deterministic; the copies from :func:`gait_nodes.robot.stance.write_stance`):

    python -m gait_nodes run --fast --robot COPY.yaml --record BAG --no-plot --json

and prints, per stance, the steady speed (inspect's: whole gait cycles after the first), the
least ZMP margin on the full model, the joints' peak speed and the seconds in which the
simulator reported commands beyond a joint's velocity or acceleration limit, as a Markdown
table.

    python bench/stance.py [--heights 0.7,0.77] [--rear-widths 0.5,0.52] [--front-x 0.56,0.6]
                           [--rear-x 0.54,0.6] [--strides 0.2,0.3] [--keep DIR]
"""

from __future__ import annotations

import argparse
import itertools
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gait_nodes.robot.stance import write_stance  # noqa: E402


def walk(robot_yaml: Path, bag: Path) -> dict:
    """The run's gait summary (inspect's numbers)."""
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--fast', '--robot', str(robot_yaml),
               '--record', str(bag), '--no-plot', '--json']
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f'{" ".join(command)} failed: {done.stderr[-2000:]}')
    summary = json.loads(done.stdout)
    return summary['inspect']['gait']


def main(argv: list[str] | None = None) -> int:
    """Walk each stance; print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--heights', default='0.77',
                        help='ground depths below the body [m]')
    parser.add_argument('--rear-widths', default='0.5',
                        help="rear feet's lateral places [m]")
    parser.add_argument('--front-x', default='0.54,0.58',
                        help="front feet's places ahead of the base [m]")
    parser.add_argument('--rear-x', default='0.54,0.6',
                        help="rear feet's places behind the base [m]")
    parser.add_argument('--strides', default='0.2,0.3',
                        help="stride caps (the static crawl's max_step_length_m) [m]")
    parser.add_argument('--keep', default=None, help='keep the YAML copies and bags here')
    options = parser.parse_args(argv)
    heights = [float(v) for v in options.heights.split(',')]
    widths = [float(v) for v in options.rear_widths.split(',')]
    fronts = [float(v) for v in options.front_x.split(',')]
    rears = [float(v) for v in options.rear_x.split(',')]
    strides = [float(v) for v in options.strides.split(',')]
    rows = ['| ground below the body [m] | rear feet out [m] | front feet ahead [m] '
            '| rear feet behind [m] | stride cap [m] | longest stride [m] '
            '| steady speed [m/s] (ft/min) | net speed over the run [m/s] '
            '| ZMP margin min [mm] | joint vel. peak / limit | commands over a limit [s] |',
            '| --- ' * 11 + '|']
    with tempfile.TemporaryDirectory(prefix='gait_nodes_stance_') as tmp:
        folder = Path(options.keep or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for height, width, front, rear, stride in itertools.product(heights, widths, fronts,
                                                                     rears, strides):
            copy = write_stance('robosimian', folder, height, width, front, rear,
                                gait='static_crawl')
            data = yaml.safe_load(copy.read_text())
            data['gait_stances']['static_crawl']['max_step_length_m'] = stride
            copy = copy.with_name(f'{copy.stem}_s{stride:g}.yaml')
            copy.write_text(yaml.safe_dump(data, sort_keys=False))
            gait = walk(copy, folder / f'{copy.stem}_bag')
            speed = gait['steady']['net_speed_m_s']
            net = gait['base']['net_speed_m_s']
            longest = gait['steps']['max_length_m']
            margin = gait['zmp_margin']['min_m']
            peak = gait['joint_velocity']['/joint_states']['peak_ratio_to_limit']
            # The simulator's once-a-second reports of commands beyond a joint's velocity or
            # acceleration limit (it follows them within the limits).
            over = gait['diagnostics']['by_name'].get(
                'kinematic_simulator: velocity saturation', {}).get('WARN', 0)
            rows.append(f'| {height:g} | {width:g} | {front:g} | {rear:g} | {stride:g} '
                        f'| {longest:.3f} | {speed:.4f} ({speed * 196.85:.2f}) | {net:.4f} '
                        f'| {1000 * margin:.1f} | {peak:.2f} | {over} |')
            print(rows[-1], file=sys.stderr, flush=True)
    print('\n'.join(rows))
    return 0


if __name__ == '__main__':
    sys.exit(main())
