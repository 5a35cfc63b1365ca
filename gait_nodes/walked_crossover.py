"""The walked crossover: each gait walked by the node graph at joint velocity limits (Fig. 21).

Thesis 000, IV.C, Fig. 21 compares the value-iteration crawl with the ZMP gait over joint
velocity limits (ZMP gait feasible from about 1.9 rad/s, faster above about 2.4 rad/s). Here
nothing is modelled: for each limit a copy of the robot YAML with its joints limited to it is
written (:func:`gait_nodes.robot.description.write_at_joint_velocity_limit`; its value table is
the cached one's times scaled, :mod:`gait_nodes.swing.cache`), and each of the robot's gaits is
walked on it by the whole inproc graph, as ``python -m gait_nodes run --fast --robot COPY
--gait GAIT --record BAG`` walks it (every node, the kinematic simulator enforcing the joints'
velocity and acceleration limits, the recorder): straight ahead, asked for
:data:`~gait_nodes.planning.gait_choice.COMMANDED_SPEED_M_S`, so that the footstep planner walks
the fastest rhythm the joints allow (``timing: joint_limit``). Every gait walks with
:data:`WALKED_WITH`: the value table's swings at the thesis' best lift, 0.06 m (the static crawl
is the thesis' value-iteration crawl walked; the same swing for the ZMP crawl and the trot
compares the gaits, not the swings).

What each row says is read back from its bag (:func:`measure`, the definitions of
:mod:`gait_nodes.bag.analysis`):

- speed: the base's net displacement over whole steady cycles (from the second lift-off of the
  first foot to swing to its last in the bag), over their time;
- step period: half the mean time between those lift-offs;
- ZMP: /gait/zmp samples outside the recorded support polygon;
- joints: /joint_states samples over the limit, and the knots the whole-body IK had to slow
  down because the plan asked more of a joint than its limit (its 'velocity saturation'
  reports).

A walk is infeasible, and says why, when it has no steady cycle, its ZMP leaves the support
polygon, a joint goes over its limit, the IK has to slow the plan down, or a node reports an
ERROR.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gait_nodes.errors import ArgumentError
from gait_nodes.planning.gait_choice import COMMANDED_SPEED_M_S

#: Joint velocity limits walked [rad/s] (the thesis' Fig. 21 spans 1-3 rad/s).
LIMITS_RAD_S = (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0)
#: ``--quick``: fewer limits, shorter walks.
QUICK_LIMITS_RAD_S = (1.0, 2.5)
#: Walk duration at 1 rad/s [s]; at a limit W, this over W (every time of a gait scales about
#: as 1 / W): at 1 rad/s the ZMP crawl's start and its first three cycles of 12.5 s, and more
#: of the faster gaits'.
DURATION_AT_1_RAD_S = 70.0
#: ``--quick``: the start and one steady cycle of the ZMP crawl.
QUICK_DURATION_AT_1_RAD_S = 45.0
#: Settings every gait walks with (besides the gait and the robot).
WALKED_WITH = {'swing': 'value_table', 'step_height_m': 0.06, 'com_method': 'preview',
               'timing': 'joint_limit', 'max_vx_m_s': COMMANDED_SPEED_M_S}
#: The whole-body IK's report of the knots it slowed down.
SATURATION = 'whole_body_ik: velocity saturation'


@dataclass(frozen=True)
class WalkedGait:
    """One gait walked at one joint velocity limit, as its bag tells.

    Attributes:
        gait: The gait.
        limit_rad_s: The joint velocity limit [rad/s].
        speed_m_s: Net speed over the steady cycles [m/s] (0: none).
        step_period_s: Half the steady cycle [s] (0: none).
        cycles: Steady cycles measured.
        zmp_outside: /gait/zmp samples outside the support polygon.
        zmp_samples: /gait/zmp samples with a polygon.
        joint_samples_over: /joint_states samples over the limit (any joint).
        joint_peak_ratio: Fastest /joint_states joint speed over the limit.
        com_error_m: Largest distance of the COM (recomputed from /joint_states and /tf) from
            its reference (horizontal) [m]: how closely the robot followed the plan.
        saturated_knots: Knots the whole-body IK slowed down to keep a joint within its limit.
        knots: Knots the whole-body IK solved.
        errors: ERROR statuses on /diagnostics.
        reason: Why the walk is infeasible ('' when it is not).
        walked_s: Simulated time walked [s].
        wall_s: Wall time of the walk and its reading [s].
        bag: The bag it was read from.
    """

    gait: str
    limit_rad_s: float
    speed_m_s: float
    step_period_s: float
    cycles: int
    zmp_outside: int
    zmp_samples: int
    joint_samples_over: int
    joint_peak_ratio: float
    com_error_m: float
    saturated_knots: int
    knots: int
    errors: int
    reason: str
    walked_s: float
    wall_s: float
    bag: str

    @property
    def feasible(self) -> bool:
        """Walked steadily within the joint limits with the ZMP inside, no ERROR."""
        return not self.reason


def walk(robot_yaml: str | Path, gait: str, duration_s: float, bag: str | Path,
         settings: dict | None = None) -> dict:
    """Walk ``gait`` straight ahead at the velocity clamp in the inproc graph, recorded.

    The graph ``python -m gait_nodes run --fast --robot ROBOT_YAML --gait GAIT --record BAG``
    starts (every node, the recorder, the launcher's /cmd_vel re-sent every 0.5 s), with
    ``settings`` (default :data:`WALKED_WITH`) for every node and
    :data:`~gait_nodes.planning.gait_choice.COMMANDED_SPEED_M_S` on /cmd_vel.

    Returns:
        The run summary of :func:`gait_nodes.__main__.run_inproc`.
    """
    import argparse

    import yaml

    from gait_nodes import graph
    from gait_nodes.__main__ import run_inproc
    from gait_nodes.scenarios import DEFAULT_SCENARIO, TimedCommand

    values = {'robot': str(robot_yaml), 'cmd_vel_timeout_s': 2.0,
              **(WALKED_WITH if settings is None else settings), 'gait': gait}
    options = argparse.Namespace(record=str(bag), scenario=DEFAULT_SCENARIO,
                                 duration=float(duration_s), namespace_args=[],
                                 simulator='kinematic', robot=None)
    with tempfile.TemporaryDirectory(prefix='gait_nodes_walk_') as tmp:
        params = Path(tmp) / 'params.yaml'
        params.write_text(yaml.safe_dump({'/**': {'ros__parameters': values}}))
        return run_inproc(options, graph.graph_nodes('kinematic'),
                          ['--ros-args', '--params-file', str(params)],
                          commands=(TimedCommand(0.0, velocity=(COMMANDED_SPEED_M_S, 0.0, 0.0)),))


def measure(bag: str | Path, robot_yaml: str | Path, gait: str, limit_rad_s: float,
            walked_s: float = math.nan, wall_s: float = math.nan) -> WalkedGait:
    """Read one walk's row from its bag (see the module docstring)."""
    from gait_nodes.bag.analysis import executed_swings, inspect_bag, net_speed

    inspection = inspect_bag(bag, robot=str(robot_yaml))
    series, report = inspection.series, inspection.report.get('gait', {})
    base = np.array(sorted(series.base))
    swings = executed_swings(series.plans, int(base[-1, 0])) if len(base) else []
    speed = period = 0.0
    cycles = 0
    if swings:
        first_foot = swings[0]['foot']
        lift_offs = [s['lift_off_ns'] for s in swings if s['foot'] == first_foot]
        cycles = len(lift_offs) - 2  # the first cycle is the start from standstill
        if cycles >= 1:
            speed = net_speed(base, lift_offs[1], lift_offs[-1]) or 0.0
            period = (lift_offs[-1] - lift_offs[1]) * 1e-9 / cycles / 2
    margin = report.get('zmp_margin') or {}
    joints = (report.get('joint_velocity') or {}).get('/joint_states') or {}
    saturated, knots = ik_saturation(bag)
    errors = int(((report.get('diagnostics') or {}).get('by_level') or {}).get('ERROR', 0))
    row = dict(gait=gait, limit_rad_s=float(limit_rad_s), speed_m_s=float(speed),
               step_period_s=float(period), cycles=max(cycles, 0),
               zmp_outside=int(margin.get('samples_outside', 0)),
               zmp_samples=int(margin.get('samples', 0)),
               joint_samples_over=int(joints.get('samples_over_limit') or 0),
               joint_peak_ratio=float(joints.get('peak_ratio_to_limit') or math.nan),
               com_error_m=float(((report.get('consistency') or {}).get('com') or {}).get(
                   'vs_reference', {}).get('max_m', math.nan)),
               saturated_knots=saturated, knots=knots, errors=errors, walked_s=walked_s,
               wall_s=wall_s, bag=str(bag))
    return WalkedGait(**row, reason=_infeasible(row, report))


def ik_saturation(bag: str | Path) -> tuple[int, int]:
    """(knots slowed down, knots solved) by the whole-body IK, from its /diagnostics reports."""
    from gait_nodes.bag.reader import BagReader
    from gait_nodes.interfaces import deserialize_message, get_message

    array = get_message('diagnostic_msgs/msg/DiagnosticArray')
    saturated = knots = 0
    for _, _, _, data in BagReader(bag).messages(topics=['/diagnostics']):
        for status in deserialize_message(data, array).status:
            if status.name == SATURATION:
                values = {v.key: v.value for v in status.values}
                saturated += int(values.get('saturated_ticks', 0))
                knots += int(values.get('ticks', 0))
    return saturated, knots


def _infeasible(row: dict, report: dict) -> str:
    """Why a walk is infeasible ('' when it is not)."""
    reasons = []
    if row['cycles'] < 1 or row['speed_m_s'] <= 0.0:
        reasons.append('no steady cycle walked')
    if row['zmp_outside']:
        reasons.append(f'the ZMP left the support polygon at {row["zmp_outside"]} of '
                       f'{row["zmp_samples"]} samples')
    if row['joint_samples_over']:
        reasons.append(f'joints over the limit at {row["joint_samples_over"]} samples')
    if row['saturated_knots']:
        reasons.append(f'the IK slowed {row["saturated_knots"]} of {row["knots"]} knots to '
                       f'keep the joints within the limit')
    if row['errors']:
        first = ((report.get('diagnostics') or {}).get('first_error') or {})
        reasons.append(f'{row["errors"]} ERROR reports (first: {first.get("name")}: '
                       f'{first.get("message")})')
    return '; '.join(reasons)


def walked_crossover(limits_rad_s: Sequence[float] = LIMITS_RAD_S, robot: str = 'robosimian',
                     gaits: Sequence[str] | None = None,
                     duration_at_1_rad_s: float = DURATION_AT_1_RAD_S,
                     bags_dir: str | Path | None = None, settings: dict | None = None,
                     log: Callable[[str], None] = lambda message: None) -> list[WalkedGait]:
    """Walk each gait at each joint velocity limit and read each walk back from its bag.

    Args:
        limits_rad_s: Joint velocity limits [rad/s].
        robot: Robot name or YAML.
        gaits: Gaits to walk (default: the robot's).
        duration_at_1_rad_s: Walk duration at 1 rad/s [s], over W at a limit W.
        bags_dir: Where the robot copies and the bags are kept (default: a temporary
            directory, removed afterwards).
        settings: Settings of every walk (default :data:`WALKED_WITH`).
        log: Called with a line per walk.

    Returns:
        One row per (limit, gait), limits in the given order.

    Raises:
        ArgumentError: A gait the robot does not have.
        ConfigError: A limit out of (0, 100] rad/s, or a robot YAML that is not valid.
    """
    from gait_nodes.robot.description import (
        load_robot_description,
        write_at_joint_velocity_limit,
    )

    description = load_robot_description(robot)
    gaits = tuple(gaits or description.gaits)
    unknown = [gait for gait in gaits if gait not in description.gaits]
    if unknown:
        raise ArgumentError(f'{unknown} not among the gaits of {description.name}: '
                            f'{list(description.gaits)}')
    settings = dict(WALKED_WITH if settings is None else settings)
    rows = []
    with tempfile.TemporaryDirectory(prefix='gait_nodes_crossover_') as tmp:
        folder = Path(bags_dir) if bags_dir is not None else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for limit in limits_rad_s:
            copy = write_at_joint_velocity_limit(robot, limit, folder / 'robots')
            _ensure_table(copy, settings, log)
            duration_s = duration_at_1_rad_s / float(limit)
            for gait in gaits:
                bag = folder / f'{gait}_w{float(limit):g}'
                started = time.perf_counter()
                summary = walk(copy, gait, duration_s, bag, settings)
                row = measure(bag, copy, gait, limit, summary['simulated_s'],
                              time.perf_counter() - started)
                rows.append(row)
                log(f'{gait} at {float(limit):g} rad/s: {describe(row)} ({row.wall_s:.0f} s)')
    return rows


def _ensure_table(robot_yaml: Path, settings: dict, log: Callable[[str], None]) -> None:
    """The value table of ``settings`` at the copy's limit, made before the graph starts.

    So that the planner times the walk with it from the start (the swing-leg policy would make
    it at its own start, the planner standing in the polynomial swing's times until then).
    """
    if settings.get('swing') != 'value_table':
        return
    from gait_nodes.robot.model import load_robot_model
    from gait_nodes.robot.whole_body_ik import limb_ik_family
    from gait_nodes.swing.cache import load_or_build

    model = load_robot_model(str(robot_yaml))
    load_or_build(model, limb_ik_family(model), settings['step_height_m'],
                  model.description.joint_velocity_limit_rad_s, log=log)


def describe(row: WalkedGait) -> str:
    """One walk in words."""
    walked = (f'{row.speed_m_s:.4f} m/s, steps of {row.step_period_s:.2f} s over {row.cycles} '
              f'steady cycles' if row.cycles >= 1 else 'no steady cycle')
    if row.feasible:
        return walked
    return f'infeasible ({walked}): {row.reason}'


def fastest(rows: Sequence[WalkedGait], limit_rad_s: float) -> WalkedGait | None:
    """The fastest feasible walk at ``limit_rad_s`` (None: none)."""
    feasible = [r for r in rows if r.limit_rad_s == limit_rad_s and r.feasible]
    return max(feasible, key=lambda r: r.speed_m_s, default=None)


def format_table(rows: Sequence[WalkedGait], settings: dict | None = None,
                 duration_at_1_rad_s: float | None = None) -> str:
    """The walks as a Markdown table, said to be walked, and the fastest at each limit."""
    from gait_nodes.swing.sweep import FT_PER_MIN

    settings = WALKED_WITH if settings is None else settings
    how = (f'{settings.get("swing")} swing, {settings.get("step_height_m"):g} m lift, timing '
           f'{settings.get("timing")}')
    duration = ('' if duration_at_1_rad_s is None else
                f', {duration_at_1_rad_s:g} s / (limit in rad/s) each')
    lines = [f'Walked, not modelled: each gait walked straight ahead, asked '
             f'{COMMANDED_SPEED_M_S:g} m/s, by the inproc node graph (python -m gait_nodes run '
             f'--fast) with the robot\'s joints limited to each limit ({how}{duration}); every '
             'figure read back from the walk\'s bag.', '',
             '| limit [rad/s] | gait | speed [m/s] | [ft/min] | step period [s] | steady cycles '
             '| ZMP samples outside | joints over the limit (peak / limit) | knots the IK '
             'slowed | COM off its reference [mm] | walked |',
             '| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |']
    for r in rows:
        verdict = 'feasible' if r.feasible else f'infeasible: {r.reason}'
        lines.append(
            f'| {r.limit_rad_s:g} | {r.gait} | {r.speed_m_s:.4f} | '
            f'{r.speed_m_s * FT_PER_MIN:.2f} | {r.step_period_s:.2f} | {r.cycles} | '
            f'{r.zmp_outside} of {r.zmp_samples} | {r.joint_samples_over} '
            f'({r.joint_peak_ratio:.2f}) | {r.saturated_knots} of {r.knots} | '
            f'{1000 * r.com_error_m:.1f} | {verdict} |')
    lines.append('')
    for limit in dict.fromkeys(r.limit_rad_s for r in rows):
        best = fastest(rows, limit)
        if best is None:
            lines.append(f'{limit:g} rad/s: no gait walked feasibly')
            continue
        others = [r for r in rows if r.limit_rad_s == limit and r is not best and r.feasible]
        runner = max(others, key=lambda r: r.speed_m_s, default=None)
        ahead = ('' if runner is None else
                 f', {best.speed_m_s / runner.speed_m_s:.2f}x the {runner.gait}')
        lines.append(f'{limit:g} rad/s: fastest walked {best.gait} ({best.speed_m_s:.4f} m/s'
                     f'{ahead})')
    return '\n'.join(lines)
