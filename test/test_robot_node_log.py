"""robot_node's log lines: a level after another from the same helper is printed, not refused."""

from __future__ import annotations

import pytest
import rclpy

from apc_feedback.robot_node import RobotNode

pytestmark = pytest.mark.ros


def test_log_lines_of_different_levels_follow_each_other():
    # The watchdog's error line is followed by the recovery's warning within the throttle
    # window; rclpy raises if one throttled call site changes severity.
    context = rclpy.Context()
    rclpy.init(context=context)
    node = RobotNode(context=context)
    try:
        node._log("error", "watchdog: no fresh joint state")
        node._log("warn", "joint states back")
        node._log("info", "configured")
        node._log("error", "watchdog: no fresh joint state")
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
