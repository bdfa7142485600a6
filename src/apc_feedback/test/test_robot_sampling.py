"""Robot-mode sampling rules with synthetic time: stamps, ages, gaps, the velocity estimate."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from apc_feedback.joint_velocity import DIFFERENCE_STATES, VelocityEstimator
from apc_feedback.linearize import VelocityStencil
from apc_feedback.robot_sampling import (
    RobotSampler,
    RobotSamplingConfig,
    RobotSamplingError,
    StateRejectedError,
)
from apc_feedback.sample_timing import SampleTiming, TimingWindow
from apc_feedback.sampling import JointStateSampler
from apc_msgs_py import JointSample

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
    with pytest.raises(RobotSamplingError, match=r"^short_difference") as err:
        RobotSamplingConfig(short_difference=1.5)
    assert err.value.field == "short_difference"
    with pytest.raises(RobotSamplingError, match=r"^watchdog must be >= max_age"):
        RobotSamplingConfig(max_age=0.05, watchdog=0.01)
    with pytest.raises(RobotSamplingError, match=r"^velocity_window"):
        RobotSamplingConfig(velocity_window=float("nan"))


def _rejected(sampler, state, now) -> str:
    with pytest.raises(StateRejectedError) as caught:
        sampler.offer(state, now)
    return caught.value.reason


def test_it_is_a_joint_state_sampler_that_samples_on_arrival():
    s: JointStateSampler = _sampler()
    assert not s.ticking and s.offer(_state(0, 0.0, 0.0), 0) is None  # not started
    assert s.tick(0) is None


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


def _drive(s, hz, start_ns, seconds, q=lambda t: 0.0, transport_ns=300_000):
    """A driver at ``hz`` from ``start_ns``: states of position ``q(t)`` without velocity,
    each offered ``transport_ns`` after its stamp; (stamp, arrival, sample) per state."""
    dt = round(1e9 / hz)
    out = []
    for i in range(round(seconds * hz)):
        t = start_ns + i * dt
        out.append((t, t + transport_ns, s.offer(_state(t, q(t)), t + transport_ns)))
    return out


@pytest.mark.parametrize("hz", [100, 200, 500, 1000])  # 4 ms (250 Hz) does not divide 10 ms
@pytest.mark.parametrize("phase_ns", [0, 1, 300_000, 3_999_999, 9_999_999])
def test_samples_are_the_drivers_states_when_its_period_divides_t(hz, phase_ns):
    s = _sampler()
    start = 1000 * T + phase_ns
    _drive(s, hz, start - 50 * MS, 0.05)  # states before activation are no samples
    s.start()
    states = _drive(s, hz, start, 0.5, q=lambda t: np.sin(1e-9 * t))
    samples = [(t, sample) for t, _, sample in states if sample is not None]
    assert s.phase_ns == phase_ns and s.driver_period_ns == round(1e9 / hz)
    # every state at a sample time kT + phase is sample k, as it is: no extrapolation
    assert [t for t, _ in samples] == [t for t, _, _ in states if (t - phase_ns) % T == 0]
    assert len(samples) == 50
    for t, sample in samples:
        assert sample.stamp_ns == t - phase_ns
        assert sample.position[0] == np.sin(1e-9 * t)
    assert [sample.stamp_ns // T for _, sample in samples] == list(range(1000, 1050))
    assert s.last.offset_ns == 0 and s.last.missed == 0 and s.last.age_ns == 300_000


@pytest.mark.parametrize(
    ("period", "directions"),
    [(3_003_003, {-1, 0, 1}), (4 * MS, {-1, 0})],  # 333 Hz; 250 Hz: a tie takes the earlier
)
@pytest.mark.parametrize("phase_ns", [0, 1_234_567, 7_000_000])
def test_other_drivers_samples_are_t_apart_carried_from_the_nearest_state(
    period, directions, phase_ns
):
    s = _sampler()

    def ramp(t):  # a constant acceleration: the parabola carries it exactly
        x = (t - 1000 * T) * 1e-9
        return 1.0 + 2.0 * x + 5.0 * x * x

    _drive(s, 1e9 / period, 1000 * T + phase_ns - 30 * MS, 0.03, q=ramp)
    s.start()
    states = _drive(s, 1e9 / period, 1000 * T + phase_ns, 0.5, q=ramp)
    samples = [(t, sample) for t, _, sample in states if sample is not None]
    stamps = [sample.stamp_ns for _, sample in samples]
    assert np.all(np.diff(stamps) == T)  # exactly T apart, no index left out
    assert len(samples) >= 49
    sample_phase = s.phase_ns
    for t, sample in samples:
        when = sample.stamp_ns + sample_phase
        assert abs(t - when) <= period // 2 + 1  # the nearest state, carried either way
        assert sample.position[0] == pytest.approx(ramp(when), abs=1e-12)
        assert sample.velocity[0] == pytest.approx(2.0 + 10.0 * (when - 1000 * T) * 1e-9)
    offsets = [t - (sample.stamp_ns + sample_phase) for t, sample in samples]
    assert {int(np.sign(o)) for o in offsets} == directions  # carried backward and forward


def test_jittered_stamps_still_give_one_sample_per_period():
    """A wall-clock driver's stamps jitter: a state a little early is still the one nearest
    its sample's time, not a reason to wait a whole driver period."""
    s = _sampler()
    rng = np.random.default_rng(1)
    start = 1000 * T + 3 * MS
    s.offer(_state(start - 2 * MS, 0.0, 0.0), start - 2 * MS)
    s.start()
    taken = []
    for i in range(400):
        t = start + i * 2 * MS + int(rng.integers(-100_000, 100_000))
        if s.offer(_state(t, 0.0, 0.0), t + 200_000) is not None:
            taken.append((t, s.last))
    assert [take.k for _, take in taken] == list(range(taken[0][1].k, taken[0][1].k + 80))
    assert all(abs(take.offset_ns) <= 300_000 for _, take in taken)


