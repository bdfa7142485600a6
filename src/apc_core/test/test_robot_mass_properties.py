"""apc_core.robot, mass properties: the PUMA bodies' masses and inertias against the reference,
and the model edits that change them, a payload (``with_payload``) and an inertia error
(``with_inertia_error``), checked with the parallel-axis theorem in plain numpy.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from robot_helpers import (
    D4,
    DH_ROWS,
    G,
    assert_same_bodies,
    dh_frames,
    frame_position,
    gravity_torque,
    snapshot,
)

from apc_core.robot import (
    PAPER_MAX_PAYLOAD_KG,
    Payload,
    Robot,
    RobotModelError,
    with_armature,
    with_friction,
    with_inertia_error,
    with_payload,
)


def parallel_axis(inertia_c: np.ndarray, mass: float, r: np.ndarray) -> np.ndarray:
    """Rotational inertia about a point at -r from the COM: I_c + m (|r|^2 1 - r r^T)."""
    return inertia_c + mass * (float(r @ r) * np.eye(3) - np.outer(r, r))


# ------------------------------------------------------------------------ mass properties
def test_total_mass(puma3: Robot, puma6: Robot) -> None:
    """3-dof: 17.4 + 4.8 + 1.25 kg (link 1 massless); 6-dof: the sum of the reference masses."""
    masses3 = [b.mass for b in puma3.model.inertias]
    assert_allclose(sum(masses3), 17.4 + 4.8 + 1.25, rtol=1e-12)
    assert_allclose(masses3, [0.0, 0.0, 17.4, 4.8 + 1.25], rtol=1e-12)
    masses6 = [b.mass for b in puma6.model.inertias]
    assert_allclose(sum(masses6), sum(r["mass_kg"] for r in DH_ROWS), rtol=1e-12)
    assert_allclose(masses6[1:], [r["mass_kg"] for r in DH_ROWS], rtol=1e-12)


def test_link_1_inertia_about_joint_1_axis(puma: Robot) -> None:
    """Body 1's inertia about the joint-1 axis is the reference's 0.35 kg m^2, and nothing else."""
    body = puma.model.inertias[1]
    about_joint = body.matrix()[3:, 3:]  # rotational inertia about the joint origin, joint frame
    assert_allclose(about_joint[2, 2], 0.35, rtol=1e-12)
    assert_allclose(about_joint, np.diag([0.0, 0.0, 0.35]), atol=1e-12)


def test_link_inertias_match_the_reference_in_dh_frames(puma6: Robot) -> None:
    """Each body's COM and inertia, rotated into DH frame i, equal the reference numbers."""
    model, data = puma6.model, puma6.model.createData()
    q = np.random.default_rng(1).uniform(-1.0, 1.0, 6)
    pin.framesForwardKinematics(model, data, q)
    for i, row in enumerate(DH_ROWS, start=1):
        if row["mass_kg"] == 0.0:
            continue
        # body inertia is in joint i's frame; express it in DH frame i
        oMi = data.oMi[i]
        oMdh = data.oMf[model.getFrameId(f"dh_frame_{i}")]
        dhMi = oMdh.actInv(oMi)
        body = dhMi.act(model.inertias[i])
        assert_allclose(body.mass, row["mass_kg"], rtol=1e-12)
        assert_allclose(body.lever, row["com_m"], atol=1e-9)
        assert_allclose(body.inertia, row["inertia_about_com_kgm2"], atol=1e-9)


# ------------------------------------------------------------------------------- payload
PAYLOAD_CASES = [
    ("wrist_center", (0.0, 0.0, 0.0)),
    ("wrist_center", (0.01, -0.02, 0.05)),
    ("dh_frame_1", (0.1, 0.2, 0.3)),
    ("dh_frame_3", (0.05, -0.02, 0.1)),
    (None, (0.01, 0.02, 0.03)),
]


