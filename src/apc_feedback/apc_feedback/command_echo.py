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
where a command is held over several driver cycles :attr:`CommandEcho.delay_ns` is the second
shortest of them once there are :data:`MIN_ECHOES`:
what the driver and its drive always take (a late command, a loaded machine's jitter, only
adds), the shortest seen twice. One shorter echo is not it: robot_sim's drive that adds a
cycle applies the first command after activation a cycle early (its buffer starts empty), and
taking that 10 ms on a 100 Hz driver told the law a wrong delay, its split held, for the two
samples before the 20 ms showed: a restart more, which on wall time tripped the supervisor in
the hold. A change seen across a state that never arrived (lost on the way, best effort; a
driver's missed cycle) is not measured: the command may have been applied in the cycle not
seen, and taken a period later, with a reader that dropped states, it had robot mode tell the
law 6 ms for 2 ms on a 500 Hz driver.

Where a command is sent every driver cycle (samples under two driver periods apart: T = 1 ms
on a 1 kHz driver, the preset's 10 ms on a 100 Hz one) the echoes are not what the arm gets.
A command a cycle late meets the next one, on time, at the driver, which applies the newer:
the late one never shows, and the cycle it missed repeats the command before, which no echo
counts. So where most commands run late the echoes are mostly the few on time. There the
measured delay is the age the command the arm applies has in most cycles (:class:`CycleAges`:
at every cycle, from the start of the cycle back to the state of the command its effort
shows, a repeat's a period older each cycle). On wall time at 1 kHz a sample takes about a
driver period on a 2-core machine, and 25-70 % of the commands act a cycle late, with the
phase of the two clocks; simulated with 70 % late, the law told the second shortest echo
(1 ms) chattered at its limits (0.5-0.7 deg, the commands' spread 12-40 N m), told the age
of most cycles (2 ms) it holds within 0.18 deg, its commands within 0.03 N m. Where a
command is held over several driver cycles a late one shows (the next comes a sample later)
and the echoes are the delays. A command
matches when every joint's effort equals it to :data:`MATCH_TOLERANCE` (relative, a double's
round trip through a message is exact): a drive that reports a measured torque (noise, a
current loop) matches nothing, and the delay stays unknown, as it was before this check. Plain
Python: no rclpy.
"""

from __future__ import annotations

from collections import Counter, deque

import numpy as np

#: Commands sent and not yet seen applied that a state's effort is matched against.
PENDING = 8
#: Delays kept; the second shortest is the measured delay.
ECHOES = 9
#: Delays needed before the measured delay is taken.
MIN_ECHOES = 3
#: How closely an effort equals a command (relative to the command's size, at least 1e-9 N m).
MATCH_TOLERANCE = 1e-9
#: Driver cycles whose applied command's age is kept where a command is sent every cycle.
CYCLES = 60
#: How many times the cycles of the measured age another age needs to replace it.
SWITCH = 1.5


class CycleAges:
    """The age the arm's command has at each driver cycle (from the start of the cycle it is
    applied over back to its state's stamp) over the last :data:`CYCLES` cycles, and the age
    most of them agree with (:attr:`delay_ns`): it changes to another once that one has been
    seen in :data:`SWITCH` times as many cycles, so that delays split near evenly do not
    alternate. Ages are grouped by whole driver periods; the delay is the median of its
    group."""

    def __init__(self) -> None:
        self._ages: deque[tuple[int, int]] = deque(maxlen=CYCLES)  # (driver periods, ns)
        self._group: int | None = None
        self.delay_ns: int | None = None

    @property
    def longest_ns(self) -> int | None:
        """The oldest age kept (ns), None without one."""
        return max(age for _, age in self._ages) if self._ages else None

    def __len__(self) -> int:
        return len(self._ages)

    def reset(self) -> None:
        """Forget the ages and the delay."""
        self._ages.clear()
        self._group = self.delay_ns = None

    def add(self, age_ns: int, driver_period_ns: int) -> None:
        """The age of the command applied over one more driver cycle (ns)."""
        self._ages.append((round(age_ns / driver_period_ns), age_ns))
        if len(self._ages) < MIN_ECHOES:
            return
        counts = Counter(group for group, _ in self._ages)
        best, cycles = counts.most_common(1)[0]
        if self._group is None or cycles >= SWITCH * counts[self._group]:
            self._group = best
        ages = sorted(age for group, age in self._ages if group == self._group)
        self.delay_ns = ages[len(ages) // 2]


class CommandEcho:
    """The delay from a state to the arm applying the command computed from it (see the module
    docstring) for samples ``sample_period_ns`` apart: :meth:`sent` every command,
    :meth:`observe` every state's effort."""

    def __init__(self, sample_period_ns: int) -> None:
        self.sample_period_ns = sample_period_ns
        self._pending: deque[tuple[int, np.ndarray]] = deque(maxlen=PENDING)
        self._delays: deque[int] = deque(maxlen=ECHOES)
        self._echo_ns: int | None = None  # the second shortest echo, None until MIN_ECHOES
        self.cycles = CycleAges()
        self._applied_ns: int | None = None  # the state of the command the last effort showed
        self._effort: np.ndarray | None = None
        self._stamp_ns: int | None = None  # the last state's
        self._per_cycle = False  # a command sent every driver cycle (at the last state)

    @property
    def delay_ns(self) -> int | None:
        """The measured delay (module docstring), None until it is measured."""
        return self.cycles.delay_ns if self._per_cycle else self._echo_ns

    @property
    def longest_ns(self) -> int | None:
        """The longest of the delays kept, once :attr:`delay_ns` is measured (else None)."""
        if self.delay_ns is None:
            return None
        return self.cycles.longest_ns if self._per_cycle else max(self._delays)

    def steady(self, driver_period_ns: int) -> bool:
        """Whether :data:`ECHOES` delays (cycles' ages) are kept and every one is within half a
        driver period of the measured delay: a drive whose timing does not jitter."""
        measured, longest = self.delay_ns, self.longest_ns
        kept = len(self.cycles) if self._per_cycle else len(self._delays)
        return (
            kept >= ECHOES
            and measured is not None
            and longest is not None
            and 2 * (longest - measured) <= driver_period_ns
        )

    def reset(self) -> None:
        """Forget the delays (the driver may have changed: a gap in its states)."""
        self._pending.clear()
        self._delays.clear()
        self.cycles.reset()
        self._echo_ns = self._applied_ns = None
        self._effort = None
        self._stamp_ns = None

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
        self._per_cycle = self.sample_period_ns < 2 * driver_period_ns
        start_ns = stamp_ns - driver_period_ns  # of the cycle the effort was applied over
        matches = [i for i, (_, command) in enumerate(self._pending) if _equal(effort, command)]
        if _equal(effort, previous):
            # The same torque as the cycle before: no new command applied, unless one equal to
            # it was sent (a clipped command repeats bit for bit), which leaves its age unknown.
            if self._applied_ns is not None and not matches:
                self.cycles.add(start_ns - self._applied_ns, driver_period_ns)
            return
        if not matches:
            self._applied_ns = None  # a torque no command was (a measured one)
            return
        state_ns = self._pending[matches[0]][0]
        for _ in range(matches[0] + 1):  # it and the older ones are past
            self._pending.popleft()
        self._applied_ns = state_ns
        delay = start_ns - state_ns
        if len(matches) == 1 and delay >= 0:
            self.cycles.add(delay, driver_period_ns)
        # Whether the state before is the previous cycle's (within half a period of jitter).
        consecutive = last_ns is not None and 2 * (stamp_ns - last_ns) <= 3 * driver_period_ns
        if consecutive and delay >= 0:
            self._delays.append(delay)
            if len(self._delays) >= MIN_ECHOES:
                self._echo_ns = sorted(self._delays)[1]


def _equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(
        np.all(np.abs(a - b) <= MATCH_TOLERANCE * np.maximum(1.0, np.abs(b)))
    )
