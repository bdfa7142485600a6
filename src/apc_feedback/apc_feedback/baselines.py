"""Baseline feedback laws the paper's adaptive controller is compared with.

All are expressed as a perturbation torque ``du = tau - u_n`` so that the plant, which applies
``u_n + du``, applies exactly the law's ``tau``.

- :class:`ComputedTorque` — Eq. 36 on the controller's model:
  ``tau = D(q)[qdd_d + Kv (qd_d - qd) + Kp (q_d - q)] + h(q, qd) + c(q)``, evaluated as one
  RNEA call at the measured state with the commanded acceleration. Paper: Kp = 100, Kv = 20.
  A model with joint friction (the controllers' ``friction``, ``damping``) adds it at the
  planned velocity, as the nominal torque does (``apc_feedforward.nominal.friction_torque``):
  RNEA has none, and the measured velocity of quantised encoders would make its Coulomb term
  chatter.
- :class:`PD` — ``du = Kp (q_d - q) + Kv (qd_d - qd)`` on top of the nominal torque.
- :class:`PID` — what a ROS user tries first: ros2_controllers' joint_trajectory_controller on an
  effort interface with the nominal torque as the trajectory's feed-forward effort,
  ``tau = u_n + Kp e + Ki ∫e + Kd e'`` per joint (control_toolbox::Pid), gains per joint.
- :class:`NoFeedback` — ``du = 0``: feedforward only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from apc_core.params import check_settings, setting, settings_from
from apc_feedback.adaptive_config import FeedbackError
from apc_feedback.feedback_law import FeedbackLaw, FeedbackOutput
from apc_feedforward.nominal import friction_torque, joint_friction


@dataclass(frozen=True)
class PdGains:
    """Position and velocity gains ``Kp`` (N m/rad, or 1/s^2 for computed torque) and ``Kv``.

    Scalars mean ``k I``. The paper's computed torque uses ``Kp = 100``, ``Kv = 20``
    ("near critically damped": ``Kv = 2 sqrt(Kp)``).
    """

    kp: float = setting(
        100.0,
        "Kp of computed torque (1/s^2) or PD (N m/rad); settable at run time",
        0.0,
        1e9,
        runtime=True,
    )
    kv: float = setting(
        20.0,
        "Kv of computed torque (1/s) or PD (N m s/rad); settable at run time",
        0.0,
        1e9,
        runtime=True,
    )

    def __post_init__(self) -> None:
        check_settings(self, FeedbackError)

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> PdGains:
        return settings_from(PdGains, values, FeedbackError, "gain parameter")


class _RuntimeGains:
    """A law whose :class:`PdGains` can change while it runs (it learns nothing to keep)."""

    gains: PdGains

    @property
    def settings(self) -> PdGains:
        return self.gains

    def reconfigure(self, settings: PdGains) -> None:
        self.gains = settings


class ComputedTorque(_RuntimeGains, FeedbackLaw):
    """Computed-torque control, Eq. 36, on the controller's model."""

    kind = "computed_torque"

    def __init__(self, model: pin.Model, gains: PdGains | None = None) -> None:
        super().__init__(model.nv)
        self.model = model
        self.gains = gains or PdGains()
        self._data = model.createData()
        self._friction = joint_friction(model)

    def reset(self) -> None:
        pass

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        qdd_cmd = qdd_d + self.gains.kv * (qd_d - qd) + self.gains.kp * (q_d - q)
        tau = np.array(pin.rnea(self.model, self._data, q, qd, qdd_cmd), dtype=float)
        if self._friction is not None:
            tau += friction_torque(self._friction, qd_d)
        return FeedbackOutput(du=tau - u_n)


class PD(_RuntimeGains, FeedbackLaw):
    """Joint-space PD on top of the nominal torque: ``du = Kp e + Kv e'``."""

    kind = "pd"

    def __init__(self, n_joints: int, gains: PdGains | None = None) -> None:
        super().__init__(n_joints)
        self.gains = gains or PdGains()

    def reset(self) -> None:
        pass

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        return FeedbackOutput(du=self.gains.kp * (q_d - q) + self.gains.kv * (qd_d - qd))


