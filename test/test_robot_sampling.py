"""Robot-mode sampling rules with synthetic time: stamps, ages, gaps, the velocity estimate."""

from __future__ import annotations

import numpy as np
import pytest

from apc_core.wire import JointSample
from apc_feedback.robot_sampling import (
    RobotSampler,
    RobotSamplingConfig,
    RobotSamplingError,
    StateRejectedError,
    VelocityEstimator,
)
from apc_feedback.sampling import JointStateSampler

MS = 1_000_000
T = 10 * MS


def _state(stamp_ns, q, qd=None, effort=None):
    q = np.atleast_1d(np.asarray(q, dtype=float))
    return JointSample(stamp_ns, q, None if qd is None else np.atleast_1d(qd), effort)


def _sampler(**kw):
    return RobotSampler(RobotSamplingConfig(**kw))


def test_config_names_the_bad_field():
    with pytest.raises(RobotSamplingError, match=r"^max_age"):
        RobotSamplingConfig(max_age=0.0)
    with pytest.raises(RobotSamplingError, match=r"^watchdog must be >= max_age"):
        RobotSamplingConfig(max_age=0.05, watchdog=0.01)
    with pytest.raises(RobotSamplingError, match=r"^velocity_window"):
        RobotSamplingConfig(velocity_window=float("nan"))


def _rejected(sampler, state, now) -> str:
    with pytest.raises(StateRejectedError) as caught:
        sampler.offer(state, now)
    return caught.value.reason


def test_it_is_a_joint_state_sampler_that_ticks():
    s: JointStateSampler = _sampler()
    assert s.ticking and s.offer(_state(0, 0.0, 0.0), 0) is None


def test_duplicate_out_of_order_stale_and_future_are_rejected():
    s = _sampler(max_age=0.02)
    now = 1000 * T
    assert s.offer(_state(now - 2 * MS, 0.0, 0.0), now) is None
    assert _rejected(s, _state(now - 2 * MS, 1.0, 0.0), now) == "duplicate"
    assert _rejected(s, _state(now - 3 * MS, 1.0, 0.0), now) == "out_of_order"
    assert _rejected(s, _state(now - 21 * MS, 1.0, 0.0), now) == "out_of_order"
    s2 = _sampler(max_age=0.02)
    assert _rejected(s2, _state(now - 21 * MS, 1.0, 0.0), now) == "stale"
    assert _rejected(s2, _state(now + 21 * MS, 1.0, 0.0), now) == "future"
    assert s2.newest is None
    # the first one stands: a rejected state never replaces it
    assert s.newest.position[0] == 0.0


def test_samples_are_grid_stamped_from_the_newest_state_carried_forward_to_the_tick():
    s = _sampler()
    t0 = 1234 * T + 3 * MS  # activation 3 ms into a period

    def ramp(t):  # q = 1 + 2 (t - t0) + 5 (t - t0)^2, sent without velocity
        x = (t - t0) * 1e-9
        return 1.0 + 2.0 * x + 5.0 * x * x

    s.offer(_state(t0 - 2 * MS, ramp(t0 - 2 * MS)), t0)
    s.offer(_state(t0 - 1 * MS, ramp(t0 - 1 * MS)), t0)
    k0 = s.start(t0)
    assert k0 == 1234
    s.tick(t0)  # two states: carried forward by their slope to t0
    take = s.last
    assert take.k == 1234 and take.sample.stamp_ns == 1234 * T
    assert take.age_ns == 1 * MS and take.missed == 0 and take.reason == ""
    slope = (ramp(t0 - MS) - ramp(t0 - 2 * MS)) / 1e-3
    assert take.sample.position[0] == pytest.approx(ramp(t0 - MS) + 1e-3 * slope)
    # two states within the next period: the newer one is taken, carried forward exactly
    s.offer(_state(t0 + 4 * MS, ramp(t0 + 4 * MS)), t0 + 4 * MS)
    s.offer(_state(t0 + 8 * MS, ramp(t0 + 8 * MS)), t0 + 8 * MS)
    s.tick(t0 + T + 1 * MS)  # timer 1 ms late: still sample k0 + 1, at its own time
    take = s.last
    assert take.k == k0 + 1 and take.age_ns == 3 * MS and take.late_ns == 1 * MS
    assert take.sample.position[0] == pytest.approx(ramp(t0 + T))
    assert take.sample.velocity[0] == pytest.approx(2.0 + 10.0 * 0.010)


def test_no_new_state_stale_and_missed_ticks_leave_gaps():
    s = _sampler(max_age=0.02)
    t0 = 500 * T
    s.offer(_state(t0, 0.0, 0.0), t0)
    k0 = s.start(t0)
    assert s.tick(t0) is not None
    s.tick(t0 + T)  # nothing new since: no sample, nothing reaches a law twice
    take = s.last
    assert take.sample is None and take.reason == "no_new_state" and take.k == k0 + 1
    s.offer(_state(t0 + T + 5 * MS, 0.1, 0.0), t0 + T + 5 * MS)
    s.tick(t0 + 4 * T)  # two ticks never ran; the state is 25 ms old by now
    take = s.last
    assert take.k == k0 + 4 and take.missed == 2 and take.reason == "stale"
    s.offer(_state(t0 + 5 * T - MS, 0.2, 0.0), t0 + 5 * T)
    s.tick(t0 + 5 * T + 4 * MS)  # a timer late by less than T keeps the index
    take = s.last
    assert take.k == k0 + 5 and take.sample is not None and take.missed == 0


def test_restart_continues_after_the_last_sample():
    s = _sampler()
    t0 = 100 * T + 9 * MS
    s.offer(_state(t0, 0.0, 0.0), t0)
    k0 = s.start(t0)
    s.tick(t0)
    k1 = s.start(t0 + 2 * MS)  # re-activated within the same period: one index left out
    assert k1 == k0 + 2
    s.tick(t0 + 2 * MS)
    assert s.last.k == k1


def test_watchdog_is_on_the_newest_accepted_stamp():
    s = _sampler(max_age=0.02, watchdog=0.05)
    assert not s.fresh(0)
    s.offer(_state(100 * T, 0.0, 0.0), 100 * T)
    assert s.fresh(100 * T + 50 * MS)
    assert not s.fresh(100 * T + 51 * MS)


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


def test_the_drivers_velocity_is_used_when_sent_and_estimated_when_not():
    s = _sampler()
    s.offer(_state(0, 0.0), 0)
    assert s.newest.velocity is None
    s.start(0)
    assert s.tick(0) is None and s.last.reason == "no_velocity"
    s.offer(_state(5 * MS, 0.01), 5 * MS)
    assert s.newest.velocity == pytest.approx([2.0])
    assert s.tick(5 * MS).velocity == pytest.approx([2.0])
    s.offer(_state(10 * MS, 0.02, 7.0), 10 * MS)
    assert s.newest.velocity == pytest.approx([7.0])


def test_the_velocity_estimate_starts_afresh_after_a_gap_in_the_states():
    s = _sampler(max_age=0.02)
    for i in range(5):
        s.offer(_state(i * MS, 0.001 * i), i * MS)
    assert s.newest.velocity == pytest.approx([1.0])
    # 300 ms without states (a watchdog), then the arm is somewhere else, moving at 2 rad/s
    t = 305 * MS
    s.offer(_state(t, 0.5), t)
    assert s.newest.velocity is None  # no difference across the gap
    s.offer(_state(t + MS, 0.502), t + MS)
    assert s.newest.velocity == pytest.approx([2.0])
