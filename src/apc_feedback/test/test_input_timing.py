"""The law's input timing with synthetic data: the candidate delays' scores and the choice."""

from __future__ import annotations

import numpy as np
import pytest

from apc_feedback.adaptive_config import FeedbackError
from apc_feedback.input_timing import MIN_STEPS, DelayChoice, InputTiming
from apc_feedback.linearize import VelocityStencil, discretize_series, split_input_matrix

T = 0.01
N = 2  # joints of a double integrator


def _double_integrator():
    A = np.zeros((2 * N, 2 * N))
    A[:N, N:] = np.eye(N)
    B = np.zeros((2 * N, N))
    B[N:] = np.eye(N)
    return A, B


def _prior(delay: float, lags: int = 2) -> np.ndarray:
    A, B = _double_integrator()
    F, _ = discretize_series(A, B, T)
    return np.hstack([F, split_input_matrix(A, B, T, delay, lags)])


def _scored(true_delay: float, steps: int = 40, bias: float = 0.0) -> DelayChoice:
    """A choice between T and 2T scored on a plant whose commands act ``true_delay`` late,
    with a constant unmodelled acceleration ``bias`` (a payload's gravity) on every sample."""
    choice = DelayChoice((T, 2 * T))
    truth = _prior(true_delay)
    choice.start(T, [_prior(T), _prior(2 * T)])
    rng = np.random.default_rng(0)
    x, inputs = np.zeros(2 * N), np.zeros(3 * N)
    for _ in range(steps):
        du = rng.standard_normal(N)
        inputs = np.concatenate([du, inputs[:-N]])
        z = np.concatenate([x, inputs])
        x_next = truth @ z
        x_next[N:] += bias * T
        choice.score(x_next, z, N)
        x = x_next
    return choice


@pytest.mark.parametrize("bias", [0.0, 5.0])
def test_the_choice_takes_the_delay_the_data_have(bias):
    """Commands a period later than told: the later candidate scores far better and a restart
    takes it; commands as told: the choice stays. An unmodelled constant (a payload) cancels in
    the differenced residuals."""
    late = _scored(2 * T, bias=bias)
    assert late.scores[2 * T] < 1e-20 < late.scores[T]
    assert late.choose(T) == 2 * T
    on_time = _scored(T, bias=bias)
    assert on_time.choose(T) == T and on_time.choose(2 * T) == T


def test_no_choice_before_enough_steps_or_without_candidates():
    assert _scored(2 * T, steps=MIN_STEPS).choose(T) == T  # one step is not differenced
    assert _scored(2 * T, steps=MIN_STEPS + 1).choose(T) == 2 * T
    alone = DelayChoice(())
    assert not alone.active and alone.choose(T) == T


def test_input_timing_keeps_scores_for_the_same_candidates_and_checks_what_it_is_told():
    timing = InputTiming(0.0)
    timing.expect_delay(T, (2 * T,))
    assert timing.delay == 0.0 and not timing.choice.active  # from the next start
    timing.begin(choose=True)
    choice = timing.choice
    assert choice.active and timing.delay == T
    timing.expect_delay(T, (2 * T,))  # a re-activation: the same arm, the same scores
    timing.begin(choose=True)
    assert timing.choice is choice and timing.delay == T
    timing.expect_delay(0.004, (0.008,))
    timing.begin(choose=False)
    assert timing.choice is not choice and timing.delay == 0.004
    with pytest.raises(FeedbackError, match="input delay"):
        timing.expect_delay(T, (float("nan"),))
    with pytest.raises(FeedbackError, match="stencil"):
        timing.expect_stencil(VelocityStencil((0.01, -0.01), (1.0, -1.0)))


def test_the_lags_grow_with_the_stencil_up_to_three():
    timing = InputTiming(T)
    assert timing.lags(2, T) == 2  # a measured velocity: the configured lags
    timing.expect_stencil(VelocityStencil((0.02, 0.01, 0.0), (50.0, -200.0, 150.0)))
    assert timing.lags(2, T) == 2  # told, not yet started with it
    timing.begin(choose=False)
    assert timing.lags(2, T) == 3  # 100 Hz: a period's delay and two of estimate
    assert timing.lags(0, T) == 0  # Eq. 16 stays Eq. 16
    timing.expect_delay(2 * T)
    timing.begin(choose=False)
    assert timing.lags(2, T) == 3  # four needed, three carried (the rest folded)
    timing.expect_stencil(VelocityStencil((0.004, 0.002, 0.0), (250.0, -1000.0, 750.0)))
    timing.expect_delay(0.002)
    timing.begin(choose=False)
    assert timing.lags(2, T) == 2  # 500 Hz: within the configured two


def test_a_measured_delay_holds_the_split_only_with_every_lag_it_needs_carried():
    timing = InputTiming(T)
    timing.expect_delay(2 * T, (), exact=True)
    timing.expect_stencil(VelocityStencil((0.0, T), (1 / T, -1 / T)))  # the drive's difference
    assert not timing.exact  # from the next start
    timing.begin(choose=True)
    assert timing.exact and timing.delay == 2 * T
    assert timing.holds_split(3, T) and not timing.holds_split(2, T)  # three needed
    timing.expect_delay(T, (2 * T,))
    timing.begin(choose=False)
    assert not timing.exact and not timing.holds_split(3, T)
