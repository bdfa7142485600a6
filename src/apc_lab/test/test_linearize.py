"""Eq. 33: the initial perturbation model F(0), G(0) against the exact hold and the paper."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

from apc_core.robot import PAPER_START_DEG, load_robot, with_inertia_error
from apc_feedback.linearize import (
    LinearizeError,
    VelocityStencil,
    continuous_jacobians,
    discretize_exact,
    discretize_series,
    initial_model,
    split_input_matrix,
    stencil_lags,
)
from apc_lab.scenario import CONFIG_DIR, PAPER_JOINT_SIGN
from apc_plant_sim.plant import Plant, PlantConfig

T = 0.010
PAPER_START_DH = np.deg2rad(PAPER_START_DEG)


@pytest.fixture(scope="module")
def puma():
    return load_robot(CONFIG_DIR / "puma560_3dof.urdf")


def _gravity_point(robot, q):
    """Rest at q under the gravity-compensating torque: the paper's first nominal point."""
    data = robot.model.createData()
    return q, np.zeros(3), pin.rnea(robot.model, data, q, np.zeros(3), np.zeros(3))


def test_jacobian_blocks_match_finite_differences_of_aba(puma):
    """A = [[0, I], [dqdd/dq, dqdd/dqd]], B = [[0], D^-1], against central differences of ABA."""
    rng = np.random.default_rng(0)
    model, data = puma.model, puma.model.createData()
    q, qd, tau = rng.normal(size=3), rng.normal(size=3), 10 * rng.normal(size=3)
    A, B = continuous_jacobians(model, data, q, qd, tau)

    def f(x, u):
        return np.concatenate([x[3:], pin.aba(model, model.createData(), x[:3], x[3:], u)])

    x0, eps = np.concatenate([q, qd]), 1e-6
    A_fd = np.column_stack(
        [(f(x0 + eps * e, tau) - f(x0 - eps * e, tau)) / (2 * eps) for e in np.eye(6)]
    )
    B_fd = np.column_stack(
        [(f(x0, tau + eps * e) - f(x0, tau - eps * e)) / (2 * eps) for e in np.eye(3)]
    )
    np.testing.assert_allclose(A, A_fd, atol=1e-6)
    np.testing.assert_allclose(B, B_fd, atol=1e-8)
    np.testing.assert_array_equal(A[:3, 3:], np.eye(3))
    D = pin.crba(model, data, q)
    D = np.triu(D) + np.triu(D, 1).T
    np.testing.assert_allclose(B[3:] @ D, np.eye(3), atol=1e-12)


def test_a_model_with_friction_is_linearised_about_the_arm_its_nominal_torque_moves(puma):
    """With joint friction (``with_friction``) the nominal torque carries it and ABA does not:
    A and B are the arm's, ``q'' = ABA(q, q', u - b q' - f tanh(q' / v_s))``, against central
    differences at speeds where the Coulomb term is flat (its slope, the smoothing's, is left
    out); ``SetpointLinearization`` agrees; without friction the Jacobians are ABA's."""
    from apc_core.robot import with_friction
    from apc_feedback.linearize import SetpointLinearization
    from apc_feedforward.nominal import friction_torque, joint_friction

    told = with_friction(puma, [25.98, 10.62, 6.36], [5.80, 9.50, 3.98])
    model = told.model
    friction = joint_friction(model)
    rng = np.random.default_rng(1)
    q, tau = rng.normal(size=3), 10 * rng.normal(size=3)
    qd = np.array([0.6, -0.8, 1.1])  # |q'| / v_s >= 60: tanh's slope below 1e-50

    def f(x, u):
        rigid = u - friction_torque(friction, x[3:])
        return np.concatenate([x[3:], pin.aba(model, model.createData(), x[:3], x[3:], rigid)])

    A, B = continuous_jacobians(model, model.createData(), q, qd, tau)
    x0, eps = np.concatenate([q, qd]), 1e-6
    A_fd = np.column_stack(
        [(f(x0 + eps * e, tau) - f(x0 - eps * e, tau)) / (2 * eps) for e in np.eye(6)]
    )
    np.testing.assert_allclose(A, A_fd, atol=1e-6)
    A_rigid, B_rigid = continuous_jacobians(puma.model, puma.model.createData(), q, qd, tau)
    np.testing.assert_array_equal(B, B_rigid)
    assert np.abs(A - A_rigid).max() > 1.0  # the friction moves them, by far more than 1e-6
    F, G = initial_model(model, q, qd, tau, T)
    FG = SetpointLinearization(model, T)(q, qd, tau)
    np.testing.assert_allclose(FG, np.hstack([F, G]), rtol=1e-12, atol=1e-14)


