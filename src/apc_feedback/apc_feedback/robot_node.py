"""``robot_node``: apc's controllers commanding a ros2_control robot, as a managed node.

    robot_node --ros-args --params-file config/puma560_3dof_robot.yaml   # then configure/activate
    robot_node --autostart --ros-args ...                                # configured and active

A lifecycle node (``ros2 lifecycle set /robot_node configure``, ``activate``, ``deactivate``,
``cleanup``, ``shutdown``; the ``lifecycle_msgs`` services ``~/change_state`` and
``~/get_state``):

- ``configure`` loads the model, checks every parameter (a bad one fails the transition with
  one line naming it) and subscribes ``/joint_states`` (a driver's, any rate and joint order,
  extra joints ignored, velocity estimated when empty);
- ``activate`` starts sampling in step with the driver: the first joint state locks the
  samples' phase to the driver's cycle, and sample k is taken in the callback of the driver's
  state for the time kT + phase (the nearest one, carried to that time when the driver's period
  does not divide T), stamped kT; a driver whose period is over half of T and does not divide
  it (125 Hz under 10 ms) has the loop built again at the first start with T the multiple of
  its period nearest T (``period_from_driver``). The feedforward's plan, inside this node
  (:class:`apc_feedforward.goals.GoalQueue`, as joint_trajectory_controller samples its
  trajectory in ``update()``), gives set point k and the nominal torque ``u_n`` of the sample
  its command acts over (``feedforward_ahead``: ``u_n((k + m + 1/2) T)`` when it acts m whole
  samples late, the middle of the interval it is held over; else ``u_n(kT)``): the first
  sample holds the measured position (or starts ``move.goal_deg``), goals on
  ``feedforward/trajectory`` (``trajectory_msgs/JointTrajectory``, any joint order) start when
  the motion before them ends. The command ``u_n + du(k)`` goes out in the same callback as
  ``std_msgs/Float64MultiArray`` on ``command_topic`` in ``command_joints`` order, clipped to
  the URDF's effort limits, with the QoS forward_command_controller subscribes with
  (``SystemDefaultsQoS``). For observers (a recorder), the sample goes out on
  ``feedback/sample`` and its set point on ``feedforward/setpoint`` (its effort the ``u_n``
  sent) when someone listens;
  goals are taken only while active;
- ``deactivate`` sends one command holding the arm against gravity at the measured position
  (the controller's model) and then none: forward_command_controller keeps applying the last
  command it got, and an inactive controller must leave the joints to whoever takes them over;
- ``cleanup`` drops the model and the subscriptions, ``shutdown`` does the same from any state
  (sending the gravity hold first if active).

Faults (counted and on ``/diagnostics``): no fresh joint state within ``watchdog`` (checked
every T by a timer on the node clock, which honours ``use_sim_time``) -> the gravity hold
once, then silence until states return (then the arm brought to rest from its measured state
over ``stop_time``, the phase locked afresh); tracking error beyond ``path_tolerance`` while a
goal moves -> the goal is aborted and the arm brought to rest the same way. See
:mod:`apc_feedback.robot_loop` for why.

Timing on ``/diagnostics`` (median, p99 and max over the last 1000 samples, in us):
``state_age_*`` (a state's age when its callback runs), ``state_to_command_*`` (its stamp to
its command's publish), ``sample_phase_*``, ``carry_*`` (how far states are carried to their
sample's time) and ``driver_period_*`` (estimated from the stamps); see
:class:`apc_feedback.sample_timing.SampleTiming`.

The adaptive law is supervised (``supervisor.*``, :mod:`apc_feedback.supervisor`): when it goes
wrong a fallback law (computed torque by default) commands until the error settles, and every
trigger and hand-over is counted (``supervisor.<trigger>``, ``supervisor.handovers``,
``supervisor.handbacks``). Its model of its input is there too: ``law.input_delay_ms`` (the
delay its prior splits a command by: one driver period, or two once the data say the drive adds
a cycle, ``input_delay_changes`` counting the switches), ``law.input_lags`` and
``law.q_input_change`` (the input change's weight in use, as ``input_ring_limit`` raised it,
"at its cap" where the limit is out of reach); and what the
samples' velocity is, ``velocity_kind``: ``driver`` (taken as the arm's), ``difference`` (the
driver's backward difference of its positions, found from its states in motion: the law then
models its lag, restarting its identification once, ``velocity_kind_changes``),
``sample_estimate`` (a drive's difference over a short span, at most ``short_difference`` of T:
a 1 kHz drive at T = 10 ms, replaced by the estimate from its positions over T, whose quantised
counts then chatter less) or ``estimated`` (from positions, for a driver that sends none);
and ``command_applied_ms``, the delay from a state to the arm applying the command computed
from it, as the driver's effort shows it (:class:`apc_feedback.command_echo.CommandEcho`;
``unknown`` for a driver whose effort is a measured torque or that sends none), which the law
models from a sample on (``measured_delay_changes``).
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from typing import Any

import numpy as np
import pinocchio as pin
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import QoSPresetProfiles
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory

import apc_msgs_py as wire
from apc_core.node_logs import level_logger
from apc_core.nodeutil import (
    Diagnostics,
    DiagnosticsPublisher,
    guarded,
    print_help,
    reject,
    run_nodes,
    split_ros_args,
)
from apc_core.params import ConfigError, Param, declare, params_from, subset
from apc_core.robot_params import CONTROLLER_ROBOT_PARAMS, controller_robot_from_params
from apc_feedback.command_echo import CommandEcho
from apc_feedback.command_map import CommandMap
from apc_feedback.controller import AdaptiveFeedback, FeedbackError
from apc_feedback.feedback_law import FeedbackLaw
from apc_feedback.lagged_control import input_change_cap
from apc_feedback.laws import LawParameters
from apc_feedback.payload_estimate import (
    PayloadCarry,
    PayloadEstimateConfig,
    PayloadEstimateError,
    payload_carry,
)
from apc_feedback.presets import PRESET_PARAM, law_params, preset_rows
from apc_feedback.robot_loop import STOP_TIME_S, RobotLoop, Step
from apc_feedback.robot_sampling import (
    RobotSampler,
    RobotSamplingConfig,
    RobotSamplingError,
    StateRejectedError,
)
from apc_feedback.sample_timing import SampleTiming
from apc_feedback.supervisor import Supervisor, SupervisorConfig, SupervisorError, fallback_law
from apc_feedforward.goals import MOVE_PARAMS, GoalQueue, setpoint_message
from apc_msgs_py import JointSample

AUTOSTART_FLAG = "--autostart"


class RobotDiagnostics(Diagnostics):
    """A node's :class:`Diagnostics` plus robot mode's sample timing (``timing``, when set),
    refreshed whenever the status is built."""

    timing: SampleTiming | None = None
    law: FeedbackLaw | None = None
    sampler: RobotSampler | None = None
    echo: CommandEcho | None = None
    payload: PayloadCarry | None = None

    def status(self) -> DiagnosticStatus:
        if self.timing is not None:
            for key, value in self.timing.figures().items():
                self.values[key] = f"{value:.1f}"
        if self.sampler is not None:
            self.values["velocity_kind"] = self.sampler.velocity_kind
            self.values["sampling_period_s"] = f"{self.sampler.period_ns * 1e-9:.6g}"
        if self.echo is not None:
            delay = self.echo.delay_ns
            self.values["command_applied_ms"] = (
                "unknown" if delay is None else f"{delay * 1e-6:.2f}"
            )
        if self.payload is not None:  # payload_estimate: what the model carries, as measured
            measured = self.payload.measured_kg
            self.values["payload_kg"] = f"{self.payload.carried_kg:.3g}"
            self.values["payload_measured_kg"] = (
                "unknown" if measured is None else f"{measured:.3g}"
            )
        # The adaptive law's model of its input: the delay and the lags it carries.
        if isinstance(self.law, AdaptiveFeedback):
            self.values["law.input_delay_ms"] = f"{self.law.input_timing.delay * 1e3:.2f}"
            self.values["law.input_lags"] = str(self.law.config.input_lags)
            weight = self.law.input_change_weight
            capped = weight > 0.0 and weight >= input_change_cap(self.law.config.q_input_change)
            self.values["law.q_input_change"] = f"{weight:.4g}" + (
                " (at its cap: input_ring_limit out of reach)" if capped else ""
            )
        return super().status()


PARAMS: tuple[Param, ...] = (
    *CONTROLLER_ROBOT_PARAMS,
    # The law's parameters, all read at configure (none changes while active); the preset
    # gives the adaptive ones their defaults (shown here: the default preset's).
    PRESET_PARAM,
    *(replace(p, read_only=True) for p in law_params()),
    Param(
        "command_topic",
        "/effort_controller/commands",
        "where the total torque goes (std_msgs/Float64MultiArray): an effort "
        "forward_command_controller's ~/commands",
    ),
    Param(
        "command_joints",
        [],
        "joint order of the command (the controller's 'joints'); empty = the URDF's order",
        array_of=str,
    ),
    *MOVE_PARAMS,
    *params_from(RobotSamplingConfig, ""),
    Param(
        "path_tolerance",
        [],
        "largest |q - q_d| (rad) while a goal moves, one per joint or one for all; beyond it "
        "the goal is aborted and the arm brought to rest; empty or 0 = no check",
    ),
    Param(
        "stop_time",
        STOP_TIME_S,
        "after a watchdog fault or a path-tolerance abort the arm is brought to rest from its "
        "measured state over this (s); 0 = hold the measured position at once",
        0.0,
        10.0,
    ),
    Param(
        "command_first",
        False,
        "the adaptive law sends each command from the gain planned at the sample before, and "
        "identifies and plans after it has left (for short periods: T = 1 ms; a law with a "
        "receding plan, every preset but paper)",
    ),
    Param(
        "feedforward_ahead",
        True,
        "the nominal torque sent with a sample is the plan's over the interval in which the "
        "adaptive law models its command acting (whole samples of its input delay later: a "
        "driver period of about T or more), at that interval's middle; false: at the sample's "
        "own time",
    ),
    Param(
        "period_from_driver",
        True,
        "at the first start after activation, a driver whose period is over half of 'period' "
        "and does not divide it (125 Hz under 0.01 s) sets the sampling period to the multiple "
        "of its period nearest 'period' (logged; 'sampling_period_s' on /diagnostics); false: "
        "'period' stays, with a warning",
    ),
    *params_from(SupervisorConfig, "supervisor."),
    *params_from(PayloadEstimateConfig, "payload_estimate."),
    Param("autostart", False, "configure and activate at start (also: --autostart)"),
)


def _per_joint(name: str, values: list[float], n: int) -> np.ndarray:
    if not values:
        return np.zeros(n)
    if len(values) not in (1, n):
        raise ConfigError(f"parameter '{name}': needs 1 or {n} values, got {len(values)}")
    array = np.broadcast_to(np.asarray(values, dtype=float), (n,)).copy()
    if not (np.isfinite(array).all() and (array >= 0.0).all()):
        raise ConfigError(f"parameter '{name}': values must be finite and >= 0, got {values}")
    return array


class RobotNode(LifecycleNode):
    """The commanding node of robot mode (see module docstring)."""

    def __init__(self, node_name: str = "robot_node", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        preset = declare(self, (PRESET_PARAM,))[PRESET_PARAM.name]
        self._declared = declare(self, preset_rows(PARAMS, preset))
        self.diagnostics = RobotDiagnostics(self.get_fully_qualified_name())
        self.diagnostics.message = "unconfigured"
        DiagnosticsPublisher(self, self.diagnostics)
        self.loop: RobotLoop | None = None
        self._timer: Any = None
        self._entities: list[Any] = []
        self.configure_error = ""
        if self._declared["autostart"]:
            self.trigger_configure()
            if self.configure_error:
                raise ConfigError(self.configure_error)
            self.trigger_activate()

    # -- lifecycle ------------------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self._configure()
        except ValueError as exc:  # ConfigError; a model or wire error
            self.configure_error = str(exc)
            self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        self.configure_error = ""
        self.diagnostics.message = "inactive"
        return TransitionCallbackReturn.SUCCESS

    def _configure(self) -> None:
        values = self._declared
        robot = self._robot = controller_robot_from_params(values)
        topic = values["command_topic"]
        if not topic.startswith("/"):
            raise ConfigError(f"parameter 'command_topic': must be absolute, got {topic!r}")
        self.joint_names = robot.joint_names
        self.loop = self._build_loop(values["period"])
        diag = self.diagnostics
        self._sample_msg = JointState()
        self._setpoint_msg = JointTrajectory()
        self._command_msg = Float64MultiArray()
        out_qos = wire.writer_qos(wire.CONTROL_QOS)
        self.command_pub = self.create_publisher(
            Float64MultiArray, topic, QoSPresetProfiles.SYSTEM_DEFAULT.value
        )
        self.sample_pub = self.create_publisher(JointState, wire.SAMPLE, out_qos)
        self.setpoint_pub = self.create_publisher(JointTrajectory, wire.SETPOINT, out_qos)
        # Best effort matches a driver's reliable and best-effort publishers alike. States
        # that queue behind a callback that overran are all taken by the next one
        # (_on_joint_state): observed, and only one whose next sample's state is not in hand
        # answered.
        states = self._state_reader = self.create_subscription(
            JointState,
            wire.JOINT_STATES,
            guarded(self, diag, wire.JOINT_STATES, self._on_joint_state),
            QoSPresetProfiles.SENSOR_DATA.value,
        )
        goals = self.create_subscription(
            JointTrajectory,
            wire.TRAJECTORY_GOAL,
            guarded(self, diag, wire.TRAJECTORY_GOAL, self._on_goal),
            wire.TRAJECTORY_GOAL_QOS,
        )
        self._entities = [self.command_pub, self.sample_pub, self.setpoint_pub, states, goals]
        self.get_logger().info(
            f"configured: {robot.n_joints} joints, T = {values['period']} s, command on "
            f"'{topic}' in order {list(self.loop.command.joints)}"
        )

    def _build_loop(self, period: float, from_driver: bool = True) -> RobotLoop:
        """Robot mode's loop at the sampling period ``period`` (s), from the parameters (a
        ConfigError names a bad one), judging the driver's period at its first start if
        ``from_driver`` and ``period_from_driver``; the diagnostics report on it."""
        values, robot, diag = {**self._declared, "period": period}, self._robot, self.diagnostics
        law = LawParameters(values, robot).law
        try:
            sampling = RobotSamplingConfig(
                period=period,
                **{
                    f: values[f]
                    for f in ("max_age", "watchdog", "velocity_window", "short_difference")
                },
            )
        except RobotSamplingError as exc:
            raise ConfigError(f"parameter '{exc.field}': {exc}") from None
        command_joints = values["command_joints"] or list(robot.joint_names)
        try:
            command = CommandMap(robot.joint_names, command_joints, robot.effort_limit, diag.count)
        except ValueError as exc:
            raise ConfigError(f"parameter 'command_joints': {exc}") from None
        model = robot.model
        data = model.createData()
        loop = RobotLoop(
            law=law,
            sampling=sampling,
            command=command,
            plan=GoalQueue.from_params(robot, values, interval_middle=values["feedforward_ahead"]),
            gravity=lambda q: pin.computeGeneralizedGravity(model, data, q).copy(),
            path_tolerance=_per_joint("path_tolerance", values["path_tolerance"], robot.n_joints),
            stop_time=values["stop_time"],
            command_first=values["command_first"],
            feedforward_ahead=values["feedforward_ahead"],
            period_from_driver=from_driver and values["period_from_driver"],
            payload=self._payload(values, robot, period),
            count=diag.count,
            log=level_logger(self),
            **self._supervision(values, robot),
        )
        diag.timing, diag.law = loop.timing, loop.law
        diag.sampler, diag.echo, diag.payload = loop.sampler, loop.echo, loop.payload
        self._period_ns = wire.seconds_to_ns(period)
        return loop

    def _retime(self, period: float) -> None:
        """The loop asked, at its first start, for a sampling period that is a multiple of the
        driver's (``period_from_driver``): build it again at ``period``, once an activation,
        and activate it with the goals accepted since activation; the next states start it."""
        old = self.loop
        assert old is not None
        driver_ms = old.sampler.driver_period_ns * 1e-6
        try:
            loop = self._build_loop(period, from_driver=False)
        except ValueError as exc:  # keep T: the old loop starts at the next state, and warns
            old.period_from_driver = False
            self.get_logger().error(f"sampling at {period:.6g} s: {exc}; keeping 'period'")
            return
        self.loop = loop
        self._watch()
        loop.activate()
        loop.plan.queued.extend(old.plan.queued)  # accepted (and counted) once
        self.get_logger().warn(
            f"the driver's period {driver_ms:.3g} ms does not divide 'period' "
            f"{old.sampling.period:g} s: sampling at {period:.6g} s, the multiple of it nearest "
            "(period_from_driver; false keeps 'period')"
        )

    @staticmethod
    def _payload(values: dict[str, Any], robot: Any, period: float) -> PayloadCarry | None:
        """The payload's estimate in the hold (``payload_estimate.*``) for the adaptive law;
        None if disabled, and for another law (a baseline keeps the model it is given)."""
        try:
            config = PayloadEstimateConfig.from_dict(subset(values, "payload_estimate."))
            if values["controller"] != "adaptive":
                return None
            return payload_carry(robot, config, period)
        except PayloadEstimateError as exc:
            raise ConfigError(f"parameter 'payload_estimate.{exc.field}': {exc}") from None

    @staticmethod
    def _supervision(values: dict[str, Any], robot: Any) -> dict:
        """The supervisor and its fallback law for the adaptive law (none for another law, or
        with ``supervisor.enable`` false)."""
        try:
            config = SupervisorConfig.from_dict(subset(values, "supervisor."))
        except SupervisorError as exc:
            raise ConfigError(f"parameter 'supervisor.{exc.field}': {exc}") from None
        if not config.enable or values["controller"] != "adaptive":
            return {}
        period = values["period"]
        try:
            fallback = fallback_law(config, robot, period, subset(values, "pid."))
        except FeedbackError as exc:
            raise ConfigError(f"parameter 'pid.{exc.field}': {exc}") from None
        return {
            "supervisor": Supervisor(config, robot.n_joints, period),
            "fallback": fallback,
        }

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        assert self.loop is not None
        if self.loop.sampling.period != self._declared["period"]:  # retimed last activation
            self.loop = self._build_loop(self._declared["period"])  # judged afresh
        self.loop.activate()
        self._watch()
        self.diagnostics.message = "active"
        self.get_logger().info("active: holding the measured position until a goal arrives")
        return super().on_activate(state)

    def _watch(self) -> None:
        """The watchdog's timer at the loop's sampling period (one before it destroyed)."""
        assert self.loop is not None
        if self._timer is not None:
            self.destroy_timer(self._timer)
        self._timer = self.create_timer(
            self.loop.sampling.period,
            guarded(self, self.diagnostics, "watchdog_check", self._on_watchdog),
        )

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop("inactive")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._release()
        self.diagnostics.message = "unconfigured"
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.loop is not None and self.loop.active:
            self._stop("finalized")
        self._release()
        self.diagnostics.message = "finalized"
        return TransitionCallbackReturn.SUCCESS

    def _stop(self, message: str) -> None:
        """Cancel the timer and send the gravity hold once (see the module docstring)."""
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        assert self.loop is not None
        self._publish(Step(command=self.loop.deactivate()))
        self.diagnostics.message = message
        self.diagnostics.level = DiagnosticStatus.OK
        self.get_logger().info(f"{message}: sent the gravity hold, commanding nothing more")

    def _release(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None
        for entity in self._entities:
            if hasattr(entity, "publish"):
                self.destroy_publisher(entity)
            else:
                self.destroy_subscription(entity)
        self._entities = []
        self.loop = None

    # -- loop -----------------------------------------------------------------------------------
    def _now(self) -> int:
        return self.get_clock().now().nanoseconds

    def _on_joint_state(self, msg: JointState) -> None:
        loop = self.loop
        if loop is None:
            return
        # The states queued behind this callback (the last one overran): each sampled in
        # turn, none answered where the next sample's state is already in hand (on wall time
        # at 1 kHz, answering each in turn sampled states 4-5 ms old for tens of samples).
        queued = [msg]
        reader = self._state_reader
        while (taken := reader.handle.take_message(reader.msg_type, reader.raw)) is not None:
            queued.append(taken[0])
        samples = []
        for each in queued:
            try:
                samples.append(
                    wire.joint_state_to_arrays(
                        each, self.joint_names, require=("position",), allow_extra=True
                    )
                )
            except wire.WireError as exc:
                reject(self, self.diagnostics, wire.JOINT_STATES, exc)
        newest_ns = samples[-1].stamp_ns if samples else None
        for i, sample in enumerate(samples):  # self.loop: a retime replaces it
            self._on_sample(self.loop, sample, newest_ns if i + 1 < len(samples) else None)

    def _on_sample(self, loop: RobotLoop, sample: JointSample, newest_ns: int | None) -> None:
        started = time.perf_counter()
        try:
            step = loop.on_joint_state(sample, self._now(), newest_ns)
        except StateRejectedError as exc:
            self.diagnostics.count(exc.reason)
            reject(self, self.diagnostics, wire.JOINT_STATES, exc)
            return
        if step.retime is not None:
            self._retime(step.retime)
            return
        if step.sample is not None:  # the law's time: most states are no sample
            self.diagnostics.time("compute", time.perf_counter() - started)
        self._publish(step)
        if step.sample is not None:
            self._show_state(loop)

    def _on_goal(self, msg: JointTrajectory) -> None:
        loop = self.loop
        try:
            if loop is None or not loop.active:
                raise wire.WireError("robot_node is not active: goals are taken only while active")
            loop.add_goal(wire.msg_to_trajectory_goal(msg, self.joint_names))
        except ValueError as exc:  # WireError, TrajectoryError
            reject(self, self.diagnostics, wire.TRAJECTORY_GOAL, exc)

    def _on_watchdog(self) -> None:
        loop = self.loop
        if loop is None or not loop.active:
            return
        self._publish(loop.tick(self._now()))
        self._show_state(loop)

    def _show_state(self, loop: RobotLoop) -> None:
        diag = self.diagnostics
        diag.level = DiagnosticStatus.ERROR if loop.faulted else DiagnosticStatus.OK
        diag.message = "watchdog: no fresh joint state" if loop.faulted else "active"

    def _publish(self, step: Step) -> None:
        # The command first: the driver waits for it; the rest is for observers, built only
        # for a listener.
        if step.command is not None:
            self._command_msg.data = step.command.tolist()
            self.command_pub.publish(self._command_msg)
            assert self.loop is not None
            started = time.perf_counter()
            self.loop.command_published(self._now())
            if self.loop.command_first:  # the law's learning, after the command
                self.diagnostics.time("learn", time.perf_counter() - started)
        sample, setpoint = step.sample, step.setpoint
        if sample is not None and self.sample_pub.get_subscription_count():
            self.sample_pub.publish(
                wire.arrays_to_joint_state(
                    sample.stamp_ns,
                    self.joint_names,
                    sample.position,
                    sample.velocity,
                    msg=self._sample_msg,
                )
            )
        if setpoint is not None and self.setpoint_pub.get_subscription_count():
            self.setpoint_pub.publish(
                setpoint_message(setpoint, self._period_ns, self.joint_names, self._setpoint_msg)
            )


def _help() -> None:
    print_help("robot_node", __doc__ or "", PARAMS)


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if args is None else args)
    user = split_ros_args(argv)[0]
    overrides = []
    if AUTOSTART_FLAG in user:
        argv.remove(AUTOSTART_FLAG)
        overrides = ["--ros-args", "-p", "autostart:=true"]
    return run_nodes(
        lambda: [RobotNode(cli_args=overrides or None)],
        prog="robot_node",
        print_help=_help,
        args=argv,
    )


if __name__ == "__main__":
    sys.exit(main())
