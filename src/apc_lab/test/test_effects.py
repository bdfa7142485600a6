"""What a physical arm adds to apc's plant: each effect alone, and all off = the plant."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from apc_core.robot import PAPER_START_DEG
from apc_lab.scenario import build, paper_scenario, recommended_settings, run_offline
from apc_plant_sim.effects import (
    ArmEffects,
    EffectsError,
    PhysicalArm,
    puma560_effects,
    single_effect,
)


@pytest.fixture(scope="module")
def built():
    return build(paper_scenario("c"))


def _arm(built, effects, qd0=None):
    q0 = np.deg2rad(PAPER_START_DEG)
    return PhysicalArm(built.plant_robot, built.plant_config, effects, q0, qd0)


def test_all_off_is_the_plant_bit_for_bit():
    scenario = paper_scenario("c")
    ideal = run_offline(scenario, "adaptive", recommended_settings())
    wrapped = run_offline(scenario, "adaptive", recommended_settings(), effects=ArmEffects())
    for name in ("q", "qd", "du", "applied"):
        np.testing.assert_array_equal(getattr(ideal, name), getattr(wrapped, name))


def test_puma_defaults_are_the_toolbox_motor_data_at_the_joints():
    e = puma560_effects()
    np.testing.assert_allclose(e.armature_kgm2, 200e-6 * np.array([62.6111, 107.815, 53.7063]) ** 2)
    np.testing.assert_allclose(e.viscous_nm_s[0], 1.48e-3 * 62.6111**2)
    np.testing.assert_allclose(e.coulomb_pos_nm[1], 0.126 * 107.815)
    np.testing.assert_allclose(e.coulomb_neg_nm[2], 0.105 * 53.7063)
    np.testing.assert_allclose(e.counts_per_rev[0], 1000 * 62.6111)
    assert (e.velocity, e.command_delay) == ("difference", 1)


def test_armature_and_friction_enter_the_forward_dynamics(built):
    e = puma560_effects()
    arm = _arm(built, single_effect("armature", e))
    friction = _arm(built, single_effect("friction", e))
    model = built.plant_robot.model
    data = model.createData()
    q, qd, tau = np.array([0.3, -0.5, -0.9]), np.array([1.0, -0.5, 0.02]), np.array([5.0, 80, 9])
    D = pin.crba(model, data, q)
    D = np.triu(D) + np.triu(D, 1).T
    bias = pin.nonLinearEffects(model, data, q, qd)
    expected = np.linalg.solve(D + np.diag(e.armature_kgm2), tau - bias)
    np.testing.assert_allclose(arm._plant.acceleration(q, qd, tau), expected, rtol=1e-10)
    f = friction._plant.friction(qd)
    b, fp, fn = map(np.array, (e.viscous_nm_s, e.coulomb_pos_nm, e.coulomb_neg_nm))
    np.testing.assert_allclose(f[:2], [b[0] + fp[0], -0.5 * b[1] - fn[1]], rtol=1e-6)
    assert 0.0 < f[2] < b[2] * 0.02 + fp[2]  # within the smoothing band: less than full Coulomb
    np.testing.assert_allclose(
        friction._plant.acceleration(q, qd, tau), np.linalg.solve(D, tau - f - bias), rtol=1e-10
    )


def test_quantised_positions_and_differenced_velocity(built):
    e = single_effect("velocity_difference", puma560_effects())
    arm = _arm(built, e)
    r = 2 * np.pi / np.array(e.counts_per_rev)
    q_prev = arm.q.copy()
    for _ in range(5):
        arm.step(np.array([5.0, 60.0, 20.0]))
        np.testing.assert_allclose(arm.q / r, np.round(arm.q / r), atol=1e-9)
        assert (np.abs(arm.q - arm.true_q) <= r / 2 + 1e-12).all()
        np.testing.assert_allclose(arm.qd, (arm.q - q_prev) / 0.01)
        q_prev = arm.q.copy()


def test_velocity_noise_is_seeded_white_noise(built):
    e = single_effect("velocity_noise", puma560_effects())
    a, b = _arm(built, e), _arm(built, e)
    noise = []
    for _ in range(200):
        a.step(np.zeros(3))
        b.step(np.zeros(3))
        np.testing.assert_array_equal(a.qd, b.qd)
        noise.append(a.qd - a.true_qd)
    assert np.std(noise) == pytest.approx(e.velocity_noise_rad_s, rel=0.15)


def test_command_delay_applies_the_previous_command(built):
    arm = _arm(built, single_effect("delay", puma560_effects()))
    commands = [np.full(3, float(k)) for k in range(1, 5)]
    applied = [arm.step(c).applied for c in commands]
    np.testing.assert_array_equal(applied[0], commands[0])  # held before the run
    for k in range(1, 4):
        np.testing.assert_array_equal(applied[k], commands[k - 1])


def test_bad_effects_are_named(built):
    with pytest.raises(EffectsError, match="viscous_nm_s"):
        ArmEffects(viscous_nm_s=(-1.0,))
    with pytest.raises(EffectsError, match="velocity must be one of"):
        ArmEffects(velocity="tacho")  # type: ignore[arg-type]
    with pytest.raises(EffectsError, match="command_delay"):
        ArmEffects(command_delay=-1)
    with pytest.raises(EffectsError, match="unknown arm effect 'delay'"):
        ArmEffects.from_dict({"delay": 1})
    with pytest.raises(EffectsError, match="armature_kgm2 needs 3 values"):
        _arm(built, ArmEffects(armature_kgm2=(1.0, 2.0)))
    with pytest.raises(EffectsError, match="effect must be"):
        single_effect("backlash", puma560_effects())


def test_panda_effects_are_gaz_et_al_friction_at_full_speed():
    from apc_plant_sim.effects import PANDA_FRICTION_PHI1_NM, panda_effects

    effects = panda_effects()
    # The sigmoid's two levels span its height phi1; phi3 > 0 shifts it to the negative side.
    np.testing.assert_allclose(
        np.add(effects.coulomb_pos_nm, effects.coulomb_neg_nm), PANDA_FRICTION_PHI1_NM
    )
    assert effects.coulomb_pos_nm[0] < effects.coulomb_neg_nm[0]  # phi3 > 0 on joint 1
    assert effects.coulomb_pos_nm[2] > effects.coulomb_neg_nm[2]  # phi3 < 0 on joint 3
    assert not effects.armature_kgm2 and not effects.viscous_nm_s
    assert len(effects.counts_per_rev) == 7 and effects.command_delay == 1
