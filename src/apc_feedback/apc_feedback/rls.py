"""Recursive least squares for the perturbation model (paper Eqs. 16, 21-32).

The discrete perturbation model of Eq. 16 is

    δx(k+1) = F δx(k) + G δu(k) + w,      δx ∈ R^p, δu ∈ R^n, p = 2n.

With the regressor ``z(k) = (δx(k), δu(k), 1) ∈ R^(3n+1)`` (Eq. 23) and the parameter matrix
``Θ = [F G w]ᵀ ∈ R^((3n+1)×p)`` (Eq. 22) this reads ``δx(k+1) = Θᵀ z(k)`` (Eq. 25). All ``p``
columns of Θ share one regressor, so one gain matrix ``P`` serves them all and is updated once
per sample (the paper's remark after Eq. 35). One update (Eqs. 26, 29-31, with Eq. 30 corrected,
see ``/work/shared/DESIGN.md``):

    e     = δx(k+1) - Θᵀ z                       (Eq. 26, a-priori residual, (p,))
    γ     = 1 / (zᵀ P z + ρ)                      (Eq. 31)
    Θ    ← Θ + γ P z eᵀ                           (Eq. 29)
    P    ← (P - γ P z zᵀ P) / ρ                   (Eq. 30 corrected, ``forgetting="exponential"``)
    P    ←  P - γ P z zᵀ P                        (Eq. 30 as printed, ``forgetting="printed"``)

``P(0) = α I`` (Eq. 32). The corrected form is exponentially weighted least squares: after k
updates ``P(k)⁻¹ = ρᵏ P(0)⁻¹ + Σᵢ ρ^(k-1-i) z(i) z(i)ᵀ``. The printed form gives
``P(k)⁻¹ = P(0)⁻¹ + ρ⁻¹ Σᵢ z(i) z(i)ᵀ``: every sample is weighted alike and nothing is
forgotten, whatever ρ.

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

No ROS here: numpy in, dataclasses out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

__all__ = ["Rls", "RlsConfig", "RlsError", "RlsStep"]

Forgetting = Literal["exponential", "printed"]
_FORGETTING: tuple[str, ...] = ("exponential", "printed")


class RlsError(ValueError):
    """Bad configuration, bad input, or an update that would make the estimator non-finite."""


def _real(key: str, value: Any) -> float:
    """Return ``value`` as a finite float, or raise RlsError naming ``key``."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise RlsError(f"{key} must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise RlsError(f"{key} must be finite, got {value!r}")
    return out


@dataclass(frozen=True)
class RlsConfig:
    """Frozen settings of the identifier.

    Attributes
    ----------
    rho : float
        Forgetting factor ρ of Eqs. 27-31, ``0 < rho <= 1`` (dimensionless). The paper uses
        0.95. ``rho = 1`` is ordinary recursive least squares.
    alpha : float
        ``P(0) = alpha I`` (Eq. 32), ``alpha > 0``. Large means a weak prior on Θ(0).
    forgetting : {"exponential", "printed"}
        ``"exponential"`` (default) divides the Eq. 30 update by ρ, the standard exponentially
        weighted RLS; ``"printed"`` is Eq. 30 as printed, which never forgets.
    trace_max : float or None
        Upper bound on ``trace(P)`` (the wind-up guard, see the module docstring); ``None``
        disables it. Must be ``> 0``. A bound below ``alpha * (3n+1) = trace(P(0))`` is allowed
        and makes the guard act from the first update.

    Raises
    ------
    RlsError
        On construction, if a value is out of range (the message names the field).
    """

    rho: float = 0.95
    alpha: float = 1.5e5
    forgetting: Forgetting = "exponential"
    trace_max: float | None = None

    def __post_init__(self) -> None:
        rho = _real("rho", self.rho)
        if not 0.0 < rho <= 1.0:
            raise RlsError(f"rho must satisfy 0 < rho <= 1, got {self.rho!r}")
        alpha = _real("alpha", self.alpha)
        if not alpha > 0.0:
            raise RlsError(f"alpha must be > 0, got {self.alpha!r}")
        if self.forgetting not in _FORGETTING:
            raise RlsError(
                f"forgetting must be one of {', '.join(_FORGETTING)}, got {self.forgetting!r}"
            )
        trace_max = self.trace_max
        if trace_max is not None:
            trace_max = _real("trace_max", trace_max)
            if not trace_max > 0.0:
                raise RlsError(f"trace_max must be > 0 or None, got {self.trace_max!r}")
        # Normalise numpy / int scalars to float so equality and hashing behave.
        object.__setattr__(self, "rho", rho)
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "trace_max", trace_max)

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> RlsConfig:
        """Build a config from a mapping (e.g. ROS parameters read once).

        Parameters
        ----------
        d : Mapping[str, Any]
            Any subset of ``rho``, ``alpha``, ``forgetting``, ``trace_max``; missing keys take
            the defaults.

        Returns
        -------
        RlsConfig

        Raises
        ------
        RlsError
            One line naming the offending key: an unknown key, a wrong type (``bool`` is not a
            number) or a value out of range.
        """
        if not isinstance(d, Mapping):
            raise RlsError(f"RLS configuration must be a mapping, got {type(d).__name__}")
        known = ("rho", "alpha", "forgetting", "trace_max")
        unknown = sorted(str(k) for k in d if k not in known)
        if unknown:
            raise RlsError(
                f"unknown RLS parameter {unknown[0]!r} (expected one of {', '.join(known)})"
            )
        return RlsConfig(**{k: d[k] for k in known if k in d})


