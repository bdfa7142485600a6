"""apc_core.robot: the PUMA URDFs against the DH table, payload, inertia error, loader guards.

The forward kinematics are checked against a standard-DH product written here from
``config/reference/puma560.json`` alone, so a mistake in ``tools/make_puma_urdf.py`` cannot hide
behind itself. Model edits are checked with the parallel-axis theorem in plain numpy.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from apc_core.config_files import config_dir
from apc_core.robot import (
    PAPER_MAX_PAYLOAD_KG,
    Payload,
    Robot,
    RobotModelError,
    load_robot,
    with_inertia_error,
    with_payload,
)

CONFIG = config_dir()
URDF_3 = CONFIG / "puma560_3dof.urdf"
URDF_6 = CONFIG / "puma560.urdf"
REFERENCE = json.loads((CONFIG / "reference" / "puma560.json").read_text())
DH_ROWS = REFERENCE["joints"]
G = 9.8062  # m/s^2, the paper's gravity and the loader's default
D4 = 0.4318  # m, wrist centre along z3
A3 = 0.0203  # m, elbow offset along x3
D3 = 0.15005  # m, shoulder offset along z2

# The paper's move (its angles, deg) and the DH angles they map to, (q1, -q2, -q3).
PAPER_START = (0.0, 45.0, 45.0)
PAPER_STRETCHED = (45.0, 0.0, 90.0)
PAPER_FINAL = (90.0, -45.0, 135.0)
ARM_FRAMES = ("dh_frame_1", "dh_frame_2", "dh_frame_3", "wrist_center")


def paper_to_dh(paper_deg) -> np.ndarray:
    """The paper's (q1, q2, q3) in degrees -> DH angles (rad) of our URDFs."""
    q1, q2, q3 = paper_deg
    return np.deg2rad([q1, -q2, -q3])


# ----------------------------------------------------------------------------------- helpers
def dh_transform(a: float, d: float, alpha: float, theta: float) -> np.ndarray:
    """Standard DH: Rz(theta) Tz(d) Tx(a) Rx(alpha) as a 4x4 homogeneous matrix."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0.0, sa, ca, d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_frames(q: np.ndarray) -> list[np.ndarray]:
    """Base -> DH frame i (i = 1..len(q)) from the reference table."""
    out, T = [], np.eye(4)
    for row, qi in zip(DH_ROWS, q, strict=False):
        T = T @ dh_transform(row["a_m"], row["d_m"], row["alpha_rad"], qi)
        out.append(T)
    return out


def frame_pose(robot: Robot, q: np.ndarray, name: str) -> pin.SE3:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(name)].copy()


def frame_position(robot: Robot, q: np.ndarray, name: str) -> np.ndarray:
    return frame_pose(robot, q, name).translation.copy()


def gravity_torque(robot: Robot, q: np.ndarray) -> np.ndarray:
    """c(q): the torque that holds the arm still at q (N m)."""
    return pin.computeGeneralizedGravity(robot.model, robot.model.createData(), q).copy()


def snapshot(model: pin.Model) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(mass, lever, rotational inertia) of every body, as copies."""
    return [(float(b.mass), b.lever.copy(), b.inertia.copy()) for b in model.inertias]


def assert_same_bodies(a: list, b: list) -> None:
    assert len(a) == len(b)
    for (ma, ca, ia), (mb, cb, ib) in zip(a, b, strict=True):
        assert ma == mb
        assert_array_equal(ca, cb)
        assert_array_equal(ia, ib)


def parallel_axis(inertia_c: np.ndarray, mass: float, r: np.ndarray) -> np.ndarray:
    """Rotational inertia about a point at -r from the COM: I_c + m (|r|^2 1 - r r^T)."""
    return inertia_c + mass * (float(r @ r) * np.eye(3) - np.outer(r, r))


@pytest.fixture(scope="module")
def puma3() -> Robot:
    return load_robot(URDF_3)


@pytest.fixture(scope="module")
def puma6() -> Robot:
    return load_robot(URDF_6)


@pytest.fixture(params=["3dof", "6dof"])
def puma(request, puma3, puma6) -> Robot:
    return puma3 if request.param == "3dof" else puma6


