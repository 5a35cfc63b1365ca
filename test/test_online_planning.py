"""The planning worker (gait_nodes.planning.online) driven directly, without a runtime.

What it must guarantee: a change joins the live plan at a step boundary ahead of the clock and
leaves everything before it as it was; a change that cannot be walked changes nothing; every
command gets exactly one decision (and an accepted one its 'applied' answer once); an id is
applied once; in a thread, the control path's plan keeps covering its horizon while a slow
change is planned, and a change is never handed over closer to the clock than its lead.
"""

import dataclasses
import threading
import time

import numpy as np
import pytest
from planning_helpers import robot

from gait_nodes.errors import GaitParameterError
from gait_nodes.planning import online
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D
from gait_nodes.planning.online import (
    ACCEPTED,
    APPLIED,
    REJECTED,
    RESCHEDULED,
    Answer,
    OnlinePlanner,
    VelocityApplied,
)

NS = 1_000_000_000
LEAD_S = 1.0  # what the control path has published ahead
QUADRUPED = robot('quadruped')


class FakeClock:
    """A clock the test moves: ROS time [ns]."""

    def __init__(self):
        self.now_ns = 0

    def __call__(self):
        """ROS time now [ns]."""
        return self.now_ns

    def advance(self, seconds):
        """Move the clock ``seconds`` on."""
        self.now_ns += int(round(seconds * NS))


def walking(clock, threaded=False, lead_s=LEAD_S):
    planner = GaitPlanner(QUADRUPED)
    planner.set_velocity(Twist2D(0.1), 0.0)
    worker = OnlinePlanner(planner, 0, clock, cover_s=6.0, lead_s=lead_s, threaded=threaded)
    return worker


def step_length(step_length_m):
    def apply(fork, at_s):
        fork.set_parameters(fork.params.replace(step_length_m=step_length_m), at_s)
    return apply


def answers(worker):
    return [event for event in worker.events() if isinstance(event, Answer)]


