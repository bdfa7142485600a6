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

Why the weight is raised where the plan's own inputs would grow. While the arm does not
answer (held still by its Coulomb friction at the end of a move, a torque at its limit) the
state error stays put and the plan's next input is a linear map of the inputs on their way;
at the preset's cheap position weight, with a command acting a whole period after its state
(a 100 Hz driver), that map pushes each input back harder than it came (spectral radius 1.42
on the Panda, 1.41 on the 3-joint PUMA; 0.71 on the Panda at 250 Hz). The commands then grow
at the Nyquist frequency until they break the arm free, and the arm is lost (the Panda with
friction on a 100 Hz driver that publishes its velocity: every run). ``input_ring_limit``
(:func:`input_ringing`, :func:`damped_input_change`) doubles the change's weight until that
radius is within the limit, at each (re)start and every :data:`RING_CHECK_PERIOD_S`; on a
driver of 500 Hz or more the preset's weight is within it already, at 250 Hz on an ideal arm
(a physical arm's identified lags raise it a few times).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from apc_feedback.adaptive_config import AdaptiveConfig
from apc_feedback.optimal import RecedingHorizonControl

__all__ = [
    "damped_input_change",
    "input_change_cap",
    "input_ringing",
    "receding_controller",
    "summed_inputs",
    "weigh_input_change",
    "write_identified",
]

#: How often (s) the adaptive law checks its own inputs' ringing against ``input_ring_limit``,
#: besides each (re)start: its model moves with the set point, by a few per cent over a move.
RING_CHECK_PERIOD_S = 0.1
#: The input change's weight is raised to at most this many doublings of ``q_input_change``
#: (x 1e6) in all: with a weight that large the plan holds its input from step to step, and
#: the radius tends to 1 from one side or the other, so a limit at or under 1 may be out of
#: reach (the weight then stays at its cap rather than growing without bound).
MAX_RING_DOUBLINGS = 20


def receding_controller(
    config: AdaptiveConfig, q_diagonal: np.ndarray, R: np.ndarray, n: int
) -> RecedingHorizonControl | None:
    """The receding-horizon controller of ``config``'s model (None: the one-step law of Eq. 35
    does), with the model's constant entries written: the shift of the lagged inputs, the
    decision entering as ``δu(k-1)`` one step on, the integral's identity. The adaptive law
    writes the identified blocks every sample
    (:func:`write_identified`)."""
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


def write_identified(
    control: RecedingHorizonControl,
    model: np.ndarray,
    lags: int,
    integral_period: float,
    velocity_gain: np.ndarray | None,
    weight: float,
    out: np.ndarray,
) -> None:
    """Write the identified model ``Θᵀ = [F G₀ … G_L w]`` (2n rows) into ``control``'s model
    (:func:`receding_controller` wrote its constant entries): ``F``, the decision's ``G₀``, the
    lags' ``G_j`` as the state's columns and ``w``; with ``integral_period`` T > 0 the integral's
    rows ``T C (F δx + G δu + w)``; with ``velocity_gain`` (the identified velocity block summed
    over the lags) the input change weighed at ``weight`` (:func:`weigh_input_change`, ``out``
    its buffer)."""
    p = model.shape[0]
    n = p // 2
    s = p + lags * n  # the state without the integral
    F, G, w = control.F, control.G, control.w
    F[:p, :p] = model[:, :p]
    G[:p] = model[:, p : p + n]
    w[:p] = model[:, -1]
    if lags:
        F[:p, p:s] = model[:, p + n : p + n + lags * n]
    if velocity_gain is not None:
        weigh_input_change(control, velocity_gain, weight, out)
    if integral_period > 0.0:
        np.multiply(F[:n, :s], integral_period, out=F[s:, :s])
        np.multiply(G[:n], integral_period, out=G[s:])
        np.multiply(w[:n], integral_period, out=w[s:])


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


def input_ringing(control: RecedingHorizonControl, lags: int, reuse: bool = False) -> float:
    """The spectral radius of the plan's own dynamics over its inputs on their way, for the
    model and weights written into ``control``: with the arm not answering (stuck in its
    friction, a torque at its limit, a drive that ignores it) the state error stays put and
    the law's next input is ``δu(k) = -K₁ δu(k-1) - … - K_L δu(k-L)`` plus a constant, ``K_j``
    the first step's gains on the lagged inputs (:meth:`RecedingHorizonControl.gain`).

    Above 1 the law's commands grow at the Nyquist frequency whenever the arm stops answering:
    a plan that compensates its inputs on their way at a cheap position weight pushes each
    one back harder than it was (the Panda on a 100 Hz driver, the recommended preset's
    weights: 1.42), and an arm held by its Coulomb friction at a hold is then lost once the
    torque breaks it free (docs/robot.md, "Commands that grow while the arm does not
    answer"). ``reuse``: the gains of the plan the last ``control.solve()`` computed (its
    model unchanged since), at the cost of a small solve.
    """
    if lags < 1:
        return 0.0
    n = control.G.shape[1]
    p = 2 * n
    gains = control.gain(slice(p, p + lags * n), reuse)
    companion = np.zeros((lags * n, lags * n))
    np.negative(gains, out=companion[:n])
    companion[n:, :-n] = np.eye((lags - 1) * n)
    return float(np.max(np.abs(np.linalg.eigvals(companion))))


def input_change_cap(q_input_change: float) -> float:
    """The largest weight of the input's change the ring check raises ``q_input_change`` to:
    :data:`MAX_RING_DOUBLINGS` doublings of it."""
    return q_input_change * 2.0**MAX_RING_DOUBLINGS


def damped_input_change(
    write: Callable[[float], RecedingHorizonControl],
    weight: float,
    lags: int,
    limit: float,
    cap: float,
) -> float:
    """The weight of the input's change at which the plan's own inputs do not ring:
    ``weight`` doubled until :func:`input_ringing` of the plan ``write(weight)`` (the model
    written, the change weighed at that weight) is within ``limit``, never past ``cap`` (the
    plan is then written at the cap). Nothing to raise with fewer than two lags (no change in
    the planned state to weigh) or a weight of 0 (the change not weighed)."""
    if lags < 2 or weight <= 0.0:
        return weight
    while True:
        control = write(weight)
        if weight >= cap or input_ringing(control, lags) <= limit:
            return weight
        weight = min(2.0 * weight, cap)


def summed_inputs(G: np.ndarray, n: int) -> np.ndarray:
    """``G₀ + G₁ + …`` of a stacked ``[G₀ G₁ …]`` (rows, (L+1) n): the effect of an input held
    over every lag's period (a fresh array)."""
    return np.add.reduce(G.reshape(G.shape[0], -1, n), axis=1)
