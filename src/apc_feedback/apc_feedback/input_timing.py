"""What the adaptive law is told of its samples' timing: when a command acts, what a velocity is.

:class:`InputTiming` holds the delay the prior splits the input by, the stencil of positions a
sampled velocity is made of (robot mode's estimate for a driver that sends none), the lags the
model needs for them, and the choice between candidate delays.

Robot mode knows when its command leaves, not when the arm applies it: ros2_control's topic
interface applies a command at the driver's next cycle (one driver period), a drive that adds
a cycle of its own one period later. The prior (Eq. 33 split by the delay, in the sample's
coordinates) places the inputs' effect by that delay; a prior that places it a period early on
a 100 Hz driver loses the arm within a few samples, and the identifier cannot move an effect
between lags fast enough to save it (``test/test_supervisor.py``, a 100 Hz driver with every
command a period late).

:class:`DelayChoice` keeps, for each candidate delay, the prior at the current set point and
scores it every identification step by its one-step prediction of the sampled velocity,

    e_d(k) = r_d(k) - r_d(k-1),   r_d(k) = δv(k) - [F G_d] z(k-1),
    score_d = λ score_d + |e_d|²,

differenced so that what every candidate misses alike and slowly (an unknown payload's
gravity, an inertia error) cancels and what the inputs' timing explains is left. A restart
(a hand-back, a re-activation) takes the candidate whose score is under :data:`MARGIN` of the
current one's, once each has :data:`MIN_STEPS` steps. Plain Python: no rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from apc_feedback.adaptive_config import MAX_INPUT_LAGS, FeedbackError
from apc_feedback.linearize import VelocityStencil, stencil_lags

#: Forgetting of the scores per identification step (a window of about 50 steps).
FORGET = 0.98
#: Steps each candidate needs before a choice.
MIN_STEPS = 10
#: A candidate replaces the current delay when its score is under this fraction of the current's.
MARGIN = 0.5


class DelayChoice:
    """Scores of candidate command delays (s); ``delays`` holds them all (none: no choice).

    The law gives it the prior of each candidate at a start (:meth:`start`) and when the prior
    moves (:meth:`moved`), the current delay's first and then :meth:`others` in order; it
    scores them at every identification step (:meth:`score`) and asks at a restart
    (:meth:`choose`).
    """

    def __init__(self, delays: Sequence[float]) -> None:
        self.delays = tuple(dict.fromkeys(float(d) for d in delays))
        self.scores = dict.fromkeys(self.delays, 0.0)
        self.steps = dict.fromkeys(self.delays, 0)
        self._order: list[float] = []
        self._models: list[np.ndarray] = []
        self._last: list[np.ndarray | None] = []

    @property
    def active(self) -> bool:
        return len(self.delays) > 1

    def others(self, current: float) -> list[float]:
        """The candidates other than ``current``, in their order."""
        return [d for d in self.delays if d != current]

    def start(self, current: float, models: list[np.ndarray]) -> None:
        """A (re)start with ``current``: the priors of ``[current, *others(current)]``; the
        residuals before it are not differenced with the ones after (a gap, a new estimate)."""
        self._order = [current, *self.others(current)] if models else []
        self._models = models
        self._last = [None] * len(models)

    def moved(self, models: list[np.ndarray]) -> None:
        """The priors at the set point the law's prior moved to (same order as at the start)."""
        if models:
            self._models = models

    def score(self, dx: np.ndarray, z: np.ndarray, n: int) -> None:
        """Score each prior by its prediction of ``dx`` (δx(k), velocity rows ``n:``) from
        ``z = (δx(k-1), δu(k-1) … δu(k-1-L))``."""
        for i, model in enumerate(self._models):
            residual = dx[n:] - model[n:] @ z
            last = self._last[i]
            if last is not None:
                change = residual - last
                delay = self._order[i]
                self.scores[delay] = FORGET * self.scores[delay] + float(change @ change)
                self.steps[delay] += 1
            self._last[i] = residual

    def choose(self, current: float) -> float:
        """The delay for a restart: the best-scored candidate when it is clearly better than
        ``current`` and every candidate has been scored enough; else ``current``."""
        if current not in self.scores or min(self.steps.values(), default=0) < MIN_STEPS:
            return current
        best = min(self.delays, key=lambda d: self.scores[d])
        if best != current and self.scores[best] < MARGIN * self.scores[current]:
            return best
        return current


