"""The ROS user's baseline: per-joint PID on top of the nominal torque (JTC with an effort
interface and a feed-forward effort)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from apc_core.robot import load_robot
from apc_feedback.baselines import PID, PidGains
from apc_feedback.controller import FeedbackError
from apc_feedback.laws import make_law
from apc_lab.scenario import CONFIG_DIR, paper_scenario, run_offline


@pytest.fixture(scope="module")
def robot():
    return load_robot(CONFIG_DIR / "puma560_3dof.urdf")


def _update(law, k, q, qd, q_d, qd_d):
    z = np.zeros(3)
    return law.update(k, q, qd, q_d, qd_d, z, z, None).du


def test_tuning_rule_puts_three_poles_at_the_bandwidth(robot):
    """Kp = 3 J w^2, Kd = 3 J w, Ki = J w^3 with J the model's D(q_d(0))_ii."""
    law = make_law("pid", robot, 0.01, {"bandwidth": 8.0})
    q0 = np.array([0.1, -0.7, -0.8])
    _update(law, 0, q0, np.zeros(3), q0, np.zeros(3))
    J = pin.crba(robot.model, robot.model.createData(), q0).diagonal()
    np.testing.assert_allclose(law.gains.p, 3 * J * 64.0)
    np.testing.assert_allclose(law.gains.d, 3 * J * 8.0)
    np.testing.assert_allclose(law.gains.i, J * 512.0)
    np.testing.assert_allclose(law.gains.i_clamp, 0.2 * robot.effort_limit)
    for i in range(3):  # the decoupled joint's closed loop: a triple pole at -w
        roots = np.roots([J[i], law.gains.d[i], law.gains.p[i], law.gains.i[i]])
        np.testing.assert_allclose(roots, -8.0, atol=1e-3)


def test_explicit_gains_give_p_plus_integral_plus_velocity_error(robot):
    gains = PidGains(p=(10, 20, 30), i=(1, 2, 3), d=(4, 5, 6), i_clamp=(100, 100, 100))
    law = PID(robot.model, robot.effort_limit, 0.01, gains)
    q_d, qd_d = np.array([0.5, 0.0, -0.5]), np.array([1.0, 0.0, 0.0])
    q, qd = np.array([0.4, 0.1, -0.5]), np.array([0.5, 0.0, 1.0])
    e, ed = q_d - q, qd_d - qd
    for k in range(3):
        du = _update(law, k, q, qd, q_d, qd_d)
        expected = np.array(gains.p) * e + np.array(gains.i) * (k + 1) * 0.01 * e
        np.testing.assert_allclose(du, expected + np.array(gains.d) * ed)


def test_integral_term_stays_within_i_clamp_and_reset_empties_it(robot):
    gains = PidGains(p=(0, 0, 0), i=(50, 50, 50), d=(0, 0, 0), i_clamp=(1.0, 2.0, 3.0))
    law = PID(robot.model, robot.effort_limit, 0.01, gains)
    e = np.array([1.0, -1.0, 1.0])
    for k in range(100):
        du = _update(law, k, np.zeros(3), np.zeros(3), e, np.zeros(3))
    np.testing.assert_allclose(du, [1.0, -2.0, 3.0])
    law.reset()
    np.testing.assert_allclose(_update(law, 0, np.zeros(3), np.zeros(3), e, np.zeros(3)), 0.5 * e)


def test_bad_gains_are_named(robot):
    with pytest.raises(FeedbackError, match="given together"):
        PidGains(p=(1, 1, 1))
    with pytest.raises(FeedbackError, match="i_clamp must be finite"):
        PidGains(i_clamp=(-1.0,))
    with pytest.raises(FeedbackError, match="bandwidth"):
        PidGains(bandwidth=0.0)
    with pytest.raises(FeedbackError, match="unknown gain parameter 'kp'"):
        make_law("pid", robot, 0.01, {"kp": 1.0})
    law = make_law("pid", robot, 0.01, {"p": [1, 2], "i": [1, 2], "d": [1, 2]})
    with pytest.raises(FeedbackError, match="pid p needs 3 values"):
        _update(law, 0, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3))


def test_pid_tracks_the_paper_move_without_load():
    """Case (a), ideal arm: the tuned PID stays within 0.1 deg (measured 0.083 deg)."""
    result = run_offline(paper_scenario("a"), "pid")
    assert np.rad2deg(np.abs(result.error)).max() < 0.1
