"""A lean re-implementation of the adaptive law's hot path, to size what optimising src/ can gain.

Same mathematics as :class:`apc_feedback.controller.AdaptiveFeedback` with its defaults
(exponential forgetting, trace guard, exact Eq. 35, one-step horizon, ``identify_with
"applied"``), but written the way a per-sample loop in numpy should be: every buffer
preallocated, Θ kept as one (3n+1, 2n) array that F̂, Ĝ, ŵ are *views* of (no copies), the
diagonal Q applied by broadcasting, shapes and finiteness checked once per sample on a single
reduction instead of per argument, no dataclass per call. ``bench/compute.py`` checks that it
returns the same ``du`` as ``AdaptiveFeedback`` (to 1e-9 relative) before timing it.

This is a measuring stick for recommendations, not a second controller: nothing imports it.
"""

from __future__ import annotations

import math

import numpy as np

from apc_feedback.controller import AdaptiveConfig
from apc_feedback.linearize import initial_model


class LeanAdaptive:
    """RLS (Eqs. 26, 29-31) + one-step optimal control (Eq. 35) with preallocated buffers."""

    def __init__(self, model, config: AdaptiveConfig) -> None:
        n = model.nv
        self.model, self.config = model, config
        self.n, self.p, self.m = n, 2 * n, 3 * n + 1
        self.rho = config.rho
        rls = config.rls_config(n)
        self.trace_max = rls.trace_max
        self.qdiag = np.concatenate([np.full(n, config.q_position), np.full(n, config.q_velocity)])
        self.R = config.r * np.eye(n)
        m, p = self.m, self.p
        self.theta = np.zeros((m, p))
        self.P = config.alpha * np.eye(m)
        self.z = np.empty(m)
        self.z[-1] = 1.0
        self.pz = np.empty(m)
        self.e = np.empty(p)
        self.outer = np.empty((m, m))
        self.touter = np.empty((m, p))
        self.dx = np.empty(p)
        self.dx_prev = np.zeros(p)
        self.u_n_prev = np.zeros(n)
        self.du_prev = np.zeros(n)
        self.y = np.empty(p)
        self.gtq = np.empty((n, p))
        self.started = False

    def update(self, q, qd, q_d, qd_d, u_n, applied):
        n, p = self.n, self.p
        dx = self.dx
        np.subtract(q, q_d, out=dx[:n])
        np.subtract(qd, qd_d, out=dx[n:])
        if not self.started:
            F0, G0 = initial_model(
                self.model, q_d, qd_d, u_n, self.config.period, self.config.initial_model
            )
            self.theta[:p] = F0.T
            self.theta[p : p + n] = G0.T
            self.theta[p + n] = 0.0
            self.started = True
        else:
            z = self.z
            z[:p] = self.dx_prev
            if applied is not None:
                np.subtract(applied, self.u_n_prev, out=z[p : p + n])
            else:
                z[p : p + n] = self.du_prev
            self._rls(z, dx)
        du = self._control(dx)
        self.dx_prev[:] = dx
        self.du_prev = du
        self.u_n_prev[:] = u_n
        return du

    def _rls(self, z, dx) -> None:
        P, theta, pz, e = self.P, self.theta, self.pz, self.e
        np.dot(P, z, out=pz)
        gamma = 1.0 / (float(z @ pz) + self.rho)
        np.dot(z, theta, out=e)
        np.subtract(dx, e, out=e)
        touter, outer = self.touter, self.outer
        np.multiply.outer(pz, e, out=touter)
        touter *= gamma
        np.multiply.outer(pz, pz, out=outer)
        outer *= -gamma
        outer += P
        outer /= self.rho
        trace = float(np.trace(outer))
        if self.trace_max is not None and trace > self.trace_max:
            outer *= self.trace_max / trace
        # One reduction each: a non-finite entry anywhere makes the sum non-finite.
        if math.isfinite(float(outer.sum()) + float(touter.sum())):
            theta += touter
            self.P, self.outer = outer, P

    def _control(self, dx):
        n, p, theta = self.n, self.p, self.theta
        y = self.y
        np.dot(dx, theta[:p], out=y)  # F̂ dx  (theta[:p] = F̂ᵀ)
        y += theta[p + n]  # + ŵ
        gt = theta[p : p + n]  # Ĝᵀ, a view
        np.multiply(gt, self.qdiag, out=self.gtq)  # ĜᵀQ for diagonal Q
        S = self.R + self.gtq @ gt.T
        return -np.linalg.solve(S, self.gtq @ y)


class LeanPlant:
    """:meth:`apc_plant_sim.plant.Plant.step` with Pinocchio's ABA for the acceleration.

    ABA computes the same ``q'' = D(q)⁻¹ (tau − h − c)`` as CRBA + nonlinear effects + solve
    (the tests check them equal to 1e-9) in one O(n) call; the RK4 stages reuse buffers.
    """

    def __init__(self, robot, period: float = 0.010, step: float = 0.0025) -> None:
        self.model = robot.model
        self.data = robot.model.createData()
        self.limit = robot.effort_limit.copy()
        self.h = step
        self.substeps = round(period / step)

    def step(self, q, qd, tau):
        import pinocchio as pin

        model, data, h = self.model, self.data, self.h
        tau = np.clip(tau, -self.limit, self.limit)
        for _ in range(self.substeps):
            a1 = pin.aba(model, data, q, qd, tau).copy()
            v2 = qd + (0.5 * h) * a1
            a2 = pin.aba(model, data, q + (0.5 * h) * qd, v2, tau).copy()
            v3 = qd + (0.5 * h) * a2
            a3 = pin.aba(model, data, q + (0.5 * h) * v2, v3, tau).copy()
            v4 = qd + h * a3
            a4 = pin.aba(model, data, q + h * v3, v4, tau).copy()
            q = q + (h / 6.0) * (qd + 2.0 * (v2 + v3) + v4)
            qd = qd + (h / 6.0) * (a1 + 2.0 * (a2 + a3) + a4)
        if not math.isfinite(float(q.sum() + qd.sum())):
            raise ValueError("state became non-finite")
        return q, qd, tau
