"""``plant_node``: the simulated arm on the wire, in lockstep or in real time.

It publishes ``joint_states`` stamped ``kT`` (``effort`` = torque applied over the period that
ended at ``k``) and ``/clock``, receives ``u_n(k)`` on ``feedforward/torque`` and ``du(k)`` on
``feedback/torque``, applies their sum (clipped to the URDF effort limits) over one period and
integrates (RK4, :mod:`apc_plant_sim.plant`).

Modes
-----
``lockstep`` (deterministic; what ``experiment`` uses)
    The plant owns time. It advances only when it holds both torques stamped ``kT``. If they
    do not come within ``resend_s`` it re-sends ``joint_states(k)`` (the controllers answer
    from a cache); after ``lockstep_timeout_s`` the run ends with a clear error.
``realtime`` (a robot's reality; the default for ``ros2 run``)
    A wall timer of period T steps the arm with the newest torques it holds. Torques stamped
    earlier than the sample are *late*, none at all *missing*; both are counted, never waited
    for. With ``use_sim_time`` the timer (and every time the node measures) runs on ``/clock``
    from elsewhere instead, and ``publish_clock`` must be false: whoever publishes ``/clock``
    decides when each period ends, so a test reproduces a real-time run, its late torques,
    watchdog and brake, sample by sample whatever the machine's load.
    Safe policy: with no fresh feedback torque for ``watchdog_s`` the nominal torque alone is
    applied (reported as a warning); with no fresh nominal torque for ``watchdog_s`` the
    arm *brakes* -- integration stops with zero velocity, as a PUMA's brakes would hold it --
    and a fault is reported until fresh torques return.

In both modes the arm stays still (brakes on) until ``wait_for_subscribers`` nodes listen to
``joint_states`` and both torque topics have a publisher; then sample 0 is sent (in real
time, again every ``resend_s`` until both torques answer it, then the clock runs).

``n_samples > 0`` ends the node after that many periods (``experiment``); 0 runs until stopped.
"""

from __future__ import annotations

import functools
import sys
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState

import apc_msgs_py as wire
from apc_core.nodeutil import (
    Diagnostics,
    DiagnosticsPublisher,
    Stopwatch,
    guarded,
    publish_robot_description,
    reject,
    run_node,
)
from apc_core.params import ConfigError, Param, declare
from apc_core.robot_params import ROBOT_PARAMS, fill_derived, robot_from_params, urdf_xml
from apc_plant_sim.intake import WATCHDOG_PARAMS, Action, Filed, Source, TorqueIntake
from apc_plant_sim.pacing import PACING_PARAMS, StatePacer
from apc_plant_sim.plant import PlantError
from apc_plant_sim.true_arm import TRUE_ARM_PARAMS, TrueArm

MODES = ("realtime", "lockstep")

#: Parameters that, left empty, take a default derived from the URDF (-> ArmDefaults field).
DERIVED = {"q_initial_deg": "q_start_deg", "payload.frame": "payload_frame"}

PARAMS: tuple[Param, ...] = (
    *ROBOT_PARAMS,
    *TRUE_ARM_PARAMS,
    Param(
        "mode",
        "realtime",
        "'realtime' (a timer of period T, on /clock with use_sim_time; newest torques) or "
        "'lockstep'",
    ),
    Param("n_samples", 0, "stop after this many periods; 0 = run until stopped", 0, 10**9),
    Param(
        "wait_for_subscribers",
        2,
        "start when this many nodes subscribe to joint_states (2: ff and fb; 3 with a recorder)",
        0,
        1000,
    ),
    *PACING_PARAMS,
    *WATCHDOG_PARAMS,
    Param(
        "publish_clock",
        True,
        "publish /clock = kT (sim time for use_sim_time nodes); false with use_sim_time",
    ),
)


