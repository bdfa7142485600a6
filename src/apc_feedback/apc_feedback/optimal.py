"""One-step optimal perturbation control (paper Eqs. 34-35, Eq. 35 corrected).

At each sample the feedback minimises the one-step cost of Eq. 34,

    J(k) = ½ [x(k+1)ᵀ Q x(k+1) + u(k)ᵀ R u(k)],

subject to the identified model of Eq. 16, ``x(k+1) = F x(k) + G u(k) + w``. Here ``x`` is
the perturbation state δx ∈ R^p (p = 2n for an arm) and ``u`` the perturbation torque
δu ∈ R^n. Setting ``∂J/∂u = Gᵀ Q (F x + G u + w) + R u = 0`` gives the exact minimiser

    u* = -(R + Gᵀ Q G)⁻¹ Gᵀ Q (F x + w)            (Eq. 35 corrected, ``form="exact"``)

unique because ``R ≻ 0`` and ``Q ⪰ 0`` make ``R + Gᵀ Q G ≻ 0``. The paper prints

    u  = -(R + Gᵀ Q G)⁻¹ Gᵀ Q F (x + w)            (Eq. 35 as printed, ``form="printed"``)

which applies ``F`` to the bias as well; the two agree when ``w = 0`` or ``F = I``. The
printed form stays selectable to reproduce the paper as written.

:func:`one_step_control` writes Eq. 35 as above, for any ``Q`` and ``R``, and is the readable
reference; :class:`OneStepControl` computes the same ``u*`` every sample for a diagonal ``Q``
from preallocated buffers, and the tests hold the two equal. The linear system is solved
(LAPACK's Cholesky solver ``dposv``: ``R + Gᵀ Q G`` is symmetric positive definite), never
inverted. :func:`receding_horizon_control` looks ``N`` steps ahead instead of one;
:class:`RecedingHorizonControl` is its per-sample form, held equal to it by the tests in the same
way. No ROS here.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np
from scipy.linalg import lapack

from apc_feedback.arrays import all_true, finite_array

__all__ = [
    "ControlError",
    "OneStepControl",
    "RecedingHorizonControl",
    "one_step_control",
    "one_step_cost",
    "receding_horizon_control",
    "validate_weights",
]

Form = Literal["exact", "printed"]
_FORMS: tuple[str, ...] = ("exact", "printed")


class ControlError(ValueError):
    """A bad argument to the one-step optimal control (the message names it)."""


# ---------------------------------------------------------------------------------- validation
def _array(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a finite float64 array of exactly ``shape``."""
    return finite_array(name, value, shape, ControlError)


def _model(F: Any, G: Any) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Validate F (p, p) and G (p, n); return them with p and n."""
    try:
        Fa = np.asarray(F, dtype=float)
    except (TypeError, ValueError):
        raise ControlError("F must be a real (p, p) array") from None
    if Fa.ndim != 2 or Fa.shape[0] != Fa.shape[1] or Fa.shape[0] < 1:
        raise ControlError(f"F must be square (p, p) with p >= 1, got shape {Fa.shape}")
    p = Fa.shape[0]
    if not np.isfinite(Fa).all():
        raise ControlError("F must be finite")
    try:
        Ga = np.asarray(G, dtype=float)
    except (TypeError, ValueError):
        raise ControlError(f"G must be a real ({p}, n) array") from None
    if Ga.ndim != 2 or Ga.shape[0] != p or Ga.shape[1] < 1:
        raise ControlError(f"G must have shape ({p}, n) with n >= 1, got {Ga.shape}")
    if not np.isfinite(Ga).all():
        raise ControlError("G must be finite")
    return Fa, Ga, p, Ga.shape[1]


def validate_weights(Q: Any, R: Any, p: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Check the weights of Eq. 34 once.

    Parameters
    ----------
    Q : array_like, shape (p, p)
        State weight, symmetric positive semidefinite (symmetric to a relative 1e-10).
    R : array_like, shape (n, n)
        Input weight, symmetric positive definite.
    p, n : int
        State and input dimensions.

    Returns
    -------
    (Q, R) : tuple of numpy.ndarray
        The weights as float64 arrays, exactly symmetrised.

    Raises
    ------
    ControlError
        "Q must ..." / "R must ..." on a wrong shape, a non-finite entry, asymmetry, ``Q`` with
        a negative eigenvalue, or ``R`` not positive definite.
    """
    Qa = _array("Q", Q, (p, p))
    Ra = _array("R", R, (n, n))
    for name, a in (("Q", Qa), ("R", Ra)):
        scale = max(1.0, float(np.max(np.abs(a))))
        if np.max(np.abs(a - a.T)) > 1e-10 * scale:
            raise ControlError(f"{name} must be symmetric")
    Qa = 0.5 * (Qa + Qa.T)
    Ra = 0.5 * (Ra + Ra.T)
    eig_q = np.linalg.eigvalsh(Qa)
    if eig_q[0] < -1e-10 * max(1.0, float(np.max(np.abs(eig_q)))):
        raise ControlError(f"Q must be positive semidefinite (smallest eigenvalue {eig_q[0]:.3g})")
    try:
        np.linalg.cholesky(Ra)
    except np.linalg.LinAlgError:
        raise ControlError("R must be positive definite") from None
    return Qa, Ra


