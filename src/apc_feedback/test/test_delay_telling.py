"""DelayTelling: which delay the law is told, and when another one is told instead."""

from __future__ import annotations

from types import SimpleNamespace

from apc_feedback.command_echo import ECHOES
from apc_feedback.delay_telling import RETELL_S, DelayTelling

MS = 1_000_000
T_NS = 10 * MS
DRIVER_NS = 4 * MS


def _telling(delay_ms: float | None):
    """A 250 Hz driver whose velocity is the arm's, every echo ``delay_ms`` (steady unless a
    test sets ``echo.is_steady`` False: the kept echoes still disagree)."""
    echo = SimpleNamespace(delay_ns=None, longest_ns=None, is_steady=True)
    echo.steady = lambda period: echo.is_steady
    sampler = SimpleNamespace(
        driver_period_ns=DRIVER_NS,
        velocity_is_the_arms=lambda: True,
        velocity_stencil=lambda: None,
    )
    telling = DelayTelling(echo, sampler, T_NS)

    def measure(ms: float | None) -> None:
        echo.delay_ns = echo.longest_ns = None if ms is None else round(ms * MS)

    measure(delay_ms)
    telling.echo_state = echo
    return telling, measure


def _told_once_lasted(telling, start: int) -> bool:
    """Not moved from sample ``start`` for ``retell_samples`` samples, then moved."""
    lasted = telling.retell_samples
    return not any(telling.moved(k) for k in range(start, start + lasted)) and telling.moved(
        start + lasted
    )


def test_a_first_measurement_is_told_at_once():
    telling, measure = _telling(None)
    assert telling.tell() is None  # the driver period assumed
    measure(8.0)
    assert telling.moved(1)
    assert telling.tell() == 8 * MS


def test_a_longer_delay_is_told_only_once_it_has_lasted():
    telling, measure = _telling(8.0)
    assert telling.tell() == 8 * MS
    measure(12.0)
    assert telling.retell_samples == round(RETELL_S * 1e9 / T_NS)
    assert _told_once_lasted(telling, 100)


def test_a_burst_that_ends_starts_the_count_again():
    telling, measure = _telling(8.0)
    telling.tell()
    measure(12.0)
    assert not any(telling.moved(k) for k in range(100, 130))
    measure(8.0)
    assert not telling.moved(130)
    measure(12.0)
    assert not any(telling.moved(k) for k in range(131, 175))


def test_a_shorter_delay_is_told_at_once():
    telling, measure = _telling(12.0)
    assert telling.tell() == 12 * MS
    measure(8.0)
    assert telling.moved(1)


def test_a_gap_in_the_samples_starts_the_count_again():
    telling, measure = _telling(8.0)
    telling.tell()
    measure(12.0)
    assert not any(telling.moved(k) for k in range(100, 140))
    assert _told_once_lasted(telling, 150)  # counted from 150, not 100


def test_no_measurement_starts_the_count_again():
    telling, measure = _telling(8.0)
    telling.tell()
    measure(12.0)
    assert not any(telling.moved(k) for k in range(100, 140))
    measure(None)  # the echo forgot (a fault)
    assert not telling.moved(140)
    measure(12.0)
    assert _told_once_lasted(telling, 141)


