"""The plain classes' log lines on a node (``nodeutil.level_logger``): every event is printed,
a level after another is printed (not refused), a repeat of the same event is throttled."""

from __future__ import annotations

import pytest
import rclpy

from apc_core.node_logs import level_logger

pytestmark = pytest.mark.ros


def test_each_event_is_logged_once_and_its_repeats_are_throttled(capfd):
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("apc_test_level_logger", context=context)
    try:
        log = level_logger(node, throttle_s=60.0)
        # rclpy raises if one throttled call site changes severity: these follow each other.
        log("error", "sample 10: watchdog: no fresh joint state")
        log("warn", "sample 12: joint states back")
        log("info", "sample 12: goal accepted: 1 point(s), 1.000 s, 0 queued")
        log("info", "sample 13: starting a 1.000 s goal")  # another event: printed
        log("error", "sample 40: watchdog: no fresh joint state")  # a repeat: throttled
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
    err = capfd.readouterr().err
    assert err.count("watchdog: no fresh joint state") == 1, err
    for line in ("joint states back", "goal accepted", "starting a 1.000 s goal"):
        assert line in err, err
