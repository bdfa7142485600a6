"""Feedback laws: computed torque is Eq. 36, the adaptive law is Eqs. 29-35 wired correctly."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from apc_core.config_files import config_dir
from apc_core.params import ConfigError
from apc_core.robot import PAPER_START_DEG, load_robot
from apc_feedback.baselines import PD, ComputedTorque, NoFeedback, PdGains
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback, FeedbackError
from apc_feedback.laws import LAW_PARAMS, LawParameters, make_law
from apc_feedback.linearize import SetpointLinearization, initial_model
from apc_feedback.optimal import one_step_control, receding_horizon_control

rng = np.random.default_rng(7)


def _random_sample(n=3):
    q, qd = rng.normal(size=n), rng.normal(size=n)
    q_d, qd_d, qdd_d = (
        q + 0.01 * rng.normal(size=n),
        qd + 0.1 * rng.normal(size=n),
        rng.normal(size=n),
    )
    return q, qd, q_d, qd_d, qdd_d


def test_computed_torque_is_eq36(controller_robot):
    """u_n + du = D(q)[qdd_d + Kv(qd_d - qd) + Kp(q_d - q)] + h(q, qd) + c(q), on the model."""
    model = controller_robot.model
    data = model.createData()
    law = ComputedTorque(model, PdGains(kp=100.0, kv=20.0))
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, data, q_d, qd_d, qdd_d)
    du = law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None).du
    D = pin.crba(model, data, q)
    D = np.triu(D) + np.triu(D, 1).T
    hc = pin.nonLinearEffects(model, data, q, qd)
    tau = D @ (qdd_d + 20.0 * (qd_d - qd) + 100.0 * (q_d - q)) + hc
    np.testing.assert_allclose(u_n + du, tau, atol=1e-9)


def test_computed_torque_on_the_plan_is_the_nominal_torque(controller_robot):
    """On the set point with no error, computed torque adds nothing to u_n."""
    model = controller_robot.model
    q_d, qd_d, qdd_d = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    du = ComputedTorque(model).update(0, q_d, qd_d, q_d, qd_d, qdd_d, u_n, None).du
    np.testing.assert_allclose(du, 0.0, atol=1e-10)


def test_pd_and_none():
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    du = PD(3, PdGains(kp=50.0, kv=5.0)).update(0, q, qd, q_d, qd_d, qdd_d, None, None).du
    np.testing.assert_allclose(du, 50.0 * (q_d - q) + 5.0 * (qd_d - qd))
    np.testing.assert_array_equal(
        NoFeedback(3).update(0, q, qd, q_d, qd_d, qdd_d, None, None).du, 0.0
    )


def test_adaptive_first_sample_uses_eq33_and_eq35(controller_robot):
    """Sample 0: F(0), G(0) from Eq. 33 at the nominal point, w = 0, du from Eq. 35 (exact)."""
    model = controller_robot.model
    config = AdaptiveConfig()
    law = AdaptiveFeedback(model, config)
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    out = law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    F0, G0 = initial_model(model, q_d, qd_d, u_n, config.period)
    np.testing.assert_array_equal(law.rls.F, F0)
    np.testing.assert_array_equal(law.rls.G, G0)
    dx = np.concatenate([q - q_d, qd - qd_d])
    Q, R = np.diag([0.1] * 6), 1e-6 * np.eye(3)
    np.testing.assert_allclose(out.du, one_step_control(F0, G0, np.zeros(6), Q, R, dx), rtol=1e-12)
    assert out.residual is None
    assert out.trace_p == pytest.approx(1.5e5 * 10)


def test_adaptive_regressor_uses_applied_torque_minus_previous_nominal(controller_robot):
    """z(k-1) = (dx(k-1), applied(k-1) - u_n(k-1), 1): the identification sees what was applied."""
    model = controller_robot.model
    law = AdaptiveFeedback(model, AdaptiveConfig())
    seen = []
    real_update = law.rls.update

    def spy(z, dx_next):
        seen.append((z.copy(), dx_next.copy()))
        return real_update(z, dx_next)

    law.rls.update = spy  # type: ignore[method-assign]
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n0 = rng.normal(size=3)
    out0 = law.update(0, q, qd, q_d, qd_d, qdd_d, u_n0, None)
    applied = u_n0 + out0.du + np.array([5.0, 0.0, -5.0])  # e.g. clipped by a torque limit
    q1, qd1 = q + 0.001, qd - 0.01
    law.update(1, q1, qd1, q_d, qd_d, qdd_d, rng.normal(size=3), applied)
    z, target = seen[0]
    dx0 = np.concatenate([q - q_d, qd - qd_d])
    np.testing.assert_array_equal(z, np.concatenate([dx0, applied - u_n0, [1.0]]))
    np.testing.assert_array_equal(target, np.concatenate([q1 - q_d, qd1 - qd_d]))


def _regulate(robot, truth, w, q_position, q_velocity, samples=300):
    """Closed loop of the adaptive law with a true linear perturbation system (Eq. 16)."""
    q0 = np.deg2rad(PAPER_START_DEG)
    tau0 = pin.rnea(truth.model, truth.model.createData(), q0, np.zeros(3), np.zeros(3))
    F, G = initial_model(truth.model, q0, np.zeros(3), tau0, 0.01)
    law = AdaptiveFeedback(
        robot.model, AdaptiveConfig(q_position=q_position, q_velocity=q_velocity)
    )
    dx = np.concatenate([np.deg2rad([1.0, -1.0, 1.0]), np.zeros(3)])
    applied = None
    for k in range(samples):
        out = law.update(k, q0 + dx[:3], dx[3:], q0, np.zeros(3), np.zeros(3), tau0, applied)
        applied = tau0 + out.du
        dx = F @ dx + G @ out.du + w
    assert np.all(np.isfinite(law.rls.P))
    return dx


def test_adaptive_regulates_a_linear_perturbation_system(controller_robot):
    """The law starts from the wrong model (+-10 % inertia) and still drives dx to ~0."""
    truth = load_robot(config_dir() / "puma560_3dof.urdf")
    dx = _regulate(controller_robot, truth, np.zeros(6), q_position=1e4, q_velocity=1.0)
    assert np.abs(dx[:3]).max() < np.deg2rad(1e-4)


def test_one_step_law_leaves_an_offset_under_a_constant_bias(controller_robot):
    """No integral action: a constant bias w (an unknown payload) leaves a position offset.

    For one joint (p+ = p + T v + a u, v+ = v + b u + w_v with a = b T / 2) the fixed point of
    the one-step law is p = -(q_v / q_p) w_v / T: the offset shrinks in proportion to the
    velocity/position weight ratio. With the paper's Q = 0.1 I (ratio 1) it is w_v / T, which
    is why the printed settings let a payload's gravity build up as position error.
    """
    truth = load_robot(config_dir() / "puma560_3dof.urdf")
    w = np.concatenate([np.zeros(3), [0.0, -0.02, 0.05]])
    offsets = [
        np.abs(_regulate(controller_robot, truth, w, q_position=qp, q_velocity=1.0)[:3]).max()
        for qp in (1e4, 1e5)
    ]
    assert offsets[0] == pytest.approx(1e-4 * 0.05 / 0.01, rel=0.05)
    assert offsets[0] / offsets[1] == pytest.approx(10.0, rel=0.05)


@pytest.mark.parametrize(
    ("cls", "kwargs", "field", "words"),
    [
        (AdaptiveConfig, {"rho": 1.5}, "rho", "out of range"),
        (AdaptiveConfig, {"r": 0.0}, "r", "out of range"),
        (AdaptiveConfig, {"q_position": -1.0}, "q_position", "out of range"),
        (AdaptiveConfig, {"q_velocity": math.nan}, "q_velocity", "out of range"),
        (AdaptiveConfig, {"q_position": "x"}, "q_position", "must be a number"),
        (AdaptiveConfig, {"alpha": True}, "alpha", "must be a number"),
        (AdaptiveConfig, {"horizon": 1.5}, "horizon", "must be an integer"),
        (AdaptiveConfig, {"horizon": 0}, "horizon", "out of range"),
        (AdaptiveConfig, {"control_form": "bogus"}, "control_form", "'exact' or 'printed'"),
        (AdaptiveConfig, {"forgetting": "bogus"}, "forgetting", "bogus"),
        (AdaptiveConfig, {"period": 0.0}, "period", "> 0"),
        (PdGains, {"kp": -1.0}, "kp", "out of range"),
        (PdGains, {"kv": math.inf}, "kv", "out of range"),
    ],
)
def test_settings_validation_names_the_field(cls, kwargs, field, words):
    """The dataclass is the one validation: the error carries the field, for the node."""
    with pytest.raises(FeedbackError, match=words) as info:
        cls(**kwargs)
    assert info.value.field == field
    assert str(info.value).startswith(field)


def test_settings_take_integers_for_floats_and_refuse_unknown_keys():
    assert AdaptiveConfig(q_position=200).q_position == 200.0
    assert isinstance(PdGains(kp=200).kp, float)
    with pytest.raises(FeedbackError, match="unknown adaptive-controller parameter 'rh0'"):
        AdaptiveConfig.from_dict({"rh0": 0.9})


@pytest.mark.parametrize(
    ("kind", "cls"),
    [
        ("adaptive", AdaptiveFeedback),
        ("computed_torque", ComputedTorque),
        ("pd", PD),
        ("none", NoFeedback),
    ],
)
def test_make_law_by_name(controller_robot, kind, cls):
    assert isinstance(make_law(kind, controller_robot, 0.01), cls)


def test_make_law_rejects_unknown():
    robot = load_robot(config_dir() / "puma560_3dof.urdf")
    with pytest.raises(FeedbackError, match="controller must be one of"):
        make_law("lqr", robot, 0.01)
    with pytest.raises(FeedbackError, match="unknown gain parameter 'kd'"):
        make_law("pd", robot, 0.01, {"kd": 1.0})


def test_reconfigure_takes_new_weights_and_keeps_the_identified_model(controller_robot):
    """New Q/R at run time change du from the same estimate; the identifier is not reset."""
    model = controller_robot.model
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    laws = [AdaptiveFeedback(model, AdaptiveConfig()) for _ in range(2)]
    for law in laws:
        law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
        law.update(1, q + 1e-3, qd, q_d, qd_d, qdd_d, u_n, u_n + 1.0)
    heavier = AdaptiveConfig(q_position=1e4, q_velocity=1.0, r=1e-4)
    laws[1].reconfigure(heavier)
    assert laws[1].config == heavier and laws[1].rls.n_updates == 1
    outs = [law.update(2, q - 1e-3, qd, q_d, qd_d, qdd_d, u_n, u_n - 1.0) for law in laws]
    np.testing.assert_array_equal(laws[0].rls.theta, laws[1].rls.theta)  # same identification
    dx = np.concatenate([q - 1e-3 - q_d, qd - qd_d])
    Q = np.diag([1e4] * 3 + [1.0] * 3)
    expected = one_step_control(
        laws[1].rls.F, laws[1].rls.G, laws[1].rls.w, Q, 1e-4 * np.eye(3), dx
    )
    np.testing.assert_allclose(outs[1].du, expected, rtol=1e-10)
    assert not np.allclose(outs[0].du, outs[1].du)
    with pytest.raises(FeedbackError, match="identifier"):
        laws[1].reconfigure(AdaptiveConfig(rho=0.9))


def test_a_gap_in_the_samples_skips_the_identification_step(controller_robot):
    """Sample k-1 missing (lost on the network, a controller restarted): the step to k spans
    two periods, so it is not identified (estimate and P unchanged, counted); the control still
    uses the estimate, and the next consecutive sample identifies again."""
    model = controller_robot.model
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    law = AdaptiveFeedback(model, AdaptiveConfig())
    law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    law.update(1, q + 1e-3, qd, q_d, qd_d, qdd_d, u_n, u_n + 1.0)
    theta, P = law.rls.theta.copy(), law.rls.P.copy()
    out = law.update(3, q - 1e-3, qd, q_d, qd_d, qdd_d, u_n, u_n - 1.0)  # 2 is missing
    assert out.skipped and not out.rejected and out.residual is None
    assert law.skipped_updates == 1 and law.rls.n_updates == 1
    np.testing.assert_array_equal(law.rls.theta, theta)
    np.testing.assert_array_equal(law.rls.P, P)
    dx = np.concatenate([q - 1e-3 - q_d, qd - qd_d])
    expected = one_step_control(law.rls.F, law.rls.G, law.rls.w, law.Q, law.R, dx)
    np.testing.assert_allclose(out.du, expected, rtol=1e-10)
    out = law.update(4, q, qd, q_d, qd_d, qdd_d, u_n, u_n + out.du)
    assert not out.skipped and law.rls.n_updates == 2 and out.residual is not None


def _law_values(**overrides):
    values = {"period": 0.01, **{p.name: p.default for p in LAW_PARAMS}}
    values.update(overrides)
    return values


@pytest.mark.parametrize(
    ("overrides", "name", "words"),
    [
        ({"adaptive.r": -1.0}, "adaptive.r", "out of range"),
        ({"adaptive.q_position": -0.1}, "adaptive.q_position", "out of range"),
        ({"adaptive.rho": 1.5}, "adaptive.rho", "out of range"),
        ({"adaptive.horizon": 2.5}, "adaptive.horizon", "must be an integer"),
        ({"adaptive.forgetting": "bogus"}, "adaptive.forgetting", "bogus"),
        ({"period": 0.0}, "period", "> 0"),
        ({"controller": "lqr"}, "controller", "must be one of"),
        ({"controller": "pd", "gains.kv": -1.0}, "gains.kv", "out of range"),
    ],
)
def test_law_parameters_name_the_bad_parameter(controller_robot, overrides, name, words):
    with pytest.raises(ConfigError, match=words) as info:
        LawParameters(_law_values(**overrides), controller_robot)
    assert str(info.value).startswith(f"parameter '{name}': ")


def test_law_parameters_take_run_time_settings_at_the_next_sample_all_or_none(controller_robot):
    laws = LawParameters(_law_values(controller="computed_torque"), controller_robot)
    assert isinstance(laws.law, ComputedTorque) and laws.family == "gains."
    laws.propose({"gains.kp": 400, "use_sim_time": True, "adaptive.rho": 0.5})  # not its own
    with pytest.raises(ConfigError, match=r"^parameter 'gains\.kv': kv = -1 is out of range"):
        laws.propose({"gains.kp": 1.0, "gains.kv": -1.0})
    with pytest.raises(ConfigError, match=r"^parameter 'adaptive\.r': not used by controller"):
        laws.propose({"gains.kv": 1.0, "adaptive.r": 1.0})
    assert laws.law.gains == PdGains()  # nothing before the sample
    assert laws.take() == {"gains.kp": 400}
    assert laws.law.gains == PdGains(kp=400.0)
    assert laws.take() == {}
    none = LawParameters(_law_values(controller="none"), controller_robot)
    with pytest.raises(ConfigError, match="not used by controller 'none'"):
        none.propose({"gains.kp": 1.0})


def _regulate_delayed(robot, lags, delay_periods, samples=400):
    """The recommended preset with ``lags`` against a true linear perturbation system whose
    input reaches it ``delay_periods`` periods late (the split model of Eq. 33's G): δx after
    ``samples``, and the law."""
    from apc_feedback.linearize import continuous_jacobians, split_input_matrix
    from apc_feedback.presets import recommended_settings

    T = 0.01
    q0 = np.deg2rad(PAPER_START_DEG)
    tau0 = pin.rnea(robot.model, robot.model.createData(), q0, np.zeros(3), np.zeros(3))
    A, B = continuous_jacobians(robot.model, robot.model.createData(), q0, np.zeros(3), tau0)
    F, _ = initial_model(robot.model, q0, np.zeros(3), tau0, T)
    G_true = split_input_matrix(A, B, T, delay_periods * T, 2)
    settings = {**recommended_settings(), "input_lags": lags, "input_delay": delay_periods * T}
    law = AdaptiveFeedback(robot.model, AdaptiveConfig.from_dict(settings))
    dx = np.concatenate([np.deg2rad([1.0, -1.0, 1.0]), np.zeros(3)])
    history = [np.zeros(3)] * 3
    for k in range(samples):
        out = law.update(k, q0 + dx[:3], dx[3:], q0, np.zeros(3), np.zeros(3), tau0, None)
        # The drive clips the command to the effort limits, as the law's memory of it does.
        limit = robot.effort_limit
        history = [np.clip(tau0 + out.du, -limit, limit) - tau0, *history[:2]]
        dx = F @ dx + G_true @ np.concatenate(history)
    return dx, law


@pytest.mark.parametrize("delay_periods", [0.0, 0.4, 1.0, 1.6])
def test_lagged_law_regulates_a_plant_whose_input_arrives_late(controller_robot, delay_periods):
    """Delays from 0 to 2T (a command applied up to two periods after its sample): with two
    lags the law brings a 1 deg error to rest; with Eq. 16 alone a delay of a period or more
    loses it."""
    dx, _ = _regulate_delayed(controller_robot, 2, delay_periods)
    assert np.abs(dx[:3]).max() < np.deg2rad(1e-3)
    if delay_periods >= 1.0:
        with np.errstate(all="ignore"):
            lost, _ = _regulate_delayed(controller_robot, 0, delay_periods)
        assert not np.abs(lost[:3]).max() < np.deg2rad(1.0)


def test_lagged_law_splits_g0_by_the_expected_delay(controller_robot):
    """Ĝ(0) is Eq. 33's G split by the delay: a whole period puts it in Ĝ₁."""
    law = AdaptiveFeedback(controller_robot.model, AdaptiveConfig(input_lags=2))
    law.expect_input_delay(0.01)
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(controller_robot.model, controller_robot.model.createData(), q_d, qd_d, qdd_d)
    law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    _, G0 = initial_model(controller_robot.model, q_d, qd_d, u_n, 0.01)
    G = law.rls.G
    assert G.shape == (6, 9)
    np.testing.assert_array_equal(G[:, :3], 0.0)
    np.testing.assert_allclose(G[:, 3:6], G0, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(G[:, 6:], 0.0)
    np.testing.assert_allclose(law.prior_input_gain, G0, rtol=1e-12, atol=1e-15)
    with pytest.raises(FeedbackError, match="delay"):
        law.expect_input_delay(-1.0)


def _lagged_model(law, dx):
    """The recommended law's model as a fresh set of arrays, from the identifier's estimate:
    state (δx, δu(k-1) … δu(k-L), ξ), the lags' shift, the integral's rows."""
    n, T = law.n_joints, law.config.period
    lags = law.config.input_lags
    p, s = 2 * n, 2 * n + lags * n
    G_all = law.rls.G
    F = np.zeros((s + n, s + n))
    F[:p, :p] = law.rls.F
    F[:p, p:s] = G_all[:, n:]
    F[p + n : s, p : s - n] = np.eye((lags - 1) * n)
    F[s:, :s] = T * F[:n, :s]
    F[s:, s:] = np.eye(n)
    G = np.zeros((s + n, n))
    G[:p] = G_all[:, :n]
    G[p : p + n] = np.eye(n)
    G[s:] = T * G[:n]
    w = np.zeros(s + n)
    w[:p] = law.rls.w
    w[s:] = T * w[:n]
    inputs = law._inputs[:lags].ravel()
    x = np.concatenate([dx, inputs, law.integral])
    Q = np.diag(np.concatenate([law.Q.diagonal(), np.zeros(lags * n), np.full(n, 1e6)]))
    # The change of the planned input, weighed on the velocity it makes:
    # q_input_change |Gv (δu(j) - δu(j-1))|², Gv the identified velocity block summed over lags.
    Gv = law.identified_input_gain[n:]
    S = law.config.q_input_change * (Gv.T @ Gv)
    change = np.kron(np.array([[1.0, -1.0], [-1.0, 1.0]]), S)
    Q[p : p + 2 * n, p : p + 2 * n] += change
    return F, G, w, Q, x


def test_recommended_law_controls_its_lagged_integral_model(controller_robot):
    """The recommended preset's du is the receding-horizon control of the lagged model with
    the integral and the weight of the input's change, built afresh from the estimate (the law
    writes only the identified blocks and that weight into its buffers every sample, the
    constant ones once)."""
    from apc_feedback.presets import recommended_settings

    model = controller_robot.model
    config = AdaptiveConfig.from_dict({**recommended_settings(), "period": 0.01})
    assert config.input_lags == 2 and config.q_integral == 1e6 and config.q_input_change > 0
    law = AdaptiveFeedback(model, config)
    data = model.createData()
    applied = None
    for k in range(6):
        q, qd, q_d, qd_d, qdd_d = _random_sample()
        u_n = pin.rnea(model, data, q_d, qd_d, qdd_d)
        out = law.update(k, q, qd, q_d, qd_d, qdd_d, u_n, applied)
        dx = np.concatenate([q - q_d, qd - qd_d])
        F, G, w, Q, x = _lagged_model(law, dx)
        expected = receding_horizon_control(
            F, G, w, Q, law.R, x, config.horizon + config.input_lags
        )
        np.testing.assert_array_equal(out.du, expected)
        applied = u_n + out.du


@pytest.mark.parametrize("lags", [0, 2])
def test_relinearize_moves_the_model_with_the_set_point(controller_robot, lags):
    """``relinearize``: across a gap (no identification step) the model moves to the new set
    point's Eq. 33: ``F̂`` to its ``F``, each ``Ĝ_j`` right-multiplied by the prior's change
    in input space, so that their summed velocity block is the new prior's; the supervisor's
    prior input gain is the new ``G``. Without it the model stays at the first set point's."""
    model = controller_robot.model
    data = model.createData()
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, data, q_d, qd_d, qdd_d)
    later = q_d + np.array([0.6, -0.8, 0.9]), qd_d + 1.0, qdd_d
    u_later = pin.rnea(model, data, *later)
    settings = {"input_lags": lags, "input_delay": 0.004 * lags}

    def eq33(q_, qd_, u_):
        return initial_model(model, q_, qd_, u_, 0.01, delay=0.004 * lags, input_lags=lags)

    F0, G0 = eq33(q_d, qd_d, u_n)
    F1, G1 = eq33(later[0], later[1], u_later)
    summed0, summed1 = (G.reshape(6, -1, 3).sum(axis=1) for G in (G0, G1))
    for relinearize in (True, False):
        law = AdaptiveFeedback(model, AdaptiveConfig(relinearize=relinearize, **settings))
        law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
        out = law.update(2, q, qd, *later, u_later, None)  # 1 is missing: no identification
        assert out.skipped
        if not relinearize:
            np.testing.assert_array_equal(law.rls.F, F0)
            np.testing.assert_array_equal(law.rls.G, G0)
            continue
        transport = np.linalg.solve(summed0[3:], summed1[3:])
        np.testing.assert_allclose(law.rls.F, F1, rtol=0, atol=1e-12)
        moved = (G0.reshape(6, -1, 3) @ transport).reshape(6, -1)
        np.testing.assert_allclose(law.rls.G, moved, rtol=0, atol=1e-12)
        identified = law.identified_input_gain
        np.testing.assert_allclose(identified[3:], summed1[3:], rtol=0, atol=1e-12)
        np.testing.assert_allclose(law.prior_input_gain, summed1, rtol=0, atol=1e-12)


def test_relinearize_keeps_what_was_identified(controller_robot):
    """An identification step's correction survives the prior's move: ``F̂`` keeps its learnt
    deviation from Eq. 33's ``F``, and ``Ĝ Gv⁻¹`` stays (``Gv``: the prior's velocity block;
    ``Ĝ`` moves by the prior's change in input space)."""
    model = controller_robot.model
    data = model.createData()
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, data, q_d, qd_d, qdd_d)
    law = AdaptiveFeedback(model, AdaptiveConfig(relinearize=True, alpha=10.0))
    law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    out = law.update(1, q + 0.01, qd - 0.2, q_d, qd_d, qdd_d, u_n, u_n + 3.0)
    assert out.residual is not None
    F0, G0 = initial_model(model, q_d, qd_d, u_n, 0.01)
    learnt_F, G_learnt = law.rls.F - F0, law.rls.G
    assert np.abs(G_learnt - G0).max() > 1e-6
    later = q_d + 0.3, qd_d, qdd_d
    u_later = pin.rnea(model, data, *later)
    law.update(3, q, qd, *later, u_later, None)
    F1, G1 = initial_model(model, later[0], later[1], u_later, 0.01)
    np.testing.assert_allclose(law.rls.F - F1, learnt_F, rtol=0, atol=1e-12)
    # Ĝ Gv⁻¹ (Gv: the prior's velocity block) is what the move keeps.
    share = np.linalg.solve(G0[3:].T, G_learnt.T)
    np.testing.assert_allclose(np.linalg.solve(G1[3:].T, law.rls.G.T), share, atol=1e-9)


