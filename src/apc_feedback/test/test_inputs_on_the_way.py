"""The adaptive law's inputs in flight at a start (with lags): the commands another law (a
fallback) sent while it was idle, and its own at a restart."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback

rng = np.random.default_rng(3)


def _random_sample():
    """q, q', and a set point near them: q_d, qd_d, qdd_d (3 joints)."""
    q, qd, noise_q, noise_qd, qdd_d = rng.normal(size=(5, 3))
    return q, qd, q + 0.01 * noise_q, qd + 0.01 * noise_qd, qdd_d


def test_a_start_plans_with_the_commands_another_law_sent(controller_robot):
    """Commands a fallback sent while the law was idle are its inputs in flight at its start,
    within the effort limits, newest first; older ones and a law without lags ignore them."""
    model = controller_robot.model
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    law = AdaptiveFeedback(model, AdaptiveConfig(period=0.01, input_lags=2))
    limit = law._effort_limit
    for k, du in ((6, np.full(3, 5.0)), (7, np.full(3, 1e9)), (8, np.array([1.0, 2.0, 3.0]))):
        law.observe_command(k, u_n, du)
    law.update(9, q, qd, q_d, qd_d, qdd_d, u_n, None)
    inputs = law._inputs
    np.testing.assert_allclose(inputs[0], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(inputs[1], np.minimum(u_n + 1e9, limit) - u_n)
    np.testing.assert_allclose(inputs[2], np.full(3, 5.0))
    law.reset()
    law.observe_command(2, u_n, np.ones(3))  # long before the next start
    law.update(20, q, qd, q_d, qd_d, qdd_d, u_n, None)
    assert not law._inputs.any()
    plain = AdaptiveFeedback(model, AdaptiveConfig(period=0.01))
    plain.observe_command(0, u_n, np.ones(3))
    plain.update(1, q, qd, q_d, qd_d, qdd_d, u_n, None)  # Eq. 16: nothing in flight


def test_a_restart_keeps_the_laws_own_commands_on_their_way(controller_robot):
    """``restart`` (robot mode, when it learns what its samples' velocity is): the next sample
    starts from Eq. 33 with the law's last commands as the inputs in flight, newest first, as
    a fallback's would be; without lags it is a reset."""
    model = controller_robot.model
    q, qd, q_d, qd_d, qdd_d = _random_sample()
    u_n = pin.rnea(model, model.createData(), q_d, qd_d, qdd_d)
    law = AdaptiveFeedback(model, AdaptiveConfig(period=0.01, input_lags=2))
    sent = [law.update(k, q + 1e-3 * k, qd, q_d, qd_d, qdd_d, u_n, None).du for k in range(5)]
    limit = law._effort_limit
    law.restart()
    assert not law._started
    law.update(5, q, qd, q_d, qd_d, qdd_d, u_n, None)
    for lag in range(3):
        expected = np.clip(u_n + sent[4 - lag], -limit, limit) - u_n
        np.testing.assert_allclose(law._inputs[lag], expected, atol=1e-12)
    plain = AdaptiveFeedback(model, AdaptiveConfig(period=0.01))
    plain.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None)
    plain.restart()
    assert not plain._started and not plain._observed