def test_corrected_series_is_the_zoh_series_to_its_truncation_order(puma):
    """Eq. 33 (corrected) differs from expm by the first omitted terms, A^3 T^3/6 and A^3 B T^4/24.

    The printed Eq. 33b is off already at the T^2 term, orders of magnitude more.
    """
    A, B = continuous_jacobians(
        puma.model, puma.model.createData(), *_gravity_point(puma, PAPER_START_DH)
    )
    F_exact, G_exact = discretize_exact(A, B, T)
    F, G = discretize_series(A, B, T, "corrected")
    A3 = np.linalg.matrix_power(A, 3)
    f_bound = np.abs(A3).max() * T**3 / 6 * 1.01
    g_bound = np.abs(A3 @ B).max() * T**4 / 24 * 1.01
    assert np.abs(F - F_exact).max() <= f_bound
    assert np.abs(G - G_exact).max() <= g_bound
    _, G_printed = discretize_series(A, B, T, "printed")
    assert np.abs(G_printed - G_exact).max() > 1000 * g_bound
    np.testing.assert_allclose(G_printed - G, (A @ B) * T**2 / 2 + (A @ A @ B) * T**3 / 3)


def test_initial_model_matches_finite_difference_of_the_one_period_plant_map(puma):
    """F(0), G(0) against the linearisation of the real plant over one period (RK4, ZOH).

    The exact zero-order hold of (A, B) equals the plant map's Jacobian to finite-difference
    accuracy; the Eq. 33 series to within its truncation error.
    """
    q, qd, tau = _gravity_point(puma, PAPER_START_DH)
    plant = Plant(puma, PlantConfig(period=T, step=0.0025), q, qd)

    def one_period(x, du):
        plant.reset(x[:3], x[3:])
        step = plant.step(tau + du)
        return np.concatenate([step.q, step.qd])

    x0, eps = np.concatenate([q, qd]), 1e-6
    zero = np.zeros(3)
    F_fd = np.column_stack(
        [
            (one_period(x0 + eps * e, zero) - one_period(x0 - eps * e, zero)) / (2 * eps)
            for e in np.eye(6)
        ]
    )
    G_fd = np.column_stack(
        [(one_period(x0, eps * e) - one_period(x0, -eps * e)) / (2 * eps) for e in np.eye(3)]
    )
    A, B = continuous_jacobians(puma.model, puma.model.createData(), q, qd, tau)
    F_exact, G_exact = discretize_exact(A, B, T)
    np.testing.assert_allclose(F_fd, F_exact, atol=1e-8)
    np.testing.assert_allclose(G_fd, G_exact, atol=1e-9)
    F0, G0 = initial_model(puma.model, q, qd, tau, T)
    A3 = np.linalg.matrix_power(A, 3)
    assert np.abs(F0 - F_fd).max() <= np.abs(A3).max() * T**3 / 6 * 1.05
    assert np.abs(G0 - G_fd).max() <= np.abs(A3 @ B).max() * T**4 / 24 * 1.05 + 1e-9


