"""inspect: what a rosbag2 MCAP bag (or a lone .mcap) holds, and how the gait in it went.

``python -m gait_nodes.inspect BAG [--json] [--plot DIR] [--robot NAME] [--namespace NS]
[--video FILE [--fps N] [--size WxH] [--from S] [--to S] [--speed X] [--scenario NAME]]``

Prints topics, types, counts, rates and duration for any ROS 2 MCAP bag; for gait bags also the
distance walked, net speed, step lengths, ZMP stability margin (min, mean, time outside the
support polygon), peak joint velocity against the limit, rejected commands and diagnostics by
level (definitions in :mod:`gait_nodes.bag.analysis`). A bag of a graph run in a ROS namespace
(``/robot1/gait/footsteps``...) is read as such: the namespace is found from its topics, or
given with ``--namespace`` when the bag holds several graphs. A truncated or damaged bag is
read up to the damage, and what was lost is said. ``--json`` prints one JSON object instead;
``--plot DIR`` writes PNGs. ``--video FILE`` (``.mp4`` or ``.gif``) renders the walk headless with
MuJoCo: the robot posed from /tf and /joint_states, its footholds, the ZMP, the centre of pressure
and the support polygon, the camera following the base (:mod:`gait_nodes.bag.video`; needs
``pip install mujoco "imageio[ffmpeg]"``). Exit status: 0 when the bag was read (even partly)
and the video, if asked for, written; 1 when the video could not be made; 2 when the path is not
a bag or the arguments are wrong.
"""

from __future__ import annotations

import json
import sys

from gait_nodes.cli import ArgumentParser, fail
from gait_nodes.errors import GaitNodesError, os_error_text

PROG = 'python -m gait_nodes.inspect'
#: Show progress on a non-terminal too above this size [bytes].
PROGRESS_BYTES = 64 << 20
FEET_PER_METRE = 3.280839895


def _mm(value) -> str:
    return 'n/a' if value is None else f'{value * 1000:.1f} mm'


def format_gait(gait: dict | None) -> list[str]:
    """Lines for the gait section of a report (none when the bag holds no gait topics)."""
    lines = []
    if not gait:
        return lines
    lines.append('gait:' + (f' ({gait["robot"]})' if 'robot' in gait else ''))
    base = gait.get('base')
    if base:
        speed = base['net_speed_m_s']
        speed_text = (f', net speed {speed:.4f} m/s ({speed * 60 * FEET_PER_METRE:.2f} '
                      f'ft/min)' if speed is not None else '')
        lines.append(f'  walked:      {base["displacement_m"]:.3f} m net (base start to end) '
                     f'in {base["time_s"]:.2f} s{speed_text}; path {base["distance_m"]:.3f} m '
                     f'(sway included)')
        steady = gait.get('steady')
        if steady and steady['net_speed_m_s'] is not None:
            speed = steady['net_speed_m_s']
            text = (f'  steady:      net speed {speed:.4f} m/s ({speed * 60 * FEET_PER_METRE:.2f} '
                    f'ft/min) over {steady["cycles"]} whole cycles, {steady["from_s"]:.1f}-'
                    f'{steady["to_s"]:.1f} s (the start excluded)')
            reference = steady.get('reference')
            if reference:
                text += (f'; {reference["ft_min"]:g} ft/min ({reference["m_s"]:.4f} m/s) in '
                         f'{reference["source"]}')
            lines.append(text)
        if base.get('rise_m') is not None and abs(base['rise_m']) >= 0.005:
            lines.append(f'  climbed:     {base["rise_m"]:+.3f} m (base height, last minus first)')
    steps = gait.get('steps')
    if steps:
        text = f'  steps:       {steps["count"]}'
        if steps['count']:
            text += (f', length mean {steps["mean_length_m"]:.3f} m (min '
                     f'{steps["min_length_m"]:.3f}, max {steps["max_length_m"]:.3f})')
        lines.append(text)
    margin = gait.get('zmp_margin')
    if margin:
        lines.append(f'  ZMP margin:  min {_mm(margin["min_m"])}, mean {_mm(margin["mean_m"])}'
                     f', outside the support polygon {margin["time_outside_s"]:.3f} s '
                     f'({margin["samples_outside"]} of {margin["samples"]} samples)')
    for topic, joints in (gait.get('joint_velocity') or {}).items():
        text = (f'  peak joint velocity ({topic}): {joints["peak_rad_s"]:.4f} rad/s at '
                f'{joints["peak_joint"]}')
        if joints['limit_rad_s']:
            text += (f', limit {joints["limit_rad_s"]:g} rad/s (max ratio '
                     f'{joints["peak_ratio_to_limit"]:.3f}, {joints["samples_over_limit"]} '
                     f'samples over)')
        lines.append(text)
    commands = gait.get('commands')
    if commands:
        lines.append(f'  commands:    {commands["answered"]} answered: {commands["accepted"]}'
                     f' accepted ({commands["applied"]} applied), {commands["rejected"]} '
                     f'rejected, {commands["superseded"]} superseded; most decisions on one '
                     f'command {commands["most_decisions"]}, most applied '
                     f'{commands["most_applied"]}')
        lines.extend(f'    rejected: {reason}' for reason in commands['rejections'])
    diagnostics = gait.get('diagnostics')
    if diagnostics:
        levels = ', '.join(f'{k} {v}' for k, v in sorted(diagnostics['by_level'].items()))
        lines.append(f'  diagnostics: {levels}')
        if diagnostics['first_error']:
            error = diagnostics['first_error']
            lines.append(f'    first ERROR: {error["name"]}: {error["message"]}')
    lines.extend(_consistency_lines(gait.get('consistency')))
    return lines


