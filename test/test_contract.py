"""The contract layouts: round trips through messages and CDR, swing reading, bad messages."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_nodes import contract
from gait_nodes.contract import (
    ComState,
    ContractError,
    FootstepPlan,
    SwingTrajectory,
    ZmpReference,
)
from gait_nodes.interfaces import deserialize_message, serialize_message


def through_cdr(msg):
    return deserialize_message(serialize_message(msg), type(msg))


def crawl_plan():
    """Two feet, one swing each: left moves over [1, 2] s, right over [3, 4] s."""
    times = [0.0, 1.0, 2.0, 3.0, 4.0]
    left = [[0, 0.2, 0], [0, 0.2, 0], [0.3, 0.2, 0], [0.3, 0.2, 0], [0.3, 0.2, 0]]
    right = [[0, -0.2, 0], [0, -0.2, 0], [0, -0.2, 0], [0, -0.2, 0], [0.3, -0.2, 0.05]]
    positions = np.stack([left, right], axis=1)
    yaws = np.zeros((5, 2))
    yaws[4, 1] = 0.1
    return FootstepPlan(5_000_000_123, ('left', 'right'), times, positions, yaws)


def test_footsteps_round_trip_and_swings():
    plan = crawl_plan()
    back = contract.footsteps_from_msg(through_cdr(contract.footsteps_to_msg(plan)))
    assert back.start_ns == plan.start_ns
    assert back.foot_names == plan.foot_names
    np.testing.assert_allclose(back.times_s, plan.times_s, atol=1e-9)
    np.testing.assert_allclose(back.positions_in_world, plan.positions_in_world, atol=1e-12)
    np.testing.assert_allclose(back.yaws_rad, plan.yaws_rad, atol=1e-12)
    swings = back.swings()
    assert [(s.foot, s.lift_off_s, s.touch_down_s) for s in swings] == [
        ('left', 1.0, 2.0), ('right', 3.0, 4.0)]
    assert swings[1].end_yaw_rad == pytest.approx(0.1)
    assert list(back.contacts_at(1.5)) == [False, True]
    assert list(back.contacts_at(2.0)) == [True, True]
    assert list(back.contacts_at(3.5)) == [True, False]
    np.testing.assert_allclose(back.stance_positions_at(1.5)[0], [0, 0.2, 0])


def test_footstep_plan_is_read_only_and_checked():
    plan = crawl_plan()
    with pytest.raises(ValueError):
        plan.positions_in_world[0, 0, 0] = 1.0
    with pytest.raises(ContractError, match='backwards'):
        FootstepPlan(0, ('a',), [1.0, 0.5], np.zeros((2, 1, 3)), np.zeros((2, 1)))
    bad = np.zeros((2, 1, 3))
    bad[1, 0, 0] = math.nan
    with pytest.raises(ContractError, match='NaN'):
        FootstepPlan(0, ('a',), [0.0, 1.0], bad, np.zeros((2, 1)))
    msg = contract.footsteps_to_msg(plan)
    msg.header.frame_id = 'map'
    with pytest.raises(ContractError, match="frame 'map'"):
        contract.footsteps_from_msg(msg)


def test_zmp_reference_round_trip_interpolation_and_errors():
    stamps = np.array([10, 20, 30], dtype=np.int64) * 1_000_000
    reference = ZmpReference(stamps, [[0.0, 0.0], [0.1, 0.0], [0.1, 0.2]])
    back = contract.zmp_reference_from_msg(through_cdr(contract.zmp_reference_to_msg(reference)))
    np.testing.assert_array_equal(back.stamps_ns, stamps)
    np.testing.assert_allclose(back.sample([15_000_000, 25_000_000, 99_000_000]),
                               [[0.05, 0.0], [0.1, 0.1], [0.1, 0.2]])
    assert back.horizon_s == pytest.approx(0.02)
    with pytest.raises(ContractError, match='strictly increasing'):
        ZmpReference([2, 1], [[0, 0], [0, 0]])
    with pytest.raises(ContractError, match='empty'):
        ZmpReference(np.zeros(0, dtype=np.int64), np.zeros((0, 2)))
    msg = contract.zmp_reference_to_msg(reference)
    msg.poses[1].pose.position.y = math.inf
    with pytest.raises(ContractError, match='NaN or infinite'):
        contract.zmp_reference_from_msg(msg)


def test_com_reference_round_trip():
    states = [ComState(1_000, [0.1, 0.2, 0.8], [0.3, 0.0, 0.0], [0.0, -1.0, 0.0], 0.5, 0.1),
              ComState(6_001_000, [0.2, 0.2, 0.8], [0.3, 0.0, 0.0], [0.0, 0.0, 0.0], 0.6, 0.1)]
    back = contract.com_reference_from_msg(through_cdr(contract.com_reference_to_msg(states)))
    assert [s.stamp_ns for s in back] == [1_000, 6_001_000]
    for a, b in zip(states, back, strict=True):
        np.testing.assert_allclose(b.position_in_world, a.position_in_world)
        np.testing.assert_allclose(b.velocity_in_world, a.velocity_in_world)
        np.testing.assert_allclose(b.acceleration_in_world, a.acceleration_in_world)
        assert b.yaw_rad == pytest.approx(a.yaw_rad)
        assert b.yaw_rate_rad_s == pytest.approx(a.yaw_rate_rad_s)
    with pytest.raises(ContractError, match='NaN'):
        ComState(0, [math.nan, 0, 0], [0, 0, 0], [0, 0, 0])


def test_swing_trajectory_round_trip():
    swing = SwingTrajectory('fl', 7, [0.0, 0.5, 1.0], [[0, 0, 0], [0.1, 0, 0.1], [0.2, 0, 0]],
                            [0.0, 0.1, 0.2])
    back = contract.swing_trajectory_from_msg(
        through_cdr(contract.swing_trajectory_to_msg(swing)))
    assert (back.foot, back.start_ns, back.duration_s) == ('fl', 7, 1.0)
    np.testing.assert_allclose(back.positions_in_world, swing.positions_in_world)
    np.testing.assert_allclose(back.yaws_rad, swing.yaws_rad)
    with pytest.raises(ContractError, match='at least 2'):
        SwingTrajectory('fl', 0, [0.0], [[0, 0, 0]], [0.0])


def test_yaw_quaternion_identity():
    for yaw in np.linspace(-3.1, 3.1, 13):
        assert contract.quaternion_to_yaw(*contract.yaw_to_quaternion(yaw)) == pytest.approx(yaw)


def test_zmp_reference_messages_equal_fresh_ones_while_sharing_poses():
    """The planner's pose-sharing builder gives the bytes of independent messages."""
    rng = np.random.default_rng(3)
    knots = rng.normal(size=(300, 2))
    knots[120] = (0.0, -0.0)

    def reference(first, points=knots):
        return ZmpReference(np.arange(first, first + 101) * 10_000_000, points[first:first + 101])

    builder = contract.ZmpReferenceMessages()
    previous = None
    changed = knots.copy()
    changed[121] = (0.0, 0.0)  # differs from its neighbour's -0.0 only in the sign bit
    for first, points in [(0, knots), (2, knots), (4, knots), (3, knots), (60, knots),
                          (60, changed), (20, knots), (150, knots), (152, changed)]:
        msg = builder.to_msg(reference(first, points))
        assert serialize_message(msg) == serialize_message(
            contract.zmp_reference_to_msg(reference(first, points)))
        if previous is not None and first == 4:
            assert msg.poses[0] is previous.poses[2]  # shared, not rebuilt
        previous = msg


