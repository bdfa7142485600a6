"""The velocity of a driver's joint states: estimated from its positions, or its drive's own.

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

from collections import deque

import numpy as np

from apc_feedback.linearize import VelocityStencil


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
