"""The loop of a ros2_control robot, as a plain class told the time (no rclpy).

A ros2_control robot runs ``read() -> update() -> write()`` at the controller manager's
``update_rate``: ``joint_state_broadcaster`` publishes what ``read()`` measured, stamped with
the robot's clock, and an effort ``forward_command_controller`` writes the newest
``Float64MultiArray`` it holds (one value per joint, its ``joints`` order) to the hardware.
:class:`RobotDriver` is that loop around a physics engine (:mod:`apc_plant_sim.engines`):

- :meth:`RobotDriver.measure` is ``read()``: the state at ``now``, in the published joint order
  (any order, with joints apc does not control), velocity and effort optional;
- :meth:`RobotDriver.offer` is the command subscription: a command with the wrong length or a
  non-finite value is rejected and counted, never applied; a good one enters the command
  latency's delay line (below) and replaces the one held once it is applicable;
- :meth:`RobotDriver.advance` is ``write()`` plus the physics: the held command (or the safe
  torque after ``command_timeout``), clipped to the effort limits, is applied over one driver
  period ``1 / state_rate`` (``command_delay`` periods later, if set) and the engine
  integrates it; then the drives read the arm (quantised positions, the velocity the drive
  reports) for the next ``read()``.

The robot's clock. The driver's cycles are at ``phase + i / state_rate``
(:meth:`DriverConfig.cycle_time`): ``phase`` offsets them from the controllers' sample grid
``kT``. A command offered at driver time ``t`` becomes applicable at ``t + latency`` and the
drive takes it up at its first cycle at or after that (times compared to the nanosecond, a
stamp's resolution): a delay line in which the newest applicable command wins and commands
keep their order (one drawn shorter than its predecessor's waits for it, as an in-order
transport delivers). The latency is ``command_latency`` or, with ``command_latency_max``, drawn
per command uniformly from ``[command_latency, command_latency_max]`` by a generator seeded with
``latency_seed`` (runs are reproducible). ``command_latency`` is the phase and transport between
a controller and the drive's write; the ``command_delay`` of :class:`ArmEffects` comes after it
and delays the torque the drive decided at a cycle by that many whole periods, so a command
that becomes applicable at cycle ``c`` is applied over cycle ``c + command_delay``. The command
timeout counts from when a command became applicable (when the drive received it).

Before the first command the arm stands still on its brakes, like an arm whose brakes release
when its drives are enabled. After ``command_timeout`` seconds without a command the drive
applies zero effort plus an optional viscous ``timeout_damping`` (the dynamic braking of a
drive whose motor windings are shorted): what ros2_control hardware with a command timeout does
(it zeroes the effort interface) and what a torque-controlled arm's drive does when its command
stream stops. Zero effort is chosen over a gravity-compensating hold because a hold needs the
arm's true dynamics, which no drive has; the arm then moves under gravity, as a real one would
with its brakes released, so a controller that relies on the hardware timeout sees it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from apc_plant_sim.effects import ArmEffects, DriveSensing

#: Second entropy word of the latency generator's seed (the sensing noise uses the seed alone).
_LATENCY_STREAM = 1


def _ns(t: float) -> int:
    """Driver time in ns: commands and cycles are compared at a stamp's resolution."""
    return round(t * 1e9)


class DriverError(ValueError):
    """A bad driver configuration; the message starts with the parameter's name."""


class Engine(Protocol):
    """What the driver needs of a physics engine: the arm's state and one integration."""

    joint_names: tuple[str, ...]
    effort_limit: np.ndarray

    @property
    def q(self) -> np.ndarray: ...

    @property
    def qd(self) -> np.ndarray: ...

    def advance(self, tau: np.ndarray, duration: float) -> None:
        """Hold ``tau`` (N m, URDF joint order) for ``duration`` seconds and integrate."""

    def hold(self) -> None:
        """Brakes on: zero the velocity, keep the position."""


