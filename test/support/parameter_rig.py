"""The feedback node's run-time parameters end to end: the node, a stand-in plant and
feedforward that drive it one sample at a time, and a client of its parameter service, as
``ros2 param set`` would use it."""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

import apc_msgs_py as wire
from apc_feedback.node import FeedbackNode
from apc_lab.experiment import RunSpec
from apc_lab.scenario import paper_scenario

from .arm import NAMES, T_NS, N
from .graph import Graph
from .nodes import counter, overrides
from .stand_ins import StandInPlant


class ParameterRig:
    """A feedback node, a stand-in plant + feedforward, and a parameter client (the service)."""

    def __init__(self, graph: Graph, controller: str) -> None:
        params = RunSpec(paper_scenario("a"), controller).node_parameters()
        self.graph = graph
        self.fb = graph.add(
            FeedbackNode(
                context=graph.context, parameter_overrides=overrides(params["feedback_node"])
            )
        )
        self.plant = StandInPlant(graph)
        self.client = AsyncParameterClient(self.plant.node, "feedback_node")
        graph.spin_until(lambda: self.client.services_are_ready(), what="parameter services")
        graph.spin_until(lambda: self.plant.sp_pub.get_subscription_count() >= 1)
        graph.spin_until(lambda: self.plant.node.count_publishers(wire.FEEDBACK_TORQUE) >= 1)
        self.k = 0

    def set(self, *parameters: Parameter) -> list[Any]:
        future = self.client.set_parameters(list(parameters))
        self.graph.spin_until(future.done, what="set_parameters")
        return list(future.result().results)

    def sample(self, q: Any, qd: Any, q_d: Any, qd_d: Any, u_n: Any) -> Any:
        """One sample; returns the published du (None if the node refused to publish)."""
        stamp = self.k * T_NS
        self.k += 1
        refused = counter(self.fb, "rejected.feedback_law")
        self.plant.joint_state(stamp, q, qd)
        self.plant.setpoint(stamp, q_d, qd_d, np.zeros(N), u_n)
        self.graph.spin_until(
            lambda: (
                self.plant.count(wire.FEEDBACK_TORQUE, stamp) == 1
                or counter(self.fb, "rejected.feedback_law") > refused
            )
        )
        if not self.plant.count(wire.FEEDBACK_TORQUE, stamp):
            return None
        return wire.msg_to_torque(self.plant.got[wire.FEEDBACK_TORQUE][stamp][0], NAMES).effort


def assert_refused(results: list[Any], name: str, why: str) -> None:
    """``set_parameters`` refused the one parameter ``name``, with ``why`` in its reason."""
    assert len(results) == 1 and not results[0].successful, results
    assert name in results[0].reason and why in results[0].reason, results[0].reason