# --------------------------------------------------------------------- forward kinematics
def test_every_dh_frame_matches_the_standard_dh_product(puma: Robot) -> None:
    """Each fixed frame dh_frame_i is the DH product of rows 1..i (rotation and translation)."""
    rng = np.random.default_rng(560)
    n = puma.n_joints
    for _ in range(6):
        q = rng.uniform(-math.pi, math.pi, n)  # rad
        expected = dh_frames(q)
        for i in range(1, n + 1):
            pose = frame_pose(puma, q, f"dh_frame_{i}")
            assert_allclose(pose.rotation, expected[i - 1][:3, :3], rtol=0, atol=1e-9)
            assert_allclose(pose.translation, expected[i - 1][:3, 3], rtol=0, atol=1e-9)


def test_wrist_center_is_d4_along_z3(puma3: Robot, puma6: Robot) -> None:
    """3-dof: wrist_center = DH frame 3 * (0, 0, d4); 6-dof: it is DH frame 6 (a4..d6 = 0)."""
    rng = np.random.default_rng(4318)
    for _ in range(6):
        q = rng.uniform(-math.pi, math.pi, 6)
        T3 = dh_frames(q[:3])[2]
        expected = T3 @ np.array([0.0, 0.0, D4, 1.0])
        assert_allclose(frame_position(puma3, q[:3], "wrist_center"), expected[:3], atol=1e-9)
        assert_allclose(frame_position(puma6, q, "wrist_center"), expected[:3], atol=1e-9)
        T6 = dh_frames(q)[5]
        assert_allclose(frame_pose(puma6, q, "wrist_center").homogeneous, T6, atol=1e-9)


def test_joint_order_and_effort_limits_of_the_pumas(puma3: Robot, puma6: Robot) -> None:
    """Joints come base to tip; effort limits are the generator's (N m)."""
    assert puma3.joint_names == ("joint_1", "joint_2", "joint_3")
    assert puma6.joint_names == tuple(f"joint_{i}" for i in range(1, 7))
    assert_array_equal(puma3.effort_limit, [97.6, 186.4, 89.4])
    assert_array_equal(puma6.effort_limit, [97.6, 186.4, 89.4, 24.2, 20.1, 21.3])
    lo, hi = puma6.position_limits
    assert_allclose(lo, [r["joint_limits_rad"][0] for r in DH_ROWS])
    assert_allclose(hi, [r["joint_limits_rad"][1] for r in DH_ROWS])


# ------------------------------------------------------------------ the paper's poses
# What the forward kinematics says about the paper's angles, mapped to DH as (q1, -q2, -q3):
# - Along the whole planned move DH q2 + q3 = -90 deg, so z3 (the forearm, elbow-to-wrist
#   axis) stays horizontal; only the upper arm tilts: 45 deg *below* horizontal at the start
#   (paper (0, 45, 45) = DH (0, -45, -45)), horizontal at 0.5 s, 45 deg above at the end.
# - At the stretched pose (paper (45, 0, 90) = DH (45, 0, -90)) the upper arm x2 and the
#   forearm z3 are parallel, horizontal and point along azimuth q1 = 45 deg: "in line". The
#   forearm axis is not collinear with the upper arm: it is shifted sideways by d3 = 0.15005 m
#   along the horizontal joint-2/3 axis and down by a3 = 0.0203 m (x3 points straight down), so
#   the wrist centre sits 0.0203 m below the shoulder (z = 0.6515 m vs 0.67183 m), at a
#   horizontal reach of 0.8636 m (a2 + d4) from the joint-2 axis.
# - The wrist centre is at z = 0.3462 m at the start (0.305 m lower than stretched) and
#   0.9569 m at the end.
# - Gravity torque on joint 2 along the move peaks at s = 0.4825 (DH q2 = -1.6 deg, because
#   link 2's and link 3's centres of mass sit slightly off the arm lines), only 0.03 % above
#   its value at s = 0.5; on a grid of 0.05 s, 0.5 s is the maximum, as the paper says.
#   Gravity torque on joint 3 is constant along the move (the forearm stays horizontal).
def test_stretched_pose_puts_upper_arm_and_forearm_in_line(puma3: Robot) -> None:
    """Paper (45, 0, 90) deg = DH (45, 0, -90): upper arm and forearm parallel and horizontal."""
    q = paper_to_dh(PAPER_STRETCHED)
    p1, p2, p3, wc = (frame_position(puma3, q, n) for n in ARM_FRAMES)
    upper, forearm = p2 - p1, wc - p3  # m
    assert_allclose([upper[2], forearm[2]], 0.0, atol=1e-9)  # both horizontal
    assert_allclose(np.linalg.norm(upper), DH_ROWS[1]["a_m"], atol=1e-12)
    assert_allclose(np.linalg.norm(forearm), D4, atol=1e-12)
    # Same horizontal direction, along azimuth q1 = 45 deg.
    azimuth = np.degrees([math.atan2(upper[1], upper[0]), math.atan2(forearm[1], forearm[0])])
    assert_allclose(azimuth, [45.0, 45.0], atol=1e-7)
    # The elbow offsets: d3 along the horizontal joint axis z2, a3 straight down along x3.
    z2 = frame_pose(puma3, q, "dh_frame_2").rotation[:, 2]
    x3 = frame_pose(puma3, q, "dh_frame_3").rotation[:, 0]
    assert_allclose(x3, [0.0, 0.0, -1.0], atol=1e-9)
    assert abs(z2[2]) < 1e-9 and abs(z2 @ upper) < 1e-9
    assert_allclose(p3 - p2, D3 * z2 + A3 * x3, atol=1e-9)
    # The whole horizontal-projected arm (shoulder -> wrist) is in line within the d3 offset.
    reach = (wc - p1)[:2] - D3 * z2[:2]
    assert_allclose(math.degrees(math.atan2(reach[1], reach[0])), 45.0, atol=1e-7)
    assert_allclose(np.linalg.norm(reach), DH_ROWS[1]["a_m"] + D4, atol=1e-9)
    assert_allclose(wc[2], p1[2] - A3, atol=1e-9)