class InputTiming:
    """The delay (s) the prior splits the input by, the sampled velocity's stencil (None:
    measured), and the candidate delays' :class:`DelayChoice`, as of the law's current run.

    What the law is told (:meth:`expect_delay`, :meth:`expect_stencil`) takes effect at its next
    (re)start (:meth:`begin`): within a run the prior the estimate moves with keeps the timing it
    started with.
    """

    def __init__(self, delay: float) -> None:
        self.delay = float(delay)
        self.stencil: VelocityStencil | None = None
        self.choice = DelayChoice(())
        self.exact = False  # the delay is measured (its split held), not assumed
        self._told_delay: tuple[float, tuple[float, ...], bool] | None = None
        self._told_stencil: tuple[VelocityStencil | None] | None = None

    def expect_delay(
        self, seconds: float, candidates: Sequence[float] = (), exact: bool = False
    ) -> None:
        """``seconds`` from the next (re)start; ``candidates`` scored beside it (the same
        candidates as before keep their scores); ``exact``: measured, not assumed."""
        for value in (seconds, *candidates):
            if not (math.isfinite(value) and value >= 0.0):
                raise FeedbackError(f"input delay must be finite and >= 0 s, got {value}")
        self._told_delay = (float(seconds), tuple(float(c) for c in candidates), exact)

    def expect_stencil(self, stencil: VelocityStencil | None) -> None:
        """``stencil`` from the next (re)start."""
        if stencil is not None and (
            len(stencil.offsets) != len(stencil.weights)
            or not all(math.isfinite(s) and s >= 0.0 for s in stencil.offsets)
            or not all(math.isfinite(w) for w in stencil.weights)
        ):
            raise FeedbackError(
                f"velocity stencil must pair finite offsets >= 0 with finite weights, got {stencil}"
            )
        self._told_stencil = (stencil,)

    def begin(self, choose: bool) -> None:
        """At a (re)start: take what was told since the last one and, with ``choose``, the
        candidate delay that predicts the arm clearly best."""
        if self._told_delay is not None:
            seconds, candidates, self.exact = self._told_delay
            self.delay = seconds
            choice = DelayChoice((seconds, *candidates) if candidates else ())
            if choice.delays != self.choice.delays:
                self.choice = choice
            self._told_delay = None
        if self._told_stencil is not None:
            self.stencil = self._told_stencil[0]
            self._told_stencil = None
        if choose:
            self.delay = self.choice.choose(self.delay)

    def lags(self, configured: int, period: float) -> int:
        """The lags the model carries: the configured ones, or more (up to
        :data:`MAX_INPUT_LAGS`) where the samples' timing needs them: a velocity estimated over
        two periods of a 100 Hz driver whose command acts a period late needs three
        (:func:`apc_feedback.linearize.stencil_lags`). None without lags (Eq. 16)."""
        if not configured or self.stencil is None:
            return configured
        return min(MAX_INPUT_LAGS, max(configured, self.needed_lags(period)))

    def needed_lags(self, period: float) -> int:
        """The lags the exact model of a sample needs (more than :data:`MAX_INPUT_LAGS`: the
        oldest inputs are folded into the last lag carried)."""
        return stencil_lags(self.stencil, period, self.delay)

    def holds_split(self, lags: int, period: float) -> bool:
        """Whether ``Ĝ(0)``'s split between the ``lags`` carried is held: the delay is measured
        and the model carries every lag it needs (a folded split is no measured one)."""
        return self.exact and self.needed_lags(period) <= lags

    def candidates(
        self, prior: np.ndarray, with_delay: Callable[[float], np.ndarray]
    ) -> list[np.ndarray]:
        """``prior`` (the current delay's, just made) and, by ``with_delay``, the same set
        point's prior for each other candidate (none without candidates)."""
        if not self.choice.active:
            return []
        return [prior] + [with_delay(d) for d in self.choice.others(self.delay)]
