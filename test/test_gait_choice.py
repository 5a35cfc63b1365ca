"""``gait: auto``: every gait of the robot planned at its joint velocity limit, the fastest walked.

Issue 26.2. The planned walks come from the footstep planner's own GaitPlanner (see
gait_nodes/planning/gait_choice.py); here they are checked for what steady walking must satisfy
(one stride per foot per cycle at most, a ZMP gait's rhythm scaling as 1 / W) and for the choice
and its reasons reaching the planner's log and its 'gait' diagnostic.
"""

import pytest

from gait_nodes import runtime
from gait_nodes.planning.gait_params import GaitParameters, auto_choice, auto_gait
from gait_nodes.robot.description import load_robot_description, write_at_joint_velocity_limit


@pytest.fixture(scope='module')
def robosimian():
    return load_robot_description('robosimian')


@pytest.fixture(scope='module')
def at_1_rad_s(robosimian):
    """The comparison of gait auto on RoboSimian at its own limit (cached for the process)."""
    return auto_choice(robosimian)


def check_steady_walks(choice, robot):
    for candidate in choice.candidates:
        assert candidate.speed_m_s > 0, candidate.describe()
        # Steady walking: a foot moves at most one stride a cycle (two steps), the gait's
        # longest, and a re-timed step only ever lasts longer than the rhythm's.
        stride_m = robot.max_step_length_m(candidate.gait)
        assert candidate.speed_m_s * 2 * candidate.step_period_s <= stride_m * (1 + 1e-6)
        assert candidate.step_period_s >= candidate.rhythm_period_s * (1 - 1e-9)
    feasible = [c for c in choice.candidates if c.feasible]
    speeds = [c.speed_m_s for c in feasible]
    assert speeds == sorted(speeds, reverse=True)
    assert choice.candidates[:len(feasible)] == tuple(feasible)  # the infeasible ones last
    assert choice.gait == feasible[0].gait


def test_auto_walks_the_static_crawl_on_robosimian_at_1_rad_s_and_says_why(robosimian,
                                                                           at_1_rad_s):
    choice = at_1_rad_s
    assert choice.joint_velocity_limit_rad_s == 1.0
    assert {c.gait for c in choice.candidates} == set(robosimian.gaits)
    check_steady_walks(choice, robosimian)
    assert choice.gait == 'static_crawl' == auto_gait(robosimian)
    params = GaitParameters.for_robot(robosimian, timing='joint_limit')
    assert params.gait == 'auto' and params.resolved_gait(robosimian) == 'static_crawl'
    speed = {c.gait: c.speed_m_s for c in choice.candidates}
    # Thesis IV.C: below about 1.9 rad/s the value-iteration crawl outwalks the ZMP gaits; the
    # static crawl (docs/robosimian.md: 0.0281 m/s walked with the value table's swing) more than
    # twice the ZMP crawl (0.0113 m/s with the polynomial swing).
    assert 0.02 < speed['static_crawl'] < 0.03
    assert speed['static_crawl'] > 2 * speed['crawl']
    why = choice.describe()
    assert why.startswith('static_crawl, the fastest planned walk at 1 rad/s (polynomial swing, '
                          '0.1 m lift, timing joint_limit')
    for candidate in choice.candidates:
        assert f'{candidate.gait} {candidate.speed_m_s:.4f} m/s' in why
    # Fixed timing cannot walk the static crawl: auto walks the fastest of the others, and
    # says so.
    from gait_nodes.planning.timing_models import auto_reason

    others = [c.gait for c in choice.candidates if c.gait != 'static_crawl']
    assert auto_gait(robosimian, 'fixed') == others[0]
    assert GaitParameters.for_robot(robosimian).resolved_gait(robosimian) == others[0]
    assert auto_reason(robosimian, 'fixed').startswith(f'{others[0]}: static_crawl, the fastest')
    with pytest.raises(Exception, match="static_crawl.*needs timing 'joint_limit'"):
        GaitParameters.for_robot(robosimian, gait='static_crawl', timing='fixed')
    # A gait the planner refuses is infeasible, with the planner's reason.
    from gait_nodes.planning.gait_choice import plan_gait

    refused = plan_gait(robosimian, 'trot', None, zmp_margin_m=0.06)
    assert not refused.feasible and 'zmp_margin_m = 0.06 cannot be kept' in refused.reason
    assert refused.describe() == f'trot infeasible: {refused.reason}'


