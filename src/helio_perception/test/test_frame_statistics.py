"""Frame counters: drops estimated from stamp gaps, reasons grouped."""

from helio_perception.frame_statistics import FrameStatistics


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
