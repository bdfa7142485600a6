"""robot_node takes the joint states queued behind a callback that overran all at once: each is
sampled (the velocity's history, the echo), and a sample whose next sample's state is already
in hand is not answered (answering each in turn had every command act samples late)."""

from __future__ import annotations

import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

import apc_msgs_py as wire
from apc_feedback.robot_node import RobotNode

pytestmark = pytest.mark.ros

MS = 1_000_000
T_NS = 10 * MS


def _state(stamp_ns: int) -> JointState:
    msg = JointState()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    msg.name = ["joint_1", "joint_2", "joint_3"]
    msg.position = [0.0, 0.1, 0.2]
    msg.velocity = [0.0, 0.0, 0.0]
    return msg


def _newest(robot: RobotNode) -> int | None:
    """The stamp of the newest state robot_node has taken."""
    newest = robot.loop.sampler.newest
    return None if newest is None else newest.stamp_ns


def test_states_queued_behind_a_callback_are_taken_at_once_and_only_the_newest_answered():
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    executor = SingleThreadedExecutor(context=context)
    nodes = []
    try:
        overrides = [
            Parameter("robot_description_path", value="puma560_3dof.urdf"),
            Parameter("period", value=T_NS * 1e-9),
            Parameter("use_sim_time", value=True),
            Parameter("max_age", value=0.05),  # the oldest queued state is 21 ms old
        ]
        robot = RobotNode(context=context, parameter_overrides=overrides)
        nodes.append(robot)
        driver = rclpy.create_node("driver", context=context)
        nodes.append(driver)
        commands: list[Float64MultiArray] = []
        driver.create_subscription(
            Float64MultiArray, "/effort_controller/commands", commands.append, 10
        )
        # A driver's broadcaster: reliable, as joint_state_broadcaster publishes.
        pub = driver.create_publisher(JointState, wire.JOINT_STATES, 10)
        clock = driver.create_publisher(Clock, "/clock", wire.CLOCK_QOS)
        robot.trigger_configure()
        robot.trigger_activate()
        executor.add_node(robot)
        executor.add_node(driver)
        deadline = time.monotonic() + 10.0
        while (pub.get_subscription_count() < 1 or clock.get_subscription_count() < 1) and (
            time.monotonic() < deadline
        ):
            time.sleep(0.01)
        assert pub.get_subscription_count() == 1, "robot_node's reader never matched"

        def counters() -> dict:
            return robot.diagnostics.counters

        def spin_until(done, what: str) -> None:
            end = time.monotonic() + 10.0
            while not done() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.05)
            assert done(), f"{what}; counters {counters()}"

        def tick(now_ns: int) -> None:  # simulated time: robot_node's clock reaches now_ns
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(now_ns, 1_000_000_000)
            clock.publish(msg)
            spin_until(lambda: robot.get_clock().now().nanoseconds >= now_ns, "the clock")

        # A 100 Hz driver (one state a sample), each state answered as it comes.
        base = 1000 * T_NS
        # The first start waits for a second state (the driver's period).
        for i in range(3):
            tick(base + i * T_NS + MS)
            pub.publish(_state(base + i * T_NS))
            spin_until(lambda i=i: _newest(robot) == base + i * T_NS, f"state {i} taken")
        spin_until(lambda: len(commands) == 2, "the commands of states 1 and 2")
        before = dict(counters())
        # robot_node's executor stalls while the driver publishes three cycles.
        tick(base + 5 * T_NS + MS)
        for i in range(3, 6):
            pub.publish(_state(base + i * T_NS))
        spin_until(lambda: counters().get("samples_overtaken", 0) == 2, "two overtaken")
        spin_until(lambda: len(commands) == 3, "the newest's command")
        executor.spin_once(timeout_sec=0.1)
        assert len(commands) == 3  # one command for the three states
        for key, change in (("samples_taken", 1), ("missed_samples", 0)):
            assert counters().get(key, 0) - before.get(key, 0) == change, (key, counters())
        reader = robot._state_reader
        assert reader.handle.take_message(reader.msg_type, reader.raw) is None
    finally:
        executor.shutdown(timeout_sec=1.0)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
