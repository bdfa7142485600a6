"""DelayTelling: which delay the law is told, and when another one is told instead."""

from __future__ import annotations

from types import SimpleNamespace

from apc_feedback.delay_telling import RETELL_S, DelayTelling

MS = 1_000_000
T_NS = 10 * MS
DRIVER_NS = 4 * MS


def _telling(delay_ms: float | None):
    """A 250 Hz driver whose velocity is the arm's, every echo ``delay_ms`` (steady)."""
    echo = SimpleNamespace(delay_ns=None, longest_ns=None, steady=lambda period: True)
    sampler = SimpleNamespace(
        driver_period_ns=DRIVER_NS,
        velocity_is_the_arms=lambda: True,
        velocity_stencil=lambda: None,
    )
    telling = DelayTelling(echo, sampler, T_NS)

    def measure(ms: float | None) -> None:
        echo.delay_ns = echo.longest_ns = None if ms is None else round(ms * MS)

    measure(delay_ms)
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
