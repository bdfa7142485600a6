"""Rigid-body dynamics identities and the plant's integrator (apc_plant_sim.plant).

- RNEA (the feedforward's Eqs. 2-8) equals the Lagrange-Euler form D qdd + h + c (Eq. 1).
- The plant's two forward dynamics, ABA and Lagrange-Euler term by term (CRBA, nonlinear
  effects, solve), agree: per acceleration and over a whole period.
- RK4 conserves energy, has order 4, matches a pendulum solved by scipy, and holds the torque
  over the whole period T (zero-order hold).
- Torque limits, configuration checks and input checks.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.integrate import solve_ivp

from apc_core.config_files import config_dir
from apc_core.robot import (
    PAPER_MAX_PAYLOAD_KG,
    PAPER_START_DEG,
    Payload,
    Robot,
    load_robot,
    with_payload,
)
from apc_feedforward.nominal import nominal_torque
from apc_plant_sim.plant import Plant, PlantConfig, PlantError, PlantStep

CONFIG = config_dir()
URDF_3 = CONFIG / "puma560_3dof.urdf"
URDF_6 = CONFIG / "puma560.urdf"
G = 9.8062  # m/s^2

# A state away from any symmetry, for the 3-dof arm (DH angles).
Q0 = np.deg2rad([10.0, -30.0, -60.0])  # rad
QD0 = np.array([1.0, -0.8, 1.5])  # rad/s
TAU = np.array([5.0, 40.0, 10.0])  # N m, well inside the effort limits


@pytest.fixture(scope="module")
def puma3() -> Robot:
    return load_robot(URDF_3)


@pytest.fixture(scope="module")
def puma6() -> Robot:
    return load_robot(URDF_6)


@pytest.fixture(scope="module")
def loaded3(puma3: Robot) -> Robot:
    """The plant's 3-dof arm: the paper's maximum payload at the wrist centre."""
    return with_payload(puma3, Payload(PAPER_MAX_PAYLOAD_KG, (0.0, 0.0, 0.0), "wrist_center"))


def mass_matrix(model: pin.Model, q: np.ndarray) -> np.ndarray:
    """D(q) from CRBA on its own Data, symmetrised from the upper triangle."""
    D = pin.crba(model, model.createData(), q)
    return np.triu(D) + np.triu(D, 1).T


def models() -> dict[str, pin.Model]:
    return {
        "puma3": load_robot(URDF_3).model,
        "puma6": load_robot(URDF_6).model,
        "sample_manipulator": pin.buildSampleModelManipulator(),
    }


# --------------------------------------------------------------------- RNEA = Lagrange-Euler
@pytest.mark.parametrize("name", ["puma3", "puma6", "sample_manipulator"])
def test_rnea_equals_lagrange_euler(name: str) -> None:
    """u_n = RNEA(q, qd, qdd) = D(q) qdd + h(q, qd) + c(q), each term from its own algorithm."""
    model = models()[name]
    rng = np.random.default_rng(2024)
    data = model.createData()
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, model.nq)  # rad
        qd = rng.uniform(-3.0, 3.0, model.nv)  # rad/s
        qdd = rng.uniform(-10.0, 10.0, model.nv)  # rad/s^2
        u_n = nominal_torque(model, data, q, qd, qdd)  # N m
        D = mass_matrix(model, q)
        h_plus_c = pin.nonLinearEffects(model, model.createData(), q, qd).copy()
        c = pin.computeGeneralizedGravity(model, model.createData(), q).copy()
        C = pin.computeCoriolisMatrix(model, model.createData(), q, qd).copy()
        assert_allclose(u_n, D @ qdd + h_plus_c, rtol=0, atol=1e-9)
        assert_allclose(h_plus_c - c, C @ qd, rtol=0, atol=1e-9)  # h alone is C(q, qd) qd
        assert_allclose(nominal_torque(model, data, q, 0 * qd, 0 * qdd), c, atol=1e-9)
        assert_allclose(nominal_torque(model, data, q, qd, 0 * qdd), h_plus_c, atol=1e-9)
        assert_allclose(D, D.T, atol=0)
        assert np.all(np.linalg.eigvalsh(D) > 0.0)


# ----------------------------------------------------------------- forward dynamics = ABA
@pytest.mark.parametrize("n_dof", [3, 6])
def test_plant_acceleration_equals_aba(puma3: Robot, puma6: Robot, n_dof: int) -> None:
    """solve(D, tau - h - c) on the plant's (payload) model equals Pinocchio's ABA."""
    base = puma3 if n_dof == 3 else puma6
    robot = with_payload(base, Payload(PAPER_MAX_PAYLOAD_KG, (0.0, 0.0, 0.05), "wrist_center"))
    by_aba = Plant(robot, PlantConfig(), np.zeros(n_dof))
    by_crba = Plant(robot, PlantConfig(forward_dynamics="crba"), np.zeros(n_dof))
    data = robot.model.createData()
    rng = np.random.default_rng(7)
    for _ in range(10):
        q = rng.uniform(-math.pi, math.pi, n_dof)
        qd = rng.uniform(-3.0, 3.0, n_dof)
        tau = rng.uniform(-1.0, 1.0, n_dof) * robot.effort_limit
        qdd = by_crba.acceleration(q, qd, tau)
        assert_allclose(qdd, pin.aba(robot.model, data, q, qd, tau), rtol=1e-9, atol=1e-9)
        assert_allclose(by_aba.acceleration(q, qd, tau), qdd, rtol=1e-9, atol=1e-9)
        # and it inverts the inverse dynamics
        assert_allclose(pin.rnea(robot.model, data, q, qd, qdd), tau, rtol=1e-9, atol=1e-9)


def test_aba_and_crba_plants_agree_over_a_second(loaded3: Robot) -> None:
    """The two algorithms integrate the same arm: 100 periods apart by rounding only."""
    rng = np.random.default_rng(3)
    torques = rng.uniform(-0.3, 0.3, (100, 3)) * loaded3.effort_limit
    plants = [
        Plant(loaded3, PlantConfig(forward_dynamics=kind), Q0, QD0) for kind in ("aba", "crba")
    ]
    for tau in torques:
        a, b = (plant.step(tau) for plant in plants)
        assert_array_equal(a.applied, b.applied)
    assert_allclose(plants[0].q, plants[1].q, rtol=0, atol=1e-10)
    assert_allclose(plants[0].qd, plants[1].qd, rtol=0, atol=1e-9)
    assert not np.allclose(plants[0].q, Q0, atol=1e-2)  # it moved


# ------------------------------------------------------------------------ energy and order
@pytest.mark.parametrize("gravity", [0.0, G])
def test_energy_is_conserved_without_torque(gravity: float) -> None:
    """Zero torque, 1 s (100 periods of T = 0.01 s, h = 0.0025 s): relative drift < 1e-6.

    Measured: about 7e-13 with gravity off, from 2.06 J of kinetic energy.
    """
    robot = load_robot(URDF_3, gravity=gravity)
    plant = Plant(robot, PlantConfig(period=0.01, step=0.0025), Q0, QD0)
    e0 = plant.energy(Q0, QD0)  # J
    drift = 0.0
    for _ in range(100):
        s = plant.step(np.zeros(3))
        drift = max(drift, abs(plant.energy(s.q, s.qd) - e0) / abs(e0))
    assert drift < 1e-6
    assert plant.k == 100
    assert np.linalg.norm(plant.q - Q0) > 0.5  # the arm really moved


def test_energy_is_kinetic_plus_potential(loaded3: Robot) -> None:
    """energy = 1/2 qd^T D qd + sum_i m_i g z_i (COM heights from forward kinematics)."""
    plant = Plant(loaded3, PlantConfig(), Q0, QD0)
    model, data = loaded3.model, loaded3.model.createData()
    pin.forwardKinematics(model, data, Q0)
    potential = sum(
        model.inertias[i].mass * G * data.oMi[i].act(model.inertias[i].lever)[2]
        for i in range(1, model.njoints)
    )
    kinetic = 0.5 * QD0 @ mass_matrix(model, Q0) @ QD0
    assert_allclose(plant.energy(Q0, QD0), kinetic + potential, rtol=1e-12)


def _reference_period(robot: Robot, x0: np.ndarray, tau: np.ndarray, T: float) -> np.ndarray:
    """(q, qd) after T under constant tau, by DOP853 at rtol 1e-13 on ABA (not the plant)."""
    model, data = robot.model, robot.model.createData()
    n = model.nv

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        return np.concatenate([x[n:], pin.aba(model, data, x[:n], x[n:], tau)])

    sol = solve_ivp(rhs, (0.0, T), x0, method="DOP853", rtol=1e-13, atol=1e-13, max_step=T / 50)
    assert sol.success
    return sol.y[:, -1]


def test_rk4_error_shrinks_16x_when_h_halves(puma3: Robot) -> None:
    """Global error over T = 0.2 s with h = T/8, T/16, T/32: ratios ~16 (order 4).

    Measured: errors 7.5e-7, 4.8e-8, 3.1e-9; ratios 15.5 and 15.7.
    """
    T = 0.2  # s
    x_ref = _reference_period(puma3, np.concatenate([Q0, QD0]), TAU, T)
    errors = []
    for substeps in (8, 16, 32):
        cfg = PlantConfig(period=T, step=T / substeps, enforce_torque_limits=False)
        s = Plant(puma3, cfg, Q0, QD0).step(TAU)
        errors.append(np.linalg.norm(np.concatenate([s.q, s.qd]) - x_ref))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 14.0) & (ratios < 18.0)), (errors, ratios)
    assert_allclose(np.log2(ratios), 4.0, atol=0.2)


# ----------------------------------------------------------------------- pendulum free fall
PENDULUM = """<?xml version="1.0"?>
<robot name="pendulum">
  <link name="base"/>
  <joint name="pivot" type="revolute">
    <parent link="base"/><child link="bob"/>
    <origin xyz="0 0 1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-6" upper="6" effort="10" velocity="20"/>
  </joint>
  <link name="bob">
    <inertial><origin xyz="0 0 -{l}"/><mass value="{m}"/>
      <inertia ixx="{ic}" ixy="0" ixz="0" iyy="{ic}" iyz="0" izz="0.0001"/></inertial>
  </link>
