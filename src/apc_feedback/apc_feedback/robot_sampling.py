"""Robot mode's sampling: the controllers own the sample clock, the driver sends what it sends.

A ros2_control driver (``joint_state_broadcaster``) stamps ``/joint_states`` with its own
clock at its own rate. Here sample ``k`` is *taken* by the controllers' timer, at time
``kT + phase`` on the node clock, from the newest joint state, and stamped ``kT``: samples stay
on apc's grid in absolute time, so the feedforward and the feedback law see the same sample
indices as with apc's plant. Everything is told times in nanoseconds, never reads a clock.

The sample is the newest state carried to the sample's time ``kT + phase`` (the tick's
nominal time): ``q + v a + acc a^2 / 2`` and ``v + acc a`` over ``a`` = that time minus the
state's stamp (velocity and acceleration from the parabola below; with fewer than three
states, ``q + v a``). Samples are then exactly T apart whatever the driver's rate and phase
and the timer's jitter, which Eq. 16 assumes: measured with the loop closed around apc's
plant (``test/test_robot_loop.py``), the newest state as it is lets the adaptive law diverge
with a 333 Hz driver (samples 9 or 12 ms apart), carried forward it holds within 0.2 deg; and
over DDS a late tick followed by a punctual one (two samples 1.4 ms apart, stamped T apart)
made it diverge at activation.

Rules (each counted by the caller under the reason's name):

- ``duplicate``: a state with the stamp of the newest accepted one (the first one stands);
- ``out_of_order``: a state older than the newest accepted one;
- ``stale``: a state older than ``max_age`` when it arrives, or when a tick would take it;
- ``future``: a state stamped more than ``max_age`` ahead of the node clock (the driver's and
  the controllers' clocks disagree: same machine, or synchronised by PTP/chrony, is required);
- ``no_new_state``: a tick finds no state newer than the one the last sample was taken from;
  no sample is taken, so nothing reaches a law twice;
- ``missed_ticks``: ticks that did not run at all (a late timer), seen as a jump of ``k``.

Both the last two leave a gap in ``k``; the adaptive law skips its identification step across
a gap (Eq. 16 describes a one-period transition).

Velocity, when the driver sends none (``velocity`` empty), is estimated from the driver's
positions: the parabola through the newest state, the newest one at least ``velocity_window``
before it (the base) and the one nearest the middle, differentiated at the newest stamp (with
a window of 0: the last three states). What it costs: no lag for a constant acceleration (the
error grows with the jerk j, about ``j a b / 6`` for states ``a`` and ``b`` seconds back), where
a two-point backward difference lags by half its span; and noise: evenly spaced over a span
``w``, position noise ``sigma`` becomes ``sqrt(26) sigma / w`` of velocity noise (the two-point
difference: ``sqrt(2) sigma / w``), an encoder count ``c`` a velocity step up to ``4 c / w``.
Measured on the adaptive law holding the PUMA with its payload, 1 kHz driver
(``test/test_robot_loop.py``'s loop): a two-point difference over 5 ms lets it diverge, the
parabola holds over 1 ms (window 0) and 10 ms; quantised positions need the drive's velocity.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from apc_core.params import SettingError, check_settings, setting
from apc_core.robot import PAPER_PERIOD_S
from apc_core.wire import JointSample, WireError, seconds_to_ns


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

    def reset(self) -> None:
        self._history.clear()
        self.acceleration = None

    def update(self, stamp_ns: int, position: np.ndarray) -> np.ndarray | None:
        """Add a state (stamps strictly increasing); its velocity, None for the first."""
        self.acceleration = None
        history = self._history
        history.append((stamp_ns, position))
        # Keep one state at least a window old (the base) and everything after it.
        while len(history) > 3 and stamp_ns - history[1][0] >= self.window_ns:
            history.popleft()
        t2, q2 = history[0]
        if t2 == stamp_ns:
            return None
        if len(history) == 2:
            return (position - q2) / ((stamp_ns - t2) * 1e-9)
        # The parabola through the base, the state nearest the middle and the newest one,
        # differentiated at the newest: no lag for a constant acceleration.
        middle = (t2 + stamp_ns) / 2
        t1, q1 = min(list(history)[1:-1], key=lambda entry: abs(entry[0] - middle))
        a, b = (stamp_ns - t1) * 1e-9, (stamp_ns - t2) * 1e-9
        self.acceleration = 2.0 * (position / (a * b) - q1 / (a * (b - a)) + q2 / (b * (b - a)))
        return position * (a + b) / (a * b) - q1 * b / (a * (b - a)) + q2 * a / (b * (b - a))


class Take(NamedTuple):
    """What one tick of :meth:`RobotSampler.tick` gives.

    Attributes
    ----------
    k : int
        Index of this tick's sample (stamp ``kT``).
    sample : JointSample or None
        The sample, stamped ``kT``: position and velocity carried forward to the tick, the
        driver's effort (or None); None if none was taken (``reason`` says why).
    age_ns : int
        Age at the tick of the joint state the sample is (or would be) taken from; -1
        without one.
    late_ns : int
        How late the tick is after the sample's nominal time ``kT + phase``.
    reason : str
        Why no sample was taken (``no_new_state``, ``stale``, ``no_state``), else "".
    missed : int
        Ticks skipped since the previous one (a late timer).
    """

    k: int
    sample: JointSample | None
    age_ns: int
    reason: str
    missed: int
    late_ns: int = 0


class RobotSampler:
    """Samples a driver's joint states on the controllers' clock (see the module docstring).

    The robot implementation of :class:`apc_feedback.sampling.JointStateSampler`:
    :meth:`offer` every joint state as it arrives (it keeps the newest, returns None and
    raises :class:`StateRejectedError` for one that cannot be sampled), :meth:`start` at
    activation, :meth:`tick` on every timer call (the sample due, or None; :attr:`last` says
    which sample, how old its state was and why none was taken). The newest state is kept
    across :meth:`start` (a re-activation samples the position the arm has then).
    """

    ticking = True

    def __init__(self, config: RobotSamplingConfig) -> None:
        self.config = config
        self.period_ns = seconds_to_ns(config.period)
        self.max_age_ns = seconds_to_ns(config.max_age)
        self.watchdog_ns = seconds_to_ns(config.watchdog)
        self.velocity = VelocityEstimator(seconds_to_ns(config.velocity_window))
        self.newest: JointSample | None = None  # with a velocity (measured or estimated)
        self._acceleration: np.ndarray | None = None  # of the newest state, when known
        self._taken_stamp: int | None = None  # driver stamp of the last sample's state
        self._phase_ns = 0
        self._last_k: int | None = None
        self.last = Take(-1, None, -1, "no_state", 0)  # what the newest tick did

    def offer(self, state: JointSample, now_ns: int) -> None:
        """Take in a validated joint state (finite, in model order); never a sample by itself.

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
        if newest is not None and stamp - newest.stamp_ns > self.max_age_ns:
            # After a gap in the states a parabola through positions from before it is no
            # velocity of now (it made the law diverge on a watchdog recovery): start afresh.
            self.velocity.reset()
        velocity = self.velocity.update(stamp, state.position)
        self._acceleration = self.velocity.acceleration
        if state.velocity is not None:
            velocity = state.velocity
        self.newest = JointSample(stamp, state.position, velocity, state.effort)
        return None

    def fresh(self, now_ns: int) -> bool:
        """Whether a joint state arrived within the watchdog window."""
        return self.newest is not None and now_ns - self.newest.stamp_ns <= self.watchdog_ns

    def start(self, now_ns: int) -> int:
        """Start sampling at this tick: its sample is ``k = floor(now / T)``; returns it.

        The ticks' phase within the period is fixed here, so a timer late by less than ``T``
        keeps consecutive indices; the samples after a re-start come after the ones before it,
        with at least one index left out.
        """
        k = now_ns // self.period_ns
        if self._last_k is not None:
            k = max(k, self._last_k + 2)  # a gap: the law takes no step across a restart
        self._phase_ns = now_ns - k * self.period_ns
        self._last_k = k - 1
        return k

    def tick(self, now_ns: int) -> JointSample | None:
        """Sample ``k``, the one due at ``now``: the newest joint state carried to the sample's
        time; None if none can be taken (:attr:`last` says why)."""
        self.last = self._take(now_ns)
        return self.last.sample

    def _take(self, now_ns: int) -> Take:
        assert self._last_k is not None, "start() first"
        # Floor: a timer is late, never early; a tick up to T late keeps its index (rounding
        # would name a late tick after the next sample, and every later one a sample ahead).
        k = max((now_ns - self._phase_ns) // self.period_ns, self._last_k + 1)
        missed = k - self._last_k - 1
        self._last_k = k
        newest = self.newest
        if newest is None:
            return Take(k, None, -1, "no_state", missed)
        age = now_ns - newest.stamp_ns
        if newest.stamp_ns == self._taken_stamp:
            return Take(k, None, age, "no_new_state", missed)
        if age > self.max_age_ns:
            return Take(k, None, age, "stale", missed)
        if newest.velocity is None:  # a single position without velocity: nothing to difference
            return Take(k, None, age, "no_velocity", missed)
        self._taken_stamp = newest.stamp_ns
        # Carried to the sample's own time kT + phase, not to ``now``: a late tick and the
        # one after it still give samples T apart.
        position, velocity = newest.position, newest.velocity
        a = (k * self.period_ns + self._phase_ns - newest.stamp_ns) * 1e-9
        acceleration = self._acceleration
        if acceleration is None:
            position = position + a * velocity
        else:
            position = position + a * velocity + (0.5 * a * a) * acceleration
            velocity = velocity + a * acceleration
        sample = JointSample(k * self.period_ns, position, velocity, newest.effort)
        return Take(k, sample, age, "", missed, now_ns - k * self.period_ns - self._phase_ns)