def test_zmp_reference_to_msg_gives_independent_messages():
    ref = ZmpReference(np.arange(10) * 10_000_000, np.zeros((10, 2)))
    first, second = contract.zmp_reference_to_msg(ref), contract.zmp_reference_to_msg(ref)
    first.poses[3].pose.position.x = 5.0
    assert second.poses[3].pose.position.x == 0.0


def _decoded(decode, msg):
    """What ``decode(msg)`` gives: the reference's exact bits, or the ContractError's text."""
    try:
        reference = decode(msg)
    except ContractError as exc:
        return 'error', str(exc)
    assert not reference.stamps_ns.flags.writeable and not reference.zmp_in_world.flags.writeable
    assert reference.zmp_in_world.dtype == float and reference.stamps_ns.dtype == np.int64
    return (reference.stamps_ns.tolist(),
            np.ascontiguousarray(reference.zmp_in_world).view(np.int64).tolist())


def _pose(stamp_ns, x, y, frame_id=contract.WORLD_FRAME):
    path = contract.zmp_reference_to_msg(ZmpReference([0], [[0.0, 0.0]]))
    pose = path.poses[0]
    pose.header.stamp = contract.ns_to_time_msg(stamp_ns)
    pose.header.frame_id = frame_id
    pose.pose.position.x, pose.pose.position.y = x, y
    return pose