</robot>
"""


@pytest.mark.parametrize("theta0", [0.3, 2.0])
def test_free_fall_matches_scalar_pendulum(theta0: float) -> None:
    """Released from rest: theta'' = -(m g l / I) sin(theta), I = m l^2 + I_c, to 1e-6 rad over 1 s.

    The bob hangs along -z at distance l; turning by theta about +y lifts it to
    z = -l cos(theta), so theta is measured from the downward vertical.
    """
    m, length, ic = 2.0, 0.5, 0.02  # kg, m, kg m^2 (about the COM, y axis)
    robot = load_robot(PENDULUM.format(m=m, l=length, ic=ic), gravity=G)
    inertia = m * length**2 + ic  # about the pivot
    plant = Plant(robot, PlantConfig(period=0.01, step=0.0025), [theta0])
    times = 0.01 * np.arange(1, 101)  # s
    theta = np.array([plant.step(np.zeros(1)).q[0] for _ in times])

    def rhs(_t: float, x: np.ndarray) -> list[float]:
        return [x[1], -(m * G * length / inertia) * math.sin(x[0])]

    sol = solve_ivp(
        rhs, (0.0, 1.0), [theta0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12, t_eval=times
    )
    assert sol.success
    assert_allclose(theta, sol.y[0], rtol=0, atol=1e-6)
    assert np.ptp(theta) > theta0  # it swung through the bottom


# -------------------------------------------------------------------------- zero-order hold
@pytest.mark.parametrize(("step", "atol"), [(0.0025, 1e-7), (0.0005, 1e-9)])
def test_torque_is_held_over_the_period(loaded3: Robot, step: float, atol: float) -> None:
    """Three periods with three torques equal a fine ODE solve with piecewise-constant tau.

    What is left is RK4's truncation error: measured worst 1.7e-8 at h = 2.5 ms (second period,
    the hardest torque) and 2.7e-11 at h = 0.5 ms, the h^4 scaling of the order test.
    """
    T = 0.01  # s
    plant = Plant(loaded3, PlantConfig(period=T, step=step), Q0, QD0)
    torques = [TAU, np.array([-20.0, 80.0, -30.0]), np.array([10.0, 0.0, 60.0])]
    x = np.concatenate([Q0, QD0])
    for tau in torques:
        s = plant.step(tau)
        x = _reference_period(loaded3, x, tau, T)
        assert_allclose(np.concatenate([s.q, s.qd]), x, rtol=0, atol=atol)
        assert_array_equal(s.applied, tau)
    # The check is sensitive: applying tau for only the first substep is far off.
    first_only = Plant(loaded3, PlantConfig(period=0.0025, step=0.0025), Q0, QD0)
    first_only.step(TAU)
    for _ in range(3):
        first_only.step(np.zeros(3))
    held = Plant(loaded3, PlantConfig(period=T, step=0.0025), Q0, QD0).step(TAU)
    assert np.linalg.norm(first_only.qd - held.qd) > 1e-3


def test_step_substeps_compose(loaded3: Robot) -> None:
    """One period of T = 4h equals four periods of T = h under the same torque, to roundoff."""
    coarse = Plant(loaded3, PlantConfig(period=0.01, step=0.0025), Q0, QD0).step(TAU)
    fine = Plant(loaded3, PlantConfig(period=0.0025, step=0.0025), Q0, QD0)
    for _ in range(4):
        s = fine.step(TAU)
    assert_allclose(s.q, coarse.q, atol=1e-14)
    assert_allclose(s.qd, coarse.qd, atol=1e-13)


# --------------------------------------------------------------------------- torque limits
def test_torque_above_the_limit_is_clipped(loaded3: Robot) -> None:
    """|tau_i| > limit_i is clipped to +-limit_i and flagged; the clipped torque is integrated."""
    limit = loaded3.effort_limit
    command = limit * np.array([1.5, -2.0, 0.5])
    plant = Plant(loaded3, PlantConfig(), Q0, QD0)
    s = plant.step(command)
    assert_array_equal(s.applied, [limit[0], -limit[1], 0.5 * limit[2]])
    assert_array_equal(s.saturated, [True, True, False])
    same = Plant(loaded3, PlantConfig(), Q0, QD0).step(s.applied)
    assert_array_equal(s.q, same.q)
    assert_array_equal(s.qd, same.qd)
    assert not same.saturated.any()
    # exactly at the limit is not saturation
    applied, saturated = plant.limit(limit.copy())
    assert_array_equal(applied, limit)
    assert not saturated.any()


def test_torque_limits_can_be_switched_off(loaded3: Robot) -> None:
    """enforce_torque_limits=False applies the command as given and flags nothing."""
    command = loaded3.effort_limit * np.array([1.5, -2.0, 0.5])
    cfg = PlantConfig(enforce_torque_limits=False)
    s = Plant(loaded3, cfg, Q0, QD0).step(command)
    assert_array_equal(s.applied, command)
    assert_array_equal(s.saturated, [False, False, False])
    clipped = Plant(loaded3, PlantConfig(), Q0, QD0).step(command)
    assert np.linalg.norm(s.qd - clipped.qd) > 1e-2


# ------------------------------------------------------------------------- configuration
@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"period": 0.0}, "period"),
        ({"period": -0.01}, "period"),
        ({"period": float("nan")}, "period"),
        ({"step": 0.0}, "step"),
        ({"step": -0.0025}, "step"),
        ({"step": float("inf")}, "step"),
        ({"step": 0.003}, "step"),  # 0.01 / 0.003 is not whole
        ({"step": 0.02}, "step"),  # longer than the period
        ({"forward_dynamics": "euler"}, "forward_dynamics"),
    ],
)
def test_plant_config_rejects(kwargs: dict, name: str) -> None:
    """Bad T or h raise PlantError naming the parameter."""
    with pytest.raises(PlantError, match=name):
        PlantConfig(**kwargs)


@pytest.mark.parametrize(("period", "step", "substeps"), [(0.01, 0.0025, 4), (0.01, 0.001, 10)])
def test_plant_config_substeps(period: float, step: float, substeps: int) -> None:
    assert PlantConfig(period=period, step=step).substeps == substeps
    assert PlantConfig(period=period, step=period).substeps == 1


def test_plant_config_from_dict() -> None:
    assert PlantConfig.from_dict({}) == PlantConfig()
    cfg = PlantConfig.from_dict({"period": 0.02, "step": 0.005, "enforce_torque_limits": False})
    assert cfg == PlantConfig(period=0.02, step=0.005, enforce_torque_limits=False)
    with pytest.raises(PlantError, match="stepsize"):
        PlantConfig.from_dict({"stepsize": 0.001})


BAD_TORQUES = {
    "nan": [np.nan, 0.0, 0.0],
    "inf": [0.0, np.inf, 0.0],
    "too short": [1.0, 2.0],
    "too long": [1.0, 2.0, 3.0, 4.0],
    "empty": [],
}


@pytest.mark.parametrize("tau", BAD_TORQUES.values(), ids=BAD_TORQUES.keys())
def test_step_rejects_bad_torque_and_keeps_state(loaded3: Robot, tau) -> None:
    """NaN, inf or wrong-shape torque: PlantError naming tau; q, qd and k unchanged."""
    plant = Plant(loaded3, PlantConfig(), Q0, QD0)
    plant.step(TAU)
    q, qd, k = plant.q.copy(), plant.qd.copy(), plant.k
    with pytest.raises(PlantError, match="tau"):
        plant.step(np.array(tau, dtype=float))
    assert_array_equal(plant.q, q)
    assert_array_equal(plant.qd, qd)
    assert plant.k == k


def test_step_keeps_state_when_it_would_blow_up(loaded3: Robot) -> None:
    """A finite but absurd unclipped torque that overflows the state is refused."""
    plant = Plant(loaded3, PlantConfig(enforce_torque_limits=False), Q0, QD0)
    with np.errstate(all="ignore"), pytest.raises(PlantError, match="non-finite"):
        plant.step(np.full(3, 1e308))
    assert_array_equal(plant.q, Q0)
    assert_array_equal(plant.qd, QD0)
    assert plant.k == 0


def test_reset_and_initial_state_checks(loaded3: Robot) -> None:
    """reset puts the state back and k to 0; bad q0/qd0 raise PlantError naming them."""
    plant = Plant(loaded3, PlantConfig(), Q0)
    assert_array_equal(plant.qd, np.zeros(3))
    first = plant.step(TAU)
    plant.step(TAU)
    plant.reset(Q0)
    assert plant.k == 0
    again = plant.step(TAU)
    assert isinstance(again, PlantStep)
    assert_array_equal(again.q, first.q)
    assert_array_equal(again.qd, first.qd)
    with pytest.raises(PlantError, match="q0"):
        plant.reset(np.zeros(2))
    with pytest.raises(PlantError, match="qd0"):
        plant.reset(Q0, [0.0, np.nan, 0.0])
    # the returned arrays are copies: editing them does not touch the plant
    again.q[:] = 99.0
    assert not np.any(plant.q == 99.0)


def test_set_robot_swaps_the_model_and_keeps_the_state() -> None:
    """A payload picked up mid-run: same state, new dynamics from the next step on."""
    robot = load_robot(URDF_3)
    loaded = with_payload(robot, Payload(2.268, frame="wrist_center"))
    q0 = np.deg2rad(PAPER_START_DEG)
    a = Plant(robot, PlantConfig(), q0)
    a.step(np.zeros(3))
    q1 = a.q.copy()
    a.set_robot(loaded)
    np.testing.assert_array_equal(a.q, q1)
    b = Plant(loaded, PlantConfig(), a.q, a.qd)
    np.testing.assert_array_equal(a.step(np.ones(3)).q, b.step(np.ones(3)).q)
    with pytest.raises(PlantError, match="set_robot"):
        a.set_robot(load_robot(URDF_6))
