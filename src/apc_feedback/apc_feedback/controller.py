"""Feedback laws: what the feedback node computes from a joint state and a set point.

Every law answers one question per sample ``k``: given the measured state ``(q, q')(k)``, the
set point ``(q_d, qd_d, qdd_d, u_n)(k)`` and the torque the plant applied over the period that
ended at ``k``, what perturbation torque ``du(k)`` goes to the plant (which applies
``u_n(k) + du(k)``)? Laws hold their own small mutable state (``reset()`` rebuilds it) and are
told the sample index, never a clock.

- :class:`AdaptiveFeedback` — the paper's adaptive perturbation control: RLS identification of
  ``dx(k+1) = F dx(k) + G du(k) + w`` (Eqs. 16, 29-31) and the one-step optimal control of
  Eqs. 34-35, with ``F(0), G(0)`` from Eq. 33 at the first nominal point.
- :mod:`apc_feedback.baselines` — computed torque (Eq. 36), PD, none.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Literal

import numpy as np
import pinocchio as pin

from apc_feedback.linearize import SeriesForm, initial_model
from apc_feedback.optimal import one_step_control, validate_weights
from apc_feedback.rls import Rls, RlsConfig, RlsError


class FeedbackError(ValueError):
    """Bad feedback configuration or input; the message names the parameter."""


@dataclass(frozen=True)
class FeedbackOutput:
    """One sample of a feedback law.

    Attributes
    ----------
    du : (n,) ndarray
        Perturbation torque (N m) for the period starting at ``k``.
    residual : (2n,) ndarray or None
        A-priori RLS residual of Eq. 26 for the step ``k-1 -> k`` (adaptive law only).
    trace_p : float
        ``trace(P)`` after the update (adaptive law only; NaN otherwise).
    rejected : bool
        The identifier refused this sample's update (it would have made P or Θ non-finite or
        P indefinite, which is what covariance wind-up ends in); the previous estimate is kept.
    """

    du: np.ndarray
    residual: np.ndarray | None = None
    trace_p: float = float("nan")
    rejected: bool = False


class FeedbackLaw(ABC):
    """A feedback law of the feedback node (see module docstring)."""

    kind: str = ""

    def __init__(self, n_joints: int) -> None:
        self.n_joints = n_joints

    @abstractmethod
    def reset(self) -> None:
        """Forget all state; the next :meth:`update` is treated as the first sample."""

    @abstractmethod
    def update(
        self,
        k: int,
        q: np.ndarray,
        qd: np.ndarray,
        q_d: np.ndarray,
        qd_d: np.ndarray,
        qdd_d: np.ndarray,
        u_n: np.ndarray,
        applied: np.ndarray | None,
    ) -> FeedbackOutput:
        """Perturbation torque for sample ``k``.

        Parameters
        ----------
        k : int
            Sample index (time ``k T``).
        q, qd : (n,) ndarray
            Measured joint position (rad) and velocity (rad/s) at ``k``.
        q_d, qd_d, qdd_d, u_n : (n,) ndarray
            Set point at ``k`` and its nominal torque (N m).
        applied : (n,) ndarray or None
            Torque the plant applied over ``[(k-1)T, kT)`` (``JointState.effort``); None at
            the first sample or when the plant does not report it.
        """


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
    trace_max : float
        Wind-up guard, an upper bound on ``trace(P)``. ``0`` (default) means
        ``trace(P(0)) = alpha (3n+1)``: never less certain than at the start. A negative value
        disables the guard (the paper's RLS). Measured in ``bench/trace_guard.py``: without it
        a 20 s hold winds ``trace(P)`` up to 1e20-1e45, the identifier's updates become
        unusable (P loses definiteness) and with a position-weighted Q the arm diverges; with
        it nothing is rejected and errors during the move are equal or smaller.
    control_form : {"exact", "printed"}
        Eq. 35: exact minimiser ``-(R + GᵀQG)⁻¹GᵀQ(F x + w)`` or as printed
        ``-(R + GᵀQG)⁻¹GᵀQF(x + w)``.
    initial_model : {"corrected", "printed"}
        Eq. 33b series with ``T²/2, T³/6`` (corrected) or as printed.
    identify_with : {"applied", "commanded"}
        Which ``du(k-1)`` enters the regressor ``z(k-1)``: the torque the plant reports it
        applied minus ``u_n(k-1)`` (right under saturation), or the commanded ``du(k-1)``.
    """

    period: float = 0.010
    q_position: float = 0.1
    q_velocity: float = 0.1
    r: float = 1e-6
    rho: float = 0.95
    alpha: float = 1.5e5
    forgetting: Literal["exponential", "printed"] = "exponential"
    trace_max: float = 0.0
    control_form: Literal["exact", "printed"] = "exact"
    initial_model: SeriesForm = "corrected"
    identify_with: Literal["applied", "commanded"] = "applied"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.period) and self.period > 0.0):
            raise FeedbackError(f"period must be > 0 s, got {self.period}")
        for name in ("q_position", "q_velocity"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise FeedbackError(f"{name} must be >= 0 (Q positive semidefinite), got {value}")
        if not (np.isfinite(self.r) and self.r > 0.0):
            raise FeedbackError(f"r must be > 0 (R positive definite), got {self.r}")
        if self.control_form not in ("exact", "printed"):
            raise FeedbackError(
                f"control_form must be 'exact' or 'printed', got {self.control_form!r}"
            )
        if self.initial_model not in ("corrected", "printed"):
            raise FeedbackError(
                f"initial_model must be 'corrected' or 'printed', got {self.initial_model!r}"
            )
        if self.identify_with not in ("applied", "commanded"):
            raise FeedbackError(
                f"identify_with must be 'applied' or 'commanded', got {self.identify_with!r}"
            )
        if not np.isfinite(self.trace_max):
            raise FeedbackError(f"trace_max must be finite, got {self.trace_max}")
        try:
            self.rls_config()
        except RlsError as exc:
            raise FeedbackError(str(exc)) from None

    def rls_config(self, n_joints: int = 1) -> RlsConfig:
        """The identifier's settings for an arm of ``n_joints`` (resolves ``trace_max``)."""
        if self.trace_max < 0.0:
            trace_max = None
        elif self.trace_max == 0.0:
            trace_max = self.alpha * (3 * n_joints + 1)
        else:
            trace_max = self.trace_max
        return RlsConfig(
            rho=self.rho, alpha=self.alpha, forgetting=self.forgetting, trace_max=trace_max
        )

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> AdaptiveConfig:
        """Build from a plain mapping; an unknown key is rejected with its name."""
        known = {f.name for f in fields(AdaptiveConfig)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise FeedbackError(f"unknown adaptive-controller parameter {unknown[0]!r}")
        return AdaptiveConfig(**dict(values))


class AdaptiveFeedback(FeedbackLaw):
    """Adaptive perturbation control (Eqs. 16, 29-35).

    Per sample ``k`` with ``dx(k) = (q - q_d, qd - qd_d)``:

    1. at the first sample, ``F̂(0), Ĝ(0)`` from Eq. 33 at ``(q_d(0), qd_d(0), u_n(0))`` on the
       controller's model, ``ŵ(0) = 0``, ``P(0) = alpha I`` (Eq. 32);
    2. otherwise one RLS step (Eqs. 29-31) with ``z(k-1) = (dx(k-1), du(k-1), 1)`` and target
       ``dx(k)``, where ``du(k-1)`` is the applied torque minus ``u_n(k-1)``;
    3. ``du(k) = -(R + ĜᵀQĜ)⁻¹ĜᵀQ(F̂ dx(k) + ŵ)`` (Eq. 35, exact minimiser of Eq. 34).

    Parameters
    ----------
    model : pinocchio.Model
        The controller's model (never the plant's).
    config : AdaptiveConfig
    """

    kind = "adaptive"

    def __init__(self, model: pin.Model, config: AdaptiveConfig) -> None:
        super().__init__(model.nv)
        self.model = model
        self.config = config
        n = model.nv
        self.Q = np.diag(
            np.concatenate([np.full(n, config.q_position), np.full(n, config.q_velocity)])
        )
        self.R = config.r * np.eye(n)
        validate_weights(self.Q, self.R, 2 * n, n)
        self.rls = Rls(n, config.rls_config(n))
        self.reset()

    def reset(self) -> None:
        self._started = False
        self.rejected_updates = 0
        self._dx_prev = np.zeros(2 * self.n_joints)
        self._du_prev = np.zeros(self.n_joints)
        self._u_n_prev = np.zeros(self.n_joints)

    def update(
        self,
        k: int,
        q: np.ndarray,
        qd: np.ndarray,
        q_d: np.ndarray,
        qd_d: np.ndarray,
        qdd_d: np.ndarray,
        u_n: np.ndarray,
        applied: np.ndarray | None,
    ) -> FeedbackOutput:
        dx = np.concatenate([q - q_d, qd - qd_d])
        if not np.all(np.isfinite(dx)):
            raise FeedbackError(f"state error is not finite at sample {k}")
        residual = None
        rejected = False
        if not self._started:
            F0, G0 = initial_model(
                self.model, q_d, qd_d, u_n, self.config.period, self.config.initial_model
            )
            self.rls.reset(F0, G0)
            self._started = True
        else:
            if applied is not None and self.config.identify_with == "applied":
                du_prev = applied - self._u_n_prev
            else:
                du_prev = self._du_prev
            z = Rls.regressor(self._dx_prev, du_prev)
            try:
                residual = self.rls.update(z, dx).residual
            except RlsError:
                # Keep controlling with the last good estimate; the node counts and reports it.
                rejected = True
                self.rejected_updates += 1
        du = one_step_control(
            self.rls.F,
            self.rls.G,
            self.rls.w,
            self.Q,
            self.R,
            dx,
            self.config.control_form,
            check_weights=False,
        )
        self._dx_prev = dx
        self._du_prev = du
        self._u_n_prev = np.array(u_n, dtype=float)
        return FeedbackOutput(du=du, residual=residual, trace_p=self.rls.trace_p, rejected=rejected)