@pytest.mark.parametrize(("frame", "com"), PAYLOAD_CASES)
def test_payload_adds_a_point_mass_to_the_carrying_body(puma3: Robot, frame, com) -> None:
    """Mass adds exactly, COM and inertia follow the parallel-axis theorem, nothing else moves."""
    mass = PAPER_MAX_PAYLOAD_KG
    before = snapshot(puma3.model)
    loaded = with_payload(puma3, Payload(mass, com, frame))
    assert_same_bodies(snapshot(puma3.model), before)  # original untouched
    assert loaded.model is not puma3.model
    # Where the point sits in the carrying joint's frame, found through forward kinematics.
    q = np.array([0.3, -0.7, 1.1])
    data = puma3.model.createData()
    pin.framesForwardKinematics(puma3.model, data, q)
    if frame is None:
        jid, point = puma3.model.njoints - 1, np.asarray(com)
    else:
        fid = puma3.model.getFrameId(frame)
        jid = puma3.model.frames[fid].parentJoint
        point = data.oMi[jid].actInv(data.oMf[fid].act(np.asarray(com)))
    m0, c0, i0 = before[jid]
    m1 = m0 + mass
    c1 = (m0 * c0 + mass * point) / m1
    i1 = parallel_axis(i0, m0, c0 - c1) + parallel_axis(np.zeros((3, 3)), mass, point - c1)
    after = snapshot(loaded.model)
    assert after[jid][0] == pytest.approx(m1, rel=1e-15)
    assert_allclose(after[jid][1], c1, atol=1e-12)
    assert_allclose(after[jid][2], i1, atol=1e-12)
    # Pinocchio's own inertia arithmetic agrees.
    expected = puma3.model.inertias[jid] + pin.Inertia(mass, point, np.zeros((3, 3)))
    assert_allclose(loaded.model.inertias[jid].matrix(), expected.matrix(), atol=1e-12)
    for k in range(len(before)):
        if k != jid:
            assert_same_bodies([after[k]], [before[k]])
    assert loaded.joint_names == puma3.joint_names
    assert_array_equal(loaded.effort_limit, puma3.effort_limit)


def test_zero_payload_changes_nothing(puma3: Robot) -> None:
    """A 0 kg payload returns an equal (but new) model."""
    same = with_payload(puma3, Payload(0.0, (1.0, 2.0, 3.0), "wrist_center"))
    assert same.model is not puma3.model
    assert_same_bodies(snapshot(same.model), snapshot(puma3.model))


@pytest.mark.parametrize("pose_deg", [(45.0, 0.0, -90.0), (30.0, -20.0, -70.0), (-60, 35, 10)])
def test_wrist_payload_gravity_torque_is_mg_times_horizontal_lever(puma3: Robot, pose_deg) -> None:
    """A wrist payload adds m g (a x r)_z to c_j: weight times horizontal lever about axis j."""
    mass = PAPER_MAX_PAYLOAD_KG
    q = np.deg2rad(pose_deg)
    loaded = with_payload(puma3, Payload(mass, (0.0, 0.0, 0.0), "wrist_center"))
    delta = gravity_torque(loaded, q) - gravity_torque(puma3, q)
    wc = frame_position(puma3, q, "wrist_center")
    T = [np.eye(4), *dh_frames(q)]
    for j in range(3):  # joint j+1 turns about z of DH frame j, through its origin
        axis, origin = T[j][:3, 2], T[j][:3, 3]
        r = wc - origin
        lever = np.cross(axis, r)[2]  # signed horizontal distance, m
        assert_allclose(delta[j], mass * G * lever, atol=1e-10)
    assert_allclose(delta[0], 0.0, atol=1e-10)  # joint 1 is vertical
    if pose_deg == (45.0, 0.0, -90.0):  # stretched: reach a2 + d4, forearm lever d4
        assert_allclose(delta[1:], mass * G * np.array([0.4318 + D4, D4]), rtol=1e-9)


