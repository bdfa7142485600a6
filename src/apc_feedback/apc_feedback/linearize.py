"""Linearised perturbation model about a nominal point, and its discretisation (Eqs. 14-20, 33).

The state-space form of Eq. 11-12 is ``x' = f(x, u)`` with ``x = (q, q')``. Its Jacobians at a
nominal point (Eq. 14) are

    A = [[0, I], [d q''/d q, d q''/d q']],   B = [[0], [D(q)^-1]],

taken from Pinocchio's analytical ABA derivatives (``computeABADerivatives``) on the
*controller's* model. Where that model has joint friction (``model.damping`` viscous b,
``model.friction`` Coulomb f: :func:`apc_feedforward.nominal.joint_friction`), which ABA
leaves out, the nominal torque carries it, ``u_n = RNEA + b q' + f tanh(q' / v_s)``; the
arm's acceleration under ``u_n`` is then ABA's under ``u_n`` less that friction, and the
viscous part slows the arm, ``d q''/d q' -= D^-1 b``. The Coulomb term's slope is its
smoothing's (``f / v_s`` at rest, thousands of N m s/rad), not the arm's: a perturbation about
a moving set point meets the same Coulomb level, so it is left out of ``A``.

Eq. 33 gives the initial discrete model ``F(0), G(0)`` as a truncated series of the
zero-order-hold discretisation:

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

A velocity estimated from positions. Eq. 16's state is the arm's ``(q, q')``; robot mode, when
the driver sends no velocity, samples ``(q, v̂)`` with ``v̂(k) = Σ_i w_i q(kT - s_i)`` (a
:class:`VelocityStencil`: the parabola through the last three states). ``v̂`` lags ``q'`` by what
the inputs did over the stencil's span: ``y(k) = (q(k), v̂(k)) = M x(k) + Σ_j N_j u(k-j)``, with
``M = [[I, 0], [Σ_i w_i C Φ(-s_i)]]`` (``C = [I 0]``, ``Φ(s) = exp(A s)``) and ``N_j`` the
inputs' share of the positions at ``kT - s_i``. The exact model of ``y`` is then

    y(k+1) = F_y y(k) + Σ_j G_y,j u(k-j),   F_y = M F M^-1,   G_y,j = M G_j - F_y N_j + N_(j+1),

(:func:`sampled_coordinates`; ``Φ`` and ``Γ`` by Eq. 33's series). On a 100 Hz driver at
``T = 10 ms`` the parabola spans two periods and the command acts one period late: for a
double integrator ``G_y = [0, (T²/2, 3T/4), (T²/4, T/2), (-T²/4, -T/4)] D^-1`` against
Eq. 33's ``[0, (T²/2, T), 0, 0] D^-1``; the matrices sum to Eq. 33's ``G`` there (to a few
per mille on an arm, whose own dynamics act over the stencil's span).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np
import pinocchio as pin
import scipy.linalg

from apc_feedforward.nominal import JointFriction, friction_torque, joint_friction

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


def _aba_derivatives(
    model: pin.Model,
    data: pin.Data,
    q: np.ndarray,
    qd: np.ndarray,
    tau: np.ndarray,
    friction: JointFriction | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``d qdd / dq``, ``d qdd / dqd`` and ``D^-1`` (symmetrised) of the arm at ``(q, qd,
    tau)`` with its joints' ``friction``: ABA has none, so it runs at ``tau``'s rigid-body
    part (``tau`` less the friction at ``qd``, as :func:`apc_feedforward.nominal.nominal_torque`
    adds it) and the viscous friction's slope ``D^-1 b`` leaves the velocity block. The Coulomb
    term's slope (steep through zero speed, flat elsewhere) is left out."""
    if friction is not None:
        tau = tau - friction_torque(friction, qd)
    ddq_dq, ddq_dv, minv = pin.computeABADerivatives(model, data, q, qd, tau)
    minv = 0.5 * (minv + minv.T)
    if friction is not None:
        ddq_dv = ddq_dv - minv * friction.viscous
    return ddq_dq, ddq_dv, minv


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
    ddq_dq, ddq_dv, minv = _aba_derivatives(model, data, q, qd, tau, joint_friction(model))
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


