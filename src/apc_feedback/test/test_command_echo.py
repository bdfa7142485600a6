"""When the arm applies a command, from the driver's effort: synthetic drivers, synthetic time."""

from __future__ import annotations

import numpy as np
import pytest

from apc_feedback.command_echo import CYCLES, ECHOES, MIN_ECHOES, SWITCH, CommandEcho, CycleAges

MS = 1_000_000


def _drive(echo, period_ms, cycles_late, every=1, commands=30, noise=0.0, seed=0, late=0.0):
    """A driver of ``period_ms`` publishing at every cycle the torque applied over the cycle
    that ended then; a command computed from the state of cycle i (sent every ``every``
    cycles, in its callback) is applied from cycle i + 1 + ``cycles_late``, with probability
    ``late`` a cycle later (where a newer command arrives for the same cycle, the newer)."""
    rng = np.random.default_rng(seed)
    P = round(period_ms * MS)
    applied = np.zeros(2)
    queue: dict[int, np.ndarray] = {}
    for cycle in range(commands * every):
        if cycle in queue:
            applied = queue.pop(cycle)
        effort = applied + noise * rng.standard_normal(2)
        echo.observe(cycle * P + P, effort, P)  # the state at the end of the cycle
        if cycle % every == 0:
            command = rng.normal(size=2) * 10.0
            echo.sent(cycle * P + P, command)
            queue[cycle + 2 + cycles_late + int(rng.random() < late)] = command


def _applied(echo, stamp_ns, before, command, P):
    """The driver's states of the cycle before ``stamp_ns`` (effort ``before``) and at it
    (``command`` applied over the cycle that ended then)."""
    echo.observe(stamp_ns - P, before, P)
    echo.observe(stamp_ns, command, P)


