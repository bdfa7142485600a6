"""Settings of the adaptive law (:class:`AdaptiveConfig`), checked once, and the error every
feedback law raises for a bad setting or input. Plain Python, no ROS."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from apc_core.params import SettingError, check_settings, setting, settings_from
from apc_core.robot import PAPER_PERIOD_S
from apc_feedback.rls import RlsConfig, RlsError

__all__ = ["AdaptiveConfig", "FeedbackError"]


class FeedbackError(SettingError):
    """Bad feedback configuration or input; ``field`` names a bad setting."""


#: The most delayed inputs a model carries (``input_lags``; robot mode's timing may ask for them).
MAX_INPUT_LAGS = 3


#: ``split_prior`` for a delay known exactly (the physical preset's, and robot mode's where the
#: driver's effort shows when a command is applied): the lags' split held, the total learnt.
HELD_SPLIT_PRIOR = 1e-6


@dataclass(frozen=True)
class AdaptiveConfig:
    """Settings of the adaptive perturbation controller (paper values by default).

    Attributes
    ----------
    period : float
        Sampling period T (s), for Eq. 33.
    q_position, q_velocity : float
        ``Q = diag(q_position I_n, q_velocity I_n)`` of Eq. 34 (paper: ``Q = 0.1 I_6``).
    r : float
        ``R = r I_n`` of Eq. 34 (paper: ``1e-6``).
    rho, alpha, forgetting :
        RLS settings (:class:`apc_feedback.rls.RlsConfig`); paper: rho = 0.95,
        alpha = 1500 (P1) or 150000 (P2).
    alpha_model : float
        ``P(0)`` of the regressor rows that carry ``δx`` and ``δu``, the prior on ``F̂(0),
        Ĝ(0)`` of Eq. 33 (``P(0) = diag(alpha_model I_3n, alpha)``; ``alpha`` then applies
        to ``ŵ`` alone). 0 (default): ``alpha`` everywhere, Eq. 32. With the paper's large
        ``alpha`` the first samples of a hold decide ``F̂`` and ``Ĝ`` alone, and one that
        does not follow Eq. 16 (a command applied a few ms late) makes ``Ĝ``'s velocity block
        indefinite within two samples (``apc_feedback.rls`` says more).
    trace_max : float
        Wind-up guard, an upper bound on ``trace(P)``. ``0`` (default) means
        ``trace(P(0))``: never less certain than at the start (with ``alpha_model``, each
        block of ``P`` within its own trace at ``P(0)``). A negative value
        disables the guard (the paper's RLS). Without it a long hold winds ``trace(P)`` up
        until ``P`` loses definiteness (``bench/trace_guard.py``; docs/model.md).
    control_form : {"exact", "printed"}
        Eq. 35: exact minimiser ``-(R + GᵀQG)⁻¹GᵀQ(F x + w)`` or as printed
        ``-(R + GᵀQG)⁻¹GᵀQF(x + w)``.
    initial_model : {"corrected", "printed"}
        Eq. 33b series with ``T²/2, T³/6`` (corrected) or as printed.
    identify_with : {"applied", "commanded"}
        Which ``du(k-1)`` enters the regressor ``z(k-1)``: the torque the plant reports it
        applied minus ``u_n(k-1)`` (right under saturation), or the commanded ``du(k-1)``.
    horizon : int
        Steps N of the optimal control over the identified model; 1 is the paper's one-step
        law (Eq. 34), N > 1 the receding-horizon generalisation
        (:func:`apc_feedback.optimal.receding_horizon_control`).
    q_integral : float
        Weight of the integrated position error ``ξ(k+1) = ξ(k) + T δq(k+1)`` added to the
        state of the cost (integral action); 0 (default) = off, the paper's law.
    integral_limit : float
        Anti-windup bound on each ``|ξ_i|`` (rad s).
    project_g : bool
        Refuse (take back) an RLS update that makes a diagonal entry of ``Ĝ``'s velocity block
        (``≈ T (D(q)⁻¹)_ii``, positive for any arm) non-positive: a projection onto physically
        possible models. Without it a sudden load (a payload picked up) lets one
        large-residual step flip the sign of ``Ĝ`` and the law pushes the wrong way at full
        torque (docs/paper.md, the pickup run). Off in the paper.
    input_lags : {0, 1, 2, 3}
        Delayed inputs the identified model carries: ``δx(k+1) = F δx(k) + G₀ δu(k) + G₁
        δu(k-1) + … + G_L δu(k-L) + w``, the exact zero-order-hold model of an input applied
        up to ``L`` periods after its sample (a driver that writes a command at its next cycle,
        a drive that adds a cycle, a velocity differenced over a period). All ``G_j`` are
        identified; ``Ĝ(0)`` is Eq. 33's ``G`` split by ``input_delay``
        (:func:`apc_feedback.linearize.split_input_matrix`), and in robot mode with a driver
        that sends no velocity the model of a sample whose velocity is estimated from positions
        (:func:`apc_feedback.linearize.sampled_coordinates`); where that timing needs more lags
        (on a 100 Hz driver the estimate spans two periods and the command acts one period late:
        three) the model carries more, up to :data:`MAX_INPUT_LAGS`; the control plans over
        ``(δx(k), δu(k-1), …, δu(k-L))`` with ``horizon + L`` steps. 0 (default): Eq. 16.
    input_delay : float
        The delay (s) from a sample to the arm applying its command that ``Ĝ(0)`` is split by
        (with ``input_lags``); robot mode measures it (:meth:`AdaptiveFeedback.expect_input_delay`).
    split_prior : float
        How sure ``P(0)`` is of that split, relative to ``alpha_model`` (with ``input_lags`` and
        ``alpha_model``): the input rows' block of ``P(0)`` is ``alpha_model (c cᵀ +
        split_prior (I - c cᵀ)) ⊗ I_n``, ``c`` the unit vector of the lags' shares of ``Ĝ(0)``.
        1 (default): every ``Ĝ_j`` identified alike, the split learnt (robot mode, which knows
        the delay only to a driver period); small: the split held where ``input_delay`` puts
        it and only the total learnt (a delay known exactly; closed-loop data let the lags
        trade effect between them: docs/paper.md, "What a physical arm adds").
    relinearize : bool
        The model's prior follows the set point: every sample, Eq. 33 at that sample's
        ``(q_d, qd_d, u_n)`` (split by the delay as ``Ĝ(0)``), and the RLS estimate is kept as a
        deviation from it (moved by the prior's change, ``P`` and ``ŵ`` kept). The RLS then
        learns what the controller's model lacks (payload, inertia error, delay), not how the
        arm's inertia changes along a move: a light arm whose mass matrix changes by a factor
        within a move (the Panda's joints 1 and 3 line up as joint 2 crosses 0) otherwise
        outruns the identifier and the law over-corrects. ``Ĝ`` moves with its prior in input
        space (a relative error, such as a payload's, keeps its proportion), ``project_g``
        refuses steps that would leave its velocity block's diagonal under a tenth of the
        prior's, and the supervisor's
        input-gain region is taken around the current set point's prior. False (default): the
        paper's prior, Eq. 33 at the first nominal point only.
    identify_min_speed : float
        No identification step while a joint's measured speed is below this at ``k-1`` or
        ``k`` (rad/s): a dead zone for a joint that sticks (Coulomb friction), through which
        a torque moves nothing and the identifier would learn ``Ĝ_ii -> 0``, and the optimal
        control ``~ Ĝ⁻¹`` command the torque limit. 0 (default): always identify (the paper).
    q_input_change : float
        Weight of the planned input's change from one step of the horizon to the next, on the
        velocity it makes: ``q_input_change |Ĝv (δu(j) - δu(j-1))|²``, ``Ĝv`` the velocity
        block of the identified input matrix summed over the lags (≈ T D⁻¹), in the units of
        ``q_velocity``: generalised predictive control's move suppression. With two input
        lags or more (the planned state then holds the last two inputs); settable at run
        time. Sampled positions do not see an input alternating from sample to sample (the
        zero-order hold's sampling zero at z = -1), and without this weight the receding
        horizon's cheap position weight leaves the law's own inputs ringing at the Nyquist
        frequency (:mod:`apc_feedback.lagged_control`). 0 (default): none (the paper).
    input_ring_limit : float
        Bound on the spectral radius of the plan's own dynamics over its inputs on their way
        (:func:`apc_feedback.lagged_control.input_ringing`: what the law's commands do while
        the arm does not answer them). At each (re)start and every ``RING_CHECK_PERIOD_S``
        the law doubles the weight of the input's change until the radius is within it, up
        to ``2**MAX_RING_DOUBLINGS`` times ``q_input_change`` (no effect while that is 0); a
        reset returns to ``q_input_change``. 0 (default): never checked.
    """

    period: float = PAPER_PERIOD_S
    q_position: float = setting(
        0.1,
        "Q weight of the position error, Eq. 34 (1/rad^2); settable at run time",
        0.0,
        1e12,
        runtime=True,
    )
    q_velocity: float = setting(
        0.1, "Q weight of the velocity error, Eq. 34; settable at run time", 0.0, 1e12, runtime=True
    )
    r: float = setting(
        1e-6,
        "R weight of the torque, Eq. 34 (1/(N m)^2), > 0; settable at run time",
        1e-15,
        1e12,
        runtime=True,
    )
    rho: float = setting(0.95, "RLS forgetting factor rho, Eqs. 29-31; 0 < rho <= 1", 1e-6, 1.0)
    alpha: float = setting(1.5e5, "P(0) = alpha I, Eq. 32", 1e-12, 1e15)
    alpha_model: float = setting(
        0.0,
        "P(0) of the F and G rows (the prior on Eq. 33's model); 0 = alpha (Eq. 32)",
        0.0,
        1e15,
    )
    forgetting: Literal["exponential", "printed"] = setting(
        "exponential",
        "Eq. 30: 'exponential' (P divided by rho) or 'printed' (as printed, never forgets)",
    )
    trace_max: float = setting(
        0.0,
        "RLS wind-up guard, bound on trace(P): 0 = trace(P(0)) = alpha (3n+1); < 0 = off",
        -1.0,
        1e30,
    )
    control_form: Literal["exact", "printed"] = setting(
        "exact", "Eq. 35: 'exact' minimiser -(R+G'QG)^-1 G'Q(F x + w) or 'printed' G'QF(x + w)"
    )
    initial_model: Literal["corrected", "printed"] = setting(
        "corrected", "Eq. 33b series: 'corrected' (T^2/2, T^3/6) or 'printed' (T^2, T^3/2)"
    )
    identify_with: Literal["applied", "commanded"] = setting(
        "applied",
        "du(k-1) in the regressor: 'applied' (joint_states effort - u_n) or 'commanded'",
    )
    horizon: int = setting(
        1,
        "steps N of the optimal control over the identified model; 1 = the paper's Eq. 34",
        1,
        200,
    )
    q_integral: float = setting(
        0.0,
        "weight of the integrated position error (integral action); 0 = off (the paper)",
        0.0,
        1e15,
    )
    integral_limit: float = setting(0.05, "anti-windup bound on the integral (rad s)", 1e-9, 1e3)
    project_g: bool = setting(
        False,
        "refuse RLS steps that make G's velocity block (~T D^-1) indefinite; put the jump in w",
    )
    input_lags: int = setting(
        0,
        "delayed inputs the identified model carries (G_1 du(k-1) ... G_L du(k-L)); 0 = Eq. 16",
        0,
        MAX_INPUT_LAGS,
    )
    input_delay: float = setting(
        0.0, "delay (s) from a sample to its command's application that splits G(0)", 0.0, 1.0
    )
    split_prior: float = setting(
        1.0,
        "P(0) of the lags' split relative to alpha_model: 1 = learnt, small = held",
        1e-12,
        1.0,
    )
    relinearize: bool = setting(
        False,
        "the model's prior follows the set point (Eq. 33 each sample, RLS learns the deviation)",
    )
    identify_min_speed: float = setting(
        0.0, "no identification step while a joint is slower than this (rad/s); 0 = off", 0.0, 1e3
    )
    q_input_change: float = setting(
        0.0,
        "weight of the planned torque's change per sample, on the velocity it makes (2+ lags)",
        0.0,
        1e12,
        runtime=True,
    )
    input_ring_limit: float = setting(
        0.0,
        "spectral radius bound of the law's own inputs while the arm does not answer; "
        "q_input_change is doubled until met (2+ lags; 0 = off)",
        0.0,
        1e3,
        runtime=True,
    )

    def __post_init__(self) -> None:
        if not (np.isfinite(self.period) and self.period > 0.0):
            raise FeedbackError(f"period must be > 0 s, got {self.period}", field="period")
        check_settings(self, FeedbackError)
        for name, choices in (
            ("forgetting", ("exponential", "printed")),
            ("control_form", ("exact", "printed")),
            ("initial_model", ("corrected", "printed")),
            ("identify_with", ("applied", "commanded")),
        ):
            value = getattr(self, name)
            if value not in choices:
                either = " or ".join(map(repr, choices))
                raise FeedbackError(f"{name} must be {either}, got {value!r}", field=name)
        try:
            self.rls_config()
        except RlsError as exc:
            raise FeedbackError(str(exc)) from None

    def rls_config(self, n_joints: int = 1) -> RlsConfig:
        """The identifier's settings for an arm of ``n_joints`` (resolves ``trace_max``)."""
        alpha_model = self.alpha_model if self.alpha_model > 0.0 else None
        if self.trace_max < 0.0:
            trace_max = None
        elif self.trace_max == 0.0:
            # trace(P(0)), as a product where alpha is all of it (its rounding)
            m = (3 + self.input_lags) * n_joints
            if alpha_model is None:
                trace_max = self.alpha * (m + 1)
            else:
                trace_max = self.alpha + m * alpha_model
        else:
            trace_max = self.trace_max
        return RlsConfig(
            rho=self.rho,
            alpha=self.alpha,
            forgetting=self.forgetting,
            trace_max=trace_max,
            alpha_model=alpha_model,
        )

    def initial_p(self, G0: np.ndarray, n_joints: int, held: bool) -> np.ndarray | None:
        """``P(0)`` with the input block of ``split_prior`` for the prior ``G0`` (2n, (L+1) n)
        (None: the identifier's own); ``held``: a delay measured exactly, with every lag it
        needs carried, holds the split (:data:`HELD_SPLIT_PRIOR`)."""
        n, lags = n_joints, self.input_lags
        split_prior = HELD_SPLIT_PRIOR if held else self.split_prior
        if not lags or split_prior == 1.0 or self.alpha_model <= 0.0:
            return None
        shares = np.linalg.norm(G0[n:].reshape(n, lags + 1, n), axis=(0, 2))
        c = shares / np.linalg.norm(shares)
        split = np.outer(c, c) + split_prior * (np.eye(lags + 1) - np.outer(c, c))
        P0 = np.diag(self.rls_config(n).initial_p_diagonal(n, lags))
        P0[2 * n : -1, 2 * n : -1] = self.alpha_model * np.kron(split, np.eye(n))
        return P0

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> AdaptiveConfig:
        """Build from a plain mapping; an unknown key is rejected with its name."""
        return settings_from(AdaptiveConfig, values, FeedbackError, "adaptive-controller parameter")
