"""Robot mode on a physical arm in simulated time: what the wall-time physical cells are made of.

:func:`apc_lab.robot_offline.run_robot_loop` with ``effects=puma560_effects()``: the 3-joint
PUMA 560 in MuJoCo with friction, rotor inertia, quantised encoders, the drive's differenced
velocity and a drive that adds one cycle (``robot_sim``'s ``effects: puma560``), 5 lb the
controllers do not know, robot mode's loop at T = 10 ms sampling on the states' arrival, the
paper's move 0.2 s after activation; no ROS, deterministic. Per driver rate (100 Hz-1 kHz),
commands either all on time (each reaches the drive before its next cycle) or 30 % of them one
driver cycle late (``Latency(late_ms=driver period, probability=0.3)``, seeds 0-3: the jitter of
a loaded machine, which wall time has and simulated time has not), and per law: the
recommended preset unsupervised, supervised with the computed-torque fallback (the default)
and with the PID fallback. Per cell the worst run's max and final tracking error over the
joints (deg, at the samples), the runs beyond 10 deg ("lost", the wall-time benchmark's rule)
and the supervisor's hand-overs. About 10 s on one core.

    .venv/bin/python bench/robot_physical.py [--json bench/robot_physical.json]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from apc_core.robot import PAPER_GOAL_DEG
from apc_feedback.supervisor import SupervisorConfig
from apc_lab.robot_offline import Latency, run_robot_loop
from apc_plant_sim.effects import puma560_effects

RATES_HZ = (100, 250, 500, 1000)
SEEDS = (0, 1, 2, 3)
LOST_DEG = 10.0
#: law label -> supervisor (None: the adaptive law alone).
LAWS: dict[str, SupervisorConfig | None] = {
    "unsupervised": None,
    "supervised, computed-torque fallback": SupervisorConfig(),
    "supervised, PID fallback": SupervisorConfig(fallback="pid"),
}


def one_run(rate_hz: float, late: bool, seed: int, supervisor: SupervisorConfig | None) -> dict:
    """One run: max and final error per joint (deg), hand-overs."""
    driver_ms = 1000.0 / rate_hz
    run = run_robot_loop(
        2.5,
        goal_deg=PAPER_GOAL_DEG,
        driver_ms=driver_ms,
        phase_ms=0.37 * driver_ms,
        transport_ms=0.3 * min(1.0, driver_ms),
        latency=Latency(late_ms=driver_ms, probability=0.3, seed=seed) if late else None,
        supervisor=supervisor,
        effects=puma560_effects(),
    )
    errors = np.array(
        [np.rad2deg(np.abs(entry[1] - entry[2])) for entry in run.log if len(entry) == 3]
    )
    return {
        "max_deg": errors.max(axis=0).round(3).tolist(),
        "final_deg": errors[-1].round(3).tolist(),
        "handovers": run.counts.get("supervisor.handovers", 0),
    }


def measure() -> list[dict]:
    cells = []
    for rate in RATES_HZ:
        for late in (False, True):
            for law, supervisor in LAWS.items():
                runs = [one_run(rate, late, seed, supervisor) for seed in (SEEDS if late else (0,))]
                cells.append(
                    {
                        "rate_hz": rate,
                        "commands": "30 % one cycle late" if late else "on time",
                        "law": law,
                        "max_deg": max(max(r["max_deg"]) for r in runs),
                        "final_deg": max(max(r["final_deg"]) for r in runs),
                        "lost": sum(max(r["max_deg"]) > LOST_DEG for r in runs),
                        "runs": len(runs),
                        "handovers": sum(r["handovers"] for r in runs),
                    }
                )
                c = cells[-1]
                print(
                    f"{rate:5d} Hz  {c['commands']:20s} {law:38s} {c['max_deg']:8.2f} "
                    f"{c['final_deg']:7.2f}  lost {c['lost']}/{c['runs']}  hand-overs "
                    f"{c['handovers']}",
                    flush=True,
                )
    return cells


def markdown(cells: list[dict]) -> str:
    lines = [
        "| driver | commands | law | worst max / final (deg) | lost | hand-overs |",
        "|---|---|---|---|---|---|",
    ]
    for c in cells:
        lines.append(
            f"| {c['rate_hz']} Hz | {c['commands']} | {c['law']} | {c['max_deg']:.2f} / "
            f"{c['final_deg']:.2f} | {c['lost']}/{c['runs']} | {c['handovers']} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the cells here")
    args = parser.parse_args()
    cells = measure()
    print()
    print(markdown(cells), end="")
    if args.json:
        args.json.write_text(json.dumps({"simulated_time": True, "cells": cells}, indent=1) + "\n")


if __name__ == "__main__":
    main()