_EDITS = st.sampled_from(['planner', 'planner_changed', 'wire', 'drop', 'insert', 'replace',
                          'swap', 'duplicate', 'nan', 'frame', 'path_frame', 'empty', 'same',
                          'reversed', 'append_earlier'])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(_EDITS, st.integers(0, 40), st.integers(0, 10**6)), min_size=1,
                max_size=12))
def test_zmp_reference_reader_equals_the_plain_decoder(steps):
    """Reusing the previous message's poses never changes what a message decodes to."""
    rng = np.random.default_rng(len(steps))
    knots = rng.normal(size=(120, 2))
    knots[30] = (0.0, -0.0)
    builder, reader = contract.ZmpReferenceMessages(), contract.ZmpReferenceReader()
    first, msg = 0, None
    for edit, where, seed in steps:
        value = np.random.default_rng(seed).normal(size=2).tolist()
        if edit.startswith('planner') or msg is None:
            first = min(first + where % 5, 60)
            points = knots.copy()
            if edit == 'planner_changed':
                points[first + where:] += 0.01
            msg = builder.to_msg(ZmpReference(np.arange(first, first + 50) * 10_000_000,
                                              points[first:first + 50]))
        else:
            poses = list(msg.poses)
            k = where % max(len(poses), 1)
            stamp = (first + k) * 10_000_000 + 1 if poses else 0
            if edit == 'wire':
                msg = through_cdr(msg)
            elif edit == 'drop' and poses:
                del poses[k]
            elif edit == 'insert':
                poses.insert(k, _pose(stamp, *value))
            elif edit == 'replace' and poses:
                poses[k] = _pose(contract.time_msg_to_ns(poses[k].header.stamp), *value)
            elif edit == 'swap' and len(poses) > 1:
                poses[k - 1], poses[k] = poses[k], poses[k - 1]
            elif edit == 'duplicate' and poses:
                poses.insert(k, poses[k])
            elif edit == 'nan':
                poses.insert(k, _pose(stamp, math.nan, value[1]))
            elif edit == 'frame':
                poses.insert(k, _pose(stamp, *value, frame_id=('', 'map')[seed % 2]))
            elif edit == 'empty':
                poses = []
            elif edit == 'reversed':
                poses.reverse()
            elif edit == 'append_earlier' and poses:
                poses.append(_pose(contract.time_msg_to_ns(poses[0].header.stamp), *value))
            header = msg.header if edit != 'path_frame' else contract._header(0, 'map')
            if edit != 'wire':
                msg = type(msg)(header, poses)
        assert _decoded(reader.read, msg) == _decoded(contract.zmp_reference_from_msg, msg)


@pytest.mark.parametrize(('vectors', 'error'), [
    (([0, 0, 1], [0, 0, 0], [0, 0, 0]), None),
    (([1e308, 1e308, 1e308], [1e308] * 3, [-1e308] * 3), None),  # finite, sum overflows
    (([0, 0, 1], [0, math.nan, 0], [0, 0, math.inf]), 'the COM velocity_in_world holds a NaN'),
    (([0, 0, math.inf], [0, 0], [0, 0, 0]), 'the COM position_in_world holds a NaN'),
    (([0, 0, 1], [0, 0], [0, 0, math.nan]), r'COM velocity_in_world must have 3 components, '
                                            r'got \(2,\)'),
    (([0, 0, 1], [0, 0, 0], [[0, 0, 0]]), 'COM acceleration_in_world must have 3'),
    (([0, 0, 1], [0, 0, 0], 0.0), 'COM acceleration_in_world must have 3'),
])
def test_com_state_names_the_first_bad_vector(vectors, error):
    if error is None:
        state = ComState(0, *vectors)
        for name, vector in zip(('position_in_world', 'velocity_in_world',
                                 'acceleration_in_world'), vectors, strict=True):
            value = getattr(state, name)
            assert value.shape == (3,) and not value.flags.writeable
            np.testing.assert_array_equal(value, vector)
    else:
        with pytest.raises(ContractError, match=error):
            ComState(0, *vectors)


