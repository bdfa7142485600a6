"""Where playback is on the bag's time line: the player's clock rules, with no rclpy.

A pass over the window ``[start_ns, end_ns)`` begins at a steady-clock instant ``t0``; the
message logged at ``log_time`` is due at ``t0 + (log_time - start_ns) / rate`` (``rate`` 0: at
once, in log-time order). The bag time a ``--clock`` publishes is ``start_ns + rate * (now -
t0)``, clamped to the window's end; before the first pass, or at rate 0, it is the log time of
the last message sent (the window start before any). Every method takes the steady-clock time
as an argument, so the rules are tested with synthetic time.
"""

from __future__ import annotations


class PlaybackTimeline:
    """Due times and bag time of one window played at ``rate``.

    Parameters
    ----------
    start_ns, end_ns : int, int or None
        The window on the bag's log-time line; ``end_ns`` excluded, ``None``: to the bag's end.
    rate : float
        Bag seconds per steady-clock second, ``>= 0``; 0 plays as fast as possible.
    """

    def __init__(self, start_ns: int, end_ns: int | None, rate: float) -> None:
        if rate < 0:
            raise ValueError(f"rate must be >= 0, got {rate}")
        if end_ns is not None and end_ns < start_ns:
            raise ValueError(f"window end {end_ns} ns is before its start {start_ns} ns")
        self.start_ns = start_ns
        self.end_ns = end_ns
        self.rate = rate
        self.t0_ns: int | None = None  # steady-clock start of the current pass
        self.last_sent_ns: int | None = None  # log time of the last message sent
        self.last_sent_at_ns = 0  # steady-clock time it went out
        self.sent_this_pass = 0

    @property
    def started(self) -> bool:
        return self.t0_ns is not None

    def begin_pass(self, now_ns: int) -> None:
        """A pass over the window starts at steady-clock ``now_ns``."""
        self.t0_ns = now_ns
        self.sent_this_pass = 0

    def due_ns(self, log_time_ns: int) -> int:
        """Steady-clock time at which the message logged at ``log_time_ns`` goes out."""
        if self.t0_ns is None:
            raise RuntimeError("no pass has begun")
        if self.rate == 0:
            return self.t0_ns
        return self.t0_ns + int((log_time_ns - self.start_ns) / self.rate)

    def sent(self, log_time_ns: int, now_ns: int) -> None:
        """The message logged at ``log_time_ns`` went out at steady-clock ``now_ns``."""
        self.last_sent_ns = log_time_ns
        self.last_sent_at_ns = now_ns
        self.sent_this_pass += 1

    def bag_time_ns(self, now_ns: int) -> int:
        """The bag time at steady-clock ``now_ns`` (what ``--clock`` publishes)."""
        if self.t0_ns is None or self.rate == 0:
            return self.start_ns if self.last_sent_ns is None else self.last_sent_ns
        now = self.start_ns + int((now_ns - self.t0_ns) * self.rate)
        return now if self.end_ns is None else min(now, self.end_ns)

    def pass_wall_s(self) -> float:
        """Steady-clock seconds from the pass's start to its last message (0 before any)."""
        if self.t0_ns is None or not self.sent_this_pass:
            return 0.0
        return (self.last_sent_at_ns - self.t0_ns) / 1e9
