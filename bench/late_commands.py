"""How late may a command reach the arm? The adaptive law in robot mode, closed offline.

:func:`apc_lab.robot_offline.run_robot_loop`: the 3-joint PUMA 560 with 5 lb the
controllers do not know, robot mode's loop at T = 10 ms on a driver's clock, no ROS. Two
tables:

1. A hold after activation, 1 s, with commands that come late (the first one, the first few,
   or a random share of all of them), for the recommended preset with ``alpha_model`` (the
   prior on Eq. 33's F and G) at 0 (``P(0) = alpha I``, Eq. 32), 1e-5 (the preset), 1e-4,
   1e-3 and 1e-2: the largest sag (deg), ticks at two phases and three random seeds, worst
   case.
2. The paper's move after activation, for ``alpha_model`` 0, 1e-3 and the preset: drivers at 1 kHz
   to 100 Hz, and a 1 kHz driver whose commands all arrive 1-8 ms late: the largest tracking
   error at the ticks (deg), "diverges" beyond 90 deg.

About 30 s on one core.

    .venv/bin/python bench/late_commands.py
"""

from __future__ import annotations

import argparse

from apc_core.robot import PAPER_GOAL_DEG
from apc_lab.robot_offline import Latency, run_robot_loop
from apc_lab.scenario import recommended_settings

ALPHA_MODELS = (0.0, 1e-5, 1e-4, 1e-3, 1e-2)
#: (label, latency factory per seed) of the hold table.
LATENESS = (
    ("on time", lambda seed: Latency()),
    ("1st 2 ms late", lambda seed: Latency(late_ms=2.0, first=1)),
    ("1st 4 ms late", lambda seed: Latency(late_ms=4.0, first=1)),
    ("first 3 4 ms late", lambda seed: Latency(late_ms=4.0, first=3)),
    ("first 10 6 ms late", lambda seed: Latency(late_ms=6.0, first=10)),
    ("5 % 6 ms late", lambda seed: Latency(late_ms=6.0, probability=0.05, seed=seed)),
    ("20 % 6 ms late", lambda seed: Latency(late_ms=6.0, probability=0.2, seed=seed)),
)
PHASES_MS = (0.0, 0.3)
SEEDS = (0, 1, 2)
DRIVER_HZ = (1000, 500, 400, 333, 250, 200, 100)
DELAYS_MS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0)
GOAL_DEG = PAPER_GOAL_DEG


def settings(alpha_model: float) -> dict:
    return {**recommended_settings(), "alpha_model": alpha_model}


def cell(value: float) -> str:
    return "diverges" if value > 90.0 else f"{value:.2f}"


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    print("| commands | " + " | ".join(f"alpha_model {a:g}" for a in ALPHA_MODELS) + " |")
    print("|---|" + "---|" * len(ALPHA_MODELS))
    for label, latency in LATENESS:
        seeds = SEEDS if "%" in label else (0,)
        cells = []
        for alpha_model in ALPHA_MODELS:
            worst = max(
                run_robot_loop(
                    1.0, phase_ms=phase, latency=latency(seed), settings=settings(alpha_model)
                ).max_deviation_deg()
                for phase in PHASES_MS
                for seed in seeds
            )
            cells.append(cell(worst))
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    print()
    runs = [(f"driver {hz} Hz", 1000.0 / hz, 0.0) for hz in DRIVER_HZ]
    runs += [(f"1 kHz, {ms:g} ms late", 1.0, ms) for ms in DELAYS_MS]
    laws = (0.0, 1e-3, recommended_settings()["alpha_model"])
    print("| the move | " + " | ".join(f"alpha_model {a:g}" for a in laws) + " |")
    print("|---|" + "---|" * len(laws))
    for label, driver_ms, delay_ms in runs:
        cells = []
        for alpha_model in laws:
            worst = max(
                run_robot_loop(
                    2.0,
                    goal_deg=GOAL_DEG,
                    driver_ms=driver_ms,
                    phase_ms=phase,
                    latency=Latency(fixed_ms=delay_ms),
                    settings=settings(alpha_model),
                ).max_tracking_error_deg()
                for phase in PHASES_MS
            )
            cells.append(cell(worst))
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
