"""Robot mode's supervisor: which law commands the joints, the adaptive one or a fallback.

The adaptive law identifies its model from the arm's answers; a command that lands a fraction
of a period (or more) after the state it was computed from breaks Eq. 16's timing, the model
can go wrong and Eq. 35 then drives the arm to its limits. :class:`Supervisor` watches the
adaptive law's samples and trips, handing the joints to a fallback law (computed torque:
bounded on every arm measured), on the first of these triggers, each named:

- ``tracking_error``: ``|q - q_d|`` on a joint beyond ``error_bound`` *and* larger than it
  was ``error_growth_samples`` samples before, its rate ``|qd - qd_d|`` not smaller: an error
  growing, not a constant offset nor an arm being brought to rest (a hold started on an arm
  still sagging after a watchdog gap overshoots while the law stops it). The error is
  judged when a command computed now can act: ``error_lead`` (2) driver periods ahead at its
  rate, ``|q - q_d + lead (qd - qd_d)|``, once the loop has told the driver period
  (:meth:`Supervisor.expect_command_delay`): the fallback's first command acts that much
  later, and a law diverging on a slow driver with a late command has the joint moving fast by
  the time the error shows (docs/robot.md, "Never lose the arm"). One
  bound for holds and moves, not a fraction of the path tolerance: a tolerance set tight on
  purpose (to abort a goal the arm cannot follow) would make it fire on a law that is fine;
  a joint beyond its path tolerance while moving hands over anyway (the loop's abort);
- ``input_gain``: the identified input gain's velocity block ``Ĝ_v`` (rows n..2n of
  ``law.identified_input_gain``, ≈ ``T D⁻¹``) leaving a region around the model's ``Ĝ_v(0)``
  (``law.prior_input_gain``, Eq. 33): a diagonal entry of the wrong sign or at or above
  ``gain_high`` times its prior; with some joint beyond ``suspicion_error`` also one at or
  below ``gain_low`` times it, or ``Ĝ_v(0)⁻¹ Ĝ_v`` pushing some direction the wrong way (its
  symmetric part's eigenvalue at or below ``-gain_wrong_way``, whatever the joints' scales);
- ``residual``: the norm of the RLS residual (Eq. 26) beyond ``residual_floor`` and
  ``residual_factor`` times its running mean (an exponential mean over ``residual_window``),
  with some joint beyond ``suspicion_error``;
- ``saturation``: the law's command clipped at the effort limit ``saturation_samples``
  samples in a row, with some joint beyond ``suspicion_error``.

Up to ``error_growth_samples`` samples missing between two of the law's (states lost, or
overtaken by the next sample's) do not clear the error's growth or the clipped run; a longer
gap does.

A residual, a clipped command or a model passing through an odd region while the arm is on its
path is no loss of it (a physical arm's move start does all three while the law tracks, and the
fallback in its place costs more), so those wait for the error.

A law that loses the arm again after each hand-back is not handed it any more: after
``failed_handbacks`` (2) hand-backs in a row each followed by a hand-over within 20 settle times,
the fallback keeps the joints (``latched``) until the node is configured again (a new
supervisor): a law that cannot hold this arm on this driver (a 100 Hz driver with every command
a period late) would otherwise be handed it again and again, each time costing an excursion.

While the fallback is in charge the supervisor waits for the error to settle (every joint
within ``settle_error`` for ``settle_time``, and its error moving at a mean rate of at most
``settle_rate`` over the last ``settle_time``: the sum of its changes from sample to sample
there, the distance it travelled, within ``settle_rate`` times ``settle_time``) and then hands
the joints back. The rate is judged from the positions at the samples, not from the states'
velocity: a drive's velocity differenced over one cycle of a quantised encoder flickers by a
count per cycle (2^16 counts a revolution: 0.024 rad/s at 250 Hz, 0.096 rad/s at 1 kHz,
beyond ``settle_rate``), and judged sample by sample the fallback never handed the physical
Panda back; a count each sample T = 10 ms apart is 0.0096 rad/s. The distance travelled, not
the spread, so that an error ringing within a small band (at the Nyquist frequency, say) is
not settled either. Settled, not small: the
fallback does not know a payload and holds it with a steady offset, which the adaptive law,
once back, removes.
The caller (:class:`~apc_feedback.robot_loop.RobotLoop`) resets the adaptive law when it trips,
so identification restarts from Eq. 33.

The fallback is computed torque, the one law bounded on every arm of the robot comparison, with
a double pole at -30 rad/s (``Kp = 900``, ``Kv = 60``), slowed on slow drivers
(:func:`fallback_gains`). The defaults (bounds, factors, gains) and the runs that chose them are
in docs/robot.md, "The supervisor's defaults".
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from apc_core.params import SettingError, check_settings, setting, settings_from
from apc_core.robot import Robot
from apc_feedback.arrays import any_true
from apc_feedback.baselines import PdGains
from apc_feedback.feedback_law import FeedbackLaw
from apc_feedback.laws import make_law

#: The triggers, in the order they are checked; each is counted as ``supervisor.<trigger>``.
TRIGGERS: tuple[str, ...] = ("tracking_error", "input_gain", "residual", "saturation")
#: The fallback laws offered (by their names in :data:`apc_feedback.laws.LAWS`).
FALLBACKS: tuple[str, ...] = ("computed_torque", "pid")
ADAPTIVE, FALLBACK = "adaptive", "fallback"


class SupervisorError(SettingError):
    """A bad supervisor setting; ``field`` names it."""


@dataclass(frozen=True)
class SupervisorConfig:
    """The supervisor's settings (see the module docstring for how the defaults were chosen)."""

    enable: bool = setting(
        True, "supervise the adaptive law: a fallback law takes the joints when it goes wrong"
    )
    fallback: str = setting(
        "computed_torque",
        f"law that holds the arm when the supervisor trips: one of {', '.join(FALLBACKS)}",
    )
    kp: float = setting(
        900.0,
        "computed-torque fallback's Kp (1/s^2); pid takes the pid.* parameters",
        0.0,
        1e9,
    )
    kv: float = setting(60.0, "computed-torque fallback's Kv (1/s)", 0.0, 1e9)
    error_bound: float = setting(
        0.07,
        "tracking_error trigger: |q - q_d| bound (rad) on every joint, with the error growing",
        1e-6,
        10.0,
    )
    suspicion_error: float = setting(
        0.03,
        "residual and saturation trip only with some |q - q_d| beyond this (rad)",
        0.0,
        10.0,
    )
    error_growth_samples: int = setting(
        3,
        "tracking_error trigger: the error must exceed its value this many samples before",
        1,
        100,
    )
    gain_low: float = setting(
        0.05,
        "input_gain trigger: a diagonal entry of G's velocity block at or below this fraction "
        "of Eq. 33's",
        0.0,
        1.0,
    )
    gain_high: float = setting(
        2.0,
        "input_gain trigger: a diagonal entry of G's velocity block at or above this multiple "
        "of Eq. 33's",
        1.0,
        1e6,
    )
    gain_wrong_way: float = setting(
        0.25,
        "input_gain trigger: G's velocity block relative to Eq. 33's pushes some direction the "
        "wrong way by this fraction (the relative symmetric part's eigenvalue <= -this)",
        0.0,
        1e6,
    )
    residual_floor: float = setting(
        2.0, "residual trigger: RLS residual norm beyond this (and the factor)", 0.0, 1e12
    )
    residual_factor: float = setting(
        10.0, "residual trigger: residual norm beyond this multiple of its running mean", 1.0, 1e12
    )
    residual_window: float = setting(
        0.5, "residual trigger: time constant of the residual's running mean (s)", 1e-3, 1e3
    )
    saturation_samples: int = setting(
        3,
        "saturation trigger: commands clipped at the effort limit this many samples in a row",
        1,
        10000,
    )
    fallback_bandwidth: float = setting(
        0.2,
        "computed-torque fallback: its natural frequency at most this over the driver period "
        "(rad), Kp and Kv lowered together",
        1e-3,
        100.0,
    )
    settle_error: float = setting(
        0.15,
        "hand-back: every |q - q_d| within this (rad) for settle_time gives the adaptive law the "
        "joints again",
        1e-6,
        10.0,
    )
    settle_rate: float = setting(
        0.02,
        "hand-back: every joint's q - q_d moving at a mean rate of at most this (rad/s) over "
        "the last settle_time as well (the distance it travels there, judged at the samples)",
        1e-6,
        100.0,
    )
    settle_time: float = setting(
        0.5,
        "hand-back: how long the error must stay within settle_error (s); doubled at each "
        "hand-over that follows a hand-back within 20 times this, up to 64 times",
        0.0,
        1e4,
    )
    failed_handbacks: int = setting(
        2,
        "latch: after this many hand-backs in a row each followed by a hand-over within 20 "
        "settle times, the fallback keeps the joints until the node is configured again",
        1,
        1000,
    )
    approach_time: float = setting(
        0.5,
        "hand-back: the law takes the joints at the next sample and the plan (hold or motion) "
        "is rejoined from the measured state over this (s); 0: the law takes the fallback's "
        "error at once",
        0.0,
        60.0,
    )
    error_lead: float = setting(
        2.0,
        "tracking_error trigger: judge q - q_d + lead (qd - qd_d), the error when a fallback's "
        "command can act, lead this many driver periods (the delay the loop tells; 0: off)",
        0.0,
        100.0,
    )

    def __post_init__(self) -> None:
        check_settings(self, SupervisorError)
        if self.fallback not in FALLBACKS:
            raise SupervisorError(
                f"fallback must be one of {', '.join(FALLBACKS)}, got {self.fallback!r}",
                field="fallback",
            )
        if self.gain_low >= self.gain_high:
            raise SupervisorError(
                f"gain_low must be below gain_high ({self.gain_high}), got {self.gain_low}",
                field="gain_low",
            )

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> SupervisorConfig:
        return settings_from(SupervisorConfig, values, SupervisorError, "supervisor parameter")


