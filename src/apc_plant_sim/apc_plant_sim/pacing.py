"""When the plant sends its joint state again, and when a lockstep run gives up: plain, no rclpy.

Wall-time rules of the plant node, told the time ``now`` (s, a monotonic clock) and never
reading one. Lockstep re-sends ``joint_states(k)`` after ``resend_s`` without both torques (the
controllers answer a resend from their cache) and ends the run after ``timeout_s``, at start
(peers missing) or at a sample; real time re-sends sample 0 every ``resend_s`` until both
controllers answer it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from apc_core.params import Param

#: The plant node's parameters of these rules.
PACING_PARAMS: tuple[Param, ...] = (
    Param(
        "resend_s", 0.5, "lockstep: re-send joint_states(k) after this wall time (s)", 0.01, 60.0
    ),
    Param(
        "lockstep_timeout_s",
        10.0,
        "lockstep: end the run with an error if the peers are not there at start, or sample k "
        "gets no torques, for this long (s)",
        0.1,
        3600.0,
    ),
)


class StatePacer:
    """Times of the joint states sent, and what is due (see module docstring).

    Parameters
    ----------
    resend_s, timeout_s : float
        Send the state again after this long; give up after this long (s).
    now : float
        When the node was created (s): the start-up timeout counts from here.
    """

    def __init__(self, resend_s: float, timeout_s: float, now: float) -> None:
        self.resend_s = resend_s
        self.timeout_s = timeout_s
        self.created = now
        #: When the current sample's state was first sent (latency counts from here).
        self.first_sent = 0.0
        self.last_sent = 0.0

    @classmethod
    def from_params(cls, values: Mapping[str, Any], now: float) -> StatePacer:
        """From the node's :data:`PACING_PARAMS` values."""
        return cls(values["resend_s"], values["lockstep_timeout_s"], now)

    def sent(self, now: float, resend: bool = False) -> None:
        """A joint state went out at ``now``; ``resend``: the current sample's, again."""
        self.last_sent = now
        if not resend:
            self.first_sent = now

    def resend_due(self, now: float) -> bool:
        """The last state went out more than ``resend_s`` ago."""
        return now - self.last_sent > self.resend_s

    def waited(self, now: float) -> float:
        """How long the current sample has waited for its torques (s)."""
        return now - self.first_sent

    def start_timed_out(self, now: float) -> bool:
        """The peers have not come within ``timeout_s`` of the node's creation."""
        return now - self.created > self.timeout_s

    def sample_timed_out(self, now: float) -> bool:
        """The current sample has waited more than ``timeout_s`` for its torques."""
        return self.waited(now) > self.timeout_s
