"""End to end in inproc: the biped_stairs scenario walks up Lucy's stairway, judged from its bag.

The scenario runs as a user runs it (``python -m gait_nodes run --runtime inproc --scenario
biped_stairs --record DIR``). From the bag:

* through ``inspect``'s analysis: no ERROR on /diagnostics, the ZMP inside the support polygon at
  every sample, the whole-body IK never saturated nor off target, the monitor's ZMP equal to the
  one recomputed by inverse dynamics on the same (stair-height) plane;
* independently, from the raw messages and the scenario's staircase: every foothold on
  /gait/footsteps is at the ground's height and on one tread; forward kinematics (Pinocchio) of
  /tf and /joint_states puts each foot where the plan has it at touch-down and keeps every foot's
  disc above the stairs in swing; the COM rises by the staircase's total rise and ends standing
  on the landing.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from bag_topics import decode_gait_topics

from gait_nodes.bag.analysis import inspect_bag
from gait_nodes.diagnostics import ERROR, OK
from gait_nodes.kinematic_simulator import node_defaults as simulator_defaults
from gait_nodes.planning.gait_params import GaitParameters
from gait_nodes.planning.terrain import Staircase, check_walkable
from gait_nodes.robot.description import load_robot_description
from gait_nodes.robot.model import load_robot_model
from gait_nodes.scenarios import get_scenario

#: Monitor samples per second: the simulator's default rate [Hz].
SIM_RATE_HZ = simulator_defaults()['rate_hz']

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = get_scenario('biped_stairs')
STAIRS = Staircase.from_parameters(SCENARIO.settings)
#: A foot's forward kinematics within this of its planned landing place [m].
FOOT_TOLERANCE_M = 0.002


@pytest.fixture(scope='module')
def bag(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp('stairs')
    env = {**os.environ, 'PYTHONPATH': str(ROOT), 'XDG_CACHE_HOME': str(out / 'cache')}
    command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'inproc', '--scenario',
               SCENARIO.name, '--record', str(out / 'bag'), '--no-plot']
    result = subprocess.run(command, cwd=out, env=env, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return out / 'bag'


@pytest.fixture(scope='module')
def inspected(bag):
    return inspect_bag(bag)


@pytest.fixture(scope='module')
def raw(bag) -> dict:
    """Base poses, joint states, footstep plans, monitor COM and ZMP, decoded independently."""
    return decode_gait_topics(bag)


@pytest.fixture(scope='module')
def feet(raw):
    """(stamps [ns], (N, F, 3) sole positions) by forward kinematics of every recorded sample."""
    robot = load_robot_model(SCENARIO.robot)
    model_data = robot.new_data()
    stamps, soles = [], []
    for stamp in sorted(set(raw['tf']) & set(raw['joints'])):
        q = np.zeros(robot.model.nq)
        q[:7] = raw['tf'][stamp]
        joints = raw['joints'][stamp]
        robot.set_joint_positions(q, np.array([joints[n] for n in robot.joint_names]))
        pin.framesForwardKinematics(robot.model, model_data, q)
        stamps.append(stamp)
        soles.append([model_data.oMf[i].translation - [0.0, 0.0, robot.foot_frame_height_m]
                      for i in robot.foot_frame_ids])
    return np.array(stamps), np.array(soles), robot.foot_names


def test_no_error_the_zmp_stays_inside_and_the_ik_is_on_target(inspected):
    report = inspected.report['gait']
    assert report['diagnostics']['by_level'].get('ERROR', 0) == 0, \
        report['diagnostics']['first_error']
    margin = report['zmp_margin']
    assert margin['samples_outside'] == 0 and margin['min_m'] > 0.01, margin
    assert margin['samples'] >= 0.99 * SCENARIO.duration_s * SIM_RATE_HZ
    ik = [(status, level, message) for _, status, level, message, _
          in inspected.series.diagnostics if status.startswith('whole_body_ik:')]
    saturation = {level for status, level, _ in ik
                  if status == 'whole_body_ik: velocity saturation'}
    assert saturation == {OK}
    assert all(level != ERROR for _, level, _ in ik)
    assert {m for s, _, m in ik if s == 'whole_body_ik: tracking'} == {'feet and COM on target'}
    for topic, peak in report['joint_velocity'].items():
        assert peak['samples_over_limit'] == 0 and peak['peak_ratio_to_limit'] < 0.9, topic
    # The monitor's ZMP and inverse dynamics agree on the plane the monitor put it on.
    assert report['consistency']['zmp']['max_m'] < 1e-4
    # The summary's climb: the base ends the total rise above where it started.
    rise = SCENARIO.settings['stairs_rise_m'] * SCENARIO.settings['stairs_count']
    assert report['base']['rise_m'] == pytest.approx(rise, abs=2e-3)


def test_footholds_are_on_the_treads_at_the_stair_heights(raw):
    robot = load_robot_description(SCENARIO.robot)
    params = GaitParameters.for_robot(robot, **{k: v for k, v in SCENARIO.settings.items()
                                                if k in GaitParameters.__dataclass_fields__})
    keep_before, keep_after = check_walkable(STAIRS, robot, params)
    for plan in raw['plans']:
        footholds = plan.positions_in_world.reshape(-1, 3)
        assert np.allclose(footholds[:, 2], STAIRS.height_at(footholds[:, 0]), atol=1e-9)
        to_riser = STAIRS.risers_x_m[None, :] - footholds[:, :1]  # > 0: ahead of the foot
        assert np.all(to_riser[to_riser > 0] >= keep_before - 1e-9)
        assert np.all(-to_riser[to_riser <= 0] >= keep_after - 1e-9)
    last = raw['plans'][-1].positions_in_world[-1]
    assert last[:, 2] == pytest.approx([STAIRS.total_rise_m] * 2)


def test_feet_land_where_planned_and_clear_the_stairs_in_swing(raw, feet):
    stamps, soles, names = feet
    plans = sorted(raw['plans'], key=lambda p: p.start_ns)
    # A plan replaces the previous ones from its start on: a swing is executed as the last plan
    # that starts at or before its lift-off has it.
    landings = {}
    for plan, later in zip(plans, [*plans[1:], None], strict=True):
        for swing in plan.swings():
            lift_off_ns = plan.start_ns + round(swing.lift_off_s * 1e9)
            if later is None or lift_off_ns < later.start_ns:
                landings[(swing.foot, lift_off_ns)] = (
                    plan.start_ns + round(swing.touch_down_s * 1e9), swing.end_in_world)
    assert len(landings) >= 6
    errors = []
    for (foot, _), (touch_down_ns, end) in landings.items():
        k = int(np.searchsorted(stamps, touch_down_ns))
        if k < len(stamps) and stamps[k] - touch_down_ns < 10_000_000:
            errors.append(np.linalg.norm(soles[k, names.index(foot)] - end))
    assert len(errors) >= 6 and max(errors) < FOOT_TOLERANCE_M
    # Every foot at every sample: its sole above the ground under it (on it in stance).
    extent = load_robot_description(SCENARIO.robot).sole_extent_x_m
    clearance = soles[:, :, 2] - STAIRS.highest_under(soles[:, :, 0], *extent)
    assert clearance.min() > -1e-4
    # The feet did climb, from the ground to the landing.
    assert soles[0, :, 2] == pytest.approx([0.0, 0.0], abs=1e-5)
    assert soles[-1, :, 2] == pytest.approx([STAIRS.total_rise_m] * 2, abs=1e-5)


def test_the_com_climbs_by_the_total_rise_smoothly_and_stands_on_the_landing(raw, feet):
    com = np.array(sorted(raw['com']))
    assert com[-1, 3] - com[0, 3] == pytest.approx(STAIRS.total_rise_m, abs=1e-3)
    reference = np.array(sorted(set(raw['com_reference'])))
    t = reference[:, 0] * 1e-9
    z, vz, az = reference[:, 3], reference[:, 6], reference[:, 9]
    # The reference's height, vertical velocity and acceleration are continuous and consistent:
    # between its states (20 ms apart) the COM climbs at most 0.2 m/s with a jerk of at most
    # 10 m/s^3.
    step_s = np.diff(t)
    assert np.all(np.abs(np.diff(z)) < 0.2 * step_s)
    assert np.all(np.abs(np.diff(az)) < 10.0 * step_s)
    assert np.allclose(np.gradient(z, t)[1:-1], vz[1:-1], atol=2e-3)
    # The monitor's ZMP is on the plane of the lowest contact, and climbs with it.
    zmp = np.array(sorted(raw['zmp']))
    stamps, soles, _ = feet
    k = np.searchsorted(stamps, zmp[:, 0]).clip(0, len(stamps) - 1)
    assert np.all(zmp[:, 3] <= soles[k, :, 2].max(axis=1) + 1e-6)
    assert zmp[-1, 3] == pytest.approx(STAIRS.total_rise_m, abs=1e-5)
    # Stopped: standing still on the landing, the COM over the middle of the feet.
    last = stamps >= stamps[-1] - 2e9
    assert np.ptp(soles[last], axis=0).max() < 1e-4
    assert np.linalg.norm(com[-1, 1:3] - soles[-1, :, :2].mean(axis=0)) < 0.005
