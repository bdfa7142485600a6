"""The arm in MuJoCo: its inertias made physical, its dynamics against Pinocchio's, and the
ideal MuJoCo arm against apc's plant (no ROS graph)."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from apc_core.config_files import resolve_config_path
from apc_core.params import ConfigError
from apc_core.robot import (
    PAPER_START_DEG,
    Payload,
    Robot,
    RobotModelError,
    load_robot,
    with_payload,
)
from apc_feedback.laws import make_law
from apc_feedforward.nominal import Feedforward
from apc_lab.reproduce import example_robot_urdf
from apc_lab.scenario import build, paper_scenario, recommended_settings
from apc_plant_sim.effects import PANDA_FRICTION_PHI1_NM, ArmEffects, puma560_effects
from apc_plant_sim.engines import EngineError, effects_from_values, make_engine
from apc_plant_sim.mujoco_engine import (
    MIN_MASS_KG,
    JointEffects,
    MujocoEngine,
    compile_model,
    physical_inertias,
)
from apc_plant_sim.plant import Plant, PlantConfig
from apc_plant_sim.robot_driver import DriverConfig, RobotDriver

RNG_STATES = 200


def _puma3() -> Robot:
    return load_robot(resolve_config_path("puma560_3dof.urdf"))


def _puma6() -> Robot:
    return load_robot(resolve_config_path("puma560.urdf"))


def _panda() -> Robot:
    return load_robot(
        example_robot_urdf("panda_description/urdf/panda.urdf"),
        lock_joints=("panda_finger_joint1", "panda_finger_joint2"),
    )


ARMS = {"puma560_3dof": _puma3, "puma560": _puma6, "panda": _panda}


def _mass_matrix(model: pin.Model, data: pin.Data, q: np.ndarray) -> np.ndarray:
    M = pin.crba(model, data, q).copy()
    return np.triu(M) + np.triu(M, 1).T


def _states(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    for _ in range(RNG_STATES):
        yield rng.uniform(-np.pi, np.pi, n), rng.uniform(-3.0, 3.0, n)


def test_mujoco_refuses_the_puma_560_inertias_as_published():
    with pytest.raises(RobotModelError, match="MuJoCo refuses"):
        compile_model(_puma3().model)


@pytest.mark.parametrize("arm", ["puma560_3dof", "puma560"])
def test_link_1_correction_leaves_the_joint_space_dynamics_unchanged(arm):
    """Link 1 hangs from the base by joint 1: only its moment about that axis ever acts."""
    model = ARMS[arm]().model
    physical, corrections = physical_inertias(model)
    link1 = next(c for c in corrections if c.joint == "joint_1")
    assert link1.invisible and link1.mass_added == MIN_MASS_KG
    np.testing.assert_allclose(link1.before, [0.0, 0.0, 0.35], atol=1e-15)
    np.testing.assert_allclose(link1.after, [0.175, 0.175, 0.35], rtol=1e-8)
    only_link1 = pin.Model(model)
    only_link1.inertias[1] = physical.inertias[1]
    d0, d1 = model.createData(), only_link1.createData()
    for q, v in _states(model.nv):
        np.testing.assert_allclose(
            _mass_matrix(only_link1, d1, q), _mass_matrix(model, d0, q), rtol=0, atol=1e-12
        )
        np.testing.assert_allclose(
            pin.nonLinearEffects(only_link1, d1, q, v),
            pin.nonLinearEffects(model, d0, q, v),
            rtol=0,
            atol=1e-12,
        )


def test_link_3_correction_what_it_changes_in_numbers():
    """The 3-joint arm's link 3 (with the lumped wrist) falls 0.00735 kg m^2 short of A + B >= C;
    the smallest correction moves its moments by (+d, +d, -d), d = 0.00245 kg m^2. Masses and
    centres of mass stay, so gravity is unchanged; M(q) changes by at most 0.00245 kg m^2 per
    entry (0.25 % of ||M||), the bias forces by at most 0.004 N m at |q'| <= 3 rad/s."""
    model = _puma3().model
    physical, corrections = physical_inertias(model)
    link3 = next(c for c in corrections if c.joint == "joint_3")
    assert not link3.invisible
    np.testing.assert_allclose(link3.before, [0.01269013, 0.19630386, 0.21635257], atol=1e-8)
    shortfall = link3.before[2] - link3.before[0] - link3.before[1]
    assert shortfall == pytest.approx(0.007359, abs=1e-6)
    np.testing.assert_allclose(link3.after - link3.before, shortfall / 3 * np.array([1, 1, -1]))
    d0, d1 = model.createData(), physical.createData()
    dM = db = dM_rel = 0.0
    for q, v in _states(model.nv, seed=1):
        M0, M1 = _mass_matrix(model, d0, q), _mass_matrix(physical, d1, q)
        dM = max(dM, np.abs(M1 - M0).max())
        dM_rel = max(dM_rel, np.linalg.norm(M1 - M0, 2) / np.linalg.norm(M0, 2))
        db = max(
            db,
            np.abs(
                pin.nonLinearEffects(physical, d1, q, v) - pin.nonLinearEffects(model, d0, q, v)
            ).max(),
        )
        np.testing.assert_allclose(
            pin.computeGeneralizedGravity(physical, d1, q),
            pin.computeGeneralizedGravity(model, d0, q),
            rtol=0,
            atol=1e-12,
        )
    assert 0.0024 < dM <= 0.00246
    assert dM_rel < 0.0025
    assert 0.0 < db < 0.004