_FLOATS = st.floats(allow_nan=False, allow_infinity=False, width=64) | st.sampled_from(
    [0.0, -0.0, 1e-310, -1e308])


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**31 * 10**9 - 1), st.lists(_FLOATS, min_size=11, max_size=11))
def test_com_reference_messages_equal_the_com_state_path(stamp_ns, values):
    """The controller's one-state builder gives com_reference_to_msg's message, to the byte."""
    position, velocity, acceleration, (yaw, rate) = (values[0:3], values[3:6], values[6:9],
                                                     values[9:11])
    built = contract.ComReferenceMessages().to_msg(stamp_ns, position, velocity, acceleration,
                                                   yaw, rate)
    expected = contract.com_reference_to_msg([ComState(stamp_ns, np.array(position),
                                                       velocity, acceleration, yaw, rate)])
    assert serialize_message(built) == serialize_message(expected)


def test_com_reference_messages_reject_what_com_state_rejects():
    builder = contract.ComReferenceMessages()
    with pytest.raises(ContractError, match='the COM velocity_in_world holds a NaN'):
        builder.to_msg(0, (0.0, 0.0, 1.0), (0.0, math.nan, 0.0), (0.0, 0.0, 0.0))
    with pytest.raises(ContractError, match='yaw holds a NaN'):
        builder.to_msg(0, (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), math.inf)
    with pytest.raises(ContractError, match='must have 3 components'):
        builder.to_msg(0, (0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10**12), st.lists(st.integers(1, 10**8), min_size=1, max_size=40),
       st.integers(0, 2**32))
def test_zmp_reference_sample_is_the_np_interp_form_to_the_bit(first_ns, gaps, seed):
    rng = np.random.default_rng(seed)
    stamps = first_ns + np.concatenate([[0], np.cumsum(gaps)])
    reference = ZmpReference(stamps, rng.normal(size=(len(stamps), 2)))
    grid = np.sort(rng.integers(first_ns - 10**8, int(stamps[-1]) + 10**8, 300))
    for _ in range(2):  # the times of the samples are kept after the first call
        origin = int(stamps[0])
        expected = np.stack([np.interp((grid - origin) * 1e-9, (stamps - origin) * 1e-9,
                                       reference.zmp_in_world[:, i]) for i in range(2)], -1)
        np.testing.assert_array_equal(reference.sample(grid).view(np.int64),
                                      expected.view(np.int64))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**40), st.integers(2, 30), st.integers(0, 2**32))
def test_swing_trajectory_to_msg_is_the_transform_composition_to_the_byte(start_ns, count,
                                                                          seed):
    rng = np.random.default_rng(seed)
    times = np.sort(rng.uniform(0.0, 3.0, count))
    times[0] = 0.0
    swing = SwingTrajectory('fr', start_ns, times, rng.normal(size=(count, 3)),
                            rng.normal(0.0, 4.0, count))
    point = contract.get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectoryPoint')
    expected = contract.get_constructor('trajectory_msgs/msg/MultiDOFJointTrajectory')(
        contract._header(start_ns), ['fr'],
        [point([contract._transform(p, y)], [], [], contract.seconds_to_duration_msg(t))
         for t, p, y in zip(times, swing.positions_in_world, swing.yaws_rad, strict=True)])
    assert serialize_message(contract.swing_trajectory_to_msg(swing)) == \
        serialize_message(expected)


def _bits(reference):
    return (reference.stamps_ns.tolist(),
            np.ascontiguousarray(reference.zmp_in_world).view(np.int64).tolist(),
            np.ascontiguousarray(reference.plane_heights_m).view(np.int64).tolist())


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 12), st.integers(0, 12), st.booleans(),
                          st.integers(0, 3)), min_size=1, max_size=30),
       st.booleans())
