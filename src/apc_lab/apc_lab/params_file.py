"""``apc_params``: write the ROS parameter file of apc's nodes for a given URDF, to edit.

    apc_params --urdf my_arm.urdf --out my_arm.yaml [--lock-joints finger_1 finger_2]
    composed --ros-args --params-file my_arm.yaml
    apc_params --urdf my_arm.urdf --out my_robot.yaml --robot-mode     # a ros2_control robot
    robot_node --ros-args --params-file my_robot.yaml

The file has one section per node (``/**`` for what all share). Active lines are what this
URDF needs: where it is, the joints to lock, and the per-joint defaults derived from it
(:mod:`apc_core.defaults`: start at the middle of each joint's range, a first move inside it,
the paper's +-10 % inertia error pattern for the simulated controllers' model, the payload on
the last link; with ``--robot-mode``, ``robot_node`` alone, started at once with
``command_joints`` in the URDF's order, and no simulated model error).
Every other parameter of each node follows as a comment with its default and
meaning, so the file shows all there is to set and the nodes keep their own defaults until a
line is uncommented. The file starts the nodes as written (``test/test_params_file.py``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from apc_core.config_files import resolve_config_path
from apc_core.defaults import DERIVATION, ArmDefaults, load
from apc_core.params import Param
from apc_core.robot import RobotModelError
from apc_core.robot_params import ROBOT_PARAMS
from apc_feedback.node import PARAMS as FEEDBACK_PARAMS
from apc_feedback.robot_node import PARAMS as ROBOT_NODE_PARAMS
from apc_feedforward.node import PARAMS as FEEDFORWARD_PARAMS
from apc_plant_sim.node import PARAMS as PLANT_PARAMS

#: Parameters every node declares, written once in the ``/**`` section.
SHARED = frozenset(p.name for p in ROBOT_PARAMS) | {"inertia_error"}
#: The derived defaults the file sets, by field, and the parameter that holds each.
WRITTEN = {
    "q_start_deg": "plant_node q_initial_deg",
    "q_goal_deg": "feedforward_node move.goal_deg",
    "inertia_error": "inertia_error",
    "payload_frame": "plant_node payload.frame",
}
#: Of those, what only a simulation uses (not written with --robot-mode).
SIMULATION_ONLY = frozenset(WRITTEN)


def _value(value: Any) -> str:
    """``value`` as one line of YAML (flow style, as ROS's parameter-file parser reads it)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6).strip()
    return text.removesuffix("\n...").removesuffix("...").strip()


def _section(
    name: str, params: Iterable[Param], active: Mapping[str, tuple[Any, str]], skip: Iterable[str]
) -> list[str]:
    """One node's section: ``active`` lines (value, why) first, then the rest commented out."""
    lines = [f"{name}:", "  ros__parameters:"]
    rows = {p.name: p for p in params if p.name not in set(skip)}
    if not active and rows:
        # ROS's parser refuses an empty ros__parameters: the first parameter is written as is.
        first = next(iter(rows.values()))
        active = {first.name: (first.default, first.description)}
    for key, (value, why) in active.items():
        lines.append(f"    {key}: {_value(value)}    # {why}")
    for key, p in rows.items():
        if key not in active:
            lines.append(f"    # {key}: {_value(p.default)}    # {p.description}")
    return lines


def render(
    urdf: str,
    defaults: ArmDefaults,
    lock_joints: Sequence[str] = (),
    source: str = "",
    robot_mode: bool = False,
) -> str:
    """The parameter file's text for the arm of ``urdf`` with its derived ``defaults``: apc's
    simulated arm (plant, feedforward, feedback), or with ``robot_mode`` the controllers of a
    ros2_control robot (robot_node)."""
    shared: dict[str, tuple[Any, str]] = {"robot_description_path": (urdf, "the arm")}
    if not robot_mode:  # a real arm's model error is whatever it is: none is added
        shared["inertia_error"] = (
            list(defaults.inertia_error),
            f"{DERIVATION['inertia_error']}; simulation only, [] on a real arm",
        )
    if lock_joints:
        shared["lock_joints"] = (list(lock_joints), "frozen at 0 so the rest is a serial chain")
    shared_rows = [p for p in (*ROBOT_PARAMS, *FEEDBACK_PARAMS) if p.name in SHARED]
    joints = ", ".join(defaults.joint_names)
    header = [
        f"# apc parameters for {source or urdf}, written by apc_params; edit freely.",
        f"# Joints, in the order of every per-joint list: {joints}.",
        "# Active lines come from the URDF; commented ones are each node's default.",
        "# A key in a node's section is overridden by naming the node: -p <node>:<key>:=<value>.",
    ]
    body = [*_section("/**", _unique(shared_rows), shared, ()), ""]
    if robot_mode:
        header += [
            "#   ros2 run apc_feedback robot_node --ros-args --params-file <this file>",
        ]
        robot = {
            "autostart": (True, "configure and activate at start (else: ros2 lifecycle set)"),
            "command_joints": (
                list(defaults.joint_names),
                "the URDF's moving joints in order: make it your effort controller's 'joints'",
            ),
        }
        body += _section("robot_node", ROBOT_NODE_PARAMS, robot, SHARED)
    else:
        header += [
            "#   composed --ros-args --params-file <this file>      # the three nodes, one process",
            "#   ros2 run apc_feedback feedback_node --ros-args --params-file <this file>",
        ]
        feedforward = {
            "move.goal_deg": (
                list(defaults.q_goal_deg),
                f"{DERIVATION['q_goal_deg']}; [] = hold until a goal arrives",
            )
        }
        plant = {
            "q_initial_deg": (list(defaults.q_start_deg), DERIVATION["q_start_deg"]),
            "payload.frame": (defaults.payload_frame, DERIVATION["payload_frame"]),
        }
        body += [
            *_section("feedforward_node", FEEDFORWARD_PARAMS, feedforward, SHARED),
            "",
            *_section("feedback_node", FEEDBACK_PARAMS, {}, SHARED),
            "",
            *_section("plant_node", PLANT_PARAMS, plant, SHARED),
        ]
    return "\n".join(header + body) + "\n"


def _unique(params: Iterable[Param]) -> list[Param]:
    """``params`` without repeated names (the first row of each name)."""
    seen: dict[str, Param] = {}
    for p in params:
        seen.setdefault(p.name, p)
    return list(seen.values())


def urdf_parameter(given: str) -> str:
    """What ``robot_description_path`` says: an absolute path for a file found from here, else
    the name as given (a file in apc's config directory, found by the nodes there too)."""
    path = Path(given).expanduser()
    return str(path.resolve()) if path.exists() else given


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="apc_params", description=__doc__.split("\n\n")[0] if __doc__ else None
    )
    parser.add_argument("--urdf", required=True, help="the arm's URDF (path or config file name)")
    parser.add_argument("--out", help="file to write (default: standard output)")
    parser.add_argument(
        "--lock-joints", nargs="+", default=[], help="joints to freeze (e.g. a gripper's)"
    )
    parser.add_argument(
        "--robot-mode",
        action="store_true",
        help="for a ros2_control robot: robot_node, no plant",
    )
    parser.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        _, defaults = load(resolve_config_path(args.urdf), lock_joints=args.lock_joints)
    except RobotModelError as exc:
        print(f"apc_params: --urdf {args.urdf}: {exc}", file=sys.stderr)
        return 2
    text = render(
        urdf_parameter(args.urdf),
        defaults,
        args.lock_joints,
        source=args.urdf,
        robot_mode=args.robot_mode,
    )
    if not args.out:
        sys.stdout.write(text)
        return 0
    out = Path(args.out)
    if out.exists() and not args.force:
        print(f"apc_params: {out} exists (--force overwrites it)", file=sys.stderr)
        return 2
    out.write_text(text)
    for field, parameter in WRITTEN.items():
        if not (args.robot_mode and field in SIMULATION_ONLY):
            print(f"apc_params: {defaults.describe(field, parameter)}", file=sys.stderr)
    print(f"apc_params: wrote {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
