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

An input that reaches the arm late. When the command decided at ``kT`` is applied over
``[kT + τ, (k+1)T + τ)`` (a driver that writes it at its next cycle, a drive that adds a cycle of
its own), the exact discrete model has more than one input matrix (the zero-order hold with a
fractional input delay: G. F. Franklin, J. D. Powell and M. L. Workman, *Digital Control of
Dynamic Systems*, 3rd ed., Addison-Wesley 1998, sec. 4.3.4). With ``τ = d T + f``,
``0 <= f < T``, the period ``[kT, (k+1)T)`` holds ``u(k-d-1)`` for ``f`` and ``u(k-d)`` after it:

    x(k+1) = F x(k) + G_d u(k-d) + G_(d+1) u(k-d-1),
    G_d = Γ(T - f),   G_(d+1) = Γ(T) - Γ(T - f),   Γ(s) = integral_0^s exp(A t) dt B,

so the input matrices sum to Eq. 33's ``G``. :func:`split_input_matrix` gives them with the
same truncated series as Eq. 33b (``Γ(s) = B s + A B s^2/2 + A^2 B s^3/6``).
"""

from __future__ import annotations

from collections.abc import Callable
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


def input_series(
    A: np.ndarray, B: np.ndarray, duration: float, form: SeriesForm = "corrected"
) -> np.ndarray:
    """``Γ(s)``, the effect of an input held for ``duration = s`` seconds, by Eq. 33b's series
    (``form`` as in :func:`discretize_series`; ``Γ(T)`` is Eq. 33b's ``G``)."""
    s = float(duration)
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    AB = A @ B
    if form == "corrected":
        return B * s + AB * (s**2 / 2.0) + (A @ AB) * (s**3 / 6.0)
    if form == "printed":
        return B * s + AB * s**2 + (A @ AB) * (s**3 / 2.0)
    raise LinearizeError(f"form must be 'corrected' or 'printed', got {form!r}")


def split_input_matrix(
    A: np.ndarray,
    B: np.ndarray,
    period: float,
    delay: float,
    input_lags: int,
    form: SeriesForm = "corrected",
) -> np.ndarray:
    """``[G_0 G_1 … G_L]`` of an input applied ``delay`` seconds after its sample (module
    docstring), shape (p, (L+1) n); they sum to Eq. 33b's ``G``.

    A delay longer than the ``input_lags`` periods the model carries is taken as ``L T`` (all
    of ``G`` in ``G_L``).
    """
    if not period > 0.0:
        raise LinearizeError(f"period must be > 0, got {period}")
    if not (np.isfinite(delay) and delay >= 0.0):
        raise LinearizeError(f"delay must be finite and >= 0 s, got {delay}")
    if isinstance(input_lags, bool) or not isinstance(input_lags, int) or input_lags < 0:
        raise LinearizeError(f"input_lags must be an int >= 0, got {input_lags!r}")
    B = np.asarray(B, dtype=float)
    p, n = B.shape
    out = np.zeros((p, (input_lags + 1) * n))
    _split_into(out, lambda s: input_series(A, B, s, form), period, delay, input_lags, n)
    return out


def _split_into(
    inputs: np.ndarray,
    gamma: Callable[[float], np.ndarray],
    period: float,
    delay: float,
    input_lags: int,
    n: int,
) -> None:
    """Write ``[G_0 … G_L]`` of an input applied ``delay`` s after its sample into the zeroed
    ``inputs`` (p, (L+1) n), ``gamma(s)`` being ``Γ(s)``: all of ``Γ(T)`` at the delay's lag,
    or ``Γ(T - f)`` there and the rest at the next (the module docstring)."""
    T = float(period)
    delay = min(float(delay), input_lags * T)
    d = min(int(delay // T), input_lags)
    f = delay - d * T
    G = gamma(T)
    if d == input_lags or f <= 0.0:
        inputs[:, d * n : (d + 1) * n] = G
        return
    G_d = gamma(T - f)
    inputs[:, d * n : (d + 1) * n] = G_d
    np.subtract(G, G_d, out=inputs[:, (d + 1) * n : (d + 2) * n])


class SetpointLinearization:
    """``[F G₀ … G_L]`` of :func:`initial_model` at set point after set point, for a law that
    re-linearises every sample (``relinearize``): the same series, the workspace made once, the
    powers of ``A`` shared by ``F`` and the split, and no argument checks (the law's set points
    are checked where they enter it). Equal to :func:`initial_model` to rounding.

    Parameters
    ----------
    model : pinocchio.Model
        The controller's model.
    period : float
        Sampling period T (s).
    form : {"corrected", "printed"}
        Eq. 33b's series, as in :func:`discretize_series`.
    input_lags : int
        Input matrices after ``G₀`` (0: Eq. 33's ``F, G``).
    """

    def __init__(
        self, model: pin.Model, period: float, form: SeriesForm = "corrected", input_lags: int = 0
    ) -> None:
        if not period > 0.0:
            raise LinearizeError(f"period must be > 0, got {period}")
        if form not in ("corrected", "printed"):
            raise LinearizeError(f"form must be 'corrected' or 'printed', got {form!r}")
        n = model.nv
        self.model, self.data = model, model.createData()
        self.period, self.input_lags, self._n = float(period), int(input_lags), n
        # Γ(s) = B s + A B s² c₂ + A² B s³ c₃ (Eq. 33b's series, corrected or printed).
        self._c2, self._c3 = (0.5, 1.0 / 6.0) if form == "corrected" else (1.0, 0.5)
        self._A = np.zeros((2 * n, 2 * n))
        self._A[:n, n:] = np.eye(n)
        self._B = np.zeros((2 * n, n))
        self._eye = np.eye(2 * n)

    def __call__(
        self, q: np.ndarray, qd: np.ndarray, tau: np.ndarray, delay: float = 0.0
    ) -> np.ndarray:
        """``[F G₀ … G_L]`` (a fresh array, shape (2n, 2n + (L+1) n)) at ``(q, qd, tau)``, the
        input split by ``delay`` (s) as :func:`split_input_matrix` splits it."""
        n, T, lags = self._n, self.period, self.input_lags
        A, B = self._A, self._B
        ddq_dq, ddq_dv, minv = pin.computeABADerivatives(self.model, self.data, q, qd, tau)
        A[n:, :n] = ddq_dq
        A[n:, n:] = ddq_dv
        np.add(minv, minv.T, out=B[n:])
        B[n:] *= 0.5
        A2 = A @ A
        AB = A @ B
        A2B = A @ AB
        p = 2 * n
        out = np.zeros((p, p + (lags + 1) * n))
        np.add(self._eye, A * T, out=out[:, :p])
        out[:, :p] += A2 * (T * T / 2.0)

        def gamma(s: float) -> np.ndarray:
            return B * s + AB * (s * s * self._c2) + A2B * (s * s * s * self._c3)

        _split_into(out[:, p:], gamma, T, delay, lags, n)
        return out


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
    *,
    delay: float = 0.0,
    input_lags: int = 0,
    data: pin.Data | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``F(0), G(0)`` of Eq. 33 at the first nominal point ``(q_d(0), qd_d(0), u_n(0))``;
    with ``input_lags``, ``G(0)`` split by ``delay`` (:func:`split_input_matrix`). ``data``:
    the model's workspace, for a caller that linearises every sample (made here if None).

    Returns
    -------
    F0 : (2n, 2n) ndarray
    G0 : (2n, n) ndarray, or (2n, (L+1) n) with lags
    """
    A, B = continuous_jacobians(model, model.createData() if data is None else data, q, qd, tau)
    F, G = discretize_series(A, B, period, form)
    if input_lags == 0 and delay == 0.0:
        return F, G
    return F, split_input_matrix(A, B, period, delay, input_lags, form)
