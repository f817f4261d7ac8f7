"""Frame counters: drops estimated from stamp gaps, reasons grouped."""

from helio_optics.node_kit.diagnostics import ERROR, OK, WARN
from helio_perception.frame_statistics import FrameStatistics, InputFreshness
import pytest


def test_drops_are_estimated_from_gaps_in_a_30_hz_stream():
    stats = FrameStatistics()
    period = 1.0 / 30.0
    stamps = [i * period for i in range(40) if i not in (20, 31, 32, 33)]
    dropped = [stats.frame(t) for t in stamps]
    assert sum(dropped) == 4 and stats.dropped == 4 and stats.received == 36
    assert dropped[20] == 1 and dropped[30] == 3


def test_no_drop_is_guessed_before_the_period_is_known_or_on_jitter():
    stats = FrameStatistics()
    for t in [0.0, 0.5, 0.51, 0.55, 0.6, 0.64, 0.68, 0.73, 0.76]:
        stats.frame(t)
    assert stats.dropped == 0


def test_reasons_are_grouped_and_counted():
    stats = FrameStatistics()
    stats.frame(0.0)
    stats.result(True, False, 'marker 0 not found (saw ids [3])', 1.5)
    stats.result(True, False, 'marker 0 not found', 2.5)
    stats.result(True, False, 'ambiguous: 2 spot candidates and no recent spot', 0.5)
    stats.result(True, True, '', 1.0)
    stats.bad_frame('rgb8 image step 5 is smaller than width 2 x 3 channel(s)')
    values = stats.as_dict()
    assert values['reason: marker 0 not found'] == 2 and values['reason: ambiguous'] == 1
    assert values['frames_published'] == 4 and values['frames_invalid'] == 3
    assert values['frames_malformed'] == 1 and values['processing_ms_max'] == 2.5
    assert 'frames_received 1' in stats.summary()


def test_input_is_stale_on_either_clock():
    freshness = InputFreshness('thermal/image_raw', timeout=2.0, wall_timeout=5.0, wall_now=100.0)
    assert freshness.stale(0.0, 104.0) == ''          # nothing yet, but only 4 s of wall time
    assert 'since the start' in freshness.stale(0.0, 105.5)
    freshness.seen(1000.0, 106.0)
    assert freshness.stale(1001.5, 107.0) == ''
    # the node clock ran on (simulated time at 10x) while little wall time passed
    assert 'stale' in freshness.stale(1002.5, 106.3)
    # /clock stopped: the node clock stands still, the wall clock does not
    reason = freshness.stale(1000.0, 111.5)
    assert 'stale' in reason and '0.0 s of node time' in reason and '5.5 s of wall' in reason
    assert freshness.ages(1000.5, 107.0) == (0.5, 1.0)
    with pytest.raises(ValueError, match='timeouts'):
        InputFreshness('x', 0.0, 1.0, 0.0)


def test_health_is_error_when_stale_warn_on_malformed_frames_ok_otherwise():
    stats = FrameStatistics()
    assert stats.health() == (OK, '')
    stats.bad_frame('bad encoding')
    level, message = stats.health()
    assert level == WARN and '1 malformed' in message
    assert stats.health() == (OK, '')                 # counted once, since the last report
    assert stats.health(warning='no camera_info yet') == (WARN, 'no camera_info yet')
    assert stats.health('input stale: ...', 'x') == (ERROR, 'input stale: ...')
