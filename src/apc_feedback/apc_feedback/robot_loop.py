"""Robot mode's control loop without ROS: samples, set points, the law, the command, faults.

:class:`RobotLoop` is what the commanding node (``robot_node``) runs; it is told joint
states, set points and tick times, never reads a clock, and answers with a :class:`Step`: the
sample to publish for the feedforward, and the command to send, if any.

One sample ``k``:

1. the timer ticks, :class:`~apc_feedback.robot_sampling.RobotSampler` takes sample ``k``
   (stamped ``kT``) from the newest joint state; it goes out for the feedforward;
2. the feedforward has already sent set point ``k`` (it answers sample ``k - 1`` with set
   points up to ``k - 1 + lookahead``), so the law runs at once; at a (re)start it arrives
   after sample ``k``, and the law runs then;
3. the command is ``u_n(k) + du(k)`` in ``command_joints`` order, clipped to the effort
   limits. The add happens here, where set point and ``du`` both are: no torque message
   between the feedforward and the command.

Starts. At activation, after a watchdog fault and after a path-tolerance abort, the sample
goes out flagged as a *start*: the feedforward drops its plan and queued goals and holds that
sample's measured position (a set point that stays put), and flags the set point that answers
it. Until that set point arrives every other one is dropped (it belongs to the plan before).
The law keeps what it identified (the payload it learned is still on the arm): restarted
with ``F̂(0), Ĝ(0)`` of Eq. 33 and ``P(0)`` on an arm still moving (sagging after a watchdog
hold) it diverged, with the model kept it stops the arm within a few samples. A start always
follows a gap in ``k``, so no identification step spans the change of plan.

Faults.

- Watchdog (no accepted joint state within ``watchdog``): one command holding the arm against
  gravity at the last measured position (the controller's model, no feedback: ``du`` needs a
  measurement there is not), then no more commands. A forward_command_controller keeps
  applying that last command, and a driver with a command timeout applies its own policy; the
  loop neither keeps closing a loop on a stale state nor leaves a torque computed for a moving
  arm. A fresh state restarts the loop at the position measured then.
- Path tolerance (``|q - q_d| > tolerance`` on a joint while the set point moves, like
  joint_trajectory_controller's ``constraints.<joint>.trajectory``): the goal is aborted and
  the measured position held (a start).
- Supervision (with a ``supervisor`` and a ``fallback`` law): when a trigger of
  :mod:`apc_feedback.supervisor` fires the fallback commands from that sample on, the law is
  reset and idle, and it takes the joints again (from Eq. 33) once the error has settled. A
  path-tolerance abort hands the hold to the fallback too when the law's identified input gain
  is outside the supervisor's region: a diverging law must not hold the arm.

Deactivation sends the same gravity hold once and stops commanding (an inactive controller
commands nothing: another one may take the joints over).

The driver's rate. A command reaches the arm at the driver's next write after it arrives, so
the torque computed from a state is applied an age plus up to one driver period later, and
that delay moves from sample to sample when T is not a whole number of driver periods. Eq. 16
has no such delay. Measured with this loop closed around apc's plant (the PUMA, 5 lb payload,
recommended preset, ``test/test_robot_loop.py``): drivers at 1 kHz, 500, 400 and 333 Hz hold
within 0.23 deg; at 250, 200 or 100 Hz the adaptive law diverges. Run the driver
(ros2_control's ``update_rate``) at 500 Hz or more.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from apc_core.wire import JointSample, SetpointStamped
from apc_feedback.controller import FeedbackLaw, FeedbackOutput
from apc_feedback.robot_sampling import RobotSampler, RobotSamplingConfig
from apc_feedback.supervisor import ADAPTIVE, FALLBACK, Supervisor

#: Samples a start waits for the set point that answers it before it is sent again: a start
#: published before the feedforward's subscription matched (DDS discovery) is lost, and without
#: a resend the loop would never command.
START_RESEND_SAMPLES = 10


class CommandMap:
    """Model-order torques -> one ``Float64MultiArray`` row in ``command_joints`` order, clipped.

    Parameters
    ----------
    model_joints : sequence of str
        The model's joint order (every array in apc).
    command_joints : sequence of str
        The command's order (the forward_command_controller's ``joints``): the same joints.
    effort_limit : (n,) array
        Per-joint bound in model order (the URDF's ``<limit effort>``).
    count : callable
        ``count("clipped.<joint>")`` for each joint clipped.
    """

    def __init__(
        self,
        model_joints: Sequence[str],
        command_joints: Sequence[str],
        effort_limit: np.ndarray,
        count: Callable[[str], object] = lambda name: None,
    ) -> None:
        model, command = list(model_joints), list(command_joints)
        if sorted(model) != sorted(command) or len(set(command)) != len(command):
            raise ValueError(
                f"command_joints must list the model's joints {model} once each, got {command}"
            )
        self.model_joints = tuple(model)
        self.joints = tuple(command)
        self.order = np.array([model.index(name) for name in command])
        self.limit = np.asarray(effort_limit, dtype=float)[self.order]
        self._clipped = tuple(f"clipped.{name}" for name in command)
        self._count = count

    def __call__(self, torque: np.ndarray) -> np.ndarray:
        """The command row (a new array), each joint clipped counted."""
        row = torque[self.order]
        over = np.abs(row) > self.limit
        if over.any():
            for i in np.flatnonzero(over):
                self._count(self._clipped[i])
            np.clip(row, -self.limit, self.limit, out=row)
        return row

    def to_model(self, row: np.ndarray) -> np.ndarray:
        """A command row back in model order."""
        torque = np.empty_like(row)
        torque[self.order] = row
        return torque


class Step(NamedTuple):
    """What the node publishes after one call of :class:`RobotLoop`.

    Attributes
    ----------
    sample : JointSample or None
        A sample stamped ``kT`` for the feedforward.
    start : bool
        ``sample`` is a start (the feedforward holds its position, see the module docstring).
    command : (n,) ndarray or None
        The command row in ``command_joints`` order.
    """

    sample: JointSample | None = None
    start: bool = False
    command: np.ndarray | None = None


NOTHING = Step()


@dataclass
class RobotLoop:
    """Robot mode's loop (see the module docstring).

    Parameters
    ----------
    law : FeedbackLaw
    sampling : RobotSamplingConfig
    command : CommandMap
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
    """

    law: FeedbackLaw
    sampling: RobotSamplingConfig
    command: CommandMap
    gravity: Callable[[np.ndarray], np.ndarray]
    path_tolerance: np.ndarray
    count: Callable[[str], object] = field(default=lambda name: None)
    log: Callable[[str, str], object] = field(default=lambda level, text: None)
    supervisor: Supervisor | None = None
    fallback: FeedbackLaw | None = None

    def __post_init__(self) -> None:
        if (self.supervisor is None) != (self.fallback is None):
            raise ValueError("a supervisor needs a fallback law and a fallback a supervisor")
        self._limit = self.command.to_model(self.command.limit)
        self.sampler = RobotSampler(self.sampling)
        self.period_ns = self.sampler.period_ns
        self.active = False
        self.faulted = False  # watchdog: silent until a fresh state
        self._restart = False  # the next sample taken is a start
        self._start_stamp: int | None = None  # waiting for the set point answering it
        self._setpoints: dict[int, SetpointStamped] = {}
        self._pending: JointSample | None = None  # sample waiting for its set point
        self._sent: tuple[int, np.ndarray] | None = None  # (k, total torque, model order)
        self._taken_stamp: int | None = None  # stamp of the newest sample taken
        self.last_age_ns = -1  # age of the state the last tick sampled (-1: none)
        self.last_late_ns = 0  # how late the last tick was after its sample's time

    # -- inputs ---------------------------------------------------------------------------------
    def on_joint_state(self, state: JointSample, now_ns: int) -> None:
        """A validated joint state (model order); raises
        :class:`~apc_feedback.robot_sampling.StateRejectedError` for one that cannot be sampled."""
        self.sampler.offer(state, now_ns)

    def activate(self, now_ns: int) -> None:
        """Start sampling at ``now`` with a start (hold the measured position)."""
        self.sampler.start(now_ns)
        self.active, self.faulted, self._restart = True, False, True
        self._pending = None

    def deactivate(self) -> np.ndarray | None:
        """Stop; the last command (gravity hold at the newest position), None without one."""
        self.active = False
        self._pending, self._start_stamp = None, None
        self._setpoints.clear()
        return self._hold_command()

    def tick(self, now_ns: int) -> Step:
        """One timer call at ``now``: take sample ``k``, run the law if its set point is here."""
        if not self.active:
            return NOTHING
        if not self.sampler.fresh(now_ns):
            self.sampler.tick(now_ns)  # keeps k moving through the fault
            if self.sampler.newest is None:
                self.count("no_state")  # nothing measured yet: wait, not a fault
                return NOTHING
            if self.faulted:
                return NOTHING
            self.faulted, self._pending = True, None
            self.count("watchdog")
            self.log("error", "watchdog: no fresh joint state; holding against gravity, silent")
            return Step(command=self._hold_command())
        self.sampler.tick(now_ns)
        take = self.sampler.last
        self.last_age_ns, self.last_late_ns = take.age_ns, take.late_ns
        if take.missed:
            self.count("missed_ticks")
        if self._pending is not None:
            self.count("missed_setpoint")  # sample k - 1 got no set point before tick k
            self._pending = None
        if take.sample is None:
            self.count(take.reason)
            return NOTHING
        self.count("samples_taken")
        self._taken_stamp = take.sample.stamp_ns
        if self.faulted:
            self.faulted, self._restart = False, True
            self.count("watchdog_recovered")
            self.log("warn", f"sample {take.k}: joint states back; holding the measured position")
        if self._restart:
            return self._start(take.sample)
        waiting = self._start_stamp is not None
        if (
            waiting
            and take.sample.stamp_ns - self._start_stamp >= START_RESEND_SAMPLES * self.period_ns
        ):
            self.count("start_resends")
            return self._start(take.sample)
        self._pending = take.sample
        step = self._try()
        return step if step.start else step._replace(sample=take.sample)

    def on_setpoint(self, setpoint: SetpointStamped, start: bool) -> Step:
        """A validated set point (model order); ``start`` if it answers a start sample."""
        stamp = setpoint.stamp_ns
        if self._start_stamp is not None:
            if not (start and stamp == self._start_stamp):
                self.count("superseded_setpoints")  # from the plan before the start
                return NOTHING
            self._start_stamp = None
        if stamp in self._setpoints:
            self.count("duplicate_setpoints")  # the first one stands
            return NOTHING
        taken = self._taken_stamp
        if taken is not None and (stamp < taken or (stamp == taken and self._pending is None)):
            self.count("late_setpoints")  # its sample is done (or gone)
            return NOTHING
        self._setpoints[stamp] = setpoint
        if len(self._setpoints) > 32:  # bounded: a feedforward far ahead is not followed
            del self._setpoints[min(self._setpoints)]
        return self._try()

    # -- the loop -------------------------------------------------------------------------------
    def _start(self, sample: JointSample) -> Step:
        """Send ``sample`` as a start; its set point arrives later."""
        self._restart = False
        self._start_stamp = sample.stamp_ns
        self._setpoints.clear()
        self._pending = sample
        self.count("starts")
        return Step(sample=sample, start=True)

    def _try(self) -> Step:
        """Run the law on the pending sample if its set point is here: the command; nothing
        when the path tolerance aborts the goal (the next sample is a start)."""
        sample = self._pending
        if sample is None or self._start_stamp is not None:
            return NOTHING
        setpoint = self._setpoints.pop(sample.stamp_ns, None)
        if setpoint is None:
            return NOTHING  # the feedforward is late; the set point may follow
        for old in [s for s in self._setpoints if s < sample.stamp_ns]:
            del self._setpoints[old]
        self._pending = None
        assert sample.position is not None and sample.velocity is not None
        error = np.abs(sample.position - setpoint.q)
        tolerance = self.path_tolerance
        if np.any(setpoint.qd != 0.0) and np.any((tolerance > 0.0) & (error > tolerance)):
            j = int(np.argmax(np.where(tolerance > 0.0, error - tolerance, -np.inf)))
            self.count("path_tolerance_aborts")
            self.log(
                "error",
                f"sample {sample.stamp_ns // self.period_ns}: tracking error {error[j]:.4g} rad "
                f"on joint {self.command.model_joints[j]!r} beyond its path tolerance "
                f"{tolerance[j]:.4g} rad; goal aborted, holding the measured position",
            )
            # The next sample is the start: this one gets no command (the last one stands), so
            # the law sees a gap and takes no identification step across the change of plan.
            # A supervised loop holds that start with the fallback when the law's identified
            # model is outside the supervisor's region (input_gain): a diverging law must not
            # hold the arm. A law whose model is sound holds it better than the fallback, which
            # does not know a payload (computed torque sags 1.7 deg under the PUMA's 5 lb,
            # test_robot_mode's abort holds within 0.5 deg); the triggers keep watching it.
            supervisor = self.supervisor
            if (
                supervisor is not None
                and supervisor.in_charge == ADAPTIVE
                and supervisor.input_gain(self.law) is not None
            ):
                supervisor.hand_over("path_tolerance")
                self._hand_over(sample.stamp_ns // self.period_ns, "path tolerance abort")
            self._restart = True
            self._setpoints.clear()
            return NOTHING
        k = sample.stamp_ns // self.period_ns
        sent = self._sent
        applied = sent[1] if sent is not None and sent[0] == k - 1 else None
        args = (k, sample.position, sample.velocity, setpoint.q, setpoint.qd, setpoint.qdd)
        if self.supervisor is None:
            out = self._update(self.law, args, setpoint.u_n, applied)
        else:
            out = self._supervised(args, setpoint.u_n, applied)
        if out is None:
            return NOTHING  # no command, the last one stands
        row = self.command(setpoint.u_n + out.du)
        self._sent = (k, self.command.to_model(row))
        self.count("commands")
        if out.skipped:
            self.count("rls_skipped_updates")
        if out.rejected:
            self.count("rls_rejected_updates")
        return Step(command=row)

    def _update(
        self, law: FeedbackLaw, args: tuple, u_n: np.ndarray, applied: np.ndarray | None
    ) -> FeedbackOutput | None:
        """One step of ``law``; None (counted, logged) when it fails or its torque is not
        finite."""
        k = args[0]
        try:
            out = law.update(*args, u_n, applied)
            if not np.isfinite(u_n + out.du).all():
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
        over, is idle while the fallback commands: its first sample at the hand-back starts it
        from Eq. 33 there. Identifying from the fallback's hold instead (its applied torques)
        made the law re-trip within 4 samples of every hand-back (``apc_plant_sim.robot_offline``,
        G forced wrong on a clean hold: 5.8 deg and three hand-overs against 1.8 deg, one
        hand-over and 0.000 deg final error after the hand-back).
        """
        supervisor, k = self.supervisor, args[0]
        error, error_qd = args[1] - args[3], args[2] - args[4]
        assert supervisor is not None and self.fallback is not None
        backup = self._update(self.fallback, args, u_n, applied)
        if supervisor.in_charge == FALLBACK:
            if supervisor.update(k, error, error_qd, self.law, None, False) is None:
                return backup
            out = self._update(self.law, args, u_n, applied)
            self.count("supervisor.handbacks")
            self.log(
                "info",
                f"sample {k}: tracking error settled under the {self.fallback.kind} fallback; "
                "the adaptive law commands again",
            )
            return out
        out = self._update(self.law, args, u_n, applied)
        if out is None:
            return None
        clipped = bool((np.abs(u_n + out.du) > self._limit).any())
        trigger = supervisor.update(k, error, error_qd, self.law, out.residual, clipped)
        if trigger is None:
            return out
        self.count(f"supervisor.{trigger}")
        self._hand_over(k, f"supervisor trigger {trigger!r}")
        return backup

    def _hand_over(self, k: int, why: str) -> None:
        """The fallback takes the joints; the adaptive law restarts its identification."""
        assert self.fallback is not None
        self.law.reset()
        self.count("supervisor.handovers")
        self.log(
            "warn",
            f"sample {k}: {why}; the {self.fallback.kind} fallback commands the joints, the "
            "adaptive law restarts its identification from Eq. 33",
        )

    def _hold_command(self) -> np.ndarray | None:
        newest = self.sampler.newest
        if newest is None or newest.position is None:
            return None
        return self.command(self.gravity(newest.position))