@dataclass(frozen=True)
class DriverConfig:
    """Timing, command handling and the published message of a simulated robot.

    Attributes
    ----------
    state_rate : float
        The driver's cycle rate (Hz): one joint state per cycle, one physics period
        ``1 / state_rate`` per cycle (the controller manager's ``update_rate``).
    command_timeout : float
        Seconds (driver clock) after the newest command before the safe torque applies.
    timeout_damping : float
        Viscous torque ``-timeout_damping * q'`` (N m s/rad) added to the zero effort after a
        command timeout; 0 = zero effort alone.
    command_joints : tuple of str
        Joint order of the command's ``data`` (empty = the engine's joint order).
    state_joints : tuple of str
        Joint order of the published state (empty = the engine's order). Must name every joint
        of the engine once; other names are joints apc does not control (a gripper finger),
        published at a constant ``extra_position`` with zero velocity and effort.
    extra_position : float
        Position of the extra joints (rad or m).
    publish_velocity, publish_effort : bool
        Fill ``velocity`` / ``effort`` (the torque applied over the period that ended at the
        stamp), or leave them empty, as a robot without those state interfaces does.
    effort_limit : tuple of float
        |tau| bound per joint (N m); empty = the engine's (the URDF's). Every command is
        clipped to it and each clipped joint counted.
    sensing : ArmEffects
        What the drive adds between the arm and the wire (all off by default): encoder
        quantisation (``counts_per_rev``), the velocity it reports (``velocity``: exact, with
        white noise of ``velocity_noise_rad_s``, or the backward difference of the quantised
        positions over one driver period) and a ``command_delay`` of whole driver periods.
        Its friction and armature fields belong to the engine and are not read here.
    command_latency : float
        Seconds (driver clock) from a command's arrival until the drive may apply it.
    command_latency_max : float or None
        None: every command waits ``command_latency``; else each waits a latency drawn
        uniformly from ``[command_latency, command_latency_max]``.
    latency_seed : int
        Seed of the latency draws.
    phase : float
        The driver's cycles are at ``phase + i / state_rate`` (s, in ``[0, 1 / state_rate)``).
    """

    state_rate: float = 500.0
    command_timeout: float = 0.1
    timeout_damping: float = 0.0
    command_joints: tuple[str, ...] = ()
    state_joints: tuple[str, ...] = ()
    extra_position: float = 0.0
    publish_velocity: bool = True
    publish_effort: bool = True
    effort_limit: tuple[float, ...] = ()
    sensing: ArmEffects = field(default_factory=ArmEffects)
    command_latency: float = 0.0
    command_latency_max: float | None = None
    latency_seed: int = 0
    phase: float = 0.0

    def __post_init__(self) -> None:
        for name in ("state_rate", "command_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise DriverError(f"{name}: must be > 0, got {value}")
        if not (math.isfinite(self.timeout_damping) and self.timeout_damping >= 0.0):
            raise DriverError(f"timeout_damping: must be >= 0, got {self.timeout_damping}")
        if not math.isfinite(self.extra_position):
            raise DriverError(f"extra_position: must be finite, got {self.extra_position}")
        if not all(math.isfinite(v) and v > 0.0 for v in self.effort_limit):
            raise DriverError(f"effort_limit: every value must be > 0, got {self.effort_limit}")
        if not (math.isfinite(self.command_latency) and self.command_latency >= 0.0):
            raise DriverError(f"command_latency: must be >= 0, got {self.command_latency}")
        high = self.command_latency_max
        if high is not None and not (math.isfinite(high) and high >= self.command_latency):
            raise DriverError(
                f"command_latency_max: must be >= command_latency ({self.command_latency}), "
                f"got {high}"
            )
        if isinstance(self.latency_seed, bool) or not isinstance(self.latency_seed, int):
            raise DriverError(f"latency_seed: must be an integer, got {self.latency_seed!r}")
        if self.latency_seed < 0:
            raise DriverError(f"latency_seed: must be >= 0, got {self.latency_seed}")
        if not (math.isfinite(self.phase) and 0 <= self.phase_ns < self.period_ns):
            raise DriverError(
                f"phase: must be in [0, {self.period}) (one driver period), got {self.phase}"
            )

    @property
    def period(self) -> float:
        return 1.0 / self.state_rate

    @property
    def period_ns(self) -> int:
        return round(1e9 / self.state_rate)

    @property
    def phase_ns(self) -> int:
        return round(self.phase * 1e9)

    def cycle_time_ns(self, i: int) -> int:
        """Driver time of cycle ``i`` (ns): ``phase + i / state_rate``."""
        return self.phase_ns + i * self.period_ns

    def cycle_time(self, i: int) -> float:
        """Driver time of cycle ``i`` (s): ``phase + i / state_rate``."""
        return self.cycle_time_ns(i) / 1e9

    def aligning_interval_ns(self, next_cycle_ns: int, tolerance_ns: int) -> int:
        """The interval after a cycle due at ``next_cycle_ns`` that puts the one after it on an
        instant ``phase + i / state_rate``: the period when the cycle is within
        ``tolerance_ns`` of one, else the period shortened or lengthened by its offset (at most
        half a period), as a timer that keeps its cycles on a phase adjusts one interval."""
        period = self.period_ns
        offset = (next_cycle_ns - self.phase_ns) % period
        if min(offset, period - offset) <= tolerance_ns:
            return period
        return period - offset if 2 * offset <= period else 2 * period - offset


class WallCycles:
    """Which driver cycles a wall timer's callback at ``now`` stands for.

    A robot's driver reads and writes on its cycle's instant (a real-time loop; the arm moves
    in real time between); a timer's callback on a loaded machine runs late by the executor's
    latency, now and then by more than a period. The callback stands for every cycle due since
    the one before, the newest at or before ``now`` (the instants ``phase + i / state_rate``):
    each is integrated for one period, the newest's state published stamped at its instant:
    the instant its physics is at. Stamped at the callback instead, the states carried the
    callback's jitter (up to a third of a period at 1 kHz) in their stamps while the arm had
    moved exactly one period: a velocity estimated from positions and stamps took that jitter
    as motion. The newest cycle's write takes the commands that arrived before the callback
    ran (robot_sim): a real driver publishes at its instant, so the timer's own latency is
    not charged to the loop's transport.
    """

    def __init__(self, config: DriverConfig) -> None:
        self._config = config
        self._last: int | None = None

    def due(self, now_ns: int) -> range:
        """The cycles (indices) the callback at ``now_ns`` (system clock) runs, oldest first:
        the newest due at or before ``now_ns`` and any the callbacks before it left; one (the
        next) for a callback that runs before its instant."""
        config = self._config
        newest = (now_ns - config.phase_ns) // config.period_ns
        last = newest - 1 if self._last is None else self._last
        newest = max(newest, last + 1)
        self._last = newest
        return range(last + 1, newest + 1)


@dataclass(frozen=True, eq=False)
class Reading:
    """One joint state as ``joint_state_broadcaster`` publishes it (published order)."""

    stamp: float
    names: tuple[str, ...]
    position: np.ndarray
    velocity: np.ndarray | None
    effort: np.ndarray | None


@dataclass
class DriverCounts:
    """What ``/diagnostics`` reports (only goes up)."""

    commands: int = 0
    rejected: int = 0
    timeouts: int = 0
    timeout_cycles: int = 0
    clipped: int = 0
    clipped_per_joint: dict[str, int] = field(default_factory=dict)
    cycles: int = 0
    #: Cycles after the first command that applied no command newer than the previous cycle's:
    #: the controller's answer missed this write (a late or lost command), so the drive
    #: re-applied the one it held. Over ``cycles`` it is the loop's late fraction.
    held_command_cycles: int = 0


def _order(names: Sequence[str], engine_names: Sequence[str], param: str) -> np.ndarray:
    """Index into the engine's joint order for each name of ``names`` (a permutation)."""
    if sorted(names) != sorted(engine_names):
        raise DriverError(
            f"{param}: must name each joint {list(engine_names)} once, got {list(names)}"
        )
    return np.array([list(engine_names).index(name) for name in names], dtype=int)


class RobotDriver:
    """A simulated ros2_control robot around ``engine`` (see module docstring)."""

    def __init__(self, engine: Engine, config: DriverConfig) -> None:
        self.engine = engine
        self.config = config
        names = tuple(engine.joint_names)
        self.joint_names = names
        n = len(names)
        self.command_joints = config.command_joints or names
        # command data[i] is the torque of engine joint _command_index[i].
        self._command_index = _order(self.command_joints, names, "command_joints")
        state_joints = config.state_joints or names
        if len(set(state_joints)) != len(state_joints):
            raise DriverError(f"state_joints: names repeat: {list(state_joints)}")
        missing = [name for name in names if name not in state_joints]
        if missing:
            raise DriverError(f"state_joints: must name every joint, missing {missing}")
        self.state_joints = tuple(state_joints)
        # Published entry j is engine joint _state_index[j], or an extra joint (-1).
        self._state_index = np.array(
            [names.index(name) if name in names else -1 for name in state_joints], dtype=int
        )
        self._extra = self._state_index < 0
        if config.effort_limit:
            if len(config.effort_limit) != n:
                raise DriverError(
                    f"effort_limit: needs {n} values (one per joint) or none, "
                    f"got {len(config.effort_limit)}"
                )
            self.effort_limit = np.array(config.effort_limit, dtype=float)
        else:
            self.effort_limit = np.asarray(engine.effort_limit, dtype=float).copy()
        self.counts = DriverCounts()
        self._command: np.ndarray | None = None  # engine order
        self._command_time = -math.inf
        self._received = False  # a command was accepted (it may still be in the delay line)
        # Accepted commands not yet applicable: (driver time it becomes applicable in ns,
        # command), in arrival order with nondecreasing times.
        self._pending: deque[tuple[int, np.ndarray]] = deque()
        # Its own stream, apart from the velocity noise's generator of the sensing seed.
        self._latency_rng = np.random.default_rng([config.latency_seed, _LATENCY_STREAM])
        self._fresh_command = False  # a command arrived since the last advance
        self._timed_out = False
        self._applied = np.zeros(n)  # torque over the period that ended at the last advance
        self.braked = True
        try:
            self._sensing = DriveSensing(config.sensing, n, config.period, engine.q)
        except ValueError as exc:
            raise DriverError(f"encoder_counts_per_rev: {exc}") from None
        # Torques decided at the last command_delay cycles, oldest first (filled at the first).
        self._delay_line: deque[np.ndarray] = deque()
        self._q_measured, self._qd_measured = self._sensing.read(engine.q, engine.qd)

    # -- command subscription -------------------------------------------------------------------
    def offer(self, data: Sequence[float], now: float) -> str | None:
        """Take a command received at ``now``; return why it was rejected, or None.

        A rejected command is counted and never applied; the command held before stays.
        """
        values = np.asarray(data, dtype=float).reshape(-1)
        n = len(self.joint_names)
        if values.shape != (n,):
            reason = (
                f"data: {values.size} values, expected {n} (one per joint of "
                f"{list(self.command_joints)})"
            )
        elif not np.isfinite(values).all():
            bad = [self.command_joints[i] for i in np.flatnonzero(~np.isfinite(values))]
            reason = f"data: non-finite value for {bad}"
        else:
            command = np.empty(n)
            command[self._command_index] = values
            due_ns = _ns(now + self._next_latency())
            if self._pending:  # order kept: never before the command offered before it
                due_ns = max(due_ns, self._pending[-1][0])
            self._pending.append((due_ns, command))
            self._received = True
            self.counts.commands += 1
            return None
        self.counts.rejected += 1
        return reason

    def _next_latency(self) -> float:
        config = self.config
        if config.command_latency_max is None:
            return config.command_latency
        return float(self._latency_rng.uniform(config.command_latency, config.command_latency_max))

    @property
    def has_command(self) -> bool:
        """A command was accepted (the drive may not have applied it yet: see the latency)."""
        return self._received

    @property
    def pending_commands(self) -> int:
        """Accepted commands still waiting for their latency to pass."""
        return len(self._pending)

    @property
    def command_time(self) -> float:
        """Driver time the held command became applicable (``-inf`` before the first)."""
        return self._command_time

    def _take_applicable(self, now: float) -> None:
        """Hold the newest command applicable at ``now``; drop the older ones it supersedes."""
        now_ns = _ns(now)
        while self._pending and self._pending[0][0] <= now_ns:
            due_ns, self._command = self._pending.popleft()
            self._command_time = due_ns / 1e9
            self._fresh_command = True

    @property
    def timed_out(self) -> bool:
        return self._timed_out

    # -- read -----------------------------------------------------------------------------------
    def measure(self, now: float) -> Reading:
        """The joint state at ``now`` as the robot publishes it (what its drives measured)."""
        return self._reading(now, self._q_measured, self._qd_measured)

    def _sense(self) -> None:
        """The drives read the arm once per cycle, after it has moved."""
        self._q_measured, self._qd_measured = self._sensing.read(self.engine.q, self.engine.qd)

    def _reading(self, now: float, q: np.ndarray, qd: np.ndarray) -> Reading:
        index = np.where(self._extra, 0, self._state_index)
        position = np.where(self._extra, self.config.extra_position, q[index])
        velocity = np.where(self._extra, 0.0, qd[index]) if self.config.publish_velocity else None
        effort = (
            np.where(self._extra, 0.0, self._applied[index]) if self.config.publish_effort else None
        )
        return Reading(now, self.state_joints, position, velocity, effort)

    # -- write + physics ------------------------------------------------------------------------
    def torque(self, now: float) -> tuple[np.ndarray, bool]:
        """The torque the drive applies from ``now``: (torque, timed_out), before clipping."""
        assert self._command is not None
        if _ns(now) - _ns(self._command_time) > _ns(self.config.command_timeout):
            return -self.config.timeout_damping * self.engine.qd, True
        return self._command, False

    def advance(self, now: float) -> np.ndarray:
        """Apply the drive's torque from ``now`` for one period and integrate; return it.

        Before the first command is applicable the brakes hold the arm (nothing is integrated).
        """
        self.counts.cycles += 1
        self._take_applicable(now)
        if self._command is None:
            self.engine.hold()
            self._applied = np.zeros(len(self.joint_names))
            self._sense()
            return self._applied
        if not self.braked and not self._fresh_command:
            self.counts.held_command_cycles += 1
        self._fresh_command = False
        self.braked = False
        tau, timed_out = self.torque(now)
        if timed_out:
            self.counts.timeout_cycles += 1
            if not self._timed_out:
                self.counts.timeouts += 1
        self._timed_out = timed_out
        clipped = np.abs(tau) > self.effort_limit
        if clipped.any():
            self.counts.clipped += 1
            for i in np.flatnonzero(clipped):
                name = self.joint_names[i]
                self.counts.clipped_per_joint[name] = self.counts.clipped_per_joint.get(name, 0) + 1
            tau = np.clip(tau, -self.effort_limit, self.effort_limit)
        tau = np.array(tau, dtype=float)
        delay = self.config.sensing.command_delay
        if delay:
            if not self._delay_line:  # before the first command the arm held it
                self._delay_line.extend(tau.copy() for _ in range(delay))
            self._delay_line.append(tau)
            tau = self._delay_line.popleft()
        self.engine.advance(tau, self.config.period)
        self._applied = tau
        self._sense()
        return self._applied


__all__ = ["DriverConfig", "DriverCounts", "DriverError", "Engine", "Reading", "RobotDriver"]
