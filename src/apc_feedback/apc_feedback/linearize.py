"""Linearised perturbation model about a nominal point, and its discretisation (Eqs. 14-20, 33).

The state-space form of Eq. 11-12 is ``x' = f(x, u)`` with ``x = (q, q')``. Its Jacobians at a
nominal point (Eq. 14) are

    A = [[0, I], [d q''/d q, d q''/d q']],   B = [[0], [D(q)^-1]],

taken from Pinocchio's analytical ABA derivatives (``computeABADerivatives``) on the
*controller's* model. Eq. 33 gives the initial discrete model ``F(0), G(0)`` as a truncated
series of the zero-order-hold discretisation:

    F(0) = I + A T + A^2 T^2 / 2                               (Eq. 33a)
    G(0) = B T + A B T^2 / 2 + A^2 B T^3 / 6                   (Eq. 33b, corrected)

The paper prints Eq. 33b as ``B T + A B T^2 + A^2 B T^3 / 2``; the exact zero-order hold,
``G = integral_0^T exp(A s) ds B = B T + A B T^2/2! + A^2 B T^3/3! + ...``, has the factorials.
The printed form stays selectable (``form="printed"``) for comparison.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pinocchio as pin
import scipy.linalg

SeriesForm = Literal["corrected", "printed"]


class LinearizeError(ValueError):
    """Bad arguments to the linearisation; the message names the argument."""


def _vector(value: np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise LinearizeError(f"{name} must have shape ({n},), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise LinearizeError(f"{name} must be finite")
    return arr


def continuous_jacobians(
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians ``A = df/dx (2n, 2n)`` and ``B = df/du (2n, n)`` of Eq. 12 at ``(q, qd, tau)``.

    Eq. 14: ``A = grad_x f |_n``, ``B = grad_u f |_n`` at the nominal state and torque.

    Parameters
    ----------
    q, qd, tau : (n,) array_like
        Nominal position (rad), velocity (rad/s) and torque (N m).
    """
    n = model.nv
    q = _vector(q, n, "q")
    qd = _vector(qd, n, "qd")
    tau = _vector(tau, n, "tau")
    ddq_dq, ddq_dv, minv = pin.computeABADerivatives(model, data, q, qd, tau)
    minv = 0.5 * (minv + minv.T)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = ddq_dq
    A[n:, n:] = ddq_dv
    B = np.zeros((2 * n, n))
    B[n:, :] = minv
    return A, B


def discretize_series(
    A: np.ndarray, B: np.ndarray, period: float, form: SeriesForm = "corrected"
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 33: truncated-series ``F(0), G(0)`` of the zero-order-hold discretisation.

    Parameters
    ----------
    A : (p, p) ndarray
    B : (p, n) ndarray
    period : float
        Sampling period T (s).
    form : {"corrected", "printed"}
        ``"corrected"``: ``G = B T + A B T^2/2 + A^2 B T^3/6``; ``"printed"``: the paper's
        ``G = B T + A B T^2 + A^2 B T^3/2``. ``F = I + A T + A^2 T^2/2`` in both.

    Returns
    -------
    F : (p, p) ndarray
    G : (p, n) ndarray
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    p = A.shape[0]
    if A.shape != (p, p) or B.ndim != 2 or B.shape[0] != p:
        raise LinearizeError(f"A must be (p, p) and B (p, n); got {A.shape} and {B.shape}")
    if not period > 0.0:
        raise LinearizeError(f"period must be > 0, got {period}")
    T = float(period)
    A2 = A @ A
    F = np.eye(p) + A * T + A2 * (T**2 / 2.0)
    if form == "corrected":
        G = B * T + (A @ B) * (T**2 / 2.0) + (A2 @ B) * (T**3 / 6.0)
    elif form == "printed":
        G = B * T + (A @ B) * T**2 + (A2 @ B) * (T**3 / 2.0)
    else:
        raise LinearizeError(f"form must be 'corrected' or 'printed', got {form!r}")
    return F, G


def discretize_exact(A: np.ndarray, B: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation (Eqs. 19-20 with constant A, B).

    ``expm([[A, B], [0, 0]] T) = [[F, G], [0, I]]``.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    p, n = B.shape
    M = np.zeros((p + n, p + n))
    M[:p, :p] = A
    M[:p, p:] = B
    E = scipy.linalg.expm(M * float(period))
    return E[:p, :p], E[:p, p:]


def initial_model(
    model: pin.Model,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    period: float,
    form: SeriesForm = "corrected",
) -> tuple[np.ndarray, np.ndarray]:
    """``F(0), G(0)`` of Eq. 33 at the first nominal point ``(q_d(0), qd_d(0), u_n(0))``.

    Returns
    -------
    F0 : (2n, 2n) ndarray
    G0 : (2n, n) ndarray
    """
    A, B = continuous_jacobians(model, model.createData(), q, qd, tau)
    return discretize_series(A, B, period, form)