def _weights(Q: Any, R: Any, p: int, n: int, check: bool) -> tuple[np.ndarray, np.ndarray]:
    if check:
        return validate_weights(Q, R, p, n)
    return np.asarray(Q, dtype=float), np.asarray(R, dtype=float)


def _solve_spd(S: np.ndarray, rhs: np.ndarray, finite: np.ndarray | None = None) -> np.ndarray:
    """Solve ``S X = rhs`` for the symmetric positive definite ``S = R + Gᵀ Q G`` by Cholesky
    (LAPACK ``dposv`` from the upper triangle: a fifth of ``numpy.linalg.solve`` at these
    sizes, and no symmetrising copy). ``finite``, a boolean buffer of ``rhs``'s shape, takes
    the finiteness check's temporary (a per-sample caller's)."""
    _, X, info = lapack.dposv(S, rhs)
    if info != 0:
        raise ControlError("R + Gᵀ Q G is not positive definite (check R)")
    if not all_true(np.isfinite(X, out=finite), axis=None):
        raise ControlError("R + Gᵀ Q G is too ill-conditioned: the solution is not finite")
    return X


def _diagonal_weights(q_diagonal: Any, R: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q, Q, R)`` of a per-sample controller: the diagonal ``q`` of ``Q`` (shape (p,)),
    ``Q = diag(q)`` and ``R`` (n, n), checked by :func:`validate_weights`."""
    q = np.array(q_diagonal, dtype=float)
    if q.ndim != 1 or q.shape[0] < 1:
        raise ControlError(f"q_diagonal must have shape (p,), got {q.shape}")
    R = np.asarray(R, dtype=float)
    n = R.shape[0] if R.ndim == 2 else 0
    Q, R = validate_weights(np.diag(q), R, q.shape[0], n)
    return q, Q, R


# ---------------------------------------------------------------------------------- public API
def one_step_control(
    F: Any,
    G: Any,
    w: Any,
    Q: Any,
    R: Any,
    x: Any,
    form: Form = "exact",
    *,
    check_weights: bool = True,
) -> np.ndarray:
    """One-step optimal perturbation torque ``u*(k)`` (Eq. 35).

    ``form="exact"`` (default) returns the minimiser of Eq. 34 subject to Eq. 16::

        u* = -(R + Gᵀ Q G)⁻¹ Gᵀ Q (F x + w)

    ``form="printed"`` returns Eq. 35 as printed, ``-(R + Gᵀ Q G)⁻¹ Gᵀ Q F (x + w)``; it
    differs from the exact form when ``F ≠ I`` and ``w ≠ 0``.

    Parameters
    ----------
    F : array_like, shape (p, p)
    G : array_like, shape (p, n)
    w : array_like, shape (p,)
        F̂, Ĝ, ŵ of Eq. 16 (e.g. :attr:`apc_feedback.rls.Rls.F` etc.).
    Q : array_like, shape (p, p)
        Symmetric positive semidefinite.
    R : array_like, shape (n, n)
        Symmetric positive definite.
    x : array_like, shape (p,)
        Current perturbation state δx(k) = x(k) - x_n(k).
    form : {"exact", "printed"}
    check_weights : bool, keyword-only
        Validate ``Q`` and ``R`` (default). Pass False in a hot loop only after checking them
        once with :func:`validate_weights`.

    Returns
    -------
    numpy.ndarray, shape (n,)
        δu(k), in the units of ``u`` in the model (N·m for joint torques).

    Raises
    ------
    ControlError
        On wrong shapes, non-finite entries, ``Q`` not symmetric PSD, ``R`` not symmetric
        positive definite, ``R + Gᵀ Q G`` numerically singular, or a bad ``form``.
    """
    if form not in _FORMS:
        raise ControlError(f"form must be one of {', '.join(_FORMS)}, got {form!r}")
    Fa, Ga, p, n = _model(F, G)
    wa = _array("w", w, (p,))
    xa = _array("x", x, (p,))
    Qa, Ra = _weights(Q, R, p, n, check_weights)
    y = Fa @ xa + wa if form == "exact" else Fa @ (xa + wa)  # F x + w, or F (x + w) as printed
    GtQ = Ga.T @ Qa
    return -_solve_spd(Ra + GtQ @ Ga, GtQ @ y)  # -(R + Gᵀ Q G)⁻¹ Gᵀ Q y (Eq. 35)


class OneStepControl:
    """Eq. 35 for the per-sample loop: fixed diagonal ``Q`` and ``R``, preallocated buffers.

    Takes the identified model as the RLS holds it, ``Θᵀ = [F G w]`` (p, p + n + 1), so
    ``F x + w`` is one product with ``(x, 0, 1)``. ``S = R + Gᵀ Q G`` is symmetric positive
    definite and solved by Cholesky (LAPACK ``dposv``, from one triangle of ``S``), which
    costs a fifth of ``numpy.linalg.solve`` at this size. Equals :func:`one_step_control`
    with ``Q = diag(q_diagonal)`` to rounding (the tests check 1e-12).

    Parameters
    ----------
    q_diagonal : array_like, shape (p,)
        Diagonal of ``Q``, finite and >= 0.
    R : array_like, shape (n, n)
        Symmetric positive definite.
    form : {"exact", "printed"}
        As in :func:`one_step_control`.

    Raises
    ------
    ControlError
        On construction, for bad weights or form (the message names it).
    """

    def __init__(self, q_diagonal: Any, R: Any, form: Form = "exact") -> None:
        if form not in _FORMS:
            raise ControlError(f"form must be one of {', '.join(_FORMS)}, got {form!r}")
        q, _, R = _diagonal_weights(q_diagonal, R)
        p, n = q.shape[0], R.shape[0]
        self.p, self.n = p, n
        self.q_diagonal = q
        self.R = R
        self.exact = form == "exact"
        self._xa = np.zeros(p + n + 1)
        self._xa_x = self._xa[:p]
        self._y = np.empty(p)
        self._gtq = np.empty((n, p))
        self._S = np.empty((n, n))
        self._b = np.empty(n)

    def __call__(self, model_t: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``δu(k)`` for the model ``Θᵀ = [F G w]`` and the state ``x`` (both finite).

        Raises
        ------
        ControlError
            If ``R + Gᵀ Q G`` is not numerically positive definite or the result is not
            finite.
        """
        # Each line names the term of Eq. 35 it computes; model_t = Θᵀ = [F G w].
        p, xa = self.p, self._xa
        if self.exact:
            self._xa_x[:] = x  # xa = (x, 0, 1), so Θᵀ xa = F x + w (Eq. 35 corrected)
            xa[-1] = 1.0
        else:
            np.add(x, model_t[:, -1], out=self._xa_x)  # xa = (x + w, 0, 0): F (x + w), as printed
            xa[-1] = 0.0
        np.dot(model_t, xa, out=self._y)  # y = F x + w (or F (x + w))
        G = model_t[:, p : p + self.n]  # Ĝ
        gtq = np.multiply(G.T, self.q_diagonal, out=self._gtq)  # Gᵀ Q (Q diagonal)
        S = np.dot(gtq, G, out=self._S)  # Gᵀ Q G
        S += self.R  # S = R + Gᵀ Q G
        np.dot(gtq, self._y, out=self._b)  # b = Gᵀ Q y
        _, u, info = lapack.dposv(S, self._b)  # u = S⁻¹ b, by Cholesky of S
        if info != 0:
            raise ControlError("R + Gᵀ Q G is not positive definite (check R)")
        if not math.isfinite(float(np.add.reduce(u))):
            raise ControlError("R + Gᵀ Q G is too ill-conditioned: the solution is not finite")
        return np.negative(u, out=u)  # u* = -S⁻¹ Gᵀ Q y (Eq. 35)