def _stat(stats: dict | None) -> str:
    if not stats or stats.get('max_m') is None:
        return '-'
    text = f'max {_mm(stats["max_m"])}'
    return text + (f', rms {_mm(stats["rms_m"])}' if stats.get('rms_m') is not None else '')


def _consistency_lines(checks: dict | None) -> list[str]:
    """The physics consistency section (gait_nodes.bag.consistency)."""
    if not checks:
        return []
    lines = [f'  consistency (full model, {checks["configurations"]} configurations from '
             f'/joint_states + /tf):']
    com = checks.get('com') or {}
    if com.get('vs_reference'):
        lines.append(f'    COM reached vs /gait/com_reference (horizontal): '
                     f'{_stat(com["vs_reference"])}')
    if com.get('vs_monitor'):
        lines.append(f'    COM vs /gait/com: {_stat(com["vs_monitor"])}')
    zmp = checks.get('zmp')
    if zmp:
        lines.append(f'    ZMP by inverse dynamics vs /gait/zmp: {_stat(zmp)}')
    feet = checks.get('footholds')
    if feet:
        lines.append(f'    feet at touch-down vs /gait/footsteps: {_stat(feet)} '
                     f'({feet["samples"]} landings)')
    slip = checks.get('stance_slip')
    if slip:
        # The foot frames' drift over their planned stance, read from /tf: not the physics
        # simulator's contact slip (the ground's material under a rolling foot stays put while
        # its frame moves), which its 'contacts' status on /diagnostics reports.
        lines.append(f'    stance feet drift (foot frames, over each planned stance): '
                     f'{_stat(slip)}')
    return lines


def format_report(report: dict) -> str:
    """The report as text for a person."""
    lines = [f'bag:       {report["bag"]}']
    if not report['complete']:
        lines.append('           INCOMPLETE: the writer did not finish (no summary); read what '
                     'was flushed')
    lines.append(f'files:     {", ".join(report["files"])}')
    lines.append(f'duration:  {report["duration_s"]:.3f} s, {report["message_count"]} messages')
    if report.get('namespace', '/') != '/':
        lines.append(f'namespace: {report["namespace"]} (the gait section reads the contract '
                     f'topics under it)')
    width = max([len(t['topic']) for t in report['topics']] + [5])
    type_width = max([len(t['type']) for t in report['topics']] + [4])
    lines.append(f'{"topic":<{width}}  {"type":<{type_width}}  {"count":>8}  {"rate":>10}')
    for topic in report['topics']:
        rate = f'{topic["rate_hz"]:.2f} Hz' if topic['rate_hz'] is not None else '-'
        lines.append(f'{topic["topic"]:<{width}}  {topic["type"]:<{type_width}}  '
                     f'{topic["count"]:>8}  {rate:>10}')
    for damage in report['damage']:
        lines.append(f'DAMAGE:    {damage["description"]}')
    check = report.get('metadata_check')
    if check is not None:
        lines.append('metadata:  metadata.yaml matches the files' if check['matches'] else
                     'metadata:  metadata.yaml disagrees: ' + '; '.join(check['problems']))
    lines.extend(format_gait(report.get('gait')))
    for topic, count in (report.get('undecodable') or {}).items():
        lines.append(f'undecodable: {count} messages on {topic}')
    return '\n'.join(lines)


