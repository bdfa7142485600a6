"""The robot path's timing at 1 kHz on wall time: commands matched to the states they were
computed from, driver cycles that got no new command, and the latencies between them.

``bench/robot_loop.py`` runs ``robot_sim`` and ``robot_node`` as two processes over DDS and
collects their records: the driver's cycles (each with whether it held the previous command)
and the commands as they arrived, the controllers' commands as sent (each with the stamp of
the joint state it was computed from). This module turns those records into the benchmark's
figures; it starts nothing and reads no clock, so that the analysis is tested on synthetic
records and the script stays a driver of processes.

A command is recognised at the driver by its data (floats cross DDS bit for bit). Commands
arrive in the order they were sent (one writer, one reader), but not every one arrives: the
driver's reader keeps only the newest (SystemDefaultsQoS, as forward_command_controller's),
and one sent before the match is never seen. So an arrival is the first command with its data
sent after the command matched before it; equal data sent in between (a command clipped to the
limits, a still arm's) never arrived. Matched by data alone, an arrival could be taken for a
copy that never arrived, sent any time before.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

#: The driver's rate (``robot_sim``'s ``state_rate``) and the controllers' (``period`` = 1 ms).
RATE_HZ = 1000
#: layout -> phase of robot_node's activation after a joint state's stamp (s). Samples are
#: taken on the states' arrival, so the phase should not matter; ``late_phase`` checks that it
#: does not. ``robot_node`` with ``autostart`` activates wherever its start falls.
LAYOUTS: dict[str, float] = {"robot_node": 0.0, "late_phase": 0.6e-3}
#: robot_node's counters a run's figures carry (with every ``supervisor.*`` one).
COUNTERS = (
    "samples_taken",
    "missed_samples",
    "samples_overtaken",
    "missed_setpoint",
    "late_setpoints",
    "watchdog",
    "stale",
)


def latency_stats(seconds: Iterable[float]) -> dict[str, Any]:
    """Per-sample latency in microseconds: median, p90, p99, max over all samples."""
    a = 1e6 * np.asarray(list(seconds), dtype=float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return {"median": None, "n": 0}
    p = np.percentile(a, [10, 50, 90, 99])
    return {
        "median": round(float(p[1]), 1),
        "p10": round(float(p[0]), 1),
        "p90": round(float(p[2]), 1),
        "p99": round(float(p[3]), 1),
        "max": round(float(a.max()), 1),
        "n": int(a.size),
    }


def run_samples(
    driver: dict[str, Any], controller: dict[str, Any], warmup_s: float, seconds: float
) -> dict[str, Any]:
    """One run's figures per driver cycle and per command, over the window
    ``[first command + warmup_s, + seconds)`` (times in s from the first command)."""
    arrivals = driver["commands"]
    if not arrivals or not driver["cycles"]:
        raise RuntimeError("the driver took no command")
    # Relative times: a float64 of ~1.8e9 s resolves only ~0.24 us.
    t0 = arrivals[0][1]
    t0_ns = round(t0 * 1e9)
    cycles = np.asarray([c[0] for c in driver["cycles"]], dtype=float) - t0
    held = np.asarray([c[1] for c in driver["cycles"]], dtype=bool)
    window = (cycles >= warmup_s) & (cycles < warmup_s + seconds)
    # The command each arrival is: the first one sent after the command matched before it
    # with its data (floats cross DDS bit for bit); those passed over never arrived.
    records = controller["sent"]
    sent: dict[tuple[float, ...], deque[int]] = {}
    duplicates = 0
    for index, (data, *_stamps) in enumerate(records):
        queue = sent.setdefault(tuple(data), deque())
        duplicates += bool(queue)
        queue.append(index)
    latency, age, trip, late_next = [], [], [], []
    unmatched = 0
    previous = -1
    matched: list[int] = []
    period = 1.0 / RATE_HZ
    for data, arrival_abs in arrivals:
        queue = sent.get(tuple(data), deque())
        while queue and queue[0] < previous:
            queue.popleft()
        index = queue.popleft() if queue else None
        if index is not None:
            previous = index
        arrival = arrival_abs - t0
        if not warmup_s <= arrival < warmup_s + seconds:
            continue
        match = records[index][1:3] if index is not None else None
        if match is None or match[0] < 0:
            unmatched += 1
            continue
        matched.append(index)
        state, tick = (match[0] - t0_ns) * 1e-9, (match[1] - t0_ns) * 1e-9
        latency.append(arrival - state)
        age.append(tick - state)
        trip.append(arrival - tick)
        # The driver's next cycle after the one that read the state (stamped at its time).
        i = int(np.searchsorted(cycles, state + 0.5 * period))
        if i < cycles.size:  # else the run ended before that cycle
            late_next.append(arrival > cycles[i])
    counters = controller.get("counters", {})
    return {
        "held": held[window],
        "intervals": np.diff(cycles[window]),
        "latency": np.asarray(latency),
        "age": np.asarray(age),
        "trip": np.asarray(trip),
        "late_next": np.asarray(late_next, dtype=bool),
        "unmatched": unmatched,
        # Sent between the window's first and last command that arrived, and not arriving.
        "lost": matched[-1] - matched[0] + 1 - len(matched) if matched else 0,
        "duplicates": duplicates,
        "counters": {
            k: v for k, v in counters.items() if k in COUNTERS or k.startswith("supervisor.")
        },
        "max_deviation_deg": math.degrees(controller.get("max_deviation_rad", math.nan)),
    }


def summary(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The runs pooled: late fraction, latencies, and per run what sets them apart."""
    held = np.concatenate([r["held"] for r in runs])
    intervals = np.concatenate([r["intervals"] for r in runs])
    late_next = np.concatenate([r["late_next"] for r in runs])
    latency = np.concatenate([r["latency"] for r in runs])
    counters: dict[str, int] = {}
    for r in runs:
        for k, v in r["counters"].items():
            counters[k] = counters.get(k, 0) + v
    return {
        "late_fraction": round(float(held.mean()), 5) if held.size else None,
        "held_cycles": int(held.sum()),
        "cycles": int(held.size),
        "late_fraction_per_run": [round(float(r["held"].mean()), 4) for r in runs],
        "state_age_median_us_per_run": [
            round(float(1e6 * np.median(r["age"])), 1) if r["age"].size else None for r in runs
        ],
        "achieved_hz": round(float(1.0 / intervals.mean()), 1) if intervals.size else None,
        "cycle_interval_us": latency_stats(intervals),
        "latency_us": latency_stats(latency),
        "state_age_at_sample_us": latency_stats(np.concatenate([r["age"] for r in runs])),
        "sample_to_arrival_us": latency_stats(np.concatenate([r["trip"] for r in runs])),
        "late_after_next_cycle": round(float(late_next.mean()), 5) if late_next.size else None,
        "commands_matched": int(latency.size),
        "commands_unmatched": sum(r["unmatched"] for r in runs),
        "commands_lost": sum(r["lost"] for r in runs),
        "duplicate_commands": sum(r["duplicates"] for r in runs),
        "controller_counters": counters,
        "max_deviation_deg_per_run": [round(r["max_deviation_deg"], 3) for r in runs],
        "runs": len(runs),
    }


def analyse(
    driver: dict[str, Any], controller: dict[str, Any], warmup_s: float, seconds: float
) -> dict[str, Any]:
    """One run's summary (see :func:`run_samples`)."""
    return summary([run_samples(driver, controller, warmup_s, seconds)])
