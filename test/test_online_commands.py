"""Every kind of command sent mid-step, in the deterministic inproc runtime (issue 25).

Judged from the planner's messages alone: the command is decided once, joins the plan at a step
boundary no earlier than the ZMP horizon already published (so the published reference and
footsteps before it stay exactly as they were), takes effect there with one 'applied' answer,
and the ZMP reference keeps inside the support polygon throughout. A full graph (IK, simulator)
walks the biped's scripted command sequence with the ZMP of the full model inside and every
joint command within its limits; bench/commands.py does the same over dds and rclpy, loaded.
"""

import json

import numpy as np
import pytest
from planning_helpers import QUADRUPED
from test_footstep_planner_node import Graph, check_zmp_inside, merged_plan, twist_msg

from gait_nodes import runtime

NS = 1_000_000_000
HORIZON_S = 2.5  # footstep_planner's zmp_horizon_s default

COMMANDS = {
    'step height': {'step_height_m': 0.08},
    'step length': {'step_length_m': 0.15},
    'step period': {'step_period_s': 1.2},
    'duty factor': {'duty_factor': 0.9},
    'gait': {'gait': 'trot', 'duty_factor': 0.6},
    'swing': {'swing': 'polynomial'},
    'zmp margin': {'zmp_margin_m': 0.02},
}
VELOCITIES = {
    'speed': (0.05, 0.0, 0.0),
    'direction': (0.0, 0.05, 0.0),
    'turn': (0.05, 0.0, 0.1),
    'stop': (0.0, 0.0, 0.0),
}


@pytest.fixture
def walking():
    graph = Graph(QUADRUPED, step_period_s=1.0, max_vx_m_s=0.5, max_wz_rad_s=0.5)
    graph.cmd_vel.publish(twist_msg(0.1))
    graph.spin(5.0)
    while not mid_swing(graph):  # a foot in the air
        graph.spin(0.01)
    yield graph
    runtime.shutdown()


def mid_swing(graph) -> bool:
    now_ns = graph.planner.get_clock().now().nanoseconds
    plan = graph.plans()[-1]
    return any(plan.start_ns + s.lift_off_s * NS < now_ns < plan.start_ns + s.touch_down_s * NS
               for s in plan.swings())


def published_until(graph, until_ns):
    """The newest ZMP reference and footsteps, as they say things before ``until_ns``."""
    reference = graph.references()[-1]
    plan = merged_plan(graph.plans())
    stamps = reference.stamps_ns[reference.stamps_ns < until_ns]
    keep = plan.start_ns + np.round(plan.times_s * NS) < until_ns
    return stamps, reference.sample(stamps), plan.positions_in_world[keep]


def check_joined_at_a_boundary_ahead(graph, before_stamps, before_zmp, before_feet,
                                     takes_effect_ns, sent_ns):
    assert takes_effect_ns >= sent_ns + HORIZON_S * NS
    # What was published before the boundary is what is published now.
    after = graph.references()[-1]
    common = before_stamps[before_stamps < takes_effect_ns]
    np.testing.assert_allclose(after.sample(common), before_zmp[:len(common)], atol=1e-12)
    plan = merged_plan(graph.plans())
    times_ns = plan.start_ns + np.round(plan.times_s * NS)
    kept = plan.positions_in_world[times_ns < takes_effect_ns]
    np.testing.assert_allclose(kept[-len(before_feet):][:len(before_feet)],
                               before_feet[-len(kept):], atol=1e-12)
    # The boundary is a contact change with every foot down: no swing spans it.
    for swing in plan.swings():
        lift = plan.start_ns + swing.lift_off_s * NS
        touch = plan.start_ns + swing.touch_down_s * NS
        assert not lift < takes_effect_ns < touch


@pytest.mark.parametrize('kind', list(COMMANDS))
def test_a_gait_command_mid_step_joins_at_a_boundary_and_is_applied_once(walking, kind):
    assert mid_swing(walking)
    sent_ns = walking.planner.get_clock().now().nanoseconds
    before = published_until(walking, sent_ns + 10 * NS)
    command = {'id': f'kind-{kind}', **COMMANDS[kind]}
    decision = walking.command(json.dumps(command))
    assert decision['id'] == command['id'] and decision['state'] == 'accepted', decision
    for key, value in COMMANDS[kind].items():
        assert decision['params'][key] == value
    # The gait walked after the change, for the swing-leg policy's time law ('auto', the
    # graph's, is the fixture robot's first gait: it has no limb IK to compare its gaits with).
    assert decision['resolved_gait'] == COMMANDS[kind].get('gait', 'crawl')
    walking.spin(0.05)
    takes_effect_ns = decision['takes_effect_ns']
    check_joined_at_a_boundary_ahead(walking, *before, takes_effect_ns, sent_ns)
    # The same command again (a retry) is answered again and not planned again.
    repeat = walking.command(json.dumps(command))
    assert repeat['repeated'] and repeat['state'] == 'accepted'
    walking.spin((takes_effect_ns - sent_ns) / NS + 0.2)
    answers = [s for s in walking.status if s['id'] == command['id']]
    assert [s['state'] for s in answers if not s.get('repeated')] == ['accepted', 'applied']
    walking.spin(6.0)
    check_zmp_inside(walking, 0.055, 0.01)