def test_relinearize_keeps_the_input_gain_off_the_floor(controller_robot):
    """With ``relinearize`` and ``project_g`` no identification step takes a diagonal entry of
    Ĝ's velocity block from above a tenth of the prior's to below it (refused and counted);
    without ``relinearize`` only a sign change is refused. The step: 50 N m on joint 3 that
    moved nothing, which takes Ĝ₃₃ to 0.04 of its prior unprojected."""
    model = controller_robot.model
    q_d, zero = np.array([0.1, -0.5, 0.4]), np.zeros(3)
    u_n = pin.rnea(model, model.createData(), q_d, zero, zero)
    for relinearize, refused in ((True, True), (False, False)):
        config = AdaptiveConfig(
            relinearize=relinearize, project_g=True, alpha_model=10.0, alpha=1e3
        )
        law = AdaptiveFeedback(model, config)
        law.update(0, q_d, zero, q_d, zero, zero, u_n, None)
        law.update(1, q_d, zero, q_d, zero, zero, u_n, u_n + np.array([0.0, 0.0, 50.0]))
        ratio = law.identified_input_gain[3:].diagonal() / law.prior_input_gain[3:].diagonal()
        assert law.projected_updates == refused
        assert ratio[2] == pytest.approx(1.0) if refused else 0.0 < ratio[2] < 0.1


