"""The stale-input watchdog on a fake clock: ages, edges, the diagnostics status."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gait_nodes.diagnostics import OK, WARN
from gait_nodes.errors import ParameterError
from gait_nodes.watchdog import InputWatchdog

NS = 1_000_000_000


class FakeClock:
    """Time that moves only when told to."""

    def __init__(self, start_ns: int = 5 * NS):
        self.now_ns = start_ns

    def advance(self, seconds: float) -> int:
        """Move on by ``seconds``; the new time [ns]."""
        self.now_ns += int(round(seconds * NS))
        return self.now_ns


def test_an_input_goes_stale_after_the_timeout_and_fresh_when_it_returns():
    clock = FakeClock()
    dog = InputWatchdog(['/a', '/b'], 0.5, clock.now_ns, holding='holding still')
    assert not dog.update(clock.now_ns)  # nothing stale, nothing changed
    assert dog.stale == ()
    assert dog.status(clock.now_ns)[1] == OK

    # Never heard: as old as the node.
    clock.advance(0.4)
    dog.heard('/b', clock.now_ns)
    assert not dog.update(clock.now_ns)
    clock.advance(0.2)
    assert dog.update(clock.now_ns)
    assert dog.stale == ('/a',)
    aspect, level, message, values = dog.status(clock.now_ns)
    assert (aspect, level) == ('inputs', WARN)
    assert 'nothing received on /a for 0.6 s' in message and 'holding still' in message
    assert values['/a age_s'] == pytest.approx(0.6)
    assert values['/b age_s'] == pytest.approx(0.2)
    assert values['/a received'] == 'no' and values['/b received'] == 'yes'

    # Both stale; no repeated edge while nothing changes.
    clock.advance(0.31)
    assert dog.update(clock.now_ns)
    assert dog.stale == ('/a', '/b')
    assert not dog.update(clock.advance(1.0))
    message = dog.status(clock.now_ns)[2]
    assert 'no /b for 1.51 s' in message and '/a' in message

    dog.heard('/a', clock.now_ns)
    dog.heard('/b', clock.now_ns)
    assert dog.update(clock.advance(0.01))
    assert dog.stale == () and dog.status(clock.now_ns)[1] == OK


def test_exactly_the_timeout_is_not_stale():
    dog = InputWatchdog(['/a'], 0.1, 0)
    dog.heard('/a', 0)
    assert not dog.is_stale('/a', int(0.1 * NS))
    assert dog.is_stale('/a', int(0.1 * NS) + 10)


def test_the_timeout_is_validated_and_changeable():
    for bad in (0.0, -1.0, float('nan'), float('inf'), True, '1'):
        with pytest.raises(ParameterError, match='> 0'):
            InputWatchdog(['/a'], bad, 0)
    with pytest.raises(ParameterError):
        InputWatchdog([], 1.0, 0)
    dog = InputWatchdog(['/a'], 1.0, 0)
    dog.update(int(0.5 * NS))
    with pytest.raises(ParameterError):
        dog.timeout_s = -2.0
    assert dog.timeout_s == 1.0
    dog.timeout_s = 0.2
    assert dog.update(int(0.5 * NS)) and dog.stale == ('/a',)
    with pytest.raises(KeyError, match='/x'):
        dog.heard('/x', 0)


@given(gaps=st.lists(st.floats(0.0, 2.0), min_size=1, max_size=30),
       timeout=st.floats(0.05, 1.0))
def test_stale_exactly_when_the_last_message_is_older_than_the_timeout(gaps, timeout):
    clock = FakeClock()
    dog = InputWatchdog(['/a'], timeout, clock.now_ns)
    last = clock.now_ns
    for k, gap in enumerate(gaps):
        clock.advance(gap)
        dog.update(clock.now_ns)
        assert (dog.stale == ('/a',)) == ((clock.now_ns - last) * 1e-9 > timeout + 1e-9)
        assert dog.age_s('/a', clock.now_ns) == pytest.approx((clock.now_ns - last) * 1e-9)
        if k % 2:
            dog.heard('/a', clock.now_ns)
            last = clock.now_ns
