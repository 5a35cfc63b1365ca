"""Planning off the control path: a worker plans, checks and hands over whole plans.

The footstep planner's control path (its 10 Hz tick, publishing the footsteps and the ZMP
reference the robot walks) must never wait for planning: timing probes through the whole-body
IK, the fastest rhythm's search, a swing timing model for a new step height or a plan from the
robot's measured state take from milliseconds to seconds. As nav2's planner and controller
servers do, :class:`OnlinePlanner` keeps that work apart: the node submits what it wants
changed, a worker (a thread, or the caller itself in the deterministic ``inproc`` runtime)
plans it on a copy of the live plan, and the control path only reads whole, finished plans
(:attr:`OnlinePlanner.snapshot`), which the worker keeps planned ``cover_s`` ahead.

A change joins the motion under way and never alters what the robot was already promised.
The control path publishes the plan ``lead_s`` ahead (the footstep planner's ZMP horizon, which
the COM controller previews). Submitted at ``now``, a change is planned from ``at_s = now +
lead_s + LEAD_MARGIN_S + the worker's own time (measured)`` on: every step that has started by
then is kept as it is, and the change starts at the first step boundary after ``at_s`` (all feet
down; the ZMP reference, the COM, the footholds and the swings continuous there; a standstill
ends at ``at_s``). The candidate is planned :data:`CHECK_CYCLES` gait cycles past the join,
through every check the planner makes (reach, the joint speeds of every swing and transfer); a
failure rejects the command and the live plan goes on unchanged. At the handover ``at_s`` must
still be ``lead_s`` ahead of the clock, so that nothing already published changes; a worker
that was too slow plans it again from a later ``at_s``, up to :data:`MAX_ATTEMPTS` times, then
rejects the command as busy.

Gait commands carry an id. Each gets exactly one decision (accepted or rejected) and, once
accepted, a second answer when it took effect. Commands that arrive while another waits for the
worker join it: they are planned together, in the order they came (each a partial change of
the parameters, the later ones on top), and each is answered with the decision on the whole.
A command whose id was already seen is not applied again: it gets the decision the first one
got (or, still pending, the one it will get).
"""

from __future__ import annotations

import collections
import dataclasses
import math
import threading
import time
from collections.abc import Callable

import numpy as np

from gait_nodes.errors import GaitNodesError
from gait_nodes.planning.footsteps import GaitPlanner, Twist2D

NS_PER_S = 1_000_000_000
#: Time added to the lead for the new plan to reach the nodes that follow it [s].
LEAD_MARGIN_S = 0.3
#: Plans of one command tried before it is rejected as busy (the worker too slow each time).
MAX_ATTEMPTS = 3
#: Step boundaries a change is tried from before it is refused (the first it can join, and the
#: next ones: a change may be walkable only from where a later step leaves the feet).
JOIN_BOUNDARIES = 3
#: A change tried from a later boundary is planned from just after it [s].
BOUNDARY_EPSILON_S = 1e-6
#: A candidate plan is checked over this many gait cycles after its join.
CHECK_CYCLES = 2.0
#: A command's step boundary is said again when the plan moves it by more than this [ns].
RESCHEDULE_TOLERANCE_NS = 1_000_000
#: Decisions remembered for repeated ids.
REMEMBERED_IDS = 1000
#: A change's lead counts this many times the last candidate's planning time (its own may
#: be longer: a plan from standstill, a loaded machine).
WORK_HEADROOM = 1.5
#: :meth:`OnlinePlanner.delivered`'s delay of the plans out lately decays by this a plan.
DELIVERY_DECAY = 0.9
#: The planning time of a walking step planned ahead lately (``OnlinePlanner._step_s``) decays
#: by this a step.
STEP_DECAY = 0.9
#: Steps a change plans anew until it is first measured (its join's and those checked after
#: it, :data:`CHECK_CYCLES` cycles: a crawl's two a cycle).
CHANGE_STEPS = 5
#: A standing robot's plan is kept this far ahead [s] (:meth:`OnlinePlanner._extend`).
STANDING_COVER_S = 30.0
#: A stopping node waits this long for the job under way [s] (:meth:`OnlinePlanner.stop`).
STOP_WAIT_S = 1.0

