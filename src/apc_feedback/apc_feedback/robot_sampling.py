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

Velocity, when the driver sends none (``velocity`` empty), is estimated from the driver's
positions: the parabola through the newest state, the newest one at least ``velocity_window``
before it (the base) and the one nearest the middle, differentiated at the newest stamp (with
a window of 0: the last three states). What it costs: no lag for a constant acceleration (the
error grows with the jerk j, about ``j a b / 6`` for states ``a`` and ``b`` seconds back), where
a two-point backward difference lags by half its span; and noise: evenly spaced over a span
``w``, position noise ``sigma`` becomes ``sqrt(26) sigma / w`` of velocity noise (the two-point
difference: ``sqrt(2) sigma / w``), an encoder count ``c`` a velocity step up to ``4 c / w``,
so quantised positions need the drive's own velocity (docs/robot.md has what each measured).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from apc_core.params import SettingError, check_settings, setting
from apc_core.robot import PAPER_PERIOD_S
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
    max_age, watchdog, velocity_window :
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

    def __post_init__(self) -> None:
        check_settings(self, RobotSamplingError)
        if not (math.isfinite(self.period) and self.period > 0.0):
            raise RobotSamplingError(f"period must be > 0 s, got {self.period}", field="period")
        if self.watchdog < self.max_age:
            raise RobotSamplingError(
                f"watchdog must be >= max_age ({self.max_age} s), got {self.watchdog}",
                field="watchdog",
            )


