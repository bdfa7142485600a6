"""Late commands at activation: does the supervised preset keep a physical arm?

A machine that stalls as the controllers start makes their first commands late: the driver's
effort shows delays that the driver does not always take, robot mode tells the law each
(docs/robot.md, "A burst of late commands at activation"). Robot mode's loop closed offline
(:func:`apc_lab.robot_offline.run_robot_loop`, no ROS, **simulated time**, deterministic): the
physical PUMA (3 joints) and Panda of the wall-time grid, run as the offline grid runs them
(``bench/robot_clock_offline.py``: every effect of ``robot_sim``'s ``effects: puma560`` /
``panda``, the controllers told the rotor inertia and friction, 5 lb they do not know, case
(c)'s move 1 s after activation), the preset supervised as shipped, at drivers of 100, 250 and
500 Hz. Two kinds of runs a cell:

- ``burst``: the first :data:`BURST_COMMANDS` commands one or two driver periods late
  (:data:`BURST_PERIODS`), the rest on time;
- ``late``: 30 % of the commands a driver period late throughout (the offline grid's late
  cells), over payloads ±2 % (:data:`PAYLOAD_FACTORS`) with seeds 0-7.

Per cell: the runs handed over to the fallback, the runs beyond 2 deg and beyond
:data:`~apc_lab.wall_clock.LOST_DEG` (lost), the worst and the median max error and the worst
error at the move's end (deg, worst joint). About three minutes on one core; the JSON keeps
every run.

    .venv/bin/python bench/activation_bursts.py [--arms panda] [--rates 250] [--json FILE]
        [--payload-estimate]
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import robot_clock_offline

from apc_feedback.supervisor import SupervisorConfig
from apc_lab.robot_offline import Latency
from apc_lab.wall_clock import LOST_DEG

ARMS = ("puma3", "panda")
RATES_HZ = (100, 250, 500)
#: How many commands from the first are late in a ``burst`` run.
BURST_COMMANDS = (3, 4, 5, 6, 8, 12, 20)
#: How late (driver periods) a burst's commands are.
BURST_PERIODS = (1, 2)
#: The payload times these in the ``late`` runs (run i draws its late commands with seed i).
PAYLOAD_FACTORS = (0.98, 0.985, 0.99, 0.995, 1.0, 1.005, 1.01, 1.015)
#: A run's error beyond this (deg) counts as a large excursion (not lost).
LARGE_DEG = 2.0
RESULTS_JSON = Path(__file__).resolve().parent / "activation_bursts.json"


def cell_runs() -> list[dict[str, Any]]:
    """The runs of a cell: kind, how many commands late or the seed, how late (driver
    periods), the payload factor."""
    bursts = [
        {"kind": "burst", "commands": c, "periods": p, "payload": 1.0}
        for p in BURST_PERIODS
        for c in BURST_COMMANDS
    ]
    late = [
        {"kind": "late", "seed": i, "periods": 1, "payload": f}
        for i, f in enumerate(PAYLOAD_FACTORS)
    ]
    return bursts + late


def latency(run: dict[str, Any], driver_ms: float) -> Latency:
    late_ms = run["periods"] * driver_ms
    if run["kind"] == "burst":
        return Latency(late_ms=late_ms, first=run["commands"])
    return Latency(late_ms=late_ms, probability=0.3, seed=run["seed"])


def one_run(
    arm: str, rate_hz: float, run: dict[str, Any], payload_estimate: bool = False
) -> dict[str, Any]:
    """One run (the offline grid's, :func:`robot_clock_offline.one_run`, with this run's
    lateness and payload; ``payload_estimate``: robot mode estimates the payload in the hold,
    as the robot files have it): its max error and error at the move's end (worst joint, deg)
    and hand-overs."""
    result = robot_clock_offline.one_run(
        arm,
        "physical",
        rate_hz,
        False,
        0,
        SupervisorConfig(),
        latency=latency(run, 1000.0 / rate_hz),
        payload_factor=run["payload"],
        payload_estimate=payload_estimate,
    )
    return {
        **run,
        "max_deg": round(_finite(np.max(result["max_deg"])), 3),
        "move_end_deg": round(_finite(np.max(result["move_end_deg"])), 3),
        "handovers": int(result["handovers"]),
    }


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """A cell: runs, runs handed over, beyond :data:`LARGE_DEG`, lost; worst and median max
    error and worst error at the move's end (deg)."""
    worst = [r["max_deg"] for r in runs]
    return {
        "runs": len(runs),
        "handover_runs": sum(r["handovers"] > 0 for r in runs),
        "large_runs": sum(w > LARGE_DEG for w in worst),
        "lost": sum(w > LOST_DEG for w in worst),
        "max_deg": max(worst),
        "median_max_deg": float(np.median(worst)),
        "move_end_deg": max(r["move_end_deg"] for r in runs),
    }


def _finite(value: float) -> float:
    return float(value) if np.isfinite(value) else float("inf")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    parser.add_argument("--rates", nargs="+", type=float, default=list(RATES_HZ))
    parser.add_argument("--json", type=Path, default=RESULTS_JSON)
    parser.add_argument(
        "--payload-estimate",
        action="store_true",
        help="robot mode estimates the payload in the hold, as the robot files do",
    )
    args = parser.parse_args(argv)
    cells = []
    print(
        "| arm | driver | runs | handed over | beyond 2° | lost | max: worst / median | "
        "move end worst |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for arm in args.arms:
        for rate in args.rates:
            for kind in ("burst", "late"):
                runs = [
                    one_run(arm, rate, r, args.payload_estimate)
                    for r in cell_runs()
                    if r["kind"] == kind
                ]
                s = summarise(runs)
                cells.append({"arm": arm, "rate_hz": rate, "kind": kind, **s, "each": runs})
                print(
                    f"| {arm} | {rate:g} Hz {kind} | {s['runs']} | {s['handover_runs']} | "
                    f"{s['large_runs']} | {s['lost']} | {s['max_deg']:.2f} / "
                    f"{s['median_max_deg']:.2f} | {s['move_end_deg']:.2f} |",
                    flush=True,
                )
    results = {"simulated_time": True, "payload_estimate": args.payload_estimate, "cells": cells}
    args.json.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
