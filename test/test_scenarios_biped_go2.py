"""End to end in inproc: the biped_walk and go2_trot scenarios walk, judged from their bags.

Each scenario runs as a user runs it (``python -m gait_nodes run --runtime inproc --scenario NAME
--record DIR``); both run at once, one process each. From the bag:

* through ``inspect``'s analysis (:func:`gait_nodes.bag.analysis.inspect_bag`): no ERROR on
  /diagnostics, the ZMP inside the recorded support polygon at every sample with a positive
  least margin, the whole-body IK never saturated (the plan is feasible, not clipped), the
  commanded speed reached (within 10 %), and the biped standing still after its stop;
* independently, from the raw messages: forward kinematics (Pinocchio) of /tf (full base pose)
  and /joint_states puts every stance foot where /gait/footsteps has it, and the COM the monitor
  reports (/gait/com) is on /gait/com_reference.
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
from gait_nodes.errors import ConfigError
from gait_nodes.kinematic_simulator import node_defaults as simulator_defaults
from gait_nodes.robot.description import example_robot_data_dir
from gait_nodes.robot.model import load_robot_model
from gait_nodes.robot.whole_body_ik import walking_vertical
from gait_nodes.scenarios import get_scenario

#: Monitor samples per second: the simulator's default rate [Hz].
SIM_RATE_HZ = simulator_defaults()['rate_hz']

ROOT = Path(__file__).resolve().parents[1]
#: Scenario -> (run duration [s], commanded forward speed [m/s], window of steady walking [s]).
RUNS = {'biped_walk': (21.0, 0.1, (4.5, 9.0)), 'go2_trot': (10.0, 0.1, (3.0, 10.0))}
#: A stance foot's forward kinematics within this of its footstep [m].
FOOT_TOLERANCE_M = 0.002
#: The monitor's COM within this of the COM reference [m].
COM_TOLERANCE_M = 0.001


@pytest.fixture(scope='module')
def bags(tmp_path_factory) -> dict[str, Path]:
    """Both scenarios recorded, run side by side."""
    try:
        example_robot_data_dir()
    except ConfigError:
        pytest.skip('example-robot-data is not installed (the Go2 model)')
    out = tmp_path_factory.mktemp('scenarios')
    env = {**os.environ, 'PYTHONPATH': str(ROOT), 'XDG_CACHE_HOME': str(out / 'cache')}
    processes = {}
    for name, (duration, _, _) in RUNS.items():
        command = [sys.executable, '-m', 'gait_nodes', 'run', '--runtime', 'inproc',
                   '--scenario', name, '--duration', str(duration), '--record',
                   str(out / name)]
        processes[name] = subprocess.Popen(command, cwd=out, env=env, stdout=subprocess.PIPE,
                                           stderr=subprocess.STDOUT, text=True)
    for name, process in processes.items():
        output, _ = process.communicate(timeout=300)
        assert process.returncode == 0, f'{name}:\n{output[-3000:]}'
    return {name: out / name for name in RUNS}


@pytest.fixture(scope='module')
def inspected(bags):
    return {name: inspect_bag(path) for name, path in bags.items()}


def _raw(bag: Path) -> dict:
    """Full base poses, joint states, footstep plans and COM samples, decoded independently."""
    return decode_gait_topics(bag)


@pytest.fixture(scope='module')
def raw(bags):
    return {name: _raw(path) for name, path in bags.items()}


@pytest.mark.parametrize('name', RUNS)
def test_no_error_and_the_zmp_stays_inside_the_support_polygon(inspected, name):
    report = inspected[name].report['gait']
    levels = report['diagnostics']['by_level']
    assert levels.get('ERROR', 0) == 0, report['diagnostics']['first_error']
    margin = report['zmp_margin']
    assert margin['samples_outside'] == 0 and margin['min_m'] > 0.0, margin
    assert margin['samples'] >= 0.99 * RUNS[name][0] * SIM_RATE_HZ


@pytest.mark.parametrize('name', RUNS)
def test_the_plan_is_feasible_the_ik_never_saturates(inspected, name):
    series = inspected[name].series
    ik = [(status, level, message) for _, status, level, message, _ in series.diagnostics
          if status.startswith('whole_body_ik:')]
    saturation = [(level, message) for status, level, message in ik
                  if status == 'whole_body_ik: velocity saturation']
    assert saturation and all(level == OK for level, _ in saturation), saturation
    assert all(level != ERROR for _, level, _ in ik)
    tracking = {message for status, _, message in ik if status == 'whole_body_ik: tracking'}
    assert tracking == {'feet and COM on target'}, tracking
    for topic, peak in inspected[name].report['gait']['joint_velocity'].items():
        # Below the limit with room: the walk does not ride the joint limits.
        assert peak['samples_over_limit'] == 0 and peak['peak_ratio_to_limit'] < 0.9, topic


@pytest.mark.parametrize('name', RUNS)
def test_the_robot_walks_at_the_commanded_speed(inspected, name):
    _, speed, (start_s, end_s) = RUNS[name]
    base = np.array(sorted(inspected[name].series.base))
    t = base[:, 0] * 1e-9
    chosen = (t >= start_s) & (t <= end_s)
    # Over whole gait cycles the body's mean forward speed is the commanded one.
    fitted = np.polyfit(t[chosen], base[chosen, 1], 1)[0]
    assert fitted == pytest.approx(speed, rel=0.1)
    assert np.abs(base[chosen, 2]).max() < 0.1  # no drift sideways


def test_the_biped_stops_and_stands(inspected, raw):
    series = inspected['biped_walk'].series
    base = np.array(sorted(series.base))
    t = base[:, 0] * 1e-9
    # The stop was commanded at 10 s: it joins at a step boundary beyond the published 2.5 s
    # horizon, then the closing step, then the COM settles.
    last = t >= 19.0
    assert np.ptp(base[last, 1]) < 1e-3 and np.ptp(base[last, 2]) < 1e-3
    plan = raw['biped_walk']['plans'][-1]
    end_s = (base[-1, 0] - plan.start_ns) * 1e-9
    assert plan.contacts_at(end_s).all()
    feet = plan.positions_in_world[plan.index_at(end_s)]
    # Both feet side by side, the body over their middle.
    assert abs(feet[0, 0] - feet[1, 0]) < 1e-6
    com = np.array(sorted(series.com))
    assert np.linalg.norm(com[-1, 1:3] - feet[:, :2].mean(axis=0)) < 0.005
    velocities = np.array(series.joints['/joint_states'].velocities)
    assert np.abs(velocities[-round(SIM_RATE_HZ):]).max() < 0.05  # over the last second


@pytest.mark.parametrize('name', RUNS)
def test_stance_feet_are_where_the_footsteps_put_them(raw, name):
    data = raw[name]
    robot = load_robot_model(get_scenario(name).robot)
    model_data = robot.new_data()
    plans = sorted(data['plans'], key=lambda p: p.start_ns)
    starts = np.array([p.start_ns for p in plans])
    errors = []
    for stamp in sorted(data['tf'])[::5]:
        if stamp not in data['joints']:
            continue
        q = np.zeros(robot.model.nq)
        q[:7] = data['tf'][stamp]
        joints = data['joints'][stamp]
        robot.set_joint_positions(q, np.array([joints[n] for n in robot.joint_names]))
        pin.framesForwardKinematics(robot.model, model_data, q)
        which = np.searchsorted(starts, stamp, side='right') - 1
        if which < 0:
            continue
        plan = plans[which]
        t_s = (stamp - plan.start_ns) * 1e-9
        down, index = plan.contacts_at(t_s), plan.index_at(t_s)
        for k, foot in enumerate(robot.foot_names):
            f = plan.foot_names.index(foot)
            if down[f]:
                sole = model_data.oMf[robot.foot_frame_ids[k]].translation \
                    - [0.0, 0.0, robot.foot_frame_height_m]
                errors.append(np.linalg.norm(sole - plan.positions_in_world[index][f]))
    assert len(errors) > 500
    assert max(errors) < FOOT_TOLERANCE_M


@pytest.mark.parametrize('name', RUNS)
def test_the_monitor_com_tracks_the_com_reference(raw, name):
    com = np.array(sorted(raw[name]['com']), dtype=float)
    reference = np.array(sorted(set(raw[name]['com_reference'])), dtype=float)
    stamps, index = np.unique(reference[:, 0], return_index=True)
    reference = reference[index]
    # The reference starts with the first ZMP reference; judge from then on.
    com = com[(com[:, 0] >= stamps[0]) & (com[:, 0] <= stamps[-1])]
    expected = np.column_stack([np.interp(com[:, 0], stamps, reference[:, i])
                                for i in (1, 2, 3)])
    assert len(com) > 0.9 * RUNS[name][0] * SIM_RATE_HZ
    # The horizontal COM is on its reference; so is its height on a biped, whose IK keeps the
    # COM's height, where a quadruped's keeps the body's (walking_vertical).
    robot = load_robot_model(get_scenario(name).robot)
    columns = 3 if walking_vertical(robot) == 'com' else 2
    assert np.abs(com[:, 1:1 + columns] - expected[:, :columns]).max() < COM_TOLERANCE_M



@pytest.mark.parametrize('name', RUNS)
def test_a_momentum_zmp_recomputed_from_the_bag_is_the_monitors(raw, name):
    """The ZMP and COM of /gait/zmp and /gait/com, from the recorded states by another scheme.

    Every monitor sample is stamped at a recorded /joint_states + /tf instant. There, the COM is
    Pinocchio's of that configuration and the ZMP follows from the rate of change of the
    centroidal momentum, differenced between the two half-steps around the instant (momentum
    at the interpolated configuration with the step's mean velocity), not from the monitor's
    central differences of the configurations: the two agree within 1 mm.
    """
    data = raw[name]
    robot = load_robot_model(get_scenario(name).robot)
    model, model_data = robot.model, robot.new_data()
    stamps = sorted(set(data['tf']) & set(data['joints']))
    zmp = {int(s): np.array(p) for s, *p in data['zmp']}
    com = {int(s): np.array(p) for s, *p in data['com']}
    assert set(zmp) <= set(stamps) and set(com) <= set(stamps)
    qs = []
    for stamp in stamps:
        q = np.zeros(model.nq)
        q[:7] = data['tf'][stamp]
        joints = data['joints'][stamp]
        robot.set_joint_positions(q, np.array([joints[n] for n in robot.joint_names]))
        qs.append(q)
    momenta = []  # (P, L_G) at each half-step
    for k in range(len(qs) - 1):
        step_s = (stamps[k + 1] - stamps[k]) * 1e-9
        momentum = pin.computeCentroidalMomentum(
            model, model_data, pin.interpolate(model, qs[k], qs[k + 1], 0.5),
            pin.difference(model, qs[k], qs[k + 1]) / step_s)
        momenta.append(np.concatenate([momentum.linear, momentum.angular]))
    plans = sorted(data['plans'], key=lambda p: p.start_ns)
    starts = np.array([p.start_ns for p in plans])
    weight = np.array([0.0, 0.0, robot.mass_kg * 9.81])
    worst_zmp = worst_com = 0.0
    checked = 0
    for k in range(1, len(qs) - 1):
        stamp = stamps[k]
        c = pin.centerOfMass(model, model_data, qs[k])
        worst_com = max(worst_com, float(np.linalg.norm(com[stamp] - c)))
        which = np.searchsorted(starts, stamp, side='right') - 1
        if stamp not in zmp or which < 0:
            continue
        plan = plans[which]
        down = plan.contacts_at((stamp - plan.start_ns) * 1e-9)
        pin.framesForwardKinematics(model, model_data, qs[k])
        plane = min(model_data.oMf[robot.foot_frame_ids[i]].translation[2]
                    - robot.foot_frame_height_m for i, foot in enumerate(robot.foot_names)
                    if down[plan.foot_names.index(foot)])
        rate = (momenta[k] - momenta[k - 1]) / ((stamps[k + 1] - stamps[k - 1]) * 0.5e-9)
        force = rate[:3] + weight
        height = c[2] - plane
        expected = [c[0] - (height * force[0] + rate[4]) / force[2],
                    c[1] - (height * force[1] - rate[3]) / force[2], plane]
        worst_zmp = max(worst_zmp, float(np.linalg.norm(zmp[stamp] - expected)))
        checked += 1
    assert checked > 0.9 * RUNS[name][0] * SIM_RATE_HZ
    assert worst_com < 1e-9
    assert worst_zmp < 1e-3
