"""The controllers' friction model in computed torque: Eq. 36 plus the friction the nominal
torque carries, at the planned velocity."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from apc_core.robot import with_friction
from apc_feedback.baselines import ComputedTorque, PdGains
from apc_feedforward.nominal import friction_torque, joint_friction, nominal_torque

rng = np.random.default_rng(11)


def test_computed_torque_with_friction_adds_it_at_the_planned_velocity(controller_robot):
    """A model told its joints' friction: Eq. 36 plus ``b qd_d + f tanh(qd_d / v_s)``, so that
    on the plan it still adds nothing to the nominal torque, which carries the same friction;
    measured velocity off the plan does not move the friction term."""
    model = with_friction(controller_robot, [20.0, 10.0, 5.0], [4.0, 6.0, 2.0]).model
    data = model.createData()
    friction = joint_friction(model)
    q, qd, qdd_d = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    q_d, qd_d = q + 0.01 * rng.normal(size=3), qd + 0.1 * rng.normal(size=3)
    law = ComputedTorque(model, PdGains(kp=100.0, kv=20.0))
    u_n = nominal_torque(model, data, q_d, qd_d, qdd_d, friction)
    on_plan = law.update(0, q_d, qd_d, q_d, qd_d, qdd_d, u_n, None).du
    np.testing.assert_allclose(on_plan, 0.0, atol=1e-9)
    rigid = ComputedTorque(controller_robot.model, PdGains(kp=100.0, kv=20.0))
    u_rigid = pin.rnea(controller_robot.model, data, q_d, qd_d, qdd_d)
    tau = u_n + law.update(0, q, qd, q_d, qd_d, qdd_d, u_n, None).du
    tau_rigid = u_rigid + rigid.update(0, q, qd, q_d, qd_d, qdd_d, u_rigid, None).du
    np.testing.assert_allclose(tau - tau_rigid, friction_torque(friction, qd_d), atol=1e-9)