@dataclass(frozen=True)
class RlsStep:
    """Diagnostics of one :meth:`Rls.update`.

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

    Notes
    -----
    Until :meth:`reset` is called with arguments, ``Θ(0) = 0`` (so ``F = G = 0``, ``w = 0``)
    and ``P(0) = alpha I``. The paper initialises ``F(0), G(0)`` from Eq. 33; pass them to
    :meth:`reset`.

    The accessors :attr:`theta`, :attr:`P`, :attr:`F`, :attr:`G`, :attr:`w` return **copies**:
    holding one across an update never sees the update, and writing to one never changes the
    estimator.
    """

    def __init__(self, n_joints: int, config: RlsConfig) -> None:
        if isinstance(n_joints, bool) or not isinstance(n_joints, int | np.integer):
            raise RlsError(f"n_joints must be an int, got {n_joints!r}")
        if n_joints < 1:
            raise RlsError(f"n_joints must be >= 1, got {n_joints}")
        if not isinstance(config, RlsConfig):
            raise RlsError(f"config must be an RlsConfig, got {type(config).__name__}")
        self._n = int(n_joints)
        self._p = 2 * self._n
        self._m = 3 * self._n + 1
        self._config = config
        self._exponential = config.forgetting == "exponential"
        m, p = self._m, self._p
        # State, double-buffered: an update is computed into the spares and swapped in only
        # when finite, so a rejected update leaves the state untouched without allocating.
        self._theta = np.zeros((m, p))
        self._theta_spare = np.empty((m, p))
        self._P = np.empty((m, m))
        self._P_spare = np.empty((m, m))
        self._pz = np.empty(m)  # P z
        self._e = np.empty(p)  # residual
        self._k = 0
        self._theta0 = np.zeros((m, p))
        self._P0 = config.alpha * np.eye(m)
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
        """m = 3n+1, the regressor dimension (Eq. 23)."""
        return self._m

    @property
    def n_updates(self) -> int:
        """Number of accepted updates since the last :meth:`reset`."""
        return self._k

    @property
    def theta(self) -> np.ndarray:
        """Copy of Θ = [F G w]ᵀ, shape (3n+1, 2n) (Eq. 22)."""
        return self._theta.copy()

    @property
    def P(self) -> np.ndarray:
        """Copy of P, shape (3n+1, 3n+1), symmetric positive definite."""
        return self._P.copy()

    @property
    def F(self) -> np.ndarray:
        """Copy of F̂, shape (2n, 2n)."""
        return self._theta[: self._p].T.copy()

    @property
    def G(self) -> np.ndarray:
        """Copy of Ĝ, shape (2n, n)."""
        return self._theta[self._p : self._p + self._n].T.copy()

    @property
    def w(self) -> np.ndarray:
        """Copy of ŵ, shape (2n,)."""
        return self._theta[self._p + self._n].copy()

    @property
    def trace_p(self) -> float:
        """trace(P)."""
        return float(np.trace(self._P))

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
        G0 : array_like, shape (2n, n)
            Ĝ(0), e.g. from Eq. 33b.
        w0 : array_like, shape (2n,), optional
            ŵ(0); default 0.
        P0 : array_like, shape (3n+1, 3n+1), optional
            P(0), symmetric positive definite; default ``alpha I`` (Eq. 32). Symmetric to
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
        n, p, m = self._n, self._p, self._m
        F0a = _matrix("F0", F0, (p, p))
        G0a = _matrix("G0", G0, (p, n))
        w0a = np.zeros(p) if w0 is None else _matrix("w0", w0, (p,))
        if P0 is None:
            P0a = self._config.alpha * np.eye(m)
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
        theta0[p : p + n] = G0a.T
        theta0[p + n] = w0a
        self._theta0 = theta0
        self._P0 = P0a
        self._restore()

    def _restore(self) -> None:
        self._theta[...] = self._theta0
        self._P[...] = self._P0
        self._k = 0
        self._can_undo = False

    def undo(self) -> None:
        """Take back the last :meth:`update` (Θ, P and the count), e.g. when a projection
        onto physically possible parameters refuses its result.

        Raises
        ------
        RlsError
            If there is no update to take back (only the last one can be).
        """
        if not getattr(self, "_can_undo", False):
            raise RlsError("undo: no update to take back")
        self._theta, self._theta_spare = self._theta_spare, self._theta
        self._P, self._P_spare = self._P_spare, self._P
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
        z = _vector("z", z, self._m)
        dx_next = _vector("dx_next", dx_next, self._p)
        # Overflow shows up as inf/nan and is rejected below; no RuntimeWarning on the way.
        with np.errstate(all="ignore"):
            theta_new, P_new, gamma, trace_p, clipped = self._candidate(z, dx_next)
        self._theta_spare, self._theta = self._theta, theta_new
        self._P_spare, self._P = self._P, P_new
        self._k += 1
        self._can_undo = True
        return RlsStep(residual=self._e.copy(), gamma=gamma, trace_p=trace_p, clipped=clipped)

    def _candidate(
        self, z: np.ndarray, dx_next: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, float, float, bool]:
        """Compute Θ(k+1), P(k+1) into the spare buffers; raise RlsError if not finite."""
        rho = self._config.rho
        P, theta = self._P, self._theta
        pz, e = self._pz, self._e

        np.dot(P, z, out=pz)  # P z
        denom = float(np.dot(z, pz)) + rho
        if not (math.isfinite(denom) and denom > 0.0):
            raise RlsError(f"update rejected: zᵀ P z + rho = {denom!r} (z too large?)")
        gamma = 1.0 / denom
        np.dot(z, theta, out=e)  # Θᵀ z
        np.subtract(dx_next, e, out=e)  # Eq. 26
        if not np.isfinite(e).all():
            raise RlsError("update rejected: residual is not finite")

        # Eq. 29: Θ + γ (P z) eᵀ
        theta_new = self._theta_spare
        np.multiply.outer(pz, e, out=theta_new)
        theta_new *= gamma
        theta_new += theta
        # Eq. 30: P - γ (P z)(P z)ᵀ, using P zzᵀ P = (P z)(P z)ᵀ for symmetric P. Every step is
        # elementwise on exactly symmetric arrays, so the result is exactly symmetric.
        P_new = self._P_spare
        np.multiply.outer(pz, pz, out=P_new)
        P_new *= -gamma
        P_new += P
        if self._exponential:
            P_new /= rho
        trace_p = float(np.trace(P_new))
        clipped = False
        trace_max = self._config.trace_max
        if trace_max is not None and trace_p > trace_max:
            P_new *= trace_max / trace_p
            trace_p = float(np.trace(P_new))
            clipped = True
        if not (
            math.isfinite(trace_p)
            and np.isfinite(theta_new).all()
            and np.isfinite(P_new).all()
            and (np.diagonal(P_new) > 0.0).all()
        ):
            raise RlsError("update rejected: Θ or P would become non-finite or P indefinite")

        return theta_new, P_new, gamma, trace_p, clipped

    # ------------------------------------------------------------------ helpers
    def predict(self, z: np.ndarray) -> np.ndarray:
        """One-step prediction ``Θᵀ z = F̂ δx + Ĝ δu + ŵ`` (Eq. 25), shape (2n,).

        Raises
        ------
        RlsError
            If ``z`` is not a finite (3n+1,) vector.
        """
        return _vector("z", z, self._m) @ self._theta

    @staticmethod
    def regressor(dx: np.ndarray, du: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Build ``z = (δx, δu, 1)`` of Eq. 23.

        Parameters
        ----------
        dx : array_like, shape (2n,)
            δx(k) = x(k) - x_n(k), positions then velocities.
        du : array_like, shape (n,)
            δu(k), the perturbation torque applied over [kT, (k+1)T).
        out : numpy.ndarray, shape (3n+1,), optional
            Float64 buffer to write into (avoids an allocation per sample).

        Returns
        -------
        numpy.ndarray, shape (3n+1,)

        Raises
        ------
        RlsError
            If ``du`` is not a finite (n,) vector with n ≥ 1, ``dx`` not a finite (2n,)
            vector, or ``out`` not a float64 (3n+1,) array.
        """
        du_a = np.asarray(du, dtype=float)
        if du_a.ndim != 1 or du_a.shape[0] < 1:
            raise RlsError(f"du must have shape (n,) with n >= 1, got {du_a.shape}")
        n = du_a.shape[0]
        du_a = _vector("du", du_a, n)
        dx_a = _vector("dx", dx, 2 * n)
        if out is None:
            out = np.empty(3 * n + 1)
        elif not (
            isinstance(out, np.ndarray) and out.shape == (3 * n + 1,) and out.dtype == np.float64
        ):
            raise RlsError(f"out must be a float64 array of shape ({3 * n + 1},)")
        out[: 2 * n] = dx_a
        out[2 * n : 3 * n] = du_a
        out[3 * n] = 1.0
        return out


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
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise RlsError(f"{name} must be a real array of shape {shape}") from None
    if a.shape != shape:
        raise RlsError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.isfinite(a).all():
        raise RlsError(f"{name} must be finite")
    return a