def one_step_cost(F: Any, G: Any, w: Any, Q: Any, R: Any, x: Any, u: Any) -> float:
    """The one-step cost of Eq. 34.

    ``J = ½ [x⁺ᵀ Q x⁺ + uᵀ R u]`` with ``x⁺ = F x + G u + w`` (Eq. 16).

    Parameters
    ----------
    F : array_like, shape (p, p)
    G : array_like, shape (p, n)
    w : array_like, shape (p,)
    Q : array_like, shape (p, p)
    R : array_like, shape (n, n)
    x : array_like, shape (p,)
    u : array_like, shape (n,)

    Returns
    -------
    float

    Raises
    ------
    ControlError
        On wrong shapes, non-finite entries or invalid weights.
    """
    Fa, Ga, p, n = _model(F, G)
    wa = _array("w", w, (p,))
    xa = _array("x", x, (p,))
    ua = _array("u", u, (n,))
    Qa, Ra = validate_weights(Q, R, p, n)
    x_next = Fa @ xa + Ga @ ua + wa
    return 0.5 * float(x_next @ Qa @ x_next + ua @ Ra @ ua)


def receding_horizon_control(
    F: Any,
    G: Any,
    w: Any,
    Q: Any,
    R: Any,
    x: Any,
    horizon: int,
    *,
    check_weights: bool = True,
) -> np.ndarray:
    """First input of the N-step optimal control of the identified affine model.

    Minimises ``J = ½ Σ_{i=1..N} x(k+i)ᵀ Q x(k+i) + ½ Σ_{i=0..N-1} u(k+i)ᵀ R u(k+i)``
    subject to Eq. 16, ``x(i+1) = F x(i) + G u(i) + w``, with ``F, G, w`` frozen at their
    current estimates (the certainty-equivalence receding horizon), and returns ``u(k)``.
    The bias is carried by augmenting the state with a constant 1,
    ``s = (x, 1)``, ``A = [[F, w], [0, 1]]``, ``B = [[G], [0]]``, ``Q̃ = diag(Q, 0)``, and the
    backward Riccati recursion ``P_N = Q̃``,
    ``P_i = Q̃ + Aᵀ P_{i+1} A − Aᵀ P_{i+1} B (R + Bᵀ P_{i+1} B)⁻¹ Bᵀ P_{i+1} A``
    gives ``u(k) = −(R + Bᵀ P_1 B)⁻¹ Bᵀ P_1 A s(k)``. With ``horizon = 1`` this is exactly the
    one-step law of Eq. 35 (corrected): the paper's structure, looking further ahead.

    Parameters
    ----------
    F : (p, p), G : (p, n), w : (p,), Q : (p, p), R : (n, n), x : (p,)
    horizon : int
        N >= 1 steps.

    Returns
    -------
    (n,) ndarray
    """
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
        raise ControlError(f"horizon must be an integer >= 1, got {horizon!r}")
    F, G, p, n = _model(F, G)
    w = _array("w", w, (p,))
    x = _array("x", x, (p,))
    Q, R = _weights(Q, R, p, n, check_weights)
    A = np.zeros((p + 1, p + 1))
    A[:p, :p] = F
    A[:p, p] = w
    A[p, p] = 1.0
    B = np.zeros((p + 1, n))
    B[:p] = G
    Qt = np.zeros((p + 1, p + 1))
    Qt[:p, :p] = Q
    P = Qt
    for _ in range(horizon - 1):
        PB = P @ B
        K = _solve_spd(R + B.T @ PB, PB.T @ A)
        P = Qt + A.T @ (P @ A - PB @ K)  # Aᵀ P A - Aᵀ P B K
        P = 0.5 * (P + P.T)
    PB = P @ B
    s = np.append(x, 1.0)
    return -_solve_spd(R + B.T @ PB, PB.T @ (A @ s))


