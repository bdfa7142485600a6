"""Robot mode's control loop without ROS: samples, the plan, the law, the command, faults.

:class:`RobotLoop` is what the commanding node (``robot_node``) runs; it is told joint
states, goals and times, never reads a clock, and answers with a :class:`Step`: the command to
send, if any, with the sample and the set point it came from (for observers).

One sample ``k``:

1. the driver's state for the sample's time arrives;
   :class:`~apc_feedback.robot_sampling.RobotSampler` takes sample ``k`` (stamped ``kT``) from
   it in :meth:`RobotLoop.on_joint_state` (unless the next sample's state is in hand too);
2. the feedforward's plan (:class:`apc_feedforward.goals.GoalQueue`: the goals, the hold, the
   nominal torque of Eqs. 2-8 by Newton-Euler) gives set point ``k``, which depends only on
   time and the goals, so it is sampled here, in the loop, as joint_trajectory_controller
   samples its trajectory in ``update()``: the command never waits for another node;
3. the law gives ``du(k)`` from the sample and the set point, and the command is ``u_n +
   du(k)`` (``u_n`` of the sample it acts over, ``feedforward_ahead``) in ``command_joints``
   order, clipped to the effort limits, sent in the same callback, a fixed time after the
   state. The feedforward and the feedback stay apart; the sum happens where both are.

:meth:`RobotLoop.tick`, called by a timer, is only the watchdog below. The loop keeps the
sampling's timing (:class:`~apc_feedback.sample_timing.SampleTiming`, ``timing``); the node
reports when a command went out (:meth:`RobotLoop.command_published`). Goals come in through
:meth:`RobotLoop.add_goal` and start when the motion before them ends.

Starts. At activation, after a watchdog fault and after a path-tolerance abort, the plan and
the queued goals are dropped. Activation holds the sample's measured position; a fault or an
abort, where the arm may be moving, brings it to rest from its measured state over
``stop_time`` (:meth:`apc_feedforward.goals.GoalQueue.stop`), starting the stop again from
the arm's state whenever it is more than :data:`STOP_TOLERANCE` off it (``stop_restarts``).
The law keeps what it identified (the payload is still on the arm; restarted from Eq. 33 on an
arm still sagging after a watchdog hold it diverged). A start follows a gap in ``k``: no
identification step spans a change of plan.

Faults.

- Watchdog (no accepted joint state within ``watchdog``): one command, the model's gravity at
  the last measured position plus the average the controllers added to it over the last 0.1 s
  (:class:`~apc_feedback.hold_torque.HoldTorque`: a payload the model does not know), then
  none; a forward_command_controller keeps applying it (a driver with a command timeout
  applies its own policy). No loop is closed on a stale state; a fresh state restarts the
  loop at the state measured then, bringing the arm to rest from it.
- Path tolerance (``|q - q_d| > tolerance`` on a joint while the set point moves, like
  joint_trajectory_controller's ``constraints.<joint>.trajectory``): the goal is aborted and
  the arm brought to rest (a start); the stop is no goal and has no path tolerance.
- Supervision (with a ``supervisor`` and a ``fallback`` law): when a trigger of
  :mod:`apc_feedback.supervisor` fires the fallback commands from that sample on, the law is
  reset and idle, and it takes the joints again (from Eq. 33) once the error has settled. A
  path-tolerance abort hands the hold to the fallback too when the law's identified input gain
  is outside the supervisor's region: a diverging law must not hold the arm.

Deactivation sends the model's gravity hold once and stops commanding (an inactive
controller commands nothing: another one may take the joints over).

The driver's rate. The driver applies a command at its next write, a driver period (plus the
trip) after the state, which Eq. 16 does not model; a law that does is told that delay at a
start (:meth:`RobotLoop._start`), and the samples' velocity as the states show it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from apc_feedback.arrays import all_true, any_true
from apc_feedback.command_echo import CommandEcho
from apc_feedback.command_map import CommandMap
from apc_feedback.delay_telling import DelayTelling
from apc_feedback.feedback_law import FeedbackLaw, FeedbackOutput
from apc_feedback.hold_torque import HoldTorque
from apc_feedback.payload_estimate import PayloadCarry
from apc_feedback.robot_sampling import (
    RETIME_INTERVALS,
    PeriodAdvice,
    RobotSampler,
    RobotSamplingConfig,
    period_advice,
)
from apc_feedback.robot_step import NOTHING, Step
from apc_feedback.sample_timing import SampleTiming
from apc_feedback.supervisor import ADAPTIVE, FALLBACK, Supervisor, fallback_gains
from apc_feedforward.goals import GoalQueue, accept_goal, report_sampled
from apc_feedforward.nominal import Setpoint
from apc_msgs_py import JointSample, TrajectoryGoal

#: How long a start after a fault or an abort takes to bring the arm to rest (s): at most
#: 7.5 |qd| rad/s^2 of deceleration (docs/robot.md, "A stall in a move").
STOP_TIME_S = 0.2
#: A stop whose set point is further than this from the arm on some joint (rad) starts again
#: from the arm's state at that sample: an arm that cannot decelerate as planned (at its effort
#: limits, or spinning faster than the stop assumed) is not pulled back to where it could not
#: stop; held to the first stop, the physical Panda was lost after 5 of 9 stalls of 0.3 s.
STOP_TOLERANCE = 0.05


@dataclass
class RobotLoop:
    """Robot mode's loop (see the module docstring).

    Parameters
    ----------
    law : FeedbackLaw
    sampling : RobotSamplingConfig
    command : CommandMap
    plan : GoalQueue
        The feedforward's plan on the model: every sample's set point and torque, the goals.
    gravity : callable
        ``g(q)`` of the controller's model (model order): the hold without feedback.
    path_tolerance : (n,) ndarray
        Per joint (rad, model order); 0 = no check on that joint.
    count : callable
        ``count(name)`` for every counted event (the node's diagnostics).
    log : callable
        ``log(level, text)`` for every event worth a line ("info", "warn", "error").
    supervisor : Supervisor, optional
        Decides per sample whether ``law`` or ``fallback`` commands (see
        :mod:`apc_feedback.supervisor`); None: ``law`` always does.
    fallback : FeedbackLaw, optional
        The law that holds the arm when the supervisor trips (with ``supervisor`` only).
    stop_time : float
        A start after a fault or an abort brings the arm to rest from its measured state over
        this (s); 0 holds the measured position at once.
    command_first : bool
        An adaptive law with a receding plan commands from the gain it planned a sample before
        and learns after the publish (:meth:`command_published`; ``defer_learning``): for
        T = 1 ms (docs/robot.md, "A robot's clock").
    feedforward_ahead : bool
        Send the nominal torque of the interval the law models the command acting over, whole
        samples on (:meth:`RobotSampler.samples_late`); its middle with a plan built so.
    period_from_driver : bool
        At the first start after activation, for a driver whose period T should be a multiple
        of (:func:`~apc_feedback.robot_sampling.period_advice`), ``Step(retime=that multiple)``
        instead of a start: the caller builds the loop again at it (else: a start, and a warning).
    payload : PayloadCarry, optional
        Estimates the payload at the first still hold of an activation and carries it in the
        plan's model and ``gravity`` (``payload_carried``), the law (``move_nominal``: the
        adaptive law's) handing that load over; None: the model stays.
    """

    law: FeedbackLaw
    sampling: RobotSamplingConfig
    command: CommandMap
    plan: GoalQueue
    gravity: Callable[[np.ndarray], np.ndarray]
    path_tolerance: np.ndarray
    count: Callable[[str], object] = field(default=lambda name: None)
    log: Callable[[str, str], object] = field(default=lambda level, text: None)
    supervisor: Supervisor | None = None
    fallback: FeedbackLaw | None = None
    stop_time: float = STOP_TIME_S
    command_first: bool = False
    feedforward_ahead: bool = True
    period_from_driver: bool = False
    payload: PayloadCarry | None = None

    def __post_init__(self) -> None:
        if not 0.0 <= self.stop_time < float("inf"):
            raise ValueError(f"stop_time must be finite and >= 0 s, got {self.stop_time}")
        if (self.supervisor is None) != (self.fallback is None):
            raise ValueError("a supervisor needs a fallback law and a fallback a supervisor")
        if self.payload is not None and not hasattr(self.law, "move_nominal"):
            raise ValueError("a payload estimate needs a law that hands its load over")
        self._limit = self.command.to_model(self.command.limit)
        # The adaptive law's learning after its command, its model of when a command acts.
        self._settle = getattr(self.law, "settle", None) if self.command_first else None
        if self._settle is not None:
            self.law.defer_learning = True
        self._split_delay = getattr(self.law, "split_delay", None)
        self.sampler = RobotSampler(self.sampling)
        self.period_ns = self.sampler.period_ns
        self._advice = PeriodAdvice(self.period_ns)
        self.active = False
        self.faulted = False  # watchdog: silent until a fresh state
        self._restart = self._first_start = False  # the next sample is a start; the first one
        self._replan = False  # and drops the plan (a fault, an abort; activation drops it then)
        self._sent: tuple[int, np.ndarray] | None = None  # (k, total torque, model order)
        self.command_state_ns: int | None = None  # driver stamp of the newest law command's
        # state, until its publish is reported
        self.timing = SampleTiming()
        self.hold = HoldTorque(self.sampling.period)  # the watchdog's torque
        # The adaptive law's model of its input, and the delay it used at its last step.
        self._input_timing = getattr(self.law, "input_timing", None)
        self._modelled_delay: float | None = None
        self._velocity_kind = ""  # what the samples' velocity was at the last start
        # When the arm applies a command, from the driver's effort; and the delay the law is told.
        self.echo = CommandEcho(self.period_ns)
        self.delay = DelayTelling(self.echo, self.sampler, self.period_ns)

    # -- inputs ---------------------------------------------------------------------------------
    def on_joint_state(self, state: JointSample, now_ns: int, newest_ns: int | None = None) -> Step:
        """A validated joint state (model order) arriving at ``now``: sample ``k`` and its
        command if it is the state for one, unless the state stamped ``newest_ns``, already in
        hand, overtakes it (:meth:`RobotSampler.overtaken`; counted: ``samples_overtaken``).
        Raises :class:`~apc_feedback.robot_sampling.StateRejectedError` for one that cannot be
        sampled."""
        sampler = self.sampler
        sample = sampler.offer(state, now_ns)
        self.echo.observe(state.stamp_ns, state.effort, sampler.driver_period_ns)
        take = sampler.last
        if not self.active or take is None or take.state_ns != state.stamp_ns:
            return NOTHING  # not sampling, or no sample time near this state
        if take.missed:
            self.count("missed_samples")
        if sample is None:
            self.count(take.reason)
            return NOTHING
        if sampler.overtaken(newest_ns):
            self.count("samples_overtaken")
            return NOTHING
        assert sampler.phase_ns is not None
        self.timing.sampled(take, sampler.phase_ns, sampler.driver_period_ns)
        self.count("samples_taken")
        if self.faulted:
            self.faulted, self._restart, self._replan = False, True, True
            self.count("watchdog_recovered")
            self.log("warn", f"sample {take.k}: joint states back; bringing the arm to rest")
        if self._restart:
            if sampler.driver_period_ns <= 0:
                # The start tells the law and the fallback the driver's period (the delay a
                # command meets): it waits for the second state, which gives the period.
                self.count("start_waits_for_driver_period")
                return NOTHING
            retime = period_advice(self.period_ns, sampler.driver_period_ns)
            if self.period_from_driver and self._first_start and retime is not None:
                if sampler.intervals_seen < RETIME_INTERVALS:  # judged on a few more
                    self.count("start_waits_for_driver_period")
                    return NOTHING
                self.count("period_from_driver")
                return Step(retime=retime)
            self._start(take.k, sample)
        elif (moved := self.delay.moved(take.k)) or sampler.velocity_kind != self._velocity_kind:
            self._follow_driver(take.k, moved)
        setpoint = self._setpoint(take.k, sample.position)
        if setpoint is None:
            return Step(sample=sample)
        if self.plan.stopping(take.k) and any_true(
            np.abs(sample.position - setpoint.q) > STOP_TOLERANCE
        ):
            self._stop(take.k, sample)  # the arm could not follow the stop: from where it is
            self.count("stop_restarts")
            setpoint = self._setpoint(take.k, sample.position)
            if setpoint is None:
                return Step(sample=sample)
        step = self._law_step(sample, setpoint)
        if step.command is not None:
            self.command_state_ns = take.state_ns
            assert self._sent is not None
            self.echo.sent(take.state_ns, self._sent[1])
        return step

    def add_goal(self, goal: TrajectoryGoal) -> None:
        """Queue a goal (model order); it starts when the motion before it ends. Raises
        ValueError naming what is wrong (the node rejects it: counted and logged)."""
        accept_goal(self.plan, goal, self.count, self.log)

    def activate(self) -> None:
        """Start sampling with a start (hold the measured position); the first state that
        arrives locks the samples' phase to the driver's cycle. The plan of an earlier
        activation and its queued goals are dropped now: goals that come after it wait for the
        first sample."""
        self.sampler.start()
        self.active, self.faulted, self._restart, self._replan = True, False, True, False
        self._first_start = True  # the one period_from_driver judges the driver at
        self._drop_plan(None)
        self.hold.reset()
        if self.payload is not None:
            self.payload.start()

    def deactivate(self) -> np.ndarray | None:
        """Stop; the last command (gravity hold at the newest position), None without one."""
        self.sampler.stop()
        self.active, self.command_state_ns = False, None
        return self._hold_command()

    def tick(self, now_ns: int) -> Step:
        """The watchdog at ``now`` (a timer calls it): no accepted state within ``watchdog`` ->
        the gravity hold once (a fault); the samples' phase locks afresh when states return."""
        if not self.active or self.sampler.fresh(now_ns):
            return NOTHING
        if self.sampler.newest is None:
            self.count("no_state")  # nothing measured yet: wait, not a fault
            return NOTHING
        if self.faulted:
            return NOTHING
        self.faulted, self.command_state_ns = True, None
        self.sampler.start()  # the driver may come back on another cycle
        self.echo.reset()
        self.count("watchdog")
        self.log("error", "watchdog: no fresh joint state; holding against gravity+payload, silent")
        return Step(command=self._hold_command(learned=True))

    def command_published(self, now_ns: int) -> None:
        """The node published the step's command at ``now``: the state-to-command time of the
        newest law command (a gravity hold has no state); with ``command_first`` the law
        learns from the sample now."""
        if self.command_state_ns is not None:
            self.timing.commanded(self.command_state_ns, now_ns)
            self.command_state_ns = None
        if self._settle is not None:
            try:
                self._settle()
            except ValueError as exc:  # FeedbackError is one
                self.count("feedback_law_errors")
                self.log("error", f"after a command: {exc}; the next sample is a gap")

    # -- the loop -------------------------------------------------------------------------------
    def _start(self, k: int, sample: JointSample) -> None:
        """Sample ``k`` is a start: the plan and the queued goals are dropped; after a fault or
        an abort the arm is brought to rest from the ``sample``'s state (``stop_time``).

        A law that models its input's delay (``AdaptiveFeedback`` with ``input_lags``) is told
        the delay it splits ``Ĝ(0)`` by at its next (re)start: the delay the driver's effort
        shows (:class:`~apc_feedback.command_echo.CommandEcho`), else one driver period (the
        driver applies a command at its next write: ros2_control's read, update, write cycle)
        with two scored beside it (a drive that adds a cycle). It is told the samples'
        velocity's stencil too: robot mode's estimate for a driver that sends none, or the
        driver's backward difference; a measured velocity has none.
        """
        driver_period = self.sampler.driver_period_ns * 1e-9  # known: a start waits for it
        if (warning := self._advice.warning(self.sampler.driver_period_ns)) is not None:
            self.count("period_advice")
            self.log("warn", f"sample {k}: {warning}")
        self._tell_law()
        if self.supervisor is not None and self.fallback is not None:
            if self.fallback.kind == "computed_torque":
                self.fallback.reconfigure(fallback_gains(self.supervisor.config, driver_period))
            self.supervisor.expect_command_delay(driver_period)
        if self._replan:
            self._drop_plan(k)
            if self.stop_time > 0.0:
                self._stop(k, sample)
        self._restart = self._replan = self._first_start = False
        self.count("starts")

    def _stop(self, k: int, sample: JointSample) -> None:
        """Bring the arm to rest from the ``sample``'s state, from sample ``k`` on."""
        assert sample.position is not None and sample.velocity is not None
        self.plan.stop(k, sample.position, sample.velocity, self.stop_time)

    def _tell_law(self) -> None:
        """Tell a law that models its samples' timing what robot mode knows of the driver now:
        the delay to the arm applying a command and the samples' velocity (see :meth:`_start`)."""
        sampler = self.sampler
        self._velocity_kind = sampler.velocity_kind
        measured = self.delay.tell()
        expect = getattr(self.law, "expect_input_delay", None)
        if expect is None:
            return
        if measured is not None:
            expect(measured * 1e-9, (), True)
        else:
            # The arm may apply a command a cycle later (a drive that adds one): the law scores
            # both delays and a restart takes the clearly better.
            driver_period = sampler.driver_period_ns * 1e-9
            expect(driver_period, (2.0 * driver_period,))
        self.law.expect_velocity_stencil(sampler.velocity_stencil())

    def _follow_driver(self, k: int, delay_moved: bool) -> None:
        """Robot mode learnt something of the driver since the start that the law models: the
        samples' velocity is another kind (that the driver's velocity is the backward
        difference of its positions takes states in motion to tell,
        :class:`~apc_feedback.joint_velocity.DifferenceCheck`), or the driver's effort shows
        another delay to the arm applying a command (``delay_moved``: judged once a sample,
        :meth:`~apc_feedback.delay_telling.DelayTelling.moved`). Counted and logged; a law
        that models its samples is told and, if it commands, restarts its identification from
        Eq. 33 with its commands on their way kept."""
        sampler = self.sampler
        what = []
        if sampler.velocity_kind != self._velocity_kind:
            self.count("velocity_kind_changes")
            what.append(f"the joint states' velocity is {sampler.velocity_description()}")
        if delay_moved:
            assert self.echo.delay_ns is not None
            self.count("measured_delay_changes")
            what.append(
                f"the driver's effort shows a command applied {self.echo.delay_ns * 1e-6:.3g} ms "
                "after its state"
            )
        self._tell_law()
        text = f"sample {k}: " + "; ".join(what)
        if getattr(self.law, "expect_input_delay", None) is None:
            self.log("info", text)
            return
        supervisor = self.supervisor
        if supervisor is None or supervisor.in_charge == ADAPTIVE:
            self.law.restart()
        self.log(
            "info",
            text + "; the adaptive law models it from its next start, which is now unless "
            "the fallback commands",
        )

    def _drop_plan(self, k: int | None) -> None:
        dropped = self.plan.restart()
        if dropped:
            self.count("goals_dropped")
            where = "activation" if k is None else f"sample {k}"
            self.log("warn", f"{where}: start, {dropped} queued goal(s) dropped")

    def _setpoint(self, k: int, position: np.ndarray) -> Setpoint | None:
        """The plan's set point of sample ``k`` (``position``: the measured one, where a start
        holds), with ``feedforward_ahead`` the nominal torque of when its command acts; what
        the plan did on the way counted and logged. None if not even a hold could be computed
        (counted: ``feedforward_errors``)."""
        out = self.plan.sample(k, position, lambda sp: sp)
        report_sampled(k, out, self.count, self.log)
        if out.setpoint is None or not self.feedforward_ahead or self._split_delay is None:
            return out.setpoint
        late = self.sampler.samples_late(self._split_delay())
        return self.plan.acting_later(out.setpoint, late)

    def _law_step(self, sample: JointSample, setpoint: Setpoint) -> Step:
        """The law on ``sample`` and its set point: the command; none when the path tolerance
        aborts the goal (the next sample is a start)."""
        assert sample.position is not None and sample.velocity is not None
        error = np.abs(sample.position - setpoint.q)
        tolerance = self.path_tolerance
        moving = not self.plan.stopping(setpoint.k) and any_true(setpoint.qd != 0.0)
        if moving and any_true((tolerance > 0.0) & (error > tolerance)):
            j = int(np.argmax(np.where(tolerance > 0.0, error - tolerance, -np.inf)))
            self.count("path_tolerance_aborts")
            self.log(
                "error",
                f"sample {setpoint.k}: tracking error {error[j]:.4g} rad "
                f"on joint {self.command.model_joints[j]!r} beyond its path tolerance "
                f"{tolerance[j]:.4g} rad; goal aborted, bringing the arm to rest",
            )
            # The next sample is the start: this one gets no command (the last one stands), so
            # the law takes no identification step across the change of plan. The fallback
            # holds that start where the law's model is outside the supervisor's region
            # (input_gain): a diverging law must not hold the arm; a sound one holds it better
            # than the fallback, which does not know a payload.
            supervisor = self.supervisor
            if (
                supervisor is not None
                and supervisor.in_charge == ADAPTIVE
                and supervisor.input_gain(self.law) is not None
            ):
                supervisor.hand_over("path_tolerance")
                self._hand_over(setpoint.k, "path tolerance abort")
            self._restart = self._replan = True
            return Step(sample=sample, setpoint=setpoint)
        k = sample.stamp_ns // self.period_ns
        sent = self._sent
        applied = sent[1] if sent is not None and sent[0] == k - 1 else None
        args = (k, sample.position, sample.velocity, setpoint.q, setpoint.qd, setpoint.qdd)
        if self.supervisor is None:
            out = self._update(self.law, args, setpoint.u_n, applied)
        else:
            out = self._supervised(args, setpoint.u_n, applied)
        if out is None:
            return Step(sample=sample, setpoint=setpoint)  # no command, the last one stands
        row = self.command(setpoint.u_n + out.du)
        self._sent = (k, self.command.to_model(row))
        self.hold.sent(self._sent[1], self.gravity(sample.position))
        self.count("commands")
        if self.payload is not None:
            self._carry_payload(k, sample.position, setpoint.q)
        if out.skipped:
            self.count("rls_skipped_updates")
        if out.rejected:
            self.count("rls_rejected_updates")
        return Step(command=row, sample=sample, setpoint=setpoint)

    def _update(
        self, law: FeedbackLaw, args: tuple, u_n: np.ndarray, applied: np.ndarray | None
    ) -> FeedbackOutput | None:
        """One step of ``law``; None (counted, logged) if it fails or its torque is not finite."""
        k = args[0]
        try:
            out = law.update(*args, u_n, applied)
            if not all_true(np.isfinite(u_n + out.du)):
                raise ValueError(f"u_n + du is not finite at sample {k}")
        except ValueError as exc:  # FeedbackError is one
            self.count("feedback_law_errors")
            self.log("error", f"sample {k}: {exc}; no command")
            return None
        return out

    def _supervised(
        self, args: tuple, u_n: np.ndarray, applied: np.ndarray | None
    ) -> FeedbackOutput | None:
        """The output of the law in charge; the supervisor decides which one that is.

        The fallback runs every sample, so it is ready the moment it takes over (its state,
        such as a PID's integral, current). The adaptive law, reset when the fallback takes
        over, is idle while the fallback commands (it is shown the commands sent, which are
        still on their way when it takes over): its first sample at the hand-back starts it
        from Eq. 33 there. A hand-back gives the law the joints at the next sample with the
        plan, hold or motion, rejoined from the measured state (``approach_time``): asked to
        remove the fallback's sag under an unknown payload at once, the law on a 100 Hz driver
        asked for 135-380 N m within two samples and re-tripped within five, at every
        hand-back (docs/robot.md has that and what else was tried).
        """
        supervisor, k = self.supervisor, args[0]
        error, error_qd = args[1] - args[3], args[2] - args[4]
        assert supervisor is not None and self.fallback is not None
        backup = self._update(self.fallback, args, u_n, applied)
        if supervisor.in_charge == FALLBACK:
            observe = getattr(self.law, "observe_command", None)
            if observe is not None and backup is not None:
                observe(k, u_n, backup.du)  # still on its way when the law takes over
            if supervisor.update(k, error, error_qd, self.law, None, False) is None:
                return backup
            approach = supervisor.config.approach_time
            # The rejoin starts at this sample's measured state, so the law's first set point,
            # a sample on, is where the arm is then: anchored a sample later, at the state
            # itself, it trailed a moving arm by a sample's motion (1.3 deg on the paper's move
            # through robot_sim).
            if approach > 0.0 and self.plan.rejoin(k, args[1], args[2], approach):
                self.count("supervisor.handbacks")
                self.log(
                    "info",
                    f"sample {k}: tracking error settled under the {self.fallback.kind} "
                    f"fallback; the adaptive law commands from the next sample, rejoining the "
                    f"plan from the measured state over {approach:g} s",
                )
                return backup
            out = self._update(self.law, args, u_n, applied)
            self.count("supervisor.handbacks")
            self.log(
                "info",
                f"sample {k}: tracking error settled under the {self.fallback.kind} fallback; "
                "the adaptive law commands again",
            )
            self._report_delay_change(k)
            return out
        out = self._update(self.law, args, u_n, applied)
        self._report_delay_change(k)  # a hand-back's start at the sample after the approach's
        if out is None:
            return None
        clipped = bool(any_true(np.abs(u_n + out.du) > self._limit))
        trigger = supervisor.update(k, error, error_qd, self.law, out.residual, clipped)
        if trigger is None:
            return out
        self.count(f"supervisor.{trigger}")
        self._hand_over(k, f"supervisor trigger {trigger!r}")
        return backup

    def _report_delay_change(self, k: int) -> None:
        """After a step of the adaptive law: count and log once a start at which it took
        another delay than the one it used before (a re-told delay it chose again is none)."""
        timing = self._input_timing
        if timing is None or timing.delay == self._modelled_delay:
            return
        changed = self._modelled_delay is not None
        self._modelled_delay = timing.delay
        if changed:
            self.count("input_delay_changes")
            self.log(
                "info",
                f"sample {k}: the adaptive law now models a command acting "
                f"{timing.delay * 1e3:.1f} ms after its state",
            )

    def _hand_over(self, k: int, why: str) -> None:
        """The fallback takes the joints; the adaptive law restarts its identification."""
        assert self.fallback is not None
        self.law.reset()
        self.count("supervisor.handovers")
        supervisor = self.supervisor
        assert supervisor is not None
        if supervisor.latched:
            self.count("supervisor.latched")
            self.log(
                "error",
                f"sample {k}: {why}; the adaptive law lost the joints again after each of its "
                f"last {supervisor.config.failed_handbacks} hand-backs: the "
                f"{self.fallback.kind} fallback keeps them (latched) until the node is "
                "configured again",
            )
            return
        self.log(
            "warn",
            f"sample {k}: {why}; the {self.fallback.kind} fallback commands the joints, the "
            "adaptive law restarts its identification from Eq. 33",
        )

    def _carry_payload(self, k: int, position: np.ndarray, held: np.ndarray) -> None:
        """Sample ``k``'s command to the payload's estimate; once in, the plan carries it."""
        assert self.payload is not None and self._sent is not None
        adaptive = self.supervisor is None or self.supervisor.in_charge == ADAPTIVE
        step = self.payload.observe(position, self._sent[1], adaptive and self.plan.holding(k + 1))
        if step.text is not None:
            self.log("info", f"sample {k}: {step.text}")
        if step.carry_kg is not None:
            model, gravity = self.payload.model_with(step.carry_kg)
            self.plan.carry(model, k + 1)
            shift, self.gravity = gravity(held) - self.gravity(held), gravity
            self.law.move_nominal(shift)
            self.count("payload_carried")

    def _hold_command(self, learned: bool = False) -> np.ndarray | None:
        newest = self.sampler.newest
        if newest is None or newest.position is None:
            return None
        gravity = self.gravity(newest.position)
        return self.command(self.hold.torque(gravity) if learned else gravity)
