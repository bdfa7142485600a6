"""The simulated arm: Lagrange-Euler dynamics (Eq. 1) integrated by classical RK4.

``D(q) q'' + h(q, q') + c(q) = tau`` is solved for the acceleration ``q'' = D(q)⁻¹ (tau - h - c)``
(Eq. 12) by one of two Pinocchio algorithms that compute the same quantity:

- ``"aba"`` (default): Featherstone's articulated-body algorithm, O(n), never forms ``D``;
- ``"crba"``: ``D`` from CRBA and ``h + c`` from the nonlinear effects, then
  ``solve(D, tau - h - c)`` — Eq. 12 term by term, kept to cross-check (the tests hold the two
  equal to 1e-9 on the PUMA and a seven-joint arm).

ABA is 4-5x faster per period in Python (one call instead of CRBA, nonlinear effects, the
triangle mirror and a solve; ``bench/compute.py``), which is what a lockstep run through the nodes
spends most of its plant time on. The two differ only by rounding (1e-13 rad over a run).
The torque is held constant over each sampling period T (zero-order hold, the paper's
piecewise-constant ``u(kT)`` of Eq. 16) and the state is integrated with T/h fixed RK4 steps of
size h (the paper used Runge-Kutta-Gill, a fourth-order RK variant; classical RK4 has the same
order and a fixed step makes runs bit-reproducible).

Torques beyond the URDF's effort limits are clipped before they are applied; every period
reports which joints saturated and the torque actually applied.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import pinocchio as pin

from apc_core.params import SettingError, check_settings, setting, settings_from
from apc_core.robot import Robot


class PlantError(SettingError):
    """Bad plant configuration or input; the message names the parameter (and ``field`` the
    setting at fault)."""


@dataclass(frozen=True)
class PlantConfig:
    """Timing and limits of the simulated arm.

    Attributes
    ----------
    period : float
        Sampling period T (s): the torque is held for T, state is reported every T.
    step : float
        RK4 integration step h (s); T/h must be a whole number.
    enforce_torque_limits : bool
        Clip |tau_i| to the URDF effort limit of joint i.
    forward_dynamics : {"aba", "crba"}
        How ``q''`` is computed (see the module docstring); same dynamics, other algorithm.
    """

    period: float = 0.010
    step: float = setting(0.0025, "RK4 integration step h (s); must divide period", 1e-6, 1.0)
    enforce_torque_limits: bool = setting(True, "clip |tau| to the URDF effort limits")
    forward_dynamics: Literal["aba", "crba"] = setting(
        "aba",
        "how q'' is computed: 'aba' (articulated body, fast) or 'crba' (D(q) and solve); "
        "same dynamics",
    )

    def __post_init__(self) -> None:
        if not (np.isfinite(self.period) and self.period > 0.0):
            raise PlantError(f"period must be > 0 s, got {self.period}", field="period")
        check_settings(self, PlantError)
        ratio = self.period / self.step
        if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
            raise PlantError(
                f"step ({self.step} s) must divide period ({self.period} s) a whole number "
                "of times",
                field="step",
            )
        if self.forward_dynamics not in ("aba", "crba"):
            raise PlantError(
                f"forward_dynamics must be 'aba' or 'crba', got {self.forward_dynamics!r}",
                field="forward_dynamics",
            )

    @property
    def substeps(self) -> int:
        return round(self.period / self.step)

    @staticmethod
    def from_dict(values: Mapping[str, Any]) -> PlantConfig:
        """Build from a plain mapping (e.g. ROS parameters); unknown keys are rejected."""
        return settings_from(PlantConfig, values, PlantError, "plant parameter")


@dataclass(frozen=True)
class PlantStep:
    """What one sampling period did.

    Attributes
    ----------
    q, qd : (n,) ndarray
        State at the end of the period (rad, rad/s).
    applied : (n,) ndarray
        Torque held over the period after limiting (N m).
    saturated : (n,) bool ndarray
        Joints whose commanded torque exceeded the effort limit.
    """

    q: np.ndarray
    qd: np.ndarray
    applied: np.ndarray
    saturated: np.ndarray


class Plant:
    """A serial arm integrated with RK4 under a zero-order-hold torque.

    Parameters
    ----------
    robot : Robot
        The *true* arm (with payload); the controllers never see it.
    config : PlantConfig
    q0, qd0 : (n,) array_like
        Initial state (rad, rad/s); qd0 defaults to zero.
    """

    def __init__(
        self,
        robot: Robot,
        config: PlantConfig,
        q0: np.ndarray,
        qd0: np.ndarray | None = None,
    ) -> None:
        self.robot = robot
        self.config = config
        self._model = robot.model
        self._data = robot.model.createData()
        self._n = robot.n_joints
        self._limit = robot.effort_limit.copy()
        self._lower = np.tril_indices(self._n, -1)
        self._aba = config.forward_dynamics == "aba"
        self.reset(q0, qd0)

    @property
    def n_joints(self) -> int:
        return self._n

    def set_robot(self, robot: Robot) -> None:
        """Swap the arm's model mid-run (e.g. a payload picked up), keeping the state.

        Raises
        ------
        PlantError
            The new model has other joints.
        """
        if robot.joint_names != self.robot.joint_names:
            raise PlantError(
                f"set_robot: joints {robot.joint_names} differ from {self.robot.joint_names}"
            )
        self.robot = robot
        self._model = robot.model
        self._data = robot.model.createData()
        self._limit = robot.effort_limit.copy()

    def reset(self, q0: np.ndarray, qd0: np.ndarray | None = None) -> None:
        """Put the arm at ``(q0, qd0)`` with time index 0."""
        self.q = self._vector(q0, "q0")
        self.qd = np.zeros(self._n) if qd0 is None else self._vector(qd0, "qd0")
        self.k = 0

    def _vector(self, value: Any, name: str) -> np.ndarray:
        arr = np.array(value, dtype=float).reshape(-1)
        if arr.shape != (self._n,):
            raise PlantError(f"{name} must have shape ({self._n},), got {arr.shape}")
        total = float(arr.sum())
        # The sum is finite only if every entry is (one reduction); if not, check each (the
        # sum may just have overflowed).
        if total - total != 0.0 and not np.isfinite(arr).all():
            raise PlantError(f"{name} must be finite, got {arr.tolist()}")
        return arr

    def acceleration(self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Forward dynamics of Eq. 1: ``q'' = D(q)⁻¹ (tau - h(q, q') - c(q))`` (Eq. 12).

        By ABA, or (``forward_dynamics="crba"``) as ``solve(D(q), tau - h - c)``; ``D`` is
        symmetric positive definite, so a Cholesky solve would do, but ``numpy.linalg.solve``
        on an n x n matrix is as fast in Python and equally exact here.
        """
        if self._aba:
            # aba returns a view of data.ddq, which the next call overwrites.
            return pin.aba(self._model, self._data, q, qd, tau).copy()
        D = pin.crba(self._model, self._data, q)
        # CRBA fills only the upper triangle; mirror it in place (half the cost of triu + triu.T).
        D[self._lower] = D.T[self._lower]
        bias = pin.nonLinearEffects(self._model, self._data, q, qd)
        return np.linalg.solve(D, tau - bias)

    def limit(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Clip a commanded torque to the effort limits; return (applied, saturated mask)."""
        if not self.config.enforce_torque_limits:
            return tau.copy(), np.zeros(self._n, dtype=bool)
        saturated = np.abs(tau) > self._limit
        return np.clip(tau, -self._limit, self._limit), saturated

    def step(self, tau: np.ndarray) -> PlantStep:
        """Hold ``tau`` over one period T and integrate (classical RK4, T/h steps).

        Raises
        ------
        PlantError
            ``tau`` has the wrong shape or is not finite (nothing is integrated), or the state
            became non-finite (the state is left as it was).
        """
        tau = self._vector(tau, "tau")
        applied, saturated = self.limit(tau)
        h = self.config.step
        half, sixth = 0.5 * h, h / 6.0
        accel = self.acceleration
        q, qd = self.q, self.qd
        for _ in range(self.config.substeps):
            # Classical RK4 on (q, q'); the position stages are the velocity stages v_i.
            a1 = accel(q, qd, applied)
            v2 = qd + half * a1
            a2 = accel(q + half * qd, v2, applied)
            v3 = qd + half * a2
            a3 = accel(q + half * v2, v3, applied)
            v4 = qd + h * a3
            a4 = accel(q + h * v3, v4, applied)
            q = q + sixth * (qd + 2.0 * (v2 + v3) + v4)
            qd = qd + sixth * (a1 + 2.0 * (a2 + a3) + a4)
        total = float(q.sum() + qd.sum())
        if total - total != 0.0 and not (np.isfinite(q).all() and np.isfinite(qd).all()):
            raise PlantError(f"state became non-finite at sample {self.k}; not applied")
        self.q, self.qd = q, qd
        self.k += 1
        return PlantStep(q=q.copy(), qd=qd.copy(), applied=applied, saturated=saturated)

    def brake(self) -> None:
        """Hold the arm over one period: velocity zero, position kept (a PUMA's brakes)."""
        self.qd = np.zeros(self._n)
        self.k += 1

    def energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """Kinetic plus potential energy (J), for conservation checks."""
        kinetic = pin.computeKineticEnergy(self._model, self._data, q, qd)
        potential = pin.computePotentialEnergy(self._model, self._data, q)
        return float(kinetic + potential)