class Supervisor:
    """Who commands the joints, sample by sample (see the module docstring).

    Told the sample index ``k`` (period ``period`` s), never a clock.

    Parameters
    ----------
    config : SupervisorConfig
    n_joints : int
    period : float
        Sample period T (s).
    """

    def __init__(self, config: SupervisorConfig, n_joints: int, period: float) -> None:
        self.config = config
        self.n_joints = n_joints
        self.bound = np.full(n_joints, config.error_bound)
        self._settle_samples = round(config.settle_time / period)
        # The hand-back's rate: how far the error travels over this many sample intervals.
        self._rate_window = max(1, self._settle_samples)
        self._travel = config.settle_rate * self._rate_window * period
        self._streak = 0  # hand-overs, each within 20 settle times of the hand-back before
        self._handback_k: int | None = None
        self.latched = False  # the fallback keeps the joints for good (failed_handbacks)
        self._lead = 0.0  # s: error_lead driver periods, once the loop tells the period
        self._decay = min(1.0, period / config.residual_window)
        self.in_charge = ADAPTIVE
        self.reason = ""  # the trigger (or "path_tolerance") of the last hand-over
        self._clear()

    def _clear(self) -> None:
        self._errors: deque[np.ndarray] = deque(maxlen=self.config.error_growth_samples + 1)
        self._k_prev: int | None = None
        self._residual_mean = 0.0
        self._clipped_run = 0
        self._settled_run = 0
        self._settling: deque[np.ndarray] = deque(maxlen=self._rate_window + 1)

    def update(
        self,
        k: int,
        error_q: np.ndarray,
        error_qd: np.ndarray,
        law: Any,
        residual: np.ndarray | None,
        clipped: bool,
    ) -> str | None:
        """Sample ``k`` of the law in charge; returns the event it causes, if any.

        Parameters
        ----------
        k : int
            Sample index.
        error_q, error_qd : (n,) ndarray
            ``q - q_d`` (rad), ``qd - qd_d`` (rad/s).
        law : FeedbackLaw
            The adaptive law (its ``identified_input_gain`` and ``prior_input_gain``, where it
            has them, after this sample's update).
        residual : (2n,) ndarray or None
            The adaptive law's RLS residual of this sample.
        clipped : bool
            The command in charge this sample is clipped at an effort limit on some joint.

        Returns
        -------
        str or None
            While the adaptive law is in charge: the trigger that hands the joints to the
            fallback (one of :data:`TRIGGERS`); while the fallback is: ``"handback"`` when the
            error has settled; else None.
        """
        error = np.abs(error_q)
        ahead = np.abs(error_q + self._lead * error_qd)  # when a fallback's command can act
        if self._k_prev is not None and k != self._k_prev + 1:
            # A few samples missing (states lost, or overtaken by the next sample's: common at
            # 1 kHz on a loaded machine) are bridged while the law commands: cleared at each
            # gap, the growth and the clipped run never filled there, and a law chattering at
            # its limits went unseen (docs/performance.md). A longer gap (a fault, a start)
            # clears them, and a settling fallback starts its count afresh at any gap.
            if not 0 < k - self._k_prev <= self.config.error_growth_samples + 1:
                self._errors.clear()
                self._clipped_run = 0
            self._settled_run = 0
            self._settling.clear()
        self._k_prev = k
        if self.in_charge == FALLBACK:
            if self.latched:
                return None
            within = bool((error <= self.config.settle_error).all())
            self._settled_run = self._settled_run + 1 if within else 0
            self._settling.append(np.array(error_q, dtype=float))
            if self._settled_run > self._settle_samples << min(self._streak, 6) and self._still():
                self.in_charge, self.reason = ADAPTIVE, ""
                self._clear()
                self._handback_k = k
                return "handback"
            return None
        self._errors.append((ahead, np.abs(error_qd)))
        # Every trigger sees every sample (the residual's mean and the clipped run are state);
        # a residual or a clipped run alone is no loss of the arm (a move's start, a payload's
        # jolt): they trip only with the error beyond suspicion_error.
        suspicions = (self._residual(residual), self._saturation(clipped))
        off_path = bool(any_true(error > self.config.suspicion_error))
        trigger = self._tracking_error() or self.input_gain(law, off_path)
        if trigger is None and off_path:
            trigger = next((s for s in suspicions if s is not None), None)
        if trigger is not None:
            self.hand_over(trigger)
        return trigger

    def _still(self) -> bool:
        """Every joint's error travelled at most ``settle_rate`` times ``settle_time`` over the
        last ``settle_time`` (see the module docstring)."""
        settling = self._settling
        if len(settling) < settling.maxlen:
            return False
        travel = np.abs(np.diff(np.array(settling), axis=0)).sum(axis=0)
        return bool((travel <= self._travel).all())

    def expect_command_delay(self, driver_period: float) -> None:
        """The loop's driver period (s): a command computed now acts about two of them later
        (one with a driver that applies it at its next write, two with a drive or a network
        that adds a cycle), so the tracking_error trigger judges the error ``error_lead``
        driver periods ahead. Until told (a bare supervisor), the error as measured."""
        self._lead = self.config.error_lead * max(0.0, driver_period)

    @property
    def dwell(self) -> float:
        """How long (in settle times) the error must now stay settled before a hand-back."""
        return float(1 << min(self._streak, 6))

    def hand_over(self, reason: str) -> None:
        """Give the joints to the fallback (a trigger, or the loop's own reason: a path
        tolerance abort) until the error settles."""
        recent = self._handback_k is not None and (
            self._k_prev is None or self._k_prev - self._handback_k <= 20 * self._settle_samples
        )
        self._streak = self._streak + 1 if recent else 0
        if self._streak >= self.config.failed_handbacks:
            self.latched = True
        self.in_charge, self.reason = FALLBACK, reason
        self._clear()

    # -- the triggers ---------------------------------------------------------------------------
    def _tracking_error(self) -> str | None:
        errors = self._errors
        if len(errors) < errors.maxlen:
            return None
        (e_then, v_then), (e, v) = errors[0], errors[-1]
        if any_true((e > self.bound) & (e > e_then) & (v >= v_then)):
            return "tracking_error"
        return None

    def input_gain(self, law: Any, off_path: bool = True) -> str | None:
        """``"input_gain"`` if ``law``'s identified input gain is outside the region around its
        prior (see the module docstring), else None (also for a law without one).

        A diagonal entry of the wrong sign or ``gain_high`` times its prior is outside the
        region always; one at ``gain_low`` or below, or a direction pushed the wrong way, only
        with the arm ``off_path`` (beyond ``suspicion_error``): identified on a physical arm
        (rotor inertia, a drive's delay, quantised positions) they pass through there while the
        law tracks (figures: docs/robot.md, "The supervisor's defaults").
        """
        prior = getattr(law, "prior_input_gain", None)
        if prior is None:
            return None
        n, config = self.n_joints, self.config
        g0, g = prior[n:], law.identified_input_gain[n:]
        ratio = g.diagonal() / g0.diagonal()
        if any_true(ratio <= 0.0) or any_true(ratio >= config.gain_high):
            return "input_gain"
        if not off_path:
            return None
        if any_true(ratio <= config.gain_low):
            return "input_gain"
        try:
            relative = np.linalg.solve(g0, g)
        except np.linalg.LinAlgError:
            return None  # a singular prior: only the diagonal can be judged
        if np.linalg.eigvalsh(0.5 * (relative + relative.T))[0] <= -config.gain_wrong_way:
            return "input_gain"
        return None

    def _residual(self, residual: np.ndarray | None) -> str | None:
        if residual is None:
            return None
        norm = math.sqrt(float(np.dot(residual, residual)))  # np.linalg.norm's own sum
        mean = self._residual_mean
        self._residual_mean = mean + self._decay * (norm - mean)
        config = self.config
        if norm > config.residual_floor and norm > config.residual_factor * mean:
            return "residual"
        return None

    def _saturation(self, clipped: bool) -> str | None:
        self._clipped_run = self._clipped_run + 1 if clipped else 0
        if self._clipped_run >= self.config.saturation_samples:
            return "saturation"
        return None