@pytest.mark.parametrize("arm", sorted(ARMS))
@pytest.mark.parametrize("payload_kg", [0.0, 2.268])
def test_mujoco_mass_matrix_and_bias_equal_pinocchios_with_the_same_inertias(arm, payload_kg):
    robot = with_payload(ARMS[arm](), Payload(mass_kg=payload_kg))
    physical, _ = physical_inertias(robot.model)
    mj_model = compile_model(physical)
    mj_data = mujoco.MjData(mj_model)
    data = physical.createData()
    n = physical.nv
    M = np.zeros((n, n))
    for q, v in _states(n, seed=2):
        mj_data.qpos[:], mj_data.qvel[:] = q, v
        mujoco.mj_forward(mj_model, mj_data)
        mujoco.mj_fullM(mj_model, mj_data, M)
        np.testing.assert_allclose(M, _mass_matrix(physical, data, q), rtol=0, atol=1e-6)
        np.testing.assert_allclose(
            mj_data.qfrc_bias, pin.nonLinearEffects(physical, data, q, v), rtol=0, atol=1e-6
        )


def test_ideal_mujoco_arm_integrates_what_apcs_plant_integrates_on_the_same_inertias():
    """Same torque sequence, same RK4 step: MuJoCo's integrator and apc's plant agree to 1e-9."""
    robot = _puma3()
    physical, _ = physical_inertias(with_payload(robot, Payload(mass_kg=2.268)).model)
    q0 = np.deg2rad(PAPER_START_DEG)
    engine = MujocoEngine(robot, Payload(mass_kg=2.268), period=0.01, max_step=0.0025, q0=q0)
    plant = Plant(
        Robot(physical, robot.joint_names, robot.effort_limit),
        PlantConfig(period=0.01, step=0.0025, enforce_torque_limits=False),
        q0,
    )
    rng = np.random.default_rng(4)
    for _ in range(100):
        tau = rng.uniform(-20.0, 20.0, 3) + pin.computeGeneralizedGravity(
            physical, physical.createData(), plant.q
        )
        engine.advance(tau, 0.01)
        plant.step(tau)
    np.testing.assert_allclose(engine.q, plant.q, rtol=0, atol=1e-9)
    np.testing.assert_allclose(engine.qd, plant.qd, rtol=0, atol=1e-8)