class RecedingHorizonControl:
    """:func:`receding_horizon_control` for the per-sample loop: ``Q`` diagonal as made (a
    caller may weigh off the diagonal, :attr:`Q`), fixed horizon, every array made once.

    The augmented model ``A = [[F, w], [0, 1]]``, ``B = [[G], [0]]`` and ``Q̃ = diag(Q, 0)`` live
    in buffers whose constant entries are written here, once; the caller writes the model into
    the views :attr:`F`, :attr:`G`, :attr:`w` and the state into :attr:`x` (or passes them to
    :meth:`__call__`) and calls :meth:`solve`. A caller whose model has constant blocks of its
    own (the adaptive law's lagged inputs and integral) writes those once too and only the
    identified blocks every sample. The Riccati recursion runs into preallocated products and
    solves by Cholesky (``dposv``), operation by operation as :func:`receding_horizon_control`
    does: the two give the same bits (the tests check it). The products are ``numpy.dot``'s,
    the same BLAS calls as the function's ``@`` at less overhead per call. Inputs are not
    checked per call (the model and state must be finite: the identifier's and the law's are).

    Parameters
    ----------
    q_diagonal : array_like, shape (p,)
        Diagonal of ``Q``, finite and >= 0.
    R : array_like, shape (n, n)
        Symmetric positive definite.
    horizon : int
        N >= 1 steps.

    Raises
    ------
    ControlError
        On construction, for bad weights or horizon (the message names it).
    """

    def __init__(self, q_diagonal: Any, R: Any, horizon: int) -> None:
        if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
            raise ControlError(f"horizon must be an integer >= 1, got {horizon!r}")
        q, Q, self.R = _diagonal_weights(q_diagonal, R)
        p, n = q.shape[0], self.R.shape[0]
        self.p, self.n, self.horizon = p, n, int(horizon)
        # The augmented model and weight, their constant entries written once.
        self._A = np.zeros((p + 1, p + 1))
        self._A[p, p] = 1.0
        self._B = np.zeros((p + 1, n))
        self._Qt = np.zeros((p + 1, p + 1))
        self._Qt[:p, :p] = Q
        self._s = np.zeros(p + 1)  # s = (x, 1)
        self._s[p] = 1.0
        #: Views the caller writes the model ``F`` (p, p), ``G`` (p, n), ``w`` (p,) into.
        self.F, self.G, self.w = self._A[:p, :p], self._B[:p], self._A[:p, p]
        #: View the caller writes the state ``x`` (p,) into.
        self.x = self._s[:p]
        #: View of ``Q`` (p, p), ``diag(q_diagonal)`` as made: a caller may write weights off
        #: the diagonal into it (:func:`apc_feedback.lagged_control.weigh_input_change`), kept
        #: symmetric positive semi-definite.
        self.Q = self._Qt[:p, :p]
        # The recursion's products.
        self._P = np.empty((p + 1, p + 1))
        self._PA = np.empty((p + 1, p + 1))
        self._next = np.empty((p + 1, p + 1))
        self._PB = np.empty((p + 1, n))
        self._PBK = np.empty((p + 1, p + 1))
        self._S = np.empty((n, n))
        self._BtPA = np.empty((n, p + 1))
        self._As = np.empty(p + 1)
        self._b = np.empty(n)
        self._finite_gain = np.empty((n, p + 1), dtype=bool)
        self._finite_u = np.empty(n, dtype=bool)

    def __call__(self, F: np.ndarray, G: np.ndarray, w: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``u(k)`` for the model ``(F, G, w)`` and the state ``x`` (all finite): written into
        the views, then :meth:`solve`."""
        self.F[...] = F
        self.G[...] = G
        self.w[...] = w
        self.x[...] = x
        return self.solve()

    def solve(self) -> np.ndarray:
        """``u(k)`` (a fresh array, shape (n,)) for the model and state in the views.

        Raises
        ------
        ControlError
            If ``R + Bᵀ P B`` is not numerically positive definite or a gain is not finite.
        """
        A, B, R = self._A, self._B, self.R
        P, PB, S = self._riccati(), self._PB, self._S
        np.dot(P, B, out=PB)
        np.dot(B.T, PB, out=S)
        S += R
        np.dot(A, self._s, out=self._As)
        np.dot(PB.T, self._As, out=self._b)  # Bᵀ P₁ A s
        u = _solve_spd(S, self._b, self._finite_u)
        return np.negative(u, out=u)

    def gain(self, columns: slice = slice(None), reuse: bool = False) -> np.ndarray:
        """The first step's gain ``K`` (a fresh array, shape (n, p + 1); with ``columns``, those
        columns only) for the model in the views, ``u(k) = -K (x, 1)``: what :meth:`solve`
        computes for any state. What the plan does with each entry of its state
        (the lagged inputs', :func:`apc_feedback.lagged_control.input_ringing`).

        ``reuse``: from the recursion of the last :meth:`solve` (the model and weights
        unchanged since), a small solve; else the recursion is run again.

        Raises
        ------
        ControlError
            As :meth:`solve`.
        """
        PB, S = self._PB, self._S
        if not reuse:
            np.dot(self._riccati(), self._B, out=PB)
            np.dot(self._B.T, PB, out=S)
            S += self.R
        return _solve_spd(S, PB.T @ self._A[:, columns])

    def input_for(self, gain: np.ndarray) -> np.ndarray:
        """``u(k) = -K (x, 1)`` (a fresh array) for a ``gain`` from :meth:`gain` (all columns)
        and the state in the view :attr:`x`: a plan made before the state came."""
        return np.negative(np.dot(gain, self._s))

    def _riccati(self) -> np.ndarray:
        """``P_1`` of the backward recursion over the horizon (a buffer of this object's)."""
        A, B, R, Qt = self._A, self._B, self.R, self._Qt
        P, PB, S, BtPA = Qt, self._PB, self._S, self._BtPA
        for _ in range(self.horizon - 1):
            np.dot(P, B, out=PB)
            np.dot(B.T, PB, out=S)
            S += R  # R + Bᵀ P B
            np.dot(PB.T, A, out=BtPA)
            K = _solve_spd(S, BtPA, self._finite_gain)  # (R + Bᵀ P B)⁻¹ Bᵀ P A
            np.dot(P, A, out=self._PA)
            np.dot(PB, K, out=self._PBK)
            np.subtract(self._PA, self._PBK, out=self._PA)  # P A - P B K
            np.dot(A.T, self._PA, out=self._next)
            self._next += Qt  # Q̃ + Aᵀ P A - Aᵀ P B K
            P = self._P
            np.add(self._next, self._next.T, out=P)
            P *= 0.5  # symmetrised
        return P
