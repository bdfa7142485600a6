"""apc_core.robot, loading a URDF: from text or a path, gravity, locked and kept joints, and the
loader's guards, each unusable or silently wrong URDF raising RobotModelError that names the
problem.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from robot_helpers import URDF_3, G, assert_same_bodies, snapshot

from apc_core.robot import Robot, RobotModelError, load_robot


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
