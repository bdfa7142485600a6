"""Baseline feedback laws the paper's adaptive controller is compared with.

All are expressed as a perturbation torque ``du = tau - u_n`` so that the plant, which applies
``u_n + du``, applies exactly the law's ``tau``.

- :class:`ComputedTorque` — Eq. 36 on the controller's model:
  ``tau = D(q)[qdd_d + Kv (qd_d - qd) + Kp (q_d - q)] + h(q, qd) + c(q)``, evaluated as one
  RNEA call at the measured state with the commanded acceleration. Paper: Kp = 100, Kv = 20.
- :class:`PD` — ``du = Kp (q_d - q) + Kv (qd_d - qd)`` on top of the nominal torque.
- :class:`NoFeedback` — ``du = 0``: feedforward only.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from apc_feedback.controller import FeedbackError, FeedbackLaw, FeedbackOutput


@dataclass(frozen=True)
class PdGains:
    """Position and velocity gains ``Kp`` (N m/rad, or 1/s^2 for computed torque) and ``Kv``.

    Scalars mean ``k I``. The paper's computed torque uses ``Kp = 100``, ``Kv = 20``
    ("near critically damped": ``Kv = 2 sqrt(Kp)``).
    """

    kp: float = 100.0
    kv: float = 20.0

    def __post_init__(self) -> None:
        for name in ("kp", "kv"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise FeedbackError(f"{name} must be finite and >= 0, got {value}")

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> PdGains:
        unknown = sorted(set(values) - {"kp", "kv"})
        if unknown:
            raise FeedbackError(f"unknown gain parameter {unknown[0]!r}")
        return PdGains(**dict(values))


class ComputedTorque(FeedbackLaw):
    """Computed-torque control, Eq. 36, on the controller's model."""

    kind = "computed_torque"

    def __init__(self, model: pin.Model, gains: PdGains | None = None) -> None:
        super().__init__(model.nv)
        self.model = model
        self.gains = gains or PdGains()
        self._data = model.createData()

    def reset(self) -> None:
        pass

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        qdd_cmd = qdd_d + self.gains.kv * (qd_d - qd) + self.gains.kp * (q_d - q)
        tau = pin.rnea(self.model, self._data, q, qd, qdd_cmd)
        return FeedbackOutput(du=np.array(tau, dtype=float) - u_n)


class PD(FeedbackLaw):
    """Joint-space PD on top of the nominal torque: ``du = Kp e + Kv e'``."""

    kind = "pd"

    def __init__(self, n_joints: int, gains: PdGains | None = None) -> None:
        super().__init__(n_joints)
        self.gains = gains or PdGains()

    def reset(self) -> None:
        pass

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        return FeedbackOutput(du=self.gains.kp * (q_d - q) + self.gains.kv * (qd_d - qd))


class NoFeedback(FeedbackLaw):
    """Feedforward only: ``du = 0``."""

    kind = "none"

    def reset(self) -> None:
        pass

    def update(self, k, q, qd, q_d, qd_d, qdd_d, u_n, applied) -> FeedbackOutput:
        return FeedbackOutput(du=np.zeros(self.n_joints))
