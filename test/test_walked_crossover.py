"""The walked crossover (issue 26.2, thesis Fig. 21): each gait walked by the graph, from bags.

The rows come from the inproc graph's bags (the session fixture ``tiny_crossover``: every
RoboSimian gait at 2.5 rad/s); here they are checked against what the bags and the footstep
planner say independently: the walk's rhythm is the one the planner times at that limit, a
foot moves at most one stride a cycle, and the ZMP stays inside.
"""

import math

import pytest

from gait_nodes import walked_crossover as walked


def test_each_gait_is_walked_at_the_limit_and_read_from_its_bag(tiny_crossover):
    from gait_nodes.planning.gait_choice import compare_gaits
    from gait_nodes.robot.description import load_robot_description
    from gait_nodes.robot.model import load_robot_model

    folder, rows = tiny_crossover
    robosimian = load_robot_description('robosimian')
    assert [(r.gait, r.limit_rad_s) for r in rows] == [(g, 2.5) for g in robosimian.gaits]
    copy = folder / 'robots' / 'robosimian_w2.5.yaml'
    assert load_robot_description(copy).joint_velocity_limit_rad_s == 2.5
    planned = compare_gaits(load_robot_model(str(copy)))
    for row in rows:
        assert (folder / f'{row.gait}_w2.5' / 'metadata.yaml').is_file()
        assert row.bag == str(folder / f'{row.gait}_w2.5')
        assert row.walked_s == pytest.approx(16.0)
        assert row.feasible, walked.describe(row)
        assert row.cycles >= 1 and row.zmp_samples > 1000 and row.knots > 1000
        assert row.zmp_outside == 0 and row.joint_samples_over == 0
        assert row.joint_peak_ratio <= 1.0 + 1e-9 and row.com_error_m < 0.01
        # A foot moves at most one stride (0.2 m) a cycle (two steps), and so does the body.
        assert row.speed_m_s * 2 * row.step_period_s <= robosimian.max_step_length_m(
            row.gait) * 1.02
        # The graph walks the rhythm the planner times at 2.5 rad/s (re-timed steps included).
        plan = planned.candidate(row.gait)
        assert row.step_period_s == pytest.approx(plan.step_period_s, rel=0.03)
        assert row.speed_m_s == pytest.approx(plan.speed_m_s, rel=0.06)


def test_the_table_says_it_is_walked_and_an_infeasible_walk_says_why(tiny_crossover):
    import dataclasses

    _, rows = tiny_crossover
    fallen = dataclasses.replace(rows[0], zmp_outside=3,
                                 reason='the ZMP left the support polygon at 3 of 1200 samples')
    text = walked.format_table([fallen, *rows[1:]])
    assert text.startswith('Walked, not modelled: each gait walked straight ahead')
    assert (f'| 2.5 | {fallen.gait} | {fallen.speed_m_s:.4f} |' in text and
            '| infeasible: the ZMP left the support polygon at 3 of 1200 samples |' in text)
    best = max(rows[1:], key=lambda r: r.speed_m_s)
    assert walked.fastest([fallen, *rows[1:]], 2.5) == best
    assert f'2.5 rad/s: fastest walked {best.gait} ({best.speed_m_s:.4f} m/s' in text
    assert not math.isnan(best.speed_m_s)