@pytest.mark.parametrize('kind', list(VELOCITIES))
def test_a_velocity_mid_step_joins_at_a_boundary(walking, kind):
    assert mid_swing(walking)
    sent_ns = walking.planner.get_clock().now().nanoseconds
    before = published_until(walking, sent_ns + 10 * NS)
    walking.cmd_vel.publish(twist_msg(*VELOCITIES[kind]))
    walking.spin(0.3)
    report = walking.statuses('velocity')[-1]
    values = {v.key: v.value for v in report.values}
    assert json.loads(f'[{values["requested_twist"]}]') == list(VELOCITIES[kind])
    takes_effect_ns = walking.planner.origin_ns + int(round(float(values['takes_effect_s']) * NS))
    check_joined_at_a_boundary_ahead(walking, *before, takes_effect_ns, sent_ns)
    walking.spin(8.0)
    check_zmp_inside(walking, 0.055, 0.01)


def test_a_command_the_robot_cannot_walk_is_refused_and_changes_nothing():
    # RoboSimian's joints (1 rad/s) cannot swing a 0.2 m stride in 0.4 s: the fixed timing
    # passes every range check and is refused by planning it, named; nothing changes.
    graph = Graph('robosimian', gait='crawl', swing='polynomial')
    try:
        graph.cmd_vel.publish(twist_msg(0.01))
        graph.spin(12.0)
        before = graph.references()[-1]
        fast = {'id': 'fast', 'timing': 'fixed', 'step_period_s': 2.0, 'duty_factor': 0.9}
        decision = graph.command(json.dumps(fast))
        assert decision['state'] == 'rejected', decision
        assert 'the joints cannot follow' in decision['reason']
        assert decision['params']['timing'] == 'joint_limit'
        graph.spin(0.3)
        after = graph.references()[-1]
        common = np.intersect1d(before.stamps_ns, after.stamps_ns)
        np.testing.assert_allclose(after.sample(common), before.sample(common), atol=1e-12)
        assert graph.planner.get_parameter('timing').value == 'joint_limit'
    finally:
        runtime.shutdown()


def test_a_flood_of_commands_is_answered_every_one():
    graph = Graph(QUADRUPED, step_period_s=1.0)
    try:
        graph.cmd_vel.publish(twist_msg(0.1))
        graph.spin(3.0)
        for k in range(300):
            graph.command_publisher.publish(type(graph.command_publisher.msg_type())(
                data=json.dumps({'id': f'flood-{k}', 'step_length_m': 0.1 + 0.001 * k})))
        graph.spin(6.0)
        decisions = {}
        for status in graph.status:
            if status['state'] != 'applied':
                decisions.setdefault(status['id'], []).append(status['state'])
        assert sorted(decisions) == sorted(f'flood-{k}' for k in range(300))
        assert all(len(states) == 1 for states in decisions.values())
        assert decisions['flood-299'] == ['accepted']
    finally:
        runtime.shutdown()


def test_a_fixed_timing_the_bipeds_joints_cannot_follow_is_refused():
    # The biped has no closed-form limb IK: its swings are probed through the whole-body IK
    # (velocity and acceleration limits). A 0.48 s swing of a 0.24 m stride is too fast.
    graph = Graph('biped', gait='biped', swing='polynomial', step_period_s=1.5,
                  duty_factor=0.72, max_vx_m_s=0.1)
    try:
        graph.cmd_vel.publish(twist_msg(0.1))
        graph.spin(4.0)
        decision = graph.command(json.dumps({'id': 'fast', 'step_period_s': 1.2,
                                             'duty_factor': 0.8}))
        assert decision['state'] == 'rejected', decision
        assert 'the joints cannot follow the swing' in decision['reason']
        assert decision['params']['step_period_s'] == 1.5
        ok = graph.command(json.dumps({'id': 'slower', 'step_period_s': 1.7}))
        assert ok['state'] == 'accepted', ok
    finally:
        runtime.shutdown()