def test_payload_errors(puma3: Robot) -> None:
    """Bad payloads and frames raise RobotModelError naming the problem."""
    with pytest.raises(RobotModelError, match="mass_kg"):
        Payload(-1.0)
    with pytest.raises(RobotModelError, match="mass_kg"):
        Payload(float("nan"))
    with pytest.raises(RobotModelError, match="com_m"):
        Payload(1.0, (0.0, float("inf"), 0.0))
    with pytest.raises(RobotModelError, match="com_m"):
        Payload(1.0, (0.0, 0.0))
    with pytest.raises(RobotModelError, match="no_such_frame"):
        with_payload(puma3, Payload(1.0, frame="no_such_frame"))
    with pytest.raises(RobotModelError, match="does not move"):
        with_payload(puma3, Payload(1.0, frame="base_link"))


def test_paper_max_payload_is_5_lb() -> None:
    assert PAPER_MAX_PAYLOAD_KG == pytest.approx(2.26796185, rel=1e-9)


# ------------------------------------------------------------------------- inertia error
@pytest.mark.parametrize("n_dof", [3, 6])
def test_inertia_error_scales_only_the_rotational_inertia(puma3, puma6, n_dof) -> None:
    """Body i's inertia about its COM becomes (1 + e_i) I_i; masses and levers stay."""
    robot = puma3 if n_dof == 3 else puma6
    err = np.array([0.1, -0.1, 0.25, -0.5, 0.0, 3.0])[:n_dof]
    before = snapshot(robot.model)
    wrong = with_inertia_error(robot, err)
    assert_same_bodies(snapshot(robot.model), before)  # original untouched
    after = snapshot(wrong.model)
    assert_same_bodies([after[0]], [before[0]])  # universe
    for i in range(1, n_dof + 1):
        assert after[i][0] == before[i][0]
        assert_array_equal(after[i][1], before[i][1])
        assert_allclose(after[i][2], (1.0 + err[i - 1]) * before[i][2], rtol=1e-15, atol=0)
    assert wrong.joint_names == robot.joint_names


def test_inertia_error_with_paper_pattern_changes_the_mass_matrix(puma3: Robot) -> None:
    """+-10 % on the 3-dof arm: D changes, gravity (masses and levers only) does not."""
    wrong = with_inertia_error(puma3, [0.1, -0.1, 0.1])
    q = np.deg2rad([10.0, -30.0, -60.0])
    D0 = pin.crba(puma3.model, puma3.model.createData(), q)
    D1 = pin.crba(wrong.model, wrong.model.createData(), q)
    assert np.max(np.abs(D1 - D0)) > 1e-3
    assert_allclose(gravity_torque(wrong, q), gravity_torque(puma3, q), atol=1e-12)
    assert_allclose(D1[0, 0] - D0[0, 0], 0.1 * 0.35 + _joint1_share(puma3, wrong, q), atol=1e-12)


def _joint1_share(base: Robot, wrong: Robot, q: np.ndarray) -> float:
    """D_11 change from links 2 and 3: z0^T (dR_i I_i R_i^T) z0 with the scaled tensors."""
    data = base.model.createData()
    pin.forwardKinematics(base.model, data, q)
    total = 0.0
    for i in (2, 3):
        R = data.oMi[i].rotation
        dI = wrong.model.inertias[i].inertia - base.model.inertias[i].inertia
        total += float(np.array([0, 0, 1.0]) @ R @ dI @ R.T @ np.array([0, 0, 1.0]))
    return total


BAD_ERRORS = {
    "too short": (0.1, 0.1),
    "too long": (0.1, 0.1, 0.1, 0.1),
    "nested": ((0.1, 0.1, 0.1),),
    "e = -1": (-1.0, 0.0, 0.0),
    "e < -1": (0.0, -1.5, 0.0),
    "nan": (0.0, 0.0, np.nan),
    "inf": (np.inf, 0.0, 0.0),
}


