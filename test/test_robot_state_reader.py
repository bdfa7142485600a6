"""robot_node reads the newest joint state only: states that arrive while its callback overruns
are replaced, not queued behind it (each would be answered late in turn)."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState

import apc_msgs_py as wire
from apc_feedback.robot_node import RobotNode

pytestmark = pytest.mark.ros


def _state(stamp_ns: int) -> JointState:
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.name = ["joint_1", "joint_2", "joint_3"]
    msg.position = [0.0, 0.1, 0.2]
    return msg


def test_states_that_arrive_while_the_callback_runs_are_replaced_by_the_newest():
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    nodes = []
    try:
        overrides = [Parameter("robot_description_path", value="puma560_3dof.urdf")]
        robot = RobotNode(context=context, parameter_overrides=overrides)
        nodes.append(robot)
        robot.trigger_configure()
        (reader,) = [s for s in robot.subscriptions if s.topic_name == "/" + wire.JOINT_STATES]
        driver = rclpy.create_node("driver", context=context)
        nodes.append(driver)
        # A driver's broadcaster: reliable, as joint_state_broadcaster publishes.
        pub = driver.create_publisher(JointState, wire.JOINT_STATES, 10)
        deadline = time.monotonic() + 10.0
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert pub.get_subscription_count() == 1, "robot_node's reader never matched"
        # Five driver cycles while robot_node's executor is busy elsewhere (nothing spins it).
        stamps = [1_000_000_000 + i * 1_000_000 for i in range(5)]
        for stamp in stamps:
            pub.publish(_state(stamp))
        # Fast DDS delivers within a participant as it publishes (the nodes of one context
        # share one); the loop only waits should a delivery come later.
        taken: list[int] = []
        deadline = time.monotonic() + 10.0
        while stamps[-1] not in taken and time.monotonic() < deadline:
            got = reader.handle.take_message(reader.msg_type, reader.raw)
            if got is None:
                time.sleep(0.01)
                continue
            stamp = got[0].header.stamp
            taken.append(stamp.sec * 1_000_000_000 + stamp.nanosec)
        assert taken == stamps[-1:], f"robot_node's reader held {taken}, not the newest only"
    finally:
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