def test_none_in_place_of_a_told_delay_waits_a_window_of_echoes_with_the_arms_velocity():
    """Told 12 ms (a burst of late commands from activation: a whole sample or more is told
    without a steady echo), the echo then shows 8 ms with 12 ms ones still kept: under a
    sample and not steady, robot mode would tell none (a driver period). With the arm's own
    velocity that waits a window of echoes (the burst's tail leaving it), and 8 ms, steady
    within it, is told at once: told none at once, the law restarted a third time within a
    few samples (the Panda lost at 13-79 deg, test_robot_loop). Echoes that still disagree
    after a window tell none; with a differenced velocity none is told at once (a jittering
    delay under a sample is never told there)."""
    telling, measure = _telling(12.0)
    assert telling.tell() == 12 * MS
    telling.echo_state.is_steady = False
    measure(8.0)
    assert telling.measured_ns() is None
    assert not any(telling.moved(k) for k in range(1, 1 + ECHOES))
    telling.echo_state.is_steady = True
    assert telling.moved(1 + ECHOES) and telling.tell() == 8 * MS
    telling.echo_state.is_steady = False
    measure(4.0)
    assert not any(telling.moved(k) for k in range(20, 20 + ECHOES))
    assert telling.moved(20 + ECHOES)
    assert telling.tell() is None
    telling, measure = _telling(12.0)
    telling.tell()
    telling.sampler.velocity_is_the_arms = lambda: False
    telling.echo_state.is_steady = False
    measure(8.0)
    assert telling.moved(1)


def test_a_wait_of_another_kind_starts_its_count_afresh():
    """A longer delay waiting, then echoes under the told one that disagree (a burst that got
    later before it ended): the window's wait starts when they do, not when the longer one
    did; and the other way round."""
    telling, measure = _telling(12.0)
    telling.tell()
    measure(16.0)
    assert not any(telling.moved(k) for k in range(1, 21))
    telling.echo_state.is_steady = False
    measure(8.0)
    assert not any(telling.moved(k) for k in range(21, 21 + ECHOES))
    assert telling.moved(21 + ECHOES)
    telling, measure = _telling(12.0)
    telling.tell()
    telling.echo_state.is_steady = False
    measure(8.0)
    assert not any(telling.moved(k) for k in range(1, 9))
    telling.echo_state.is_steady = True
    measure(16.0)
    assert _told_once_lasted(telling, 9)


def test_a_delay_longer_than_the_law_carries_waits_as_a_longer_one():
    """40 ms at T = 10 ms needs more lags than the law carries (three), so the longest they hold
    would be told, 30 ms; it is longer than the 12 ms told, and it waits RETELL_S as a longer
    delay does, with either kind of velocity."""
    for arms in (True, False):
        telling, measure = _telling(12.0)
        telling.tell()
        telling.sampler.velocity_is_the_arms = lambda arms=arms: arms
        measure(40.0)
        assert telling.measured_ns() == 30 * MS
        assert _told_once_lasted(telling, 1)
        assert telling.tell() == 30 * MS


def _on_a_100hz_driver(measured_ms: float, span_s: float):
    from apc_feedback.linearize import VelocityStencil

    telling, _ = _telling(measured_ms)
    telling.sampler.driver_period_ns = 10 * MS
    telling.sampler.velocity_is_the_arms = lambda: False
    stencil = VelocityStencil(offsets=(0.0, span_s), weights=(1 / span_s, -1 / span_s))
    telling.sampler.velocity_stencil = lambda: stencil
    return telling


def test_a_delay_longer_than_the_lags_hold_is_told_as_the_longest_they_hold():
    """A 100 Hz drive's velocity differenced over its 10 ms period spans one of the three lags:
    20 ms is held and told as it is; 30 ms (a burst of late commands where the drive adds a
    cycle) and longer are told as 20 ms, nearer to the arm than none (the driver period, with
    20 ms only scored)."""
    for measured_ms in (20.0, 30.0, 60.0):
        assert _on_a_100hz_driver(measured_ms, 0.01).tell() == 20 * MS
    assert _on_a_100hz_driver(30.0, 0.01).carried_ns(None) == 30 * MS


def test_where_the_lags_hold_less_than_the_law_scores_none_is_told():
    """Robot mode's own estimate on a positions-only 100 Hz driver spans 20 ms: the lags hold
    10 ms, the driver period, and none is told, so that the law scores 20 ms beside it."""
    telling = _on_a_100hz_driver(20.0, 0.02)
    assert telling.carried_ns(telling.sampler.velocity_stencil()) == 10 * MS
    assert telling.tell() is None