@pytest.mark.parametrize("err", BAD_ERRORS.values(), ids=BAD_ERRORS.keys())
def test_inertia_error_rejects_bad_values(puma3: Robot, err) -> None:
    """Wrong length, e <= -1, NaN or inf: RobotModelError."""
    with pytest.raises(RobotModelError, match="inertia error"):
        with_inertia_error(puma3, err)


def test_armature_adds_to_the_mass_matrix_diagonal_and_to_rnea(puma3: Robot) -> None:
    armature = np.array([0.5, 1.0, 0.25])
    geared = with_armature(puma3, armature)
    q, v, a = np.array([0.1, -0.4, 0.7]), np.array([0.3, -0.2, 0.5]), np.array([1.0, -2.0, 3.0])
    plain_data, geared_data = puma3.model.createData(), geared.model.createData()
    m_plain = pin.crba(puma3.model, plain_data, q)
    m_geared = pin.crba(geared.model, geared_data, q)
    m_plain = np.triu(m_plain) + np.triu(m_plain, 1).T
    m_geared = np.triu(m_geared) + np.triu(m_geared, 1).T
    assert_allclose(m_geared - m_plain, np.diag(armature), atol=1e-12)
    tau_plain = pin.rnea(puma3.model, plain_data, q, v, a)
    assert_allclose(pin.rnea(geared.model, geared_data, q, v, a) - tau_plain, armature * a)
    assert_array_equal(puma3.model.armature, np.zeros(3))  # the robot given is not changed


@pytest.mark.parametrize("bad", [[0.1, 0.2], [0.1, -0.2, 0.3], [0.1, float("nan"), 0.3]])
def test_armature_needs_one_finite_non_negative_value_per_joint(puma3: Robot, bad) -> None:
    with pytest.raises(RobotModelError, match="armature"):
        with_armature(puma3, bad)


def test_friction_is_the_models_and_leaves_rnea_and_the_robot_given_alone(puma3: Robot) -> None:
    """``with_friction`` sets Pinocchio's ``friction`` (Coulomb) and ``damping`` (viscous);
    None keeps what was there; RNEA ignores both."""
    both = with_friction(puma3, [1.0, 2.0, 3.0], [0.1, 0.2, 0.3])
    assert_array_equal(both.model.friction, [1.0, 2.0, 3.0])
    assert_array_equal(both.model.damping, [0.1, 0.2, 0.3])
    coulomb_only = with_friction(both, [4.0, 5.0, 6.0], None)
    assert_array_equal(coulomb_only.model.damping, [0.1, 0.2, 0.3])
    assert_array_equal(puma3.model.friction, np.zeros(3))
    q, v, a = np.array([0.1, -0.4, 0.7]), np.array([0.3, -0.2, 0.5]), np.array([1.0, -2.0, 3.0])
    assert_array_equal(
        pin.rnea(both.model, both.model.createData(), q, v, a),
        pin.rnea(puma3.model, puma3.model.createData(), q, v, a),
    )


@pytest.mark.parametrize("bad", [[0.1, 0.2], [0.1, -0.2, 0.3], [0.1, float("inf"), 0.3]])
def test_friction_needs_one_finite_non_negative_value_per_joint(puma3: Robot, bad) -> None:
    with pytest.raises(RobotModelError, match="friction"):
        with_friction(puma3, bad, None)
    with pytest.raises(RobotModelError, match="damping"):
        with_friction(puma3, None, bad)


def test_a_urdfs_dynamics_is_not_the_controllers_friction() -> None:
    """example-robot-data's Panda declares ``<dynamics damping="0.003">`` for a simulator; the
    loaded model carries no friction until one is told (:func:`with_friction`)."""
    from apc_core.config_files import resolve_config_path
    from apc_core.robot import load_robot

    panda = load_robot(
        resolve_config_path("example-robot-data/panda_description/urdf/panda.urdf"),
        lock_joints=("panda_finger_joint1", "panda_finger_joint2"),
    )
    assert_array_equal(panda.model.damping, np.zeros(7))
    assert_array_equal(panda.model.friction, np.zeros(7))
