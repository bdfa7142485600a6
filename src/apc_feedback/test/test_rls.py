"""Recursive least squares of Eqs. 29-32 (apc_feedback.rls): identities and guards."""

from __future__ import annotations

import numpy as np
import pytest

from apc_feedback.rls import Rls, RlsConfig, RlsError, RlsStep
from apc_feedback.rls_reference import rls_update_reference

N = 3  # joints
P_DIM = 2 * N  # state
M = 3 * N + 1  # regressor


def random_system(rng: np.random.Generator, n: int = N) -> tuple[np.ndarray, ...]:
    """A random stable-ish (F, G, w): F near I with spectral radius about 0.9."""
    p = 2 * n
    A = rng.standard_normal((p, p))
    F = 0.9 * A / np.max(np.abs(np.linalg.eigvals(A)))
    G = rng.standard_normal((p, n))
    w = rng.standard_normal(p)
    return F, G, w


def theta_of(F: np.ndarray, G: np.ndarray, w: np.ndarray) -> np.ndarray:
    return np.vstack([F.T, G.T, w[None, :]])


def exciting_data(
    rng: np.random.Generator, F: np.ndarray, G: np.ndarray, w: np.ndarray, count: int
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Noise-free (z, dx_next) pairs with random, persistently exciting dx and du."""
    n = G.shape[1]
    out = []
    for _ in range(count):
        dx = rng.standard_normal(2 * n)
        du = rng.standard_normal(n)
        out.append((Rls.regressor(dx, du), F @ dx + G @ du + w))
    return out


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


# ----------------------------------------------------------------------------------- config
def test_config_defaults_and_from_dict() -> None:
    cfg = RlsConfig()
    assert (cfg.rho, cfg.alpha, cfg.forgetting, cfg.trace_max) == (
        0.95,
        1.5e5,
        "exponential",
        None,
    )
    assert RlsConfig.from_dict({}) == cfg
    cfg2 = RlsConfig.from_dict({"rho": 1, "alpha": 10, "forgetting": "printed", "trace_max": 5})
    assert cfg2 == RlsConfig(rho=1.0, alpha=10.0, forgetting="printed", trace_max=5.0)
    assert isinstance(cfg2.rho, float)


@pytest.mark.parametrize(
    ("d", "key"),
    [
        ({"rho": 0.0}, "rho"),
        ({"rho": 1.01}, "rho"),
        ({"rho": float("nan")}, "rho"),
        ({"rho": True}, "rho"),
        ({"rho": "0.9"}, "rho"),
        ({"alpha": -1.0}, "alpha"),
        ({"alpha": float("inf")}, "alpha"),
        ({"forgetting": "linear"}, "forgetting"),
        ({"trace_max": 0.0}, "trace_max"),
        ({"trace_max": float("nan")}, "trace_max"),
        ({"lambda": 0.9}, "lambda"),
    ],
)
def test_config_rejects_bad_values_naming_the_key(d: dict, key: str) -> None:
    with pytest.raises(RlsError, match=key) as info:
        RlsConfig.from_dict(d)
    assert "\n" not in str(info.value)


# ----------------------------------------------------------------------------------- identities
@pytest.mark.parametrize("rho", [1.0, 0.95])
def test_recovers_known_system_from_noise_free_data(rho: float) -> None:
    rng = np.random.default_rng(1)
    F, G, w = random_system(rng)
    rls = Rls(N, RlsConfig(rho=rho, alpha=1e8))
    # Start far from the truth (Eq. 33 gives something like I, 0).
    rls.reset(np.eye(P_DIM), np.zeros((P_DIM, N)), w0=np.full(P_DIM, 5.0))
    for z, dx_next in exciting_data(rng, F, G, w, 200):
        rls.update(z, dx_next)
    assert rls.n_updates == 200
    assert rel_err(rls.F, F) < 1e-8
    assert rel_err(rls.G, G) < 1e-8
    assert rel_err(rls.w, w) < 1e-8
    assert rel_err(rls.theta, theta_of(F, G, w)) < 1e-8
    # And the model now predicts the next state.
    z, dx_next = exciting_data(rng, F, G, w, 1)[0]
    np.testing.assert_allclose(rls.predict(z), dx_next, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("lags", [1, 2])
def test_recovers_the_input_matrices_of_a_delayed_plant(lags: int) -> None:
    """Data of ``δx(k+1) = F δx(k) + G₀ δu(k) + G₁ δu(k-1) + G₂ δu(k-2) + w`` (an input that
    reaches the plant late): the lagged regressor recovers every input matrix."""
    rng = np.random.default_rng(7)
    F, _, w = random_system(rng)
    G_all = rng.standard_normal((P_DIM, (lags + 1) * N))
    rls = Rls(N, RlsConfig(rho=0.95, alpha=1e8), input_lags=lags)
    assert rls.m == P_DIM + (lags + 1) * N + 1
    rls.reset(np.eye(P_DIM), np.zeros((P_DIM, (lags + 1) * N)))
    inputs = [rng.standard_normal(N) for _ in range(lags)]
    dx = rng.standard_normal(P_DIM)
    for _ in range(200):
        inputs.insert(0, rng.standard_normal(N))  # δu(k), then δu(k-1), …
        du = np.concatenate(inputs[: lags + 1])
        dx_next = F @ dx + G_all @ du + w
        rls.update(Rls.regressor(dx, du), dx_next)
        dx = dx_next / max(1.0, float(np.abs(dx_next).max()))  # keep the data scaled
    assert rel_err(rls.G, G_all) < 1e-8
    assert rel_err(rls.F, F) < 1e-8
    assert rel_err(rls.w, w) < 1e-8


def test_model_prior_guard_bounds_the_input_block_with_lags() -> None:
    config = RlsConfig(alpha=1e3, alpha_model=1e-3, trace_max=1e3 + 15 * 1e-3)
    np.testing.assert_allclose(config.block_trace_max(N, 2), [6e-3, 9e-3, 1e3])
    rls = Rls(N, config, input_lags=2)
    z = np.zeros(rls.m)
    z[-1] = 1.0
    for _ in range(500):  # a hold: nothing but the constant row is excited
        rls.update(z, np.zeros(P_DIM))
    d = rls.P.diagonal()
    assert d[:P_DIM].sum() <= 6e-3 * (1 + 1e-12)
    assert d[P_DIM:-1].sum() <= 9e-3 * (1 + 1e-12)


def test_lags_are_checked() -> None:
    with pytest.raises(RlsError, match="input_lags"):
        Rls(N, RlsConfig(), input_lags=-1)
    with pytest.raises(RlsError, match="G0"):
        Rls(N, RlsConfig(), input_lags=1).reset(np.eye(P_DIM), np.zeros((P_DIM, N)))


def _batch_solution(
    theta0: np.ndarray,
    P0: np.ndarray,
    data: list[tuple[np.ndarray, np.ndarray]],
    prior_weight: float,
    sample_weights: list[float],
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares with a quadratic prior, in closed form.

    Minimises  prior_weight ‖P0^{-1/2}(Θ - Θ0)‖²  +  Σ_i c_i ‖x_i - Θᵀ z_i‖²  over Θ.
    Returns (Θ, H⁻¹) with H = prior_weight P0⁻¹ + Σ c_i z_i z_iᵀ.
    """
    P0_inv = np.linalg.inv(P0)
    H = prior_weight * P0_inv
    b = prior_weight * P0_inv @ theta0
    for c, (z, x) in zip(sample_weights, data, strict=True):
        H = H + c * np.outer(z, z)
        b = b + c * np.outer(z, x)
    return np.linalg.solve(H, b), np.linalg.inv(H)


@pytest.mark.parametrize("count", [1, 2, 25])
@pytest.mark.parametrize("rho", [1.0, 0.9])
def test_exponential_update_equals_weighted_batch_least_squares(count: int, rho: float) -> None:
    # Identity: after k updates, Θ(k) minimises ρᵏ (Θ-Θ0)ᵀP0⁻¹(Θ-Θ0) + Σ ρ^(k-1-i) ‖e_i‖²
    # and P(k) = (ρᵏ P0⁻¹ + Σ ρ^(k-1-i) z_i z_iᵀ)⁻¹. Noisy data, a non-diagonal P0, modest α.
    rng = np.random.default_rng(2 + count)
    F, G, w = random_system(rng)
    data = [
        (z, x + 0.3 * rng.standard_normal(P_DIM)) for z, x in exciting_data(rng, F, G, w, count)
    ]
    F0, G0, w0 = random_system(rng)
    B = rng.standard_normal((M, M))
    P0 = 2.0 * np.eye(M) + 0.1 * (B @ B.T)
    rls = Rls(N, RlsConfig(rho=rho, alpha=3.0))
    rls.reset(F0, G0, w0, P0)
    steps = [rls.update(z, x) for z, x in data]
    k = len(data)
    theta_b, P_b = _batch_solution(
        theta_of(F0, G0, w0), P0, data, rho**k, [rho ** (k - 1 - i) for i in range(k)]
    )
    np.testing.assert_allclose(rls.theta, theta_b, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rls.P, P_b, rtol=1e-9, atol=1e-9)
    # The first residual is a-priori (Eq. 26): measured minus the prediction of Θ(0).
    z0, x0 = data[0]
    np.testing.assert_allclose(steps[0].residual, x0 - theta_of(F0, G0, w0).T @ z0, atol=1e-12)
    assert steps[0].gamma == pytest.approx(1.0 / (z0 @ P0 @ z0 + rho), rel=1e-12)


def test_printed_update_equals_unforgetting_batch_least_squares() -> None:
    # Eq. 30 as printed gives P(k)⁻¹ = P0⁻¹ + ρ⁻¹ Σ z zᵀ: every sample weighs 1/ρ, none is
    # forgotten.
    rng = np.random.default_rng(7)
    rho = 0.8
    F, G, w = random_system(rng)
    data = [(z, x + 0.3 * rng.standard_normal(P_DIM)) for z, x in exciting_data(rng, F, G, w, 30)]
    rls = Rls(N, RlsConfig(rho=rho, alpha=4.0, forgetting="printed"))
    for z, x in data:
        rls.update(z, x)
    theta_b, P_b = _batch_solution(
        np.zeros((M, P_DIM)), 4.0 * np.eye(M), data, 1.0, [1.0 / rho] * len(data)
    )
    np.testing.assert_allclose(rls.theta, theta_b, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(rls.P, P_b, rtol=1e-9, atol=1e-9)


# ----------------------------------------------------------------------------------- reference
@pytest.mark.parametrize(
    "config",
    [
        RlsConfig(rho=0.95, alpha=50.0),
        RlsConfig(rho=0.8, alpha=50.0, forgetting="printed"),
        RlsConfig(rho=0.9, alpha=50.0, trace_max=20.0),
        RlsConfig(rho=0.9, alpha=50.0, trace_max=50.0, alpha_model=0.5),
    ],
    ids=["exponential", "printed", "guarded", "model prior"],
)
def test_fast_update_equals_the_paper_written_reference(config: RlsConfig) -> None:
    # Rls.update computes all columns in stacked buffers; rls_update_reference writes Eqs.
    # 26, 29-31 column by column. Noisy exciting data, then a still stretch that winds P up
    # (and, guarded, makes the guard act), then exciting data again.
    rng = np.random.default_rng(11)
    F, G, w = random_system(rng)
    F0, G0, w0 = random_system(rng)
    rls = Rls(N, config)
    rls.reset(F0, G0, w0)
    theta, P = theta_of(F0, G0, w0), np.diag(config.initial_p_diagonal(N))
    still = Rls.regressor(np.full(P_DIM, 0.2), np.full(N, -0.1))
    data = exciting_data(rng, F, G, w, 120)
    data[40:80] = [(still, F @ still[:P_DIM] + G @ still[P_DIM:-1] + w)] * 40
    clipped = 0
    for z, x in data:
        x = x + 0.05 * rng.standard_normal(P_DIM)
        step = rls.update(z, x)
        theta, P, expected = rls_update_reference(theta, P, z, x, config)
        np.testing.assert_allclose(rls.theta, theta, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(rls.P, P, rtol=1e-9, atol=1e-9 * np.max(np.abs(P)))
        np.testing.assert_allclose(step.residual, expected.residual, rtol=1e-9, atol=1e-9)
        assert step.gamma == pytest.approx(expected.gamma, rel=1e-9)
        assert step.trace_p == pytest.approx(expected.trace_p, rel=1e-9)
        assert step.clipped == expected.clipped
        clipped += step.clipped
    assert (clipped > 0) == (config.trace_max is not None)


# ----------------------------------------------------------------------------------- forgetting
def test_exponential_forgets_a_parameter_jump_printed_does_not() -> None:
    rng = np.random.default_rng(3)
    sys_a = random_system(rng)
    sys_b = random_system(rng)
    theta_a, theta_b = theta_of(*sys_a), theta_of(*sys_b)
    before = exciting_data(rng, *sys_a, 300)
    after = exciting_data(rng, *sys_b, 300)
    errors = {}
    traces = {}
    for forgetting in ("exponential", "printed"):
        rls = Rls(N, RlsConfig(rho=0.95, alpha=1e6, forgetting=forgetting))
        trace = []
        for z, x in before + after:
            trace.append(rls.update(z, x).trace_p)
        errors[forgetting] = rel_err(rls.theta, theta_b)
        traces[forgetting] = np.array(trace)
    jump = rel_err(theta_a, theta_b)
    assert jump > 0.5
    # Exponential: the 300 new samples outweigh the old ones by 0.95^-300 ≈ 5e6.
    assert errors["exponential"] < 1e-6
    # Printed: old and new samples weigh the same, so the estimate sits between the two systems.
    assert errors["printed"] > 0.1 * jump
    # Printed P only shrinks (like 1/k); exponential P settles at a level set by ρ, about
    # (1 - ρ) m, instead of going to 0.
    assert np.all(np.diff(traces["printed"]) <= 1e-12 * traces["printed"][:-1])
    assert traces["exponential"][-1] > 10 * traces["printed"][-1]
    assert np.ptp(traces["exponential"][-100:]) < 0.5 * traces["exponential"][-1]


def test_rho_one_makes_both_forms_identical() -> None:
    rng = np.random.default_rng(4)
    data = exciting_data(rng, *random_system(rng), 20)
    a = Rls(N, RlsConfig(rho=1.0, forgetting="exponential"))
    b = Rls(N, RlsConfig(rho=1.0, forgetting="printed"))
    for z, x in data:
        a.update(z, x)
        b.update(z, x)
    assert np.array_equal(a.theta, b.theta)
    assert np.array_equal(a.P, b.P)


# ----------------------------------------------------------------------------------- P health
def test_P_stays_exactly_symmetric_and_positive_definite() -> None:
    rng = np.random.default_rng(5)
    F, G, w = random_system(rng)
    rls = Rls(N, RlsConfig(rho=0.95, alpha=1.5e5))
    for i, (z, x) in enumerate(exciting_data(rng, F, G, w, 2000)):
        # Mix in noisy and poorly exciting stretches.
        if 500 <= i < 700:
            z = Rls.regressor(np.full(P_DIM, 0.01), np.zeros(N))
        rls.update(z, x + 0.01 * rng.standard_normal(P_DIM))
        if i % 50 == 0:
            P = rls.P
            assert np.array_equal(P, P.T)
            np.linalg.cholesky(P)
    P = rls.P
    assert np.array_equal(P, P.T)
    assert np.linalg.eigvalsh(P)[0] > 0.0


@pytest.mark.parametrize(
    "z",
    [
        np.r_[np.zeros(M - 1), 1.0],  # no excitation: only the bias regressor
        np.r_[np.full(P_DIM, 0.2), np.full(N, -0.1), 1.0],  # the arm holding still
    ],
    ids=["bias-only", "repeated"],
)
def test_trace_guard_bounds_windup(z: np.ndarray) -> None:
    x = np.ones(P_DIM)
    free = Rls(N, RlsConfig(rho=0.95, alpha=100.0))
    trace_max = 5.0 * 100.0 * M
    guarded = Rls(N, RlsConfig(rho=0.95, alpha=100.0, trace_max=trace_max))
    free_traces, guarded_steps = [], []
    for _ in range(300):
        free_traces.append(free.update(z, x).trace_p)
        guarded_steps.append(guarded.update(z, x))
    # Unguarded: P winds up like ρ⁻ᵏ in the unexcited directions.
    assert np.all(np.diff(free_traces[5:]) > 0.0)
    assert free_traces[-1] > 1e6 * 100.0 * M
    # Guarded: trace(P) ≤ trace_max (to rounding), the guard reports when it acts.
    guarded_traces = np.array([s.trace_p for s in guarded_steps])
    assert np.all(guarded_traces <= trace_max * (1.0 + 1e-12))
    assert guarded.trace_p <= trace_max * (1.0 + 1e-12)
    assert any(s.clipped for s in guarded_steps)
    assert not guarded_steps[0].clipped
    P = guarded.P
    assert np.array_equal(P, P.T)
    np.linalg.cholesky(P)
    # Both still fit the one direction they were shown (the guarded one more slowly: its gain
    # P z is scaled down with P).
    np.testing.assert_allclose(free.predict(z), x, rtol=1e-9)
    np.testing.assert_allclose(guarded.predict(z), x, rtol=1e-4)


def test_model_prior_guard_bounds_each_block_of_p() -> None:
    # A hold: the regressor repeats, P winds up in every unexcited direction. With a model
    # prior each block stays within its share of trace_max, P symmetric positive definite.
    alpha, alpha_model = 1e3, 1e-2
    config = RlsConfig(rho=0.95, alpha=alpha, trace_max=alpha + 3 * N * alpha_model,
                       alpha_model=alpha_model)  # fmt: skip
    np.testing.assert_allclose(config.block_trace_max(N), [2 * N * 1e-2, N * 1e-2, alpha])
    rls = Rls(N, config)
    np.testing.assert_array_equal(rls.P.diagonal(), [alpha_model] * (3 * N) + [alpha])
    still = Rls.regressor(np.full(P_DIM, 1e-3), np.full(N, 2.0))
    steps = [rls.update(still, np.zeros(P_DIM)) for _ in range(400)]
    assert any(s.clipped for s in steps)
    d = rls.P.diagonal()
    assert d[:P_DIM].sum() <= 2 * N * alpha_model * (1 + 1e-12)
    assert d[P_DIM:-1].sum() <= N * alpha_model * (1 + 1e-12)
    assert d[-1] <= alpha * (1 + 1e-12)
    P = rls.P
    assert np.array_equal(P, P.T)
    np.linalg.cholesky(P)


def test_model_prior_keeps_g_through_a_sample_that_does_not_follow_the_model() -> None:
    # The estimate sits at the true (F, G, w); one sample arrives whose input was applied for
    # part of the period only (a command applied late), dx = F x + 0.6 G u + w. Without a prior
    # on the model that one sample moves Ĝ by a large fraction; with it Ĝ barely moves and ŵ
    # takes the residual.
    rng = np.random.default_rng(21)
    F, G, w = random_system(rng)
    z = Rls.regressor(1e-3 * rng.standard_normal(P_DIM), np.array([3.0, -2.0, 1.5]))
    late = F @ z[:P_DIM] + 0.6 * G @ z[P_DIM:-1] + w
    moved = {}
    for name, alpha_model in (("flat", None), ("prior", 1e-4)):
        rls = Rls(N, RlsConfig(alpha=1.5e5, alpha_model=alpha_model))
        rls.reset(F, G, w)
        rls.update(z, late)
        moved[name] = rel_err(rls.G, G)
    assert moved["flat"] > 0.1
    assert moved["prior"] < 1e-3


def test_trace_guard_keeps_identification_working() -> None:
    rng = np.random.default_rng(6)
    F, G, w = random_system(rng)
    rls = Rls(N, RlsConfig(rho=0.95, alpha=1e3, trace_max=1e3 * M))
    for z, x in exciting_data(rng, F, G, w, 300):
        rls.update(z, x)
    assert rel_err(rls.theta, theta_of(F, G, w)) < 1e-8


# ----------------------------------------------------------------------------------- reset
def test_reset_restores_initial_state_and_rejects_bad_input() -> None:
    rng = np.random.default_rng(8)
    F0, G0, w0 = random_system(rng)
    rls = Rls(N, RlsConfig(alpha=7.0))
    np.testing.assert_array_equal(rls.theta, np.zeros((M, P_DIM)))
    np.testing.assert_array_equal(rls.P, 7.0 * np.eye(M))
    rls.reset(F0, G0, w0)
    np.testing.assert_array_equal(rls.F, F0)
    np.testing.assert_array_equal(rls.G, G0)
    np.testing.assert_array_equal(rls.w, w0)
    np.testing.assert_array_equal(rls.P, 7.0 * np.eye(M))
    for z, x in exciting_data(rng, *random_system(rng), 5):
        rls.update(z, x)
    assert rls.n_updates == 5
    rls.reset()
    assert rls.n_updates == 0
    np.testing.assert_array_equal(rls.theta, theta_of(F0, G0, w0))
    np.testing.assert_array_equal(rls.P, 7.0 * np.eye(M))
    # w0 defaults to zero; P0 given is used.
    rls.reset(F0, G0, P0=2.0 * np.eye(M))
    np.testing.assert_array_equal(rls.w, np.zeros(P_DIM))
    np.testing.assert_array_equal(rls.P, 2.0 * np.eye(M))
    # Bad arguments name themselves and leave the state alone.
    before = (rls.theta, rls.P)
    bad = [
        ({"F0": F0[:-1], "G0": G0}, "F0"),
        ({"F0": F0, "G0": G0.T}, "G0"),
        ({"F0": F0, "G0": G0, "w0": np.r_[w0[:-1], np.nan]}, "w0"),
        ({"F0": F0, "G0": G0, "P0": -np.eye(M)}, "P0"),
        ({"F0": F0, "G0": G0, "P0": np.triu(np.ones((M, M)))}, "P0"),
        ({"F0": F0}, "G0"),
    ]
    for kwargs, name in bad:
        with pytest.raises(RlsError, match=name):
            rls.reset(**kwargs)
    np.testing.assert_array_equal(rls.theta, before[0])
    np.testing.assert_array_equal(rls.P, before[1])


def test_accessors_are_copies() -> None:
    rls = Rls(N, RlsConfig())
    F = rls.F
    F[:] = 99.0
    rls.theta[:] = 99.0
    rls.P[:] = 99.0
    assert not np.any(rls.theta == 99.0)
    assert not np.any(rls.P == 99.0)
    F_held = rls.F
    rls.update(np.ones(M), np.ones(P_DIM))
    assert np.array_equal(F_held, np.zeros((P_DIM, P_DIM)))
    assert not np.array_equal(rls.F, F_held)


# ----------------------------------------------------------------------------------- bad input
def _state(rls: Rls) -> tuple[np.ndarray, np.ndarray, int]:
    return rls.theta, rls.P, rls.n_updates


@pytest.mark.parametrize(
    ("z", "x", "name"),
    [
        (np.ones(M - 1), np.ones(P_DIM), "z"),
        (np.ones((M, 1)), np.ones(P_DIM), "z"),
        (np.r_[np.ones(M - 1), np.nan], np.ones(P_DIM), "z"),
        (np.r_[np.inf, np.ones(M - 1)], np.ones(P_DIM), "z"),
        (np.ones(M), np.ones(P_DIM + 1), "dx_next"),
        (np.ones(M), np.r_[np.nan, np.ones(P_DIM - 1)], "dx_next"),
        (["a"] * M, np.ones(P_DIM), "z"),
    ],
)
def test_bad_update_raises_and_leaves_state_unchanged(z, x, name: str) -> None:
    rng = np.random.default_rng(9)
    rls = Rls(N, RlsConfig())
    for zz, xx in exciting_data(rng, *random_system(rng), 12):
        rls.update(zz, xx)
    before = _state(rls)
    with pytest.raises(RlsError, match=name):
        rls.update(z, x)
    after = _state(rls)
    assert np.array_equal(before[0], after[0])
    assert np.array_equal(before[1], after[1])
    assert before[2] == after[2]
    # And the estimator carries on.
    rls.update(np.ones(M), np.ones(P_DIM))
    assert rls.n_updates == before[2] + 1


@pytest.mark.parametrize("case", ["overflowing-residual", "overflowing-gain"])
def test_update_that_would_be_non_finite_is_rejected(case: str) -> None:
    rls = Rls(N, RlsConfig(alpha=1e300))
    rls.reset(np.eye(P_DIM), np.zeros((P_DIM, N)), w0=np.full(P_DIM, -1e308))
    before = _state(rls)
    if case == "overflowing-residual":
        z, x = np.r_[np.zeros(M - 1), 1.0], np.full(P_DIM, 1e308)  # e = 2e308 = inf
    else:
        z, x = np.full(M, 1e10), np.zeros(P_DIM)  # zᵀ P z = inf
    with pytest.raises(RlsError, match="rejected"):
        rls.update(z, x)
    after = _state(rls)
    assert np.array_equal(before[0], after[0])
    assert np.array_equal(before[1], after[1])
    assert after[2] == 0


# ----------------------------------------------------------------------------------- misc
def test_regressor_layout_and_checks() -> None:
    dx = np.arange(1.0, 7.0)
    du = np.array([10.0, 20.0, 30.0])
    z = Rls.regressor(dx, du)
    np.testing.assert_array_equal(z, np.r_[dx, du, 1.0])
    buf = np.empty(M)
    assert Rls.regressor(dx, du, out=buf) is buf
    np.testing.assert_array_equal(buf, z)
    with pytest.raises(RlsError, match="dx"):
        Rls.regressor(dx[:-1], du)
    with pytest.raises(RlsError, match="du"):
        Rls.regressor(dx, np.array([1.0, np.nan, 2.0]))
    with pytest.raises(RlsError, match="out"):
        Rls.regressor(dx, du, out=np.empty(M - 1))


def test_theta_layout_matches_eq_22() -> None:
    # x(k+1) = Θᵀ z with Θ = [F G w]ᵀ: the blocks land where Eq. 22 puts them.
    rng = np.random.default_rng(10)
    F, G, w = random_system(rng)
    rls = Rls(N, RlsConfig())
    rls.reset(F, G, w)
    np.testing.assert_array_equal(rls.theta[:P_DIM], F.T)
    np.testing.assert_array_equal(rls.theta[P_DIM : P_DIM + N], G.T)
    np.testing.assert_array_equal(rls.theta[-1], w)
    dx, du = rng.standard_normal(P_DIM), rng.standard_normal(N)
    np.testing.assert_allclose(rls.predict(Rls.regressor(dx, du)), F @ dx + G @ du + w)
    step = rls.update(Rls.regressor(dx, du), F @ dx + G @ du + w)
    assert isinstance(step, RlsStep)
    np.testing.assert_allclose(step.residual, 0.0, atol=1e-12)


@pytest.mark.parametrize("n", [0, -1, 1.5, True])
def test_bad_joint_count(n) -> None:
    with pytest.raises(RlsError, match="n_joints"):
        Rls(n, RlsConfig())


def test_model_view_is_read_only_and_follows_the_estimate() -> None:
    """model_view() is Θᵀ = [F G w] without a copy, read-only, as of the last change."""
    rng = np.random.default_rng(21)
    rls = Rls(N, RlsConfig())
    for zz, xx in exciting_data(rng, *random_system(rng), 5):
        rls.update(zz, xx)
    view = rls.model_view()
    np.testing.assert_array_equal(view, np.hstack([rls.F, rls.G, rls.w[:, None]]))
    with pytest.raises(ValueError, match="read-only"):
        view[0, 0] = 1.0
    rls.update(np.ones(M), np.ones(P_DIM))
    np.testing.assert_array_equal(rls.model_view(), rls.theta.T)
    rls.undo()
    np.testing.assert_array_equal(rls.model_view(), view)


# ------------------------------------------------------------------------- a moving prior
def test_shift_model_moves_f_and_g_and_keeps_w_and_p() -> None:
    """``shift_model``: the prior moved by ``delta``; ŵ and P stay, the last update can no
    longer be taken back, and a bad ``delta`` is refused with the estimate unchanged."""
    rng = np.random.default_rng(3)
    F, G, w = random_system(rng)
    rls = Rls(N, RlsConfig(rho=0.98, alpha=100.0))
    rls.reset(F, G)
    z, dx_next = exciting_data(rng, F, G, w, 1)[0]
    rls.update(z, dx_next)
    before_F, before_G, before_w, before_P = rls.F, rls.G, rls.w, rls.P
    delta = rng.standard_normal((P_DIM, P_DIM + N))
    rls.shift_model(delta)
    np.testing.assert_allclose(rls.F, before_F + delta[:, :P_DIM], rtol=0, atol=1e-15)
    np.testing.assert_allclose(rls.G, before_G + delta[:, P_DIM:], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(rls.w, before_w)
    np.testing.assert_array_equal(rls.P, before_P)
    with pytest.raises(RlsError, match="undo"):
        rls.undo()
    theta = rls.theta
    for bad in (np.zeros((P_DIM, P_DIM)), np.full((P_DIM, P_DIM + N), np.nan)):
        with pytest.raises(RlsError, match="delta"):
            rls.shift_model(bad)
        np.testing.assert_array_equal(rls.theta, theta)
