"""``guarded``: a callback's exception is counted and logged, except where the node is stopping."""

from __future__ import annotations

import pytest
import rclpy
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import Float64MultiArray

from apc_core.nodeutil import Diagnostics, guarded

pytestmark = pytest.mark.ros


def test_an_error_is_counted_but_one_from_a_publish_on_a_stopping_node_is_not():
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("guarded_test", context=context)
    diagnostics = Diagnostics("guarded_test")
    pub = node.create_publisher(Float64MultiArray, "guarded_test_out", 1)
    try:
        failing = guarded(node, diagnostics, "input", lambda: 1 / 0)
        assert failing() is None
        assert diagnostics.counters == {"callback_errors.input": 1, "callback_errors": 1}
        publishing = guarded(node, diagnostics, "input", lambda: pub.publish(Float64MultiArray()))
        publishing()  # a running node publishes
        rclpy.shutdown(context=context)  # Ctrl-C: rclpy shuts the context down mid-callback
        with pytest.raises(Exception, match="context"):
            pub.publish(Float64MultiArray())  # what the callback meets
        assert publishing() is None
        assert failing() is None  # whatever fails then
        assert diagnostics.counters == {"callback_errors.input": 1, "callback_errors": 1}
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=context)
