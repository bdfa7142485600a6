"""What loses a physical arm on a slow driver: one effect at a time, and what telling helps.

The offline grid (``bench/robot_clock_offline.py``) lost the physical PUMA at 100 Hz and the
physical Panda at 100 and 250 Hz with the recommended preset alone when this bench was written
(now it loses one run of five, the Panda at 100 Hz with late commands; docs/robot.md has both
runs of this bench). This bench takes those drivers apart, **simulated time**, robot mode's loop
closed offline (:func:`apc_lab.robot_offline.run_robot_loop`, no ROS), the arms and move of
the grid (5 lb the controllers do not know, 10 % inertia error, case (c)'s move), commands on
time, the adaptive law **alone** (no supervisor: what is measured is the law):

- **effects**: the arm in MuJoCo with none of ``robot_sim``'s effects (its exact velocity
  published), each effect of the arm's preset alone (``effects: puma560`` / ``panda``), and all
  of them (``physical``, the grid's physical arm);
- **variants** of the law, each told or changed one thing:

  - ``shipped``: robot mode as it is (the delay it measures from the driver's effort and the
    kind of velocity the states show, told as robot mode tells them);
  - ``told``: told what the driver does, from the start: the delay (two driver periods where
    the drive adds a cycle) and, where the drive differences its positions, that the velocity
    is ``(q(t) - q(t - Td)) / Td`` (the stencil robot mode tells for its own estimate);
  - ``held``: as shipped, the model held at its prior (``alpha_model`` 1e-12: Eq. 33 at each
    set point, nothing identified but the bias ŵ);
  - ``told, held``: both.

Five runs per cell, the payload within ±1 % (the grid's :data:`PAYLOAD_FACTORS`: a physical
arm's run is chaotic in its inputs). Per cell: the median over the runs of the worst joint's
max error, the worst run's max / final error (deg) and the runs lost (beyond
:data:`apc_lab.wall_clock.LOST_DEG`). About three minutes on one core.

    .venv/bin/python bench/slow_driver_effects.py [--arms puma3 panda] [--rates 100 250]
        [--json bench/slow_driver_effects.json]
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
from robot_clock_offline import PAYLOAD_FACTORS, entry, one_run, summarise
from robot_clock_offline import markdown as table

from apc_feedback.linearize import VelocityStencil
from apc_feedback.presets import recommended_settings
from apc_feedback.robot_loop import RobotLoop
from apc_lab.robot_compare import ARM_EFFECTS
from apc_plant_sim.effects import EFFECT_FIELDS, ArmEffects, single_effect

ARMS = ("puma3", "panda")
RATES_HZ = (100, 250)
VARIANTS = ("shipped", "told", "held", "told, held")
#: ``alpha_model`` that holds the model at its prior (nothing but the bias is identified).
HELD_ALPHA_MODEL = 1e-12


def effects_of(arm: str) -> dict[str, ArmEffects]:
    """``none``, each effect the arm's preset has alone, and ``physical`` (all of them)."""
    full, none = ARM_EFFECTS[arm](), ArmEffects()
    out = {"none": none}
    for name, fields in EFFECT_FIELDS.items():
        if any(getattr(full, f) != getattr(none, f) for f in fields):
            out[name] = single_effect(name, full)
    out["physical"] = full
    return out


def tell(effects: ArmEffects, driver_period: float) -> Callable[[RobotLoop], None]:
    """``setup`` for :func:`run_robot_loop`: the law told the driver's delay and velocity."""
    periods = 1 + effects.command_delay
    difference = effects.velocity == "difference"

    def setup(loop: RobotLoop) -> None:
        law = loop.law
        expect_delay, expect_stencil = law.expect_input_delay, law.expect_velocity_stencil

        def expect_input_delay(
            seconds: float, candidates: tuple[float, ...] = (), exact: bool = False
        ) -> None:
            expect_delay(periods * driver_period, (), exact)

        def expect_velocity_stencil(stencil: VelocityStencil | None) -> None:
            if stencil is None and difference:
                stencil = VelocityStencil(
                    (0.0, driver_period), (1.0 / driver_period, -1.0 / driver_period)
                )
            expect_stencil(stencil)

        law.expect_input_delay = expect_input_delay
        law.expect_velocity_stencil = expect_velocity_stencil

    return setup


def one_cell(arm: str, rate_hz: int, effects: ArmEffects, variant: str) -> dict:
    """The five runs of a cell, summarised as the grid's (:func:`summarise`)."""
    settings = recommended_settings()
    if "held" in variant:
        settings["alpha_model"] = HELD_ALPHA_MODEL
    setup = tell(effects, 1.0 / rate_hz) if "told" in variant else None
    runs = [
        one_run(arm, effects, rate_hz, False, i, None, settings, setup=setup)
        for i in range(len(PAYLOAD_FACTORS))
    ]
    return summarise(runs)


def markdown(cells: list[dict]) -> str:
    """One row per arm, driver and effect; one column per variant."""
    return table(cells, rows=("arm", "rate_hz", "effects"), column="variant", columns=VARIANTS)


def measure(arms: tuple[str, ...], rates: tuple[int, ...]) -> list[dict]:
    cells = []
    for arm in arms:
        for rate in rates:
            for name, effects in effects_of(arm).items():
                for variant in VARIANTS:
                    cell = {"arm": arm, "rate_hz": rate, "effects": name, "variant": variant}
                    cell.update(one_cell(arm, rate, effects, variant))
                    cells.append(cell)
                    print(
                        f"{arm:6s} {rate:4d} Hz {name:20s} {variant:11s} {entry(cell)}",
                        flush=True,
                    )
    return cells


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--arms", nargs="+", choices=ARMS, default=list(ARMS))
    parser.add_argument("--rates", nargs="+", type=int, default=list(RATES_HZ))
    parser.add_argument("--json", type=Path, help="write the cells here")
    args = parser.parse_args()
    cells = measure(tuple(args.arms), tuple(args.rates))
    print()
    print(markdown(cells), end="")
    if args.json:
        # A run that ended with the simulation blown up (not finite) is written as null.
        finite = [
            {k: (v if not isinstance(v, float) or np.isfinite(v) else None) for k, v in c.items()}
            for c in cells
        ]
        doc = {"simulated_time": True, "law": "adaptive recommended, alone", "cells": finite}
        args.json.write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
