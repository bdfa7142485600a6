"""``composed``: the nodes of one arm composed in one process, on one executor.

    composed --ros-args --params-file config/puma560_3dof.yaml [-r __ns:=/arm0]
    composed --controllers --ros-args --params-file ...    # feedforward + feedback only

The same ``plant_node``, ``feedforward_node`` and ``feedback_node`` as the three executables,
built in one process: each reads its own section of the parameters file, a namespace remap
applies to all, and topics, QoS and ``ros2 param`` are those of the separate executables.
``--controllers`` leaves the plant out, for a ``plant_node`` of its own. A ros2_control robot
is commanded by one node, ``robot_node`` (:mod:`apc_feedback.robot_node`), which samples the
feedforward's plan itself.

Why: a message between processes costs a DDS hop and a thread wake-up on each side, one
between nodes of a process much less (``bench/ros_loop.py`` and ``bench/multi_arm.py``
measure both; docs/performance.md has the figures). Composition is ROS 2's own answer
(component containers). Numbers of a lockstep run are the same bit for bit either way.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from rclpy.node import Node

from apc_core.nodeutil import print_help, run_nodes, split_ros_args
from apc_feedback.node import PARAMS as FEEDBACK_PARAMS
from apc_feedback.node import FeedbackNode
from apc_feedforward.node import PARAMS as FEEDFORWARD_PARAMS
from apc_feedforward.node import FeedforwardNode
from apc_plant_sim.node import PARAMS as PLANT_PARAMS
from apc_plant_sim.node import PlantNode

CONTROLLERS_FLAG = "--controllers"


def _help(controllers_only: bool) -> None:
    print(__doc__.strip() + "\n")
    sections = [
        ("feedforward_node", FEEDFORWARD_PARAMS),
        ("feedback_node", FEEDBACK_PARAMS),
    ]
    if not controllers_only:
        sections.insert(0, ("plant_node", PLANT_PARAMS))
    for name, params in sections:
        print(f"--- {name} ---")
        print_help(name, "", params)
        print()


def main(args: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if args is None else args)
    user = split_ros_args(argv)[0]
    controllers_only = CONTROLLERS_FLAG in user
    if controllers_only:
        argv.remove(CONTROLLERS_FLAG)
    unknown = [a for a in user if a not in (CONTROLLERS_FLAG, "-h", "--help")]
    if unknown:
        print(f"arm: unknown argument {unknown[0]!r} (see --help)", file=sys.stderr)
        return 2

    def make_nodes() -> list[Node]:
        nodes: list[Node] = [FeedforwardNode(), FeedbackNode()]
        if not controllers_only:
            nodes.append(PlantNode())  # last: it starts the run once the others listen
        return nodes

    def ended(nodes: list[Node]) -> bool:
        return any(getattr(node, "done", False) for node in nodes)

    return run_nodes(
        make_nodes,
        prog="composed",
        print_help=lambda: _help(controllers_only),
        args=argv,
        spin_until=ended,
    )


if __name__ == "__main__":
    sys.exit(main())
