"""The nominal torque: RNEA along the plan, and the joints' friction at the planned velocity."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from numpy.testing import assert_allclose, assert_array_equal

from apc_core.config_files import config_dir
from apc_core.robot import load_robot, with_friction
from apc_feedforward.nominal import FRICTION_SPEED, Feedforward
from apc_feedforward.trajectory import Quintic


def _arm():
    return load_robot(config_dir() / "puma560_3dof.urdf")


def _plan():
    return Quintic(np.zeros(3), np.array([0.4, -0.3, 0.2]), 1.0)


def test_without_friction_the_nominal_torque_is_rnea_bit_for_bit():
    arm = _arm()
    ff = Feedforward(arm.model, _plan(), 0.01)
    for k in (0, 1, 37, 100):
        sp = ff.sample(k)
        tau = pin.rnea(arm.model, arm.model.createData(), sp.q, sp.qd, sp.qdd)
        assert_array_equal(sp.u_n, tau)


def test_friction_adds_viscous_and_smoothed_coulomb_torque_at_the_planned_velocity():
    arm = _arm()
    coulomb, viscous = np.array([1.0, 2.0, 0.5]), np.array([0.3, 0.2, 0.1])
    geared = with_friction(arm, coulomb, viscous)
    plain, told = Feedforward(arm.model, _plan(), 0.01), Feedforward(geared.model, _plan(), 0.01)
    for k in (0, 1, 37, 100):
        sp, sp_f = plain.sample(k), told.sample(k)
        extra = viscous * sp.qd + coulomb * np.tanh(sp.qd / FRICTION_SPEED)
        assert_allclose(sp_f.u_n - sp.u_n, extra, atol=1e-12)
    at_rest = told.sample(0)  # the plan starts at rest: no friction is pushed against yet
    assert_allclose(at_rest.u_n, plain.sample(0).u_n, atol=1e-12)
    moving = told.sample(50)
    assert np.all(np.abs(moving.u_n - plain.sample(50).u_n) > 0.9 * coulomb)


def test_with_interval_middle_the_torque_is_the_plans_half_a_period_on():
    """A command computed at sample k is held over [kT, (k+1)T): its nominal torque is the
    plan's at the interval's middle, its set point the plan's at kT (where the error is
    measured). Without the option the torque is the set point's own, bit for bit."""
    arm = _arm()
    plan, period = _plan(), 0.01
    middle, own = (
        Feedforward(arm.model, plan, period, 5, True),
        Feedforward(arm.model, plan, period, 5),
    )
    data = arm.model.createData()
    for k in (0, 5, 6, 42, 104, 105, 300):
        sp, at_k = middle.sample(k), own.sample(k)
        for name in ("q", "qd", "qdd"):
            assert_array_equal(getattr(sp, name), getattr(at_k, name))
        q, qd, qdd = plan.sample((k - 5 + 0.5) * period)
        assert_allclose(sp.u_n, pin.rnea(arm.model, data, q, qd, qdd), atol=1e-9)
    moving = middle.sample(40)
    assert np.abs(moving.u_n - own.sample(40).u_n).max() > 1e-3  # the torque changes mid-move
    assert_array_equal(middle.sample(400).u_n, own.sample(400).u_n)  # held: no change
