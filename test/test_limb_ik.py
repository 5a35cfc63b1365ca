"""Closed-form RoboSimian limb IK: FK of IK, the thesis workspace, 8 families, continuity."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes.errors import ConfigError
from gait_nodes.robot.limb_ik import (
    FAMILIES,
    RoboSimianLimbIk,
    continuity_breaks,
    family_bits,
    trajectory_ik,
)
from gait_nodes.robot.limb_ik import (
    limb_ik as cached_limb_ik,
)
from gait_nodes.robot.model import load_robot_model

FEET = ('front_left', 'front_right', 'rear_left', 'rear_right')


@pytest.fixture(scope='module')
def robot():
    return load_robot_model('robosimian')


@pytest.fixture(scope='module')
def limb_ik(robot):
    return RoboSimianLimbIk(robot)


def mirrored(foot: str, targets: np.ndarray, yaws: np.ndarray):
    """Thesis workspace targets (front-right) mirrored onto ``foot``."""
    sx = -1.0 if foot.startswith('rear') else 1.0
    sy = -1.0 if foot.endswith('left') else 1.0
    return targets * np.array([sx, sy, 1.0]), yaws * sx * sy


def thesis_workspace(z_values=(-0.7, -0.65, -0.6, -0.55, -0.5), yaws=(-0.3, 0.0, 0.3)):
    """The swing workspace of thesis IV.B.1 for the front-right foot: x 0.2-0.8, y -0.65..-0.4."""
    x, y, z, yaw = np.meshgrid(np.linspace(0.2, 0.8, 13), np.linspace(-0.65, -0.4, 6),
                               z_values, yaws, indexing='ij')
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1), yaw.ravel()


def pinocchio_sole(robot, foot, angles):
    """Sole position and rotation in the base frame by Pinocchio, independently of limb_ik."""
    joints = np.array(robot.posture)
    joints[robot.indices(robot.description.foot(foot).joints)] = angles
    q = robot.configuration(np.zeros(3), 0.0, joints)
    data = robot.new_data()
    pin.framesForwardKinematics(robot.model, data, q)
    placement = data.oMf[robot.foot_frame_ids[robot.foot_names.index(foot)]]
    return placement.translation.copy(), placement.rotation.copy()


@pytest.mark.parametrize('foot', FEET)
@pytest.mark.parametrize('family', FAMILIES)
def test_thesis_workspace_is_reachable_and_fk_of_ik_hits_every_target(robot, limb_ik, foot,
                                                                     family):
    targets, yaws = mirrored(foot, *thesis_workspace())
    q, feasible = limb_ik.solve(targets, yaws, family, foot)
    assert feasible.all()
    assert np.all(np.isfinite(q))
    positions, solved_yaws = limb_ik.forward(q, foot)
    np.testing.assert_allclose(positions, targets, atol=1e-9)
    np.testing.assert_allclose(solved_yaws, yaws, atol=1e-9)
    # Independent check with Pinocchio on a sample: sole on target, level, with the yaw.
    for k in range(0, len(q), 37):
        position, rotation = pinocchio_sole(robot, foot, q[k])
        np.testing.assert_allclose(position, targets[k], atol=1e-9)
        expected = pin.rpy.rpyToMatrix(0.0, 0.0, yaws[k])
        np.testing.assert_allclose(rotation, expected, atol=1e-9)
    assert np.all((q >= limb_ik.lower_limits) & (q <= limb_ik.upper_limits))


@settings(max_examples=40, deadline=None)
@given(x=st.floats(0.2, 0.8), y=st.floats(-0.65, -0.4), z=st.floats(-0.7, -0.5),
       yaw=st.floats(-0.5, 0.5), foot=st.sampled_from(FEET))
def test_eight_families_give_eight_distinct_solutions_for_one_pose(robot, limb_ik, x, y, z,
                                                                    yaw, foot):
    target, target_yaw = mirrored(foot, np.array([[x, y, z]]), np.array([yaw]))
    solutions = []
    for family in FAMILIES:
        q, feasible = limb_ik.solve(target, target_yaw, family, foot)
        assert feasible[0], family
        position, rotation = pinocchio_sole(robot, foot, q[0])
        np.testing.assert_allclose(position, target[0], atol=1e-9)
        np.testing.assert_allclose(rotation, pin.rpy.rpyToMatrix(0, 0, target_yaw[0]),
                                   atol=1e-9)
        assert limb_ik.family_of(q, foot)[0] == family
        # Trying a likely family first changes the cost, not the answer.
        for likely in (family, (family + 3) % 8):
            assert limb_ik.family_of(q, foot, likely=likely)[0] == family
        solutions.append(q[0])
    solutions = np.array(solutions)
    gaps = np.abs(np.angle(np.exp(1j * (solutions[:, None, :6] - solutions[None, :, :6]))))
    distinct = gaps.max(axis=2) + np.eye(8)
    assert distinct.min() > 1e-3
    # The thesis' 3rd (010) and 8th (111) families: shoulder, knee and wrist pitch all differ.
    assert gaps[2, 7][[0, 1, 2, 4]].min() > 1e-3


def test_module_level_limb_ik_matches_the_class(limb_ik):
    targets, yaws = thesis_workspace()
    q, feasible = cached_limb_ik(targets, yaws, 2)
    expected, expected_feasible = limb_ik.solve(targets, yaws, 2)
    np.testing.assert_array_equal(q, expected)
    np.testing.assert_array_equal(feasible, expected_feasible)


def test_family_bits_and_bad_family():
    assert family_bits(2) == (0, 1, 0)
    assert family_bits(7) == (1, 1, 1)
    for bad in (-1, 8, 2.0, True):
        with pytest.raises(ConfigError, match=r'\[0, 7\]'):
            family_bits(bad)


def test_unreachable_and_nan_targets_are_infeasible_without_nan(limb_ik):
    targets = np.array([[0.5, -0.5, -1.5], [3.0, 0.0, 0.0], [np.nan, 0.0, -0.6],
                        [0.4, -0.25, -0.5]])
    q, feasible = limb_ik.solve(targets, np.array([0.0, 0.0, 0.0, np.inf]), 2)
    assert not feasible.any()
    assert np.all(np.isfinite(q))
    # Out of reach: the limb is stretched towards the target (best effort).
    positions, _ = limb_ik.forward(q[:1])
    reach = limb_ik.geometry.thigh_m + limb_ik.geometry.shin_m
    shoulder = limb_ik.geometry.shoulder_in_base
    wrist = positions[0] + [0, 0, limb_ik.geometry.wrist_to_sole_m]
    assert np.linalg.norm(wrist - shoulder) == pytest.approx(reach)


def test_smooth_swing_is_continuous_and_a_family_jump_is_caught(limb_ik):
    s = np.linspace(0.0, 1.0, 200)
    targets = np.stack([0.3 + 0.4 * s, -0.5 + 0.05 * np.sin(np.pi * s),
                        -0.6 + 0.1 * np.sin(np.pi * s)], axis=1)
    yaws = 0.3 * s
    for family in FAMILIES:
        result = trajectory_ik(limb_ik, targets, yaws, family)
        assert result.ok, family
    smooth, _ = limb_ik.solve(targets, yaws, 2)
    other, _ = limb_ik.solve(targets, yaws, 7)
    spliced = np.concatenate([smooth[:100], other[100:]])
    breaks = continuity_breaks(spliced)
    assert breaks.sum() == 1 and breaks[99]
    # Both halves reach their targets: only the continuity check tells them apart.
    np.testing.assert_allclose(limb_ik.forward(spliced)[0], targets, atol=1e-9)
    families = limb_ik.family_of(spliced)
    assert set(families[:100]) == {2} and set(families[100:]) == {7}


def test_passing_through_the_wrist_singularity_breaks_the_branch(limb_ik):
    # Turning the sole far in yaw drives the wrist pitch through +-pi/2, where the wrist
    # branches meet: the fixed-family solution must jump there, and the check must say so.
    yaws = np.linspace(0.0, 2 * np.pi, 400)
    targets = np.tile([0.5, -0.525, -0.65], (len(yaws), 1))
    result = trajectory_ik(limb_ik, targets, yaws, 2)
    positions, solved = limb_ik.forward(result.joint_angles)
    np.testing.assert_allclose(positions, targets, atol=1e-9)
    assert result.breaks.any() or not result.feasible.all()
    assert not result.ok
