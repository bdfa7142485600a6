"""Robot mode's loop closed offline: a driver on its own clock, the controllers on theirs, no ROS.

What :mod:`apc_lab.offline` is for the lockstep wire, this is for robot mode: the simulated
ros2_control robot of ``robot_sim`` (:class:`apc_plant_sim.robot_driver.RobotDriver` around apc's
plant, reporting positions only, stamped with its time) cycling every ``driver_ms``,
:class:`apc_feedback.robot_loop.RobotLoop` offered each state ``transport_ms`` after its stamp
(the trip to the controllers and their wake-up) and taking its samples from them, its watchdog
checked every T, the loop sampling the feedforward's plan itself, all on one synthetic clock. A
command leaves when its state arrives and reaches the driver after a latency that
:class:`Latency` chooses per command (the delay a network or a drive adds, on time or late);
the driver applies the newest one at its first cycle after that. The 3-joint PUMA 560 (or another
arm, ``arm``) with 10 % inertia error in the controllers and a payload they do not know; with
``effects`` the arm is MuJoCo's with a physical arm's friction, rotor inertia and drive
(``robot_sim``'s ``effects``).
Used by ``test/test_robot_loop.py``, ``test/test_supervisor.py``, ``bench/late_commands.py`` and
``bench/robot_clock_offline.py``.
"""

from __future__ import annotations

import heapq
import itertools
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from apc_core.robot import Payload, load_robot, with_armature, with_friction, with_inertia_error
from apc_feedback.command_map import CommandMap
from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback
from apc_feedback.payload_estimate import PayloadEstimateConfig, payload_carry
from apc_feedback.presets import recommended_settings
from apc_feedback.robot_loop import RobotLoop, Step
from apc_feedback.robot_sampling import RobotSamplingConfig
from apc_feedback.supervisor import Supervisor, SupervisorConfig, fallback_law
from apc_feedforward.four_three_four import FourThreeFour
from apc_feedforward.goals import GoalQueue
from apc_lab.scenario import CONFIG_DIR, Scenario
from apc_msgs_py import JointSample
from apc_plant_sim.effects import ArmEffects
from apc_plant_sim.engines import EngineError, PinocchioEngine, make_engine
from apc_plant_sim.robot_driver import DriverConfig, RobotDriver

MS = 1_000_000  # ns


@dataclass
class Latency:
    """How late each command reaches the driver beyond its next cycle (ms).

    ``fixed_ms`` for every command; ``late_ms`` more for the first ``first`` commands, for the
    ``burst`` commands from the ``burst_from``-th on (counted from 1: a loaded machine's run of
    late commands), and for each other one with probability ``probability`` (``seed`` fixes
    the draws).
    """

    fixed_ms: float = 0.0
    late_ms: float = 0.0
    first: int = 0
    probability: float = 0.0
    seed: int = 0
    burst_from: int = 0
    burst: int = 0
    _count: int = field(default=0, init=False)
    _rng: Any = field(default=None, init=False)

    def __post_init__(self) -> None:
        if self.burst and self.burst_from < 1:
            raise ValueError("burst_from counts commands from 1")
        self._rng = np.random.default_rng(self.seed)

    def next_ns(self) -> int:
        """The latency of the next command (ns)."""
        self._count += 1
        late = (
            self._count <= self.first
            or 0 <= self._count - self.burst_from < self.burst
            or (self.probability > 0.0 and self._rng.random() < self.probability)
        )
        return round((self.fixed_ms + (self.late_ms if late else 0.0)) * MS)


