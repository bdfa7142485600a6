"""One RLS update written as the paper writes it (Eqs. 26, 29-31, column by column): the
readable reference that :meth:`apc_feedback.rls.Rls.update` is tested against."""

from __future__ import annotations

import numpy as np

from apc_feedback.rls import RlsStep
from apc_feedback.rls_config import RlsConfig

__all__ = ["rls_update_reference"]


def rls_update_reference(
    theta: np.ndarray, P: np.ndarray, z: np.ndarray, dx_next: np.ndarray, config: RlsConfig
) -> tuple[np.ndarray, np.ndarray, RlsStep]:
    """One update of Eqs. 26, 29-31 written as the paper writes it: the readable reference
    that :meth:`Rls.update` is tested against.

    Column by column (Eq. 29 for each ``θᵢ``), fresh arrays, no checks and no buffers. The
    same wind-up guard as :class:`Rls` (see the module docstring).

    Parameters
    ----------
    theta : numpy.ndarray, shape (m, 2n)
        Θ(k) = [θ₁ … θ_p] (Eq. 22); ``m = 3n+1``, or ``2n + (L+1) n + 1`` with ``L`` lags.
    P : numpy.ndarray, shape (m, m)
        P(k), symmetric positive definite.
    z : numpy.ndarray, shape (m,)
        z(k) (Eq. 23).
    dx_next : numpy.ndarray, shape (2n,)
        The measured δx(k+1).
    config : RlsConfig

    Returns
    -------
    theta_next : numpy.ndarray, shape (3n+1, 2n)
        Θ(k+1).
    P_next : numpy.ndarray, shape (3n+1, 3n+1)
        P(k+1).
    step : RlsStep
        The a-priori residual, γ, trace(P(k+1)) and whether the guard acted.
    """
    gamma = 1.0 / (z @ P @ z + config.rho)  # γ(k) (Eq. 31)
    residual = np.empty(theta.shape[1])
    theta_next = np.empty_like(theta)
    for i in range(theta.shape[1]):
        theta_i = theta[:, i]  # θᵢ(k) (Eq. 21)
        residual[i] = dx_next[i] - z @ theta_i  # eᵢ(k) = xᵢ(k+1) - zᵀ θᵢ (Eq. 26)
        theta_next[:, i] = theta_i + gamma * (P @ z) * residual[i]  # θᵢ(k+1) (Eq. 29)
    P_next = P - gamma * P @ np.outer(z, z) @ P  # Eq. 30 as printed
    if config.forgetting == "exponential":
        P_next = P_next / config.rho  # Eq. 30 corrected
    p, m = theta.shape[1], theta.shape[0]
    n = p // 2
    block_max = config.block_trace_max(n, (m - p - 1) // n - 1)
    if block_max is None:
        clipped = config.trace_max is not None and np.trace(P_next) > config.trace_max
        if clipped:
            P_next = P_next * (config.trace_max / np.trace(P_next))  # wind-up guard
    else:  # each block of P (δx, the inputs and constant rows) within its bound, by S P S
        blocks = (slice(0, p), slice(p, m - 1), slice(m - 1, m))
        scale = np.ones(m)
        for block, bound in zip(blocks, block_max, strict=True):
            trace = np.trace(P_next[block, block])
            if trace > bound:
                scale[block] = np.sqrt(bound / trace)
        clipped = bool((scale < 1.0).any())
        P_next = P_next * np.outer(scale, scale)
    return theta_next, P_next, RlsStep(residual, gamma, float(np.trace(P_next)), clipped)
