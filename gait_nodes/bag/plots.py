"""PNG plots of a gait bag for ``inspect --plot DIR`` (matplotlib, no display needed).

Each plot is drawn only when the bag holds its data, and :func:`write_plots` returns the files
it wrote:

- ``top_view.png``: footholds, a sample of support polygons, the ZMP reference, the ZMP and the
  COM seen from above;
- ``com_zmp_time.png``: COM and ZMP x and y over time against the ZMP reference, and the
  stability margin;
- ``joint_velocities.png``: every joint's velocity over time with the limit drawn;
- ``swing_trajectories.png``: swing-foot trajectories in 3-D.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from gait_nodes.bag.analysis import GaitSeries, executed_swings, zmp_margins


def _pyplot():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def _origin(series: GaitSeries) -> int:
    stamps = [s[0] for s in series.zmp + series.com + series.base]
    stamps += [s[0] for s in series.zmp_reference]
    for joints in series.joints.values():
        stamps += joints.stamps_ns[:1]
    return min(stamps) if stamps else 0


def top_view(series: GaitSeries, path: Path) -> bool:
    """Footholds, support polygons, ZMP reference, ZMP and COM from above."""
    if not (series.plans or series.zmp or series.com or series.base):
        return False
    plt = _pyplot()
    figure, axes = plt.subplots(figsize=(10, 6))
    if series.polygons:
        step = max(1, len(series.polygons) // 40)
        for index, (_, polygon) in enumerate(series.polygons[::step]):
            closed = np.vstack([polygon, polygon[:1]])
            axes.plot(closed[:, 0], closed[:, 1], color='0.75', linewidth=0.6,
                      label='support polygons' if index == 0 else None)
    if series.plans:
        plan = series.plans[-1]
        feet = plan.foot_names
        markers = 'o^sv<>'
        landed = executed_swings(series.plans, None)
        for f, foot in enumerate(feet):
            points = [s['end'] for s in landed if s['foot'] == foot]
            points.insert(0, series.plans[0].positions_in_world[0, f].tolist())
            points = np.array(points)
            axes.plot(points[:, 0], points[:, 1], markers[f % len(markers)], markersize=5,
                      linestyle='none', label=f'footholds {foot}')
    if series.zmp_reference:
        ref = np.array(series.zmp_reference)
        axes.plot(ref[:, 1], ref[:, 2], color='tab:green', linewidth=1.5, label='ZMP reference')
    if series.zmp:
        zmp = np.array(series.zmp)
        axes.plot(zmp[:, 1], zmp[:, 2], color='tab:red', linewidth=1.0, label='ZMP (model)')
    if series.com:
        com = np.array(series.com)
        axes.plot(com[:, 1], com[:, 2], color='tab:blue', linewidth=1.0, label='COM')
    elif series.base:
        base = np.array(series.base)
        axes.plot(base[:, 1], base[:, 2], color='tab:blue', linewidth=1.0, label='base')
    axes.set_aspect('equal', adjustable='datalim')
    axes.set_xlabel('x in odom [m]')
    axes.set_ylabel('y in odom [m]')
    axes.set_title('Top view')
    axes.grid(True, linewidth=0.3)
    axes.legend(fontsize=7, loc='best')
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return True


def com_zmp_time(series: GaitSeries, path: Path) -> bool:
    """COM, ZMP and reference against time, per axis, and the margin."""
    if not (series.zmp or series.com or series.zmp_reference):
        return False
    plt = _pyplot()
    origin = _origin(series)
    figure, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for axis, (label, column) in zip(axes[:2], (('x', 1), ('y', 2)), strict=True):
        for data, name, style in ((series.zmp_reference, 'ZMP reference', 'tab:green'),
                                  (series.zmp, 'ZMP (model)', 'tab:red'),
                                  (series.com, 'COM', 'tab:blue'),
                                  (series.com_reference, 'COM reference', 'tab:purple')):
            if data:
                array = np.array(data)
                axis.plot((array[:, 0] - origin) * 1e-9, array[:, column], color=style,
                          linewidth=1.0, label=name)
        axis.set_ylabel(f'{label} [m]')
        axis.grid(True, linewidth=0.3)
        axis.legend(fontsize=7, loc='best')
    stamps, margins = zmp_margins(series)
    if len(margins):
        axes[2].plot((stamps - origin) * 1e-9, margins * 1000, color='tab:red', linewidth=1.0)
        axes[2].axhline(0.0, color='k', linewidth=0.8)
    axes[2].set_ylabel('stability margin [mm]')
    axes[2].set_xlabel('time [s]')
    axes[2].grid(True, linewidth=0.3)
    axes[0].set_title('COM and ZMP against the reference')
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return True


def joint_velocities(series: GaitSeries, path: Path,
                     limit_of: Callable[[str], float | None]) -> bool:
    """Joint velocities of /joint_states (else the trajectory of /joint_commands), limits."""
    joints = series.joints.get('/joint_states') or series.joints.get('/joint_commands')
    if joints is None or not joints.names:
        return False
    rows = [(t, v) for t, v in zip(joints.stamps_ns, joints.velocities, strict=True)
            if len(v) == len(joints.names)]
    if not rows:
        return False
    plt = _pyplot()
    origin = _origin(series)
    times = (np.array([t for t, _ in rows]) - origin) * 1e-9
    velocities = np.array([v for _, v in rows])
    figure, axes = plt.subplots(figsize=(10, 5))
    for i, name in enumerate(joints.names):
        axes.plot(times, velocities[:, i], linewidth=0.7, label=name)
    limits = sorted({limit for limit in map(limit_of, joints.names) if limit})
    for limit in limits:
        axes.axhline(limit, color='k', linestyle='--', linewidth=0.8)
        axes.axhline(-limit, color='k', linestyle='--', linewidth=0.8)
    axes.set_xlabel('time [s]')
    axes.set_ylabel('joint velocity [rad/s]')
    axes.set_title('Joint velocities' + (' (dashed: limits)' if limits else ''))
    axes.grid(True, linewidth=0.3)
    if len(joints.names) <= 14:
        axes.legend(fontsize=6, ncol=2, loc='best')
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return True


def swing_trajectories(series: GaitSeries, path: Path) -> bool:
    """Every recorded swing trajectory in 3-D."""
    if not series.swings:
        return False
    plt = _pyplot()
    figure = plt.figure(figsize=(9, 7))
    axes = figure.add_subplot(projection='3d')
    colours = {}
    for swing in series.swings:
        colour = colours.setdefault(swing.foot, f'C{len(colours)}')
        p = swing.positions_in_world
        axes.plot(p[:, 0], p[:, 1], p[:, 2], color=colour, linewidth=1.0, marker='.',
                  markersize=2)
    for foot, colour in colours.items():
        axes.plot([], [], [], color=colour, label=foot)
    axes.set_xlabel('x [m]')
    axes.set_ylabel('y [m]')
    axes.set_zlabel('z [m]')
    axes.set_title('Swing trajectories')
    axes.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)
    return True


def write_plots(series: GaitSeries, folder: str | Path,
                limit_of: Callable[[str], float | None] = lambda joint: None) -> list[Path]:
    """Write every plot the bag has data for into ``folder``; the files written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, draw in (('top_view.png', top_view), ('com_zmp_time.png', com_zmp_time),
                       ('swing_trajectories.png', swing_trajectories)):
        if draw(series, folder / name):
            written.append(folder / name)
    if joint_velocities(series, folder / 'joint_velocities.png', limit_of):
        written.append(folder / 'joint_velocities.png')
    return written