@dataclass
class RobotRun:
    """One run: the start position; per driver cycle (time ns, q), with the set point's q
    appended for the cycles whose state was a sample; the loop's timing figures at the end
    (:meth:`apc_feedback.sample_timing.SampleTiming.figures`, us), its counters, its logged
    lines ``(level, text)``, the commands it sent ``(time ns, torque in the driver's order)``,
    when it was activated (ns), the controllers' sampling period T (ns) and the grid time of
    the move's end (ns; None without a move)."""

    q0: np.ndarray
    log: list[tuple]
    timing: dict[str, float] = field(default_factory=dict)
    counts: Counter = field(default_factory=Counter)
    lines: list[tuple[str, str]] = field(default_factory=list)
    commands: list[tuple[int, np.ndarray]] = field(default_factory=list)
    activated_ns: int = 0
    period_ns: int = 0
    move_end_ns: int | None = None

    @property
    def q(self) -> np.ndarray:
        return np.array([entry[1] for entry in self.log])

    def max_deviation_deg(self) -> float:
        """Largest |q - q0| over the run (a hold's sag), deg."""
        return float(np.rad2deg(np.max(np.abs(self.q - self.q0))))

    def tracking_error_deg(self) -> np.ndarray:
        """|q - q_d| at each sample, per joint, deg: shape (samples, n)."""
        return np.array([np.rad2deg(np.abs(e[1] - e[2])) for e in self.log if len(e) == 3])

    def tracking_error_at_deg(self, at_s: float) -> np.ndarray:
        """|q - q_d| per joint (deg) at the sample for ``at_s`` s after activation: the last
        sample whose state is stamped within half a period after that time (a state comes a
        fraction of its driver's cycle after its sample's grid time)."""
        return self._tracking_error_at_ns(self.activated_ns + round(at_s * 1e9))

    def tracking_error_at_move_end_deg(self) -> np.ndarray:
        """|q - q_d| per joint (deg) at the sample of the move's end, as the wall-time bench's
        final error (``apc_lab.wall_clock``)."""
        if self.move_end_ns is None:
            raise ValueError("the run has no move")
        return self._tracking_error_at_ns(self.move_end_ns)

    def _tracking_error_at_ns(self, time_ns: int) -> np.ndarray:
        if self.period_ns <= 0:
            raise ValueError("the run's sampling period (period_ns) is not known")
        until = time_ns + self.period_ns // 2
        rows = [e for e in self.log if len(e) == 3 and e[0] <= until]
        if not rows:
            raise ValueError(
                f"no sample by {(time_ns - self.activated_ns) * 1e-9} s after activation"
            )
        return np.rad2deg(np.abs(rows[-1][1] - rows[-1][2]))

    def max_tracking_error_deg(self) -> float:
        """Largest |q - q_d| at the samples, deg."""
        return float(self.tracking_error_deg().max())

    def command_chatter_nm(self, from_s: float) -> np.ndarray:
        """Per joint (driver order), the mean |u(k) - u(k-1)| of the commands sent from
        ``from_s`` s after activation on (N m): how much the command moves from one sample to
        the next (docs/robot.md, "Commands that chatter"). NaN with fewer than two."""
        start = self.activated_ns + round(from_s * 1e9)
        sent = np.array([u for t, u in self.commands if t >= start])
        if len(sent) < 2:
            return np.full(len(self.q0), np.nan)
        return np.abs(np.diff(sent, axis=0)).mean(axis=0)


