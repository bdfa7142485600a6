"""Robot mode's sampling: the controllers own the sample clock, the driver sends what it sends.

A ros2_control driver (``joint_state_broadcaster``) stamps ``/joint_states`` with its own
clock at its own rate. Here sample ``k`` is *taken* by the controllers' timer, at time
``kT + phase`` on the node clock, from the newest joint state, and stamped ``kT``: samples stay
on apc's grid in absolute time, so the feedforward and the feedback law see the same sample
indices as with apc's plant. Everything is told times in nanoseconds, never reads a clock.

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

from apc_core.wire import JointSample, seconds_to_ns


class RobotSamplingError(ValueError):
    """A bad robot-sampling setting; the message starts with the field name."""


@dataclass(frozen=True)
class RobotSamplingConfig:
    """Timing rules of robot mode (seconds).

    Attributes
    ----------
    period : float
        Sample period T.
    max_age : float
        Oldest joint state a sample may be taken from (and that is accepted at all).
    watchdog : float
        No accepted joint state this long -> the watchdog fault (``>= max_age``).
    velocity_window : float
        Span of the velocity estimate from positions (0: the last three states).
    """

    period: float = 0.010
    max_age: float = 0.02
    watchdog: float = 0.1
    velocity_window: float = 0.0

    def __post_init__(self) -> None:
        for name in ("period", "max_age", "watchdog"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise RobotSamplingError(f"{name} must be > 0 s, got {value}")
        if not (math.isfinite(self.velocity_window) and self.velocity_window >= 0.0):
            raise RobotSamplingError(f"velocity_window must be >= 0 s, got {self.velocity_window}")
        if self.watchdog < self.max_age:
            raise RobotSamplingError(
                f"watchdog must be >= max_age ({self.max_age} s), got {self.watchdog}"
            )


class VelocityEstimator:
    """Velocity from positions: a parabola over ``window_ns`` (see the module docstring)."""

    def __init__(self, window_ns: int) -> None:
        self.window_ns = int(window_ns)
        self._history: deque[tuple[int, np.ndarray]] = deque()

    def reset(self) -> None:
        self._history.clear()

    def update(self, stamp_ns: int, position: np.ndarray) -> np.ndarray | None:
        """Add a state (stamps strictly increasing); its velocity, None for the first."""
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
        return position * (a + b) / (a * b) - q1 * b / (a * (b - a)) + q2 * a / (b * (b - a))


class Take(NamedTuple):
    """What one tick of :meth:`RobotSampler.tick` gives.

    Attributes
    ----------
    k : int
        Index of this tick's sample (stamp ``kT``).
    sample : JointSample or None
        The sample, stamped ``kT`` (position, velocity, the driver's effort or None); None if
        none was taken (``reason`` says why).
    age_ns : int
        Age of the joint state the sample is (or would be) taken from; -1 without one.
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


class RobotSampler:
    """Samples a driver's joint states on the controllers' clock (see the module docstring).

    :meth:`offer` every joint state as it arrives, :meth:`start` at activation, :meth:`tick`
    on every timer call. The newest state is kept across :meth:`start` (a re-activation
    samples the position the arm has then).
    """

    def __init__(self, config: RobotSamplingConfig) -> None:
        self.config = config
        self.period_ns = seconds_to_ns(config.period)
        self.max_age_ns = seconds_to_ns(config.max_age)
        self.watchdog_ns = seconds_to_ns(config.watchdog)
        self.velocity = VelocityEstimator(seconds_to_ns(config.velocity_window))
        self.newest: JointSample | None = None  # with a velocity (measured or estimated)
        self._taken_stamp: int | None = None  # driver stamp of the last sample's state
        self._phase_ns = 0
        self._last_k: int | None = None

    def offer(self, state: JointSample, now_ns: int) -> str:
        """Take in a validated joint state (finite, in model order); a reject reason or ""."""
        newest = self.newest
        stamp = state.stamp_ns
        if newest is not None and stamp <= newest.stamp_ns:
            return "duplicate" if stamp == newest.stamp_ns else "out_of_order"
        if now_ns - stamp > self.max_age_ns:
            return "stale"
        if stamp - now_ns > self.max_age_ns:
            return "future"
        assert state.position is not None
        velocity = self.velocity.update(stamp, state.position)
        if state.velocity is not None:
            velocity = state.velocity
        self.newest = JointSample(stamp, state.position, velocity, state.effort)
        return ""

    def fresh(self, now_ns: int) -> bool:
        """Whether a joint state arrived within the watchdog window."""
        return self.newest is not None and now_ns - self.newest.stamp_ns <= self.watchdog_ns

    def start(self, now_ns: int) -> int:
        """Start sampling at this tick: its sample is ``k = floor(now / T)``; returns it.

        The ticks' phase within the period is fixed here, so a timer jittering by less than
        ``T / 2`` keeps consecutive indices; the samples after a re-start all come after the
        ones before it.
        """
        k = now_ns // self.period_ns
        if self._last_k is not None and k <= self._last_k:
            k = self._last_k + 1
        self._phase_ns = now_ns - k * self.period_ns
        self._last_k = k - 1
        return k

    def tick(self, now_ns: int) -> Take:
        """Take sample ``k`` (the one due at ``now``) from the newest joint state."""
        assert self._last_k is not None, "start() first"
        k = max(round((now_ns - self._phase_ns) / self.period_ns), self._last_k + 1)
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
        sample = JointSample(k * self.period_ns, newest.position, newest.velocity, newest.effort)
        return Take(k, sample, age, "", missed)