def test_zmp_reference_followed_by_is_the_concatenation(slides, heights):
    """A slid window is the reference of the concatenated arrays, bit for bit.

    Its message (built from the kept poses) has the bytes of an independent message; a window
    slid twice (a branch) or a buffer full of windows leaves every earlier window as it was.
    """
    rng = np.random.default_rng(len(slides))
    count = 10
    stamps = np.arange(count, dtype=np.int64) * 7 + 1_000
    zmp = rng.normal(size=(count, 2))
    plane = rng.normal(size=count) if heights else None
    start = ZmpReference(stamps, zmp, plane)
    windows = [(start, _bits(start))]
    builder = contract.ZmpReferenceMessages()
    builder.to_msg(start)
    for shift, new, negative_zero, branch in slides:
        # Mostly the last window; sometimes an older one (its buffer is filled further on).
        base = windows[-4][0] if branch == 3 and len(windows) >= 4 else windows[-1][0]
        shift = min(shift, len(base.stamps_ns))
        if shift == len(base.stamps_ns) and new == 0:
            with pytest.raises(ContractError):
                base.followed_by(shift, [], np.zeros((0, 2)))
            continue
        new_stamps = int(base.stamps_ns[-1]) + 1 + 5 * np.arange(new, dtype=np.int64)
        new_zmp = rng.normal(size=(new, 2))
        if negative_zero and new:
            new_zmp[0] = (-0.0, 0.0)
        new_plane = rng.normal(size=new) if heights else None
        slid = base.followed_by(shift, new_stamps, new_zmp, new_plane)
        whole = ZmpReference(
            np.concatenate((base.stamps_ns[shift:], new_stamps)),
            np.concatenate((base.zmp_in_world[shift:], new_zmp)),
            np.concatenate((base.plane_heights_m[shift:],
                            np.zeros(new) if new_plane is None else new_plane)))
        assert _bits(slid) == _bits(whole)
        assert not slid.stamps_ns.flags.writeable and not slid.zmp_in_world.flags.writeable
        assert not slid.plane_heights_m.flags.writeable
        assert serialize_message(builder.to_msg(slid)) == serialize_message(
            contract.zmp_reference_to_msg(whole))
        windows.append((slid, _bits(slid)))
        assert all(_bits(window) == bits for window, bits in windows)


def test_zmp_reference_followed_by_checks_the_new_samples():
    reference = ZmpReference([0, 10, 20], np.zeros((3, 2)))
    bad = [([20], [[0.0, 0.0]], None),                  # not after the kept samples
           ([30, 30], np.zeros((2, 2)), None),          # not increasing
           ([30], [[math.nan, 0.0]], None),             # not finite
           ([30], [[0.0, 0.0]], [math.inf]),            # height not finite
           ([30], np.zeros((1, 3)), None),              # shape
           ([30, 40], np.zeros((2, 2)), [0.0])]         # heights shape
    for stamps, zmp, heights in bad:
        with pytest.raises(ContractError):
            reference.followed_by(1, stamps, zmp, heights)
    with pytest.raises(ContractError):
        reference.followed_by(4, [30], [[0.0, 0.0]])
    assert reference.followed_by(3, [20], [[1.0, 2.0]]).stamps_ns.tolist() == [20]


_SAMPLE_VALUES = st.sampled_from([0.0, -0.0, 1.5, -2.25, 1e-310, 1e308, math.nan, math.inf])


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 3), st.lists(st.tuples(st.integers(-3, 8), _SAMPLE_VALUES, _SAMPLE_VALUES,
                                             _SAMPLE_VALUES), max_size=5),
       st.booleans(), st.sampled_from(['tuples', 'lists', 'numpy_floats', 'ints']))
