"""The joint states' velocity with synthetic time: the estimate from positions (exact for a
constant acceleration, its noise and lag, its stencil) and the check for a drive's backward
difference of its positions."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from apc_feedback.joint_velocity import DIFFERENCE_STATES, DifferenceCheck, VelocityEstimator

MS = 1_000_000
T = 10 * MS


def test_velocity_is_exact_for_a_constant_acceleration():
    est = VelocityEstimator(window_ns=10 * MS)
    assert est.update(0, np.array([0.0])) is None
    assert est.update(MS, np.array([1e-6])) == pytest.approx([1e-3])  # two states: a difference
    # q = t^2 at 1 kHz, then at uneven stamps: the parabola's slope is 2 t exactly
    for i in [*range(2, 30), 31, 35, 36, 44]:
        t = i * 1e-3
        assert est.update(i * MS, np.array([t * t])) == pytest.approx([2 * t])
    # the base is the newest state at least a window old: after a step 5 ms ago ...
    est = VelocityEstimator(window_ns=10 * MS)
    for i in range(20):
        est.update(i * MS, np.array([0.0 if i < 15 else 1.0]))
    assert np.isfinite(est.update(20 * MS, np.array([1.0]))).all()
    # ... and with window 0 the last three states
    est = VelocityEstimator(window_ns=0)
    for i in range(5):
        est.update(i * MS, np.array([0.0]))
    assert est.update(5 * MS, np.array([1.0])) == pytest.approx([1.5 / 1e-3])


def test_added_states_give_the_acceleration_update_gives():
    """A driver that sends its velocity: states added without an estimate give, when asked,
    the acceleration that estimating at every state gives (the same bits)."""
    rng = np.random.default_rng(5)
    every, lazy = VelocityEstimator(window_ns=3 * MS), VelocityEstimator(window_ns=3 * MS)
    for i in range(40):
        stamp, position = i * MS + int(rng.integers(0, 300_000)), rng.normal(size=3)
        every.update(stamp, position)
        lazy.add(stamp, position)
        if i % 3 == 0:
            expected, got = every.acceleration, lazy.newest_acceleration()
            assert (got is None) == (expected is None)
            if got is not None:
                np.testing.assert_array_equal(got, expected)


def test_velocity_noise_and_lag_are_as_documented():
    """sqrt(26) sigma / w of noise over a span w; no lag on a smooth signal (1 kHz, 10 ms)."""
    rng = np.random.default_rng(3)
    sigma, window = 1e-4, 0.010
    est = VelocityEstimator(window_ns=int(window * 1e9))
    out = [est.update(i * MS, np.array([sigma * rng.normal()])) for i in range(4000)]
    noise = np.std([v[0] for v in out[20:]])
    assert noise == pytest.approx(np.sqrt(26) * sigma / window, rel=0.1)
    # q = sin(w t): the estimate at t is the true velocity at t (a two-point difference
    # would match t - window / 2)
    est, w = VelocityEstimator(window_ns=int(window * 1e9)), 2.0
    for i in range(200):
        v = est.update(i * MS, np.array([np.sin(w * i * 1e-3)]))
    t = 199e-3
    assert v[0] == pytest.approx(w * np.cos(w * t), abs=1e-4)
    assert abs(w * np.cos(w * (t - window / 2)) - w * np.cos(w * t)) > 1e-3


@pytest.mark.parametrize("window_ms", [0, 10, 25])
@pytest.mark.parametrize("driver_ms", [10, 4, 1])
def test_the_stencil_is_the_estimate_on_a_steady_driver(window_ms, driver_ms):
    """The weights the law's prior models give the velocity the estimator gives, on any
    positions from a driver at a steady period."""
    est = VelocityEstimator(window_ns=window_ms * MS)
    stencil = est.stencil(driver_ms * MS)
    assert len(stencil.offsets) == 3 and stencil.offsets[-1] == 0.0
    assert sum(stencil.weights) == pytest.approx(0.0, abs=1e-9)
    rng = np.random.default_rng(window_ms + driver_ms)
    positions = rng.standard_normal((40, 2))
    for i, q in enumerate(positions):
        v = est.update(i * driver_ms * MS, q)
    newest = len(positions) - 1
    expected = sum(
        w * positions[newest - round(s / (driver_ms * 1e-3))]
        for s, w in zip(stencil.offsets, stencil.weights, strict=True)
    )
    np.testing.assert_allclose(v, expected, rtol=1e-12, atol=1e-9)


def _differenced(positions, period_s):
    """(change, velocity) pairs of a drive that reports (q - q_prev) / period."""
    for before, after in itertools.pairwise(positions):
        change = after - before
        yield change, change / period_s


def test_a_velocity_that_differences_the_positions_is_recognised_with_its_period():
    counts = 2.0 * np.pi / 2**16
    rng = np.random.default_rng(0)
    positions = np.round(np.cumsum(rng.normal(0.0, 20.0, (30, 3)), axis=0)) * counts
    check = DifferenceCheck()
    for i, (change, velocity) in enumerate(_differenced(positions, 0.004)):
        check.add(change, velocity, 4 * MS + (i % 3 - 1) * 200_000)  # stamps jitter
        assert (check.period_s is None) == (i + 1 < DIFFERENCE_STATES)
    assert check.period_s == pytest.approx(0.004, rel=1e-12)


def test_an_arms_own_velocity_is_not_taken_for_a_difference():
    """The arm's velocity differs from a backward difference by its acceleration over half a
    period (a smooth move), by sub-count motion (quantised positions) or by noise."""
    t = np.arange(30) * 0.01
    q = np.stack([np.sin(t), 0.5 * t**2, np.cos(2 * t)], axis=1)
    qd = np.stack([np.cos(t), t, -2 * np.sin(2 * t)], axis=1)
    check = DifferenceCheck()
    assert not check.refuted  # nothing seen: not known to be the arm's either
    for i in range(1, len(t)):
        check.add(q[i] - q[i - 1], qd[i], T)
    assert check.period_s is None and check.refuted
    check.reset()  # states gone for the watchdog: the driver may be another
    assert not check.refuted
    counts = 2.0 * np.pi / 2**16
    quantised = np.round(q / counts) * counts
    for i in range(1, len(t)):
        check.add(quantised[i] - quantised[i - 1], qd[i], T)
    assert check.period_s is None and check.refuted


def test_states_at_rest_say_nothing_and_one_that_disagrees_starts_the_count_again():
    check = DifferenceCheck()
    step = np.array([1e-4, -2e-4])
    for _ in range(DIFFERENCE_STATES):
        check.add(step, step / 0.01, T)
        check.add(np.zeros(2), np.zeros(2), T)  # at rest: no evidence either way
        assert not check.refuted
    assert check.period_s == pytest.approx(0.01)
    check.add(step, step / 0.01 + np.array([0.0, 1e-3]), T)  # not a difference
    assert check.period_s is None and check.refuted
    check.add(np.array([1e-4, 0.0]), np.array([1e-2, 1e-3]), T)  # velocity without a change
    assert check.period_s is None
    for _ in range(DIFFERENCE_STATES - 1):
        check.add(step, step / 0.01, T)
    assert check.period_s is None and check.refuted
    check.add(step, step / 0.01, T)
    assert check.period_s == pytest.approx(0.01) and not check.refuted
    check.add(step, step / 0.001, T)  # a difference over a tenth of the states' interval
    assert check.period_s is None


def test_a_state_after_a_missed_one_is_no_evidence_either_way():
    """Its change spans two of the drive's cycles, its velocity one: judged, it would make the
    difference the arm's velocity (a restart of the law) and ten states later a difference
    again (another)."""
    step = np.array([1e-4, -2e-4])
    check = DifferenceCheck()
    for _ in range(DIFFERENCE_STATES):
        check.add(step, step / 0.001, MS, MS)
    assert check.period_s == pytest.approx(0.001)
    check.add(2.5 * step + np.array([0.0, 1e-5]), step / 0.001, 2 * MS, MS)  # one missed
    check.add(step, step / 0.001, MS // 3, MS)  # an early one
    assert check.period_s == pytest.approx(0.001)
    check.add(step, step / 0.001 + np.array([0.0, 1e-3]), MS, MS)  # one cycle, disagreeing
    assert check.period_s is None
    fresh = DifferenceCheck()  # the driver's period not known yet: every state is judged
    fresh.add(step, step / 0.001, MS)
    fresh.add(2.5 * step + np.array([0.0, 1e-5]), step / 0.001, 2 * MS)
    for _ in range(DIFFERENCE_STATES - 1):
        fresh.add(step, step / 0.001, MS)
    assert fresh.period_s is None
