"""The bag's physics consistency checks: they agree on a consistent motion and catch each lie."""

import math

import numpy as np
import pinocchio as pin
import pytest

from gait_nodes import contract
from gait_nodes.bag.analysis import GaitSeries, JointSeries
from gait_nodes.bag.consistency import consistency_report, inverse_dynamics_zmp
from gait_nodes.robot.model import load_robot_model
from gait_nodes.sim.zmp_monitor import ZmpMonitor

RATE_HZ = 200
SECONDS = 2.0
TOUCH_DOWN_S = 1.0
NS = 1_000_000_000


@pytest.fixture(scope='module')
def robot():
    return load_robot_model('robosimian')


def test_inverse_dynamics_zmp_equals_the_monitors_momentum_rate_zmp(robot):
    monitor = ZmpMonitor(robot.model, robot.description.foot_radius_m, ground_height_m=0.02)
    data = robot.new_data()
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = pin.randomConfiguration(robot.model, -np.ones(robot.model.nq),
                                    np.ones(robot.model.nq))
        q[:3] = rng.uniform(-1, 1, 3) + [0, 0, 1.0]
        v, a = rng.normal(size=robot.model.nv), rng.normal(size=robot.model.nv)
        _, expected, force = monitor.com_and_zmp(q, v, a)
        zmp, fz = inverse_dynamics_zmp(robot.model, data, q, v, a, 0.02)
        assert fz == pytest.approx(force, rel=1e-9)
        if force > 1e-6:
            np.testing.assert_allclose(zmp, expected[:2], atol=1e-9)


def motion(robot):
    """A base sliding along x with joints waving: (stamps [ns], q)."""
    stamps = np.arange(int(SECONDS * RATE_HZ)) * (NS // RATE_HZ)
    rest = robot.joint_positions(robot.configuration((0.0, 0.0, robot.description.body_height_m),
                                                     0.0))
    qs = []
    for stamp in stamps:
        t = stamp * 1e-9
        q = robot.configuration((0.05 * t, 0.01 * math.sin(t), robot.description.body_height_m),
                                0.1 * t, rest + 0.05 * np.sin(2 * t + np.arange(len(rest))))
        qs.append(q)
    return stamps, qs


def consistent_series(robot) -> GaitSeries:
    """What nodes that agree with each other would have recorded for :func:`motion`."""
    stamps, qs = motion(robot)
    monitor = ZmpMonitor(robot.model, robot.description.foot_radius_m)
    series = GaitSeries()
    states = JointSeries(names=list(robot.joint_names))
    data = robot.new_data()
    for i, (stamp, q) in enumerate(zip(stamps, qs, strict=True)):
        series.base_poses.append((int(stamp), *q[:7]))
        series.base.append((int(stamp), q[0], q[1], q[2], 0.0))
        states.stamps_ns.append(int(stamp))
        states.positions.append(list(robot.joint_positions(q)))
        states.velocities.append([0.0] * len(robot.joint_names))
        com = pin.centerOfMass(robot.model, data, q)
        series.com.append((int(stamp), *com))
        series.com_reference.append((int(stamp), *com))
        if 0 < i < len(qs) - 1:
            dt = 1.0 / RATE_HZ
            d1 = pin.difference(robot.model, qs[i - 1], q)
            d2 = pin.difference(robot.model, q, qs[i + 1])
            _, zmp, _ = monitor.com_and_zmp(q, (d1 + d2) / (2 * dt), (d2 - d1) / dt ** 2)
            series.zmp.append((int(stamp), zmp[0], zmp[1]))
    series.zmp_plane_height_m = 0.0
    series.joints['/joint_states'] = states
    # One plan: every foot where it is at the start, the first foot "lands" at TOUCH_DOWN_S
    # where it really is then (it moves all along, being carried by the base).
    k = int(TOUCH_DOWN_S * RATE_HZ)
    start_feet, start_yaws = robot.foot_poses(qs[0], data)
    land_feet, land_yaws = robot.foot_poses(qs[k], data)
    positions = np.stack([start_feet, start_feet.copy()])
    positions[1, 0] = land_feet[0]
    yaws = np.stack([start_yaws, start_yaws.copy()])
    yaws[1, 0] = land_yaws[0]
    series.plans.append(contract.FootstepPlan(0, robot.foot_names, np.array([0.0, TOUCH_DOWN_S]),
                                              positions, yaws))
    return series


def test_a_consistent_recording_passes_every_check(robot):
    checks = consistency_report(robot, consistent_series(robot))
    assert checks['configurations'] == SECONDS * RATE_HZ
    assert checks['com']['vs_reference']['max_m'] < 1e-9
    assert checks['com']['vs_monitor']['max_m'] < 1e-9
    assert checks['zmp']['max_m'] < 1e-6
    assert checks['zmp']['samples'] == SECONDS * RATE_HZ - 2
    assert checks['footholds']['samples'] == 1
    assert checks['footholds']['max_m'] < 1e-9


def test_each_inconsistency_is_caught_with_its_size(robot):
    series = consistent_series(robot)
    series.com_reference = [(s, x + 0.03, y, z) for s, x, y, z in series.com_reference]
    stamp, x, y = series.zmp[100]
    series.zmp[100] = (stamp, x, y + 0.25)
    plan = series.plans[0]
    moved = plan.positions_in_world.copy()
    moved[1, 0, 1] += 0.04
    series.plans = [contract.FootstepPlan(0, plan.foot_names, plan.times_s, moved,
                                          plan.yaws_rad)]
    checks = consistency_report(robot, series)
    assert checks['com']['vs_reference']['max_m'] == pytest.approx(0.03, abs=1e-6)
    assert checks['zmp']['max_m'] == pytest.approx(0.25, abs=1e-6)
    assert checks['footholds']['max_m'] == pytest.approx(0.04, abs=1e-6)
    # The plan says the other feet stand still; the motion carries them along with the base.
    base_travel = np.linalg.norm(np.subtract(series.base[-1][1:3], series.base[0][1:3]))
    assert checks['stance_slip']['max_m'] > 0.5 * base_travel
