"""``feedback_node``: perturbation torques from the joint-state error (Eqs. 29-35, 36).

For each sample ``k`` it waits until it holds both ``joint_states`` and ``feedforward/setpoint``
stamped ``kT`` (in either order), runs its feedback law once, and publishes ``du(k)`` on
``feedback/torque`` (stamped ``kT``) and, for the adaptive law, the identified ``[F̂ Ĝ ŵ]``,
trace(P) and residual norm on ``feedback/estimate``. A re-sent sample (lockstep resend) is
answered from a cache, so the identifier never sees a sample twice; the copy of a used set point
that the feedforward sends again then (samples later, with its lookahead) is counted as
``resent.feedforward/setpoint``, not rejected.

Controller kinds: ``adaptive`` (the paper's), ``computed_torque`` (Eq. 36), ``pd``, ``none``.

The weights and gains ``adaptive.q_position``, ``adaptive.q_velocity``, ``adaptive.r``,
``gains.kp`` and ``gains.kv`` can be changed while the node runs (``ros2 param set``); a value
is checked when it is set (refused with a reason naming the parameter) and applied from the
next sample on. Every other parameter is read-only.
"""

from __future__ import annotations

import dataclasses
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

from apc_core import wire
from apc_core.nodeutil import (
    ROBOT_PARAMS,
    Diagnostics,
    DiagnosticsPublisher,
    Stopwatch,
    guarded,
    reject,
    robot_from_params,
    run_node,
)
from apc_core.params import ConfigError, Param, check_number, declare, subset
from apc_core.robot import with_inertia_error
from apc_feedback.baselines import PD, ComputedTorque, NoFeedback, PdGains
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback, FeedbackError, FeedbackLaw
from apc_feedback.sampling import (
    Decision,
    GridSampler,
    JointStateSampler,
    SamplePairer,
    Step,
    Verdict,
)

CONTROLLER_KINDS = ("adaptive", "computed_torque", "pd", "none")

PARAMS: tuple[Param, ...] = (
    *ROBOT_PARAMS,
    Param(
        "inertia_error",
        [],
        "relative error of the controller's link inertia tensors, one per joint; empty = none",
    ),
    Param("controller", "adaptive", f"feedback law: one of {', '.join(CONTROLLER_KINDS)}"),
    Param(
        "adaptive.q_position",
        0.1,
        "Q weight of the position error, Eq. 34 (1/rad^2); settable at run time",
        0.0,
        1e12,
        read_only=False,
        dynamic_typing=True,
    ),
    Param(
        "adaptive.q_velocity",
        0.1,
        "Q weight of the velocity error, Eq. 34; settable at run time",
        0.0,
        1e12,
        read_only=False,
        dynamic_typing=True,
    ),
    Param(
        "adaptive.r",
        1e-6,
        "R weight of the torque, Eq. 34 (1/(N m)^2), > 0; settable at run time",
        1e-15,
        1e12,
        read_only=False,
        dynamic_typing=True,
    ),
    Param("adaptive.rho", 0.95, "RLS forgetting factor rho, Eqs. 29-31; 0 < rho <= 1", 1e-6, 1.0),
    Param("adaptive.alpha", 1.5e5, "P(0) = alpha I, Eq. 32", 1e-12, 1e15),
    Param(
        "adaptive.trace_max",
        0.0,
        "RLS wind-up guard, bound on trace(P): 0 = trace(P(0)) = alpha (3n+1); < 0 = off",
        -1.0,
        1e30,
    ),
    Param(
        "adaptive.forgetting",
        "exponential",
        "Eq. 30: 'exponential' (P divided by rho) or 'printed' (as printed, never forgets)",
    ),
    Param(
        "adaptive.control_form",
        "exact",
        "Eq. 35: 'exact' minimiser -(R+G'QG)^-1 G'Q(F x + w) or 'printed' G'QF(x + w)",
    ),
    Param(
        "adaptive.initial_model",
        "corrected",
        "Eq. 33b series: 'corrected' (T^2/2, T^3/6) or 'printed' (T^2, T^3/2)",
    ),
    Param(
        "adaptive.identify_with",
        "applied",
        "du(k-1) in the regressor: 'applied' (joint_states effort - u_n) or 'commanded'",
    ),
    Param(
        "adaptive.horizon",
        1,
        "steps N of the optimal control over the identified model; 1 = the paper's Eq. 34",
        1,
        200,
    ),
    Param(
        "adaptive.q_integral",
        0.0,
        "weight of the integrated position error (integral action); 0 = off (the paper)",
        0.0,
        1e15,
    ),
    Param("adaptive.integral_limit", 0.05, "anti-windup bound on the integral (rad s)", 1e-9, 1e3),
    Param(
        "adaptive.project_g",
        False,
        "refuse RLS steps that make G's velocity block (~T D^-1) indefinite; put the jump in w",
    ),
    Param(
        "gains.kp",
        100.0,
        "Kp of computed torque (1/s^2) or PD (N m/rad); settable at run time",
        0.0,
        1e9,
        read_only=False,
        dynamic_typing=True,
    ),
    Param(
        "gains.kv",
        20.0,
        "Kv of computed torque (1/s) or PD (N m s/rad); settable at run time",
        0.0,
        1e9,
        read_only=False,
        dynamic_typing=True,
    ),
)

#: The parameters that can change while the node runs, by name.
RUNTIME_PARAMS: dict[str, Param] = {p.name: p for p in PARAMS if not p.read_only}
#: Which family of runtime parameters each law uses.
RUNTIME_FAMILY = {"adaptive": "adaptive.", "computed_torque": "gains.", "pd": "gains."}


