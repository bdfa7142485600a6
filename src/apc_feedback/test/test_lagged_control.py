"""The adaptive law's controller over its lagged inputs: the weight of the planned input's change
(``q_input_change``) is the block it says, where it says, and only with two lags or more; the
plan's own dynamics over its inputs on their way (:func:`input_ringing`) is what the law's
commands do while the arm does not answer, and ``input_ring_limit`` keeps it from growing."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from apc_core.config_files import config_dir
from apc_core.robot import load_robot
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback
from apc_feedback.lagged_control import (
    damped_input_change,
    input_ringing,
    receding_controller,
    summed_inputs,
    weigh_input_change,
    write_identified,
)
from apc_feedback.linearize import initial_model
from apc_feedback.presets import recommended_settings

N = 3


@pytest.fixture(scope="module")
def model():
    return load_robot(config_dir() / "puma560_3dof.urdf").model


def test_the_weight_is_the_velocity_of_the_change_between_the_two_newest_inputs():
    config = AdaptiveConfig.from_dict({**recommended_settings(), "period": 0.01})
    q_diagonal = np.arange(1.0, 2 * N + 1)
    control = receding_controller(config, q_diagonal, 1e-6 * np.eye(N), N)
    before = control.Q.copy()
    Gv = np.array([[0.5, 0.1, 0.0], [0.2, 2.0, 0.3], [0.0, -0.4, 8.0]])
    weigh_input_change(control, Gv, 0.5, np.empty((N, N)))
    S = 0.5 * Gv.T @ Gv
    expected = before.copy()
    expected[2 * N : 4 * N, 2 * N : 4 * N] = np.kron([[1.0, -1.0], [-1.0, 1.0]], S)
    np.testing.assert_allclose(control.Q, expected, rtol=0, atol=1e-15)
    assert np.linalg.eigvalsh(control.Q).min() > -1e-12  # still a weight
    # |Gv (a - b)|² weighed, a and b the two newest inputs: zero for a held input
    a, b = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.2])
    x = np.concatenate([np.zeros(2 * N), a, b, np.zeros(N)])
    assert x @ (control.Q - before) @ x == pytest.approx(0.5 * np.sum((Gv @ (a - b)) ** 2))
    held = np.concatenate([np.zeros(2 * N), a, a, np.zeros(N)])
    assert held @ (control.Q - before) @ held == pytest.approx(0.0, abs=1e-12)


def _commands(model, config, samples=8, reconfigure_at=None, reconfigured=None):
    law = AdaptiveFeedback(model, config)
    data = model.createData()
    rng = np.random.default_rng(3)
    out = []
    for k in range(samples):
        if k == reconfigure_at:
            law.reconfigure(reconfigured)
        q, qd = 0.1 * rng.normal(size=N), 0.1 * rng.normal(size=N)
        q_d, qd_d, qdd_d = q + 0.01 * rng.normal(size=N), qd, np.zeros(N)
        u_n = pin.rnea(model, data, q_d, qd_d, qdd_d)
        out.append(law.update(k, q, qd, q_d, qd_d, qdd_d, u_n, None).du)
    return np.array(out)


def test_the_weight_acts_with_two_lags_or_more_and_changes_a_running_law(model):
    """With one lag the planned state holds a single input, so there is no change to weigh:
    the same commands as without the weight. With two it changes them; set at run time
    (``reconfigure``) it takes effect at the next sample."""
    base = AdaptiveConfig.from_dict({**recommended_settings(), "period": 0.01})
    for lags, differs in ((1, False), (2, True)):
        config = dataclasses.replace(base, input_lags=lags)
        without = _commands(model, dataclasses.replace(config, q_input_change=0.0))
        weighed = _commands(model, dataclasses.replace(config, q_input_change=0.5))
        assert (not np.array_equal(without, weighed)) is differs
    unweighed, weighed = (dataclasses.replace(base, q_input_change=c) for c in (0.0, 0.5))
    plain = _commands(model, unweighed)
    changed = _commands(model, unweighed, reconfigure_at=5, reconfigured=weighed)
    np.testing.assert_array_equal(changed[:5], plain[:5])
    assert not np.array_equal(changed[5], plain[5])


#: The 3-joint PUMA's hold pose and a command acting a whole period after its state (a 100 Hz
#: driver that applies it at its next write): the plan pushes back the inputs on their way.
POSE = np.array([0.0, -0.5, 0.3])
PERIOD = 0.01


def _prior_plan(model, weight: float):
    """The preset's plan of the prior at ``POSE`` (Eq. 33, split by one period, no bias), the
    input change weighed at ``weight``; and the number of lags."""
    config = AdaptiveConfig.from_dict(
        {**recommended_settings(), "period": PERIOD, "input_delay": PERIOD}
    )
    zero = np.zeros(N)
    u_n = pin.rnea(model, model.createData(), POSE, zero, zero)
    F, G = initial_model(model, POSE, zero, u_n, PERIOD, delay=PERIOD, input_lags=config.input_lags)
    q_diagonal = np.concatenate([np.full(N, config.q_position), np.full(N, config.q_velocity)])
    control = receding_controller(config, q_diagonal, config.r * np.eye(N), N)
    lags = config.input_lags
    velocity_gain = summed_inputs(G[N:], N)
    theta = np.hstack([F, G, np.zeros((2 * N, 1))])
    write_identified(control, theta, lags, PERIOD, velocity_gain, weight, np.empty((N, N)))
    return control, lags


def _stuck_inputs(control, lags: int, steps: int) -> np.ndarray:
    """The plan's inputs, step after step, with the state error and the integral held at 0 (an
    arm that does not answer) from inputs on their way that are not."""
    x = control.x
    x[:] = 0.0
    x[2 * N : 2 * N + lags * N] = np.random.default_rng(1).normal(size=lags * N)
    inputs = []
    for _ in range(steps):
        u = control.solve()
        x[2 * N + N : 2 * N + lags * N] = x[2 * N : 2 * N + (lags - 1) * N].copy()
        x[2 * N : 3 * N] = u
        inputs.append(u)
    return np.array(inputs)


def test_the_ringing_is_the_growth_of_the_plan_s_inputs_while_the_arm_does_not_answer(model):
    """On the prior with the preset's weight (0.003) the plan's inputs, iterated with the arm
    not answering, grow at the Nyquist frequency by the radius :func:`input_ringing` gives
    (measured 1.41 on this pose); with the weight ``damped_input_change`` finds for the limit
    1 they die out."""
    control, lags = _prior_plan(model, 0.003)
    radius = input_ringing(control, lags)
    assert radius > 1.2
    inputs = _stuck_inputs(control, lags, 60)
    norms = np.linalg.norm(inputs, axis=1)
    assert norms[-1] / norms[-3] == pytest.approx(radius**2, rel=0.02)
    assert np.sign(inputs[-1] @ inputs[-2]) < 0  # alternating: the Nyquist frequency

    cap = 0.003 * 2.0**20
    weight = damped_input_change(lambda c: _prior_plan(model, c)[0], 0.003, lags, 1.0, cap)
    assert weight > 0.003
    damped, _ = _prior_plan(model, weight)
    assert input_ringing(damped, lags) <= 1.0
    assert input_ringing(_prior_plan(model, weight / 2.0)[0], lags) > 1.0  # the first
    norms = np.linalg.norm(_stuck_inputs(damped, lags, 60), axis=1)
    assert norms[-1] < 0.1 * norms[0]


def test_nothing_is_raised_without_two_lags_or_a_weight_and_never_past_the_cap(model):
    """A limit out of reach (the plan holding its input tends to a radius of 1) leaves the
    weight at its cap, the plan written at it; fewer than two lags or no weight: nothing."""

    def write(weight):
        raise AssertionError("no plan is needed")

    assert damped_input_change(write, 0.003, 1, 1.0, 1.0) == 0.003
    assert damped_input_change(write, 0.0, 2, 1.0, 1.0) == 0.0
    written = []

    def plan(weight):
        written.append(weight)
        return _prior_plan(model, weight)[0]

    assert damped_input_change(plan, 0.003, 2, 1e-3, 0.1) == 0.1
    assert written[-1] == 0.1 and written[:2] == [0.003, 0.006]


@pytest.mark.parametrize("limit", [0.0, 1.0])
def test_the_law_s_commands_do_not_grow_on_an_arm_that_does_not_answer(model, limit):
    """The adaptive law, its commands acting a period late, on an arm that never moves (held by
    its friction, say) after a 1 mrad kick: without the limit its commands ring at the
    Nyquist frequency up to the effort limits (measured 264 N m); with the preset's (1) the
    ringing dies out and the law holds the few N m its integral and bias ask (6.9 N m)."""
    config = AdaptiveConfig.from_dict(
        {
            **recommended_settings(),
            "period": PERIOD,
            "input_delay": PERIOD,
            "input_ring_limit": limit,
        }
    )
    law = AdaptiveFeedback(model, config)
    zero = np.zeros(N)
    u_n = pin.rnea(model, model.createData(), POSE, zero, zero)
    largest = []
    for k in range(80):
        q = POSE + (1e-3 if k == 0 else 0.0)
        largest.append(np.abs(law.update(k, q, zero, POSE, zero, zero, u_n, None).du).max())
    if limit == 0.0:
        assert max(largest) > 150.0
        assert law.input_change_weight == config.q_input_change
    else:
        assert law.input_change_weight > config.q_input_change  # raised, and shown so
        assert max(largest[40:]) < 10.0
        assert max(largest[60:]) <= max(largest[40:60])