def test_paper_eq37_structure_and_magnitudes(puma):
    """At the paper's start our F(0), G(0) have Eq. 37's structure and magnitudes.

    Compared in the paper's sign convention (joints 2 and 3 negated), on the controller's
    model (+-10 % inertia), with the paper's F(2,5) = 0.100 misprint read as T = 0.010.
    Known differences (different PUMA parameter sets): the small couplings F(4,2) and G(4,6)
    have the opposite sign here; the gravity-stiffness entries F(5,2), F(6,2) differ by
    <= 27 %; G's diagonal (D^-1 T) by <= 65 % on joint 2.
    """
    paper = json.loads((CONFIG_DIR / "reference" / "paper.json").read_text())["controller"]
    F_paper = np.array(paper["F0"])
    G_paper = np.array(paper["G0_transposed"]).T
    F_paper[1, 4] = 0.010  # the misprint (DESIGN.md)
    controller = with_inertia_error(puma, [0.1, -0.1, 0.1])
    F0, G0 = initial_model(controller.model, *_gravity_point(controller, PAPER_START_DH), T)
    S = np.diag(np.concatenate([PAPER_JOINT_SIGN, PAPER_JOINT_SIGN]))
    F = S @ F0 @ S
    G = S @ G0 @ np.diag(PAPER_JOINT_SIGN)
    # Structure: position rows are I and T I (to printed precision), G's position rows ~ 0.
    np.testing.assert_allclose(F[:3, :3], F_paper[:3, :3], atol=3e-3)
    np.testing.assert_allclose(F[:3, 3:], F_paper[:3, 3:], atol=5e-4)
    np.testing.assert_allclose(G[:3], G_paper[:3], atol=5e-4)
    np.testing.assert_allclose(np.diag(F[3:, 3:]), np.diag(F_paper[3:, 3:]), atol=2e-3)
    # Magnitudes: every entry within 0.06 of the paper's; the dominant entries within 30 %.
    assert np.abs(F - F_paper).max() < 0.06
    assert np.abs(G - G_paper).max() < 0.005
    for i, j in ((4, 1), (5, 1)):
        assert 0.7 < F[i, j] / F_paper[i, j] < 1.3, (i, j, F[i, j], F_paper[i, j])
    for j in range(3):
        assert 0.5 < G[3 + j, j] / G_paper[3 + j, j] < 1.8, (j, G[3 + j, j], G_paper[3 + j, j])


def test_bad_arguments_raise():
    with pytest.raises(LinearizeError, match="form"):
        discretize_series(np.eye(2), np.ones((2, 1)), T, "bogus")  # type: ignore[arg-type]
    with pytest.raises(LinearizeError, match="period"):
        discretize_series(np.eye(2), np.ones((2, 1)), 0.0)
    with pytest.raises(LinearizeError, match="A must be"):
        discretize_series(np.eye(2), np.ones((3, 1)), T)
    model = pin.buildSampleModelManipulator()
    with pytest.raises(LinearizeError, match="q must"):
        continuous_jacobians(model, model.createData(), np.zeros(2), np.zeros(6), np.zeros(6))
    with pytest.raises(LinearizeError, match="tau must be finite"):
        continuous_jacobians(
            model, model.createData(), np.zeros(6), np.zeros(6), np.full(6, np.nan)
        )


