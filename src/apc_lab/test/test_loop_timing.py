"""The robot path's timing analysis (``bench/robot_loop.py``'s) on synthetic records."""

from __future__ import annotations

import pytest

from apc_lab import loop_timing

T0 = 1.795e9  # driver clock (s): system time, where a float64 resolves ~0.24 us


def _records() -> tuple[dict, dict]:
    """Driver cycles every 1 ms; command i computed from state i, 0.3 ms after it, except
    command 5 (arrives 1.2 ms after its state: after the next cycle) and a repeated value."""
    cycles, arrivals, sent = [], [], []
    for i in range(10):
        t = T0 + i * 1e-3
        cycles.append((t, i == 6))  # the cycle after the late command got none
        state_ns = round(t * 1e9)
        delay = 1.2e-3 if i == 5 else 0.3e-3
        data = [1.0, 2.0, 3.0] if i in (2, 3) else [float(i), 0.0, 0.0]
        sent.append((data, state_ns, state_ns + 100_000, state_ns + 200_000))
        arrivals.append((data, t + delay))
    driver = {"commands": arrivals, "cycles": cycles, "counts": {}}
    return driver, {"sent": sent, "counters": {"samples_taken": 10}, "max_deviation_rad": 0.01}


def test_analysis_matches_commands_to_their_states_in_order_and_counts_late_cycles():
    driver, controller = _records()
    out = loop_timing.analyse(driver, controller, warmup_s=0.0, seconds=1.0)
    # The window opens at the first command's arrival: cycle 0 comes before it.
    assert out["cycles"] == 9 and out["held_cycles"] == 1
    assert out["late_fraction"] == pytest.approx(1 / 9, abs=1e-5)
    assert out["commands_matched"] == 10 and out["commands_unmatched"] == 0
    assert out["commands_lost"] == 0
    assert out["duplicate_commands"] == 1
    assert out["latency_us"]["max"] == pytest.approx(1200.0, abs=0.5)
    assert out["latency_us"]["median"] == pytest.approx(300.0, abs=0.5)
    assert out["state_age_at_sample_us"]["median"] == pytest.approx(100.0, abs=0.5)
    assert out["late_after_next_cycle"] == pytest.approx(1 / 9, abs=1e-5)  # 9 has no next
    assert out["max_deviation_deg_per_run"] == [pytest.approx(0.573, abs=1e-3)]


def test_a_command_that_never_arrived_is_passed_over_not_matched_to_a_later_copy():
    """Command 4 never arrives and command 7 carries its data: 7 is matched to itself (0.3 ms),
    not to 4 (3.3 ms), and 4 is counted lost."""
    driver, controller = _records()
    data = controller["sent"][4][0]
    controller["sent"][7] = (data, *controller["sent"][7][1:])
    driver["commands"][7] = (data, driver["commands"][7][1])
    del driver["commands"][4]
    out = loop_timing.analyse(driver, controller, warmup_s=0.0, seconds=1.0)
    assert out["latency_us"]["max"] == pytest.approx(1200.0, abs=0.5)  # command 5's
    assert out["commands_matched"] == 9 and out["commands_unmatched"] == 0
    assert out["commands_lost"] == 1


def test_analysis_without_commands_is_an_error():
    with pytest.raises(RuntimeError, match="no command"):
        loop_timing.analyse({"commands": [], "cycles": []}, {"sent": []}, 0.0, 1.0)
