"""``bench/activation_bursts.py``'s parts, in milliseconds: the runs a cell has, the lateness
each gives its commands, and how a cell is summed up (the figures come from full runs)."""

from __future__ import annotations

import pytest
from support.bench import bench_module


@pytest.fixture(scope="module")
def bench():
    with bench_module("activation_bursts") as module:
        yield module


def test_a_cell_has_every_burst_and_every_late_run_once(bench):
    runs = bench.cell_runs()
    bursts = [(r["commands"], r["periods"]) for r in runs if r["kind"] == "burst"]
    assert sorted(bursts) == sorted(
        (c, p) for c in bench.BURST_COMMANDS for p in bench.BURST_PERIODS
    )
    late = [r for r in runs if r["kind"] == "late"]
    assert [r["seed"] for r in late] == list(range(len(bench.PAYLOAD_FACTORS)))
    assert [r["payload"] for r in late] == list(bench.PAYLOAD_FACTORS)


def test_a_burst_makes_exactly_its_first_commands_late_by_its_periods(bench):
    latency = bench.latency({"kind": "burst", "commands": 5, "periods": 2, "payload": 1.0}, 4.0)
    late_ns = [latency.next_ns() for _ in range(20)]
    assert late_ns == [8_000_000] * 5 + [0] * 15


def test_a_late_run_makes_about_a_third_of_its_commands_a_period_late(bench):
    run = {"kind": "late", "seed": 3, "periods": 1, "payload": 1.0}
    latency = bench.latency(run, 10.0)
    late_ns = [latency.next_ns() for _ in range(2000)]
    assert set(late_ns) == {0, 10_000_000}
    assert 0.25 < late_ns.count(10_000_000) / len(late_ns) < 0.35


def test_a_cell_counts_hand_overs_large_and_lost_runs(bench):
    runs = [
        {"max_deg": 0.5, "move_end_deg": 0.1, "handovers": 0},
        {"max_deg": 3.0, "move_end_deg": 0.2, "handovers": 1},
        {"max_deg": 12.0, "move_end_deg": 5.0, "handovers": 2},
    ]
    s = bench.summarise(runs)
    assert (s["runs"], s["handover_runs"], s["large_runs"], s["lost"]) == (3, 2, 2, 1)
    assert (s["max_deg"], s["median_max_deg"], s["move_end_deg"]) == (12.0, 3.0, 5.0)
