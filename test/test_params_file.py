"""``apc_params`` writes a parameter file for a URDF that loads back and starts the nodes."""

from __future__ import annotations

import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from numpy.testing import assert_allclose
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from apc_core.defaults import load
from apc_core.robot import Payload, with_payload
from apc_feedback.node import FeedbackNode
from apc_feedback.robot_node import RobotNode
from apc_feedforward.node import FeedforwardNode
from apc_lab.params_file import main
from apc_lab.reproduce import example_robot_urdf
from apc_lab.scenario import CONFIG_DIR
from apc_plant_sim.node import PlantNode

PANDA_FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]


def _arm(name: str) -> tuple[str, list[str]]:
    if name == "panda":
        return str(example_robot_urdf("panda_description/urdf/panda.urdf")), PANDA_FINGERS
    return str(CONFIG_DIR / name), []


@contextmanager
def _started(params_file: Path, *makers):
    """The nodes ``makers`` build, started from ``params_file`` in a context of their own."""
    context = rclpy.Context()
    rclpy.init(
        args=["--ros-args", "--params-file", str(params_file)],
        context=context,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    nodes = []
    try:
        for make in makers:
            nodes.append(make(context=context))
        yield nodes
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize("arm", ["puma560_3dof.urdf", "puma560.urdf", "panda"])
def test_the_written_file_loads_back_and_starts_the_nodes(arm, tmp_path, capsys):
    urdf, lock = _arm(arm)
    out = tmp_path / "robot.yaml"
    argv = ["--urdf", urdf, "--out", str(out)] + (["--lock-joints", *lock] if lock else [])
    assert main(argv) == 0
    told = capsys.readouterr().err.splitlines()
    # One line per derived default, naming the parameter that holds it, then the file.
    assert len(told) == 5 and "plant_node q_initial_deg = [" in told[0]
    assert told[-1] == f"apc_params: wrote {out}"

    robot, derived = load(urdf, lock_joints=lock)
    values = yaml.safe_load(out.read_text())
    shared = values["/**"]["ros__parameters"]
    assert shared["robot_description_path"] == urdf
    assert shared["inertia_error"] == list(derived.inertia_error)
    assert shared.get("lock_joints", []) == lock
    plant = values["plant_node"]["ros__parameters"]
    assert plant == {
        "q_initial_deg": list(derived.q_start_deg),
        "payload.frame": derived.payload_frame,
    }
    goal = values["feedforward_node"]["ros__parameters"]["move.goal_deg"]
    assert goal == list(derived.q_goal_deg)

    with _started(out, FeedforwardNode, FeedbackNode, PlantNode) as nodes:
        feedforward, feedback, plant_node = nodes
        for node in nodes:
            assert node.joint_names == robot.joint_names
        assert_allclose(np.rad2deg(plant_node.plant.q), derived.q_start_deg, atol=1e-9)
        assert plant_node.get_parameter("payload.frame").value == derived.payload_frame
        assert list(feedforward.get_parameter("move.goal_deg").value) == goal
        error = list(feedback.get_parameter("inertia_error").value)
        assert error == list(derived.inertia_error)


def test_an_existing_file_is_kept_unless_forced(tmp_path, capsys):
    out = tmp_path / "robot.yaml"
    out.write_text("mine\n")
    assert main(["--urdf", "puma560_3dof.urdf", "--out", str(out)]) == 2
    assert out.read_text() == "mine\n"
    assert "exists" in capsys.readouterr().err
    assert main(["--urdf", "puma560_3dof.urdf", "--out", str(out), "--force"]) == 0
    assert "plant_node:" in out.read_text()


def test_a_urdf_apc_cannot_use_stops_with_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "apc_lab.params_file", "--urdf", str(tmp_path / "no.urdf")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"apc_params: --urdf {tmp_path / 'no.urdf'}: URDF file not found: {tmp_path / 'no.urdf'}"
    ]


def test_without_out_the_file_goes_to_standard_output(capsys):
    assert main(["--urdf", "puma560_3dof.urdf"]) == 0
    text = capsys.readouterr().out
    assert yaml.safe_load(text)["plant_node"]["ros__parameters"]["payload.frame"] == (
        "wrist_center"
    )
    # A name in apc's config directory stays a name (the nodes find it there too).
    assert "robot_description_path: puma560_3dof.urdf" in text


def test_a_plant_given_only_the_urdf_starts_mid_range_with_the_payload_on_the_last_link():
    urdf, lock = _arm("panda")
    robot, derived = load(urdf, lock_joints=lock)
    context = rclpy.Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = PlantNode(
            context=context,
            parameter_overrides=[
                Parameter("robot_description_path", value=urdf),
                Parameter("lock_joints", value=lock),
                Parameter("payload.mass_kg", value=2.0),
            ],
        )
        # The Panda's zero pose is outside joint 4's range; the middle of each range is not.
        assert_allclose(np.rad2deg(node.plant.q), derived.q_start_deg, atol=1e-9)
        expected = with_payload(robot, Payload(2.0, frame="panda_hand")).model.inertias[7]
        assert node.arm.loaded.model.inertias[7].isApprox(expected)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize("arm", ["puma560_3dof.urdf", "panda"])
def test_the_robot_mode_file_starts_the_controllers_of_a_ros2_control_robot(arm, tmp_path):
    urdf, lock = _arm(arm)
    out = tmp_path / "robot.yaml"
    argv = ["--urdf", urdf, "--out", str(out), "--robot-mode"]
    assert main(argv + (["--lock-joints", *lock] if lock else [])) == 0
    values = yaml.safe_load(out.read_text())
    assert set(values) == {"/**", "robot_node"}
    assert "inertia_error" not in values["/**"]["ros__parameters"]  # none added to a real arm
    robot, _ = load(urdf, lock_joints=lock)
    assert values["robot_node"]["ros__parameters"]["command_joints"] == list(robot.joint_names)

    with _started(out, RobotNode) as (robot_node,):
        # autostart: configured and activated at construction
        assert robot_node.configure_error == "" and robot_node.loop is not None
        assert robot_node.get_parameter("preset").value == "recommended"