def test_the_delay_is_one_driver_period_or_one_more_per_cycle_the_drive_adds():
    for period_ms, late, every in ((10.0, 0, 1), (10.0, 1, 1), (2.0, 1, 5), (4.0, 0, 5 // 2)):
        echo = CommandEcho(round(every * period_ms * MS))
        _drive(echo, period_ms, late, every)
        assert echo.delay_ns == round((1 + late) * period_ms * MS)
        assert echo.steady(round(period_ms * MS))  # every echo the same


def test_a_delay_is_steady_once_a_full_window_agrees_within_half_a_period():
    P = 4 * MS
    echo = CommandEcho(10 * P)
    assert not echo.steady(P)
    before = np.zeros(2)  # the effort before the first command
    for i in range(ECHOES):
        command = np.full(2, float(i + 1))
        echo.sent(i * 10 * P, command)
        _applied(echo, i * 10 * P + 3 * P, before, command, P)  # 2 P after its state
        before = command
        assert echo.steady(P) == (i + 1 == ECHOES)  # not on the first few: a window's worth
    command = np.full(2, 99.0)
    echo.sent(100 * P, command)
    _applied(echo, 100 * P + 4 * P, before, command, P)  # a cycle late: a jittering drive
    assert echo.delay_ns == 2 * P and not echo.steady(P)


def test_a_measured_torque_gives_no_delay_and_a_late_command_adds_none():
    noisy = CommandEcho(10 * MS)
    _drive(noisy, 10.0, 0, noise=1e-3)
    assert noisy.delay_ns is None
    P = 10 * MS
    echo = CommandEcho(10 * P)
    for i in range(MIN_ECHOES + 2):  # every third command a cycle late
        late = i % 3 == 2
        command = np.full(2, float(i + 1))
        echo.sent(i * 10 * P, command)
        _applied(echo, i * 10 * P + (3 if late else 2) * P, np.full(2, float(i)), command, P)
        echo.observe(i * 10 * P + 5 * P, command, P)  # held: no new application
    assert echo.delay_ns == P
    assert echo.longest_ns == 2 * P  # the late ones are kept: what a delay is not always
    echo.reset()
    assert echo.delay_ns is None and echo.longest_ns is None


def test_no_effort_or_a_torque_no_command_was_leaves_the_delay_unknown():
    silent, other = CommandEcho(MS), CommandEcho(MS)
    for i in range(10):
        for echo in (silent, other):
            echo.sent(i * MS, np.full(2, float(i)))
        silent.observe(i * MS + 2 * MS, None, MS)
        other.observe(i * MS + 2 * MS, np.full(2, 100.0 + i), MS)
    assert silent.delay_ns is None and other.delay_ns is None


def test_one_shorter_echo_is_not_the_delay():
    """A drive that adds a cycle and applies the first command a cycle early (its buffer
    empty at the start): the echoes are one period, then two; the delay is two periods from
    the first measurement on, the shortest seen twice."""
    P = 10 * MS
    echo = CommandEcho(10 * P)
    for i in range(MIN_ECHOES + 3):
        command = np.full(2, float(i + 1))
        echo.sent(i * 10 * P, command)
        _applied(echo, i * 10 * P + (2 if i == 0 else 3) * P, np.full(2, float(i)), command, P)
        if echo.delay_ns is not None:
            assert echo.delay_ns == 2 * P
    assert echo.delay_ns == 2 * P and echo.longest_ns == 2 * P


def test_a_change_seen_across_a_state_that_never_arrived_is_not_measured():
    """Commands applied 2 P after their state; before every other change the state of the
    cycle before is missing (states lost on the way): the change may have come in that cycle,
    so only the changes seen from the cycle before are measured."""
    P = 2 * MS
    echo = CommandEcho(10 * P)
    before = np.zeros(2)
    for i in range(2 * ECHOES):
        command = np.full(2, float(i + 1))
        echo.sent(i * 10 * P, command)
        applied = i * 10 * P + 3 * P  # over the cycle that ends then
        if i % 2:  # the states of that cycle's end and the one before it never arrive
            echo.observe(applied - 2 * P, before, P)
            echo.observe(applied + P, command, P)  # the change, seen a cycle late
        else:
            _applied(echo, applied, before, command, P)
        before = command
    assert echo.delay_ns == 2 * P and echo.longest_ns == 2 * P  # none measured as 3 P
    assert echo.steady(P)


@pytest.mark.parametrize(("late", "cycles"), [(0.0, 1), (0.3, 1), (0.7, 2), (0.9, 2)])
def test_a_command_every_cycle_is_measured_by_the_age_most_cycles_apply(late, cycles):
    """A 1 kHz driver and a command every cycle, a share ``late`` of them a cycle late: the
    late ones that meet the next command never show, and the cycles they miss repeat the
    command before, so the echoes are mostly the on-time commands. The delay is the age of
    the command most cycles apply (2 ms once most run late); with commands held over ten
    cycles a late one shows, and the delay is the shortest echo seen twice (1 ms)."""
    per_cycle = CommandEcho(MS)
    _drive(per_cycle, 1.0, 0, commands=300, seed=1, late=late)
    assert per_cycle.delay_ns == cycles * MS
    held = CommandEcho(10 * MS)
    _drive(held, 1.0, 0, every=10, commands=30, seed=1, late=late)
    assert held.delay_ns == MS


def test_the_age_most_cycles_apply_changes_once_another_is_switch_times_as_common():
    P = MS
    ages = CycleAges()
    for _ in range(CYCLES):
        ages.add(2 * P, P)
    assert ages.delay_ns == 2 * P and ages.longest_ns == 2 * P
    needed = next(n for n in range(CYCLES) if n >= SWITCH * (CYCLES - n))
    for n in range(1, needed + 1):
        ages.add(P + 30_000, P)  # jitter within the period's group
        assert ages.delay_ns == (2 * P if n < needed else P + 30_000)
    ages.reset()
    assert ages.delay_ns is None and ages.longest_ns is None
