"""The feedback's stamp and fault rules on the plain sampling classes (no ROS graph).

Every rule the feedback node applies to a joint state or a set point is decided by
:class:`apc_feedback.sampling.SamplePairer` and :class:`~apc_feedback.sampling.GridSampler`;
here they are driven with synthetic stamps. The DDS tests in ``test_faults_input.py`` keep a
few end-to-end checks of the same families through the node.
"""

from __future__ import annotations

import numpy as np
import pytest

import apc_msgs_py as wire
from apc_feedback.sampling import (
    MAX_PENDING,
    RECENT_SETPOINTS,
    GridSampler,
    JointStateSampler,
    SamplePairer,
    Verdict,
)

T = 10_000_000
N = 3


def state(k: int, q: float = 0.0, effort: float | None = 1.0, stamp: int | None = None):
    return wire.JointSample(
        stamp_ns=k * T if stamp is None else stamp,
        position=np.full(N, q),
        velocity=np.zeros(N),
        effort=None if effort is None else np.full(N, effort),
    )


def setpoint(k: int, q: float = 0.0, stamp: int | None = None) -> wire.SetpointStamped:
    return wire.SetpointStamped(
        stamp_ns=k * T if stamp is None else stamp,
        q=np.full(N, q),
        qd=np.zeros(N),
        qdd=np.zeros(N),
        u_n=np.ones(N),
        time_from_start_ns=k * T,
    )


