"""The player's clock rules on synthetic steady-clock time (PlaybackTimeline)."""

from __future__ import annotations

import pytest

from apc_recording.playback import PlaybackTimeline

MS = 1_000_000
T0 = 5_000 * MS  # an arbitrary steady-clock instant


def test_messages_fall_due_at_their_log_time_over_the_rate() -> None:
    for rate in (1.0, 2.0, 0.5):
        timeline = PlaybackTimeline(200 * MS, 500 * MS, rate)
        timeline.begin_pass(T0)
        assert timeline.due_ns(200 * MS) == T0
        assert timeline.due_ns(290 * MS) == T0 + round(90 * MS / rate)


def test_rate_two_takes_half_the_time_of_rate_one() -> None:
    logs = [k * 10 * MS for k in range(60)]  # 0 .. 0.59 s
    spans = {}
    for rate in (1.0, 2.0):
        timeline = PlaybackTimeline(0, 600 * MS, rate)
        timeline.begin_pass(T0)
        for log in logs:
            timeline.sent(log, timeline.due_ns(log))  # each message sent when due
        spans[rate] = timeline.pass_wall_s()
    assert spans[1.0] == pytest.approx(0.59)
    assert spans[1.0] / spans[2.0] == pytest.approx(2.0)


def test_rate_zero_makes_everything_due_at_once() -> None:
    timeline = PlaybackTimeline(0, None, 0.0)
    timeline.begin_pass(T0)
    assert timeline.due_ns(0) == timeline.due_ns(10**12) == T0


def test_bag_time_advances_at_the_rate_and_stops_at_the_window_end() -> None:
    timeline = PlaybackTimeline(500 * MS, 900 * MS, 2.0)
    assert timeline.bag_time_ns(T0) == 500 * MS  # before the pass: the window start
    timeline.begin_pass(T0)
    assert timeline.bag_time_ns(T0 + 100 * MS) == 700 * MS
    assert timeline.bag_time_ns(T0 + 10_000 * MS) == 900 * MS
    open_ended = PlaybackTimeline(0, None, 1.0)
    open_ended.begin_pass(T0)
    assert open_ended.bag_time_ns(T0 + 10_000 * MS) == 10_000 * MS


def test_at_rate_zero_bag_time_is_the_last_message_sent() -> None:
    timeline = PlaybackTimeline(100 * MS, None, 0.0)
    timeline.begin_pass(T0)
    assert timeline.bag_time_ns(T0 + 7 * MS) == 100 * MS
    timeline.sent(130 * MS, T0 + 1)
    assert timeline.bag_time_ns(T0 + 7 * MS) == 130 * MS


def test_a_new_pass_starts_its_count_and_span_over() -> None:
    timeline = PlaybackTimeline(0, 30 * MS, 1.0)
    assert timeline.pass_wall_s() == 0.0 and not timeline.started
    timeline.begin_pass(T0)
    timeline.sent(20 * MS, T0 + 21 * MS)
    assert timeline.pass_wall_s() == pytest.approx(0.021)
    timeline.begin_pass(T0 + 50 * MS)
    assert timeline.sent_this_pass == 0 and timeline.pass_wall_s() == 0.0


def test_bad_rate_and_window_are_refused() -> None:
    with pytest.raises(ValueError, match="rate"):
        PlaybackTimeline(0, None, -1.0)
    with pytest.raises(ValueError, match="before its start"):
        PlaybackTimeline(10, 5, 1.0)
    with pytest.raises(RuntimeError, match="no pass"):
        PlaybackTimeline(0, None, 1.0).due_ns(0)
