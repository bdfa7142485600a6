"""The arm and sampling period the node tests run: the paper's 3-joint PUMA at T = 10 ms.

Tests that build messages by hand (stand-ins, injected garbage) need the arm's joint names and
limits and the grid their stamps lie on.
"""

from __future__ import annotations

from apc_core.robot import load_robot
from apc_lab.scenario import PUMA_3DOF_URDF

ROBOT = load_robot(PUMA_3DOF_URDF)
NAMES: tuple[str, ...] = ROBOT.joint_names
N = len(NAMES)
LOWER, UPPER = ROBOT.position_limits
#: The sampling period in ns: sample k is stamped k * T_NS.
T_NS = 10_000_000
