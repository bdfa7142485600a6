"""The adaptive law's controller over its lagged inputs: the weight of the planned input's change
(``q_input_change``) is the block it says, where it says, and only with two lags or more."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from apc_core.config_files import config_dir
from apc_core.robot import load_robot
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback
from apc_feedback.lagged_control import receding_controller, weigh_input_change
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