def test_grid_sampler_takes_states_on_the_grid_and_never_ticks():
    sampler: JointStateSampler = GridSampler(T)
    s = state(3)
    assert sampler.offer(s, now_ns=123) is s
    assert sampler.offer(state(0), now_ns=0).stamp_ns == 0
    assert sampler.tick(10**12) is None
    assert sampler.ticking is False
    with pytest.raises(wire.WireError, match="not on the sample grid"):
        sampler.offer(state(0, stamp=T + T // 2), now_ns=0)
    with pytest.raises(wire.WireError, match="negative"):
        sampler.offer(state(0, stamp=-T), now_ns=0)


@pytest.mark.parametrize("state_first", [True, False])
def test_a_step_needs_both_halves_in_either_order(state_first):
    pairer = SamplePairer(T)
    first, second = (
        (lambda: pairer.offer_state(state(2)), lambda: pairer.offer_setpoint(setpoint(2)))
        if state_first
        else (lambda: pairer.offer_setpoint(setpoint(2)), lambda: pairer.offer_state(state(2)))
    )
    assert first().verdict is Verdict.HELD
    assert pairer.offer_state(state(3)).verdict is Verdict.HELD  # another sample's half
    decision = second()
    assert decision.verdict is Verdict.STEP and not decision.dropped
    step = decision.step
    assert (step.k, step.stamp_ns) == (2, 2 * T)
    assert step.state.stamp_ns == step.setpoint.stamp_ns == 2 * T
    assert step.applied is None  # the first step: the torque before it was not the law's
    assert pairer.done_ns == 2 * T
    # Sample 3's state is still held; its set point completes it, now with the applied torque.
    step3 = pairer.offer_setpoint(setpoint(3)).step
    assert step3.k == 3
    np.testing.assert_array_equal(step3.applied, np.ones(N))


def test_applied_is_none_when_the_state_reports_no_effort():
    pairer = SamplePairer(T)
    pairer.offer_state(state(0))
    pairer.offer_setpoint(setpoint(0))
    pairer.offer_state(state(1, effort=None))
    assert pairer.offer_setpoint(setpoint(1)).step.applied is None


def test_the_first_of_two_halves_with_one_stamp_stands():
    pairer = SamplePairer(T)
    assert pairer.offer_state(state(0, q=0.1)).verdict is Verdict.HELD
    assert pairer.offer_state(state(0, q=0.2)).verdict is Verdict.DUPLICATE
    assert pairer.offer_setpoint(setpoint(1, q=0.1)).verdict is Verdict.HELD
    assert pairer.offer_setpoint(setpoint(1, q=0.2)).verdict is Verdict.DUPLICATE
    step = pairer.offer_setpoint(setpoint(0)).step
    np.testing.assert_array_equal(step.state.position, np.full(N, 0.1))
    step = pairer.offer_state(state(1)).step
    np.testing.assert_array_equal(step.setpoint.q, np.full(N, 0.1))


def test_a_resent_state_of_the_sample_just_done_is_answered_never_stepped_again():
    pairer = SamplePairer(T)
    for k in (0, 1):
        pairer.offer_state(state(k))
        assert pairer.offer_setpoint(setpoint(k)).verdict is Verdict.STEP
    # Sample 1 again, even with other values: a resend, answered with the output published.
    assert pairer.offer_state(state(1, q=0.5)).verdict is Verdict.RESENT
    assert pairer.offer_state(state(1)).verdict is Verdict.RESENT
    # Older: stale.
    decision = pairer.offer_state(state(0))
    assert decision.verdict is Verdict.REJECTED
    assert decision.reason == "stale stamp 0 ns"
    # The next sample steps as usual.
    pairer.offer_state(state(2))
    assert pairer.offer_setpoint(setpoint(2)).step.k == 2


def test_set_points_for_done_samples_copy_duplicate_or_stale():
    """A copy of a set point used is the feedforward answering a re-sent joint state (also
    samples later, with its lookahead); a different one is a duplicate for the sample just
    done, stale for an older one."""
    pairer = SamplePairer(T)
    for k in (0, 1):
        pairer.offer_state(state(k))
        pairer.offer_setpoint(setpoint(k))
    assert pairer.offer_setpoint(setpoint(0)).verdict is Verdict.COPY
    assert pairer.offer_setpoint(setpoint(1)).verdict is Verdict.COPY
    assert pairer.offer_setpoint(setpoint(1, q=0.1)).verdict is Verdict.DUPLICATE
    decision = pairer.offer_setpoint(setpoint(0, q=0.1))
    assert decision.verdict is Verdict.REJECTED and "stale stamp 0 ns" in decision.reason
    # time_from_start is part of the copy.
    moved = setpoint(0)
    moved = wire.SetpointStamped(moved.stamp_ns, moved.q, moved.qd, moved.qdd, moved.u_n, 1)
    assert pairer.offer_setpoint(moved).verdict is Verdict.REJECTED


def test_copies_are_recognised_for_the_recent_set_points_only():
    pairer = SamplePairer(T)
    last = RECENT_SETPOINTS + 3
    for k in range(last + 1):
        pairer.offer_state(state(k))
        pairer.offer_setpoint(setpoint(k))
    oldest_kept = last - RECENT_SETPOINTS + 1
    assert pairer.offer_setpoint(setpoint(oldest_kept)).verdict is Verdict.COPY
    assert pairer.offer_setpoint(setpoint(oldest_kept - 1)).verdict is Verdict.REJECTED


@pytest.mark.parametrize(("stamp", "why"), [(-T, "negative"), (T + 1, "not on the sample grid")])
def test_set_points_off_the_grid_are_rejected(stamp, why):
    decision = SamplePairer(T).offer_setpoint(setpoint(0, stamp=stamp))
    assert decision.verdict is Verdict.REJECTED and why in decision.reason


def test_a_gap_forgets_the_halves_that_can_no_longer_be_completed():
    pairer = SamplePairer(T)
    pairer.offer_state(state(0))
    pairer.offer_setpoint(setpoint(0))
    # Sample 1's set point is lost: its state waits, sample 2 completes, k jumps 0 -> 2.
    pairer.offer_state(state(1))
    pairer.offer_state(state(2))
    pairer.offer_setpoint(setpoint(4))
    step = pairer.offer_setpoint(setpoint(2)).step
    assert step.k == 2
    # Sample 1's state was forgotten with the step: its set point now is stale.
    assert pairer.offer_setpoint(setpoint(1)).verdict is Verdict.REJECTED
    # Sample 4's set point (newer) is still held.
    assert pairer.offer_state(state(4)).step.k == 4


def test_at_most_max_pending_halves_wait_per_topic_the_oldest_is_dropped():
    pairer = SamplePairer(T)
    for k in range(MAX_PENDING):
        assert not pairer.offer_state(state(k)).dropped
    decision = pairer.offer_state(state(MAX_PENDING))
    assert decision.verdict is Verdict.HELD and decision.dropped
    # Sample 0's state went; its set point now waits alone, sample 1 still pairs.
    assert pairer.offer_setpoint(setpoint(0)).verdict is Verdict.HELD
    assert pairer.offer_setpoint(setpoint(1)).step.k == 1
    # The set points waiting are bounded the same way.
    pairer = SamplePairer(T)
    for k in range(MAX_PENDING):
        pairer.offer_setpoint(setpoint(k))
    assert pairer.offer_setpoint(setpoint(MAX_PENDING)).dropped