class VelocityStencil(NamedTuple):
    """A sampled velocity made of positions: ``v̂(k) = Σ_i weights[i] q(kT - offsets[i])``
    (offsets in s, >= 0; weights in 1/s, summing to 0)."""

    offsets: tuple[float, ...]
    weights: tuple[float, ...]


#: A delay this fraction of a period past a whole number of periods needs no lag more (its
#: share of one is under this): a delay measured on a driver's clock carries its estimated
#: period (a 100 Hz driver at 10.00013 ms showed 20.00026 ms, which asked for a fourth lag,
#: one more than a model carries, so the delay was not told and the law tripped).
LAG_SLACK = 0.01


def stencil_span(stencil: VelocityStencil | None) -> float:
    """How far back the positions of a sampled velocity reach (s): 0 for a measured one."""
    return max(stencil.offsets) if stencil is not None and stencil.offsets else 0.0


def stencil_lags(stencil: VelocityStencil | None, period: float, delay: float) -> int:
    """The input lags the exact model of a sample needs: the inputs that acted over the
    stencil's span (:func:`stencil_span`) or are still on their way, ``ceil((delay + span) /
    T)`` (within :data:`LAG_SLACK` of a whole number, that number)."""
    return math.ceil((delay + stencil_span(stencil)) / period - LAG_SLACK)


#: ``c₂, c₃`` of Eq. 33b's series ``Γ(s) = B s + A B s² c₂ + A² B s³ c₃`` in each form.
_SERIES_COEFFICIENTS: dict[str, tuple[float, float]] = {
    "corrected": (0.5, 1.0 / 6.0),
    "printed": (1.0, 0.5),
}


class _Series:
    """``A``, ``B`` and the products Eq. 33's series needs; ``Γ(s) = B s + A B s² c₂ + A² B s³
    c₃`` (``c₂, c₃``: its corrected or printed form)."""

    def __init__(self, A: np.ndarray, B: np.ndarray, c2: float, c3: float) -> None:
        self.A, self.B, self.A2 = A, B, A @ A
        self.AB = A @ B
        self.A2B = A @ self.AB
        self.c2, self.c3 = c2, c3

    def gamma(self, s: float) -> np.ndarray:
        return self.B * s + self.AB * (s * s * self.c2) + self.A2B * (s * s * s * self.c3)


