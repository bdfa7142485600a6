"""``feedforward_node``: set points and nominal torques (Eqs. 2-8), one per joint state.

On ``joint_states`` stamped ``kT`` it samples the current plan and publishes, stamped ``jT``,
the set point on ``feedforward/setpoint`` and ``u_n(j)`` on ``feedforward/torque`` for every
``j`` up to ``k + lookahead`` not sent yet. Driving both lockstep and real time from the plant's
samples keeps every node on the same sample index ``k`` without a shared clock.

Why ahead: the plan does not depend on the measured state (only its start does), so sample
``k + 1`` can leave as soon as ``k``'s joint state arrives. The feedback then has set point
``k`` in hand when joint state ``k`` arrives and the loop's critical path is plant -> feedback ->
plant, one DDS hop shorter (the paper's parallel feedforward and feedback). With
``lookahead = 0`` set point ``k`` answers joint state ``k`` (serial, one hop more). A goal that
arrives mid-motion starts ``lookahead`` samples later than it would otherwise; the numbers of a
lockstep run do not change.

The plan: at the first joint state the arm's measured position becomes the start; if
``move.goal_deg`` is set the 4-3-4 move to it starts there, else the arm holds. Goals on
``feedforward/trajectory`` (any joint order) are planned from the end of the current motion
and start when it ends; after the last motion the final set point is held.

This node runs beside apc's plant. On a robot, ``robot_node`` samples the same plan
(:class:`apc_feedforward.goals.GoalQueue`) inside its commanding loop, so no set point crosses
DDS there.
"""

from __future__ import annotations

import sys
from typing import Any

from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

import apc_msgs_py as wire
from apc_core.node_logs import level_logger
from apc_core.nodeutil import (
    Diagnostics,
    DiagnosticsPublisher,
    Stopwatch,
    guarded,
    matched_publisher,
    reject,
    run_node,
)
from apc_core.params import Param, declare
from apc_core.robot_params import CONTROLLER_ROBOT_PARAMS, controller_robot_from_params
from apc_feedforward.goals import (
    MOVE_PARAMS,
    GoalQueue,
    Lookahead,
    accept_goal,
    report_sampled,
    setpoint_message,
)
from apc_feedforward.nominal import Setpoint

PARAMS: tuple[Param, ...] = (
    *CONTROLLER_ROBOT_PARAMS,
    *MOVE_PARAMS,
    Param(
        "lookahead",
        1,
        "publish set points and nominal torques this many samples ahead of the joint state "
        "(0 = answer joint state k with sample k)",
        0,
        wire.MAX_LOOKAHEAD,
    ),
)


class FeedforwardNode(Node):
    """Composable feedforward node (see module docstring).

    Parameters
    ----------
    qos : QoSProfile
        Profile of the control-loop topics (default :data:`apc_msgs_py.CONTROL_QOS`).
    kwargs :
        Passed to ``rclpy.node.Node`` (namespace, parameter_overrides, ...).
    """

    def __init__(
        self, node_name: str = "feedforward_node", *, qos: QoSProfile | None = None, **kwargs: Any
    ) -> None:
        super().__init__(node_name, **kwargs)
        qos = qos or wire.CONTROL_QOS
        out_qos = wire.writer_qos(qos)
        values = declare(self, PARAMS)
        self.controller_robot = controller_robot_from_params(values)
        self.joint_names = self.controller_robot.joint_names
        self.period = values["period"]
        self.period_ns = wire.seconds_to_ns(self.period)
        self.goals = GoalQueue.from_params(self.controller_robot, values)
        self.lookahead = Lookahead(values["lookahead"])
        self.diagnostics = Diagnostics(self.get_fully_qualified_name())
        self._log = level_logger(self)
        self._setpoint_msg = JointTrajectory()
        self._torque_msg = JointState()

        self.setpoint_pub = matched_publisher(self, JointTrajectory, wire.SETPOINT, out_qos)
        self.torque_pub = matched_publisher(self, JointState, wire.FEEDFORWARD_TORQUE, out_qos)
        diag = self.diagnostics
        self.create_subscription(
            JointState,
            wire.JOINT_STATES,
            guarded(self, diag, wire.JOINT_STATES, self._on_joint_state),
            qos,
        )
        self.create_subscription(
            JointTrajectory,
            wire.TRAJECTORY_GOAL,
            guarded(self, diag, wire.TRAJECTORY_GOAL, self._on_goal),
            wire.TRAJECTORY_GOAL_QOS,
        )
        DiagnosticsPublisher(self, self.diagnostics)

    def _on_goal(self, msg: JointTrajectory) -> None:
        try:
            goal = wire.msg_to_trajectory_goal(msg, self.joint_names)
            accept_goal(self.goals, goal, self.diagnostics.count, self._log)
        except ValueError as exc:  # WireError, TrajectoryError
            reject(self, self.diagnostics, wire.TRAJECTORY_GOAL, exc)

    def _on_joint_state(self, msg: JointState) -> None:
        try:
            sample = wire.joint_state_to_arrays(msg, self.joint_names, require=("position",))
            k = wire.sample_index(sample.stamp_ns, self.period_ns)
            due = self.lookahead.due(sample.stamp_ns, k)
        except wire.WireError as exc:
            reject(self, self.diagnostics, wire.JOINT_STATES, exc)
            return
        if due.resend is not None:
            # The plant re-sent sample k (lockstep resend): send what answered it again.
            self.diagnostics.count("resent")
            for sp in due.resend:
                self._publish(*self._messages(sp))
            return
        for j in due.samples:
            with Stopwatch(self.diagnostics, "compute"):
                out = self.goals.sample(j, sample.position, self._messages)
                report_sampled(j, out, self.diagnostics.count, self._log)
            if out.rendered is None or out.setpoint is None:
                break
            self._publish(*out.rendered)
            self.lookahead.sent(out.setpoint)
        self.lookahead.answered(k)
        self.diagnostics.count("samples")

    def _messages(self, sp: Setpoint) -> tuple[JointTrajectory, JointState]:
        """Set point and nominal torque of ``sp`` as messages (validated for the wire)."""
        setpoint = setpoint_message(sp, self.period_ns, self.joint_names, self._setpoint_msg)
        stamp = wire.sample_stamp_ns(sp.k, self.period_ns)
        torque = wire.torque_to_msg(stamp, self.joint_names, sp.u_n, self._torque_msg)
        return setpoint, torque

    def _publish(self, setpoint: JointTrajectory, torque: JointState) -> None:
        self.setpoint_pub.publish(setpoint)
        self.torque_pub.publish(torque)


def main(args: list[str] | None = None) -> int:
    return run_node(
        FeedforwardNode,
        prog="feedforward_node",
        summary=__doc__ or "",
        params=PARAMS,
        args=args,
    )


if __name__ == "__main__":
    sys.exit(main())