def _track_paper_move(engine_name: str) -> tuple[np.ndarray, np.ndarray]:
    """Case (c) (5 lb) under the recommended preset through the driver at 100 Hz."""
    scenario = paper_scenario("c")
    built = build(scenario)
    q0, _, _ = built.trajectory.sample(0.0)
    payload = Payload(scenario.payload_kg, tuple(scenario.payload_com_m), scenario.payload_frame)
    engine = make_engine(
        engine_name,
        built.unloaded_robot,
        payload,
        ArmEffects(),
        period=scenario.period,
        max_step=scenario.step,
        q0=q0,
        loaded=True,
    )
    driver = RobotDriver(engine, DriverConfig(state_rate=1.0 / scenario.period))
    feedforward = Feedforward(built.controller_robot.model, built.trajectory, scenario.period)
    feedback = make_law("adaptive", built.controller_robot, scenario.period, recommended_settings())
    feedback.reset()
    applied = None
    q, error = [], []
    for k in range(scenario.n_samples + 1):
        t = k * scenario.period
        reading = driver.measure(t)
        sp = feedforward.sample(k)
        out = feedback.update(
            k, reading.position, reading.velocity, sp.q, sp.qd, sp.qdd, sp.u_n, applied
        )
        q.append(reading.position)
        error.append(reading.position - sp.q)
        driver.offer(sp.u_n + out.du, t)
        applied = driver.advance(t).copy()
    return np.array(q), np.array(error)


def test_ideal_mujoco_arm_tracks_the_paper_move_like_apcs_plant():
    """All effects off: the MuJoCo arm and apc's plant (engine pinocchio) under the same laws
    stay within 0.01 deg of each other over the paper's move and hold (measured: 0.0008 deg,
    the link-3 inertia correction), and both track within 0.2 deg (measured 0.16 deg)."""
    q_pin, e_pin = _track_paper_move("pinocchio")
    q_mj, e_mj = _track_paper_move("mujoco")
    assert np.rad2deg(np.abs(q_mj - q_pin).max()) < 0.01
    for error in (e_pin, e_mj):
        assert np.rad2deg(np.abs(error).max()) < 0.2


def test_payload_picked_up_mid_motion_changes_mujocos_model_to_the_loaded_one():
    robot = _puma3()
    payload = Payload(mass_kg=2.268, frame="wrist_center")
    q0 = np.deg2rad([10.0, -30.0, 20.0])
    engine = MujocoEngine(robot, payload, period=0.01, max_step=0.005, q0=q0, loaded=False)
    physical, _ = physical_inertias(with_payload(robot, payload).model)
    engine.advance(np.zeros(3), 0.01)
    engine.load_payload()
    mujoco.mj_forward(engine.model, engine.data)
    M = np.zeros((3, 3))
    mujoco.mj_fullM(engine.model, engine.data, M)
    np.testing.assert_allclose(
        M, _mass_matrix(physical, physical.createData(), engine.q), rtol=0, atol=1e-9
    )