def test_lost_states_and_a_slow_driver_leave_gaps_counted_as_missed():
    s = _sampler(max_age=0.02)
    t0 = 500 * T + 2 * MS
    s.offer(_state(t0 - MS, 0.0, 0.0), t0 - MS)
    s.start()
    assert s.offer(_state(t0, 0.0, 0.0), t0).stamp_ns == 500 * T
    for i in range(1, 10):  # the state at sample 501's time is lost: 502 follows
        state = s.offer(_state(t0 + i * MS, 0.0, 0.0), t0 + i * MS)
        assert state is None
    assert s.offer(_state(t0 + 20 * MS, 0.0, 0.0), t0 + 20 * MS).stamp_ns == 502 * T
    assert s.last.missed == 1 and s.last.offset_ns == 0
    # a state lost just before its sample's time: the one after it is carried back
    assert s.offer(_state(t0 + 31 * MS, 0.0, 0.0), t0 + 31 * MS).stamp_ns == 503 * T
    assert s.last.offset_ns == MS and s.last.missed == 0
    # a driver at 50 Hz: every other sample time has no state near it
    s2 = _sampler()
    s2.offer(_state(t0 - 20 * MS, 0.0, 0.0), t0 - 20 * MS)
    s2.start()
    got = [s2.offer(_state(t0 + i * 20 * MS, 0.0, 0.0), t0 + i * 20 * MS) for i in range(4)]
    assert [g.stamp_ns // T for g in got] == [500, 502, 504, 506]
    assert s2.last.missed == 1


def test_restart_continues_after_the_last_sample_and_locks_the_phase_again():
    s = _sampler()
    t0 = 100 * T + 9 * MS
    s.offer(_state(t0 - T, 0.0, 0.0), t0 - T)
    s.start()
    assert s.offer(_state(t0, 0.0, 0.0), t0).stamp_ns == 100 * T
    s.stop()
    assert s.offer(_state(t0 + 2 * MS, 0.0, 0.0), t0 + 2 * MS) is None  # stopped
    s.start()  # re-started: one index left out, the phase locked afresh (5 ms)
    t1 = 101 * T + 5 * MS
    assert s.offer(_state(t1, 0.0, 0.0), t1) is None  # sample 102 is at 102 T + 5 ms
    assert s.phase_ns == 5 * MS
    got = s.offer(_state(t1 + T, 0.0, 0.0), t1 + T)
    assert got.stamp_ns == 102 * T and s.last.offset_ns == 0 and s.last.missed == 0
    # after a long gap (a watchdog) the first sample is no missed sample either
    s.start()
    t2 = t1 + 50 * T + 4 * MS  # 9 ms into a period
    assert s.offer(_state(t2, 1.0, 0.0), t2).stamp_ns == (t2 // T) * T
    assert s.last.missed == 0 and s.phase_ns == t2 % T


def test_watchdog_is_on_the_newest_accepted_stamp():
    s = _sampler(max_age=0.02, watchdog=0.05)
    assert not s.fresh(0)
    s.offer(_state(100 * T, 0.0, 0.0), 100 * T)
    assert s.fresh(100 * T + 50 * MS)
    assert not s.fresh(100 * T + 51 * MS)


def test_the_drivers_velocity_is_used_when_sent_and_estimated_when_not():
    s = _sampler()
    s.start()
    assert s.offer(_state(0, 0.0), 0) is None
    assert s.newest.velocity is None and s.last.reason == "no_velocity"
    assert s.phase_ns is None  # the phase locks on the first state that can be a sample
    assert s.offer(_state(5 * MS, 0.01), 5 * MS).velocity == pytest.approx([2.0])
    assert s.phase_ns == 5 * MS
    s.offer(_state(10 * MS, 0.02, 7.0), 10 * MS)
    assert s.newest.velocity == pytest.approx([7.0])


def test_the_sampler_gives_a_stencil_only_for_an_estimated_velocity():
    s = _sampler()
    assert s.velocity_stencil() is None  # no driver period yet
    for i in range(3):
        s.offer(_state(i * T, 0.0), i * T)
    assert s.velocity_stencil() == s.velocity.stencil(T)
    assert s.velocity_stencil().offsets == (0.02, 0.01, 0.0)
    s.offer(_state(3 * T, 0.0, 0.0), 3 * T)  # this driver sends its velocity
    assert s.velocity_stencil() is None


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


def test_timing_window_median_p99_and_max():
    w = TimingWindow(200)
    for v in range(1, 301):  # the window keeps the last 200: 101 .. 300
        w.add(v)
    assert len(w) == 200
    assert w.figures() == (200.5, 298.0, 300.0)  # nearest rank: the 198th of 200
    one = TimingWindow(10)
    one.add(7)
    assert one.figures() == (7.0, 7.0, 7.0)


def test_sample_timing_figures_from_a_333_hz_driver():
    s = _sampler()
    timing = SampleTiming(window=1000)
    period = 3_003_003
    s.offer(_state(1000 * T + 500_000 - period, 0.0, 0.0), 1000 * T + 500_000 - period)
    s.start()
    for i in range(300):
        t = 1000 * T + 500_000 + i * period
        arrival = t + 200_000 + (i % 4) * 100_000  # 0.2 .. 0.5 ms on the way
        if s.offer(_state(t, 0.0, 0.0), arrival) is not None:
            timing.sampled(s.last, s.phase_ns, s.driver_period_ns)
            timing.commanded(t, arrival + 50_000)
    f = timing.figures()
    assert set(f) == {
        f"{name}_{figure}_us" for name in SampleTiming.NAMES for figure in ("median", "p99", "max")
    }
    assert f["sample_phase_median_us"] == f["sample_phase_max_us"] == 500.0
    assert f["driver_period_median_us"] == f["driver_period_max_us"] == period * 1e-3
    assert 200.0 <= f["state_age_median_us"] <= 500.0 and f["state_age_max_us"] == 500.0
    assert f["state_to_command_max_us"] == 550.0
    assert f["carry_max_us"] <= period / 2 * 1e-3 and f["carry_median_us"] > 0.0
    assert SampleTiming().figures() == {}


def test_a_1khz_drivers_difference_stays_one_through_missed_states():
    """The physical arm's drive at 1 kHz, every 37th state not published (a loaded machine's
    missed cycles): the sampler tells the difference once and keeps it (kept as the samples'
    velocity: ``short_difference`` 0)."""
    s = _sampler(short_difference=0.0)
    t = np.arange(400) * 0.001
    q = np.stack([np.sin(3 * t), 0.2 * t**2], axis=1)
    kinds = []
    for i in range(1, len(t)):
        if i % 37 == 0:
            continue  # this cycle's state was not published
        s.offer(_state(i * MS, q[i], (q[i] - q[i - 1]) / 0.001), i * MS)
        kinds.append(s.velocity_kind)
    changes = [b for a, b in itertools.pairwise(kinds) if a != b]
    assert changes == ["difference"]
    assert s.velocity_stencil() == VelocityStencil((0.0, 0.001), (1000.0, -1000.0))


def _quantised_drive(s, hz, seconds=0.3, count=2 * np.pi / 2**16):
    """Offer ``s`` a drive at ``hz`` whose encoder counts ``count`` (2^16 a revolution) on a
    joint moving at 0.05 rad/s and 0.3 rad/s with a 2 Hz swing, its velocity the backward
    difference of its counts; the samples' velocity error (rad/s) against the arm's."""
    period_ns = 1_000_000_000 // hz
    errors = []
    for i in range(round(seconds * hz)):
        t = i * period_ns * 1e-9
        arm = np.array([0.05 * t, 0.3 * t + 0.02 * np.sin(4 * np.pi * t)])
        q = np.round(arm / count) * count
        before = np.array([0.05 * (t - period_ns * 1e-9), 0.3 * (t - period_ns * 1e-9)])
        before[1] += 0.02 * np.sin(4 * np.pi * (t - period_ns * 1e-9))
        qd = (q - np.round(before / count) * count) / (period_ns * 1e-9)
        sample = s.offer(_state(i * period_ns, q, qd), i * period_ns)
        if sample is not None:
            truth = np.array([0.05, 0.3 + 0.08 * np.pi * np.cos(4 * np.pi * t)])
            errors.append(sample.velocity - truth)
    return np.array(errors)


def test_a_1khz_drives_short_difference_is_replaced_by_an_estimate_over_a_sample():
    """A drive's one-cycle difference of a quantised encoder at 1 kHz jumps by a count per
    cycle (0.096 rad/s); the samples' velocity is then robot mode's parabola over T = 10 ms of
    the same positions, with that estimate's stencil for the law: under half of the error
    (``sqrt(26) sigma / T`` against ``sqrt(2) sigma / P``).
    A 500 Hz drive (its cycle a fifth of T, over ``short_difference``) keeps its difference."""
    s = _sampler(period=0.01)
    s.start()
    errors = _quantised_drive(s, 1000)
    assert s.velocity_kind == "sample_estimate"
    over_a_sample = VelocityEstimator(window_ns=T)
    assert s.velocity_stencil() == over_a_sample.stencil(MS)
    assert "over 10 ms" in s.velocity_description()
    kept = _sampler(period=0.01, short_difference=0.0)
    kept.start()
    drives = _quantised_drive(kept, 1000)
    assert kept.velocity_kind == "difference"
    settled = slice(DIFFERENCE_STATES // 10 + 2, None)  # samples after the kind is known
    estimate_rms = np.sqrt(np.mean(errors[settled] ** 2))
    drive_rms = np.sqrt(np.mean(drives[settled] ** 2))
    assert estimate_rms < drive_rms / 2.0  # 0.016 vs 0.046 rad/s; the noises' ratio: 2.8
    slower = _sampler(period=0.01)
    slower.start()
    _quantised_drive(slower, 500)
    assert slower.velocity_kind == "difference"
    assert slower.velocity_stencil() == VelocityStencil((0.0, 0.002), (500.0, -500.0))


def test_the_estimate_in_place_of_a_short_difference_is_the_parabola_over_a_sample():
    """Sample by sample the velocity is what :class:`VelocityEstimator` over T gives for the
    driver's positions (fed from the first state, so it has its window when the kind is told)."""
    s = _sampler(period=0.01)
    s.start()
    reference = VelocityEstimator(window_ns=T)
    t = np.arange(200) * 0.001
    q = np.stack([np.sin(3 * t), 0.2 * t**2], axis=1)
    for i in range(1, len(t)):
        expected = reference.update(i * MS, q[i])
        sample = s.offer(_state(i * MS, q[i], (q[i] - q[i - 1]) / 0.001), i * MS)
        if sample is not None and s.velocity_kind == "sample_estimate":
            np.testing.assert_array_equal(sample.velocity, expected)
    assert s.velocity_kind == "sample_estimate"


def test_the_sampler_gives_a_drivers_difference_as_a_stencil_and_forgets_it_after_a_gap():
    """Kept through a stall shorter than the watchdog (the same drive: forgetting it restarted
    the law twice); forgotten after states gone for longer (a driver back may be another)."""
    s = _sampler(max_age=0.02, watchdog=0.1)
    assert s.velocity_kind == "none"
    q = np.array([0.0])
    for i in range(DIFFERENCE_STATES + 1):
        s.offer(_state(i * T, q.copy(), (q - (q - 1e-3 * i if i else q)) / 0.01), i * T)
        assert s.velocity_kind == "driver" or i == DIFFERENCE_STATES
        q = q + 1e-3 * (i + 1)
    assert s.velocity_kind == "difference"
    assert s.velocity_stencil() == VelocityStencil((0.0, 0.01), (100.0, -100.0))
    stalled = (DIFFERENCE_STATES + 5) * T  # 50 ms without states: beyond max_age only
    s.offer(_state(stalled, q, 1.0), stalled)
    assert s.velocity_kind == "difference"
    later = stalled + 11 * T  # beyond the watchdog: the evidence is from before it
    s.offer(_state(later, q, 1.0), later)
    assert s.velocity_kind == "driver" and s.velocity_stencil() is None
    s.offer(_state(later + T, q + 0.01), later + T)  # positions only: its own estimate
    assert s.velocity_kind == "estimated"


@pytest.mark.parametrize(
    ("hz", "delays_ms", "samples"),
    [
        (100, (0.0, 4.0, 9.9, 10.0, 14.0, 19.9, 20.0), (0, 0, 1, 1, 1, 2, 2)),
        (250, (4.0, 8.0, 9.9, 12.0), (0, 0, 1, 1)),
        (1000, (1.0, 9.0, 9.8, 10.0), (0, 0, 1, 1)),
    ],
)
def test_a_delay_short_of_whole_samples_by_jitter_counts_as_them(hz, delays_ms, samples):
    """``samples_late``: the whole samples of T = 10 ms a delay spans, a delay short of one by
    under a quarter of the driver's period (its stamps' jitter) counting as it; 8 ms on a
    250 Hz driver is under a sample (the law's lags model it)."""
    s = _sampler(period=0.01)
    period_ns = 1_000_000_000 // hz
    for i in range(5):
        s.offer(_state(i * period_ns, 0.0, 0.0), i * period_ns)
    assert s.driver_period_ns == period_ns
    got = tuple(s.samples_late(d * 1e-3) for d in delays_ms)
    assert got == samples


@pytest.mark.parametrize(("hz", "first_ms"), [(250, 8), (1000, 10), (100, 10)])
def test_a_sample_is_overtaken_by_a_state_in_hand_that_is_the_next_samples(hz, first_ms):
    """The next sample's state is the driver's nearest to its time (250 Hz: 8 or 12 ms after
    a sample's state, a tie taking the earlier): a state in hand that far on overtakes the
    sample, the driver's states before it do not."""
    s = _sampler()
    start = 1000 * T
    _drive(s, hz, start - 50 * MS, 0.05)
    s.start()
    _drive(s, hz, start, 0.05)
    assert s.last is not None and not s.overtaken(None)
    last, driver = s.last.state_ns, round(1e9 / hz)
    later = [last + i * driver for i in range(1, 3 * T // driver)]
    assert all(s.overtaken(t) == (t - last >= first_ms * MS) for t in later)