def _double_integrator(n: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """``q'' = u`` per joint: ``A² = 0``, so Eq. 33's series is the exact hold."""
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    B = np.zeros((2 * n, n))
    B[n:] = np.eye(n)
    return A, B


def _delayed_step(A, B, x, inputs, delay, period, steps=2000):
    """x((k+1)T) of ``x' = A x + B u(t - delay)`` by fine Euler-free exact sub-steps, with the
    commands ``inputs[j]`` = u(k-j) decided at (k-j)T and held one period each."""
    F_h, G_h = discretize_exact(A, B, period / steps)
    for i in range(steps):
        t = (i + 0.5) * period / steps - delay  # the command in force now was decided at t
        j = int(np.floor(-t / period)) + 1 if t < 0 else 0
        x = F_h @ x + G_h @ inputs[j]
    return x


@pytest.mark.parametrize("delay", [0.0, 0.003, 0.010, 0.0137, 0.020])
def test_split_input_matrix_is_the_hold_with_a_late_input(delay):
    """The split model (Franklin, Powell & Workman) equals the continuous system whose input
    arrives ``delay`` late, for delays from 0 to 2T, and its matrices sum to Eq. 33's G."""
    A, B = _double_integrator()
    rng = np.random.default_rng(3)
    G_all = split_input_matrix(A, B, T, delay, 2)
    F, G = discretize_series(A, B, T)
    np.testing.assert_allclose(G_all.reshape(4, 3, 2).sum(axis=1), G, atol=1e-15)
    x = rng.standard_normal(4)
    inputs = [rng.standard_normal(2) for _ in range(3)]
    expected = _delayed_step(A, B, x, inputs, delay, T)
    np.testing.assert_allclose(F @ x + G_all @ np.concatenate(inputs), expected, atol=1e-9)


def test_split_input_matrix_takes_a_longer_delay_as_the_last_lag():
    A, B = _double_integrator()
    _, G = discretize_series(A, B, T)
    np.testing.assert_array_equal(split_input_matrix(A, B, T, 0.015, 1)[:, 2:], G)
    np.testing.assert_array_equal(split_input_matrix(A, B, T, 0.0, 0), G)
    with pytest.raises(LinearizeError, match="delay"):
        split_input_matrix(A, B, T, -1e-3, 1)


#: Robot mode's estimate on a driver at T: the parabola through the last three states.
PARABOLA = VelocityStencil((0.0, T, 2 * T), (1.5 / T, -2.0 / T, 0.5 / T))


def test_the_parabola_on_a_late_input_is_exact_for_a_double_integrator():
    """A command one period late seen through the parabola: the hand-derived model, against
    Eq. 33's ``G`` all at lag 1. Its matrices still sum to Eq. 33's ``G``."""
    A, B = _double_integrator()
    F0, G0 = discretize_series(A, B, T)
    F, G = _sampled(A, B, delay=T, lags=3)
    np.testing.assert_allclose(F, F0, atol=1e-15)
    expected = [(0.0, 0.0), (T**2 / 2, 3 * T / 4), (T**2 / 4, T / 2), (-(T**2) / 4, -T / 4)]
    for j, (position, velocity) in enumerate(expected):
        np.testing.assert_allclose(G[:2, 2 * j : 2 * j + 2], position * np.eye(2), atol=1e-15)
        np.testing.assert_allclose(G[2:, 2 * j : 2 * j + 2], velocity * np.eye(2), atol=1e-15)
    np.testing.assert_allclose(G.reshape(4, 4, 2).sum(axis=1), G0, atol=1e-15)


def _sampled(A, B, delay, lags, stencil=PARABOLA):
    from apc_feedback.linearize import _SERIES_COEFFICIENTS, _Series, sampled_coordinates

    F, _ = discretize_series(A, B, T)
    series = _Series(A, B, *_SERIES_COEFFICIENTS["corrected"])
    return sampled_coordinates(F, series, T, delay, stencil, lags)


def test_a_measured_delay_a_hair_past_whole_periods_needs_no_lag_more():
    """A drive's two cycles measured on a 100 Hz driver whose period the stamps give as
    10.00013 ms: 20.00026 ms with a velocity differenced over 10 ms is three lags, as 20 ms
    is (a fourth, beyond what a model carries, kept the delay from being told); a whole
    hundredth of a period more is a lag more."""
    difference = VelocityStencil((0.0, T), (1.0 / T, -1.0 / T))
    assert stencil_lags(difference, T, 0.020) == 3
    assert stencil_lags(difference, T, 0.02000026) == 3
    assert stencil_lags(difference, T, 0.0199997) == 3
    assert stencil_lags(difference, T, 0.0202) == 4
    assert stencil_lags(None, T, 0.0) == 0
    assert stencil_lags(None, T, 0.004) == 1


@pytest.mark.parametrize("delay", [0.0, 0.004, 0.010, 0.013])
def test_the_sampled_model_predicts_the_estimated_velocity_of_an_arm(puma, delay):
    """The PUMA linearised at the paper's start, run as a continuous system with each command
    applied ``delay`` late, sampled as robot mode samples a driver that sends no velocity (the
    position, and the parabola through the last three positions): the sampled model predicts
    the next sample to the series' truncation; Eq. 33's split, which takes the parabola for
    the velocity, is off by the inputs' effect over the parabola's span."""
    A, B = continuous_jacobians(
        puma.model, puma.model.createData(), *_gravity_point(puma, PAPER_START_DH)
    )
    lags = stencil_lags(PARABOLA, T, delay)
    assert lags == int(np.ceil((delay + 2 * T) / T - 1e-9))
    F, G = _sampled(A, B, delay, lags)
    F_eq33, _ = discretize_series(A, B, T)
    G_split = split_input_matrix(A, B, T, delay, lags)
    rng = np.random.default_rng(7)
    commands = [rng.standard_normal(3) * 20 for _ in range(lags + 4)]  # oldest first
    # Positions at the samples k-3 .. k+1 of the continuous system, each step exact.
    x = rng.standard_normal(6) * 0.01
    positions = []
    for i in range(lags + 4):
        positions.append(x[:3].copy())
        recent = commands[max(0, i - 2) : i + 1][::-1]  # u(i), u(i-1), u(i-2)
        recent += [np.zeros(3)] * (3 - len(recent))
        x = _delayed_step(A, B, x, recent, delay, T)
    positions.append(x[:3].copy())

    def sample(i):
        q0, q1, q2 = positions[i], positions[i - 1], positions[i - 2]
        return np.concatenate([q0, (1.5 * q0 - 2.0 * q1 + 0.5 * q2) / T])

    k = lags + 3
    inputs = np.concatenate([commands[k - j] for j in range(lags + 1)])
    truth = sample(k + 1)
    sampled_error = np.abs(F @ sample(k) + G @ inputs - truth).max()
    eq33_error = np.abs(F_eq33 @ sample(k) + G_split @ inputs - truth).max()
    assert sampled_error < 1e-3 * eq33_error
    assert eq33_error > 1e-3  # rad/s: what the parabola's lag costs the unmodelled split


def test_lags_beyond_the_model_s_go_to_its_last():
    """With fewer lags than the sample needs, the rest is added to the last: the sum stays."""
    A, B = _double_integrator()
    _, G3 = _sampled(A, B, delay=T, lags=3)
    _, G2 = _sampled(A, B, delay=T, lags=2)
    np.testing.assert_allclose(G2[:, :4], G3[:, :4], atol=1e-15)
    np.testing.assert_allclose(G2[:, 4:], G3[:, 4:6] + G3[:, 6:], atol=1e-15)


def test_initial_model_takes_the_stencil_only_with_lags(puma):
    q, qd, tau = _gravity_point(puma, PAPER_START_DH)
    plain = initial_model(puma.model, q, qd, tau, T, delay=T, input_lags=3)
    sampled = initial_model(puma.model, q, qd, tau, T, delay=T, input_lags=3, stencil=PARABOLA)
    assert np.abs(sampled[1] - plain[1]).max() > 1e-4
    # Their sum is Eq. 33's G for a double integrator; the arm's own dynamics over the
    # parabola's span move it a little.
    np.testing.assert_allclose(
        sampled[1].reshape(6, 4, 3).sum(axis=1), plain[1].reshape(6, 4, 3).sum(axis=1), rtol=0.01
    )
    eq16 = initial_model(puma.model, q, qd, tau, T)
    for got, want in zip(
        initial_model(puma.model, q, qd, tau, T, stencil=PARABOLA), eq16, strict=True
    ):
        np.testing.assert_array_equal(got, want)
