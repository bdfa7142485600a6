"""The feedforward's plan and what it sends when: plain classes, no rclpy, no clock.

- :class:`GoalQueue` owns the plan: it starts at the first measured position (the first move
  or a hold), queues goals (checked when they arrive, planned from the end of the motion before
  them when they start), and holds the last set point after the last motion or when a plan
  cannot be published.
- :class:`Lookahead` decides which samples answer a joint state: every ``j`` up to
  ``k + lookahead`` not sent yet, everything again for a resent state, nothing for a stale one.

Both are told sample indices and stamps (integer ns); the node maps their outcomes to topics,
counters and log lines.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Generic, TypeVar

import numpy as np
import pinocchio as pin

import apc_msgs_py as wire
from apc_core.params import ConfigError, Param
from apc_core.robot import Robot
from apc_feedforward.four_three_four import LIFT_OFF, SEGMENT_TIMES, SET_DOWN, FourThreeFour
from apc_feedforward.nominal import Feedforward, Setpoint
from apc_feedforward.trajectory import (
    Quintic,
    Rejoin,
    Trajectory,
    TrajectoryError,
    Waypoints,
)

#: Goals waiting for the current motion to end; one more is rejected (a flood is not a plan).
MAX_QUEUED_GOALS = 100
#: A goal's plan is checked on at most this many sample times before it is accepted.
PLAN_CHECK_SAMPLES = 10_000

R = TypeVar("R")

#: The feedforward node's parameters of the first move.
MOVE_PARAMS: tuple[Param, ...] = (
    Param(
        "move.goal_deg",
        [],
        "first move: 4-3-4 from the first measured position to this goal (deg, URDF angles); "
        "empty = hold the first measured position until a goal arrives",
    ),
    Param("move.segment_times", list(SEGMENT_TIMES), "4-3-4 segment durations (s)"),
    Param("move.lift_off", LIFT_OFF, "4-3-4 lift-off point, fraction of travel", 0.0, 1.0),
    Param("move.set_down", SET_DOWN, "4-3-4 set-down point, fraction of travel", 0.0, 1.0),
)


def setpoint_message(
    sp: Setpoint, period_ns: int, joint_names: Sequence[str], msg: Any = None
) -> Any:
    """Set point ``sp`` as the ``feedforward/setpoint`` message (a one-point
    ``JointTrajectory`` stamped ``kT``, validated for the wire; ``msg`` is refilled if given),
    whoever publishes the plan: ``feedforward_node`` beside apc's plant, ``robot_node`` on a
    robot."""
    t_ns = wire.seconds_to_ns(sp.t) if sp.t > 0 else 0
    return wire.setpoint_to_msg(
        wire.sample_stamp_ns(sp.k, period_ns), joint_names, sp.q, sp.qd, sp.qdd, sp.u_n, t_ns, msg
    )


@dataclass
class Sampled(Generic[R]):
    """What :meth:`GoalQueue.sample` did for one sample.

    Attributes
    ----------
    setpoint, rendered :
        The set point of the sample and what ``render`` made of it; both None if not even a
        hold could be rendered (``failed`` says why).
    started : list of float
        Durations (s) of the goals that started at this sample.
    refused : list of ValueError
        Goals dropped when they were to start (their plan from the actual start is unusable).
    plan_error : ValueError or None
        Why the plan was dropped for a hold of the last set point at this sample.
    failed : ValueError or None
        Why even the hold could not be rendered.
    """

    setpoint: Setpoint | None = None
    rendered: R | None = None
    started: list[float] = field(default_factory=list)
    refused: list[ValueError] = field(default_factory=list)
    plan_error: ValueError | None = None
    failed: ValueError | None = None


#: ``count(name)``: a counter on ``/diagnostics`` goes up by one.
Count = Callable[[str], object]
#: ``log(level, text)``: a line at ``"info"``, ``"warn"`` or ``"error"``.
Log = Callable[[str, str], object]


def report_sampled(k: int, out: Sampled[Any], count: Count, log: Log) -> None:
    """Count and log what :meth:`GoalQueue.sample` did at sample ``k``: the same counters and
    lines in every node that samples a plan (``feedforward_node``, ``robot_node``)."""
    for exc in out.refused:
        count("goals_refused")
        log("error", f"sample {k}: goal refused when it was to start: {exc}")
    for duration in out.started:
        count("goals_started")
        log("info", f"sample {k}: starting a {duration:.3f} s goal")
    if out.plan_error is not None:
        count("plan_errors")
        log("error", f"sample {k}: {out.plan_error}; dropping the plan, holding the last set point")
    if out.failed is not None:
        count("feedforward_errors")
        log("error", f"sample {k}: {out.failed}; no set point")


def accept_goal(plan: GoalQueue, goal: wire.TrajectoryGoal, count: Count, log: Log) -> None:
    """Queue ``goal`` in ``plan`` (it starts when the motion before it ends), counted and
    logged. Raises ValueError naming what is wrong; the caller rejects the message."""
    plan.add(goal)
    count("goals_accepted")
    log(
        "info",
        f"goal accepted: {len(goal.times_s)} point(s), {goal.times_s[-1]:.3f} s, "
        f"{len(plan.queued)} queued",
    )


class GoalQueue:
    """The feedforward's plan: the first move, queued goals, and holds.

    Parameters
    ----------
    model : pinocchio.Model
        The controller's model (nominal torques, Eqs. 2-8).
    period : float
        Sampling period T (s).
    joint_names : sequence of str
        Names of the model's joints (in error messages).
    position_limits : (lower, upper)
        The URDF's joint position limits; waypoints outside them are refused. Arrays of
        another shape than a goal's positions mean no limits.
    first_goal : (n,) ndarray or None
        Goal of the first move (rad), a 4-3-4 from the first measured position; None holds
        that position until a goal arrives.
    move : dict
        ``FourThreeFour`` keywords of the first move (segment_times, lift_off, set_down).
    interval_middle : bool
        Every nominal torque at the middle of the interval its command is held over
        (:class:`~apc_feedforward.nominal.Feedforward`'s ``interval_middle``: robot mode's
        ``feedforward_ahead``); off for the paper's sampled law.
    """

    def __init__(
        self,
        model: pin.Model,
        period: float,
        joint_names: Sequence[str],
        position_limits: tuple[np.ndarray, np.ndarray],
        *,
        first_goal: np.ndarray | None = None,
        move: dict[str, Any] | None = None,
        interval_middle: bool = False,
    ) -> None:
        self.model = model
        self.interval_middle = interval_middle
        self.period = period
        self.joint_names = list(joint_names)
        self.position_limits = position_limits
        self.first_goal = first_goal
        self.move = dict(move or {})
        self.feedforward: Feedforward | None = None
        self.queued: list[wire.TrajectoryGoal] = []
        self._last_q: np.ndarray | None = None  # last rendered q_d (where a fallback holds)
        self._stop_plan: Trajectory | None = None  # the plan of the last stop()
        # The next queued goal as planned from the current motion's end (acting_later), which
        # _advance starts: (that goal, the motion's end sample, its plan, its feedforward).
        self._next_plan: tuple[wire.TrajectoryGoal, int, Trajectory, Feedforward] | None = None

    @classmethod
    def from_params(
        cls, robot: Robot, values: Mapping[str, Any], *, interval_middle: bool = False
    ) -> GoalQueue:
        """Built from the node's parameter values (:data:`MOVE_PARAMS` and ``period``) for the
        controller's ``robot``; a bad value raises ConfigError naming it."""
        n = robot.n_joints
        goal = values["move.goal_deg"]
        if goal and len(goal) != n:
            raise ConfigError(f"parameter 'move.goal_deg': needs {n} values, got {len(goal)}")
        segments = values["move.segment_times"]
        if len(segments) != 3 or min(segments) <= 0.0:
            raise ConfigError("parameter 'move.segment_times': needs 3 positive durations (s)")
        return cls(
            robot.model,
            values["period"],
            robot.joint_names,
            robot.position_limits,
            first_goal=np.deg2rad(goal) if goal else None,
            move=dict(
                segment_times=tuple(segments),
                lift_off=values["move.lift_off"],
                set_down=values["move.set_down"],
            ),
            interval_middle=interval_middle,
        )

    # -- goals ----------------------------------------------------------------------------------
    def add(self, goal: wire.TrajectoryGoal) -> None:
        """Queue a goal; raises ValueError (WireError, TrajectoryError) naming what is wrong."""
        self._check_limits(goal.positions)
        if len(self.queued) >= MAX_QUEUED_GOALS:
            raise wire.WireError(f"points: {MAX_QUEUED_GOALS} goals already queued")
        # Check the goal now (timing, shapes, speed) with its first point as a stand-in start;
        # it is planned for real from the end of the motion before it when it starts.
        self._check_plan(self._plan(goal.positions[0], goal))
        self.queued.append(goal)

    @staticmethod
    def _plan(start: np.ndarray, goal: wire.TrajectoryGoal) -> Trajectory:
        return Waypoints(
            start,
            goal.times_s,
            goal.positions,
            velocities=goal.velocities,
            accelerations=goal.accelerations,
        )

    def _plan_after(self, ff: Feedforward, goal: wire.TrajectoryGoal) -> Trajectory:
        """``goal`` planned from the end of ``ff``'s motion and checked (ValueError: refused);
        the plan :meth:`acting_later` made of it from that end, if it did."""
        if (cached := self._planned_next(goal, ff.end_k())) is not None:
            return cached[2]
        plan = self._plan(ff.trajectory.sample(ff.trajectory.duration)[0], goal)
        self._check_plan(plan)
        return plan

    def _planned_next(
        self, goal: wire.TrajectoryGoal, end: int
    ) -> tuple[wire.TrajectoryGoal, int, Trajectory, Feedforward] | None:
        """What :meth:`acting_later` planned of ``goal`` from a motion ending at ``end``, if
        it did (the queue and the end unchanged since)."""
        cached = self._next_plan
        return cached if cached is not None and cached[0] is goal and cached[1] == end else None

    def _check_limits(self, positions: np.ndarray) -> None:
        """Refuse waypoints outside the URDF's joint position limits."""
        lower, upper = self.position_limits
        if lower.shape != positions.shape[1:] or upper.shape != positions.shape[1:]:
            return  # a model without position limits
        outside = (positions < lower) | (positions > upper)
        if outside.any():
            j, i = (int(v) for v in np.argwhere(outside)[0])
            raise wire.WireError(
                f"points[{j}].positions: {positions[j, i]:.6g} rad at joint "
                f"{self.joint_names[i]!r} is outside the URDF limits "
                f"[{lower[i]:.6g}, {upper[i]:.6g}]"
            )

    def _check_plan(self, plan: Trajectory) -> None:
        """Refuse a plan whose set points could not go on the wire (beyond its bound)."""
        count = int(min(np.ceil(plan.duration / self.period) + 1, PLAN_CHECK_SAMPLES))
        times = np.linspace(0.0, plan.duration, max(count, 2))
        for name, values in zip(
            ("positions", "velocities", "accelerations"), plan.sample_many(times), strict=True
        ):
            peak = float(np.max(np.abs(values)))
            if not peak <= wire.DEFAULT_MAX_ABS:  # also NaN
                raise TrajectoryError(
                    f"points: the planned {name} reach {peak:.3g} (more than "
                    f"{wire.DEFAULT_MAX_ABS:g}); the goal is too fast for its distance"
                )

    def restart(self) -> int:
        """Drop the plan and the queued goals (robot mode's start: activation, a watchdog
        recovery, an aborted goal, :mod:`apc_feedback.robot_loop`); the next sample holds its
        measured position. The first move
        is only ever the first plan. Returns how many queued goals were dropped."""
        dropped = len(self.queued)
        self.queued.clear()
        if self.feedforward is not None:
            self.first_goal = None
        self.feedforward = None
        self._last_q = None
        self._stop_plan = None
        return dropped

    def stop(self, k: int, position: np.ndarray, velocity: np.ndarray, duration: float) -> None:
        """From sample ``k`` on, bring the arm to rest from its measured state (robot mode's
        start after a fault or an abort, when the arm may be moving): the set point starts at
        ``position`` and ``velocity`` and is at rest ``duration`` s later, half the distance
        the velocity would cover on (a quintic whose velocity falls monotonically, at most
        1.5 |velocity| / duration rad/s^2), within the URDF's limits; held there after. A
        set point that holds ``position`` instead asks a moving arm to stop at once: from the
        speed a stall leaves it at, it overshoots by tens of degrees (docs/robot.md). Call
        after :meth:`restart`."""
        rest = position + 0.5 * duration * velocity
        lower, upper = self.position_limits
        if lower.shape == rest.shape and upper.shape == rest.shape:
            rest = np.clip(rest, np.minimum(lower, position), np.maximum(upper, position))
        plan = Quintic(position, rest, duration, qd0=velocity)
        self.feedforward = self._feedforward(plan, k)
        self._stop_plan = plan

    def stopping(self, k: int) -> bool:
        """Whether set point ``k`` is on the way to rest of :meth:`stop` (no goal: robot mode
        holds it to no path tolerance and starts it again when the arm cannot follow it)."""
        ff = self.feedforward
        return ff is not None and ff.trajectory is self._stop_plan and ff.start_k <= k < ff.end_k()

    def holding(self, k: int) -> bool:
        """Whether set point ``k`` holds still: before the plan's motion starts or after it
        has ended, with no goal queued."""
        ff = self.feedforward
        return ff is not None and not ff.start_k <= k < ff.end_k() and not self.queued

    def carry(self, model: pin.Model, k: int) -> None:
        """From sample ``k`` on the nominal torques are ``model``'s (robot mode carrying the
        payload it estimated, :mod:`apc_feedback.payload_estimate`): the hold goes on, on the
        new model, and so does every goal planned later. Only while :meth:`holding`."""
        if not self.holding(k):
            raise ValueError(f"sample {k}: the plan's model changes only in a hold")
        self.model = model
        self._next_plan = None
        ff = self.feedforward
        assert ff is not None
        self.feedforward = self._feedforward(ff.trajectory, ff.start_k)

    def rejoin(self, k: int, position: np.ndarray, velocity: np.ndarray, duration: float) -> bool:
        """Rejoin the plan from the measured state at sample ``k`` (robot mode's hand-back from
        a fallback): from ``k`` on the set point starts at ``position`` and ``velocity`` and
        reaches the plan, hold or motion, over ``duration`` s (:class:`Rejoin`), on the plan's
        own timing; queued goals start after it. False before the first sample (no plan yet)."""
        ff = self.feedforward
        if ff is None:
            return False
        t0 = (k - ff.start_k) * self.period
        ff.set_trajectory(Rejoin(ff.trajectory, t0, position, velocity, duration), k)
        return True

    # -- samples --------------------------------------------------------------------------------
    def sample(self, k: int, position: np.ndarray, render: Callable[[Setpoint], R]) -> Sampled[R]:
        """Set point ``k`` rendered for the wire by ``render`` (which raises ValueError for a
        set point the wire refuses); on a plan that cannot be published, the last set point
        held. ``position`` is the measured position of the newest joint state: the start of
        the plan at the first sample, the hold if nothing was rendered yet."""
        out: Sampled[R] = Sampled()
        try:
            self._compute(k, position, render, out)
        except ValueError as exc:  # WireError, TrajectoryError, FeedforwardError
            # The plan cannot be published (e.g. a motion too fast for the wire's bound): drop
            # it and hold the last set point, so the loop keeps its nominal torque.
            out.plan_error = exc
            hold = self._last_q if self._last_q is not None else position
            self.feedforward = self._feedforward(Quintic(hold, hold, self.period), k)
            try:
                self._compute(k, position, render, out)
            except ValueError as exc2:
                out.failed = exc2
        return out

    def acting_later(self, setpoint: Setpoint, samples: int) -> Setpoint:
        """``setpoint`` (sample ``k``, just sampled) with the nominal torque of sample ``k +
        samples`` as the plan will run it: where that is past the current motion's end and a
        goal is queued, the goal's as :meth:`sample` will start it there (planned from the
        motion's end); sample ``k``'s own where that torque cannot be computed (the plan's own
        fault shows at its own sample)."""
        ff = self.feedforward
        if samples == 0 or ff is None:
            return setpoint
        later = setpoint.k + samples
        try:
            if not self.queued or later < ff.end_k():
                return ff.acting_later(setpoint, samples)
            goal, end = self.queued[0], ff.end_k()
            cached = self._planned_next(goal, end)
            if cached is None:
                plan = self._plan_after(ff, goal)  # a goal _advance refuses raises here too
                cached = (goal, end, plan, self._feedforward(plan, end))
                self._next_plan = cached
            u_n = cached[3].sample(later).u_n
        except ValueError:  # FeedforwardError, TrajectoryError
            return setpoint
        return replace(setpoint, u_n=u_n)

    def _compute(
        self, k: int, position: np.ndarray, render: Callable[[Setpoint], R], out: Sampled[R]
    ) -> None:
        if self.feedforward is None:
            if self.first_goal is not None:
                plan: Trajectory = FourThreeFour(position, self.first_goal, **self.move)
            else:
                plan = Quintic(position, position, self.period)
            self.feedforward = self._feedforward(plan, k)
        self._advance(k, out)
        sp = self.feedforward.sample(k)
        out.rendered = render(sp)
        out.setpoint = sp
        self._last_q = sp.q

    def _feedforward(self, plan: Trajectory, start_k: int) -> Feedforward:
        """``plan``'s feedforward on the queue's model from sample ``start_k``."""
        return Feedforward(self.model, plan, self.period, start_k, self.interval_middle)

    def _advance(self, k: int, out: Sampled[Any]) -> None:
        """Start the next queued goal once the current motion has ended.

        A goal is planned when it becomes active, from the last set point of the motion before
        it, so goals can be queued before the first joint state or during a motion.
        """
        ff = self.feedforward
        while self.queued and ff is not None and k >= ff.end_k():
            goal = self.queued.pop(0)
            try:
                plan = self._plan_after(ff, goal)
            except ValueError as exc:  # TrajectoryError, or a plan that cannot be published
                out.refused.append(exc)
                continue
            ff.set_trajectory(plan, max(k, ff.end_k()))
            out.started.append(plan.duration)


