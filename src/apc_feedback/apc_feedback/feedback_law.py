"""The interface every feedback law implements, and what one sample of a law gives.

A law answers one question per sample ``k``: given the measured state ``(q, q')(k)``, the set
point ``(q_d, qd_d, qdd_d, u_n)(k)`` and the torque the plant applied over the period that ended
at ``k``, what perturbation torque ``du(k)`` goes to the plant (which applies ``u_n(k) +
du(k)``)? Laws hold their own small mutable state (``reset()`` rebuilds it) and are told the
sample index, never a clock. The laws: :mod:`apc_feedback.controller` (adaptive) and
:mod:`apc_feedback.baselines`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, NamedTuple

import numpy as np

from apc_feedback.adaptive_config import FeedbackError


class FeedbackOutput(NamedTuple):
    """One sample of a feedback law (a named tuple: made every sample, cheaply).

    Attributes
    ----------
    du : (n,) ndarray
        Perturbation torque (N m) for the period starting at ``k``.
    residual : (2n,) ndarray or None
        A-priori RLS residual of Eq. 26 for the step ``k-1 -> k`` (adaptive law only).
    trace_p : float
        ``trace(P)`` after the update (adaptive law only; NaN otherwise).
    rejected : bool
        The identifier refused this sample's update (it would have made P or Θ non-finite or
        P indefinite, which is what covariance wind-up ends in); the previous estimate is kept.
    skipped : bool
        No update: sample ``k - 1`` was not handled (a gap), so the step to ``k`` is not the
        one-period transition Eq. 16 describes.
    """

    du: np.ndarray
    residual: np.ndarray | None = None
    trace_p: float = float("nan")
    rejected: bool = False
    skipped: bool = False


class FeedbackLaw(ABC):
    """A feedback law of the feedback node (see module docstring)."""

    kind: str = ""

    def __init__(self, n_joints: int) -> None:
        self.n_joints = n_joints

    @property
    def settings(self) -> Any:
        """The law's settings dataclass (None for a law without settings)."""
        return None

    def reconfigure(self, settings: Any) -> None:
        """Take new run-time settings (the fields made with ``runtime=True``) from the next
        sample on, keeping what the law has learnt."""
        raise FeedbackError(f"controller {self.kind!r} has no run-time settings")

    @abstractmethod
    def reset(self) -> None:
        """Forget all state; the next :meth:`update` is treated as the first sample."""

    @abstractmethod
    def update(
        self,
        k: int,
        q: np.ndarray,
        qd: np.ndarray,
        q_d: np.ndarray,
        qd_d: np.ndarray,
        qdd_d: np.ndarray,
        u_n: np.ndarray,
        applied: np.ndarray | None,
    ) -> FeedbackOutput:
        """Perturbation torque for sample ``k``.

        Parameters
        ----------
        k : int
            Sample index (time ``k T``).
        q, qd : (n,) ndarray
            Measured joint position (rad) and velocity (rad/s) at ``k``.
        q_d, qd_d, qdd_d, u_n : (n,) ndarray
            Set point at ``k`` and its nominal torque (N m).
        applied : (n,) ndarray or None
            Torque the plant applied over ``[(k-1)T, kT)`` (``JointState.effort``); None at
            the first sample or when the plant does not report it.
        """