class PlantNode(Node):
    """Composable plant node (see module docstring).

    Attributes
    ----------
    done : bool
        The run has ended (``n_samples`` reached, or a lockstep timeout).
    exit_code : int
        0 on success, 1 after a lockstep timeout.
    """

    def __init__(
        self, node_name: str = "plant_node", *, qos: QoSProfile | None = None, **kwargs: Any
    ) -> None:
        super().__init__(node_name, **kwargs)
        qos = qos or wire.CONTROL_QOS
        values = declare(self, PARAMS)
        robot = robot_from_params(values)
        self.joint_names = robot.joint_names
        self.mode = values["mode"]
        if self.mode not in MODES:
            raise ConfigError(
                f"parameter 'mode': must be one of {', '.join(MODES)}, got {self.mode!r}"
            )
        # The clock of the real-time timer and of every time measured here: steady wall time,
        # or /clock from elsewhere with use_sim_time (the plant then never publishes /clock: it
        # would step on its own time). Lockstep owns time.
        sim_time = bool(self.get_parameter("use_sim_time").value)
        if sim_time and self.mode == "lockstep":
            raise ConfigError(
                "parameter 'use_sim_time': lockstep owns time (it publishes /clock); "
                "use mode 'realtime' to step on /clock from elsewhere"
            )
        if sim_time and values["publish_clock"]:
            raise ConfigError(
                "parameter 'publish_clock': must be false with use_sim_time (the plant would "
                "step on its own /clock)"
            )
        self._wall = Clock(clock_type=ClockType.STEADY_TIME)
        self._clock = self.get_clock() if sim_time else self._wall
        chosen = fill_derived(values, robot, DERIVED)
        self.arm = TrueArm.from_params(robot, values)
        for line in chosen:
            self.get_logger().info(line)
        self.plant = self.arm.plant
        self.period_ns = wire.seconds_to_ns(self.plant.config.period)
        self.n_samples = values["n_samples"]
        self._values = values
        self.diagnostics = Diagnostics(self.get_fully_qualified_name())
        self.diagnostics.set("mode", self.mode)
        self.done = False
        self.exit_code = 0
        self.intake = TorqueIntake.from_params(self.period_ns, self.mode == "lockstep", values)
        self._applied: np.ndarray | None = None
        self.pacer = StatePacer.from_params(values, now=self._now())
        self._js_msg = JointState()
        self._clock_msg = ClockMsg()

        self.js_pub = self.create_publisher(JointState, wire.JOINT_STATES, wire.writer_qos(qos))
        self.description_pub = publish_robot_description(self, urdf_xml(values))
        self.clock_pub = (
            self.create_publisher(ClockMsg, wire.CLOCK, wire.CLOCK_QOS)
            if values["publish_clock"]
            else None
        )
        diag = self.diagnostics
        # Real time applies the newest torque and never waits for one: a reliable subscription
        # would hold every later torque back until a lost one is repaired (head-of-line
        # blocking: with FastDDS's defaults on a lossy link, longer than the watchdog, so the
        # arm braked mid-move; docs/reliability.md). Best effort matches the controllers' reliable
        # publishers and hands over what arrives. Lockstep needs every sample: reliable.
        torque_qos = qos
        if self.mode != "lockstep":
            torque_qos = QoSProfile(history=qos.history, depth=qos.depth, durability=qos.durability)
            torque_qos.reliability = ReliabilityPolicy.BEST_EFFORT
        self.ff_sub, self.fb_sub = (
            self.create_subscription(
                JointState,
                source.value,
                guarded(self, diag, source.value, functools.partial(self._take, source)),
                torque_qos,
            )
            for source in Source
        )
        self._diagnostics_pub = DiagnosticsPublisher(self, self.diagnostics)
        if self.mode == "lockstep":
            tick = guarded(self, diag, "lockstep_watch", self._lockstep_watch)
            self._timer = self.create_timer(0.01, tick, clock=self._wall)
        else:
            tick = guarded(self, diag, "realtime_tick", self._realtime_tick)
            self._timer = self.create_timer(self.plant.config.period, tick, clock=self._clock)

    # -- wire -----------------------------------------------------------------------------------
    @property
    def k(self) -> int:
        return self.plant.k

    def _now(self) -> float:
        """The time of the node's timer (s): steady wall time, or /clock with use_sim_time."""
        return self._clock.now().nanoseconds / wire.NS_PER_S

    def _publish_state(self, resend: bool = False) -> None:
        stamp = self.k * self.period_ns
        # /clock only for a listener (use_sim_time nodes, a recorder): nobody else needs it.
        if self.clock_pub is not None and self.clock_pub.get_subscription_count() > 0:
            self._clock_msg.clock = wire.ns_to_stamp(stamp, self._clock_msg.clock)
            self.clock_pub.publish(self._clock_msg)
        try:
            msg = wire.arrays_to_joint_state(
                stamp,
                self.joint_names,
                position=self.plant.q,
                velocity=self.plant.qd,
                effort=self._applied,
                msg=self._js_msg,
            )
        except wire.WireError as exc:  # a state beyond the wire's bound: the simulation blew up
            self._fail(f"sample {self.k}: the arm's state cannot be published ({exc})")
            return
        self.js_pub.publish(msg)
        self.pacer.sent(self._now(), resend)

    @property
    def started(self) -> bool:
        return self.intake.started

    def _take(self, source: Source, msg: JointState) -> None:
        """File a torque with the intake; count what it did (see ``TorqueIntake.take``)."""
        topic = source.value
        try:
            torque = wire.msg_to_torque(msg, self.joint_names)
            filed = self.intake.take(source, torque.stamp_ns, torque.effort, self.k)
        except wire.WireError as exc:
            reject(self, self.diagnostics, topic, exc)
            return
        if filed not in (Filed.TAKEN, Filed.AHEAD):
            self.diagnostics.count(f"{filed.value}.{topic}")
            return
        if filed is Filed.TAKEN and torque.stamp_ns == self.k * self.period_ns:
            self.diagnostics.time(f"latency.{topic}", self.pacer.waited(self._now()))
        if self.intake.lockstep:
            self._lockstep_try()

    # -- lockstep -------------------------------------------------------------------------------
    def _start_when_ready(self, what: str) -> None:
        """Send sample 0 once ``wait_for_subscribers`` nodes listen and both torque topics have
        a publisher; until then the arm stays still, like a robot whose brakes stay on until
        its controllers are up."""
        if not self._missing_peers():
            self.intake.started = True
            self.get_logger().info(f"{what}: starting at sample {self.k}")
            self._publish_state()

    def _lockstep_watch(self) -> None:
        if self.done:
            return
        if not self.started:
            self._start_when_ready("lockstep")
            if not self.started and self.pacer.start_timed_out(self._now()):
                self._fail(
                    f"lockstep: peers missing after {self._values['lockstep_timeout_s']} s: "
                    f"{self._missing_peers()}"
                )
            return
        now = self._now()
        if self.pacer.sample_timed_out(now):
            missing = [source.value for source in self.intake.missing(self.k)]
            self._fail(
                f"lockstep: no {' and no '.join(missing)} for sample {self.k} after "
                f"{self.pacer.waited(now):.1f} s; ending the run (is the peer node running?)"
            )
        elif self.pacer.resend_due(now):
            self.diagnostics.count("resent")
            self._publish_state(resend=True)

    def _missing_peers(self) -> str:
        """The peers sample 0 waits for that are not there ("" when all are)."""
        missing = []
        subscribers = self.js_pub.get_subscription_count()
        wanted = self._values["wait_for_subscribers"]
        if subscribers < wanted:
            missing.append(f"{subscribers} of {wanted} subscribers on {wire.JOINT_STATES}")
        for source, sub in zip(Source, (self.ff_sub, self.fb_sub), strict=True):
            if sub.get_publisher_count() < 1:
                missing.append(f"no publisher on {source.value}")
        return "; ".join(missing)

    def _fail(self, message: str) -> None:
        self.get_logger().error(message)
        self.diagnostics.level = DiagnosticStatus.ERROR
        self.diagnostics.message = message
        self.exit_code = 1
        self._finish()

    def _finish(self) -> None:
        """End the run and report the final counters on ``/diagnostics`` at once."""
        self.done = True
        self._diagnostics_pub.publish()

    def _lockstep_try(self) -> None:
        if self.done or not self.intake.complete(self.k):
            return
        if self.n_samples and self.k >= self.n_samples:
            # The torques of the final sample are in (recorded); nothing more to integrate.
            self._finish()
            return
        self._step(self.intake.pop(self.k))
        self._publish_state()

    def _step(self, tau: np.ndarray) -> None:
        if self.arm.pick_up():
            self.get_logger().info(f"sample {self.k}: payload picked up")
        with Stopwatch(self.diagnostics, "integrate"):
            try:
                result = self.plant.step(tau)
            except PlantError as exc:
                reject(self, self.diagnostics, "integrate", exc)
                self._applied = np.zeros(len(self.joint_names))
                return
        self._applied = result.applied
        if result.saturated.any():
            self.diagnostics.count("saturated_samples")
            for name in np.asarray(self.joint_names)[result.saturated]:
                self.diagnostics.count(f"saturated.{name}")
        self.diagnostics.count("samples")

    # -- real time ------------------------------------------------------------------------------
    def _realtime_tick(self) -> None:
        if self.done:
            return
        now = self._now()
        if not self.started:
            self._start_when_ready("real time")
            return
        tick = self.intake.tick(self.k)
        if tick.action is Action.WAIT:
            if self.pacer.resend_due(now):
                self._publish_state()  # sample 0 again, until both controllers answer it
            return
        diag = self.diagnostics
        for kind, sources in (("missing", tick.missing), ("late", tick.late)):
            for source in sources:
                diag.count(f"{kind}.{source.value}")
        if tick.missing or tick.late:
            diag.count("late_samples")
        if tick.action is Action.BRAKE:
            if tick.braking_starts:
                self.get_logger().error(
                    f"no fresh nominal torque for {self._values['watchdog_s']} s: braking"
                )
                diag.count("watchdog_trips")
            diag.level = DiagnosticStatus.ERROR
            diag.message = "no nominal torque: brakes engaged (holding position)"
            self.plant.brake()
            self._applied = np.zeros(len(self.joint_names))
            diag.count("braked_samples")
        else:
            if tick.braking_ends:
                self.get_logger().info("nominal torque back: releasing the brake")
                diag.level, diag.message = DiagnosticStatus.OK, "ok"
            if tick.action is Action.NOMINAL_ONLY:
                diag.count("feedback_missing_samples")
                diag.level = DiagnosticStatus.WARN
                diag.message = "no fresh feedback torque: applying nominal torque only"
            elif diag.level == DiagnosticStatus.WARN:
                diag.level, diag.message = DiagnosticStatus.OK, "ok"
            assert tick.tau is not None
            self._step(tick.tau)
        if hasattr(self, "_last_tick"):
            period = now - self._last_tick
            diag.time("period", period)
            diag.time("jitter", abs(period - self.plant.config.period))
        self._last_tick = now
        self._publish_state()
        if self.n_samples and self.k >= self.n_samples:
            self._finish()


def main(args: list[str] | None = None) -> int:
    return run_node(
        PlantNode,
        prog="plant_node",
        summary=__doc__ or "",
        params=PARAMS,
        args=args,
        spin_until=lambda node: node.done,
    )


if __name__ == "__main__":
    sys.exit(main())
