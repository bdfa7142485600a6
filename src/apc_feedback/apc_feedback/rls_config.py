"""Settings of the recursive least squares identifier (:mod:`apc_feedback.rls`): forgetting,
``P(0)`` and its prior on the model, the wind-up guard. Plain Python, no ROS."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

__all__ = ["RlsConfig", "RlsError"]

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
        disables it. Must be ``> 0``. A bound below ``trace(P(0))`` is allowed and makes the
        guard act from the first update. With ``alpha_model`` it is shared among the three
        blocks of ``P`` in their proportions at ``P(0)``.
    alpha_model : float or None
        ``P(0)`` of the ``δx`` and ``δu`` rows of ``z`` (the prior on ``F̂(0), Ĝ(0)``, see the
        module docstring): ``P(0) = diag(alpha_model I_3n, alpha)``. ``None`` (default):
        ``alpha`` for every row, Eq. 32.

    Raises
    ------
    RlsError
        On construction, if a value is out of range (the message names the field).
    """

    rho: float = 0.95
    alpha: float = 1.5e5
    forgetting: Forgetting = "exponential"
    trace_max: float | None = None
    alpha_model: float | None = None

    def initial_p_diagonal(self, n_joints: int, input_lags: int = 0) -> np.ndarray:
        """The diagonal of ``P(0)`` for an arm of ``n_joints`` whose model has ``input_lags``
        delayed inputs, shape (2n + (1 + lags) n + 1,)."""
        model = self.alpha if self.alpha_model is None else self.alpha_model
        return np.concatenate([np.full((3 + input_lags) * n_joints, model), [self.alpha]])

    def block_trace_max(self, n_joints: int, input_lags: int = 0) -> np.ndarray | None:
        """Per block of ``P`` (``δx``, the inputs, constant rows), the bound on its trace; None
        when one bound on ``trace(P)`` is the guard (no ``alpha_model``) or there is no guard."""
        if self.trace_max is None or self.alpha_model is None:
            return None
        diagonal = self.initial_p_diagonal(n_joints, input_lags)
        p = 2 * n_joints
        blocks = np.array([diagonal[:p].sum(), diagonal[p:-1].sum(), diagonal[-1]])
        return blocks * (self.trace_max / diagonal.sum())

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
        alpha_model = self.alpha_model
        if alpha_model is not None:
            alpha_model = _real("alpha_model", alpha_model)
            if not alpha_model > 0.0:
                raise RlsError(f"alpha_model must be > 0 or None, got {self.alpha_model!r}")
        # Normalise numpy / int scalars to float so equality and hashing behave.
        object.__setattr__(self, "alpha_model", alpha_model)
        object.__setattr__(self, "rho", rho)
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "trace_max", trace_max)

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> RlsConfig:
        """Build a config from a mapping (e.g. ROS parameters read once).

        Parameters
        ----------
        d : Mapping[str, Any]
            Any subset of ``rho``, ``alpha``, ``forgetting``, ``trace_max``, ``alpha_model``;
            missing keys take the defaults.

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
        known = ("rho", "alpha", "forgetting", "trace_max", "alpha_model")
        unknown = sorted(str(k) for k in d if k not in known)
        if unknown:
            raise RlsError(
                f"unknown RLS parameter {unknown[0]!r} (expected one of {', '.join(known)})"
            )
        return RlsConfig(**{k: d[k] for k in known if k in d})