def decisions_within(worker, timeout_s: float) -> list:
    """The first answers of a threaded worker, waited for up to ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    decisions = []
    while not decisions and time.monotonic() < deadline:
        decisions = answers(worker)
        time.sleep(0.01)
    return decisions


def test_a_change_joins_at_a_step_boundary_after_its_lead_and_keeps_what_came_before():
    clock = FakeClock()
    worker = walking(clock)
    clock.advance(3.3)  # mid-step
    worker.run_pending()
    before = worker.snapshot.planner
    assert worker.submit_command('a', '{}', step_length(0.15)) is None
    worker.run_pending()
    (decision,) = answers(worker)
    assert decision.state == ACCEPTED and decision.params['step_length_m'] == 0.15
    join_s = decision.takes_effect_ns / NS
    now_s = clock.now_ns / NS
    assert join_s >= now_s + LEAD_S + online.LEAD_MARGIN_S
    after = worker.snapshot.planner
    # Every step that starts before the join is the same object; the steps from the join on
    # are new, planned with the new length and starting where the old ones ended.
    kept = [step for step in after.steps if step.start_s < join_s - 1e-12]
    assert kept and all(any(step is old for old in before.steps) for step in kept)
    assert kept[-1].end_s == pytest.approx(join_s)
    new = [step for step in after.steps if step.start_s >= join_s - 1e-12]
    assert new and all(step.params.step_length_m == 0.15 for step in new)
    np.testing.assert_allclose(new[0].positions_start, kept[-1].positions_end, atol=0)
    times = np.linspace(now_s, join_s, 200)
    np.testing.assert_allclose(after.zmp(times), before.zmp(times), atol=1e-12)
    # Its answer that it took effect comes once the clock passes the boundary, once.
    clock.advance(join_s - now_s - 0.01)
    assert answers(worker) == []
    clock.advance(0.02)
    (applied,) = answers(worker)
    assert applied.state == APPLIED and applied.command_id == 'a'
    clock.advance(5.0)
    assert answers(worker) == []


def test_a_change_that_cannot_be_walked_changes_nothing():
    clock = FakeClock()
    worker = walking(clock)
    clock.advance(2.0)
    worker.run_pending()
    before = worker.snapshot.planner

    def unwalkable(fork, at_s):
        fork.set_parameters(fork.params.replace(step_length_m=0.12), at_s)
        raise GaitParameterError('no: a swing leaves the reach')

    worker.submit_command('bad', '{}', unwalkable)
    worker.run_pending()
    (decision,) = answers(worker)
    assert decision.state == REJECTED and 'reach' in decision.reason
    assert decision.params == before.params.to_dict()
    after = worker.snapshot.planner
    assert after.params == before.params
    assert all(a is b for a, b in zip(after.steps, before.steps, strict=False))


def test_commands_waiting_together_are_planned_together_and_each_answered_once():
    clock = FakeClock()
    worker = walking(clock)
    ids = [f'c{k}' for k in range(1000)]
    for k, command_id in enumerate(ids):
        worker.submit_command(command_id, '{}', step_length(0.1 + 0.0001 * (k % 100)))
    worker.run_pending()
    decisions = answers(worker)
    assert sorted(a.command_id for a in decisions) == sorted(ids)
    states = {a.command_id: a.state for a in decisions}
    assert all(state == ACCEPTED for state in states.values())
    assert len({a.takes_effect_ns for a in decisions}) == 1  # one plan for all of them
    assert 'planned together with' in decisions[0].reason
    assert worker.snapshot.planner.params.step_length_m == pytest.approx(0.1 + 0.0001 * 99)


def test_a_repeated_id_is_answered_again_and_not_applied_again():
    clock = FakeClock()
    worker = walking(clock)
    calls = []

    def counted(fork, at_s):
        calls.append(at_s)
        step_length(0.15)(fork, at_s)

    worker.submit_command('once', '{}', counted)
    worker.run_pending()
    (first,) = answers(worker)
    repeat = worker.submit_command('once', '{}', counted)
    worker.run_pending()
    assert repeat is not None and repeat.repeated and repeat.state == first.state
    assert [a.repeated for a in answers(worker)] == [True]
    assert len(calls) == 1


def test_a_velocity_is_planned_ahead_and_reported_once():
    clock = FakeClock()
    worker = walking(clock)
    clock.advance(1.0)
    worker.submit_velocity(Twist2D(0.03))
    worker.submit_velocity(Twist2D(0.08))  # the latest waiting twist wins
    worker.run_pending()
    events = [e for e in worker.events() if isinstance(e, VelocityApplied)]
    assert len(events) == 1 and events[0].requested == Twist2D(0.08)
    assert events[0].takes_effect_ns >= clock.now_ns + LEAD_S * NS
    worker.submit_velocity(Twist2D(0.08))  # the same twist: nothing to plan
    worker.run_pending()
    assert worker.events() == []


def test_in_a_thread_the_plan_covers_the_horizon_while_a_slow_change_is_planned():
    start = time.monotonic_ns()

    def clock():
        return time.monotonic_ns() - start

    worker = walking(clock, threaded=True)
    worker.start()
    try:
        def slow(fork, at_s):
            time.sleep(1.5)  # longer than the margin: the first plan joins too late
            step_length(0.15)(fork, at_s)

        worker.submit_command('slow', '{}', slow)
        covered = []
        deadline = time.monotonic() + 10.0
        decisions = []
        while not decisions and time.monotonic() < deadline:
            now_s = clock() / NS
            covered.append(worker.snapshot.planned_until_s - now_s)
            decisions = answers(worker)
            time.sleep(0.01)
        (decision,) = decisions
        handed_over_ns = clock()
        assert decision.state == ACCEPTED
        # Planned again from a later start: the join still a lead ahead of the handover.
        assert decision.takes_effect_ns - handed_over_ns >= (LEAD_S - 0.1) * NS
        assert min(covered) > 2.5  # the control path's horizon stayed covered
    finally:
        worker.stop()


def test_in_a_thread_a_node_slow_to_publish_plans_makes_changes_join_that_much_later():
    # The node took 2 s to publish the worker's newest plan (a loaded machine): a command
    # joins at least that much further ahead than the lead and margin, so that its plan is
    # out before the motion it changes.
    start = time.monotonic_ns()

    def clock():
        return time.monotonic_ns() - start

    worker = walking(clock, threaded=True)
    late_s = 2.0
    snapshot = worker.snapshot
    worker.delivered(dataclasses.replace(snapshot, ready_s=time.monotonic() - late_s))
    worker.start()
    try:
        submitted_ns = clock()
        worker.submit_command('after_a_slow_publish', '{}', step_length(0.15))
        (decision,) = decisions_within(worker, 20.0)
        assert decision.state == ACCEPTED
        assert decision.takes_effect_ns - submitted_ns >= (
            LEAD_S + online.LEAD_MARGIN_S + late_s) * NS
    finally:
        worker.stop()


def test_in_a_thread_a_change_always_too_slow_is_rejected_as_busy():
    start = time.monotonic_ns()
    worker = walking(lambda: time.monotonic_ns() - start, threaded=True, lead_s=0.05)
    worker.start()
    entered = threading.Event()
    try:
        def slower_each_time(fork, at_s):
            entered.set()
            time.sleep(0.1 + at_s - (time.monotonic_ns() - start) / NS)  # past the join
            step_length(0.15)(fork, at_s)

        worker.submit_command('slow', '{}', slower_each_time)
        (decision,) = decisions_within(worker, 20.0)
        assert decision.state == REJECTED and decision.reason.startswith('busy')
        assert worker.snapshot.planner.params.step_length_m != 0.15
    finally:
        worker.stop()


def test_a_plan_from_scratch_starts_when_it_is_handed_over():
    clock = FakeClock()
    worker = walking(clock)
    clock.advance(7.0)

    def make(live):
        clock.advance(1.5)  # the worker's time making it: the robot stands meanwhile
        return GaitPlanner(QUADRUPED, live.params, base_pose=(1.0, 0.0, 0.0))

    worker.submit_replace(make, 'restart')
    worker.run_pending()
    (replaced,) = [e for e in worker.events() if isinstance(e, online.Replaced)]
    assert replaced.token == 'restart' and replaced.error is None
    snapshot = worker.snapshot
    assert snapshot.generation == 1 and snapshot.origin_ns == clock.now_ns
    assert snapshot.planned_until_s >= 6.0  # planned cover_s ahead before the handover

    def broken(live):
        raise GaitParameterError('no plan')

    worker.submit_replace(broken, 'again')
    worker.run_pending()
    (failed,) = [e for e in worker.events() if isinstance(e, online.Replaced)]
    assert isinstance(failed.error, GaitParameterError)
    assert worker.snapshot.generation == 1  # the live plan goes on


@pytest.mark.parametrize('first, then', [
    (Twist2D(0.1), Twist2D(0.05, 0.0, 0.1)),   # walking: a turn
    (Twist2D(0.1), Twist2D()),                 # walking: stop
    (Twist2D(), Twist2D(0.1)),                 # standing, stopping: go
])
def test_a_change_from_any_time_leaves_the_plan_before_it_as_it_was(first, then):
    # The worker's join rests on this: a change planned from at_s keeps everything before
    # at_s (the ZMP reference and the footholds), whatever the step under way then.
    planner = GaitPlanner(QUADRUPED)
    planner.set_velocity(Twist2D(0.1), 0.0)
    planner.advance(6.0)
    planner.set_velocity(first, 6.0)
    planner.advance(30.0)
    before_plan = planner.footstep_plan()
    for at_s in np.arange(6.0, 16.0, 0.37):
        fork = planner.fork()
        fork.set_velocity(then, float(at_s))
        fork.advance(30.0)
        times = np.linspace(0.0, at_s, 400)
        np.testing.assert_allclose(fork.zmp(times), planner.zmp(times), atol=1e-12,
                                   err_msg=f'the ZMP before {at_s:.2f} s changed')
        plan = fork.footstep_plan()
        kept = plan.times_s <= at_s
        np.testing.assert_allclose(plan.positions_in_world[kept],
                                   before_plan.positions_in_world[:kept.sum()], atol=1e-12)


def test_a_stop_that_joins_before_a_commands_boundary_reschedules_it_and_says_so():
    # A command walkable only from a later boundary; a stop then joins before that boundary:
    # the stop's steps are planned with the command's settings, so the command takes effect
    # where the stop joins, and a RESCHEDULED answer says so before that boundary comes.
    clock = FakeClock()
    worker = walking(clock)
    clock.advance(3.3)
    worker.run_pending()
    later_than_s = None

    def from_a_later_boundary(fork, at_s):
        if at_s < later_than_s:
            raise GaitParameterError('not from this boundary')
        fork.set_parameters(fork.params.replace(step_length_m=0.15), at_s)

    later_than_s = worker.snapshot.planner.next_boundary_s(3.3 + LEAD_S + online.LEAD_MARGIN_S)
    worker.submit_command('late', '{}', from_a_later_boundary)
    worker.run_pending()
    (decision,) = answers(worker)
    assert decision.state == ACCEPTED
    announced_ns = decision.takes_effect_ns
    worker.submit_velocity(Twist2D())  # stop, joining at the first boundary after its lead
    worker.run_pending()
    (moved,) = answers(worker)
    assert moved.state == RESCHEDULED and moved.command_id == 'late' and moved.accepted
    assert clock.now_ns + LEAD_S * NS <= moved.takes_effect_ns < announced_ns
    plan = worker.snapshot.planner
    new = [step.params.step_length_m == 0.15 for step in plan.steps]
    first_new = plan.steps[new.index(True)]
    assert first_new.start_s * NS == pytest.approx(moved.takes_effect_ns, abs=1e3)
    assert all(new[new.index(True):]) and not any(new[:new.index(True)])
    clock.advance((moved.takes_effect_ns - clock.now_ns) / NS)
    worker.run_pending()
    (applied,) = answers(worker)
    assert applied.state == APPLIED and applied.takes_effect_ns == moved.takes_effect_ns
    clock.advance(10.0)
    worker.run_pending()
    assert answers(worker) == []  # applied once, rescheduled once


class SlowToWalk(GaitPlanner):
    """A planner on a slow machine: a search, then a slow first plan of each new walk.

    The fastest walk in a new direction takes 1 s to search, and its first plan from standstill
    1 s (its probes), once for every fork (as the planner's shared caches keep them); planned
    again, it takes 0.2 s.
    """

    searched: set = set()
    probed: set = set()
    plans: list[float] = []

    def set_velocity(self, twist, now_s):
        """As the planner's, after the search the first time ``twist`` is asked."""
        if twist not in SlowToWalk.searched:
            time.sleep(1.0)
            SlowToWalk.searched.add(twist)
        self.unplanned = twist
        return super().set_velocity(twist, now_s)

    def advance(self, until_s):
        """As the planner's, 1 s later when a new walk is planned first, 0.2 s after that."""
        twist = getattr(self, 'unplanned', None)
        if twist is not None:
            self.unplanned = None
            time.sleep(WARM_S if twist in SlowToWalk.probed else COLD_S)
            SlowToWalk.probed.add(twist)
            SlowToWalk.plans.append(until_s)
        return super().advance(until_s)


COLD_S, WARM_S = 1.0, 0.2
FORWARD = Twist2D(0.1)


def first_walk(rehearsed: bool, twist: Twist2D = FORWARD) -> tuple[int, float]:
    """A threaded worker's first walk from standstill: its plans, and its join after asked [s]."""
    start = time.monotonic_ns()

    def clock():
        return time.monotonic_ns() - start

    done = []
    worker = OnlinePlanner(SlowToWalk(QUADRUPED), 0, clock, cover_s=6.0, lead_s=LEAD_S,
                           standing_lead_s=0.2, threaded=True,
                           job_done=lambda kind, seconds: done.append(kind))
    SlowToWalk.plans, SlowToWalk.searched, SlowToWalk.probed = [], set(), set()
    worker.start()
    try:
        if rehearsed:
            worker.submit_rehearsal(Twist2D(0.1))
            deadline = time.monotonic() + 10.0
            while 'rehearsal' not in done and time.monotonic() < deadline:
                time.sleep(0.01)
            # The fastest walk searched, then the walk planned as a change would be, twice (the
            # second time, what the change will take: the caches keep the first's probes).
            assert done == ['rehearsal'] and len(SlowToWalk.plans) == 2
            assert SlowToWalk.searched == {Twist2D(0.1)}
            assert worker.snapshot.planner.twist.is_zero()  # nothing walks yet
            (found,) = worker.events()  # what it found, and nothing else
            assert isinstance(found, online.Rehearsed) and found.reason == ''
            assert 0.0 < found.applied.vx_m_s <= 0.1  # as clamped
            assert found.seconds >= 1.0 + COLD_S + WARM_S
        submitted_ns = clock()
        before = len(SlowToWalk.plans)
        worker.submit_velocity(twist)
        deadline = time.monotonic() + 20.0
        applied = []
        while not applied and time.monotonic() < deadline:
            applied = [e for e in worker.events() if isinstance(e, VelocityApplied)]
            time.sleep(0.01)
        (event,) = applied
        joined_s = (event.takes_effect_ns - submitted_ns) / NS
        # Its own planning time covered, and the margin for the plan to go out.
        assert joined_s >= 0.2 + online.LEAD_MARGIN_S + WARM_S
        return len(SlowToWalk.plans) - before, joined_s
    finally:
        worker.stop()


def test_in_a_thread_a_rehearsed_first_walk_is_planned_once_and_joins_sooner():
    # A walk from standstill planned without an estimate of its planning time misses its lead
    # and is planned again from later; the rehearsal solved it while the robot stood, and the
    # walk asked then plans what the caches keep: its lead counts that time, not the first's.
    plans, joined_s = first_walk(rehearsed=False)
    rehearsed_plans, rehearsed_joined_s = first_walk(rehearsed=True)
    assert (plans, rehearsed_plans) == (2, 1)
    # Unrehearsed: the search, a first plan that missed, and a lead counting the cold plan's
    # time. Rehearsed: none of these, and a lead counting the warm plan's time.
    assert rehearsed_joined_s < joined_s - (1.0 + COLD_S + online.WORK_HEADROOM
                                            * (COLD_S - WARM_S))


def test_in_a_thread_a_new_directions_search_is_not_counted_as_planning_time():
    # Rehearsed forwards, asked sideways: the fastest sideways walk is searched (1 s) before
    # the join is set, and the walk's first plan (1 s, its caches cold) counts the rehearsal's
    # first planning time in its lead: it fits and is planned once.
    plans, joined_s = first_walk(rehearsed=True, twist=Twist2D(0.0, 0.05))
    assert plans == 1
    assert SlowToWalk.searched == {Twist2D(0.1), Twist2D(0.0, 0.05)}
    assert joined_s >= 1.0 + 0.2 + online.LEAD_MARGIN_S  # after the search


class SlowSteps(GaitPlanner):
    """A planner on a loaded machine: every walking step it plans takes STEP_S (its probes)."""

    def advance(self, until_s):
        """As the planner's, STEP_S later for each walking step added."""
        before = len(self.steps)
        changed = super().advance(until_s)
        time.sleep(STEP_S * sum(1 for step in self.steps[before:] if step.slots))
        return changed


STEP_S = 0.15


def test_in_a_thread_a_change_counts_the_planning_of_its_new_steps_in_its_lead():
    # The last change's planning time may be next to nothing (a first walk rehearsed); a
    # command joins a later boundary and plans its steps anew, each as long as the walking
    # steps planned ahead lately: its lead counts them, and it is planned once.
    start = time.monotonic_ns()
    planner = SlowSteps(QUADRUPED)
    planner.set_velocity(Twist2D(0.1), 0.0)
    worker = OnlinePlanner(planner, 0, lambda: time.monotonic_ns() - start, cover_s=6.0,
                           lead_s=0.3, threaded=True)
    worker.start()
    tries = []
    try:
        time.sleep(1.5)  # walking, planned ahead

        def counted(fork, at_s):
            tries.append(at_s)
            step_length(0.15)(fork, at_s)

        worker.submit_command('longer', '{}', counted)
        (decision, *_) = decisions_within(worker, 20.0)
        assert decision.state == ACCEPTED
        assert len(tries) == 1
    finally:
        worker.stop()


def test_a_change_whose_lead_reaches_past_the_plan_joins_after_it_as_announced():
    # A loaded machine's lead can reach past the plan ahead: the change joins at the first
    # boundary after its lead, as its answer says, with the steps up to there planned as they
    # were (before, it was walked from the plan's end, and rescheduled there at once).
    clock = FakeClock()
    worker = walking(clock, lead_s=9.0)  # the plan reaches 6 s ahead (cover_s)
    clock.advance(3.3)
    worker.run_pending()
    assert worker.snapshot.planner.steps[-1].end_s < 3.3 + 9.0
    worker.submit_command('far', '{}', step_length(0.15))
    worker.run_pending()
    (decision,) = answers(worker)
    assert decision.state == ACCEPTED
    join_s = decision.takes_effect_ns / NS
    assert join_s >= 3.3 + 9.0 + online.LEAD_MARGIN_S
    plan = worker.snapshot.planner
    first_new = next(step for step in plan.steps if step.params.step_length_m == 0.15)
    assert first_new.start_s == pytest.approx(join_s, abs=1e-9)
    clock.advance(join_s - 3.3 - 0.01)
    worker.run_pending()
    assert answers(worker) == []  # not rescheduled, not applied yet
    clock.advance(0.02)
    worker.run_pending()
    (applied,) = answers(worker)
    assert applied.state == APPLIED and applied.takes_effect_ns == decision.takes_effect_ns