def run_robot_loop(
    duration_s: float,
    *,
    goal_deg: Sequence[float] | None = None,
    hold_s: float = 0.2,
    driver_ms: float = 2.0,
    period_ms: float = 10.0,
    phase_ms: float = 0.3,
    transport_ms: float = 0.3,
    payload_kg: float = 2.268,
    pause: tuple[float, float] | None = None,
    latency: Latency | None = None,
    settings: Mapping[str, Any] | None = None,
    supervisor: SupervisorConfig | None = None,
    setup: Callable[[RobotLoop], object] | None = None,
    effects: ArmEffects | None = None,
    arm: Scenario | None = None,
    velocity: bool | None = None,
    armature: Sequence[float] | None = None,
    friction: tuple[Sequence[float], Sequence[float]] | None = None,
    effort: bool = True,
    missed: float = 0.0,
    missed_seed: int = 0,
    command_first: bool = False,
    feedforward_ahead: bool = True,
    period_from_driver: bool = False,
    payload_estimate: PayloadEstimateConfig | None = None,
) -> RobotRun:
    """Activate at the start pose, hold, and (with ``goal_deg``) move there ``hold_s`` later.

    Parameters
    ----------
    duration_s : float
        Run time after activation (s).
    goal_deg : sequence of float, optional
        A 4-3-4 move (0.2, 0.6, 0.2 s) from the measured position, ``hold_s`` (s) after
        activation (default 0.2).
    driver_ms, phase_ms : float
        The driver's period and its cycles' phase after a multiple of T (ms).
    period_ms : float
        The controllers' sampling period T (ms); the preset's is 10.
    transport_ms : float
        From a state's stamp to its arrival at the loop (ms): its trip and the controllers'
        wake-up; the command computed from it leaves then.
    payload_kg : float
        The payload the controllers do not know (at the arm's payload frame: the PUMA's wrist
        centre).
    pause : (start, end), optional
        Seconds after activation during which the driver publishes no states.
    latency : Latency, optional
        When commands reach the driver beyond its first cycle after they leave (default: at it).
    settings : mapping, optional
        The adaptive law's settings (default: the recommended preset).
    supervisor : SupervisorConfig, optional
        Supervise the adaptive law, with the fallback law it names (default: unsupervised).
    setup : callable, optional
        ``setup(loop)`` once the loop is built, before activation: to observe the law or to
        make it go wrong (wrap ``loop.law.update``).
    effects : ArmEffects, optional
        A physical arm (``apc_plant_sim.effects.puma560_effects()``: friction, rotor inertia,
        quantised encoders, the drive's differenced velocity, a drive that adds a cycle), as
        ``robot_sim``'s ``effects: puma560``: the arm is MuJoCo's and its states carry the
        drive's velocity. Default: the ideal arm on apc's plant, positions only.
    arm : Scenario, optional
        Another arm: its URDF, locked joints, payload frame, the controllers' inertia error and
        the start pose (``q_start_deg``); its payload comes from ``payload_kg``. Default: the
        3-joint PUMA 560 at the paper's start pose, 10 % inertia error.
    velocity : bool, optional
        Whether the states carry a velocity (the ideal arm's exact one, a physical arm's
        drive's); default: a physical arm's do, the ideal arm's do not.
    armature : sequence of float, optional
        The controllers' model's rotor inertia per joint (kg m^2), as the controller nodes'
        ``armature`` parameter; default none.
    friction : (coulomb, viscous) per joint, optional
        The controllers' model's friction (N m, N m s/rad), as the controller nodes'
        ``friction`` and ``damping`` parameters; default none.
    effort : bool
        Whether the states carry the torque the drive applied over the period that ended at
        their stamp (``robot_sim``'s ``publish_effort``, on by default as there), from which
        robot mode measures when a command is applied.
    missed, missed_seed : float, int
        The share of the driver's cycles whose state is not published, drawn with the seed: a
        driver on a loaded machine misses cycles (``robot_sim``'s ``unpublished_cycles`` on wall
        time; the arm moves on, no state goes out).
    command_first : bool
        Robot mode's ``command_first``: the law's command from the gain planned at the sample
        before (simulated time has no compute time, so only its cost shows here).
    feedforward_ahead : bool
        Robot mode's ``feedforward_ahead`` (on, as robot mode's default): the nominal torque of
        the interval over which the law models the command acting, at its middle.
    period_from_driver : bool
        Robot mode's ``period_from_driver``: where the loop asks for another T at its first
        start, it is built again at that T (``setup`` called again), as ``robot_node`` does.
    payload_estimate : PayloadEstimateConfig, optional
        Robot mode's ``payload_estimate.*`` (with ``enable``: the controllers estimate the
        payload in the hold and carry it); None: as disabled.
    """
    T_NS = round(period_ms * MS)
    T = T_NS * 1e-9
    arm = arm or Scenario(urdf=str(CONFIG_DIR / "puma560_3dof.urdf"), payload_frame="wrist_center")
    robot = load_robot(arm.urdf, gravity=arm.gravity, lock_joints=arm.lock_joints)
    n = robot.n_joints
    controller = with_inertia_error(robot, arm.inertia_error)
    if armature is not None:
        controller = with_armature(controller, armature)
    if friction is not None:
        controller = with_friction(controller, *friction)
    q0 = np.deg2rad(arm.q_start_deg)
    # The driver's command order: the URDF's reversed, so that the loop's mapping is exercised.
    command_joints = tuple(reversed(robot.joint_names))
    dt = round(driver_ms * MS)
    # One RK4 step per driver period; no command timeout (a forward_command_controller holds
    # its last command) and positions only, as the robot files' drivers publish.
    payload = Payload(payload_kg, com_m=tuple(arm.payload_com_m), frame=arm.payload_frame)
    if effects is None:
        engine = PinocchioEngine(robot, payload, period=dt * 1e-9, max_step=dt * 1e-9, q0=q0)
    else:
        engine = make_engine(
            "mujoco",
            robot,
            payload,
            effects,
            period=dt * 1e-9,
            max_step=min(dt * 1e-9, 1e-3),
            q0=q0,
            loaded=True,
        )
    driver = RobotDriver(
        engine,
        DriverConfig(
            state_rate=1e9 / dt,
            command_timeout=duration_s + 1.0,
            command_joints=command_joints,
            publish_velocity=effects is not None if velocity is None else velocity,
            publish_effort=effort,
            sensing=effects if effects is not None else ArmEffects(),
        ),
    )
    data = controller.model.createData()
    counts: Counter = Counter()
    lines: list[tuple[str, str]] = []

    def build(T: float, from_driver: bool) -> RobotLoop:
        config = AdaptiveConfig.from_dict(dict(settings or recommended_settings(), period=T))
        supervision = {}
        if supervisor is not None and supervisor.enable:
            supervision = {
                "supervisor": Supervisor(supervisor, n, T),
                "fallback": fallback_law(supervisor, controller, T),
            }
        loop = RobotLoop(
            law=AdaptiveFeedback(controller.model, config),
            sampling=RobotSamplingConfig(period=T),
            command=CommandMap(robot.joint_names, command_joints, robot.effort_limit),
            plan=GoalQueue(
                controller.model,
                T,
                robot.joint_names,
                robot.position_limits,
                interval_middle=feedforward_ahead,
            ),
            gravity=lambda q: pin.computeGeneralizedGravity(controller.model, data, q).copy(),
            path_tolerance=np.full(n, 0.2),
            command_first=command_first,
            feedforward_ahead=feedforward_ahead,
            period_from_driver=from_driver,
            payload=payload_carry(controller, payload_estimate, T) if payload_estimate else None,
            count=lambda name: counts.update((name,)),
            log=lambda level, text: lines.append((level, text)),
            **supervision,
        )
        if setup is not None:
            setup(loop)
        return loop

    loop = build(T, period_from_driver)
    latency = latency or Latency()
    draws = np.random.default_rng(missed_seed)
    transport = round(transport_ms * MS)
    log: list[tuple] = []
    commands: list[tuple[int, np.ndarray]] = []
    # Before activation the brakes hold the arm (the driver has no command yet).
    moved = goal_deg is None
    move_end_ns: int | None = None

    def handle(step: Step, now: int) -> None:
        nonlocal moved, move_end_ns, loop
        if step.retime is not None:  # robot_node builds its loop again at that T, once
            loop = build(step.retime, False)
            loop.activate()
            return
        if step.command is not None:
            # It reaches the driver after its latency; the driver applies the newest arrival at
            # its first cycle after that (a cycle at the same instant has already run).
            arrival = now + 1 + latency.next_ns()
            heapq.heappush(events, (arrival, COMMAND, next(order), step.command.copy()))
            commands.append((now, step.command.copy()))
            loop.command_published(now)
        plan = loop.plan.feedforward
        if not moved and plan is not None and step.setpoint is not None:
            # The move, from the held position, starts hold_s after the first sample (a user's
            # goal; a 4-3-4 as the feedforward's first move).
            assert goal_deg is not None
            start = step.setpoint.q
            move = FourThreeFour(start, np.deg2rad(goal_deg), (0.2, 0.6, 0.2))
            plan.set_trajectory(move, step.setpoint.k + round(hold_s / (loop.period_ns * 1e-9)))
            move_end_ns = plan.end_k() * loop.period_ns
            moved = True

    # Events on the one clock: (time, kind, order of scheduling, payload). At equal times a
    # command reaching the driver comes first, then a driver cycle, then a state's arrival, then
    # the watchdog's check; activation is the first check.
    COMMAND, CYCLE, ARRIVAL, WATCHDOG = 0, 1, 2, 3
    order = itertools.count()
    t_act = 5000 * T_NS
    end = t_act + round(duration_s * 1e9)
    events: list[tuple[int, int, int, Any]] = [
        (5000 * T_NS - 40 * MS + round(phase_ms * MS), CYCLE, next(order), None),
        (t_act, WATCHDOG, next(order), None),
    ]
    while events:
        now, kind, _, payload = heapq.heappop(events)
        if now >= end:
            break
        if kind == COMMAND:
            driver.offer(payload, now * 1e-9)
        elif kind == CYCLE:
            reading = driver.measure(now * 1e-9)
            log.append((now, reading.position.copy()))
            paused = pause and pause[0] <= (now - t_act) * 1e-9 < pause[1]
            if not paused and not (missed > 0.0 and draws.random() < missed):
                velocity = None if reading.velocity is None else reading.velocity.copy()
                torque = None if reading.effort is None else reading.effort.copy()
                state = JointSample(now, reading.position.copy(), velocity, torque)
                heapq.heappush(
                    events, (now + transport, ARRIVAL, next(order), (len(log) - 1, state))
                )
            try:
                driver.advance(now * 1e-9)
            except EngineError:  # the arm is lost: the run ends here
                break
            heapq.heappush(events, (now + dt, CYCLE, next(order), None))
        elif kind == ARRIVAL:
            index, state = payload
            step = loop.on_joint_state(state, now)
            handle(step, now)
            if step.setpoint is not None:
                log[index] = (*log[index][:2], step.setpoint.q)
        else:
            if not loop.active:
                loop.activate()
            handle(loop.tick(now), now)
            heapq.heappush(events, (now + loop.period_ns, WATCHDOG, next(order), None))
    return RobotRun(
        q0, log, loop.timing.figures(), counts, lines, commands, t_act, loop.period_ns, move_end_ns
    )
