"""Recursive least squares for the perturbation model (paper Eqs. 16, 21-32).

The discrete perturbation model of Eq. 16 is

    δx(k+1) = F δx(k) + G δu(k) + w,      δx ∈ R^p, δu ∈ R^n, p = 2n.

With the regressor ``z(k) = (δx(k), δu(k), 1) ∈ R^(3n+1)`` (Eq. 23) and the parameter matrix
``Θ = [F G w]ᵀ ∈ R^((3n+1)×p)`` (Eq. 22) this reads ``δx(k+1) = Θᵀ z(k)`` (Eq. 25). All ``p``
columns of Θ share one regressor, so one gain matrix ``P`` serves them all and is updated once
per sample (the paper's remark after Eq. 35). One update (Eqs. 26, 29-31):

    e     = δx(k+1) - Θᵀ z                       (Eq. 26, a-priori residual, (p,))
    γ     = 1 / (zᵀ P z + ρ)                      (Eq. 31)
    Θ    ← Θ + γ P z eᵀ                           (Eq. 29)
    P    ← (P - γ P z zᵀ P) / ρ                   (Eq. 30 corrected, ``forgetting="exponential"``)
    P    ←  P - γ P z zᵀ P                        (Eq. 30 as printed, ``forgetting="printed"``)

``P(0) = α I`` (Eq. 32). Eq. 30 as printed omits the division by ρ that minimising the
exponentially weighted criterion of Eq. 27 yields. With it, after k updates
``P(k)⁻¹ = ρᵏ P(0)⁻¹ + Σᵢ ρ^(k-1-i) z(i) z(i)ᵀ``: old samples fade by ρ per step. The printed
form gives ``P(k)⁻¹ = P(0)⁻¹ + ρ⁻¹ Σᵢ z(i) z(i)ᵀ``: every sample is weighted alike and nothing
is forgotten, whatever ρ. The corrected form is the default; the printed one stays selectable
to reproduce the paper as written.

:func:`apc_feedback.rls_reference.rls_update_reference` writes one update as the paper
does, column by column (Eq. 29 for each ``θᵢ``) with fresh arrays; :class:`Rls` computes the
same update for all columns at once in preallocated buffers, and the tests hold the two equal.

Wind-up guard: when the data do not excite every direction of ``z`` (the arm holding still,
``δu`` constant) the exponential form divides the unexcited part of ``P`` by ρ at every sample,
so ``P`` grows like ``ρ⁻ᵏ`` until it overflows and the next informative sample causes a huge
jump in Θ ("estimator wind-up"). ``RlsConfig.trace_max`` bounds ``trace(P)``: whenever an update
leaves ``trace(P) > trace_max``, ``P`` is scaled by ``trace_max / trace(P)``. This is the
bounded-trace variant of the constant-trace least-squares algorithm (G. C. Goodwin and K. S. Sin,
*Adaptive Filtering Prediction and Control*, Prentice-Hall 1984, ch. 3; K. J. Åström and
B. Wittenmark, *Adaptive Control*, 2nd ed., Addison-Wesley 1995, ch. 11 on estimator wind-up).
Scaling keeps ``P`` symmetric positive definite and leaves the direction of the gain ``P z``
unchanged; only its size shrinks.

A prior on the model. ``P(0) = α I`` says as little about ``F`` and ``G`` as about ``w``. With a
large α the first samples decide ``F̂`` and ``Ĝ`` almost alone, whatever Eq. 33 gave: on an arm
that holds still (activation on a robot, every hold between moves) those samples excite almost
nothing, and one that does not follow Eq. 16 (a command applied a few ms late) turns ``Ĝ``'s
velocity block indefinite within two steps, after which Eq. 35 drives the arm to its limits.
``RlsConfig.alpha_model`` gives the rows of ``z`` that carry ``δx`` and ``δu`` their own, small
``P(0)`` (``diag(alpha_model I_3n, alpha)``): the model moves only on samples whose inputs are
large on that scale, ``ŵ`` still follows every sample. The guard then bounds the trace of each
block of ``P`` (the ``δx``, ``δu`` and constant rows) by its share of ``trace_max`` at ``P(0)``,
by a congruence ``S P S`` with ``S`` constant on each block (still symmetric positive definite):
one bound on the sum would let the model blocks wind up to the bias block's scale within a few
seconds of a hold, and the prior would be gone.

No ROS here: numpy in, dataclasses out.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from apc_feedback.arrays import finite_array
from apc_feedback.rls_config import RlsConfig, RlsError

__all__ = ["Rls", "RlsConfig", "RlsError", "RlsStep"]


class RlsStep(NamedTuple):
    """Diagnostics of one :meth:`Rls.update` (a named tuple: made every sample, cheaply).

    Attributes
    ----------
    residual : numpy.ndarray, shape (p,)
        A-priori residual ``e(k) = δx(k+1) - Θ(k)ᵀ z(k)`` of Eq. 26 (a fresh array).
    gamma : float
        ``γ(k) = 1 / (z(k)ᵀ P(k) z(k) + ρ)`` of Eq. 31.
    trace_p : float
        ``trace(P(k+1))`` after the update and the guard.
    clipped : bool
        True when the trace guard scaled ``P(k+1)`` down to ``trace_max``.
    """

    residual: np.ndarray
    gamma: float
    trace_p: float
    clipped: bool


class Rls:
    """Recursive least-squares identifier of ``[F G w]`` for all ``p = 2n`` rows at once.

    Configuration (``n_joints``, ``config``) is fixed; the mutable state is Θ, P, the number of
    updates since the last reset, and the initial values that :meth:`reset` restores.

    Parameters
    ----------
    n_joints : int
        n ≥ 1. The state has ``p = 2n`` entries, the regressor ``m = 3n+1``.
    config : RlsConfig
    input_lags : int
        Delayed inputs the model carries (0: Eq. 16). With ``L`` lags the regressor is
        ``z(k) = (δx(k), δu(k), δu(k-1), …, δu(k-L), 1)`` (``m = 2n + (L+1) n + 1``) and
        ``Θᵀ = [F G₀ G₁ … G_L w]``: the exact discrete model of a zero-order hold whose input
        reaches the arm up to ``L`` periods late (:mod:`apc_feedback.linearize`).

    Notes
    -----
    Until :meth:`reset` is called with arguments, ``Θ(0) = 0`` (so ``F = G = 0``, ``w = 0``)
    and ``P(0) = alpha I``. The paper initialises ``F(0), G(0)`` from Eq. 33; pass them to
    :meth:`reset`.

    The accessors :attr:`theta`, :attr:`P`, :attr:`F`, :attr:`G`, :attr:`w` return **copies**:
    holding one across an update never sees the update, and writing to one never changes the
    estimator.
    """

    def __init__(self, n_joints: int, config: RlsConfig, input_lags: int = 0) -> None:
        if isinstance(n_joints, bool) or not isinstance(n_joints, int | np.integer):
            raise RlsError(f"n_joints must be an int, got {n_joints!r}")
        if n_joints < 1:
            raise RlsError(f"n_joints must be >= 1, got {n_joints}")
        if not isinstance(config, RlsConfig):
            raise RlsError(f"config must be an RlsConfig, got {type(config).__name__}")
        if isinstance(input_lags, bool) or not isinstance(input_lags, int) or input_lags < 0:
            raise RlsError(f"input_lags must be an int >= 0, got {input_lags!r}")
        self._n = int(n_joints)
        self._p = 2 * self._n
        self._lags = input_lags
        self._q = (input_lags + 1) * self._n  # input entries of z
        self._m = self._p + self._q + 1
        self._config = config
        self._exponential = config.forgetting == "exponential"
        m, p = self._m, self._p
        # State: P (m, m) stacked over Θᵀ = [F G w] (p, m) in one (m + p, m) array, so one
        # product gives P z and Θᵀ z and one outer product updates both (Eqs. 29-30).
        # Double-buffered: an update is computed into the spare and swapped in only when
        # finite, so a rejected update leaves the state untouched without allocating.
        self._buffers = (np.empty((m + p, m)), np.empty((m + p, m)))
        self._views = tuple(_BufferViews(buf, m) for buf in self._buffers)
        self._cur = 0
        self._traces = [0.0, 0.0]
        self._r = np.empty(m + p)  # [P z; Θᵀ z]
        self._pz = self._r[:m]
        self._theta_z = self._r[m:]  # Θᵀ z, then overwritten with -e
        self._k = 0
        self._can_undo = False
        self._theta0 = np.zeros((m, p))
        self._P0 = np.diag(config.initial_p_diagonal(self._n, input_lags))
        # Block guard (alpha_model): the bound of each block's trace (δx, inputs, constant), and
        # buffers for the congruence's scale per row and per entry (see the module docstring).
        block_max = config.block_trace_max(self._n, input_lags)
        self._block_bounds = None if block_max is None else block_max.tolist()
        self._row_scale = np.empty(m)
        self._block_scale = np.empty((m, m))
        self._restore()

    # ------------------------------------------------------------------ read-only accessors
    @property
    def config(self) -> RlsConfig:
        """The frozen configuration."""
        return self._config

    @property
    def n_joints(self) -> int:
        """n, the number of joints (inputs)."""
        return self._n

    @property
    def p(self) -> int:
        """p = 2n, the state dimension."""
        return self._p

    @property
    def m(self) -> int:
        """m = 3n+1, the regressor dimension (Eq. 23); ``2n + (L+1) n + 1`` with ``L`` lags."""
        return self._m

    @property
    def input_lags(self) -> int:
        """Delayed inputs the model carries (0: Eq. 16)."""
        return self._lags

    @property
    def n_updates(self) -> int:
        """Number of accepted updates since the last :meth:`reset`."""
        return self._k

    @property
    def theta(self) -> np.ndarray:
        """Copy of Θ = [F G w]ᵀ, shape (m, 2n) (Eq. 22)."""
        return self._views[self._cur].theta_t.T.copy()

    @property
    def P(self) -> np.ndarray:
        """Copy of P, shape (3n+1, 3n+1), symmetric positive definite."""
        return self._views[self._cur].P.copy()

    @property
    def F(self) -> np.ndarray:
        """Copy of F̂, shape (2n, 2n)."""
        return self._views[self._cur].theta_t[:, : self._p].copy()

    @property
    def G(self) -> np.ndarray:
        """Copy of Ĝ, shape (2n, n); with lags ``[Ĝ₀ Ĝ₁ … Ĝ_L]``, shape (2n, (L+1) n)."""
        return self._views[self._cur].theta_t[:, self._p : self._p + self._q].copy()

    @property
    def w(self) -> np.ndarray:
        """Copy of ŵ, shape (2n,)."""
        return self._views[self._cur].theta_t[:, self._p + self._q].copy()

    @property
    def trace_p(self) -> float:
        """trace(P)."""
        return self._traces[self._cur]

    def model_view(self) -> np.ndarray:
        """Read-only view of ``Θᵀ = [F̂ Ĝ ŵ]``, shape (2n, m), without a copy.

        For a per-sample loop that reads the model right after an update (the feedback law's
        Eq. 35). The view shows the estimate as it is now and is not valid after the next
        :meth:`update`, :meth:`undo` or :meth:`reset`; use :attr:`F`, :attr:`G`, :attr:`w` to
        keep one.
        """
        return self._views[self._cur].theta_t_readonly

    # ------------------------------------------------------------------ state changes
    def reset(
        self,
        F0: np.ndarray | None = None,
        G0: np.ndarray | None = None,
        w0: np.ndarray | None = None,
        P0: np.ndarray | None = None,
    ) -> None:
        """Restart the identifier.

        ``reset()`` with no argument restores the stored initial state (zeros and ``alpha I``
        after construction, else the values of the last ``reset`` with arguments) and sets the
        update count to 0. With arguments, ``F0`` and ``G0`` are required and the given values
        become the new stored initial state.

        Parameters
        ----------
        F0 : array_like, shape (2n, 2n)
            F̂(0), e.g. from Eq. 33a.
        G0 : array_like, shape (2n, n), or (2n, (L+1) n) with lags
            Ĝ(0), e.g. from Eq. 33b (with lags, split by the delay:
            :func:`apc_feedback.linearize.split_input_matrix`).
        w0 : array_like, shape (2n,), optional
            ŵ(0); default 0.
        P0 : array_like, shape (3n+1, 3n+1), optional
            P(0), symmetric positive definite; default the config's (``alpha I``, Eq. 32, or
            with ``alpha_model`` its block diagonal). Symmetric to
            rounding is accepted and stored exactly symmetrised.

        Raises
        ------
        RlsError
            On a wrong shape, a non-finite entry, ``P0`` not symmetric positive definite, or
            only some of ``F0``/``G0`` given. The state is unchanged then.
        """
        if F0 is None and G0 is None and w0 is None and P0 is None:
            self._restore()
            return
        if F0 is None or G0 is None:
            raise RlsError("reset needs both F0 and G0 (or no argument to restore)")
        n, p, m, q = self._n, self._p, self._m, self._q
        F0a = _matrix("F0", F0, (p, p))
        G0a = _matrix("G0", G0, (p, q))
        w0a = np.zeros(p) if w0 is None else _matrix("w0", w0, (p,))
        if P0 is None:
            P0a = np.diag(self._config.initial_p_diagonal(n, self._lags))
        else:
            P0a = _matrix("P0", P0, (m, m))
            scale = max(1.0, float(np.max(np.abs(P0a))))
            if np.max(np.abs(P0a - P0a.T)) > 1e-12 * scale:
                raise RlsError("P0 must be symmetric")
            P0a = 0.5 * (P0a + P0a.T)
            try:
                np.linalg.cholesky(P0a)
            except np.linalg.LinAlgError:
                raise RlsError("P0 must be positive definite") from None
        theta0 = np.empty((m, p))
        theta0[:p] = F0a.T
        theta0[p : p + q] = G0a.T
        theta0[p + q] = w0a
        self._theta0 = theta0
        self._P0 = P0a
        self._restore()

    def _restore(self) -> None:
        views = self._views[self._cur]
        views.P[...] = self._P0
        views.theta_t[...] = self._theta0.T
        self._traces[self._cur] = float(views.diagonal.sum())
        self._k = 0
        self._can_undo = False

    def shift_model(self, delta: np.ndarray) -> None:
        """Add ``delta`` to the estimate's ``[F̂ Ĝ]`` (shape (2n, 2n + (L+1) n)), ``P`` and
        ``ŵ`` kept: the prior the estimate is a deviation from has moved by ``delta`` (the
        feedback law's model re-linearised at a new set point). The last update can no longer
        be taken back.

        Raises
        ------
        RlsError
            On a wrong shape or a non-finite entry (the estimate is unchanged then).
        """
        p, q = self._p, self._q
        delta = _matrix("delta", delta, (p, p + q))
        self._views[self._cur].theta_t[:, : p + q] += delta
        self._can_undo = False

    def move_input_origin(self, shift: np.ndarray) -> None:
        """Measure every input ``δu_j`` from an origin ``shift`` (shape (n,)) higher: ``ŵ``
        takes what the inputs held, ``ŵ ← ŵ + (Σ_j Ĝ_j) shift``, so that ``Θᵀz`` is the same
        for every regressor once its inputs are ``δu_j - shift``. ``[F̂ Ĝ]`` and ``P`` are
        kept (the exact change of coordinates would move the inputs' uncertainty into ``ŵ``'s
        block of ``P``, which the per-block trace bound is not made for). For a nominal
        torque that takes on a load the law held (robot mode carrying an estimated payload).
        The last update can no longer be taken back.

        Raises
        ------
        RlsError
            On a wrong shape or a non-finite entry (the estimate is unchanged then).
        """
        p, q = self._p, self._q
        shift = _vector("shift", shift, self._n)
        theta_t = self._views[self._cur].theta_t
        theta_t[:, p + q] += theta_t[:, p : p + q] @ np.tile(shift, q // self._n)
        self._can_undo = False

    def undo(self) -> None:
        """Take back the last :meth:`update` (Θ, P and the count), e.g. when a projection
        onto physically possible parameters refuses its result.

        Raises
        ------
        RlsError
            If there is no update to take back (only the last one can be).
        """
        if not self._can_undo:
            raise RlsError("undo: no update to take back")
        self._cur = 1 - self._cur
        self._k -= 1
        self._can_undo = False

    def update(self, z: np.ndarray, dx_next: np.ndarray) -> RlsStep:
        """Fold one sample into the estimate (Eqs. 26, 29, 30 corrected or printed, 31).

        Parameters
        ----------
        z : array_like, shape (3n+1,)
            Regressor ``z(k) = (δx(k), δu(k), 1)`` (Eq. 23); see :meth:`regressor`. The last
            entry is not forced to 1.
        dx_next : array_like, shape (2n,)
            The measured ``δx(k+1)``.

        Returns
        -------
        RlsStep
            A-priori residual, γ, trace(P) after the update, and whether the trace guard acted.

        Raises
        ------
        RlsError
            If ``z`` or ``dx_next`` has a wrong shape or a non-finite entry, or if the update
            would make Θ or P non-finite (or a diagonal entry of P non-positive). The state is
            unchanged then; the caller may count the failure and carry on, or :meth:`reset`.
        """
        m = self._m
        if not (type(z) is np.ndarray and z.dtype == np.float64 and z.shape == (m,)):
            z = _vector("z", z, m)
        if not (
            type(dx_next) is np.ndarray
            and dx_next.dtype == np.float64
            and dx_next.shape == (self._p,)
        ):
            dx_next = _vector("dx_next", dx_next, self._p)
        gamma, trace_p, clipped = self._candidate(z, dx_next)
        self._cur = 1 - self._cur
        self._traces[self._cur] = trace_p
        self._k += 1
        self._can_undo = True
        return RlsStep(
            residual=np.negative(self._theta_z), gamma=gamma, trace_p=trace_p, clipped=clipped
        )

    # Overflow on the way to a rejected update is expected, not a warning (the decorator form
    # of errstate costs half the with-statement's).
    @np.errstate(all="ignore")
    def _candidate(self, z: np.ndarray, dx_next: np.ndarray) -> tuple[float, float, bool]:
        """Compute Θ(k+1), P(k+1) into the spare buffer; raise RlsError if not finite.

        Finiteness of the inputs is not checked up front: a non-finite ``z`` or ``dx_next``
        makes the candidate non-finite, and only then are the inputs examined to name the
        culprit. One reduction over the candidate replaces a check per array.
        """
        # Each line names the term of Eqs. 26, 29-31 it computes; the state buffer holds
        # [P; Θᵀ] stacked, so a row of the Θᵀ block is one θᵢᵀ of Eq. 21.
        rho = self._config.rho  # ρ
        now, new = self._views[self._cur], self._views[1 - self._cur]
        r = self._r
        np.dot(now.stacked, z, out=r)  # [P z; Θᵀ z]: Θᵀ z is Eq. 25's prediction of δx(k+1)
        pz = self._pz  # P z, the gain direction shared by every θᵢ (Eqs. 29-30)
        denom = float(np.dot(z, pz)) + rho  # zᵀ P z + ρ (Eq. 31)
        if not (denom > 0.0 and math.isfinite(denom)):
            _name_non_finite(z, dx_next)
            raise RlsError(f"update rejected: zᵀ P z + rho = {denom!r} (z too large?)")
        gamma = 1.0 / denom  # γ (Eq. 31)
        np.subtract(self._theta_z, dx_next, out=self._theta_z)  # -e = Θᵀ z - δx(k+1) (Eq. 26)
        stacked = new.stacked
        # P zzᵀ P = (P z)(P z)ᵀ for symmetric P, so one outer product of [P z; -e] with P z
        # serves both updates. The P block is built elementwise from exactly symmetric arrays,
        # so it stays exactly symmetric.
        np.multiply.outer(r, pz, out=stacked)  # [P z zᵀ P; -e (P z)ᵀ]
        stacked *= -gamma  # [-γ P z zᵀ P; γ e (P z)ᵀ], the increments of Eqs. 30 and 29
        stacked += now.stacked  # [P - γ P z zᵀ P (Eq. 30); Θᵀ + γ e (P z)ᵀ (Eq. 29, every i)]
        scale = 1.0 / rho if self._exponential else 1.0  # the 1/ρ of Eq. 30 corrected
        clipped = False
        trace_max = self._config.trace_max
        if self._block_bounds is not None:
            if scale != 1.0:
                new.P *= scale  # Eq. 30's 1/ρ
            trace_p, clipped = self._guard_blocks(new)
        else:
            trace_p = float(_sum(new.diagonal))  # trace(P - γ P z zᵀ P)
            if trace_max is not None and trace_p * scale > trace_max:
                scale = trace_max / trace_p  # wind-up guard: trace(P(k+1)) = trace_max
                clipped = True
            if scale != 1.0:
                new.P *= scale  # P(k+1): forgetting and the guard as one scaling
                trace_p *= scale  # trace(s P) = s trace(P), to rounding
        # One reduction: a non-finite entry anywhere makes the sum non-finite.
        if not (math.isfinite(float(_sum(stacked, None))) and _min(new.diagonal) > 0.0):
            _name_non_finite(z, dx_next)
            if not np.isfinite(self._theta_z).all():
                raise RlsError("update rejected: residual is not finite")
            raise RlsError("update rejected: Θ or P would become non-finite or P indefinite")
        return gamma, trace_p, clipped

    def _guard_blocks(self, views: _BufferViews) -> tuple[float, bool]:
        """The guard with a model prior: ``P ← S P S``, ``S`` = ``sqrt(bound / trace)`` on each
        block over its bound, 1 elsewhere; returns trace(P) and whether it acted."""
        # Three traces and bounds as Python floats: a sample costs less than with arrays.
        traces = (
            float(_sum(views.diagonal_x)),
            float(_sum(views.diagonal_u)),
            float(views.diagonal[-1]),
        )
        bounds = self._block_bounds
        assert bounds is not None
        over = [trace > bound for trace, bound in zip(traces, bounds, strict=True)]
        if not any(over):
            return traces[0] + traces[1] + traces[2], False
        scales = [
            math.sqrt(bound / trace) if past else 1.0
            for trace, bound, past in zip(traces, bounds, over, strict=True)
        ]
        s, p = self._row_scale, self._p
        s[:p], s[p:-1], s[-1] = scales
        np.multiply.outer(s, s, out=self._block_scale)  # exactly symmetric, as P is
        views.P *= self._block_scale
        return float(_sum(views.diagonal)), True

    # ------------------------------------------------------------------ helpers
    def predict(self, z: np.ndarray) -> np.ndarray:
        """One-step prediction ``Θᵀ z = F̂ δx + Ĝ δu + ŵ`` (Eq. 25), shape (2n,).

        Raises
        ------
        RlsError
            If ``z`` is not a finite (3n+1,) vector.
        """
        return self._views[self._cur].theta_t @ _vector("z", z, self._m)

    @staticmethod
    def regressor(dx: np.ndarray, du: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Build ``z = (δx, δu, 1)`` of Eq. 23.

        Parameters
        ----------
        dx : array_like, shape (2n,)
            δx(k) = x(k) - x_n(k), positions then velocities.
        du : array_like, shape (n,), or ((L+1) n,) with lags
            δu(k), the perturbation torque applied over [kT, (k+1)T) (with lags, followed by
            δu(k-1), …, δu(k-L)).
        out : numpy.ndarray, shape (3n+1,), optional
            Float64 buffer to write into (avoids an allocation per sample).

        Returns
        -------
        numpy.ndarray, shape (2n + len(du) + 1,)

        Raises
        ------
        RlsError
            If ``dx`` is not a finite (2n,) vector with n ≥ 1, ``du`` not a finite vector of
            a whole number of n entries, or ``out`` not a float64 array of the regressor's
            shape.
        """
        dx_a = np.asarray(dx, dtype=float)
        if dx_a.ndim != 1 or dx_a.shape[0] < 2 or dx_a.shape[0] % 2:
            raise RlsError(f"dx must have shape (2n,) with n >= 1, got {dx_a.shape}")
        p = dx_a.shape[0]
        dx_a = _vector("dx", dx_a, p)
        du_a = np.asarray(du, dtype=float)
        if du_a.ndim != 1 or du_a.shape[0] < p // 2 or du_a.shape[0] % (p // 2):
            raise RlsError(
                f"du must have shape (n,) or ((L+1) n,) with n = {p // 2}, got {du_a.shape}"
            )
        q = du_a.shape[0]
        du_a = _vector("du", du_a, q)
        m = p + q + 1
        if out is None:
            out = np.empty(m)
        elif not (isinstance(out, np.ndarray) and out.shape == (m,) and out.dtype == np.float64):
            raise RlsError(f"out must be a float64 array of shape ({m},)")
        out[:p] = dx_a
        out[p : p + q] = du_a
        out[-1] = 1.0
        return out


# The ufunc reductions, without ndarray.sum's Python wrapper (a third of its cost here).
_sum = np.add.reduce
_min = np.minimum.reduce


class _BufferViews:
    """Named views of one state buffer ``[P; Θᵀ]`` (made once: slicing per sample costs)."""

    def __init__(self, stacked: np.ndarray, m: int) -> None:
        self.stacked = stacked
        self.P = stacked[:m]
        self.theta_t = stacked[m:]
        self.diagonal = self.P.diagonal()
        p = stacked.shape[0] - m
        self.diagonal_x = self.diagonal[:p]  # the δx block's (the model prior's guard)
        self.diagonal_u = self.diagonal[p:-1]  # the inputs' block's
        self.theta_t_readonly = stacked[m:].view()
        self.theta_t_readonly.flags.writeable = False


def _name_non_finite(z: np.ndarray, dx_next: np.ndarray) -> None:
    """Raise RlsError naming ``z`` or ``dx_next`` if it has a non-finite entry."""
    if not np.isfinite(z).all():
        raise RlsError("z must be finite")
    if not np.isfinite(dx_next).all():
        raise RlsError("dx_next must be finite")


def _vector(name: str, value: Any, size: int) -> np.ndarray:
    """``value`` as a finite float64 vector of length ``size`` (no copy when already one)."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise RlsError(f"{name} must be a real array of shape ({size},)") from None
    if a.shape != (size,):
        raise RlsError(f"{name} must have shape ({size},), got {a.shape}")
    if not np.isfinite(a).all():
        raise RlsError(f"{name} must be finite")
    return a


def _matrix(name: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (always a fresh copy)."""
    return finite_array(name, value, shape, RlsError, copy=True)