def sampled_coordinates(
    F: np.ndarray,
    series: _Series,
    period: float,
    delay: float,
    stencil: VelocityStencil,
    input_lags: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``F_y, [G_y,0 … G_y,L]``: Eq. 33's ``F`` and its input split by ``delay``, in the
    coordinates of a sample whose velocity is ``stencil`` of positions (the module docstring).

    The exact model may need more lags than ``input_lags`` (:func:`stencil_lags`); those beyond
    are added to ``G_L``, so that the matrices' sum, the effect of a held input, is kept.
    """
    p = F.shape[0]
    sampled = _SampledCoordinates(series, F, stencil)
    G = np.empty((p, (input_lags + 1) * (p // 2)))
    sampled.inputs(G, period, delay, input_lags)
    return sampled.F, G


#: Powers of ``A`` in a piece of :func:`_piece_coefficients`: ``C A^m B``, m = 0 … 6.
_PIECE_POWERS = 7


@functools.lru_cache(maxsize=64)
def _piece_coefficients(
    stencil: VelocityStencil, period: float, delay: float, lags: int, c2: float, c3: float
) -> np.ndarray:
    """``K`` (lags + 2, 7) with ``Nv_j = Σ_m K[j, m] C A^m B``: the inputs' share of ``v̂``.

    ``x(kT - s) = Φ(-s) (x(k) - Σ pieces Φ(-b) Γ(b - a) u(k-j))``, ``u(k-j)`` acting over
    ``[a, b]`` within ``[-s, 0]``; with Eq. 33's series ``C Φ(-s) = C (I - A s + A² s²/2)``,
    ``Φ(-b) = I - A b + A² b²/2``, ``Γ(L) = B L + A B L² c₂ + A² B L³ c₃``, each piece is a
    polynomial in ``A`` whose scalar coefficients depend only on the timing: made once per
    timing, the per-sample work is the powers ``C A^m B``.
    """
    T = period
    K = np.zeros((lags + 2, _PIECE_POWERS))
    for s, w in zip(stencil.offsets, stencil.weights, strict=True):
        back = (w, -w * s, w * s * s / 2.0)
        for j in range(1, lags + 2):
            a, b = max(-s, -j * T + delay), min(0.0, (1 - j) * T + delay)
            if b <= a:
                continue
            L = b - a
            phi = (1.0, -b, b * b / 2.0)
            gamma = (L, L * L * c2, L * L * L * c3)
            for alpha, x in enumerate(back):
                for beta, y in enumerate(phi):
                    for power, z in enumerate(gamma):
                        K[j, alpha + beta + power] -= x * y * z
    K.setflags(write=False)
    return K


class _SampledCoordinates:
    """The parts of :func:`sampled_coordinates` that do not depend on the delay (``M``,
    ``F_y = M F M⁻¹``, ``w_i C Φ(-s_i)``), and the input matrices for a delay
    (:meth:`inputs`), batched over the stencil's pieces."""

    def __init__(self, series: _Series, F: np.ndarray, stencil: VelocityStencil) -> None:
        p = F.shape[0]
        n = p // 2
        self.series, self.stencil, self.n = series, stencil, n
        offsets = np.asarray(stencil.offsets, dtype=float)
        weights = np.asarray(stencil.weights, dtype=float)
        # w_i C Φ(-s_i), C = [I 0]: C Φ(t) = C + (C A) t + (C A²) t²/2.
        C = np.zeros((n, p))
        C[:, :n] = np.eye(n)
        self.backs = weights[:, None, None] * (
            C
            - series.A[:n] * offsets[:, None, None]
            + series.A2[:n] * (offsets * offsets / 2.0)[:, None, None]
        )
        M = np.eye(p)
        M[n:] = self.backs.sum(axis=0)  # v̂ = V x(k) + …
        # C A^m B, m = 0 … 6: the inputs' share of v̂ for any delay (:meth:`inputs`).
        self._powers = np.empty((_PIECE_POWERS, n * n))
        AmB = series.B
        for m in range(_PIECE_POWERS):
            self._powers[m] = AmB[:n].ravel()
            if m + 1 < _PIECE_POWERS:
                AmB = series.A @ AmB
        self.M = M
        self.F = np.linalg.solve(M.T, (M @ F).T).T  # M F M⁻¹, solved

    def inputs(self, out: np.ndarray, period: float, delay: float, input_lags: int) -> None:
        """Write ``[G_y,0 … G_y,L]`` of ``delay`` into ``out`` (p, (L+1) n)."""
        series, n, T = self.series, self.n, float(period)
        p = 2 * n
        lags = max(input_lags, stencil_lags(self.stencil, T, delay))
        steps = np.zeros((p, (lags + 2) * n))
        _split_into(steps, series.gamma, T, delay, lags + 1, n)
        # v̂'s share of the inputs, Nv_j = Σ_m K[j, m] C A^m B (:func:`_piece_coefficients`).
        K = _piece_coefficients(self.stencil, T, float(delay), lags, series.c2, series.c3)
        Nv = (K @ self._powers).reshape(lags + 2, n, n)
        # G_y,j = M G_j - F_y N_j + N_(j+1), N_j = [0; Nv_j]; lags beyond input_lags folded.
        G = (self.M @ steps).reshape(p, lags + 2, n).transpose(1, 0, 2)[: lags + 1]
        G -= self.F[:, n:] @ Nv[: lags + 1]
        G[:, n:] += Nv[1:]
        if lags > input_lags:
            G[input_lags] += G[input_lags + 1 :].sum(axis=0)
        out[:] = G[: input_lags + 1].transpose(1, 0, 2).reshape(p, (input_lags + 1) * n)


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
        self._c2, self._c3 = _SERIES_COEFFICIENTS[form]
        self._A = np.zeros((2 * n, 2 * n))
        self._A[:n, n:] = np.eye(n)
        self._B = np.zeros((2 * n, n))
        self._eye = np.eye(2 * n)
        self._friction = joint_friction(model)

    def __call__(
        self,
        q: np.ndarray,
        qd: np.ndarray,
        tau: np.ndarray,
        delay: float = 0.0,
        stencil: VelocityStencil | None = None,
    ) -> np.ndarray:
        """``[F G₀ … G_L]`` (a fresh array, shape (2n, 2n + (L+1) n)) at ``(q, qd, tau)``, the
        input split by ``delay`` (s) as :func:`split_input_matrix` splits it; with a
        ``stencil``, in the coordinates of a sample whose velocity it is
        (:func:`sampled_coordinates`)."""
        n, T, lags = self._n, self.period, self.input_lags
        A, B = self._A, self._B
        A[n:, :n], A[n:, n:], B[n:] = _aba_derivatives(
            self.model, self.data, q, qd, tau, self._friction
        )
        series = _Series(A.copy(), B.copy(), self._c2, self._c3)
        p = 2 * n
        out = np.zeros((p, p + (lags + 1) * n))
        np.add(self._eye, A * T, out=out[:, :p])
        out[:, :p] += series.A2 * (T * T / 2.0)
        if stencil is not None and lags:
            sampled = _SampledCoordinates(series, out[:, :p], stencil)
            out[:, :p] = sampled.F
            sampled.inputs(out[:, p:], T, delay, lags)
            self._last: tuple[_Series, np.ndarray, _SampledCoordinates | None] = (
                series,
                out,
                sampled,
            )
        else:
            _split_into(out[:, p:], series.gamma, T, delay, lags, n)
            self._last = (series, out, None)
        return out

    def with_delay(self, delay: float) -> np.ndarray:
        """The last call's ``[F G₀ … G_L]`` with the input split by another ``delay`` (a fresh
        array; the linearisation and the stencil's delay-free parts reused)."""
        series, last, sampled = self._last
        p = 2 * self._n
        out = last.copy()
        if sampled is not None:
            sampled.inputs(out[:, p:], self.period, delay, self.input_lags)
        else:
            out[:, p:] = 0.0
            _split_into(out[:, p:], series.gamma, self.period, delay, self.input_lags, self._n)
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
    stencil: VelocityStencil | None = None,
    data: pin.Data | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``F(0), G(0)`` of Eq. 33 at the first nominal point ``(q_d(0), qd_d(0), u_n(0))``;
    with ``input_lags``, ``G(0)`` split by ``delay`` (:func:`split_input_matrix`) and, with a
    ``stencil`` as well, the model of a sample whose velocity it is
    (:func:`sampled_coordinates`). ``data``: the model's workspace, for a caller that
    linearises every sample (made here if None).

    Returns
    -------
    F0 : (2n, 2n) ndarray
    G0 : (2n, n) ndarray, or (2n, (L+1) n) with lags
    """
    A, B = continuous_jacobians(model, model.createData() if data is None else data, q, qd, tau)
    F, G = discretize_series(A, B, period, form)
    if input_lags == 0 and delay == 0.0:
        return F, G
    if stencil is not None and input_lags:
        series = _Series(A, B, *_SERIES_COEFFICIENTS[form])
        return sampled_coordinates(F, series, period, delay, stencil, input_lags)
    return F, split_input_matrix(A, B, period, delay, input_lags, form)
