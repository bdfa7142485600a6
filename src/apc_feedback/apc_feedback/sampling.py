"""What a sample of the feedback is, and every rule about stamps: plain classes, no rclpy.

The feedback law runs once per sample ``k``, on the joint state and the set point of that
sample. Two jobs decide what reaches it, each told message stamps (integer ns) and sample
indices, never a clock of its own:

- a :class:`JointStateSampler` turns the joint states that arrive into samples stamped on
  apc's grid ``kT``: :class:`GridSampler` for apc's plant, whose states are the samples;
- the :class:`SamplePairer` pairs sample ``k``'s state with the set point stamped ``kT`` (in
  either order) into one :class:`Step`, and decides what every other message is: a duplicate,
  a resend, a copy of a set point already used, stale, or off the grid.

Each call returns a :class:`Decision`; the node maps it to counters, log lines and what it
publishes, and keeps no rule of its own.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol

import numpy as np

import apc_msgs_py as wire

#: Samples waiting for their other half; beyond this the oldest is dropped (bounded memory).
MAX_PENDING = 100
#: Set points kept after use, to recognise a copy the feedforward sends again when the plant
#: re-sends a joint state (lockstep): with the lookahead it can arrive samples later.
RECENT_SETPOINTS = wire.MAX_LOOKAHEAD + 2


class JointStateSampler(Protocol):
    """Where the feedback's samples come from: joint states in, samples on the grid out.

    A sample is a :class:`apc_msgs_py.JointSample` stamped ``kT`` (``T`` the period in ns,
    ``k >= 0`` its index); the node hands every sample to the :class:`SamplePairer`, which
    pairs it with the set point of the same stamp. Implementations are plain classes told the
    node's time ``now_ns`` (the node's clock, which honours ``use_sim_time``), never reading
    a clock themselves, so they are tested with synthetic time.

    - Grid (:class:`GridSampler`, apc's plant): every joint state is stamped on the grid and
      *is* sample ``k``; :meth:`offer` returns it, :meth:`tick` is never due.
    - Robot (:class:`apc_feedback.robot_sampling.RobotSampler`, a driver stamping states
      with its own clock, at its own rate): :meth:`offer` returns the state nearest the time
      ``kT + phase`` (the phase locked to the driver's cycle) carried to that time and
      restamped ``kT``, None for the states between samples; :meth:`tick` is never due. A
      sample time without a state is a gap, which the law skips, as for a lost sample. How
      old the state was is the sampler's to measure and expose for diagnostics.

    A state that cannot be a sample (off the grid, negative, older than allowed, a duplicate
    or out of order) raises :class:`apc_msgs_py.WireError` from :meth:`offer` with the
    reason; the node counts and logs it as ``rejected.joint_states``, like a malformed message.
    """

    #: True if the node must call :meth:`tick` every period (a timer on the node's clock).
    ticking: bool

    def offer(self, state: wire.JointSample, now_ns: int) -> wire.JointSample | None:
        """A joint state as it arrived: the sample it is, if it is one now; else None."""
        ...

    def tick(self, now_ns: int) -> wire.JointSample | None:
        """The sample due at ``now_ns``, if one is; else None."""
        ...


class GridSampler:
    """Samples of apc's plant: a joint state stamped ``kT`` is sample ``k`` (lockstep or
    real time alike); any other stamp is refused."""

    ticking = False

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns

    def offer(self, state: wire.JointSample, now_ns: int) -> wire.JointSample:
        wire.sample_index(state.stamp_ns, self.period_ns)  # raises WireError off the grid
        return state

    def tick(self, now_ns: int) -> None:
        return None


class Verdict(enum.Enum):
    """What a message offered to the :class:`SamplePairer` turned out to be."""

    #: Kept until the other half of its sample arrives.
    HELD = "held"
    #: Completed its sample: :attr:`Decision.step` is ready for the law.
    STEP = "step"
    #: A second, different half for a sample held or just done: the first one stands.
    DUPLICATE = "duplicate"
    #: The joint state of the sample just done, sent again (a lockstep resend): answer it with
    #: the output already published; the law never sees a sample twice.
    RESENT = "resent"
    #: A bit-identical copy of a set point already used (the feedforward answering a re-sent
    #: joint state, possibly samples later with its lookahead): nothing to do.
    COPY = "copy"
    #: Not a usable sample (stale, off the grid): :attr:`Decision.reason` says why.
    REJECTED = "rejected"


@dataclass(frozen=True, slots=True)
class Step:
    """One law step: sample ``k``'s joint state and set point.

    ``applied`` is the torque the state reports applied over the period before ``k``
    (``effort``), None at the first step: before it, the torque applied was not this law's.
    """

    k: int
    stamp_ns: int
    state: wire.JointSample
    setpoint: wire.SetpointStamped
    applied: np.ndarray | None

    def law_inputs(self) -> tuple:
        """``(q, qd, q_d, qd_d, qdd_d, u_n, applied)``: what ``FeedbackLaw.update`` takes
        after ``k``."""
        s, d = self.state, self.setpoint
        return (s.position, s.velocity, d.q, d.qd, d.qdd, d.u_n, self.applied)


@dataclass(frozen=True, slots=True)
class Decision:
    """The :class:`SamplePairer`'s answer to one message.

    ``dropped`` is True when holding it pushed the oldest waiting half of the same topic out
    (more than :data:`MAX_PENDING` samples waiting).
    """

    verdict: Verdict
    step: Step | None = None
    reason: str = ""
    dropped: bool = False


_HELD = Decision(Verdict.HELD)
_DUPLICATE = Decision(Verdict.DUPLICATE)
_RESENT = Decision(Verdict.RESENT)
_COPY = Decision(Verdict.COPY)


def same_setpoint(used: wire.SetpointStamped | None, other: wire.SetpointStamped) -> bool:
    """Whether ``other`` is a bit-identical copy of the set point ``used`` for its sample."""
    return (
        used is not None
        and used.time_from_start_ns == other.time_from_start_ns
        and all(
            np.array_equal(a, b)
            for a, b in zip(
                (used.q, used.qd, used.qdd, used.u_n),
                (other.q, other.qd, other.qdd, other.u_n),
                strict=True,
            )
        )
    )


class SamplePairer:
    """Pairs sample ``k``'s joint state with the set point stamped ``kT`` into one :class:`Step`.

    Rules, per message:

    - a set point off the grid is rejected (a joint state is its sampler's to judge);
    - for the sample just done (the newest step), a joint state is :attr:`Verdict.RESENT`;
      a set point is a :attr:`Verdict.COPY` if bit-identical to the one used, else a
      :attr:`Verdict.DUPLICATE`;
    - for an older sample, a copy of a set point used within the last
      :data:`RECENT_SETPOINTS` samples is a :attr:`Verdict.COPY`; anything else is stale and
      rejected;
    - for a newer sample, a second half of the same kind is a duplicate (the first stands);
      otherwise it is held until its other half arrives; the step then forgets every half
      waiting for that sample or an older one, which can no longer be completed (a gap: the
      law sees sample ``k`` follow an older one, not ``k - 1``, and skips its identification
      step).

    A sample is done once its step is returned, whatever the law then makes of it: nothing
    reaches the law twice.
    """

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns
        #: Stamp of the newest step returned (None before the first).
        self.done_ns: int | None = None
        self._states: dict[int, wire.JointSample] = {}
        self._setpoints: dict[int, wire.SetpointStamped] = {}
        self._used: dict[int, wire.SetpointStamped] = {}

    def offer_state(self, sample: wire.JointSample) -> Decision:
        """Sample ``k``'s joint state (from a :class:`JointStateSampler`)."""
        stamp = sample.stamp_ns
        if self.done_ns is not None and stamp <= self.done_ns:
            if stamp == self.done_ns:
                return _RESENT
            return self._stale(stamp)
        return self._hold(self._states, stamp, sample)

    def offer_setpoint(self, setpoint: wire.SetpointStamped) -> Decision:
        """The set point stamped ``kT`` (from the feedforward)."""
        stamp = setpoint.stamp_ns
        try:
            wire.sample_index(stamp, self.period_ns)
        except wire.WireError as exc:
            return Decision(Verdict.REJECTED, reason=str(exc))
        if self.done_ns is not None and stamp <= self.done_ns:
            if same_setpoint(self._used.get(stamp), setpoint):
                return _COPY
            if stamp == self.done_ns:
                return _DUPLICATE
            return self._stale(stamp)
        return self._hold(self._setpoints, stamp, setpoint)

    @staticmethod
    def _stale(stamp: int) -> Decision:
        return Decision(Verdict.REJECTED, reason=f"stale stamp {stamp} ns")

    def _hold(
        self, pending: dict, stamp: int, half: wire.JointSample | wire.SetpointStamped
    ) -> Decision:
        if stamp in pending:
            return _DUPLICATE
        pending[stamp] = half
        dropped = len(pending) > MAX_PENDING
        if dropped:
            del pending[min(pending)]
        state, setpoint = self._states.get(stamp), self._setpoints.get(stamp)
        if state is None or setpoint is None:
            return Decision(Verdict.HELD, dropped=True) if dropped else _HELD
        for waiting in (self._states, self._setpoints):
            for old in [s for s in waiting if s <= stamp]:
                del waiting[old]
        self._used[stamp] = setpoint
        if len(self._used) > RECENT_SETPOINTS:
            del self._used[min(self._used)]
        first = self.done_ns is None
        self.done_ns = stamp
        applied = None if first else state.effort
        step = Step(stamp // self.period_ns, stamp, state, setpoint, applied)
        return Decision(Verdict.STEP, step=step, dropped=dropped)