def test_paper_start_and_final_poses(puma3: Robot) -> None:
    """Start: upper arm 45 deg down, forearm level, wrist lower than stretched; final: 45 deg up."""
    heights = {}
    for name, paper, tilt in (("start", PAPER_START, -45.0), ("final", PAPER_FINAL, 45.0)):
        q = paper_to_dh(paper)
        p1, p2, p3, wc = (frame_position(puma3, q, n) for n in ARM_FRAMES)
        upper, forearm = p2 - p1, wc - p3
        elevation = math.degrees(math.asin(upper[2] / np.linalg.norm(upper)))
        assert_allclose(elevation, tilt, atol=1e-7)
        assert abs(forearm[2]) < 1e-9
        heights[name] = wc[2]
    heights["stretched"] = frame_position(puma3, paper_to_dh(PAPER_STRETCHED), "wrist_center")[2]
    assert heights["start"] < heights["stretched"] < heights["final"]
    # Only the upper arm tilts, so each half of the move lifts the wrist by a2 sin 45 deg.
    rise = DH_ROWS[1]["a_m"] * math.sin(math.pi / 4)  # 0.305 m
    assert_allclose(heights["stretched"] - heights["start"], rise, atol=1e-9)
    assert_allclose(heights["final"] - heights["stretched"], rise, atol=1e-9)


def _move(s: float, n: int) -> np.ndarray:
    """Joint-interpolated pose at fraction s of the paper's move (DH, rad), wrist at zero."""
    start, final = paper_to_dh(PAPER_START), paper_to_dh(PAPER_FINAL)
    q = np.zeros(n)
    q[:3] = start + s * (final - start)
    return q


def test_joint_2_gravity_torque_peaks_at_the_stretched_pose(puma: Robot) -> None:
    """On a 0.05 s grid along the paper's move, c_2 is largest at 0.5 s; c_3 stays constant."""
    s_grid = np.linspace(0.0, 1.0, 21)
    c = np.array([gravity_torque(puma, _move(s, puma.n_joints)) for s in s_grid])
    assert int(np.argmax(c[:, 1])) == 10
    assert_allclose(_move(0.5, 3)[:3], paper_to_dh(PAPER_STRETCHED), atol=1e-15)
    assert_allclose(c[:, 2], c[10, 2], rtol=1e-9)  # forearm level throughout
    # The exact peak (fine grid) is within 0.05 % of the value at 0.5 s.
    fine = np.linspace(0.4, 0.6, 201)
    peak = max(gravity_torque(puma, _move(s, puma.n_joints))[1] for s in fine)
    assert c[10, 1] <= peak < c[10, 1] * 1.0005
    assert 40.0 < c[10, 1] < 50.0  # N m: about 24 kg of arm at ~0.2 m mean lever


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