def main(args: list[str] | None = None) -> int:
    """Entry point of ``python -m gait_nodes.inspect``."""
    parser = ArgumentParser(prog=PROG, description=__doc__.split('\n\n')[0])
    parser.add_argument('bag', help='rosbag2 directory or .mcap file')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--plot', metavar='DIR', help='write PNG plots into DIR')
    parser.add_argument('--robot', help='robot name or YAML for joint limits (default: the '
                                        "hardware_id in the bag's diagnostics)")
    parser.add_argument('--namespace', metavar='NS',
                        help="the graph's ROS namespace (default: the bag's, found from its "
                             'topics; needed when it holds several)')
    video = parser.add_argument_group('video', 'render the walk with MuJoCo (headless: '
                                               'MUJOCO_GL=egl, the default without a display)')
    video.add_argument('--video', metavar='FILE',
                       help='write the walk as FILE (.mp4 or .gif; .png: a still of the frame '
                            'at --from)')
    video.add_argument('--fps', type=float, default=15.0, help='frames per second (default 15)')
    video.add_argument('--size', default='640x480', metavar='WxH',
                       help='frame size in pixels (default 640x480)')
    video.add_argument('--from', dest='start_s', type=float, default=0.0, metavar='S',
                       help="first frame, seconds from the walk's first base pose (default 0)")
    video.add_argument('--to', dest='end_s', type=float, default=None, metavar='S',
                       help="last frame at most, seconds from the same origin (default: the "
                            "walk's end)")
    video.add_argument('--speed', type=float, default=1.0,
                       help='playback speed: 2 plays the walk twice as fast (default 1)')
    video.add_argument('--scenario', metavar='NAME',
                       help="the scenario the bag walked, for its terrain (a scenario's "
                            "staircase is not in the bag; default: flat ground)")
    progress_group = parser.add_mutually_exclusive_group()
    progress_group.add_argument('--progress', dest='progress', action='store_true',
                                default=None, help='always show a progress bar on stderr')
    progress_group.add_argument('--no-progress', dest='progress', action='store_false',
                                help='never show one')
    options = parser.parse_args(args)
    try:
        video = _video_request(options)
    except GaitNodesError as error:
        return fail(PROG, error)

    from gait_nodes.bag.analysis import inspect_bag, robot_limits
    from gait_nodes.bag.reader import BagReader

    try:
        total = BagReader(options.bag).total_bytes
        show = options.progress if options.progress is not None else (
            sys.stderr.isatty() or total > PROGRESS_BYTES)
        from tqdm import tqdm

        with tqdm(total=total, unit='B', unit_scale=True, desc='reading', disable=not show,
                  file=sys.stderr, leave=False) as bar:
            inspection = inspect_bag(options.bag, robot=options.robot, progress=bar.update,
                                     namespace=options.namespace)
        report = inspection.report
        if options.plot:
            from gait_nodes.bag.plots import write_plots

            robot = options.robot or report.get('gait', {}).get('robot')
            try:
                written = write_plots(inspection.series, options.plot, robot_limits(robot)[1])
            except OSError as error:  # the bag was read: the plots' place is the problem
                return fail(PROG, GaitNodesError(
                    f'--plot {options.plot}: cannot write {error.filename or "the plots"}: '
                    f'{os_error_text(error)}'))
            report['plots'] = [str(p) for p in written]
    except GaitNodesError as error:
        return fail(PROG, error)
    except OSError as error:
        return fail(PROG, GaitNodesError(f'{options.bag}: {error.strerror or error}'))
    status = 0
    if video is not None:
        status = render_video(options.bag, options.video, video, options.robot,
                              report.get('namespace'), report)
    if options.json:
        print(json.dumps(report, indent=1))
    else:
        print(format_report(report))
        for plot in report.get('plots', []):
            print(f'plot:      {plot}')
        if 'video' in report:
            print(f'video:     {report["video"]["description"]}')
    return status


def _video_request(options):
    """``(settings, staircase)`` of the video asked for on the command line, or None."""
    if options.video is None:
        return None
    from gait_nodes.bag.video import (
        VideoSettings,
        check_dependencies,
        parse_size,
        prefer_headless_gl,
    )
    from gait_nodes.planning.terrain import Staircase

    prefer_headless_gl()  # before MuJoCo is imported
    check_dependencies(options.video)
    width, height = parse_size(options.size)
    settings = VideoSettings(fps=options.fps, width=width, height=height,
                             start_s=options.start_s, end_s=options.end_s, speed=options.speed)
    staircase = Staircase()
    if options.scenario:
        from gait_nodes.scenarios import get_scenario

        staircase = scenario_staircase(get_scenario(options.scenario))
    return settings, staircase


def scenario_staircase(scenario):
    """The staircase a scenario walks on (flat ground without one)."""
    from gait_nodes.planning.terrain import STAIRS_DEFAULTS, Staircase

    return Staircase.from_parameters({**STAIRS_DEFAULTS, **scenario.settings})


def render_video(bag, output, request, robot: str | None, namespace: str | None,
                 report: dict, prog: str = PROG) -> int:
    """Write the walk of ``bag`` as ``output``; its account in ``report['video']``.

    Args:
        bag: The bag.
        output: The video file.
        request: ``(VideoSettings, Staircase)``.
        robot: Robot name or YAML (None: the bag's).
        namespace: The graph's namespace in the bag (None: found from its topics).
        report: Where to put the video's account.
        prog: The command named in an error message.

    Returns:
        0 when written, 1 (the reason on stderr) when not.
    """
    from tqdm import tqdm

    from gait_nodes.bag.video import write_video

    settings, staircase = request
    try:
        with tqdm(unit='frame', desc='video', disable=not sys.stderr.isatty(), file=sys.stderr,
                  leave=False) as bar:
            written = write_video(bag, output, settings, robot=robot, staircase=staircase,
                                  namespace=namespace, progress=bar.update)
    except GaitNodesError as error:
        fail(prog, error)
        return 1
    except OSError as error:
        fail(prog, GaitNodesError(f'--video {output}: cannot write it: {os_error_text(error)}'))
        return 1
    report['video'] = {**written.__dict__, 'description': written.describe()}
    return 0


if __name__ == '__main__':
    sys.exit(main())