class VelocityEstimator:
    """Velocity from positions: a parabola over ``window_ns`` (see the module docstring).

    :attr:`acceleration` is the parabola's (None before three states).
    """

    def __init__(self, window_ns: int) -> None:
        self.window_ns = int(window_ns)
        self._history: deque[tuple[int, np.ndarray]] = deque()
        self.acceleration: np.ndarray | None = None
        self._estimated = True  # the newest state's acceleration is known

    def reset(self) -> None:
        self._history.clear()
        self.acceleration = None
        self._estimated = True

    def update(self, stamp_ns: int, position: np.ndarray) -> np.ndarray | None:
        """Add a state (stamps strictly increasing); its velocity, None for the first."""
        self.add(stamp_ns, position)
        return self._estimate()

    def add(self, stamp_ns: int, position: np.ndarray) -> None:
        """Add a state (stamps strictly increasing) without estimating at it: for a driver
        that sends its velocity, whose states need the estimate's acceleration only when one
        is carried to its sample's time (:meth:`newest_acceleration`)."""
        history = self._history
        history.append((stamp_ns, position))
        # Keep one state at least a window old (the base) and everything after it.
        while len(history) > 3 and stamp_ns - history[1][0] >= self.window_ns:
            history.popleft()
        self.acceleration, self._estimated = None, False

    def stencil(self, period_ns: int) -> VelocityStencil:
        """The estimate as weights on past positions for states ``period_ns`` apart (a steady
        driver): what the adaptive law's prior models (its ``expect_velocity_stencil``).

        Read off this estimator's own rule: positions that are unit vectors, one per state, give
        each state's weight as the velocity's entry.
        """
        if period_ns <= 0:
            raise ValueError(f"period_ns must be > 0, got {period_ns}")
        states = max(3, -(-self.window_ns // period_ns) + 2)
        probe = VelocityEstimator(self.window_ns)
        unit = np.eye(states)
        for i in range(states - 1):
            probe.add(i * period_ns, unit[i])
        weights = probe.update((states - 1) * period_ns, unit[-1])
        assert weights is not None
        used = [i for i in range(states) if weights[i] != 0.0]
        return VelocityStencil(
            tuple((states - 1 - i) * period_ns * 1e-9 for i in used),
            tuple(float(weights[i]) for i in used),
        )

    def newest_acceleration(self) -> np.ndarray | None:
        """The parabola's acceleration at the newest state (None before three states)."""
        if not self._estimated:
            self._estimate()
        return self.acceleration

    def _estimate(self) -> np.ndarray | None:
        """The velocity at the newest state (None for the first); sets :attr:`acceleration`."""
        self._estimated = True
        history = self._history
        stamp_ns, position = history[-1]
        t2, q2 = history[0]
        if t2 == stamp_ns:
            return None
        if len(history) == 2:
            return (position - q2) / ((stamp_ns - t2) * 1e-9)
        # The parabola through the base, the state nearest the middle and the newest one,
        # differentiated at the newest: no lag for a constant acceleration.
        if len(history) == 3:  # the last three states (a window of 0, or the states spread)
            t1, q1 = history[1]
        else:
            middle = (t2 + stamp_ns) / 2
            t1, q1 = min(list(history)[1:-1], key=lambda entry: abs(entry[0] - middle))
        a, b = (stamp_ns - t1) * 1e-9, (stamp_ns - t2) * 1e-9
        velocity, self.acceleration = _parabola(position, q1, q2, a, b)
        return velocity


#: Informative states in a row whose velocity is their positions' backward difference before
#: the driver's velocity is taken as one (:class:`DifferenceCheck`).
DIFFERENCE_STATES = 10
#: How closely the periods a differenced velocity implies agree (relative): a double's rounding
#: of ``(q - q_prev) / P`` moves them by a few parts in 1e16; an arm's own velocity misses by
#: its acceleration over half a period, or by a whole encoder count.
DIFFERENCE_TOLERANCE = 1e-6


class DifferenceCheck:
    """Whether the driver's velocity is the backward difference of its positions.

    Many drives report ``(q(t) - q(t - P)) / P`` of their encoder (robot_sim's
    ``velocity_source: difference``): a velocity half a period behind the arm's, which the
    adaptive law's prior models once it is told the stencil (the same lag robot mode's own
    estimate has, over one period instead of two). The driver does not say; its states do. A
    state is informative when some joint moved or has a velocity; then every joint with a
    position change must have a velocity of the same sign, every joint without one none, and
    each moving joint's ``Δq / v`` is the period it was differenced over: the same on every joint,
    within half to twice the stamps' interval. :data:`DIFFERENCE_STATES` informative states in a
    row that agree make it a difference over their median period; one that does not, or states
    gone for longer than the watchdog (:meth:`reset`), makes it a velocity of the arm's again.
    States that say nothing (the arm at rest: every position and velocity unchanged at zero)
    change nothing, and so does a state that follows a missed one (its interval not within half
    a period of the driver's): its change spans two cycles where the drive's difference spans
    one, so it is no evidence either way. A driver on a loaded machine misses cycles (robot_sim
    at 1 kHz on wall time: 1-3 % of them); judged, each missed cycle made the drive's difference
    the arm's velocity and ten states later a difference again, each change a restart of the
    adaptive law. A drive that
    differences in single precision or filters its difference is taken as measuring the arm's
    velocity (the law is then not told a stencil: robot mode's behaviour without the check).
    :attr:`refuted`: since the last reset a state has shown a velocity that is no difference.
    """

    def __init__(self) -> None:
        self._periods: deque[float] = deque(maxlen=DIFFERENCE_STATES)
        self.period_s: float | None = None  # the period the velocity differences over, or None
        self.refuted = False  # a state showed a velocity that is no difference (since reset)

    def reset(self) -> None:
        self._periods.clear()
        self.period_s = None
        self.refuted = False

    def add(
        self, change: np.ndarray, velocity: np.ndarray, interval_ns: int, driver_period_ns: int = 0
    ) -> None:
        """A state's position change since the previous state (``interval_ns`` before it) and
        its velocity; ``driver_period_ns``: the driver's period as known so far (0: not yet)."""
        moved, reported = change != 0.0, velocity != 0.0
        if not (moved.any() or reported.any()):
            return
        if driver_period_ns > 0 and 2 * abs(interval_ns - driver_period_ns) > driver_period_ns:
            return  # after a missed state (or an early one): not one cycle's change
        period = self._period(change, velocity, moved, reported, interval_ns * 1e-9)
        if period is None:
            self.reset()
            self.refuted = True
            return
        self._periods.append(period)
        if len(self._periods) == DIFFERENCE_STATES:
            self.period_s = float(np.median(self._periods))
            self.refuted = False

    @staticmethod
    def _period(
        change: np.ndarray,
        velocity: np.ndarray,
        moved: np.ndarray,
        reported: np.ndarray,
        interval_s: float,
    ) -> float | None:
        """The period every joint's velocity differences its change over, or None."""
        if not np.array_equal(moved, reported):
            return None
        periods = change[moved] / velocity[moved]
        period = float(periods[0])
        if not (0.5 * interval_s <= period <= 2.0 * interval_s):
            return None
        if np.any(np.abs(periods - period) > DIFFERENCE_TOLERANCE * period):
            return None
        return period


def _parabola(
    q0: np.ndarray, q1: np.ndarray, q2: np.ndarray, a: float, b: float
) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration at ``q0`` of the parabola through ``q0`` (now), ``q1`` (``a``
    s before) and ``q2`` (``b`` s before), per joint.

    Plain Python per entry: for a joint state's few entries it is quicker than numpy's fourteen
    array operations, with the same arithmetic in the same order (the same bits).
    """
    ab, a_ba, b_ba, a_b = a * b, a * (b - a), b * (b - a), a + b
    velocity, acceleration = [], []
    for x0, x1, x2 in zip(q0.tolist(), q1.tolist(), q2.tolist(), strict=True):
        velocity.append(x0 * a_b / ab - x1 * b / a_ba + x2 * a / b_ba)
        acceleration.append(2.0 * (x0 / ab - x1 / a_ba + x2 / b_ba))
    return np.array(velocity), np.array(acceleration)


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
        if not self.velocity_estimated:
            period = self.difference.period_s
            return (
                None
                if period is None
                else VelocityStencil((0.0, period), (1.0 / period, -1.0 / period))
            )
        if self.driver_period_ns <= 0:
            return None
        return self.velocity.stencil(self.driver_period_ns)

    def velocity_is_the_arms(self) -> bool:
        """The driver's velocity, shown by its states to be no difference: the arm's own."""
        return self.velocity_kind == "driver" and self.difference.refuted

    @property
    def velocity_kind(self) -> str:
        """What the samples' velocity is: ``estimated`` (from positions), ``difference`` (the
        driver's backward difference of its positions), ``driver`` (the driver's, taken as
        the arm's), or ``none`` before a state."""
        if self.newest is None:
            return "none"
        if self.velocity_estimated:
            return "estimated"
        return "driver" if self.difference.period_s is None else "difference"

    def velocity_description(self) -> str:
        """What the samples' velocity is, in words (for a log line)."""
        stencil = self.velocity_stencil()
        if self.velocity_kind == "difference" and stencil is not None:
            span = stencil.offsets[-1] * 1e3
            return f"the backward difference of the driver's positions over {span:.3g} ms"
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
    ratio = period_ns / driver_ns
    if ratio >= 2.0 or abs(ratio - round(ratio)) < 0.02:
        return None
    return max(1, round(ratio)) * driver_ns * 1e-9
