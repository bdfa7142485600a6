"""The plant's torque intake: which torque is applied at which sample. Plain class, no rclpy.

The plant applies ``u_n(k) + du(k)`` over the period after sample ``k``. :class:`TorqueIntake`
files the torques that arrive by their stamp and decides, told the current sample index and
never reading a clock:

- what a torque is: rejected (not a sample the plant sent), out of order, stale, a duplicate,
  kept ahead for its sample, or taken;
- lockstep: when both torques of the current sample are in (:meth:`TorqueIntake.complete`);
- real time: what the tick of the current sample applies (:meth:`TorqueIntake.tick`): both
  newest torques, the nominal one alone (no fresh feedback torque: a warning), or the brake
  (no fresh nominal torque), freshness counted in samples.

The node maps each outcome to counters, log lines and what it publishes.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

import apc_msgs_py as wire
from apc_core.params import Param

#: The plant node's parameter of the real-time watchdog.
WATCHDOG_PARAMS: tuple[Param, ...] = (
    Param(
        "watchdog_s",
        0.05,
        "realtime: a torque whose sample is older than this (s, counted in the plant's own "
        "periods) is missing: no feedback -> nominal only; no nominal -> brake",
        0.0,
        60.0,
    ),
)


class Source(enum.Enum):
    """Where a torque comes from; the value is its topic (the node's counters name it)."""

    NOMINAL = wire.FEEDFORWARD_TORQUE
    FEEDBACK = wire.FEEDBACK_TORQUE


class Filed(enum.Enum):
    """What :meth:`TorqueIntake.take` did with a torque; the value names its counter."""

    TAKEN = "taken"
    AHEAD = "ahead"  # real time: kept until its sample comes
    OUT_OF_ORDER = "out_of_order"
    STALE = "stale"
    DUPLICATE = "duplicate"


class Action(enum.Enum):
    """What the real-time tick of a sample does."""

    WAIT = "wait"  # sample 0 is not answered by both controllers yet: the clock has not started
    BOTH = "both"  # apply u_n + du
    NOMINAL_ONLY = "nominal_only"  # no fresh feedback torque: apply u_n alone
    BRAKE = "brake"  # no fresh nominal torque: hold the arm


@dataclass(frozen=True)
class Tick:
    """What the real-time tick of sample ``k`` applies and how its torques stood.

    Attributes
    ----------
    action : Action
    tau : (n,) ndarray or None
        The torque to apply (BOTH, NOMINAL_ONLY).
    missing, late : tuple of Source
        Torques never received / whose newest answers an earlier sample.
    braking_starts, braking_ends : bool
        The brake engages at this sample / is released at it.
    """

    action: Action
    tau: np.ndarray | None = None
    missing: tuple[Source, ...] = ()
    late: tuple[Source, ...] = ()
    braking_starts: bool = False
    braking_ends: bool = False


class TorqueIntake:
    """Nominal and feedback torques by sample (see module docstring).

    Parameters
    ----------
    period_ns : int
        Sampling period T (ns); stamps are ``kT``.
    lockstep : bool
        Lockstep (every torque of every sample, in order) or real time (the newest torques).
    watchdog_ns : int
        Real time: a torque answering sample ``j`` is fresh up to the sample stamped
        ``jT + watchdog_ns``.
    """

    def __init__(self, period_ns: int, lockstep: bool, watchdog_ns: int) -> None:
        self.period_ns = period_ns
        self.lockstep = lockstep
        self.watchdog_ns = watchdog_ns
        #: The plant sent sample 0: before that no controller can have computed a torque.
        self.started = False
        self.braking = False
        # Lockstep: torques by stamp until their sample is integrated.
        self.pending: dict[Source, dict[int, np.ndarray]] = {s: {} for s in Source}
        # Real time: the newest torque taken for a sample that has come, as (stamp, effort).
        self.latest: dict[Source, tuple[int, np.ndarray] | None] = {s: None for s in Source}
        # Real time: nominal torques for samples not reached yet (the feedforward's lookahead),
        # by stamp; each becomes the latest when its sample comes.
        self.ahead: dict[int, np.ndarray] = {}
        self._newest: dict[Source, int] = {}  # newest stamp taken per source

    @classmethod
    def from_params(cls, period_ns: int, lockstep: bool, values: Mapping[str, Any]) -> TorqueIntake:
        """With the watchdog of the node's :data:`WATCHDOG_PARAMS` values."""
        return cls(period_ns, lockstep, wire.seconds_to_ns(values["watchdog_s"]))

    def take(self, source: Source, stamp_ns: int, effort: np.ndarray, k: int) -> Filed:
        """File a torque stamped ``stamp_ns`` while the plant is at sample ``k``.

        Rejected (raises :class:`~apc_msgs_py.WireError`): a stamp that is negative, off the
        sample grid, ahead of the current sample (a nominal torque: more than
        :data:`~apc_msgs_py.MAX_LOOKAHEAD` samples ahead), or any torque before the plant
        sent sample 0 -- no controller can have computed it. Ignored: older than the newest
        torque taken for a sample that has come (OUT_OF_ORDER); in lockstep, an answer to a
        sample already integrated (STALE, e.g. to a resend) and a second torque for a sample
        (DUPLICATE: the first stands, nothing is applied twice). In real time a nominal torque
        sent ahead is kept by its sample (AHEAD) and does not make an older one out of order:
        over a link with jitter u_n(k + 1) can overtake u_n(k) (best effort keeps no order),
        and u_n(0) dropped that way would hold the run at sample 0.
        """
        current = k * self.period_ns
        ahead = wire.MAX_LOOKAHEAD * self.period_ns if source is Source.NOMINAL else 0
        wire.sample_index(stamp_ns, self.period_ns)
        if stamp_ns > current + ahead or not self.started:
            raise wire.WireError(
                f"header.stamp: {stamp_ns} ns is not a sample the plant sent (at {current} ns)"
            )
        newest = self._newest.get(source)
        if newest is not None and stamp_ns < newest:
            return Filed.OUT_OF_ORDER
        pending = self.pending[source]
        if self.lockstep:
            if stamp_ns < current:
                return Filed.STALE
            if stamp_ns in pending:
                return Filed.DUPLICATE
        elif stamp_ns > current:
            self.ahead[stamp_ns] = effort  # the newest when its sample comes
            return Filed.AHEAD
        self._newest[source] = stamp_ns
        if self.lockstep:
            pending[stamp_ns] = effort
        else:
            self.latest[source] = (stamp_ns, effort)
        return Filed.TAKEN

    # -- lockstep -------------------------------------------------------------------------------
    def missing(self, k: int) -> list[Source]:
        """Lockstep: the torques of sample ``k`` not in yet."""
        stamp = k * self.period_ns
        return [s for s in Source if not self.holds(s, stamp)]

    def complete(self, k: int) -> bool:
        """Lockstep: both torques of sample ``k`` are in."""
        return self.started and not self.missing(k)

    def pop(self, k: int) -> np.ndarray:
        """Lockstep: ``u_n(k) + du(k)``, forgetting both."""
        stamp = k * self.period_ns
        return self.pending[Source.NOMINAL].pop(stamp) + self.pending[Source.FEEDBACK].pop(stamp)

    def holds(self, source: Source, stamp_ns: int) -> bool:
        """Whether the torque of ``source`` answering the sample stamped ``stamp_ns`` is held:
        pending (lockstep), the latest or kept ahead (real time). For a driver of the plant's
        clock that steps once the plant has what it needs (a simulated-time test)."""
        if self.lockstep:
            return stamp_ns in self.pending[source]
        latest = self.latest[source]
        if latest is not None and latest[0] == stamp_ns:
            return True
        return source is Source.NOMINAL and stamp_ns in self.ahead

    # -- real time ------------------------------------------------------------------------------
    def _promote_ahead(self, k: int) -> None:
        """The newest nominal torque sent ahead whose sample has come is the latest."""
        current = k * self.period_ns
        due = [stamp for stamp in self.ahead if stamp <= current]
        if not due:
            return
        newest = max(due)
        latest = self.latest[Source.NOMINAL]
        if latest is None or newest > latest[0]:
            self.latest[Source.NOMINAL] = (newest, self.ahead[newest])
            self._newest[Source.NOMINAL] = newest
        for stamp in due:
            del self.ahead[stamp]

    def tick(self, k: int) -> Tick:
        """Real time: what the tick of sample ``k`` applies (see :class:`Action`).

        Freshness is by the sample a torque answers, not by when it arrived: after a stall of
        the process (a loaded machine) the tick fires before the torques waiting in the queue
        are taken, and a wall-clock rule would brake the arm although both controllers had
        answered every sample. A torque answering sample ``j`` is fresh up to sample
        ``j + watchdog / T``, so a dead controller trips the watchdog at the tick one to two
        periods after the watchdog time since its last torque arrived.
        """
        self._promote_ahead(k)
        ff, fb = self.latest[Source.NOMINAL], self.latest[Source.FEEDBACK]
        if k == 0 and (ff is None or fb is None):
            # The clock starts once both controllers have answered sample 0, so that start-up
            # (first callbacks, discovery of the return path) is not counted as late.
            return Tick(Action.WAIT)
        stamp = k * self.period_ns
        missing = tuple(s for s in Source if self.latest[s] is None)
        late = tuple(
            s for s in Source if (latest := self.latest[s]) is not None and latest[0] < stamp
        )
        ff_fresh = ff is not None and stamp - ff[0] <= self.watchdog_ns
        fb_fresh = fb is not None and stamp - fb[0] <= self.watchdog_ns
        if not ff_fresh:
            starts = not self.braking
            self.braking = True
            return Tick(Action.BRAKE, None, missing, late, braking_starts=starts)
        assert ff is not None
        ends, self.braking = self.braking, False
        if fb_fresh and fb is not None:
            return Tick(Action.BOTH, ff[1] + fb[1], missing, late, braking_ends=ends)
        tau = ff[1] + np.zeros_like(ff[1])
        return Tick(Action.NOMINAL_ONLY, tau, missing, late, braking_ends=ends)