@pytest.mark.parametrize(("lags", "delay"), [(0, 0.0), (2, 0.004), (2, 0.013), (2, 0.03)])
@pytest.mark.parametrize("form", ["corrected", "printed"])
def test_setpoint_linearization_is_initial_model(controller_robot, lags, delay, form):
    """The per-sample linearisation ``relinearize`` uses gives :func:`initial_model`'s
    ``[F G₀ … G_L]`` (to rounding) at every set point, whatever the delay's split."""
    model = controller_robot.model
    linearize = SetpointLinearization(model, 0.01, form, lags)
    for _ in range(3):
        q, qd, _, _, qdd = _random_sample()
        tau = pin.rnea(model, model.createData(), q, qd, qdd)
        F, G = initial_model(model, q, qd, tau, 0.01, form, delay=delay, input_lags=lags)
        np.testing.assert_allclose(linearize(q, qd, tau, delay), np.hstack((F, G)), atol=1e-12)


def test_a_velocity_stencil_gives_the_prior_of_the_sampled_state(controller_robot):
    """Told the estimate's stencil, the law starts from :func:`initial_model` of that sample;
    a bad stencil is refused; a law without lags ignores it (Eq. 16)."""
    from apc_feedback.linearize import VelocityStencil

    model = controller_robot.model
    stencil = VelocityStencil((0.02, 0.01, 0.0), (50.0, -200.0, 150.0))
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    for relinearize in (False, True):
        config = AdaptiveConfig(period=0.01, input_lags=3, relinearize=relinearize)
        law = AdaptiveFeedback(model, config)
        law.expect_input_delay(0.01)
        law.expect_velocity_stencil(stencil)
        law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
        F, G = initial_model(model, q_d, qd_d, u_n, 0.01, delay=0.01, input_lags=3, stencil=stencil)
        np.testing.assert_allclose(law.rls.F, F, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(law.rls.G, G, rtol=1e-12, atol=1e-15)
    with pytest.raises(FeedbackError, match="stencil"):
        law.expect_velocity_stencil(VelocityStencil((0.01, -0.01), (1.0, -1.0)))
    plain = AdaptiveFeedback(model, AdaptiveConfig(period=0.01))
    plain.expect_velocity_stencil(stencil)
    plain.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    F, G = initial_model(model, q_d, qd_d, u_n, 0.01)
    np.testing.assert_array_equal(plain.rls.G, G)


def test_the_model_carries_the_lags_the_samples_timing_needs(controller_robot):
    """A law configured with two lags, told a 100 Hz driver's timing (a command a period late,
    a velocity estimated over two periods), carries three from its next start and keeps its
    weights' reconfiguration; told a measured velocity, it is back to two at the next start."""
    from apc_feedback.linearize import VelocityStencil

    model = controller_robot.model
    config = AdaptiveConfig(period=0.01, input_lags=2, relinearize=True)
    law = AdaptiveFeedback(model, config)
    law.expect_input_delay(0.01)
    law.expect_velocity_stencil(VelocityStencil((0.02, 0.01, 0.0), (50.0, -200.0, 150.0)))
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    assert law.config.input_lags == 3 and law.rls.G.shape == (6, 12)
    law.reconfigure(AdaptiveConfig(period=0.01, input_lags=2, relinearize=True, r=1e-5))
    assert law.config.input_lags == 3 and law.R[0, 0] == 1e-5
    with pytest.raises(FeedbackError, match="identifier"):
        law.reconfigure(AdaptiveConfig(period=0.01, input_lags=3, relinearize=True))
    law.update(1, q, qd, q_d, qd_d, qdd_d, u_n, u_n)
    law.expect_velocity_stencil(None)
    law.reset()
    law.update(2, q, qd, q_d, qd_d, qdd_d, u_n, None)
    assert law.config.input_lags == 2 and law.rls.G.shape == (6, 9)


def test_a_measured_delay_starts_the_identifier_with_the_split_held(controller_robot):
    """Told a delay exactly (robot mode's measurement), ``P(0)``'s input block is
    ``alpha_model (c cᵀ + HELD_SPLIT_PRIOR (I - c cᵀ)) ⊗ I``: only the total input gain moves."""
    from apc_feedback.adaptive_config import HELD_SPLIT_PRIOR
    from apc_feedback.presets import recommended_settings

    model = controller_robot.model
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    config = AdaptiveConfig.from_dict({**recommended_settings(), "period": 0.01})
    blocks = {}
    for exact in (False, True):
        law = AdaptiveFeedback(model, config)
        law.expect_input_delay(0.015, (), exact)
        law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
        blocks[exact] = law.rls.P[6:-1, 6:-1]
    assert np.allclose(blocks[False], np.diag(np.diag(blocks[False])))  # every lag learnt alike
    held = blocks[True]
    # 15 ms at T = 10 ms: half of the input's effect in each of lags 1 and 2, none in lag 0
    for j in range(3):
        unit = np.zeros(9)
        unit[[3 + j, 6 + j]] = np.sqrt(0.5)
        assert unit @ held @ unit == pytest.approx(config.alpha_model, rel=0.2)
        assert held[j, j] == pytest.approx(config.alpha_model * HELD_SPLIT_PRIOR, rel=0.5)
