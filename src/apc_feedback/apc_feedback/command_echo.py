"""When the arm applies a command, measured from the driver's effort state.

A ros2_control driver whose hardware exports an effort state interface publishes it in
``/joint_states``; for an effort-commanded arm that is the torque its drives apply (robot_sim's
``effort``: the torque applied over the period that ended at the stamp). Robot mode knows when
its command leaves (in the callback of the state it was computed from), not when the arm
applies it: at the driver's next write after it arrives, one driver period, or later where the
drive adds a cycle of its own or the command's trip crosses a cycle. The effort shows it: the
first state whose effort is a sent command, where the state of the cycle before it had another
one, reports the command applied over the period that ended at its stamp, so

    delay = stamp - driver period - stamp of the state the command was computed from.

:class:`CommandEcho` matches every state's effort against the commands sent and not yet seen
applied (:data:`PENDING` of them, the newest last), and keeps the last :data:`ECHOES` delays;
:attr:`CommandEcho.delay_ns` is the second shortest of them once there are :data:`MIN_ECHOES`:
what the driver and its drive always take (a late command, a loaded machine's jitter, only
adds), the shortest seen twice. One shorter echo is not it: robot_sim's drive that adds a
cycle applies the first command after activation a cycle early (its buffer starts empty), and
taking that 10 ms on a 100 Hz driver told the law a wrong delay, its split held, for the two
samples before the 20 ms showed: a restart more, which on wall time tripped the supervisor in
the hold. A change seen across a state that never arrived (lost on the way, best effort; a
driver's missed cycle) is not measured: the command may have been applied in the cycle not
seen, and taken a period later, with a reader that dropped states, it had robot mode tell the
law 6 ms for 2 ms on a 500 Hz driver. A command
matches when every joint's effort equals it to :data:`MATCH_TOLERANCE` (relative, a double's
round trip through a message is exact): a drive that reports a measured torque (noise, a
current loop) matches nothing, and the delay stays unknown, as it was before this check. Plain
Python: no rclpy.
"""

from __future__ import annotations

from collections import deque

import numpy as np

#: Commands sent and not yet seen applied that a state's effort is matched against.
PENDING = 8
#: Delays kept; the second shortest is the measured delay.
ECHOES = 9
#: Delays needed before the measured delay is taken.
MIN_ECHOES = 3
#: How closely an effort equals a command (relative to the command's size, at least 1e-9 N m).
MATCH_TOLERANCE = 1e-9


class CommandEcho:
    """The delay from a state to the arm applying the command computed from it (see the module
    docstring): :meth:`sent` every command, :meth:`observe` every state's effort."""

    def __init__(self) -> None:
        self._pending: deque[tuple[int, np.ndarray]] = deque(maxlen=PENDING)
        self._delays: deque[int] = deque(maxlen=ECHOES)
        self._effort: np.ndarray | None = None
        self._stamp_ns: int | None = None  # the last state's
        self.delay_ns: int | None = None  # the measured delay, None until MIN_ECHOES

    @property
    def longest_ns(self) -> int | None:
        """The longest of the delays kept, once :attr:`delay_ns` is measured (else None)."""
        return max(self._delays) if self.delay_ns is not None else None

    def steady(self, driver_period_ns: int) -> bool:
        """Whether :data:`ECHOES` delays are kept and every one is within half a driver period
        of the measured delay: a drive whose timing does not jitter."""
        delays = self._delays
        return (
            len(delays) == ECHOES
            and self.delay_ns is not None
            and 2 * (max(delays) - self.delay_ns) <= driver_period_ns
        )

    def reset(self) -> None:
        """Forget the delays (the driver may have changed: a gap in its states)."""
        self._pending.clear()
        self._delays.clear()
        self._effort = None
        self._stamp_ns = None
        self.delay_ns = None

    def sent(self, state_ns: int, command: np.ndarray) -> None:
        """A command (model order, as the arm applies it: within the effort limits) left in the
        callback of the state stamped ``state_ns``."""
        self._pending.append((state_ns, np.array(command, dtype=float)))

    def observe(self, stamp_ns: int, effort: np.ndarray | None, driver_period_ns: int) -> None:
        """A state's effort (model order; None: the driver sends none)."""
        previous, self._effort = self._effort, effort
        last_ns, self._stamp_ns = self._stamp_ns, stamp_ns
        if effort is None or previous is None or driver_period_ns <= 0:
            return
        if _equal(effort, previous):
            return  # the same torque as the cycle before: no new command applied
        # Whether the state before is the previous cycle's (within half a period of jitter).
        consecutive = last_ns is not None and 2 * (stamp_ns - last_ns) <= 3 * driver_period_ns
        for i, (state_ns, command) in enumerate(self._pending):
            if _equal(effort, command):
                delay = stamp_ns - driver_period_ns - state_ns
                for _ in range(i + 1):  # it and the older ones are past
                    self._pending.popleft()
                if consecutive and delay >= 0:
                    self._delays.append(delay)
                    if len(self._delays) >= MIN_ECHOES:
                        self.delay_ns = sorted(self._delays)[1]
                return


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(
        np.all(np.abs(a - b) <= MATCH_TOLERANCE * np.maximum(1.0, np.abs(b)))
    )
