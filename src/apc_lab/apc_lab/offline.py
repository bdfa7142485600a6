"""The closed loop without ROS: plant -> feedforward -> feedback, stepped at period T.

This is the reference the lockstep ROS run must reproduce bit for bit. One sample ``k``:

1. the plant reports ``(q, q')(k)`` and the torque it applied over ``[(k-1)T, kT)``;
2. the feedforward samples the plan at ``kT`` and computes ``u_n(k)`` (Eqs. 2-8);
3. the feedback computes ``du(k)`` from the state, the set point and the applied torque;
4. the plant applies ``u_n(k) + du(k)`` (clipped to its limits) over ``[kT, (k+1)T)``.

Steps 2 and 3 are independent of each other's output at sample k (the paper's parallel
structure): the feedback reads ``u_n(k)`` only through the set point.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from apc_core.robot import Robot
from apc_feedback.feedback_law import FeedbackLaw
from apc_feedforward.nominal import Feedforward
from apc_plant_sim.plant import Plant


@dataclass
class RunResult:
    """Time series of one closed-loop run; row ``k`` is sample time ``k T``.

    Attributes
    ----------
    t : (N+1,) ndarray
        Sample times (s).
    q, qd : (N+1, n) ndarray
        Measured state at each sample (rad, rad/s).
    q_d, qd_d, qdd_d, u_n : (N+1, n) ndarray
        Set point and nominal torque (N m) at each sample.
    du : (N+1, n) ndarray
        Perturbation torque commanded at each sample (N m).
    applied : (N+1, n) ndarray
        Torque applied over ``[kT, (k+1)T)`` after limits; the last row is what would be
        applied next (the run stops before integrating it).
    saturated : (N+1, n) bool ndarray
    residual_norm, trace_p : (N+1,) ndarray
        RLS telemetry (NaN where the law has none or at the first sample).
    rejected : (N+1,) bool ndarray
        The identifier refused the update at that sample (covariance wind-up).
    F, G, w : ndarray or None
        Identified parameters per sample, (N+1, 2n, 2n), (N+1, 2n, n), (N+1, 2n), for the
        adaptive law.
    """

    joint_names: tuple[str, ...]
    period: float
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    q_d: np.ndarray
    qd_d: np.ndarray
    qdd_d: np.ndarray
    u_n: np.ndarray
    du: np.ndarray
    applied: np.ndarray
    saturated: np.ndarray
    residual_norm: np.ndarray
    trace_p: np.ndarray
    rejected: np.ndarray
    F: np.ndarray | None = None
    G: np.ndarray | None = None
    w: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        """Position tracking error ``q - q_d`` (rad), (N+1, n)."""
        return self.q - self.q_d


def run_closed_loop(
    plant: Plant,
    feedforward: Feedforward,
    feedback: FeedbackLaw,
    n_samples: int,
    *,
    record_parameters: bool = True,
    plant_changes: Mapping[int, Robot] | None = None,
) -> RunResult:
    """Run ``n_samples`` sampling periods of the closed loop from the plant's current state.

    Parameters
    ----------
    plant : Plant
        The true arm, already reset to its initial state (sample index ``plant.k``).
    feedforward : Feedforward
        Plan and nominal torques on the controller's model.
    feedback : FeedbackLaw
        Reset before the run.
    n_samples : int
        Number of periods integrated; the result has ``n_samples + 1`` rows.
    record_parameters : bool
        Keep the identified ``F, G, w`` of an adaptive law at every sample.
    plant_changes : mapping of sample index to Robot, optional
        The true arm changes at these samples (e.g. a payload picked up mid-motion); the new
        model integrates the period starting at that sample.

    Returns
    -------
    RunResult
    """
    if n_samples < 0:
        raise ValueError(f"n_samples must be >= 0, got {n_samples}")
    n = plant.n_joints
    rows = n_samples + 1
    k0 = plant.k
    out = {
        name: np.zeros((rows, n))
        for name in ("q", "qd", "q_d", "qd_d", "qdd_d", "u_n", "du", "applied")
    }
    saturated = np.zeros((rows, n), dtype=bool)
    residual_norm = np.full(rows, np.nan)
    trace_p = np.full(rows, np.nan)
    rejected = np.zeros(rows, dtype=bool)
    rls = getattr(feedback, "rls", None) if record_parameters else None
    F = np.zeros((rows, 2 * n, 2 * n)) if rls is not None else None
    G = np.zeros((rows, 2 * n, rls.m - 2 * n - 1)) if rls is not None else None
    w = np.zeros((rows, 2 * n)) if rls is not None else None

    applied_prev: np.ndarray | None = None
    feedback.reset()
    for i in range(rows):
        k = k0 + i
        q, qd = plant.q.copy(), plant.qd.copy()
        sp = feedforward.sample(k)
        fb = feedback.update(k, q, qd, sp.q, sp.qd, sp.qdd, sp.u_n, applied_prev)
        tau = sp.u_n + fb.du
        out["q"][i], out["qd"][i] = q, qd
        out["q_d"][i], out["qd_d"][i], out["qdd_d"][i] = sp.q, sp.qd, sp.qdd
        out["u_n"][i], out["du"][i] = sp.u_n, fb.du
        trace_p[i] = fb.trace_p
        rejected[i] = fb.rejected
        if fb.residual is not None:
            residual_norm[i] = float(np.linalg.norm(fb.residual))
        if rls is not None:
            F[i], G[i], w[i] = rls.F, rls.G, rls.w
        if plant_changes and k in plant_changes:
            plant.set_robot(plant_changes[k])
        if i < n_samples:
            step = plant.step(tau)
            applied_prev = step.applied
            out["applied"][i], saturated[i] = step.applied, step.saturated
        else:
            out["applied"][i], saturated[i] = plant.limit(tau)
    return RunResult(
        joint_names=plant.robot.joint_names,
        period=plant.config.period,
        t=(k0 + np.arange(rows)) * plant.config.period,
        saturated=saturated,
        residual_norm=residual_norm,
        trace_p=trace_p,
        rejected=rejected,
        F=F,
        G=G,
        w=w,
        **out,
    )
