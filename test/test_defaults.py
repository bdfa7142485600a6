"""Per-joint defaults from a URDF alone (apc_core.defaults): plain, no ROS graph."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from apc_core.defaults import (
    DERIVATION,
    MOVE_FRACTION,
    NO_RANGE_MOVE_RAD,
    last_link,
    load,
    start_and_goal,
)
from apc_core.robot import RobotModelError
from apc_lab.reproduce import example_robot_urdf
from apc_lab.scenario import CONFIG_DIR, Scenario, recommended_settings, run_offline

PANDA_FINGERS = ("panda_finger_joint1", "panda_finger_joint2")


def _panda() -> str:
    return str(example_robot_urdf("panda_description/urdf/panda.urdf"))


ARMS = {
    "puma3": (str(CONFIG_DIR / "puma560_3dof.urdf"), ()),
    "puma6": (str(CONFIG_DIR / "puma560.urdf"), ()),
    "panda": (None, PANDA_FINGERS),
}


def _load(arm: str):
    urdf, lock = ARMS[arm]
    return load(urdf or _panda(), lock_joints=lock)


def test_puma3_defaults():
    _, d = _load("puma3")
    assert d.joint_names == ("joint_1", "joint_2", "joint_3")
    # Limits +-160, [-45, 225], [-225, 45] deg: middles 0, 90, -90.
    assert_allclose(d.q_start_deg, [0.0, 90.0, -90.0], atol=1e-4)
    span = MOVE_FRACTION * np.array([320.0, 270.0, 270.0])
    assert_allclose(d.q_goal_deg, np.array([0.0, 90.0, -90.0]) + span * [1, -1, 1], atol=1e-3)
    assert d.inertia_error == (0.1, -0.1, 0.1)
    assert d.payload_frame == "wrist_center"


@pytest.mark.parametrize(
    "arm, n, frame", [("puma6", 6, "wrist_center"), ("panda", 7, "panda_hand")]
)
def test_defaults_have_one_value_per_joint_inside_the_limits(arm, n, frame):
    robot, d = _load(arm)
    assert robot.n_joints == n
    assert len(d.q_start_deg) == len(d.q_goal_deg) == len(d.inertia_error) == n
    lower, upper = (np.rad2deg(v) for v in robot.position_limits)
    for q in (d.q_start_deg, d.q_goal_deg):
        assert np.all(lower < np.array(q)) and np.all(np.array(q) < upper)
    assert_allclose(d.inertia_error, [0.1 if i % 2 == 0 else -0.1 for i in range(n)])
    assert d.payload_frame == frame
    assert robot.model.existFrame(d.payload_frame)


def test_a_joint_without_a_usable_range_starts_at_zero_and_moves_a_stated_amount():
    start, goal = start_and_goal([-1.0, 0.0, -np.inf], [3.0, 0.0, np.inf])
    assert_allclose(start, [1.0, 0.0, 0.0])
    assert_allclose(goal, [1.0 + MOVE_FRACTION * 4.0, -NO_RANGE_MOVE_RAD, NO_RANGE_MOVE_RAD])


@pytest.mark.parametrize("fraction", [0.0, 0.6])
def test_a_move_that_would_leave_the_range_is_refused(fraction):
    with pytest.raises(ValueError, match="fraction"):
        start_and_goal([0.0], [1.0], fraction)


_CHAIN = """<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/><link name="d"/><link name="e"/>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="f1" type="fixed"><parent link="b"/><child link="c"/></joint>
  {tail}
</robot>"""


@pytest.mark.parametrize(
    "tail, expected",
    [
        ("", "c"),  # fixed chain ends
        ('<joint name="f2" type="fixed"><parent link="c"/><child link="d"/></joint>', "d"),
        (  # a branch stops the walk
            '<joint name="f2" type="fixed"><parent link="c"/><child link="d"/></joint>'
            '<joint name="f3" type="fixed"><parent link="c"/><child link="e"/></joint>',
            "c",
        ),
        (  # a moving joint (e.g. a locked finger) stops it too
            '<joint name="p" type="prismatic"><parent link="c"/><child link="d"/>'
            '<limit lower="0" upper="1" effort="1" velocity="1"/></joint>',
            "c",
        ),
    ],
)
def test_last_link_follows_fixed_joints_up_to_a_branch(tail, expected):
    assert last_link(_CHAIN.format(tail=tail), "j1") == expected


def test_last_link_of_an_unknown_joint_is_an_error():
    with pytest.raises(RobotModelError, match="nope"):
        last_link(_CHAIN.format(tail=""), "nope")


def test_each_default_is_described_in_one_line_with_its_parameter_name():
    _, d = _load("puma3")
    for field in DERIVATION:
        line = d.describe(field, f"param.{field}")
        assert "\n" not in line and line.startswith(f"param.{field} = ")
        assert DERIVATION[field] in line
    assert "[0, 90, -90]" in d.describe("q_start_deg")
    with pytest.raises(KeyError):
        d.describe("gravity")


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_the_derived_move_is_tracked_with_the_recommended_preset(arm):
    """The defaults work: +-10 % inertia error and 5 lb on the last link, the recommended
    adaptive preset keeps every joint within 1 deg of the plan, without saturating."""
    urdf, lock = ARMS[arm]
    _, d = _load(arm)
    scenario = Scenario(
        urdf=urdf or _panda(),
        lock_joints=lock,
        payload_kg=2.268,
        payload_frame=d.payload_frame,
        inertia_error=d.inertia_error,
        q_start_deg=d.q_start_deg,
        q_goal_deg=d.q_goal_deg,
    )
    result = run_offline(scenario, "adaptive", recommended_settings())
    error_deg = np.rad2deg(np.abs(result.q - result.q_d))
    assert error_deg.max() < 1.0
    assert not np.any(result.saturated)


def test_experiment_with_a_urdf_derives_what_is_not_given_and_prints_each(tmp_path, capsys):
    from apc_lab.experiment import build_parser, spec_from_args

    urdf = str(CONFIG_DIR / "puma560.urdf")
    _, d = load(urdf)
    spec = spec_from_args(build_parser().parse_args(["--urdf", urdf]))
    sc = spec.scenario
    assert (sc.q_start_deg, sc.q_goal_deg) == (d.q_start_deg, d.q_goal_deg)
    assert (sc.inertia_error, sc.payload_frame) == (d.inertia_error, d.payload_frame)
    told = capsys.readouterr().err.splitlines()
    assert told == [f"experiment: {d.describe(field)}" for field in DERIVATION]
    # A scenario file naming the URDF keeps what it gives and derives the rest.
    given = tmp_path / "move.yaml"
    given.write_text(f"urdf: {urdf}\nq_goal_deg: [10, 80, -80, 30, 0, 0]\n")
    sc = spec_from_args(build_parser().parse_args(["--scenario", str(given)])).scenario
    assert sc.q_goal_deg == (10, 80, -80, 30, 0, 0) and sc.q_start_deg == d.q_start_deg
    assert len(capsys.readouterr().err.splitlines()) == 3
