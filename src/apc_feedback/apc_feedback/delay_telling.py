"""Which delay robot mode tells the adaptive law, and when it tells another one.

The driver's effort shows when the arm applies a command (:class:`~apc_feedback.command_echo.
CommandEcho`); the law models the delay it is told (its input lags split by it). Told:

- a delay of a whole sample or more (the sample's own command cannot act before the next
  sample, which a split learnt from closed-loop data fills with a channel the plan leans on);
- a delay where every kept echo is at most half a driver period (applied over its state's own
  cycle: a lockstep simulator, where Eq. 16 holds as it stands and the driver period the law
  would assume is a whole sample too late on a slow driver);
- a steady delay under a sample where the samples' velocity is the arm's own (the states have
  shown it is no difference of positions: the delay's split is then the exact model of the
  sample; assumed, with the drive's extra cycle at 250 Hz, the law lost the Panda in every
  run). Steady: a full window of echoes agrees (:meth:`CommandEcho.steady`), and once told
  the delay stays told while the echo measures it, so that a command late now and then does
  not restart the law twice.

Else none: the law assumes a driver period and scores two. A delay longer than the lags the
law carries with the samples' velocity can hold is told as the longest they hold
(:meth:`DelayTelling.carried_ns`: ``MAX_INPUT_LAGS`` samples less the velocity's span) where
that reaches two driver periods, the longest the law would otherwise score; else none, the
law scoring one and two. Of what the law can be told, that is nearest to when the arm
applies the command. A burst of late commands at activation on the physical Panda at 100 Hz
has commands act 30 ms after their state, which with the drive's differenced velocity needs
four lags: told none, the 10 ms driver period with 20 ms scored, at the restart that
velocity brings, the law diverged before a restart could take the better score and was
handed over (the computed-torque fallback, its gains set for 10 ms, then swung the arm up
to 9 deg in such runs); told 20 ms it holds (docs/robot.md, "A burst of late commands at
activation"). Robot mode's own velocity estimate on a positions-only 100 Hz driver spans
20 ms, so there the lags hold only 10 ms and none is told: scoring 20 ms is what holds the
PUMA whose every command is a period late.

A told delay is told again when the one robot mode would tell now differs from it by half a
driver period or more. A longer one only once it has lasted :data:`RETELL_S`: a machine whose
commands run late for a while (a burst of scheduling delay, a garbage collection) makes the
echo show a cycle more for a window and then the old delay again, and a law told each of them
restarts two or three times within a few samples, which lost the Panda on wall time
(docs/robot.md, "When the arm applies a command"); lateness only adds to what the driver
always takes. A shorter one at once: the delay the driver takes showing again after a
longer one was told (held 0.5 s on a 12 ms model where commands acted after 8 ms, the
physical Panda at 250 Hz with 30 % of its commands late was lost in one run of five); and a
first measurement, where the law assumed a driver period. With the arm's own velocity, none in
place of a told delay (a delay under a sample whose echoes do not agree) waits a window of
echoes (:data:`~apc_feedback.command_echo.ECHOES` samples): a burst of late commands from
activation has a whole sample or more told at once (12 ms on the Panda at 250 Hz), and while
the echoes move to what the driver always takes (8 ms) they disagree until the burst's tail
has left their window; told none at once there, the law restarted on the driver period and
then on 8 ms within a few samples and lost the arm alone (13-79 deg). With a differenced
velocity none is what a jittering delay under a sample is told for good, and it is told at
once (held a window, the physical Panda at 250 Hz with 30 % of its commands late, told 12 ms
at activation, was lost in one run of five). None where the echo shows a longer delay than
the told one waits as a longer delay does; a wait of another kind than the one under way
starts its count afresh. Every
(re)start of the law tells it the delay measured then, longer or not (an activation, a
fault's recovery, an abort, a velocity of another kind). Plain Python: no rclpy.
"""

from __future__ import annotations

