"""``feedback_node``: perturbation torques from the joint-state error (Eqs. 29-35, 36).

For each sample ``k`` it runs its feedback law once on the ``joint_states`` and the
``feedforward/setpoint`` stamped ``kT`` (in either order; :mod:`apc_feedback.sampling` decides
what a sample, a duplicate, a resend or a stale message is) and publishes ``du(k)`` on
``feedback/torque`` and, for the adaptive law, ``[F̂ Ĝ ŵ]``, trace(P) and the residual norm on
``feedback/estimate``. A re-sent sample is answered with what was published for it: the
identifier never sees a sample twice.

The law is the ``controller`` parameter, its settings a parameter family (``adaptive.``,
``gains.``) made from its settings dataclass (:mod:`apc_feedback.laws`); the ``preset``
parameter (:mod:`apc_feedback.presets`: ``recommended`` unless told, ``paper`` as printed) gives
the ``adaptive.*`` parameters their defaults, which a value given overrides. Those "settable at run
time" can be changed with ``ros2 param set``: checked when set (refused with a reason naming
the parameter), applied from the next sample on. Every other parameter is read-only.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

import apc_msgs_py as wire
from apc_core.nodeutil import (
    Diagnostics,
    DiagnosticsPublisher,
    Stopwatch,
    guarded,
    matched_publisher,
    reject,
    run_node,
)
from apc_core.params import ConfigError, Param, declare
from apc_core.robot_params import CONTROLLER_ROBOT_PARAMS, controller_robot_from_params
from apc_feedback.controller import FeedbackError
from apc_feedback.laws import LawParameters
from apc_feedback.presets import PRESET_PARAM, law_params, preset_rows
from apc_feedback.sampling import (
    Decision,
    GridSampler,
    JointStateSampler,
    SamplePairer,
    Step,
    Verdict,
)

#: The node's parameters, with the default preset's adaptive settings (what --help shows).
PARAMS: tuple[Param, ...] = (*CONTROLLER_ROBOT_PARAMS, PRESET_PARAM, *law_params())


class FeedbackNode(Node):
    """Composable feedback node (see module docstring)."""

    def __init__(
        self, node_name: str = "feedback_node", *, qos: QoSProfile | None = None, **kwargs: Any
    ) -> None:
        super().__init__(node_name, **kwargs)
        qos = qos or wire.CONTROL_QOS
        out_qos = wire.writer_qos(qos)
        # The preset first: it gives the adaptive.* parameters their defaults.
        preset = declare(self, (PRESET_PARAM,))[PRESET_PARAM.name]
        values = declare(self, preset_rows(PARAMS, preset))
        robot = controller_robot_from_params(values)
        self.joint_names = robot.joint_names
        self.laws = LawParameters(values, robot)
        self.law, self.kind = self.laws.law, self.laws.kind
        self.period_ns = wire.seconds_to_ns(values["period"])
        self.diagnostics = Diagnostics(self.get_fully_qualified_name())
        self.diagnostics.set("controller", self.kind)
        self.sampler: JointStateSampler = GridSampler(self.period_ns)
        self.pairer = SamplePairer(self.period_ns)
        #: The output published for the newest step, (stamp, torque, estimate): a resend's answer.
        self._answer: tuple[int, JointState, Float64MultiArray | None] | None = None
        self._torque_msg = JointState()
        self._estimate_msg = Float64MultiArray()

        self.torque_pub = matched_publisher(self, JointState, wire.FEEDBACK_TORQUE, out_qos)
        self.estimate_pub = self.create_publisher(Float64MultiArray, wire.ESTIMATE, out_qos)
        diag = self.diagnostics
        for msg_type, topic, callback in (
            (JointState, wire.JOINT_STATES, self._on_joint_state),
            (JointTrajectory, wire.SETPOINT, self._on_setpoint),
        ):
            self.create_subscription(msg_type, topic, guarded(self, diag, topic, callback), qos)
        DiagnosticsPublisher(self, self.diagnostics)
        # After declaring: rclpy calls this for every later set (read-only ones are refused
        # by rclpy before it gets here, with "Trying to set a read-only parameter: <name>.").
        self.add_on_set_parameters_callback(self._on_set_parameters)

    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """New run-time settings: checked now, taken at the next sample (all or none)."""
        try:
            self.laws.propose({p.name: p.value for p in parameters})
        except ConfigError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    # -- samples --------------------------------------------------------------------------------
    def _on_joint_state(self, msg: JointState) -> None:
        try:
            state = wire.joint_state_to_arrays(msg, self.joint_names)
            sample = self.sampler.offer(state, self.get_clock().now().nanoseconds)
        except wire.WireError as exc:
            reject(self, self.diagnostics, wire.JOINT_STATES, exc)
            return
        if sample is not None:
            self._decided(wire.JOINT_STATES, self.pairer.offer_state(sample))

    def _on_setpoint(self, msg: JointTrajectory) -> None:
        try:
            setpoint = wire.msg_to_setpoint(msg, self.joint_names)
        except wire.WireError as exc:
            reject(self, self.diagnostics, wire.SETPOINT, exc)
            return
        self._decided(wire.SETPOINT, self.pairer.offer_setpoint(setpoint))

    def _decided(self, topic: str, decision: Decision) -> None:
        """Count, log or publish what the pairer decided about a message on ``topic``."""
        if decision.dropped:
            self.diagnostics.count(f"dropped.{topic}")
        verdict = decision.verdict
        if verdict is Verdict.STEP:
            self._step(decision.step)
        elif verdict is Verdict.RESENT:
            # Answered with the output already published for that sample, if there was one.
            self.diagnostics.count("resent")
            if self._answer is not None and self._answer[0] == self.pairer.done_ns:
                _, torque, estimate = self._answer
                self.torque_pub.publish(torque)
                if estimate is not None:
                    self.estimate_pub.publish(estimate)
        elif verdict is Verdict.COPY:
            self.diagnostics.count(f"resent.{topic}")
        elif verdict is Verdict.DUPLICATE:
            self.diagnostics.count(f"duplicate.{topic}")
        elif verdict is Verdict.REJECTED:
            reject(self, self.diagnostics, topic, wire.WireError(decision.reason))

    def _step(self, step: Step) -> None:
        stamp = step.stamp_ns
        changes = self.laws.take()
        if changes:
            self.diagnostics.count("parameter_updates")
            listed = ", ".join(f"{name} = {value:g}" for name, value in sorted(changes.items()))
            self.get_logger().info(f"sample {step.k}: applying {listed}")
        with Stopwatch(self.diagnostics, "compute"):
            try:
                out = self.law.update(step.k, *step.law_inputs())
                # Refuses du that is not finite or beyond the wire's bound: nothing is
                # published, the plant's watchdog / lockstep timeout takes over.
                torque = wire.torque_to_msg(stamp, self.joint_names, out.du, self._torque_msg)
            except (FeedbackError, ValueError) as exc:  # WireError is a ValueError
                reject(self, self.diagnostics, "feedback_law", exc)
                return
        # The torque first: the plant waits for it, the telemetry can follow.
        self.torque_pub.publish(torque)
        estimate = None
        rls = getattr(self.law, "rls", None)
        if rls is not None:
            # 0 before the first identification step: nothing non-finite goes on the wire.
            residual = float(np.linalg.norm(out.residual)) if out.residual is not None else 0.0
            self.diagnostics.set("trace_p", out.trace_p)
            self.diagnostics.set("residual_norm", residual)
            if out.rejected:
                self.diagnostics.count("rls_rejected_updates")
            elif out.skipped:
                self.diagnostics.count("rls_skipped_updates")
            # Built only for a listener (a recorder): a fifth of the node's work per sample.
            if self.estimate_pub.get_subscription_count() > 0:
                try:
                    estimate = wire.theta_t_to_estimate_msg(
                        rls.model_view(),
                        out.trace_p,
                        residual,
                        stamp_ns=stamp,
                        msg=self._estimate_msg,
                    )
                except wire.WireError as exc:
                    reject(self, self.diagnostics, "estimate", exc)
                else:
                    self.estimate_pub.publish(estimate)
        self._answer = (stamp, torque, estimate)
        self.diagnostics.count("samples")


def main(args: list[str] | None = None) -> int:
    return run_node(
        FeedbackNode, prog="feedback_node", summary=__doc__ or "", params=PARAMS, args=args
    )


if __name__ == "__main__":
    sys.exit(main())