ACCEPTED, REJECTED, APPLIED = 'accepted', 'rejected', 'applied'
#: An accepted command's step boundary moved: a later change re-planned the steps before it.
RESCHEDULED = 'rescheduled'
#: What a change's ``apply`` returns when it leaves the plan as it is (nothing handed over).
UNCHANGED = object()


@dataclasses.dataclass(frozen=True)
class Answer:
    """What /gait/command_status says of a command.

    Attributes:
        command_id: The command's id.
        state: ``accepted``, ``rejected`` (the decision), ``rescheduled`` (the accepted change
            takes effect at another boundary: a later change, such as a stop, re-planned the
            steps before the one it was given) or ``applied`` (it took effect).
        reason: Why it was rejected, or when it takes effect.
        text: The command as received.
        params: The gait parameters after the change (accepted, applied) or as they stay.
        takes_effect_ns: ROS time of the step boundary the change takes effect at [ns]
            (accepted, applied), else None.
        repeated: The answer to a command whose id was already seen (not applied again).
        settings: The plan's :attr:`GaitPlanner.settings` with the change (accepted).
    """

    command_id: str
    state: str
    reason: str
    text: str
    params: dict
    takes_effect_ns: int | None = None
    repeated: bool = False
    settings: int | None = None

    @property
    def accepted(self) -> bool:
        """Whether the change is (or will be) walked."""
        return self.state in (ACCEPTED, RESCHEDULED, APPLIED)


@dataclasses.dataclass(frozen=True)
class Failure:
    """Planning the live plan ahead failed; the worker stopped it at a safe stand."""

    error: Exception
    what: str


@dataclasses.dataclass(frozen=True)
class Replaced:
    """A plan from scratch (``submit_replace``) is live, or could not be made (``error``)."""

    token: object
    error: Exception | None


@dataclasses.dataclass(frozen=True)
class VelocityApplied:
    """A /cmd_vel is planned: the twist walked from ``takes_effect_ns`` on and any clamp notes."""

    requested: Twist2D
    applied: Twist2D
    notes: tuple[str, ...]
    takes_effect_ns: int


@dataclasses.dataclass(frozen=True)
class Rehearsed:
    """What a rehearsal (:meth:`OnlinePlanner.submit_rehearsal`) found, its plan dropped.

    Attributes:
        requested: The twist rehearsed.
        applied: The twist the planner would walk for it (None: it cannot be walked).
        rhythm: The rhythm of that walk (None: fixed timing, or it cannot be walked).
        reason: Why it cannot be walked ('' if it can).
        seconds: The rehearsal's planning time [s] (wall time).
    """

    requested: Twist2D
    applied: Twist2D | None
    rhythm: object
    reason: str
    seconds: float


@dataclasses.dataclass(frozen=True)
class ChangeRefused:
    """A change without a command (``submit_change``) could not be planned; nothing changed."""

    key: str
    reason: str
    payload: object = None


@dataclasses.dataclass(frozen=True)
class Changed:
    """A change without a command (e.g. a new swing timing model) is live; ``info`` says what."""

    info: object
    takes_effect_ns: int


@dataclasses.dataclass(frozen=True)
class Snapshot:
    """A finished plan for the control path: read it, never change it.

    Attributes:
        planner: A copy of the live plan (its outputs are computed on demand and memoized in it).
        origin_ns: ROS time of the plan's 0 s [ns].
        generation: Counts the plans made from scratch (``submit_replace``).
        planned_until_s: The plan's steps reach this time [s].
        report: What the worker measured of the plan for the node's reports (the rhythm).
        ready_s: ``time.monotonic()`` when the plan was ready: a change's, when it was found
            to join in time (:meth:`OnlinePlanner.delivered` measures from there).
    """

    planner: GaitPlanner
    origin_ns: int
    generation: int
    planned_until_s: float
    report: dict
    ready_s: float = 0.0


