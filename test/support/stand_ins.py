"""Stand-ins for the nodes a test does not run, played by the test on its own graph: a plant
(and feedforward) that publishes joint states and set points and records what the controllers
answer, or the two controllers that publish torques to a plant under test."""

from __future__ import annotations

from typing import Any

import numpy as np
import rclpy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

import apc_msgs_py as wire

from .arm import NAMES
from .capture import CONTROLLER_OUTPUT, ByStamp
from .graph import Graph
from .qos import DEEP_QOS


class StandInPlant:
    """Publishes ``joint_states`` (and, optionally, set points) like a plant (and feedforward);
    records what the controllers answer, by stamp (``got[topic][stamp_ns]``)."""

    def __init__(self, graph: Graph) -> None:
        self.graph = graph
        self.node = graph.add(rclpy.create_node("stand_in", context=graph.context))
        self.js_pub = self.node.create_publisher(JointState, wire.JOINT_STATES, DEEP_QOS)
        self.sp_pub = self.node.create_publisher(JointTrajectory, wire.SETPOINT, DEEP_QOS)
        self.goal_pub = self.node.create_publisher(
            JointTrajectory, wire.TRAJECTORY_GOAL, wire.TRAJECTORY_GOAL_QOS
        )
        self._received = ByStamp(self.node, CONTROLLER_OUTPUT)
        self.got = self._received.by_topic

    def count(self, topic: str, stamp_ns: int) -> int:
        return self._received.count(topic, stamp_ns)

    def joint_state(self, stamp_ns: int, q: Any, qd: Any, effort: Any = None) -> None:
        msg = JointState(name=list(NAMES), position=[float(v) for v in q])
        msg.velocity = [float(v) for v in qd]
        if effort is not None:
            msg.effort = [float(v) for v in effort]
        msg.header.stamp = wire.ns_to_stamp(stamp_ns)
        self.js_pub.publish(msg)

    def setpoint(self, stamp_ns: int, q_d: Any, qd_d: Any, qdd_d: Any, u_n: Any) -> None:
        self.sp_pub.publish(wire.setpoint_to_msg(stamp_ns, NAMES, q_d, qd_d, qdd_d, u_n, 0))


def stand_in_controllers(graph: Graph) -> tuple[Any, Any, dict[int, Any]]:
    """Publishers of both torques, and the plant's joint states by stamp, for a test that plays
    the controllers."""
    helper = graph.add(rclpy.create_node("controllers", context=graph.context))
    ff_pub = helper.create_publisher(JointState, wire.FEEDFORWARD_TORQUE, DEEP_QOS)
    fb_pub = helper.create_publisher(JointState, wire.FEEDBACK_TORQUE, DEEP_QOS)
    states: dict[int, Any] = {}
    helper.create_subscription(
        JointState,
        wire.JOINT_STATES,
        lambda m: states.setdefault(wire.stamp_to_ns(m.header.stamp), m),
        DEEP_QOS,
    )
    return ff_pub, fb_pub, states


def torque(pub: Any, stamp_ns: int, effort: Any) -> None:
    """Publish ``effort`` as the torque for the sample at ``stamp_ns``, on ``pub``."""
    pub.publish(wire.torque_to_msg(stamp_ns, NAMES, np.asarray(effort, dtype=float)))