def test_at_3_rad_s_auto_walks_the_trot_the_static_crawl_gaining_less(robosimian, at_1_rad_s,
                                                                    tmp_path):
    """Auto's choice changes at a high limit, and why (issue 26.2)."""
    from gait_nodes.planning.gait_choice import compare_gaits
    from gait_nodes.robot.model import load_robot_model

    fast = load_robot_model(str(write_at_joint_velocity_limit('robosimian', 3.0, tmp_path)))
    choice = compare_gaits(fast)
    assert choice.joint_velocity_limit_rad_s == 3.0
    check_steady_walks(choice, robosimian)
    slow = {c.gait: c for c in at_1_rad_s.candidates}
    quick = {c.gait: c for c in choice.candidates}
    # The ZMP gaits' rhythm is their swings' and body moves' times, each max|dq| / W at the
    # velocity limit: three times the limit, a third of the step (but for a transfer held at
    # its 0.3 s floor: the trot's, whose transfer is short) and about three times the speed.
    from gait_nodes.planning.rhythm import MIN_TRANSFER_S

    for gait in ('crawl', 'trot'):
        assert quick[gait].feasible
        third = slow[gait].rhythm_period_s / 3
        assert third * 0.98 <= quick[gait].rhythm_period_s <= third + MIN_TRANSFER_S
        assert quick[gait].speed_m_s == pytest.approx(3 * slow[gait].speed_m_s, rel=0.1)
    # The static crawl is timed for the joints' acceleration limit too (20 rad/s^2): it gains
    # less than 2.5x and the trot outwalks it (thesis: the ZMP gait faster above 2.4 rad/s).
    assert quick['static_crawl'].feasible
    assert quick['static_crawl'].speed_m_s < 2.5 * slow['static_crawl'].speed_m_s
    assert choice.gait == 'trot'
    assert choice.describe().startswith('trot, the fastest planned walk at 3 rad/s')


def test_the_planner_logs_and_reports_which_gait_auto_walks_and_why(robosimian, at_1_rad_s,
                                                                    capsys):
    # The shipped footstep planner settings: gait auto, timing joint_limit.
    runtime.init(args=['test', '--ros-args', '-p', 'robot:=robosimian'], runtime='inproc',
                 signal_handlers=False)
    try:
        from gait_nodes.footstep_planner import FootstepPlanner
        from gait_nodes.interfaces import get_message

        planner = FootstepPlanner()
        assert planner.planner.params.gait == 'auto'
        logged = capsys.readouterr().err
        assert f'gait auto: {at_1_rad_s.describe()}' in logged
        assert 'robosimian: gait auto (static_crawl), timing from the joint limit' in logged
        user = runtime.Node('user', use_global_arguments=False)
        arrays = []
        user.create_subscription(get_message('diagnostic_msgs/msg/DiagnosticArray'),
                                 '/diagnostics', arrays.append, 10)
        executor = runtime.SingleThreadedExecutor()
        executor.add_node(planner)
        executor.add_node(user)
        executor.spin_for(1.5)
        gait = [s for a in arrays for s in a.status if s.name.endswith('footstep_planner: gait')]
        assert gait, [s.name for a in arrays for s in a.status]
        values = {v.key: v.value for v in gait[-1].values}
        assert gait[-1].message.startswith('static_crawl, ')
        assert values['resolved_gait'] == 'static_crawl'
        assert values['auto'] == at_1_rad_s.describe()
    finally:
        runtime.shutdown()