# ------------------------------------------------------------------------------- loading
def two_link(
    *,
    elbow_type: str = "revolute",
    elbow_limit: str = '<limit lower="-3" upper="3" effort="20" velocity="2"/>',
    fore_mass: str = "1.5",
    fore_ixx: str = "0.012",
    fore_origin: str = 'xyz="0 0 -0.15"',
    elbow_axis: str = "0 1 0",
    extra: str = "",
) -> str:
    """A two-joint arm (shoulder, elbow about y) as URDF text, with parts to break."""
    return f"""<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="50" velocity="2"/>
  </joint>
  <link name="upper">
    <inertial><origin xyz="0 0 -0.2"/><mass value="2.0"/>
      <inertia ixx="0.03" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.001"/></inertial>
  </link>
  <joint name="elbow" type="{elbow_type}">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0 0 -0.4" rpy="0 0 0"/><axis xyz="{elbow_axis}"/>
    {elbow_limit}
  </joint>
  <link name="fore">
    <inertial><origin {fore_origin}/><mass value="{fore_mass}"/>
      <inertia ixx="{fore_ixx}" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.0005"/></inertial>
  </link>
  {extra}
</robot>
"""


BRANCH = """
  <joint name="thumb" type="revolute">
    <parent link="upper"/><child link="thumb_link"/>
    <origin xyz="0.1 0 -0.2" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="5" velocity="1"/>
  </joint>
  <link name="thumb_link">
    <inertial><origin xyz="0.05 0 0"/><mass value="0.3"/>
      <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial>
  </link>
"""


def test_loads_from_string_and_from_path(tmp_path: Path) -> None:
    """XML text and a file (str or Path) give the same model; names and limits are read."""
    text = two_link()
    path = tmp_path / "two_link.urdf"
    path.write_text(text)
    robots = [load_robot(text), load_robot(path), load_robot(str(path))]
    assert robots[0].source == "<string>"
    assert robots[1].source == robots[2].source == str(path)
    for r in robots:
        assert r.joint_names == ("shoulder", "elbow")  # URDF order, not alphabetical
        assert r.n_joints == 2
        assert_array_equal(r.effort_limit, [50.0, 20.0])
        assert_array_equal(r.position_limits[0], [-3.0, -3.0])
        assert_array_equal(r.position_limits[1], [3.0, 3.0])
        assert_same_bodies(snapshot(r.model), snapshot(robots[0].model))
    assert_allclose([b.mass for b in robots[0].model.inertias], [0.0, 2.0, 1.5])


def test_puma_from_string_equals_puma_from_file(puma3: Robot) -> None:
    r = load_robot(URDF_3.read_text())
    assert_same_bodies(snapshot(r.model), snapshot(puma3.model))


@pytest.mark.parametrize("g", [0.0, 9.81, G])
def test_gravity_parameter(g: float) -> None:
    """gravity=g sets model.gravity.linear to (0, 0, -g); the default is 9.8062."""
    r = load_robot(two_link(), gravity=g)
    assert_array_equal(r.model.gravity.linear, [0.0, 0.0, -g])
    assert_array_equal(r.model.gravity.angular, [0.0, 0.0, 0.0])


def test_default_gravity_is_the_papers(puma3: Robot) -> None:
    assert_array_equal(puma3.model.gravity.linear, [0.0, 0.0, -G])
    with pytest.raises(RobotModelError, match="gravity"):
        load_robot(two_link(), gravity=-9.8)
    with pytest.raises(RobotModelError, match="gravity"):
        load_robot(two_link(), gravity=float("nan"))


def test_pinocchio_alone_drops_an_unparsable_inertia() -> None:
    """Why the loader checks numbers itself: urdfdom zeroes a bad <inertia> and carries on."""
    model = pin.buildModelFromXML(two_link(fore_ixx="0.01x"))
    assert_array_equal(model.inertias[2].inertia, np.zeros((3, 3)))  # silently massless-ish


LOADER_ERRORS = {
    "missing file": ("/no/such/dir/arm.urdf", "not found"),
    "malformed xml": ("<robot name='x'><link name='a'></robot>", "well-formed"),
    "wrong root": ("<model name='x'/>", "<robot>"),
    "continuous joint": (two_link(elbow_type="continuous"), "continuous"),
    "floating joint": (two_link(elbow_type="floating", elbow_limit=""), "floating"),
    "planar joint": (two_link(elbow_type="planar"), "planar"),
    "non-numeric inertia": (two_link(fore_ixx="0.01x"), "ixx"),
    "empty inertia": (two_link(fore_ixx=""), "ixx"),
    "nan inertia": (two_link(fore_ixx="nan"), "ixx"),
    "negative mass": (two_link(fore_mass="-1.5"), "negative mass"),
    "non-numeric mass": (two_link(fore_mass="heavy"), "mass"),
    "missing limit": (two_link(elbow_limit=""), "'elbow': missing <limit>"),
    "missing effort": (
        two_link(elbow_limit='<limit lower="-3" upper="3" velocity="2"/>'),
        "effort",
    ),
    "zero effort": (
        two_link(elbow_limit='<limit lower="-3" upper="3" effort="0" velocity="2"/>'),
        "effort limit",
    ),
    "branching tree": (two_link(extra=BRANCH), "serial chain"),
}