def test_zmp_reference_followed_by_takes_lists_as_it_takes_arrays(shift, new, heights, form):
    """New samples as lists (the planner's, the reader's) or as arrays: the same result.

    The same reference bit for bit, or the same ContractError.
    """
    base = ZmpReference([0, 10, 20], [[0.5, -0.5], [0.0, -0.0], [1.0, 2.0]], [0.0, 0.1, -0.0])
    stamps = [20 + gap for gap, _, _, _ in new]
    stamps = [sum(stamps[:k + 1]) - 20 * k for k in range(len(stamps))]  # gaps may be <= 0
    zmp = [(x, y) for _, x, y, _ in new]
    plane = [z for _, _, _, z in new] if heights else None
    if form == 'lists':
        zmp = [list(row) for row in zmp]
    elif form == 'numpy_floats':
        zmp = [tuple(np.float64(v) for v in row) for row in zmp]
    elif form == 'ints':
        zmp = [tuple(int(v) if math.isfinite(v) else v for v in row) for row in zmp]

    def slid(stamps_ns, zmp_in_world, plane_heights_m):
        try:
            return _bits(base.followed_by(shift, stamps_ns, zmp_in_world, plane_heights_m))
        except ContractError as exc:
            return str(exc)

    as_arrays = slid(np.array(stamps, dtype=np.int64),
                     np.array(zmp, dtype=float).reshape(len(zmp), 2),
                     None if plane is None else np.array(plane, dtype=float))
    assert slid(stamps, zmp, plane) == as_arrays
    if isinstance(as_arrays, tuple):  # and as the reference of the concatenated arrays
        whole = ZmpReference(
            np.concatenate((base.stamps_ns[shift:], np.array(stamps, dtype=np.int64))),
            np.concatenate((base.zmp_in_world[shift:],
                            np.array(zmp, dtype=float).reshape(len(zmp), 2))),
            np.concatenate((base.plane_heights_m[shift:],
                            np.zeros(len(stamps)) if plane is None else plane)))
        assert as_arrays == _bits(whole)


def test_zmp_reference_followed_by_refuses_bad_shapes_given_as_lists():
    reference = ZmpReference([0, 10], np.zeros((2, 2)))
    for stamps, zmp, heights in [([20], [(0.0, 0.0, 0.0)], None), ([20], [(0.0,)], None),
                                 ([20, 30], [(0.0, 0.0)], None), ([20], [(0.0, 0.0)], [0.0, 1.0]),
                                 ([20], [(0.0, 0.0)], [[0.0]])]:
        with pytest.raises(ContractError, match='shape'):
            reference.followed_by(1, stamps, zmp, heights)


def test_zmp_reference_to_msg_parts_are_independent_within_a_message():
    """The publisher's builder shares the identity orientation; the converter does not."""
    reference = ZmpReference(np.arange(3) * 10_000_000, np.ones((3, 2)))
    msg = contract.zmp_reference_to_msg(reference)
    assert msg.header is not msg.poses[0].header
    msg.poses[0].pose.orientation.w = 0.5
    assert msg.poses[1].pose.orientation.w == 1.0
    shared = contract.ZmpReferenceMessages().to_msg(reference)
    assert shared.poses[0].pose.orientation is shared.poses[2].pose.orientation
    assert serialize_message(shared) == serialize_message(
        contract.zmp_reference_to_msg(reference))


def test_com_reference_messages_share_constants_without_changing_a_byte():
    """Shared parts (repeated yaws, signed zeros): every message is com_reference_to_msg's.

    And stays so after the later ones were built.
    """
    builder = contract.ComReferenceMessages()
    yaws = [0.0, 0.0, -0.0, -0.0, 0.0, 0.3, 0.3, -0.3, 0.0]
    rates = [0.0, -0.0, -0.0, 0.0, 1.0, 1.0, 0.0, -0.0, 0.0]
    built, expected = [], []
    for k, (yaw, rate) in enumerate(zip(yaws, rates, strict=True)):
        position, velocity, acceleration = (0.1 * k, 0.2, 0.7), (0.0, -0.0, 0.0), (k, 0.0, 0.0)
        built.append(builder.to_msg(k * 5_000_000, position, velocity, acceleration, yaw, rate))
        expected.append(serialize_message(contract.com_reference_to_msg([ComState(
            k * 5_000_000, position, velocity, acceleration, yaw, rate)])))
        assert serialize_message(built[-1]) == expected[-1]
    assert [serialize_message(msg) for msg in built] == expected
    assert built[0].points[0].transforms[0].rotation is built[1].points[0].transforms[0].rotation
    assert built[1].points[0].transforms[0].rotation \
        is not built[2].points[0].transforms[0].rotation  # -0.0: another quaternion