@dataclasses.dataclass
class _Job:
    kind: str  # 'command' | 'velocity' | 'change' | 'replace' | 'stand' | 'rehearsal'
    payload: object
    command_id: str = ''  # a change's key
    commands: list[tuple[str, str]] = dataclasses.field(default_factory=list)  # (id, text)


class OnlinePlanner:
    """Owns the live gait plan; changes it in a worker and hands over whole plans.

    Args:
        planner: The live plan to start from (owned by this object from now on).
        origin_ns: ROS time of its 0 s [ns].
        clock_ns: The node's clock: ROS time now [ns].
        cover_s: The worker keeps the plan this far ahead of the clock [s] (the control path's
            horizon, a step and the time of a slow candidate).
        lead_s: How far ahead of the clock the control path has published the plan [s]: no
            change starts earlier while the robot walks.
        standing_lead_s: The lead while the robot stands (no swing under way or planned): the
            COM's consumers have committed no motion, the lead need only cover the states
            they have committed (default ``lead_s``).
        threaded: Plan in a background thread (``start``/``stop``); False: :meth:`run_pending`
            does the work when the caller asks (the deterministic ``inproc`` runtime).
        describe: ``describe(planner) -> dict``: the report kept with each snapshot.
        failure_hold_s: ``failure_hold_s(planner) -> float``: how long a failed plan holds its
            safe stand before walking again [s].
        job_done: ``job_done(kind, seconds)`` after each job of the worker (for benchmarks).
        check: ``check(fork, from_s)``: raises :class:`GaitNodesError` if the candidate plan
            ``fork`` cannot be walked from ``from_s`` on (beyond the planner's own checks,
            e.g. the joint speeds of a plan with fixed timing).
    """

    def __init__(self, planner: GaitPlanner, origin_ns: int, clock_ns: Callable[[], int], *,
                 cover_s: float, lead_s: float = 0.0, standing_lead_s: float | None = None,
                 threaded: bool = False,
                 describe: Callable[[GaitPlanner], dict] | None = None,
                 failure_hold_s: Callable[[GaitPlanner], float] | None = None,
                 job_done: Callable[[str, float], None] | None = None,
                 check: Callable[[GaitPlanner, float], None] | None = None):
        self._live = planner
        self._origin_ns = int(origin_ns)
        self._clock_ns = clock_ns
        self.cover_s = float(cover_s)
        self.lead_s = float(lead_s)
        self.standing_lead_s = self.lead_s if standing_lead_s is None else float(standing_lead_s)
        self._threaded = threaded
        self._describe = describe or (lambda planner: {})
        self._failure_hold_s = failure_hold_s or (lambda planner: 1.0)
        self._generation = 0
        self._lock = threading.Lock()
        self._jobs: collections.deque[_Job] = collections.deque()
        self._events: list = []
        self._outbox: list = []  # the worker's events, out once the plan they speak of is
        self._decided: collections.OrderedDict[str, Answer] = collections.OrderedDict()
        self._pending: set[str] = set()  # ids submitted, not decided yet
        self._to_apply: list[Answer] = []  # accepted, not taken effect yet
        self._work_s = 0.0  # the last candidate's planning time [s]
        # A walking step's planning time lately (each probed anew, as a change's steps are)
        # [s], and how many steps the last change planned anew.
        self._step_s = 0.0
        self._change_steps = CHANGE_STEPS
        # The rehearsed walk (the twist walked) and its planning time from cold caches [s],
        # until the first change: one that walks another twist counts that time in its lead.
        self._rehearsed: tuple[Twist2D, float] | None = None
        self._delivery_s = 0.0  # how long the node took to publish a plan, lately [s]
        self._ready_s: float | None = None  # when the job's change was found in time
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._busy_since: float | None = None
        self._job_done = job_done or (lambda kind, seconds: None)
        self._check = check or (lambda fork, from_s: None)
        self._extend()
        self._publish()

    # --- the control path's side: every call is short --------------------------------------

    @property
    def snapshot(self) -> Snapshot:
        """The newest finished plan."""
        return self._snapshot

    def delivered(self, snapshot: Snapshot) -> None:
        """The node published ``snapshot`` now: learn how long plans take to go out.

        From a change found to join in time to its plan published, the worker makes the
        snapshot and the node waits for its tick and the CPU; on a loaded machine that is
        more than :data:`LEAD_MARGIN_S`. The longest such delay lately (it decays by
        :data:`DELIVERY_DECAY` a plan) is added to every change's margin.
        """
        if self._threaded:
            delay = max(time.monotonic() - snapshot.ready_s, 0.0)
            self._delivery_s = max(delay, DELIVERY_DECAY * self._delivery_s)

    @property
    def busy_s(self) -> float:
        """How long the worker has been working on its current job [s] (0: idle)."""
        since = self._busy_since
        return 0.0 if since is None else time.monotonic() - since

    def submit_command(self, command_id: str, text: str,
                       apply: Callable[[GaitPlanner, float], object]) -> Answer | None:
        """Plan ``apply(fork, at_s)`` as a command; its answers come from :meth:`events`.

        ``apply`` changes the fork of the live plan from ``at_s`` on (e.g.
        ``fork.set_parameters(params, at_s)``) and raises :class:`GaitNodesError` if the change
        cannot be walked. A command still waiting for the worker is planned together with this
        one (this one's changes on top) and both get the decision on the whole.

        Returns:
            The answer at once for a repeated id (it is not planned again), else None.
        """
        with self._lock:
            if command_id in self._decided:
                answer = dataclasses.replace(self._decided[command_id], repeated=True)
                self._events.append(answer)
                return answer
            if command_id in self._pending:
                return None  # its answer is coming
            self._pending.add(command_id)
            waiting = next((job for job in self._jobs if job.kind == 'command'), None)
            if waiting is not None:
                waiting.payload.append(apply)
                waiting.commands.append((command_id, text))
            else:
                self._jobs.append(_Job('command', [apply], commands=[(command_id, text)]))
        self._wake.set()
        return None

    def submit_velocity(self, twist: Twist2D) -> None:
        """Walk ``twist`` from the first step boundary the worker can join (latest one wins)."""
        self._submit(_Job('velocity', twist), replaces='velocity')

    def submit_change(self, apply: Callable[[GaitPlanner, float], object],
                      key: str = 'change') -> None:
        """Plan ``apply(fork, at_s)`` like a command, without an answer (a failure is dropped).

        A change of the same ``key`` still waiting is replaced by this one.
        """
        self._submit(_Job('change', apply, command_id=key), replaces=('change', key))

    def submit_replace(self, make: Callable[[GaitPlanner], GaitPlanner],
                       token: object = None) -> None:
        """Replace the live plan by ``make(live)`` (a plan from scratch, from a robot at rest).

        ``make`` gets the live plan, to carry its settings (the parameters, the swing timing
        and the terrain of every change accepted so far) into the new one.

        The new plan is made and planned ``cover_s`` ahead first; its 0 s is then the moment it
        is handed over (the robot stood, or was held, meanwhile: it starts where it was).
        Every job waiting is dropped but gait commands (answered as usual, planned on the new
        plan). A :class:`Replaced` event with ``token`` says when it is live or that it failed.
        """
        with self._lock:
            for job in [j for j in self._jobs if j.kind in ('velocity', 'change', 'replace')]:
                self._jobs.remove(job)
            self._jobs.appendleft(_Job('replace', (make, token)))
        self._wake.set()

    def submit_rehearsal(self, twist: Twist2D) -> None:
        """Plan walking ``twist`` from the live plan on a fork, as a change would, and drop it.

        A walk from standstill is the slowest change to plan (every probe of its first cycles
        through the limb IK). Without an estimate of its planning time the first one is
        planned to join a lead that covers none of it, misses it and is planned again from
        later (twice the work, and a later start). The rehearsal, done while the robot stands
        before anything was asked, solves that walk (the planner's caches, shared by every
        fork, keep its search and probes), then plans it once more and takes that time for the
        first change's (which plans what the rehearsal solved); it changes nothing else. A
        change that finds the caches cold (another direction) misses its join once and is
        planned again from later, caches warm. A :class:`Rehearsed` event says what it found
        (its time: both plannings).
        """
        self._submit(_Job('rehearsal', twist), replaces='rehearsal')

    def submit_stand(self, hold_s: float) -> None:
        """Stop at a safe stand now and hold it ``hold_s`` (see :meth:`GaitPlanner.stand`)."""
        with self._lock:
            self._jobs.appendleft(_Job('stand', float(hold_s)))
        self._wake.set()

    def events(self) -> list:
        """Answers and reports since the last call, in order."""
        with self._lock:
            self._check_applied()
            events, self._events = self._events, []
        return events

    # --- the worker ------------------------------------------------------------------------

    def start(self) -> None:
        """Start the worker thread (threaded mode)."""
        if self._threaded and self._thread is None:
            self._thread = threading.Thread(target=self._loop, name='gait-planning',
                                            daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """Stop the worker thread: its current job finishes, or is left after STOP_WAIT_S.

        A plan under way when the node stops is of no use to anyone, and the thread holds
        nothing to save (a daemon, it ends with the process): a node stopping mid-plan (the
        first plan of a slow start) exits at once, not after the launcher's kill.
        """
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=STOP_WAIT_S)
            self._thread = None

    def run_pending(self) -> None:
        """Do every job waiting and keep the plan ahead, in the caller's thread (not threaded)."""
        if not self._threaded:
            self._work()

    def _loop(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(timeout=0.05)
            self._wake.clear()
            self._work()

    def _work(self) -> None:
        while True:
            with self._lock:
                job = self._jobs.popleft() if self._jobs else None
            if job is None:
                break
            started = time.monotonic()
            self._busy_since = started
            try:
                self._run(job)
            except Exception as exc:  # noqa: BLE001 (the worker never dies of a plan)
                self._emit(Failure(exc, f'the {job.kind} job'))
            finally:
                self._busy_since = None
                self._job_done(job.kind, time.monotonic() - started)
            # The job's plan and events to the node at once, then the plan ahead: a change
            # joins a lead ahead of the motion, which planning further first would spend (on
            # a loaded machine, a swing lifted off before its plan was out), and a join plan
            # is live while a velocity waits.
            self._publish()
            self._hand_over()
            if self._extend():
                self._publish()
        if self._extend():
            self._publish()
        self._hand_over()

    def _hand_over(self) -> None:
        """Give the node the events of the plan just published, in order."""
        with self._lock:
            self._events.extend(self._outbox)
            self._to_apply.extend(event for event in self._outbox
                                  if isinstance(event, Answer) and event.state == ACCEPTED)
            self._reschedule()
        self._outbox = []

    def _submit(self, job: _Job, replaces) -> None:
        with self._lock:
            for old in list(self._jobs):
                if (old.kind == replaces if isinstance(replaces, str)
                        else (old.kind, old.command_id) == replaces):
                    self._jobs.remove(old)
            self._jobs.append(job)
        self._wake.set()

    def _now_s(self) -> float:
        return (self._clock_ns() - self._origin_ns) * 1e-9

    def _run(self, job: _Job) -> None:
        if job.kind == 'replace':
            make, token = job.payload
            try:
                planner = make(self._live)
                planner.advance(self.cover_s)
            except Exception as exc:  # noqa: BLE001 (reported: the live plan goes on)
                self._emit(Replaced(token, exc))
                return
            self._live, self._origin_ns = planner, self._clock_ns()
            self._generation += 1
            self._emit(Replaced(token, None))
        elif job.kind == 'stand':
            self._live.stand(self._now_s(), job.payload)
        elif job.kind == 'rehearsal':
            self._rehearse(job)
        else:
            self._plan_change(job)

    def _plan_change(self, job: _Job) -> None:
        """Plan a command, a velocity or a change on a fork; hand it over if it joins in time.

        A change that cannot be walked from the first boundary it can join (the feet where that
        step leaves them) is tried from the next ones, up to :data:`JOIN_BOUNDARIES`.
        """
        if job.kind == 'velocity' and self._threaded:
            walked = self._search_fastest(job.payload)
            # (Another twist in the rehearsed direction walks the same fastest one, but for the
            # last bits of its search's arithmetic.)
            if self._rehearsed is not None and (walked is None or not np.allclose(
                    walked.as_tuple(), self._rehearsed[0].as_tuple(), rtol=1e-6, atol=1e-9)):
                self._work_s = max(self._work_s, self._rehearsed[1])  # its caches are cold
        self._rehearsed = None
        least_s = self._least_lead_s()
        margin_s = LEAD_MARGIN_S + self._delivery_s
        # The last change's planning time, or, if longer, what planning as many new steps as
        # it did takes lately: a change walked from a new boundary probes its steps anew (the
        # last one may have found its probes made, a first walk rehearsed).
        lead_s = least_s + margin_s + WORK_HEADROOM * max(
            self._work_s, self._change_steps * self._step_s)
        for _ in range(MAX_ATTEMPTS):
            started = time.monotonic()
            at_s = self._now_s() + lead_s
            for _ in range(JOIN_BOUNDARIES):
                fork = self._live.fork()
                try:
                    result = self._candidate(job, fork, at_s)
                    error = None
                    break
                except Exception as exc:  # noqa: BLE001 (any failure refuses the candidate)
                    error = exc
                    later_s = self._live.next_boundary_s(at_s)
                    if not later_s > at_s:
                        break
                    at_s = later_s + BOUNDARY_EPSILON_S  # the step from there is kept too
            # The worker's own time delays the join only when it runs beside the clock: the
            # deterministic caller plans between ticks, in no simulated time (so a slower
            # machine walks the same plan).
            self._work_s = time.monotonic() - started if self._threaded else 0.0
            if error is not None:
                self._refuse(job, str(error) if isinstance(error, GaitNodesError)
                             else f'{type(error).__name__}: {error}')
                return
            if result is UNCHANGED:
                return
            # Handed over with the margin left for the plan to go out and reach the nodes that
            # follow it (the swing-leg policy sends a swing's path before it lifts off):
            # planning may have spent the rest of the lead, not that.
            if at_s - self._now_s() >= least_s + margin_s or not self._threaded:
                self._ready_s = time.monotonic()
                join_s = fork.next_boundary_s(at_s)
                takes_effect_ns = self._origin_ns + int(round(join_s * NS_PER_S))
                self._change_steps = sum(1 for step in fork.steps if step.start_s >= join_s)
                self._live = fork
                self._handed_over(job, result, takes_effect_ns)
                return
            lead_s = least_s + margin_s + 2.0 * self._work_s
        self._refuse(job, f'busy: the planner could not plan it ahead of the motion '
                          f'({MAX_ATTEMPTS} tries, the last {self._work_s:.2f} s); send it again')

    def _rehearse(self, job: _Job) -> None:
        """See :meth:`submit_rehearsal`: the change's planning time, its plan dropped."""
        started = time.monotonic()
        self._search_fastest(job.payload)
        velocity = dataclasses.replace(job, kind='velocity')
        planning = time.monotonic()
        try:
            fork = self._live.fork()
            result = self._candidate(velocity, fork,
                                     self._now_s() + self._least_lead_s() + LEAD_MARGIN_S)
            applied = fork.twist if result is UNCHANGED else result[0]
            rhythm, reason = fork.rhythm(), ''
            cold_s = time.monotonic() - planning
            # The change asked next plans what the rehearsal solved (the caches keep it): its
            # lead counts the time of that planning, measured on a second fork, not the first.
            planning = time.monotonic()
            self._candidate(velocity, self._live.fork(),
                            self._now_s() + self._least_lead_s() + LEAD_MARGIN_S)
            warm_s = time.monotonic() - planning
        except Exception as exc:  # noqa: BLE001 (reported; a change asking it is refused then)
            applied, rhythm, reason = None, None, str(exc)
            cold_s = warm_s = time.monotonic() - planning
        if self._threaded and self._work_s == 0.0:
            self._work_s = warm_s
            if applied is not None:
                self._rehearsed = (applied, cold_s)
        self._emit(Rehearsed(job.payload, applied, rhythm, reason, time.monotonic() - started))

    def _search_fastest(self, twist: Twist2D) -> Twist2D | None:
        """Search the fastest walk in ``twist``'s direction, before a velocity is timed.

        The search (seconds, the first time a direction is asked) is done once for good: the
        planner's caches keep it, shared by every fork. Done before the join is set, it is not
        a part of the change's planning time, and the join is not missed for it. Returns the
        twist walked (``twist`` as the planner reduces it; None: it cannot be walked).
        """
        try:
            return self._live.fork().set_velocity(twist, self._now_s())[0]
        except Exception:  # noqa: BLE001 (the change itself says why)
            return None

    def _candidate(self, job: _Job, fork: GaitPlanner, at_s: float):
        """``job`` applied to ``fork`` from ``at_s``, planned and checked past its join.

        The plan is first made to reach ``at_s`` as it is: a lead longer than the plan ahead
        (a loaded machine's) would otherwise have the change walked from the plan's end,
        before ``at_s``, where nothing was checked against the lead, and announced at the next
        boundary after it (then rescheduled at once to the plan's end: RoboSimian's switch to
        the ZMP crawl beside a busy process was announced 5 s later than it was walked).
        """
        fork.advance(at_s)
        result = self._apply(job, fork, at_s)
        if result is UNCHANGED and job.kind != 'command':
            return UNCHANGED
        rhythm = fork.rhythm()
        cycle_s = rhythm.cycle_s if rhythm is not None else fork.params.cycle_s
        join_s = fork.next_boundary_s(at_s)
        fork.advance(join_s + CHECK_CYCLES * cycle_s)
        self._check(fork, join_s)
        return result

    def _least_lead_s(self) -> float:
        """The least lead of a change now [s]: ``standing_lead_s`` if nothing swings."""
        now_s = self._now_s()
        moving = any(step.slots and step.end_s > now_s for step in self._live.steps)
        return self.lead_s if moving else min(self.lead_s, self.standing_lead_s)

    def _apply(self, job: _Job, fork: GaitPlanner, at_s: float):
        if job.kind == 'velocity':
            if job.payload == fork.requested_twist:
                return UNCHANGED
            applied, notes = fork.set_velocity(job.payload, at_s)
            return applied, tuple(notes)
        if job.kind == 'command':  # the commands planned together, in the order they came
            result = None
            for apply in job.payload:
                result = apply(fork, at_s)
            return result
        return job.payload(fork, at_s)

    def _refuse(self, job: _Job, reason: str) -> None:
        if job.kind == 'command':
            with self._lock:
                self._outbox.extend(self._decide(job, REJECTED, reason, publish=False))
        elif job.kind == 'velocity':
            self._emit(ChangeRefused('velocity', reason, job.payload))
        else:
            self._emit(ChangeRefused(job.command_id, reason))

    def _handed_over(self, job: _Job, result, takes_effect_ns: int) -> None:
        if job.kind == 'command':
            with self._lock:
                answers = self._decide(job, ACCEPTED, f'accepted: takes effect at the step '
                                       f'boundary at {takes_effect_ns * 1e-9:.3f} s',
                                       takes_effect_ns, publish=False)
            self._outbox.extend(answers)
        elif job.kind == 'velocity':
            applied, notes = result
            self._emit(VelocityApplied(job.payload, applied, notes, takes_effect_ns))
        else:
            self._emit(Changed(result, takes_effect_ns))

    def _decide(self, job: _Job, state: str, reason: str, takes_effect_ns: int | None = None,
                publish: bool = True) -> list[Answer]:
        """Record the decision on each command of ``job``; emit it unless told not to.

        Called with the lock held.
        """
        answers = []
        ids = [command_id for command_id, _ in job.commands]
        for command_id, text in job.commands:
            together = [other for other in ids if other != command_id]
            note = f' (planned together with {together[:5]}' + (
                f' and {len(together) - 5} more)' if len(together) > 5 else ')') \
                if together else ''
            answer = Answer(command_id, state, reason + note, text,
                            self._live.params.to_dict(), takes_effect_ns,
                            settings=self._live.settings if state == ACCEPTED else None)
            self._pending.discard(command_id)
            self._decided[command_id] = answer
            answers.append(answer)
        while len(self._decided) > REMEMBERED_IDS:
            self._decided.popitem(last=False)
        if publish:
            self._events.extend(answers)
        return answers

    def _reschedule(self) -> None:
        """Answer RESCHEDULED for the accepted commands the live plan walks from elsewhere.

        A stop, a velocity or a stand planned after a command may join before the command's
        boundary: the steps from there are planned with the settings in force, the command's
        among them, so it takes effect there (:meth:`GaitPlanner.settings_from_s`). Its new
        boundary is said, and followed (the swing-leg policy), before it comes: the join keeps
        the lead. Called with the lock held.
        """
        for k, answer in enumerate(self._to_apply):
            from_s = self._live.settings_from_s(answer.settings)
            if from_s is None:
                continue
            takes_effect_ns = self._origin_ns + int(round(from_s * NS_PER_S))
            if abs(takes_effect_ns - answer.takes_effect_ns) < RESCHEDULE_TOLERANCE_NS:
                continue
            moved = dataclasses.replace(
                answer, state=RESCHEDULED, takes_effect_ns=takes_effect_ns,
                reason=f'rescheduled: a later change re-planned the steps before its boundary; '
                       f'takes effect at the step boundary at {takes_effect_ns * 1e-9:.3f} s')
            self._to_apply[k] = dataclasses.replace(moved, state=ACCEPTED)
            self._decided[answer.command_id] = moved
            self._events.append(moved)

    def _check_applied(self) -> None:
        """Emit APPLIED for the accepted commands whose step boundary has come (lock held)."""
        now_ns = self._clock_ns()
        due = [a for a in self._to_apply if a.takes_effect_ns <= now_ns]
        for answer in due:
            self._to_apply.remove(answer)
            applied = dataclasses.replace(answer, state=APPLIED,
                                          reason='applied: the change is walked from here')
            self._decided[answer.command_id] = applied
            self._events.append(applied)

    def _emit(self, event) -> None:
        """Keep a worker's event until its plan is published (see :meth:`_work`)."""
        self._outbox.append(event)

    def _extend(self) -> bool:
        """Plan the live plan ahead and forget what is past; True if it changed.

        ``cover_s`` ahead, and :data:`WORK_HEADROOM` times the last change's planning time more.

        A robot standing is planned :data:`STANDING_COVER_S` ahead (standing steps cost next
        to nothing): the first walk from standstill is the slowest change to plan (its rhythm,
        every probe), and the plan it joins must cover the horizon until it is out.
        """
        now_s = self._now_s()
        standing = self._live.twist.is_zero() and not any(
            step.slots and step.end_s > now_s for step in self._live.steps)
        # Beside the clock, also as far as the next change may take to plan (the plan must
        # cover the horizon until that change is out; on a loaded machine a change took more
        # than cover_s); deterministic callers plan in no time.
        ahead_s = self.cover_s + WORK_HEADROOM * self._work_s
        started, before = time.monotonic(), len(self._live.steps)
        try:
            added = self._live.advance(
                now_s + (max(ahead_s, STANDING_COVER_S) if standing else ahead_s))
        except Exception as exc:  # noqa: BLE001 (the worker never dies of a plan)
            self._live.stand(now_s, self._failure_hold_s(self._live))
            self._emit(Failure(exc, 'planning ahead'))
            added = True
        steps = len(self._live.steps)
        if self._threaded and not standing and steps > before:
            self._step_s = max((time.monotonic() - started) / (steps - before),
                               STEP_DECAY * self._step_s)
        self._live.prune(now_s - 1.0)
        return added or len(self._live.steps) != steps

    def _publish(self) -> None:
        live = self._live
        planned = live.steps[-1].end_s if live.steps else -math.inf
        ready_s = self._ready_s if self._ready_s is not None else time.monotonic()
        self._ready_s = None
        self._snapshot = Snapshot(live.fork(), self._origin_ns, self._generation, planned,
                                  self._describe(live), ready_s)