@dataclass(frozen=True)
class PidGains:
    """Per-joint PID gains, JTC's ``gains.<joint>.p/i/d/i_clamp``, or the tuning rule's inputs.

    Empty ``p``, ``i``, ``d`` mean: tune at the first sample (:meth:`tuned`) from the
    controller model's joint-space inertia at the first set point, the way a user tunes each
    joint as a decoupled inertia ``J_i = D(q_0)_ii``: all three closed-loop poles of
    ``J s³ + Kd s² + Kp s + Ki`` at ``-bandwidth``, i.e. ``Kp = 3 J ω²``, ``Kd = 3 J ω``,
    ``Ki = J ω³``. The default ``ω = 10 rad/s`` is the bandwidth of the paper's computed torque
    (``Kp = 100``, ``Kv = 20``: a double pole at -10 rad/s), so the two baselines are equally
    fast; ``i_clamp`` defaults to ``i_clamp_fraction`` of the joint's effort limit.

    Attributes
    ----------
    p, i, d : per joint
        N m/rad, N m/(rad s), N m s/rad.
    i_clamp : per joint
        Bound on ``|Ki ∫e|`` (N m): the integrator stops where its term would pass it
        (control_toolbox's anti-windup).
    bandwidth : float
        ω of the tuning rule (rad/s).
    i_clamp_fraction : float
        Default ``i_clamp`` as a fraction of the effort limit.
    """

    p: tuple[float, ...] = setting((), "Kp per joint (N m/rad); empty: p, i, d tuned")
    i: tuple[float, ...] = setting((), "Ki per joint (N m/(rad s)); empty: tuned")
    d: tuple[float, ...] = setting((), "Kd per joint (N m s/rad); empty: tuned")
    i_clamp: tuple[float, ...] = setting(
        (), "bound on |Ki integral| per joint (N m); empty: i_clamp_fraction of the effort limit"
    )
    bandwidth: float = setting(
        10.0, "tuning rule: all three closed-loop poles at -bandwidth (rad/s)", 1e-3, 1e4
    )
    i_clamp_fraction: float = setting(
        0.2, "default i_clamp as a fraction of each joint's effort limit", 0.0, 100.0
    )

    def __post_init__(self) -> None:
        for name in ("p", "i", "d", "i_clamp"):
            values = tuple(float(v) for v in getattr(self, name))
            if not all(np.isfinite(v) and v >= 0.0 for v in values):
                raise FeedbackError(
                    f"{name} must be finite and >= 0, got {list(values)}", field=name
                )
            object.__setattr__(self, name, values)
        given = {name for name in ("p", "i", "d") if getattr(self, name)}
        if given and given != {"p", "i", "d"}:
            missing = sorted({"p", "i", "d"} - given)[0]
            raise FeedbackError(
                "pid gains p, i and d must be given together (or none: tuned)", field=missing
            )
        check_settings(self, FeedbackError)

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> PidGains:
        return settings_from(PidGains, values, FeedbackError, "gain parameter")

    def tuned(self, model: pin.Model, q0: np.ndarray, effort_limit: np.ndarray) -> PidGains:
        """These gains with every empty entry filled by the tuning rule at pose ``q0``."""
        n = model.nv
        out = {}
        if not self.p:
            inertia = np.array(pin.crba(model, model.createData(), q0)).diagonal()
            w = self.bandwidth
            out = {"p": 3.0 * inertia * w**2, "d": 3.0 * inertia * w, "i": inertia * w**3}
        if not self.i_clamp:
            out["i_clamp"] = self.i_clamp_fraction * np.asarray(effort_limit, dtype=float)
        gains = replace(self, **{k: tuple(float(x) for x in v) for k, v in out.items()})
        for name in ("p", "i", "d", "i_clamp"):
            if len(getattr(gains, name)) != n:
                raise FeedbackError(f"pid {name} needs {n} values, got {len(getattr(gains, name))}")
        return gains


class PID(FeedbackLaw):
    """Per-joint PID on top of the nominal torque, as JTC computes an effort command.

    ``e = q_d - q``, ``e' = qd_d - qd`` (JTC passes the velocity error as the error's
    derivative, no differencing); the integrator ``I += T e`` is held within
    ``±i_clamp / Ki`` so that the integral term never exceeds ``i_clamp``.

    Parameters
    ----------
    model : pinocchio.Model
        The controller's model (for the tuning rule only).
    effort_limit : (n,) array
        The arm's effort limits (default ``i_clamp``).
    period : float
        Sampling period T (s).
    gains : PidGains
    """

    kind = "pid"

    def __init__(
        self,
        model: pin.Model,
        effort_limit: np.ndarray,
        period: float,
        gains: PidGains | None = None,
    ) -> None:
        super().__init__(model.nv)
        if not (np.isfinite(period) and period > 0.0):
            raise FeedbackError(f"period must be > 0 s, got {period}")
        self.model = model
        self.period = float(period)
        self.effort_limit = np.asarray(effort_limit, dtype=float)
        self.requested = gains or PidGains()
        self.reset()

    def reset(self) -> None:
        self.gains: PidGains | None = None
        self.integral = np.zeros(self.n_joints)

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        if self.gains is None:
            self.gains = self.requested.tuned(self.model, q_d, self.effort_limit)
            g = self.gains
            self._p, self._i, self._d = np.array(g.p), np.array(g.i), np.array(g.d)
            with np.errstate(divide="ignore"):
                self._i_bound = np.where(self._i > 0.0, np.array(g.i_clamp) / self._i, 0.0)
        e = q_d - q
        self.integral = np.clip(self.integral + self.period * e, -self._i_bound, self._i_bound)
        return FeedbackOutput(du=self._p * e + self._i * self.integral + self._d * (qd_d - qd))


class NoFeedback(FeedbackLaw):
    """Feedforward only: ``du = 0``."""

    kind = "none"

    def reset(self) -> None:
        pass

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        return FeedbackOutput(du=np.zeros(self.n_joints))