from apc_feedback.adaptive_config import MAX_INPUT_LAGS
from apc_feedback.command_echo import ECHOES, CommandEcho
from apc_feedback.linearize import VelocityStencil, stencil_lags, stencil_span
from apc_feedback.robot_sampling import RobotSampler

#: How long a told delay must be measured otherwise before it is told again (s).
RETELL_S = 0.5


class DelayTelling:
    """The delay told to the law (:attr:`told_ns`, None: a driver period assumed) for samples
    ``period_ns`` apart, from ``echo`` and ``sampler``; :meth:`moved` each sample,
    :meth:`tell` at each (re)start of the law."""

    def __init__(self, echo: CommandEcho, sampler: RobotSampler, period_ns: int) -> None:
        self.echo, self.sampler, self.period_ns = echo, sampler, period_ns
        self.retell_samples = round(RETELL_S * 1e9 / period_ns)
        # Samples echoes that disagree wait before none replaces a told delay (a window of them).
        self.disagree_samples = ECHOES
        self.told_ns: int | None = None
        # The sample from which the delay to tell has differed from the one told, and the kind
        # of wait it is in ("longer", "disagree"); the last sample judged (a gap in the samples
        # starts the count again).
        self._waiting: tuple[int, str] | None = None
        self._last_k: int | None = None

    def tell(self) -> int | None:
        """The delay to tell the law at its (re)start, now told (ns; None: a driver period)."""
        self.told_ns = self.measured_ns()
        self._waiting = None
        return self.told_ns

    def measured_ns(self) -> int | None:
        """The delay robot mode would tell now (module docstring), else None."""
        echo, sampler = self.echo, self.sampler
        measured, longest = echo.delay_ns, echo.longest_ns
        if measured is None or longest is None:
            return None
        period = sampler.driver_period_ns
        if (
            measured < self.period_ns
            and 2 * longest > period
            and not (
                sampler.velocity_is_the_arms() and (echo.steady(period) or self.told_ns == measured)
            )
        ):
            return None
        stencil = sampler.velocity_stencil()
        needed = stencil_lags(stencil, self.period_ns * 1e-9, measured * 1e-9)
        if needed <= MAX_INPUT_LAGS:
            return measured
        carried = self.carried_ns(stencil)
        return carried if carried >= 2 * sampler.driver_period_ns else None

    def carried_ns(self, stencil: VelocityStencil | None) -> int:
        """The longest delay the law's lags hold with samples whose velocity is ``stencil``
        (ns): ``MAX_INPUT_LAGS`` samples less the stencil's span."""
        return max(0, MAX_INPUT_LAGS * self.period_ns - round(stencil_span(stencil) * 1e9))

    def moved(self, k: int) -> bool:
        """Whether at sample ``k`` the delay to tell differs from the one told (the measured one,
        else the driver period) by half a driver period or more: at once where none was
        measured when the law was told or where a shorter one is measured, a longer one after
        :data:`RETELL_S` of it (also none where the echo shows a longer delay than the told
        one), none where echoes under the
        told delay disagree with the arm's velocity after :attr:`disagree_samples`, else at
        once. A wait of another kind starts its count afresh."""
        last, self._last_k = self._last_k, k
        if last is None or k != last + 1:
            self._waiting = None
        echo = self.echo
        if echo.delay_ns is None:
            self._waiting = None
            return False
        period = self.sampler.driver_period_ns
        measured, told_ns = self.measured_ns(), self.told_ns
        if told_ns is None:  # a first measurement: at once
            return measured is not None and 2 * abs(measured - period) >= period
        now = period if measured is None else measured
        if 2 * abs(now - told_ns) < period:
            self._waiting = None
            return False
        if (echo.delay_ns if measured is None else measured) > told_ns:
            kind, wait = "longer", self.retell_samples
        elif measured is None and self.sampler.velocity_is_the_arms():
            kind, wait = "disagree", self.disagree_samples  # a burst's tail leaving the window
        else:
            return True  # a shorter delay, or none for a differenced velocity: at once
        if self._waiting is None or self._waiting[1] != kind:
            self._waiting = (k, kind)
        return k - self._waiting[0] >= wait
