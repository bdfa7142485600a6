"""Every parameter override the README and docs/ show beside a parameter file takes effect.

ROS applies a plain ``-p name:=value`` to every node (``/**``), and a node's own section in a
parameter file wins over it, so an override the README documents can be silently lost. Each
command in their shell blocks that gives ``--params-file`` and ``-p`` is started here as
written (its nodes built in-process with exactly its ``--ros-args``, from the repository root),
and every override is read back from the node it names, or from each node of the executable
that declares it.
"""

from __future__ import annotations

import itertools
import os
import re
import shlex
from pathlib import Path
from typing import Any

import pytest
import rclpy
import yaml

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[1]


def _node_classes() -> dict[str, type]:
    from apc_feedback.node import FeedbackNode
    from apc_feedback.robot_node import RobotNode
    from apc_feedforward.node import FeedforwardNode
    from apc_plant_sim.node import PlantNode
    from apc_plant_sim.robot_sim import RobotSimNode

    return {
        "feedback_node": FeedbackNode,
        "robot_node": RobotNode,
        "feedforward_node": FeedforwardNode,
        "plant_node": PlantNode,
        "robot_sim": RobotSimNode,
    }


#: The nodes each executable starts (``composed`` composes the three, ``composed --controllers`` the
#: controllers beside a plant of their own).
EXECUTABLE_NODES: dict[str, tuple[str, ...]] = {
    "feedback_node": ("feedback_node",),
    "robot_node": ("robot_node",),
    "feedforward_node": ("feedforward_node",),
    "plant_node": ("plant_node",),
    "robot_sim": ("robot_sim",),
    "composed": ("feedforward_node", "feedback_node", "plant_node"),
    "composed --controllers": ("feedforward_node", "feedback_node"),
}


def documented_overrides() -> list[tuple[str, list[str]]]:
    """(executable, its ``--ros-args``) of each shell command of the README and docs/ with a
    parameter file and a ``-p`` override."""
    text = "\n".join(p.read_text() for p in (REPO / "README.md", *sorted(REPO.glob("docs/*.md"))))
    commands = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if "--params-file" not in line or " -p " not in line:
                continue
            words = shlex.split(line)
            if words[:2] == ["ros2", "run"]:
                words = words[3:]
            ros_args = words.index("--ros-args")
            executable = " ".join(words[:ros_args])
            commands.append((executable, words[ros_args:]))
    return commands


def _overrides(ros_args: list[str]) -> list[tuple[str | None, str, Any]]:
    """(node or None for every node, parameter, value) of each ``-p``."""
    out = []
    for flag, item in itertools.pairwise(ros_args):
        if flag != "-p":
            continue
        name, text = item.split(":=", 1)
        node, _, name = name.rpartition(":")
        out.append((node or None, name, yaml.safe_load(text)))
    return out


def _start(node_name: str, ros_args: list[str]) -> tuple[Any, Any]:
    context = rclpy.Context()
    rclpy.init(args=["test", *ros_args], context=context)
    try:
        return _node_classes()[node_name](context=context), context
    except BaseException:
        rclpy.try_shutdown(context=context)
        raise


COMMANDS = documented_overrides()


def test_the_readme_documents_overrides_beside_parameter_files():
    executables = {executable for executable, _ in COMMANDS}
    assert {"feedback_node", "composed", "robot_node"} <= executables


@pytest.mark.parametrize(
    ("executable", "ros_args"), COMMANDS, ids=[" ".join(c[1][-2:]) for c in COMMANDS]
)
def test_each_documented_override_takes_effect(executable, ros_args, monkeypatch):
    monkeypatch.chdir(REPO)  # the README's paths are the repository's
    monkeypatch.setenv("ROS_DOMAIN_ID", str(os.getpid() % 100 + 100))
    nodes = EXECUTABLE_NODES[executable]
    checked = 0
    for target, name, value in _overrides(ros_args):
        for node_name in nodes if target is None else (target,):
            assert node_name in nodes, f"{executable} starts no {node_name}"
            node, context = _start(node_name, ros_args)
            try:
                if target is None and not node.has_parameter(name):
                    continue  # a wildcard a node does not declare
                assert node.get_parameter(name).value == value, (executable, node_name, name)
                checked += 1
            finally:
                node.destroy_node()
                rclpy.try_shutdown(context=context)
    assert checked, f"no node of {executable} took {ros_args}"
