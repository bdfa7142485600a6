"""Per-joint defaults derived from a URDF alone: start pose, a move, inertia error, payload frame.

Whatever a run or a node needs once per joint has a default here, so that any serial arm runs
from its URDF without a hand-written list of the right length:

- start pose: the middle of each joint's ``<limit lower upper>`` range;
- a move: from there by :data:`MOVE_FRACTION` of each joint's range, alternately up and down
  (+, -, +, ...), so the goal stays inside the limits and the joints do not all turn one way;
- inertia error for simulation: the paper's +-10 % pattern (``+0.1, -0.1, +0.1, ...``), one
  value per joint (:func:`apc_core.robot.alternating_error`);
- payload frame: the last link, i.e. the link reached from the last moving joint's child
  through fixed joints for as long as the tree does not branch (the 3- and 6-joint PUMA's
  ``wrist_center``, the Panda's ``panda_hand``, whose fingers and tool point branch off).

A joint whose URDF range is empty or not finite (``lower >= upper``) starts at 0 and moves by
:data:`NO_RANGE_MOVE_RAD`. Every default is reported by :meth:`ArmDefaults.describe` in one
line, so a caller prints what it chose; any of them is overridden by giving the value.
Plain Python: no rclpy.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from apc_core.robot import (
    PAPER_GRAVITY_M_S2,
    Robot,
    RobotModelError,
    alternating_error,
    load_robot,
    read_urdf,
)

#: The default move goes this fraction of each joint's range from the middle of it: about 20 deg
#: on the PUMA's and the Panda's first joint in the 1 s 4-3-4, well inside their velocity and
#: effort limits with a 5 lb payload (test/test_defaults.py runs it on both arms).
MOVE_FRACTION = 0.06
#: Magnitude of the simulated inertia error of the controllers' model (the paper's 10 %).
SIMULATED_INERTIA_ERROR = 0.1
#: Move (rad, or m for a prismatic joint) of a joint whose URDF gives no usable range.
NO_RANGE_MOVE_RAD = 0.5

#: How each default is derived, by field name, for the one line that reports it.
DERIVATION = {
    "q_start_deg": "middle of each joint's URDF range",
    "q_goal_deg": f"start +/- {MOVE_FRACTION:g} of each joint's URDF range (+, -, +, ...)",
    "inertia_error": f"+/-{SIMULATED_INERTIA_ERROR:g} alternating per joint (the paper's pattern)",
    "payload_frame": "the last link (fixed to the last moving joint, up to a branch)",
}


@dataclass(frozen=True)
class ArmDefaults:
    """Per-joint defaults of one arm, in apc's joint order (angles in degrees, URDF angles)."""

    joint_names: tuple[str, ...]
    q_start_deg: tuple[float, ...]
    q_goal_deg: tuple[float, ...]
    inertia_error: tuple[float, ...]
    payload_frame: str

    def describe(self, field: str, parameter: str | None = None) -> str:
        """One line: the value of ``field`` and how it was derived, named ``parameter``."""
        if field not in DERIVATION:
            raise KeyError(f"no derived default named {field!r}")
        value = getattr(self, field)
        if isinstance(value, tuple):
            shown = "[" + ", ".join(f"{v:.4g}" for v in value) + "]"
        else:
            shown = repr(value)
        return f"{parameter or field} = {shown} (not given; from the URDF: {DERIVATION[field]})"


def last_link(urdf_xml: str, last_joint: str) -> str:
    """The link at the end of the fixed joints after ``last_joint``, up to a branch.

    Starts at ``last_joint``'s child link and follows a fixed joint as long as it is the only
    joint leaving the current link; a link with no child, with several, or with a moving one
    ends the walk.
    """
    root = ET.fromstring(urdf_xml)
    children: dict[str, list[ET.Element]] = {}
    by_name: dict[str, ET.Element] = {}
    for joint in root.findall("joint"):
        by_name[joint.get("name", "")] = joint
        parent = joint.find("parent")
        if parent is not None:
            children.setdefault(parent.get("link", ""), []).append(joint)
    joint = by_name.get(last_joint)
    child = joint.find("child") if joint is not None else None
    if child is None:
        raise RobotModelError(f"joint '{last_joint}' has no child link in the URDF")
    link = child.get("link", "")
    seen = {link}
    while True:
        leaving = children.get(link, [])
        if len(leaving) != 1 or leaving[0].get("type") != "fixed":
            return link
        nxt = leaving[0].find("child")
        if nxt is None or nxt.get("link", "") in seen:
            return link
        link = nxt.get("link", "")
        seen.add(link)


def start_and_goal(
    lower: Sequence[float], upper: Sequence[float], fraction: float = MOVE_FRACTION
) -> tuple[np.ndarray, np.ndarray]:
    """Start at the middle of each range; goal ``fraction`` of the range away, +, -, +, ..."""
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    if lo.shape != hi.shape or lo.ndim != 1:
        raise ValueError(f"lower and upper limits need one value per joint: {lo.shape}, {hi.shape}")
    if not 0.0 < fraction <= 0.5:
        raise ValueError(f"fraction must be in (0, 0.5] to stay inside the range, got {fraction}")
    has_range = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    lo, hi = np.where(has_range, lo, 0.0), np.where(has_range, hi, 0.0)
    start = 0.5 * (lo + hi)
    span = np.where(has_range, fraction * (hi - lo), NO_RANGE_MOVE_RAD)
    sign = np.where(np.arange(lo.size) % 2 == 0, 1.0, -1.0)
    return start, start + sign * span


def derive(robot: Robot, urdf_xml: str) -> ArmDefaults:
    """The per-joint defaults of ``robot``, loaded from ``urdf_xml``."""
    start, goal = start_and_goal(*robot.position_limits)
    n = robot.n_joints
    return ArmDefaults(
        joint_names=robot.joint_names,
        q_start_deg=_degrees(start),
        q_goal_deg=_degrees(goal),
        inertia_error=tuple(float(v) for v in alternating_error(n, SIMULATED_INERTIA_ERROR)),
        payload_frame=last_link(urdf_xml, robot.joint_names[-1]),
    )


def load(
    urdf: str | Path,
    *,
    gravity: float = PAPER_GRAVITY_M_S2,
    lock_joints: Sequence[str] = (),
) -> tuple[Robot, ArmDefaults]:
    """Load the arm of ``urdf`` (path or XML) and derive its defaults."""
    robot = load_robot(urdf, gravity=gravity, lock_joints=tuple(lock_joints))
    return robot, derive(robot, read_urdf(urdf)[0])


def _degrees(values: np.ndarray) -> tuple[float, ...]:
    """Radians to degrees, rounded to 1e-3 deg so a written parameter file reads cleanly."""
    return tuple(round(math.degrees(float(v)), 3) + 0.0 for v in values)