def make_law(kind: str, values: dict[str, Any], model: Any) -> FeedbackLaw:
    """The feedback law named by the ``controller`` parameter, from the parameter values."""
    if kind == "adaptive":
        settings = subset(values, "adaptive.")
        settings["period"] = values["period"]
        return AdaptiveFeedback(model, AdaptiveConfig.from_dict(settings))
    gains = PdGains.from_dict(subset(values, "gains."))
    if kind == "computed_torque":
        return ComputedTorque(model, gains)
    if kind == "pd":
        return PD(model.nv, gains)
    if kind == "none":
        return NoFeedback(model.nv)
    raise ConfigError(
        f"parameter 'controller': must be one of {', '.join(CONTROLLER_KINDS)}, got {kind!r}"
    )


class FeedbackNode(Node):
    """Composable feedback node (see module docstring)."""

    def __init__(
        self, node_name: str = "feedback_node", *, qos: QoSProfile | None = None, **kwargs: Any
    ) -> None:
        super().__init__(node_name, **kwargs)
        qos = qos or wire.CONTROL_QOS
        values = declare(self, PARAMS)
        for name, param in RUNTIME_PARAMS.items():  # dynamically typed: check the type here
            values[name] = check_number(param, values[name])
        robot = robot_from_params(values)
        self.joint_names = robot.joint_names
        n = robot.n_joints
        error = values["inertia_error"] or [0.0] * n
        if len(error) != n:
            raise ConfigError(f"parameter 'inertia_error': needs {n} values, got {len(error)}")
        model = with_inertia_error(robot, error).model
        try:
            self.law = make_law(values["controller"], values, model)
        except FeedbackError as exc:
            # The law's messages start with the field name ("rho must satisfy ...").
            prefix = "adaptive." if values["controller"] == "adaptive" else "gains."
            raise ConfigError(f"parameter '{prefix}{str(exc).split()[0]}': {exc}") from None
        self.kind = values["controller"]
        self.period_ns = wire.seconds_to_ns(values["period"])
        self.diagnostics = Diagnostics(self.get_fully_qualified_name())
        self.diagnostics.set("controller", self.kind)
        self.sampler: JointStateSampler = GridSampler(self.period_ns)
        self.pairer = SamplePairer(self.period_ns)
        #: The output published for the newest step, (stamp, torque, estimate): a resend's answer.
        self._answer: tuple[int, JointState, Float64MultiArray | None] | None = None
        self._torque_msg = JointState()
        self._estimate_msg = Float64MultiArray()
        self._gain_updates: dict[str, float] = {}

        self.torque_pub = self.create_publisher(JointState, wire.FEEDBACK_TORQUE, qos)
        self.estimate_pub = self.create_publisher(Float64MultiArray, wire.ESTIMATE, qos)
        diag = self.diagnostics
        self.create_subscription(
            JointState,
            wire.JOINT_STATES,
            guarded(self, diag, wire.JOINT_STATES, self._on_joint_state),
            qos,
        )
        self.create_subscription(
            JointTrajectory,
            wire.SETPOINT,
            guarded(self, diag, wire.SETPOINT, self._on_setpoint),
            qos,
        )
        DiagnosticsPublisher(self, self.diagnostics)
        # After declaring: rclpy calls this for every later set (read-only ones are refused
        # by rclpy before it gets here, with "Trying to set a read-only parameter: <name>.").
        self.add_on_set_parameters_callback(self._on_set_parameters)

    # -- runtime parameters ---------------------------------------------------------------------
    def _on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Check new weights/gains; they are applied at the next sample (all or none)."""
        updates: dict[str, float] = {}
        for parameter in parameters:
            row = RUNTIME_PARAMS.get(parameter.name)
            if row is None:
                continue  # e.g. use_sim_time: not ours to judge
            try:
                value = check_number(row, parameter.value)
            except ConfigError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            family = RUNTIME_FAMILY.get(self.kind)
            if family is None or not parameter.name.startswith(family):
                return SetParametersResult(
                    successful=False,
                    reason=f"parameter '{parameter.name}': not used by controller '{self.kind}'",
                )
            updates[parameter.name] = value
        self._gain_updates.update(updates)
        return SetParametersResult(successful=True)

    def _apply_gain_updates(self, k: int) -> None:
        """Give the running law the weights/gains set since the last sample (new objects)."""
        updates, self._gain_updates = self._gain_updates, {}
        law = self.law
        try:
            if isinstance(law, AdaptiveFeedback):
                law.reconfigure(dataclasses.replace(law.config, **subset(updates, "adaptive.")))
            elif isinstance(law, (ComputedTorque, PD)):
                law.gains = dataclasses.replace(law.gains, **subset(updates, "gains."))
        except ValueError as exc:  # checked when set; a law that still refuses keeps its gains
            reject(self, self.diagnostics, "parameters", exc)
            return
        self.diagnostics.count("parameter_updates")
        changes = ", ".join(f"{name} = {value:g}" for name, value in sorted(updates.items()))
        self.get_logger().info(f"sample {k}: applying {changes}")

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
        stamp, state, setpoint = step.stamp_ns, step.state, step.setpoint
        if self._gain_updates:
            self._apply_gain_updates(step.k)
        with Stopwatch(self.diagnostics, "compute"):
            try:
                out = self.law.update(
                    step.k,
                    state.position,
                    state.velocity,
                    setpoint.q,
                    setpoint.qd,
                    setpoint.qdd,
                    setpoint.u_n,
                    step.applied,
                )
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
                    estimate = wire.theta_to_estimate_msg(
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
