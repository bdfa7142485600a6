"""One-step optimal control of Eqs. 34-35 (apc_feedback.optimal)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from apc_feedback.optimal import (
    ControlError,
    OneStepControl,
    RecedingHorizonControl,
    one_step_control,
    one_step_cost,
    receding_horizon_control,
    validate_weights,
)


def random_problem(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    p = 2 * n
    A = rng.standard_normal((p, p))
    Bq = rng.standard_normal((p, p))
    Br = rng.standard_normal((n, n))
    return {
        "F": np.eye(p) + 0.1 * A,
        "G": rng.standard_normal((p, n)),
        "w": rng.standard_normal(p),
        "Q": Bq @ Bq.T,
        "R": Br @ Br.T + 0.1 * np.eye(n),
        "x": rng.standard_normal(p),
    }


def gradient(F, G, w, Q, R, x, u) -> np.ndarray:
    """∂J/∂u of Eq. 34 under Eq. 16: Gᵀ Q (F x + G u + w) + R u."""
    return G.T @ Q @ (F @ x + G @ u + w) + R @ u


# ----------------------------------------------------------------------------------- optimality
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("n", [1, 2, 3])
def test_control_minimises_the_one_step_cost(seed: int, n: int) -> None:
    rng = np.random.default_rng(100 * n + seed)
    pb = random_problem(rng, n)
    u_star = one_step_control(**pb)
    assert u_star.shape == (n,)
    cost = lambda u: one_step_cost(u=u, **pb)  # noqa: E731
    res = minimize(
        cost,
        np.zeros(n),
        jac=lambda u: gradient(u=u, **pb),
        method="BFGS",
        options={"gtol": 1e-12},
    )
    np.testing.assert_allclose(u_star, res.x, rtol=1e-6, atol=1e-8)
    assert cost(u_star) <= res.fun + 1e-12 * max(1.0, abs(res.fun))
    # First-order condition: the gradient vanishes at u*, relative to its size at u = 0.
    g0 = np.linalg.norm(gradient(u=np.zeros(n), **pb))
    assert np.linalg.norm(gradient(u=u_star, **pb)) <= 1e-10 * max(1.0, g0)
    # And J is strictly larger at random perturbations of u*.
    for _ in range(10):
        assert cost(u_star + 1e-3 * rng.standard_normal(n)) > cost(u_star)


def test_control_matches_brute_force_grid_for_one_joint() -> None:
    pb = {
        "F": np.array([[1.0, 0.01], [-0.3, 0.98]]),
        "G": np.array([[0.0], [0.02]]),
        "w": np.array([0.001, -0.05]),
        "Q": 0.1 * np.eye(2),
        "R": np.array([[1e-4]]),
        "x": np.array([0.02, -0.1]),
    }
    u_star = one_step_control(**pb)[0]
    grid = np.linspace(u_star - 1.0, u_star + 1.0, 200_001)  # step 1e-5
    costs = [one_step_cost(u=np.array([u]), **pb) for u in grid[::1000]]
    assert min(costs) >= one_step_cost(u=np.array([u_star]), **pb)
    # Dense scan in closed form (J is a quadratic in scalar u).
    F, G, w, Q, R, x = (pb[k] for k in ("F", "G", "w", "Q", "R", "x"))
    x_next = (F @ x + w)[:, None] + G @ grid[None, :]
    J = 0.5 * (np.einsum("ik,ij,jk->k", x_next, Q, x_next) + R[0, 0] * grid**2)
    assert abs(grid[np.argmin(J)] - u_star) <= 1e-5


@pytest.mark.parametrize(
    ("f", "g", "w", "q", "r", "x"),
    [
        (1.0, 1.0, 0.0, 1.0, 1.0, 1.0),
        (0.9, 0.5, 0.2, 2.0, 0.1, -1.5),
        (1.2, -0.01, -3.0, 0.1, 1e-6, 0.3),
        (0.5, 2.0, 1.0, 0.0, 1.0, 4.0),  # Q = 0: no reason to act
    ],
)
def test_scalar_case_by_hand(f: float, g: float, w: float, q: float, r: float, x: float) -> None:
    # dJ/du = g q (f x + g u + w) + r u = 0  ⇒  u* = -g q (f x + w) / (r + g² q)
    expected = -g * q * (f * x + w) / (r + g * g * q)
    args = ([[f]], [[g]], [w], [[q]], [[r]], [x])
    u = one_step_control(*args)
    assert u.shape == (1,)
    assert u[0] == pytest.approx(expected, rel=1e-12, abs=1e-15)
    # The printed Eq. 35: -g q f (x + w) / (r + g² q).
    printed = one_step_control(*args, form="printed")
    assert printed[0] == pytest.approx(-g * q * f * (x + w) / (r + g * g * q), rel=1e-12, abs=1e-15)


def test_paper_weights_on_paper_sized_model() -> None:
    # Q = 0.1 I6, R = 1e-6 I3 (paper, after Eq. 37) with a G of the size of Eq. 37.
    rng = np.random.default_rng(12)
    T = 0.01
    F = np.eye(6)
    F[:3, 3:] = T * np.eye(3)
    G = np.vstack([np.zeros((3, 3)), 0.003 * np.eye(3) + 0.001 * rng.standard_normal((3, 3))])
    Q, R = 0.1 * np.eye(6), 1e-6 * np.eye(3)
    x = np.r_[0.01 * rng.standard_normal(3), 0.1 * rng.standard_normal(3)]
    w = 1e-3 * rng.standard_normal(6)
    u = one_step_control(F, G, w, Q, R, x)
    assert np.linalg.norm(gradient(F, G, w, Q, R, x, u)) < 1e-12
    assert one_step_cost(F, G, w, Q, R, x, u) < one_step_cost(F, G, w, Q, R, x, np.zeros(3))


# ----------------------------------------------------------------------------------- printed form
def test_printed_form_differs_only_with_bias_and_non_identity_F() -> None:
    rng = np.random.default_rng(13)
    pb = random_problem(rng, 3)
    exact = one_step_control(**pb)
    printed = one_step_control(**pb, form="printed")
    assert np.linalg.norm(exact - printed) > 1e-3 * np.linalg.norm(exact)
    # The printed form is then not optimal.
    assert one_step_cost(u=printed, **pb) > one_step_cost(u=exact, **pb)
    # w = 0: identical.
    no_bias = {**pb, "w": np.zeros(6)}
    np.testing.assert_allclose(
        one_step_control(**no_bias, form="printed"),
        one_step_control(**no_bias),
        rtol=1e-12,
        atol=1e-14,
    )
    # F = I: identical as well.
    identity_F = {**pb, "F": np.eye(6)}
    np.testing.assert_allclose(
        one_step_control(**identity_F, form="printed"),
        one_step_control(**identity_F),
        rtol=1e-12,
        atol=1e-14,
    )


def test_one_step_cost_value() -> None:
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    G = np.array([[0.0], [1.0]])
    w = np.array([0.5, -1.0])
    Q = np.diag([2.0, 4.0])
    R = np.array([[3.0]])
    x = np.array([1.0, 2.0])
    u = np.array([0.5])
    # x⁺ = (3 + 0.5, 2 + 0.5 - 1) = (3.5, 1.5); J = ½ (2·12.25 + 4·2.25 + 3·0.25)
    assert one_step_cost(F, G, w, Q, R, x, u) == pytest.approx(0.5 * (24.5 + 9.0 + 0.75))


# ----------------------------------------------------------------------------------- validation
def _base() -> dict[str, np.ndarray]:
    return random_problem(np.random.default_rng(15), 3)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"R": -np.eye(3)}, "R must be positive definite"),
        ({"R": np.zeros((3, 3))}, "R must be positive definite"),
        ({"R": np.diag([1.0, 1.0, 0.0])}, "R must be positive definite"),
        ({"R": np.triu(np.ones((3, 3)))}, "R must be symmetric"),
        ({"R": np.eye(2)}, "R must have shape"),
        ({"Q": -np.eye(6)}, "Q must be positive semidefinite"),
        ({"Q": np.triu(np.ones((6, 6)))}, "Q must be symmetric"),
        ({"Q": np.eye(5)}, "Q must have shape"),
        ({"F": np.ones((6, 5))}, "F must be square"),
        ({"F": np.ones(6)}, "F must be square"),
        ({"G": np.ones((5, 3))}, "G must have shape"),
        ({"G": np.ones((6, 3, 1))}, "G must have shape"),
        ({"w": np.ones(5)}, "w must have shape"),
        ({"x": np.ones((6, 1))}, "x must have shape"),
        ({"x": np.r_[np.ones(5), np.nan]}, "x must be finite"),
        ({"w": np.r_[np.inf, np.ones(5)]}, "w must be finite"),
        ({"F": np.full((6, 6), np.nan)}, "F must be finite"),
        ({"G": np.full((6, 3), np.inf)}, "G must be finite"),
        ({"R": np.full((3, 3), np.nan)}, "R must be finite"),
    ],
)
def test_bad_arguments_raise_control_error(change: dict, message: str) -> None:
    pb = {**_base(), **change}
    with pytest.raises(ControlError, match=message):
        one_step_control(**pb)


def test_bad_form_and_unchecked_weights() -> None:
    pb = _base()
    with pytest.raises(ControlError, match="form"):
        one_step_control(**pb, form="paper")  # type: ignore[arg-type]
    Q, R = validate_weights(pb["Q"], pb["R"], 6, 3)
    np.testing.assert_array_equal(
        one_step_control(**{**pb, "Q": Q, "R": R}, check_weights=False),
        one_step_control(**pb),
    )
    assert issubclass(ControlError, ValueError)


def test_psd_Q_with_zero_block_is_accepted() -> None:
    # Q may be singular (Eq. 34 asks semidefinite), e.g. weighting positions only.
    pb = _base()
    Q = np.diag([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    u = one_step_control(**{**pb, "Q": Q})
    assert np.linalg.norm(gradient(**{**pb, "Q": Q}, u=u)) < 1e-10


# ----------------------------------------------------------------------------- per-sample form
@pytest.mark.parametrize("form", ["exact", "printed"])
@pytest.mark.parametrize("n", [1, 3, 7])
def test_one_step_control_object_equals_the_function(form: str, n: int) -> None:
    """OneStepControl on Θᵀ = [F G w] (Cholesky solve) equals one_step_control with diagonal Q."""
    rng = np.random.default_rng(40 + n)
    q_diagonal = np.concatenate([np.full(n, 1e3), np.full(n, 0.1)])
    R = 1e-6 * np.eye(n)
    control = OneStepControl(q_diagonal, R, form)
    for _ in range(20):
        pb = random_problem(rng, n)
        model_t = np.hstack([pb["F"], pb["G"], pb["w"][:, None]])
        expected = one_step_control(
            pb["F"], pb["G"], pb["w"], np.diag(q_diagonal), R, pb["x"], form
        )
        got = control(model_t, pb["x"])
        np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-12)
    # A fresh array each call: holding one never sees the next.
    first = control(model_t, pb["x"])
    second = control(model_t, -pb["x"])
    assert first is not second and not np.array_equal(first, second)


def test_one_step_control_object_rejects_bad_weights_and_singular_systems() -> None:
    with pytest.raises(ControlError, match="Q must be positive semidefinite"):
        OneStepControl(np.array([1.0, -1.0]), np.eye(1))
    with pytest.raises(ControlError, match="R must be positive definite"):
        OneStepControl(np.ones(2), np.zeros((1, 1)))
    with pytest.raises(ControlError, match="form"):
        OneStepControl(np.ones(2), np.eye(1), "lqr")
    control = OneStepControl(np.ones(2), np.eye(1))
    model_t = np.array([[1.0, 0.0, 1.0, 0.0], [0.0, 1.0, 1.0, 0.0]])  # [F G w], p = 2, n = 1
    assert np.isfinite(control(model_t, np.ones(2))).all()
    for row, col in ((0, 2), (1, 3)):  # a NaN in G (S not positive definite), in w (u not finite)
        bad = model_t.copy()
        bad[row, col] = np.nan
        with pytest.raises(ControlError, match="R \\+ Gᵀ Q G"):
            control(bad, np.ones(2))


# ------------------------------------------------------------------------- receding horizon
@pytest.mark.parametrize("horizon", [1, 2, 5])
@pytest.mark.parametrize(("n", "p"), [(1, 2), (3, 18), (7, 42)])
def test_receding_horizon_object_equals_the_function(horizon: int, n: int, p: int) -> None:
    """RecedingHorizonControl (buffers made once) gives receding_horizon_control's bits: the
    same operations in the same order."""
    rng = np.random.default_rng(60 + n + horizon)
    q_diagonal = rng.uniform(0.0, 1e3, p)
    R = 1e-6 * np.eye(n)
    control = RecedingHorizonControl(q_diagonal, R, horizon)
    for _ in range(10):
        F = np.eye(p) + 0.1 * rng.standard_normal((p, p))
        G, w, x = rng.standard_normal((p, n)), rng.standard_normal(p), rng.standard_normal(p)
        expected = receding_horizon_control(F, G, w, np.diag(q_diagonal), R, x, horizon)
        np.testing.assert_array_equal(control(F, G, w, x), expected)
    # With horizon 1 it is Eq. 35 (corrected); a fresh array each call.
    first = control(F, G, w, x)
    assert first is not control(F, G, w, x)
    if horizon == 1:
        one_step = one_step_control(F, G, w, np.diag(q_diagonal), R, x)
        np.testing.assert_allclose(first, one_step, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("horizon", [1, 3])
def test_the_receding_horizon_gain_gives_the_control_of_every_state(horizon: int) -> None:
    """``gain()`` is the first step's ``K`` of ``u = -K (x, 1)``: it gives ``solve()``'s input
    for any state (to rounding), and leaves the next ``solve()`` as it was."""
    rng = np.random.default_rng(7 + horizon)
    n, p = 3, 12
    control = RecedingHorizonControl(rng.uniform(0.0, 1e3, p), 1e-6 * np.eye(n), horizon)
    control.F[...] = np.eye(p) + 0.1 * rng.standard_normal((p, p))
    control.G[...] = rng.standard_normal((p, n))
    control.w[...] = rng.standard_normal(p)
    K = control.gain()
    assert K.shape == (n, p + 1)
    for _ in range(5):
        x = rng.standard_normal(p)
        control.x[...] = x
        u = control.solve()
        np.testing.assert_allclose(-K @ np.append(x, 1.0), u, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(control.solve(), u)
    # After a solve, its recursion reused gives the same gain, any columns of it.
    np.testing.assert_array_equal(control.gain(reuse=True), control.gain())
    np.testing.assert_allclose(control.gain(slice(2, 5), reuse=True), K[:, 2:5], rtol=1e-12)


def test_receding_horizon_object_rejects_bad_settings_and_singular_systems() -> None:
    with pytest.raises(ControlError, match="horizon"):
        RecedingHorizonControl(np.ones(2), np.eye(1), 0)
    with pytest.raises(ControlError, match="Q must be positive semidefinite"):
        RecedingHorizonControl(np.array([1.0, -1.0]), np.eye(1), 2)
    with pytest.raises(ControlError, match="R must be positive definite"):
        RecedingHorizonControl(np.ones(2), np.zeros((1, 1)), 2)
    control = RecedingHorizonControl(np.ones(2), np.eye(1), 3)
    F, G, w = np.eye(2), np.ones((2, 1)), np.zeros(2)
    assert np.isfinite(control(F, G, w, np.ones(2))).all()
    with pytest.raises(ControlError, match="R \\+ Gᵀ Q G"):
        control(F, np.full((2, 1), np.nan), w, np.ones(2))
