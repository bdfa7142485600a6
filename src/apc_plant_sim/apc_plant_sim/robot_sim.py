"""``robot_sim``: a simulated arm that behaves like a ros2_control robot, not like apc's plant.

It publishes ``/joint_states`` the way ``joint_state_broadcaster`` does (absolute topic,
``SystemDefaultsQoS``, its own rate ``state_rate``, stamped with its own clock, joints in
``state_joints`` order with optional extra joints, velocity and effort optional) and takes
efforts the way an effort ``forward_command_controller`` does (``std_msgs/Float64MultiArray``
on ``command_topic``, ``SystemDefaultsQoS``, one value per joint in ``command_joints`` order,
the newest one held). The loop, the command checks, the effort limits and the command timeout
are :class:`apc_plant_sim.robot_driver.RobotDriver`; the physics is ``engine``
(:mod:`apc_plant_sim.engines`): ``pinocchio`` (apc's plant) or ``mujoco`` (MuJoCo's own
dynamics and integrator, :mod:`apc_plant_sim.mujoco_engine`). ``effects`` and the parameters after
it add what a physical arm adds (friction, rotor inertia, encoder quantisation, the drive's
velocity, a command delay); ``ideal`` turns them all off.

Time
----
``sim_time: false`` (default): a wall timer runs the loop at ``state_rate``; each state is
stamped with its cycle's instant on the node's clock (system time), the instant its physics is
at, and a callback that runs late runs the cycles it stands for
(:class:`apc_plant_sim.robot_driver.WallCycles`). ``sim_time: true``: the node owns time,
publishes ``/clock`` and steps as fast as the controllers answer, the way Gazebo or MuJoCo are
run with ``use_sim_time``: after publishing the state at ``t`` it waits for a command received after
that state (or ``sim_wait_s`` of wall time) before it integrates to ``t + 1/state_rate``.
Controllers slower than the driver (``state_rate`` = 500 Hz, T = 10 ms) answer every
``sim_cycles_per_command`` cycles; the cycles in between step without waiting. Before the first
command the arm stands on its brakes and time moves one cycle every :data:`SIM_RESEND_S` (or
``sim_wait_s`` if shorter) of wall time: controllers that start later find a state, and
controllers on ``use_sim_time`` reach their first tick. Each state is published before the
``/clock`` that reaches its time, so a controller ticking then has it in hand.

The robot's clock, as parameters (what a test in simulated time reproduces of a robot on wall
time, deterministically): ``phase`` puts the driver's cycles at ``phase + i / state_rate``
(stamps, physics and, in sim time, ``/clock``; on wall time the timer's cycles are kept on
those instants of the system clock, best effort), offset from the controllers' sample grid ``kT``;
``command_latency`` (fixed, or drawn per command up to ``command_latency_max`` with ``seed``)
holds each command back from its arrival until the drive may apply it, from its first cycle
at or after that (:class:`apc_plant_sim.robot_driver.RobotDriver`). In sim time a command
arrives at the time of the state it answers (the controllers compute in no simulated time):
the driver still waits for it, then steps on and applies it once its latency has passed.
``missed_states`` (sim time) leaves a share of the cycles unpublished, as a driver on a loaded
machine misses cycles on wall time (``unpublished_cycles``: 1-3 % at 1 kHz on a 2-core
machine): the arm moves on and its drive still reads it, no state goes out. A cycle the driver
waits for a command after always publishes (in sim time the controllers answer what they get).
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import qos_profile_system_default
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

import apc_msgs_py as wire
from apc_core.nodeutil import (
    Diagnostics,
    DiagnosticsPublisher,
    guarded,
    run_node,
)
from apc_core.params import ConfigError, Param, declare
from apc_core.robot_params import ROBOT_PARAMS, fill_derived, robot_from_params
from apc_plant_sim.effects import ArmEffects
from apc_plant_sim.engines import (
    EFFECT_PRESETS,
    ENGINES,
    VELOCITY_SOURCES,
    EngineError,
    effects_from_values,
    make_engine,
)
from apc_plant_sim.mujoco_engine import INTEGRATORS
from apc_plant_sim.node import DERIVED as PLANT_DERIVED
from apc_plant_sim.robot_driver import (
    DriverConfig,
    DriverError,
    Reading,
    RobotDriver,
    WallCycles,
)
from apc_plant_sim.true_arm import TRUE_ARM_PARAMS, payload_from_params

#: Where ros2_control's ``joint_state_broadcaster`` publishes (``use_local_topics: false``).
JOINT_STATES_TOPIC = "/joint_states"
#: ``~/commands`` of an effort ``forward_command_controller`` named ``effort_controller``.
DEFAULT_COMMAND_TOPIC = "/effort_controller/commands"

#: sim_time: wall seconds between braked cycles until the first command arrives.
SIM_RESEND_S = 0.1
#: Wall time: how far (a fraction of the period) the timer's cycles may drift off ``phase``.
WALL_PHASE_TOLERANCE = 0.01

_DEFAULTS = DriverConfig()
#: The arm's start and payload, declared as ``plant_node`` declares them (``payload.at_s`` is
#: driver time since the first cycle here).
PLANT_ARM_PARAMS = tuple(
    p for p in TRUE_ARM_PARAMS if p.name == "q_initial_deg" or p.name.startswith("payload.")
)

PARAMS: tuple[Param, ...] = (
    *(p for p in ROBOT_PARAMS if p.name != "period"),
    Param("engine", "pinocchio", f"physics engine: {' or '.join(ENGINES)}"),
    Param(
        "state_rate",
        _DEFAULTS.state_rate,
        "driver cycle rate (Hz): one joint state and one physics period per cycle",
        1.0,
        10000.0,
    ),
    Param("command_topic", DEFAULT_COMMAND_TOPIC, "effort command topic (Float64MultiArray)"),
    Param(
        "command_joints",
        [],
        "joint order of the command's data; empty = the URDF's moving joints in order",
        array_of=str,
    ),
    Param(
        "command_timeout",
        _DEFAULTS.command_timeout,
        "seconds (driver clock) without a command before the drive applies zero effort",
        1e-4,
        3600.0,
    ),
    Param(
        "timeout_damping",
        _DEFAULTS.timeout_damping,
        "viscous braking after a command timeout (N m s/rad); 0 = zero effort alone",
        0.0,
        1e6,
    ),
    Param(
        "state_joints",
        [],
        "joint order of the published state; names not in the URDF are extra joints at "
        "extra_position (e.g. a gripper finger); empty = the URDF's order",
        array_of=str,
    ),
    Param("extra_position", _DEFAULTS.extra_position, "position of the extra joints", -1e3, 1e3),
    Param("publish_velocity", _DEFAULTS.publish_velocity, "fill JointState.velocity"),
    Param("publish_effort", _DEFAULTS.publish_effort, "fill JointState.effort (applied torque)"),
    Param(
        "effort_limit",
        [],
        "|torque| limit per joint (N m), commands clipped to it; empty = the URDF's limits",
    ),
    *PLANT_ARM_PARAMS,
    Param(
        "physics_step",
        0.001,
        "longest integration step (s); each driver period is split into equal steps",
        1e-6,
        1.0,
    ),
    Param(
        "mujoco.integrator",
        "RK4",
        f"mujoco engine: MuJoCo's integrator, one of {', '.join(INTEGRATORS)}",
    ),
    Param(
        "effects",
        "ideal",
        f"what a physical arm adds, as a preset: {', '.join(EFFECT_PRESETS)} (ideal: none; "
        "puma560: the 3-joint PUMA 560's motor, gear and friction data; panda: the Panda's "
        "identified friction); the parameters below override it one by one",
    ),
    Param("damping", [], "mujoco: viscous joint friction (N m s/rad per joint); empty = preset"),
    Param("frictionloss", [], "mujoco: Coulomb joint friction (N m per joint); empty = preset"),
    Param("armature", [], "mujoco: rotor inertia G^2 Jm (kg m^2 per joint); empty = preset"),
    Param(
        "encoder_counts_per_rev",
        [],
        "encoder counts per joint revolution (positions quantised); empty = preset",
    ),
    Param(
        "velocity_source",
        "",
        f"velocity the drive reports: {', '.join(VELOCITY_SOURCES)} (difference of quantised "
        "positions over one period); empty = preset",
    ),
    Param(
        "velocity_noise",
        -1.0,
        "standard deviation of the velocity noise (rad/s, velocity_source noisy); -1 = preset",
        -1.0,
        1e3,
    ),
    Param(
        "command_delay_cycles",
        -1,
        "whole driver periods between a command's arrival and its application, beyond the "
        "drive's own; -1 = preset",
        -1,
        1000,
    ),
    Param(
        "command_latency",
        _DEFAULTS.command_latency,
        "seconds (driver clock) from a command's arrival (sim_time: the time of the state it "
        "answers) until the drive may apply it, from its first cycle at or after that; 0 = the "
        "next cycle (sim_time: the same cycle)",
        0.0,
        10.0,
    ),
    Param(
        "command_latency_max",
        -1.0,
        ">= command_latency: each command's latency is drawn uniformly from [command_latency, "
        "command_latency_max] (seed; commands keep their order); < 0 = command_latency for all",
        -1.0,
        10.0,
    ),
    Param(
        "phase",
        _DEFAULTS.phase,
        "the driver's cycles are at phase + i / state_rate (s, below 1 / state_rate): their "
        "offset from the controllers' sample grid kT (sim_time: stamps and /clock; wall time: "
        "the timer's cycles, best effort)",
        0.0,
        1.0,
    ),
    Param(
        "missed_states",
        0.0,
        "sim_time: the share of the driver's cycles that publish no state (drawn with seed; "
        "never a cycle the driver waits for a command after), as a loaded machine's driver "
        "misses cycles on wall time",
        0.0,
        0.9,
    ),
    Param(
        "seed",
        0,
        "seed of the velocity noise, of the random command latency and of the missed states",
        0,
        2**31 - 1,
    ),
    Param("sim_time", False, "own the clock: publish /clock and step as the controllers answer"),
    Param(
        "sim_wait_s",
        0.5,
        "sim_time: wall seconds to wait for a command before stepping without one",
        1e-3,
        60.0,
    ),
    Param(
        "sim_cycles_per_command",
        1,
        "sim_time: driver cycles per controller command (state_rate x the controllers' "
        "period); the driver waits for a command every this many cycles",
        1,
        100000,
    ),
)


def _driver_config(values: dict[str, Any], effects: ArmEffects) -> DriverConfig:
    try:
        return DriverConfig(
            state_rate=values["state_rate"],
            command_timeout=values["command_timeout"],
            timeout_damping=values["timeout_damping"],
            command_joints=tuple(values["command_joints"]),
            state_joints=tuple(values["state_joints"]),
            extra_position=values["extra_position"],
            publish_velocity=values["publish_velocity"],
            publish_effort=values["publish_effort"],
            effort_limit=tuple(values["effort_limit"]),
            sensing=effects,
            command_latency=values["command_latency"],
            command_latency_max=(
                values["command_latency_max"] if values["command_latency_max"] >= 0.0 else None
            ),
            latency_seed=values["seed"],
            phase=values["phase"],
        )
    except DriverError as exc:
        raise ConfigError(f"parameter '{str(exc).split(':')[0]}': {exc}") from None


class RobotSimNode(Node):
    """The simulated ros2_control robot (see module docstring)."""

    def __init__(self, node_name: str = "robot_sim", **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        values = declare(self, PARAMS)
        robot = robot_from_params(values)
        n = robot.n_joints
        effects = effects_from_values(values, n)
        config = _driver_config(values, effects)
        chosen = fill_derived(values, robot, PLANT_DERIVED)
        q0 = values["q_initial_deg"]
        if len(q0) != n:
            raise ConfigError(f"parameter 'q_initial_deg': needs {n} values, got {len(q0)}")
        payload, _ = payload_from_params(robot, values)
        at_s = values["payload.at_s"] if payload.mass_kg > 0.0 else 0.0
        engine_name = values["engine"]
        self.engine = make_engine(
            engine_name,
            robot,
            payload,
            effects,
            period=config.period,
            max_step=values["physics_step"],
            q0=np.deg2rad(q0),
            loaded=at_s == 0.0,
            integrator=values["mujoco.integrator"],
        )
        for correction in getattr(self.engine, "corrections", ()):
            self.get_logger().info(
                f"MuJoCo: inertia of the body of {correction.joint} made physical: principal "
                f"moments {np.round(correction.before, 6).tolist()} -> "
                f"{np.round(correction.after, 6).tolist()} kg m^2"
                + (" (invisible to the joint-space dynamics)" if correction.invisible else "")
            )
        try:
            self.driver = RobotDriver(self.engine, config)
        except DriverError as exc:
            raise ConfigError(f"parameter '{str(exc).split(':')[0]}': {exc}") from None
        for line in chosen:
            self.get_logger().info(line)
        self._pickup_s = at_s
        self._fault = ""  # the physics' last failure, until a period integrates again
        self.sim_time = bool(values["sim_time"])
        self._sim_wait_s = float(values["sim_wait_s"])
        self.command_topic = values["command_topic"]
        self.diagnostics = Diagnostics(self.get_fully_qualified_name(), hardware_id="robot_sim")
        self.diagnostics.set("engine", engine_name)
        self.diagnostics.set("state_rate_hz", config.state_rate)
        self.diagnostics.set("phase_s", config.phase)
        self.diagnostics.set("command_latency_s", config.command_latency)
        if config.command_latency_max is not None:
            self.diagnostics.set("command_latency_max_s", config.command_latency_max)
        self._msg = JointState()
        self._clock_msg = ClockMsg()
        # joint_state_broadcaster and forward_command_controller both use SystemDefaultsQoS.
        self.state_pub = self.create_publisher(
            JointState, JOINT_STATES_TOPIC, qos_profile_system_default
        )
        self.clock_pub = (
            self.create_publisher(ClockMsg, wire.CLOCK, wire.CLOCK_QOS) if self.sim_time else None
        )
        self.command_sub = self.create_subscription(
            Float64MultiArray,
            self.command_topic,
            guarded(self, self.diagnostics, "command", self._on_command),
            qos_profile_system_default,
        )
        self._diagnostics_pub = DiagnosticsPublisher(self, self.diagnostics)
        self._wall = Clock(clock_type=ClockType.STEADY_TIME)
        # Driver time: the first cycle's sim time (phase), or the node's clock (system time) at
        # the first cycle.
        self._start: float | None = config.phase if self.sim_time else None
        self._k = 0  # sim time of the state last published: cycle k, config.cycle_time(k)
        self._t = config.phase
        self._cycles_per_command = int(values["sim_cycles_per_command"])
        self._missed_states = float(values["missed_states"])
        self._missed_draws = np.random.default_rng([int(values["seed"]), 1])
        self._published_wall = 0.0
        if self.sim_time:
            self._publish(self.driver.measure(self._t))
            tick = guarded(self, self.diagnostics, "sim_wait", self._sim_watch)
            self._timer = self.create_timer(min(self._sim_wait_s, 0.01), tick, clock=self._wall)
        else:
            self._wall_cycles = WallCycles(config)
            tick = guarded(self, self.diagnostics, "cycle", self._wall_cycle)
            self._timer = self.create_timer(config.period, tick, clock=self._wall)

    @property
    def driver_time(self) -> float:
        """Driver time since the first cycle (s): sim time, or wall time since it started."""
        if self.sim_time:
            return self._t - self.driver.config.phase
        return 0.0 if self._start is None else self._now() - self._start

    # -- wire -----------------------------------------------------------------------------------
    def _now(self) -> float:
        if self.sim_time:
            return self._t
        return self.get_clock().now().nanoseconds / wire.NS_PER_S

    def _on_command(self, msg: Float64MultiArray) -> None:
        reason = self.driver.offer(msg.data, self._now())
        if reason is not None:
            self.get_logger().warn(
                f"rejected command on '{self.command_topic}' ({self.driver.counts.rejected} so "
                f"far): {reason}",
                throttle_duration_sec=1.0,
            )
            self._sync_diagnostics()
            return
        if self.sim_time:
            self._sim_step()

    def _publish(self, reading: Reading, state: bool = True) -> None:
        """The state (unless ``state`` is False: a missed cycle) and, in sim time, /clock."""
        stamp_ns = round(reading.stamp * wire.NS_PER_S)
        if state:
            msg = wire.arrays_to_joint_state(
                stamp_ns,
                reading.names,
                position=reading.position,
                velocity=reading.velocity,
                effort=reading.effort,
                msg=self._msg,
            )
            self.state_pub.publish(msg)
        # /clock after the state it stamps: a controller whose timer fires when the clock
        # reaches t then has the state at t in hand (one period "ahead" of its clock until then).
        if self.clock_pub is not None:
            self._clock_msg.clock = wire.ns_to_stamp(stamp_ns, self._clock_msg.clock)
            self.clock_pub.publish(self._clock_msg)
        self._published_wall = time.monotonic()

    def _sync_diagnostics(self) -> None:
        counts = self.driver.counts
        counters = self.diagnostics.counters
        for key in (
            "commands",
            "rejected",
            "timeouts",
            "timeout_cycles",
            "clipped",
            "cycles",
            "held_command_cycles",
        ):
            counters[key] = getattr(counts, key)
        for name, value in counts.clipped_per_joint.items():
            counters[f"clipped.{name}"] = value
        if self._fault:
            self.diagnostics.level = DiagnosticStatus.ERROR
            self.diagnostics.message = self._fault
        elif self.driver.timed_out:
            self.diagnostics.level = DiagnosticStatus.WARN
            self.diagnostics.message = "command timeout: zero effort"
        elif self.driver.braked:
            self.diagnostics.message = "brakes on: waiting for the first command"
        else:
            self.diagnostics.level = DiagnosticStatus.OK
            self.diagnostics.message = "ok"

    def _cycle(self, now: float) -> None:
        """Apply the drive's torque from ``now`` for one period (``write()`` + physics)."""
        assert self._start is not None
        if self._pickup_s and now - self._start >= self._pickup_s:
            self.engine.load_payload()
            self._pickup_s = 0.0
            self.get_logger().info(f"t = {now - self._start:.3f} s: payload picked up")
        was_timed_out = self.driver.timed_out
        try:
            self.driver.advance(now)
            self._fault = ""
        except EngineError as exc:
            # The physics blew up (a command that drives the arm unstable): the arm is held
            # where it last was, as a drive's fault stop would, and the fault is reported.
            self.engine.hold()
            n = self.diagnostics.count("unstable_cycles")
            self._fault = f"physics unstable, arm held: {exc}"
            self.get_logger().error(
                f"{exc}; holding the arm ({n} so far)", throttle_duration_sec=1.0
            )
        if self.driver.timed_out and not was_timed_out:
            self.get_logger().warn(
                f"no command for {self.driver.config.command_timeout} s: applying zero effort"
            )
        self._sync_diagnostics()

    # -- wall time ------------------------------------------------------------------------------
    def _wall_cycle(self) -> None:
        if not self.context.ok():  # a signal between the timer's wake-up and this call
            return
        config = self.driver.config
        now_ns = self.get_clock().now().nanoseconds
        cycles = self._wall_cycles.due(now_ns)
        if self._start is None:
            self._start = config.cycle_time_ns(cycles[0]) / wire.NS_PER_S
        for i in cycles[:-1]:  # cycles the callbacks missed: the arm moved, no state went out
            self.diagnostics.count("unpublished_cycles")
            self._cycle(config.cycle_time_ns(i) / wire.NS_PER_S)
        instant = config.cycle_time_ns(cycles[-1]) / wire.NS_PER_S
        self._publish(self.driver.measure(instant))  # read() -> joint_state_broadcaster
        # The write takes what arrived before the callback runs: the timer's own latency is
        # the simulator's, not the transport's, and a real driver publishes at its instant.
        self._cycle(now_ns / wire.NS_PER_S)
        self._keep_phase()

    def _keep_phase(self) -> None:
        """Keep the timer's cycles on the instants phase + i / state_rate of the system clock.

        The timer runs on the steady clock, its cycles a whole period after the previous one's
        due time (not after its callback), so one shortened or lengthened interval puts them on
        the phase: at the first cycles, and again if the clocks drift apart by more than
        :data:`WALL_PHASE_TOLERANCE` of a period. Best effort: callbacks run late by the
        executor's latency; the stamps are the cycles' instants all the same (``WallCycles``).
        """
        config = self.driver.config
        if self._timer.timer_period_ns != config.period_ns:
            # The adjusted interval is scheduled (at the cycle that just ran): back to the period.
            self._timer.timer_period_ns = config.period_ns
            return
        until_ns = self._timer.time_until_next_call()
        if until_ns is None:
            return
        next_ns = self.get_clock().now().nanoseconds + until_ns
        tolerance_ns = round(WALL_PHASE_TOLERANCE * config.period_ns)
        interval_ns = config.aligning_interval_ns(next_ns, tolerance_ns)
        if interval_ns != config.period_ns:
            self._timer.timer_period_ns = interval_ns

    # -- sim time -------------------------------------------------------------------------------
    def _sim_cycle(self) -> None:
        """One cycle: the drive's torque over one period, then the state at the new time.

        Before the first command the arm stands on its brakes while time moves on: controllers
        on ``use_sim_time`` take their first sample when their clock reaches their first tick,
        so time must pass before they can answer at all.
        """
        self._cycle(self._t)
        self._k += 1
        self._t = self.driver.config.cycle_time(self._k)
        missed = (
            self._missed_states > 0.0
            and self._k % self._cycles_per_command != 0
            and self._missed_draws.random() < self._missed_states
        )
        if missed:
            self.diagnostics.count("unpublished_cycles")
        self._publish(self.driver.measure(self._t), state=not missed)

    def _sim_step(self) -> None:
        """Integrate one period, then on to the next cycle that waits for a command."""
        self._sim_cycle()
        while self._k % self._cycles_per_command:
            self._sim_cycle()

    def _sim_watch(self) -> None:
        waited = time.monotonic() - self._published_wall
        if not self.driver.has_command:
            if waited >= min(SIM_RESEND_S, self._sim_wait_s):
                self._sim_cycle()
        elif waited >= self._sim_wait_s:
            self.diagnostics.count("unanswered_cycles")
            self._sim_step()


def main(args: list[str] | None = None) -> int:
    return run_node(RobotSimNode, prog="robot_sim", summary=__doc__ or "", params=PARAMS, args=args)


if __name__ == "__main__":
    sys.exit(main())
