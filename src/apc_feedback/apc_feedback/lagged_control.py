"""The adaptive law's receding-horizon controller over its lagged inputs (no rclpy).

With ``L`` input lags the identified model is ``δx(k+1) = F δx + G₀ δu(k) + G₁ δu(k-1) + … +
G_L δu(k-L) + w``, and the law plans over the state ``(δx(k), δu(k-1), …, δu(k-L), ξ(k+1))``
(the inputs already on their way, the integral). :func:`receding_controller` builds that
controller with its constant entries written once; :func:`weigh_input_change` writes the cost
of the planned input's change from one step to the next.

Why the change is weighed. Sampled positions do not see an input that alternates from one
sample to the next: the zero-order hold's double integrator has its sampling zero at ``z = -1``
(Åström & Wittenmark, *Computer-Controlled Systems*, sampling zeros), and a velocity estimated
from positions inherits it. With the preset's cheap position weight the law keeps compensating
its own inputs on their way, and an alternating sequence of them costs it nothing to continue:
on its own prior model (the Panda, a 100 Hz driver, positions only) the closed loop has
eigenvalues at -1.000 to -1.002. Its commands then ring at the Nyquist frequency on a hold
(±2-5 N m on the Panda's shoulder and elbow while the position error stays under 0.002°), and
whether the move after it is tracked or the arm is lost within 50 ms of the move's end
depends on the ringing's phase, i.e. on whether the hold lasted an odd or an even number of
samples. A weight on ``δu(j) - δu(j-1)`` is generalised predictive control's move suppression
(Clarke, Mohtadi & Tuffs 1987); it is measured here on the velocity the change makes in the
law's own model, ``|Ĝv (δu(j) - δu(j-1))|²`` with ``Ĝv`` the identified velocity block (≈ T D⁻¹,
summed over the lags), so one weight suits a heavy shoulder and a light wrist, carries over to
other periods, and scales with the rest of the plan: measured on the prior's block instead, a
law whose Ĝ was forced to 1 % of it (it believes a torque does a hundredth of what it does)
was held back to 4.2° where it repairs itself within 1.5°.
"""

from __future__ import annotations

import numpy as np

from apc_feedback.adaptive_config import AdaptiveConfig
from apc_feedback.optimal import RecedingHorizonControl

__all__ = ["receding_controller", "weigh_input_change"]


def receding_controller(
    config: AdaptiveConfig, q_diagonal: np.ndarray, R: np.ndarray, n: int
) -> RecedingHorizonControl | None:
    """The receding-horizon controller of ``config``'s model (None: the one-step law of Eq. 35
    does), with the model's constant entries written: the shift of the lagged inputs, the
    decision entering as ``δu(k-1)`` one step on, the integral's identity. The adaptive law
    writes the identified blocks every sample
    (:meth:`apc_feedback.controller.AdaptiveFeedback._receding_control`)."""
    lags, integral = config.input_lags, config.q_integral > 0.0
    if lags == 0 and not integral and config.horizon == 1:
        return None
    p = 2 * n
    s = p + lags * n
    weights = [q_diagonal, np.zeros(lags * n)]
    if integral:
        weights.append(np.full(n, config.q_integral))
    control = RecedingHorizonControl(np.concatenate(weights), R, config.horizon + lags)
    if lags:
        control.G[p : p + n] = np.eye(n)  # v = δu(k) is δu(k-1) one step on
        control.F[p + n : s, p : s - n] = np.eye((lags - 1) * n)  # δu(k-j) -> δu(k-j-1)
    if integral:
        control.F[s:, s:] = np.eye(n)  # ξ(k+1) = ξ(k) + …
    return control


def weigh_input_change(
    control: RecedingHorizonControl, velocity_gain: np.ndarray, weight: float, out: np.ndarray
) -> None:
    """Weigh the change of the planned input, ``weight |Gv (δu(j) - δu(j-1))|²`` at every step
    of the horizon, into ``control``'s ``Q`` (a model with input lags: its state holds
    ``δu(j-1)``, ``δu(j-2)`` at the entries ``2n … 4n``).

    ``velocity_gain``: ``Gv`` (n, n), the velocity block of the identified input matrix summed
    over the lags; ``out``: an (n, n) buffer. The block ``[[S, -S], [-S, S]]`` with ``S = weight
    GvᵀGv`` is symmetric positive semi-definite, so ``Q`` stays a valid weight.
    """
    n = velocity_gain.shape[0]
    p = 2 * n
    np.dot(velocity_gain.T, velocity_gain, out=out)
    out *= weight
    Q = control.Q
    newest, older = slice(p, p + n), slice(p + n, p + 2 * n)
    Q[newest, newest] = out
    Q[older, older] = out
    np.negative(out, out=out)
    Q[newest, older] = out
    Q[older, newest] = out
