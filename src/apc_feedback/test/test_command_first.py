"""The adaptive law's command first, its learning after (``defer_learning``, robot mode's
``command_first``): the command of sample k from the gain planned after sample k-1."""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback
from apc_feedback.presets import recommended_settings

T = 0.001


def _config(**changes) -> AdaptiveConfig:
    return dataclasses.replace(
        AdaptiveConfig.from_dict({**recommended_settings(), "period": T}), **changes
    )


def _samples(model, count: int = 40, seed: int = 5):
    """A slow move with measurement noise: (k, q, qd, q_d, qd_d, qdd_d, u_n) per sample."""
    rng = np.random.default_rng(seed)
    data = model.createData()
    out = []
    for k in range(count):
        t = k * T
        q_d = np.array([0.1 * t, -0.7 + 0.2 * t, 0.5 - 0.1 * t])
        qd_d = np.array([0.1, 0.2, -0.1])
        qdd_d = np.zeros(3)
        u_n = pin.rnea(model, data, q_d, qd_d, qdd_d).copy()
        q = q_d + 1e-3 * np.sin(7.0 * t + np.arange(3)) + 1e-5 * rng.normal(size=3)
        qd = qd_d + 0.05 * np.cos(7.0 * t + np.arange(3)) + 1e-3 * rng.normal(size=3)
        out.append((k, q, qd, q_d, qd_d, qdd_d, u_n))
    return out


def _run(law: AdaptiveFeedback, samples, settle: bool = True) -> list:
    outs = []
    for k, q, qd, q_d, qd_d, qdd_d, u_n in samples:
        outs.append(law.update(k, q, qd, q_d, qd_d, qdd_d, u_n, None))
        if settle:
            law.settle()
    return outs


def _deferred(model, config: AdaptiveConfig) -> AdaptiveFeedback:
    law = AdaptiveFeedback(model, config)
    law.defer_learning = True
    return law


def test_with_a_model_that_does_not_change_the_command_is_the_same(controller_robot):
    """No identification (every joint below ``identify_min_speed``) and a fixed prior: the gain
    planned after sample k-1 is the one sample k would plan, so the commands agree with the
    paper's order to rounding, over the lagged inputs, the integral and ``ŵ``'s column."""
    model = controller_robot.model
    config = _config(identify_min_speed=1e3, relinearize=False)
    samples = _samples(model)
    plain = _run(AdaptiveFeedback(model, config), samples)
    first = _run(_deferred(model, config), samples)
    for a, b in zip(plain, first, strict=True):
        np.testing.assert_allclose(b.du, a.du, rtol=1e-9, atol=1e-9)


def test_with_identification_each_command_uses_the_model_a_sample_older(controller_robot):
    """Identifying, the command of sample k is the gain planned from the model after the step
    to k-1 on the state at k: the same as a law in the paper's order whose step to k is taken
    after its command (its model copied in before it steps)."""
    model = controller_robot.model
    config = _config()
    samples = _samples(model)
    law = _deferred(model, config)
    plain = AdaptiveFeedback(model, config)
    outs = _run(law, samples[:20])
    _run(plain, samples[:20])
    assert any(out.residual is not None for out in outs)  # it identified
    # The next command: the deferred law's, against a plan of the model it learnt to k-1.
    k, q, qd, q_d, qd_d, qdd_d, u_n = samples[20]
    before = law.rls.model_view().copy()
    du = law.update(k, q, qd, q_d, qd_d, qdd_d, u_n, None).du
    np.testing.assert_array_equal(law.rls.model_view(), before)  # not learnt yet
    receding = law._receding
    assert receding is not None
    expected = -(law._write_plan().gain() @ np.append(receding.x, 1.0))
    np.testing.assert_allclose(du, expected, rtol=1e-12, atol=1e-12)
    law.settle()
    assert not np.array_equal(law.rls.model_view(), before)  # learnt after the command
    assert not np.allclose(
        du, plain.update(k, q, qd, q_d, qd_d, qdd_d, u_n, None).du, rtol=1e-6, atol=0.0
    )


def test_learning_left_for_the_next_sample_is_the_same_as_learning_after_the_command(
    controller_robot,
):
    """A caller that never calls ``settle`` gets the same commands, bit for bit (the next
    update learns first), and every output after the first reports the step taken after the
    command before it."""
    model = controller_robot.model
    samples = _samples(model)
    settled = _run(_deferred(model, _config()), samples, settle=True)
    lazy = _run(_deferred(model, _config()), samples, settle=False)
    for a, b in zip(settled, lazy, strict=True):
        np.testing.assert_array_equal(a.du, b.du)
        assert (a.residual is None) == (b.residual is None)
    assert any(a.residual is not None for a in settled[1:])