def fallback_gains(config: SupervisorConfig, driver_period: float) -> PdGains:
    """Computed torque's gains for a driver of this period (s): ``config.kp``/``kv``, their
    natural frequency lowered to ``fallback_bandwidth / driver_period`` where that is less.

    A command acts a driver period after its state, two with a drive that adds a cycle: on a
    slow driver a light arm is lost at gains a fast one holds, while a softer hold sags more
    under a payload the model does not know. The damping ratio is kept. Figures: docs/robot.md,
    "The supervisor's defaults".
    """
    omega = math.sqrt(config.kp)
    if omega <= 0.0 or driver_period <= 0.0:
        return PdGains(kp=config.kp, kv=config.kv)
    scale = min(1.0, config.fallback_bandwidth / (driver_period * omega))
    return PdGains(kp=config.kp * scale * scale, kv=config.kv * scale)


def fallback_law(
    config: SupervisorConfig,
    robot: Robot,
    period: float,
    pid: Mapping[str, Any] | None = None,
) -> FeedbackLaw:
    """The fallback ``config`` names on the controller's ``robot``: computed torque with
    ``config.kp``/``kv``, or the PID with the settings ``pid`` (:class:`PidGains` fields;
    default: tuned)."""
    if config.fallback == "computed_torque":
        return make_law("computed_torque", robot, period, {"kp": config.kp, "kv": config.kv})
    return make_law("pid", robot, period, pid)
