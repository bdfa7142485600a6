"""Robot mode's sampling: sample ``k`` is taken when the driver's state for its instant arrives.

A ros2_control driver (``joint_state_broadcaster``) stamps ``/joint_states`` with its own
clock at its own rate. Sample ``k`` belongs to the time ``kT + phase`` and is stamped ``kT``:
samples stay on apc's grid, so the feedforward and the feedback law see the same sample
indices as with apc's plant. Everything is told times in nanoseconds, never reads a clock.

Taken on arrival. At :meth:`RobotSampler.start` (activation, a watchdog's recovery) the phase
locks to the driver's cycle: the first state's stamp modulo ``T``. Sample ``k`` is the state
nearest ``kT + phase``: the first one stamped at or after ``kT + phase - P / 2`` (``P`` the
driver's period, the median of its recent stamp intervals), taken in that state's callback, so
the command computed from it leaves at once and always the same time after the state. A driver
whose period divides ``T`` (100, 250, 500, 1000 Hz at 10 ms) has a state at every sample time:
the samples are its states exactly. Otherwise (333 Hz) the state is carried to the sample's
time, backward or forward by at most ``P / 2``: ``q + v a + acc a^2 / 2`` and ``v + acc a`` over
``a`` = sample time minus the state's stamp (velocity and acceleration from the parabola below;
with fewer than three states, ``q + v a``), so samples stand exactly ``T`` apart, which Eq. 16
assumes. There is no sample timer: one of its own would take sample ``k`` at an arbitrary
phase of the driver's cycle, the delay from a state to its command would then differ between
runs by up to a driver period, and with it the adaptive law loses the arm in some runs.

Rules (each counted by the caller under the reason's name):

- ``duplicate``: a state with the stamp of the newest accepted one (the first one stands);
- ``out_of_order``: a state older than the newest accepted one;
- ``stale``: a state older than ``max_age`` when it arrives;
- ``future``: a state stamped more than ``max_age`` ahead of the node clock (the driver's and
  the controllers' clocks disagree: same machine, or synchronised by PTP/chrony, is required);
- ``missed_samples``: sample times no state came near (states lost, a driver slower than
  ``1/T``), seen as a jump of ``k``;
- ``no_velocity``: the state for a sample has no velocity (the driver sends none and the
  estimate has a single position after a gap): no sample.

The last two leave a gap in ``k``; the adaptive law skips its identification step across a
gap (Eq. 16 describes a one-period transition). Without states the sampler takes nothing; the
caller's watchdog (:meth:`RobotSampler.fresh`) notices.

Velocity, when the driver sends none, is estimated from its positions; a drive's velocity is
checked for being the backward difference of its positions (:mod:`apc_feedback.joint_velocity`),
and one differenced over a short span (at most ``short_difference`` of ``T``: a 1 kHz drive at
T = 10 ms) is replaced by the estimate from its positions over ``T``
(:meth:`RobotSampler._short_difference` says why).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

from apc_core.params import SettingError, check_settings, setting
from apc_core.robot import PAPER_PERIOD_S
from apc_feedback.joint_velocity import DifferenceCheck, VelocityEstimator
from apc_feedback.linearize import VelocityStencil
from apc_msgs_py import JointSample, WireError, seconds_to_ns


class StateRejectedError(WireError):
    """A joint state that cannot be sampled; ``reason`` is its counter's name (``duplicate``,
    ``out_of_order``, ``stale``, ``future``)."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason


class RobotSamplingError(SettingError):
    """A bad robot-sampling setting; ``field`` names it."""


@dataclass(frozen=True)
class RobotSamplingConfig:
    """Timing rules of robot mode (seconds); the node's parameters are made from the settings.

    Attributes
    ----------
    period : float
        Sample period T.
    max_age, watchdog, velocity_window, short_difference :
        See their descriptions; ``watchdog >= max_age``.
    """

    period: float = PAPER_PERIOD_S
    max_age: float = setting(
        0.02,
        "oldest joint state (s, by its stamp) accepted and sampled; older is stale",
        1e-4,
        10.0,
    )
    watchdog: float = setting(
        0.1,
        "no fresh joint state this long (s) -> hold against gravity once, then silence",
        1e-4,
        60.0,
    )
    velocity_window: float = setting(
        0.0,
        "span (s) of the velocity estimate when the driver sends none (0: last three states)",
        0.0,
        1.0,
    )
    short_difference: float = setting(
        0.15,
        "a drive's velocity differenced over at most this fraction of T is replaced by an "
        "estimate from its positions over T (0: never)",
        0.0,
        1.0,
    )

    def __post_init__(self) -> None:
        check_settings(self, RobotSamplingError)
        if not (math.isfinite(self.period) and self.period > 0.0):
            raise RobotSamplingError(f"period must be > 0 s, got {self.period}", field="period")
        if self.watchdog < self.max_age:
            raise RobotSamplingError(
                f"watchdog must be >= max_age ({self.max_age} s), got {self.watchdog}",
                field="watchdog",
            )