def test_a_plan_that_fails_after_the_command_is_planned_again_before_the_next(
    controller_robot, monkeypatch
):
    """A plan that cannot be solved after a command leaves no gain: the next sample plans
    before its command, in the paper's order, and goes on deferring after it."""
    model = controller_robot.model
    samples = _samples(model)
    law = _deferred(model, _config())
    _run(law, samples[:5])
    with monkeypatch.context() as patch:
        patch.setattr(law, "_plan_gain", lambda k: (_ for _ in ()).throw(ValueError("singular")))
        law.settle()  # nothing pending: nothing to fail
        law.update(*samples[5][:7], None)
        law.settle()
    assert law._gain is None
    k, q, qd, q_d, qd_d, qdd_d, u_n = samples[6]
    du = law.update(k, q, qd, q_d, qd_d, qdd_d, u_n, None).du
    assert np.isfinite(du).all()
    assert law._pending is not None and law._pending.dx is None  # planned before, gain after
    law.settle()
    assert law._gain is not None


@pytest.mark.parametrize("weights", [{}, {"horizon": 1, "input_lags": 0, "q_integral": 0.0}])
def test_only_a_receding_plan_defers(controller_robot, weights):
    """The paper's one-step law (no receding plan) keeps its order: nothing is left after its
    command."""
    model = controller_robot.model
    law = _deferred(model, _config(**weights))
    _run(law, _samples(model, 3), settle=False)
    assert (law._pending is not None) == (not weights)


def test_the_identification_after_the_command_is_the_one_before_it(controller_robot):
    """Without lags the regressor's input is the torque the arm applied (given here, the same
    for both laws), so the model a deferred law holds after ``settle`` is, step for step, the
    one the paper's order holds after its update: the same step to the same ``dx`` from the
    same ``z``, and the prior moved to the same set points."""
    model = controller_robot.model
    config = _config(input_lags=0)
    samples = _samples(model)
    first, plain = _deferred(model, config), AdaptiveFeedback(model, config)
    start = None
    for k, q, qd, q_d, qd_d, qdd_d, u_n in samples:
        applied = u_n + 0.5 * np.sin(k + np.arange(3))
        first.update(k, q, qd, q_d, qd_d, qdd_d, u_n, applied)
        first.settle()
        plain.update(k, q, qd, q_d, qd_d, qdd_d, u_n, applied)
        np.testing.assert_array_equal(first.rls.model_view(), plain.rls.model_view())
        np.testing.assert_array_equal(first._z_dx, plain._z_dx)
        start = plain.rls.model_view().copy() if start is None else start
    assert not np.array_equal(plain.rls.model_view(), start)  # it identified


def test_the_input_ringing_is_judged_after_the_commands_too(controller_robot):
    """The plan's ringing check comes due every ``RING_CHECK_PERIOD_S`` in the deferred path as
    in the paper's order, and new weights given with work left are judged before the next
    command, whoever settles."""
    model = controller_robot.model
    samples = _samples(model, count=260)
    law = _deferred(model, _config())
    _run(law, samples[:5])
    first_check = law._next_ring_check
    _run(law, samples[5:250])
    assert first_check is not None and law._next_ring_check > first_check + 100
    law.update(*samples[250][:7], None)  # work left
    law.reconfigure(dataclasses.replace(law.config, q_input_change=0.01))
    assert law._next_ring_check is None
    _run(law, samples[251:253], settle=False)  # the next update settles, then plans first
    assert law._next_ring_check is not None and law.input_change_weight >= 0.01


def test_a_step_that_fails_after_the_command_makes_the_next_sample_a_gap(
    controller_robot, monkeypatch
):
    """An identification step that raises in ``settle`` reaches its caller (robot mode counts
    it) and the next sample is a gap, as after an update that failed: no step across it."""
    model = controller_robot.model
    samples = _samples(model)
    law = _deferred(model, _config())
    _run(law, samples[:10])
    law.update(*samples[10][:7], None)

    def fail(dx):
        raise ValueError("a step that cannot be taken")

    monkeypatch.setattr(law, "_identify", fail)
    with pytest.raises(ValueError, match="cannot be taken"):
        law.settle()
    monkeypatch.undo()
    out = law.update(*samples[11][:7], None)
    assert out.skipped