def test_joint_effects_enter_mujocos_model():
    effects = JointEffects(
        damping=(1.0, 2.0, 3.0), frictionloss=(4.0, 5.0, 6.0), armature=(0.7, 0.8, 0.9)
    )
    engine = MujocoEngine(
        _puma3(), Payload(), period=0.01, max_step=0.01, q0=np.zeros(3), effects=effects
    )
    np.testing.assert_array_equal(engine.model.dof_damping, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(engine.model.dof_frictionloss, [4.0, 5.0, 6.0])
    np.testing.assert_array_equal(engine.model.dof_armature, [0.7, 0.8, 0.9])
    # Coulomb friction holds the arm against a torque below it (joint 1 moves in a horizontal
    # plane: no gravity on it).
    engine.advance(np.array([3.0, 0.0, 0.0]), 0.01)
    assert abs(engine.qd[0]) < 1e-3


def _effect_values(**overrides) -> dict:
    values = {
        "effects": "ideal",
        "damping": [],
        "frictionloss": [],
        "armature": [],
        "encoder_counts_per_rev": [],
        "velocity_source": "",
        "velocity_noise": -1.0,
        "command_delay_cycles": -1,
        "seed": 0,
    }
    values.update(overrides)
    return values


def test_effect_presets_and_overrides():
    assert effects_from_values(_effect_values(), 3) == ArmEffects()
    puma = effects_from_values(_effect_values(effects="puma560"), 3)
    data = puma560_effects()
    assert puma.viscous_nm_s == data.viscous_nm_s and puma.armature_kgm2 == data.armature_kgm2
    np.testing.assert_allclose(
        puma.coulomb_pos_nm, 0.5 * (np.array(data.coulomb_pos_nm) + data.coulomb_neg_nm)
    )
    assert puma.velocity == "difference" and puma.command_delay == 1
    np.testing.assert_allclose(puma.armature_kgm2, [0.784, 2.325, 0.577], atol=1e-3)
    panda = effects_from_values(_effect_values(effects="panda"), 7)
    np.testing.assert_allclose(panda.coulomb_pos_nm, np.array(PANDA_FRICTION_PHI1_NM) / 2)
    assert panda.velocity == "difference" and len(panda.counts_per_rev) == 7
    assert panda.command_delay == 1 and not panda.viscous_nm_s
    mixed = effects_from_values(
        _effect_values(
            effects="puma560",
            damping=[1.0, 2.0, 3.0],
            velocity_source="exact",
            command_delay_cycles=0,
        ),
        3,
    )
    assert mixed.viscous_nm_s == (1.0, 2.0, 3.0) and mixed.velocity == "exact"
    assert mixed.command_delay == 0 and mixed.armature_kgm2 == data.armature_kgm2
    for overrides, n, param in (
        ({"effects": "puma560"}, 6, "effects"),
        ({"effects": "panda"}, 3, "effects"),
        ({"effects": "ur5"}, 3, "effects"),
        ({"damping": [1.0]}, 3, "damping"),
        ({"armature": [0.1, -0.1, 0.0]}, 3, "armature"),
        ({"velocity_source": "tacho"}, 3, "velocity_source"),
    ):
        with pytest.raises(ConfigError, match=f"^parameter '{param}'"):
            effects_from_values(_effect_values(**overrides), n)


def test_panda_in_mujoco_with_its_identified_friction():
    robot = _panda()
    effects = effects_from_values(_effect_values(effects="panda"), 7)
    engine = make_engine(
        "mujoco",
        robot,
        Payload(),
        effects,
        period=0.001,
        max_step=0.001,
        q0=np.zeros(7),
        loaded=True,
    )
    np.testing.assert_allclose(engine.model.dof_frictionloss, np.array(PANDA_FRICTION_PHI1_NM) / 2)


@pytest.mark.parametrize("engine_name", ["mujoco", "pinocchio"])
def test_an_unstable_period_raises_and_keeps_the_state(engine_name, tmp_path, monkeypatch):
    """MuJoCo would reset the arm to its initial pose (and write MUJOCO_LOG.TXT into the
    working directory); here the period is refused, the state before it kept."""
    monkeypatch.chdir(tmp_path)
    q0 = np.deg2rad([10.0, -30.0, 20.0])
    engine = make_engine(
        engine_name,
        _puma3(),
        Payload(),
        ArmEffects(),
        period=0.01,
        max_step=0.005,
        q0=q0,
        loaded=True,
    )
    engine.advance(np.array([0.0, 50.0, 0.0]), 0.01)
    q, qd = engine.q, engine.qd
    with pytest.raises(EngineError):
        engine.advance(np.array([1e300, -1e300, 1e300]), 0.01)
    np.testing.assert_array_equal(engine.q, q)
    np.testing.assert_array_equal(engine.qd, qd)
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