class Take(NamedTuple):
    """The newest sample :meth:`RobotSampler.offer` took, or why the state for one gave none.

    Attributes
    ----------
    k : int
        The sample's index (stamp ``kT``).
    sample : JointSample or None
        The sample, stamped ``kT``: position and velocity carried to ``kT + phase``, the
        driver's effort (or None); None if the state could not be one (``reason`` says why).
    state_ns : int
        Driver stamp of the state the sample is taken from.
    age_ns : int
        That state's age when it arrived (``now`` minus its stamp).
    offset_ns : int
        The state's stamp minus the sample's time ``kT + phase`` (0 when the driver's period
        divides ``T``; the state is carried back by it).
    missed : int
        Sample times skipped since the previous sample (no state came near them).
    reason : str
        Why no sample was taken (``no_velocity``), else "".
    """

    k: int
    sample: JointSample | None
    state_ns: int
    age_ns: int
    offset_ns: int
    missed: int
    reason: str = ""


#: Stamp intervals the driver's period is the median of: robust to a lost state or a late cycle.
PERIOD_INTERVALS = 15
#: Stamp intervals in hand before the sampling period is chosen from the driver's
#: (``period_from_driver``): a median of one or two is a lost state's double period, or jitter.
RETIME_INTERVALS = 5


class RobotSampler:
    """Samples a driver's joint states as they arrive (see the module docstring).

    The robot implementation of :class:`apc_feedback.sampling.JointStateSampler`:
    :meth:`offer` every joint state as it arrives; once started (:meth:`start`) it returns the
    sample the state is, else None (:attr:`last` says which sample, how old its state was and
    why none was taken), and raises :class:`StateRejectedError` for one that cannot be sampled.
    :meth:`stop` ends sampling; states are still taken in (the velocity estimate and the
    driver's period keep up), and the newest one is kept across :meth:`start` (a re-activation
    samples the position the arm has then).
    """

    ticking = False

    def __init__(self, config: RobotSamplingConfig) -> None:
        self.config = config
        self.period_ns = seconds_to_ns(config.period)
        self.max_age_ns = seconds_to_ns(config.max_age)
        self.watchdog_ns = seconds_to_ns(config.watchdog)
        self.velocity = VelocityEstimator(seconds_to_ns(config.velocity_window))
        # Over a sample's span: in place of a drive's short difference (velocity_kind).
        self.sample_velocity = VelocityEstimator(self.period_ns)
        self.short_difference_s = config.short_difference * config.period
        self.newest: JointSample | None = None  # with a velocity (measured or estimated)
        self.velocity_estimated = False  # the newest state came without a velocity
        self.difference = DifferenceCheck()  # whether the driver's velocity differences positions
        self._intervals: deque[int] = deque(maxlen=PERIOD_INTERVALS)
        self.driver_period_ns = 0  # median stamp interval; 0 before two states
        self.sampling = False
        self.phase_ns: int | None = None  # locked by the first state after start()
        self._next_k = 0  # the lowest index the next sample may have
        self._last_k: int | None = None
        self._started = False  # no sample since start(): its gap in k is no missed sample
        self.last: Take | None = None  # the newest sample taken (or refused for a reason)

    def offer(self, state: JointSample, now_ns: int) -> JointSample | None:
        """Take in a validated joint state (finite, in model order) arriving at ``now``: the
        sample it is, or None (not sampling, or no sample time near it yet).

        Raises
        ------
        StateRejectedError
            A duplicate or out-of-order stamp, or one more than ``max_age`` from ``now``.
        """
        newest = self.newest
        stamp = state.stamp_ns
        if newest is not None and stamp <= newest.stamp_ns:
            reason = "duplicate" if stamp == newest.stamp_ns else "out_of_order"
            raise StateRejectedError(
                f"header.stamp: {stamp} ns, the newest state is {newest.stamp_ns} ns ({reason})",
                reason,
            )
        if now_ns - stamp > self.max_age_ns:
            raise StateRejectedError(
                f"header.stamp: {stamp} ns is {(now_ns - stamp) * 1e-6:.3f} ms old, more than "
                f"max_age (stale)",
                "stale",
            )
        if stamp - now_ns > self.max_age_ns:
            raise StateRejectedError(
                f"header.stamp: {stamp} ns is {(stamp - now_ns) * 1e-6:.3f} ms ahead of the "
                "node's clock (future: the driver's and the controllers' clocks disagree)",
                "future",
            )
        assert state.position is not None
        if newest is not None:
            if stamp - newest.stamp_ns > self.max_age_ns:
                # After a gap in the states a parabola through positions from before it is no
                # velocity of now (it made the law diverge on a watchdog recovery): start afresh.
                self.velocity.reset()
                self.sample_velocity.reset()
                if stamp - newest.stamp_ns > self.watchdog_ns:
                    # A driver back after the watchdog may be another; one that stalled for
                    # less is the same drive (forgetting its difference restarted the law
                    # twice, and on wall time a 250 Hz stall of 20 ms then lost the Panda).
                    self.difference.reset()
            else:
                if state.velocity is not None:
                    self.difference.add(
                        state.position - newest.position,
                        state.velocity,
                        stamp - newest.stamp_ns,
                        self.driver_period_ns,
                    )
                self._intervals.append(stamp - newest.stamp_ns)
                ordered = sorted(self._intervals)  # 15 ints: a tenth of numpy.median's cost
                n = len(ordered)
                self.driver_period_ns = int((ordered[(n - 1) // 2] + ordered[n // 2]) / 2)
        self.velocity_estimated = state.velocity is None
        if self.velocity_estimated:
            self.difference.reset()
            velocity = self.velocity.update(stamp, state.position)
        else:  # the driver's velocity; the estimate's acceleration only if _take carries it
            self.velocity.add(stamp, state.position)
            if self._short_difference():
                velocity = self.sample_velocity.update(stamp, state.position)
            else:
                self.sample_velocity.add(stamp, state.position)
                velocity = state.velocity
        self.newest = JointSample(stamp, state.position, velocity, state.effort)
        if not self.sampling:
            return None
        return self._take(now_ns)

    def velocity_stencil(self) -> VelocityStencil | None:
        """The samples' velocity as a stencil of the driver's positions: this estimate's at the
        driver's period, or the driver's own backward difference (:class:`DifferenceCheck`);
        None where it is the arm's velocity as far as is known (a driver's that is not a
        difference, or the driver's period not known yet)."""
        if not self.velocity_estimated and not self._short_difference():
            period = self.difference.period_s
            return (
                None
                if period is None
                else VelocityStencil((0.0, period), (1.0 / period, -1.0 / period))
            )
        if self.driver_period_ns <= 0:
            return None
        estimate = self.velocity if self.velocity_estimated else self.sample_velocity
        return estimate.stencil(self.driver_period_ns)

    def _short_difference(self) -> bool:
        """The driver's velocity is its drive's backward difference over at most
        ``short_difference`` of ``T`` (a 1 kHz drive at T = 10 ms): the samples' velocity is
        then estimated from its positions over ``T`` instead (``velocity_kind``
        ``sample_estimate``).

        Why. A drive differences its encoder over one of its cycles, so a count of position is
        a velocity step of a count over that cycle (0.096 rad/s at 1 kHz on 2^16 counts a
        revolution), and the law's gains of order M/T turn it into torque from sample to
        sample: the physical Panda's commands in a hold moved by 24 N m a sample on a 1 kHz
        drive. The parabola over ``T`` spreads a count over the sample (its noise
        ``sqrt(26) sigma / T`` against the difference's ``sqrt(2) sigma / P``) at the cost of
        a lag the law's prior models (its stencil). Measured in simulated time
        (docs/robot.md, "Commands that chatter"): on a 1 kHz drive it halves the chatter and
        the physical arms track closer; on 250-500 Hz drives (P a fifth of T or more) it
        costs the physical arms tracking, and there the difference is kept.
        """
        period = self.difference.period_s
        return period is not None and period <= self.short_difference_s

    def velocity_is_the_arms(self) -> bool:
        """The driver's velocity, shown by its states to be no difference: the arm's own."""
        return self.velocity_kind == "driver" and self.difference.refuted

    @property
    def intervals_seen(self) -> int:
        """The stamp intervals the driver's period is the median of (at most 15)."""
        return len(self._intervals)

    @property
    def velocity_kind(self) -> str:
        """What the samples' velocity is: ``estimated`` (from positions), ``difference`` (the
        driver's backward difference of its positions), ``sample_estimate`` (estimated from
        the positions over ``T`` in place of a drive's short difference), ``driver`` (the
        driver's, taken as the arm's), or ``none`` before a state."""
        if self.newest is None:
            return "none"
        if self.velocity_estimated:
            return "estimated"
        if self.difference.period_s is None:
            return "driver"
        return "sample_estimate" if self._short_difference() else "difference"

    def velocity_description(self) -> str:
        """What the samples' velocity is, in words (for a log line)."""
        stencil = self.velocity_stencil()
        if self.velocity_kind == "difference" and stencil is not None:
            span = stencil.offsets[-1] * 1e3
            return f"the backward difference of the driver's positions over {span:.3g} ms"
        if self.velocity_kind == "sample_estimate":
            period = self.difference.period_s
            assert period is not None
            return (
                f"estimated from the driver's positions over {self.period_ns * 1e-6:.3g} ms "
                f"(its drive's difference over {period * 1e3:.3g} ms is short)"
            )
        return {
            "driver": "the driver's, taken as the arm's",
            "estimated": "estimated from the driver's positions",
        }.get(self.velocity_kind, self.velocity_kind)

    def samples_late(self, delay_s: float) -> int:
        """The whole samples from a sample to the one whose interval its command, applied
        ``delay_s`` after the sample, acts over: the sample whose nominal torque the command
        should carry (robot mode's ``feedforward_ahead``).

        Whole samples only: a delay under a sample (a driver faster than 1/T) is the law's to
        model (its input lags split by it), and shifting the torque by a fraction of a sample
        moved the physical arms both ways in simulated time (docs/robot.md, "The nominal
        torque of when a command acts"). A delay measured from the driver's stamps is a whole
        number of its periods up to their jitter, and the echo keeps a short one
        (:class:`~apc_feedback.command_echo.CommandEcho`): a quarter of the driver's period
        more counts, so that 9.9 ms measured on a 100 Hz driver is the sample it is (and a
        driver of over 100 Hz whose period is over half of T, which robot mode warns about,
        rounds up: 8.3 ms at 120 Hz counts as a sample). No slack before the driver's period
        is known, which a start waits for.
        """
        if not delay_s > 0.0:
            return 0
        return int((delay_s * 1e9 + 0.25 * self.driver_period_ns) // self.period_ns)

    def overtaken(self, newest_ns: int | None) -> bool:
        """Whether the last sample taken is overtaken by a state stamped ``newest_ns`` already
        in hand (None: none newer): one at the next sample's time or later (within half a
        driver period, where states are carried to it), so that a command from the last one
        would act after the next one's. Its state is then observed, not answered."""
        take = self.last
        return (
            newest_ns is not None
            and take is not None
            and 2 * (newest_ns - take.state_ns) >= 2 * self.period_ns - self.driver_period_ns
        )

    def fresh(self, now_ns: int) -> bool:
        """Whether a joint state arrived within the watchdog window."""
        return self.newest is not None and now_ns - self.newest.stamp_ns <= self.watchdog_ns

    def start(self) -> None:
        """Start sampling: the next state that can be a sample locks the phase and is one.

        Its index is its stamp's ``floor(stamp / T)``; the samples after a re-start come after
        the ones before it with at least one index left out (the law takes no step across).
        """
        self.sampling, self._started = True, True
        self.phase_ns = None
        self._next_k = 0 if self._last_k is None else self._last_k + 2

    def stop(self) -> None:
        """Stop sampling (states are still taken in)."""
        self.sampling = False

    def tick(self, now_ns: int) -> None:
        """Never due: samples are taken on arrival (:class:`JointStateSampler`'s protocol)."""
        return None

    def _take(self, now_ns: int) -> JointSample | None:
        newest = self.newest
        assert newest is not None
        stamp, period = newest.stamp_ns, self.period_ns
        if self.phase_ns is None:
            if newest.velocity is None:  # a single position: nothing to carry it with
                self.last = Take(stamp // period, None, stamp, now_ns - stamp, 0, 0, "no_velocity")
                return None
            self.phase_ns = stamp % period
            self._next_k = max(self._next_k, stamp // period)
        phase = self.phase_ns
        # The sample time nearest the stamp, never one already passed.
        k = max((stamp - phase + period // 2) // period, self._next_k)
        offset = stamp - (k * period + phase)
        if 2 * offset < -self.driver_period_ns:
            return None  # the driver's next state is nearer sample k's time
        missed = 0 if self._started else k - self._next_k
        self._next_k = k + 1
        if newest.velocity is None:
            self.last = Take(k, None, stamp, now_ns - stamp, offset, missed, "no_velocity")
            return None
        self._last_k, self._started = k, False
        position, velocity = newest.position, newest.velocity
        if offset:
            a = -offset * 1e-9
            acceleration = self.velocity.newest_acceleration()
            if acceleration is None:
                position = position + a * velocity
            else:
                position = position + a * velocity + (0.5 * a * a) * acceleration
                velocity = velocity + a * acceleration
        sample = JointSample(k * period, position, velocity, newest.effort)
        self.last = Take(k, sample, stamp, now_ns - stamp, offset, missed)
        return sample


def period_advice(period_ns: int, driver_ns: int) -> float | None:
    """The sampling period (s) to advise for a driver whose period ``driver_ns`` is over half
    of ``T = period_ns`` and does not divide it (125 Hz under T = 10 ms): the multiple of the
    driver's period nearest ``T``; None for any other driver.

    Such a driver's states fall up to half its period off the sample times and its commands'
    delay changes from sample to sample over a cycle of samples. In simulated time it lost the
    Panda at T = 10 ms with 30 % of the commands a cycle late (the law alone 2 runs of 5;
    supervised, with every physical effect, 2 of 5) and at 8 ms none (docs/robot.md, "When the
    arm applies a command"). Faster drivers (250 Hz: T is 2.5 of their periods) track better
    at T = 10 ms than at a multiple of their period.
    """
    driver_ns = nominal_period_ns(driver_ns)
    ratio = period_ns / driver_ns
    if ratio >= 2.0 or abs(ratio - round(ratio)) < 0.02:
        return None
    return max(1, round(ratio)) * driver_ns * 1e-9


def nominal_period_ns(driver_ns: int) -> int:
    """The driver's period as a whole number of hertz (ros2_control's ``update_rate`` is one)
    or of tenths of a millisecond (a simulator's step) gives it, whichever is nearer the
    measured median ``driver_ns``, where that is within 1 % of it; else the median. Stamps
    taken at each update's time jitter by tens of microseconds, and a sampling period as far
    off the driver's drifts across its cycles."""
    hertz = max(1, round(1e9 / driver_ns))
    nominal = min((round(1e9 / hertz), round(driver_ns, -5)), key=lambda c: abs(c - driver_ns))
    return nominal if abs(nominal - driver_ns) <= 0.01 * driver_ns else driver_ns


def period_warning(period_ns: int, driver_ns: int) -> str | None:
    """What robot mode says of a driver whose period ``T`` should be a multiple of
    (:func:`period_advice`), naming that multiple; None for any other driver."""
    if (multiple := period_advice(period_ns, driver_ns)) is None:
        return None
    return (
        f"the driver's period {driver_ns * 1e-6:.3g} ms does not divide the sampling period "
        f"{period_ns * 1e-6:.3g} ms: its states are carried to the sample times and a "
        "command's delay changes from sample to sample, which the adaptive law does not "
        f"model; set 'period' to a multiple of the driver's ({multiple:.4g} s)"
    )


class PeriodAdvice:
    """Robot mode's warning of a driver whose period ``T`` should be a multiple of
    (:func:`period_warning`), once per driver period seen."""

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns
        self._judged_ns = 0  # the driver period judged last

    def warning(self, driver_ns: int) -> str | None:
        """The warning for ``driver_ns`` the first time it is seen (in a row), else None."""
        if driver_ns == self._judged_ns:
            return None
        self._judged_ns = driver_ns
        return period_warning(self.period_ns, driver_ns)