@pytest.mark.parametrize(("urdf", "message"), LOADER_ERRORS.values(), ids=LOADER_ERRORS.keys())
def test_loader_rejects(urdf: str, message: str) -> None:
    """Each unusable URDF raises RobotModelError whose message names the problem."""
    with pytest.raises(RobotModelError, match=message):
        load_robot(urdf)


# URDFs that urdfdom/Pinocchio would turn into a silently wrong model (found while writing
# these tests, fixed in robot.py's _check_urdf_xml): a non-numeric or short inertial origin
# (urdfdom drops the whole <inertial>: mass 0), a zero joint axis (singular D(q)), and an
# inertia tensor that is not positive semidefinite (indefinite D(q)).
SILENTLY_ACCEPTED = [
    pytest.param(
        two_link(fore_origin='xyz="0 0 -0.15x"'),
        "origin",
        id="non-numeric inertial origin",
    ),
    pytest.param(
        two_link(fore_origin='xyz="0 -0.15"'),
        "origin",
        id="two-number inertial origin",
    ),
    pytest.param(
        two_link(elbow_axis="0 0 0"),
        "axis",
        id="zero joint axis",
    ),
    pytest.param(
        two_link(fore_ixx="-1"),
        "inertia",
        id="negative principal inertia",
    ),
]


@pytest.mark.parametrize(("urdf", "message"), SILENTLY_ACCEPTED)
def test_loader_rejects_silently_wrong_models(urdf: str, message: str) -> None:
    """URDFs that Pinocchio accepts but turns into a wrong model must raise RobotModelError."""
    try:
        robot = load_robot(urdf)
    except RobotModelError as exc:
        assert message in str(exc).lower()
        return
    masses = [float(b.mass) for b in robot.model.inertias]
    raise AssertionError(f"accepted; body masses {masses}")


def test_no_moving_joint_is_rejected() -> None:
    fixed = two_link(elbow_type="fixed").replace(
        '<joint name="shoulder" type="revolute">', '<joint name="shoulder" type="fixed">'
    )
    with pytest.raises(RobotModelError, match="no moving joint"):
        load_robot(fixed)


def test_branch_is_accepted_when_one_side_is_locked() -> None:
    """Locking the extra branch leaves a serial chain whose mass includes the locked link."""
    r = load_robot(two_link(extra=BRANCH), lock_joints=["thumb"], lock_positions={"thumb": 0.5})
    assert r.joint_names == ("shoulder", "elbow")
    assert_array_equal(r.effort_limit, [50.0, 20.0])
    masses = [b.mass for b in r.model.inertias]
    assert_allclose(masses, [0.0, 2.3, 1.5], rtol=1e-12)
    # The locked thumb's COM at 0.5 rad about z: (0.1, 0, -0.2) + Rz(0.5) (0.05, 0, 0).
    thumb_com = np.array([0.1 + 0.05 * math.cos(0.5), 0.05 * math.sin(0.5), -0.2])
    expected_com = (2.0 * np.array([0.0, 0.0, -0.2]) + 0.3 * thumb_com) / 2.3
    assert_allclose(r.model.inertias[1].lever, expected_com, atol=1e-12)


def test_lock_joints_with_unknown_name() -> None:
    with pytest.raises(RobotModelError, match="no joint named 'pinky'"):
        load_robot(two_link(extra=BRANCH), lock_joints=["thumb", "pinky"])


def test_keep_joints_locks_every_other_joint() -> None:
    """The arm a recording moved: its joints kept, the rest (here the thumb) locked at 0."""
    kept = load_robot(two_link(extra=BRANCH), keep_joints=["shoulder", "elbow"])
    locked = load_robot(two_link(extra=BRANCH), lock_joints=["thumb"])
    assert kept.joint_names == locked.joint_names == ("shoulder", "elbow")
    assert_allclose(kept.model.inertias[1].lever, locked.model.inertias[1].lever, atol=0)
    with pytest.raises(RobotModelError, match=r"keep_joints: no joint named \['wrist'\]"):
        load_robot(two_link(extra=BRANCH), keep_joints=["shoulder", "wrist"])