@dataclass(frozen=True)
class Due:
    """The answer to one joint state: ``samples`` to compute and send, in order, or (for a
    state sent again) the set points already sent for it, to send again."""

    samples: range
    resend: tuple[Setpoint, ...] | None = None


class Lookahead:
    """Which samples answer which joint state.

    A joint state stamped ``kT`` is answered with every sample ``j <= k + lookahead`` not sent
    yet (the plan does not depend on the state, so samples ahead can leave at once). The same
    stamp again (a lockstep resend) is answered with everything sent for ``k`` or later, again;
    an older stamp is stale.
    """

    def __init__(self, lookahead: int) -> None:
        self.lookahead = int(lookahead)
        self._last_stamp: int | None = None  # newest joint state handled
        self._sent: dict[int, Setpoint] = {}  # samples sent for it, for a resend
        self._next_k: int | None = None  # first sample not sent yet

    def due(self, stamp_ns: int, k: int) -> Due:
        """Samples answering the joint state stamped ``stamp_ns`` (sample ``k``); raises
        WireError for a stale stamp."""
        last = self._last_stamp
        if last is not None and stamp_ns <= last:
            if stamp_ns == last:
                return Due(range(0), tuple(self._sent[j] for j in sorted(self._sent)))
            raise wire.WireError(
                f"header.stamp: {stamp_ns} ns is stale (sample {last} ns already done)"
            )
        self._last_stamp = stamp_ns
        first = k if self._next_k is None else max(self._next_k, k)
        return Due(range(first, k + self.lookahead + 1))

    def sent(self, sp: Setpoint) -> None:
        """Set point ``sp`` went out."""
        self._sent[sp.k] = sp
        self._next_k = sp.k + 1

    def answered(self, k: int) -> None:
        """Joint state ``k`` is answered: forget what answers only earlier samples."""
        self._sent = {j: v for j, v in self._sent.items() if j >= k}
