"""apc_core.robot, forward kinematics of the PUMA URDFs: every DH frame, the wrist centre, joint
order and limits, and what the paper's poses are (the stretched pose in line, the start and final
tilts, joint 2's gravity torque peaking at the stretched pose).

The forward kinematics are checked against a standard-DH product written from
``config/reference/puma560.json`` alone, so a mistake in ``tools/make_puma_urdf.py`` cannot hide
behind itself.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal
from robot_helpers import D4, DH_ROWS, dh_frames, frame_pose, frame_position, gravity_torque

from apc_core.robot import Robot

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
