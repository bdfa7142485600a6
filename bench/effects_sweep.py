"""What a physical arm does to each law: one effect at a time, then all, offline (no ROS).

The three-joint PUMA 560 on the paper's move, cases (a)-(c) and the 5 lb payload picked up at
t = 0.5 s ("pickup"), each law on apc's plant wrapped by :mod:`apc_plant_sim.effects` with the
PUMA 560 data of :func:`apc_plant_sim.effects.puma560_effects` (friction, armature, 1000
counts per motor revolution, velocity differenced from the quantised positions or with one
count per period of noise, a one-period command delay). Laws: computed torque (Eq. 36,
Kp = 100, Kv = 20), the JTC-style PID (tuned at 10 rad/s), the adaptive law with the paper's
settings, the recommended preset, and the recommended preset with the law option that answers
the effect (``FIXES``: the command delay in the model, the two-period input of a differenced
velocity; friction, armature, quantisation and noise need none; for "all", both: the
"physical" preset).

Per effect, case and law: maximum error over the move and final error at its end, per joint
(deg), and whether each adaptive column beats both computed torque and PID on every joint in
both. About 15 s on one core.

    .venv/bin/python bench/effects_sweep.py --out bench/effects_sweep.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from apc_lab.scenario import (
    paper_scenario,
    paper_settings,
    physical_settings,
    recommended_settings,
    run_offline,
)
from apc_plant_sim.effects import EFFECT_FIELDS, puma560_effects, single_effect

EFFECTS = ("ideal", *EFFECT_FIELDS, "all")
CASES = ("a", "b", "c", "pickup")
LAWS = {
    "computed_torque": ("computed_torque", None),
    "pid": ("pid", None),
    "adaptive_paper": ("adaptive", paper_settings()),
    "adaptive_recommended": ("adaptive", recommended_settings()),
    "adaptive_recommended_fixed": ("adaptive", recommended_settings()),
}
BASELINES = ("computed_torque", "pid")
# The AdaptiveConfig options added to the recommended preset for each effect (none: nothing to
# answer), chosen one effect at a time; "all" combines them.
FIXES = {
    "velocity_difference": {"input_lags": 2, "input_delay": 0.005},
    "delay": {"input_lags": 2, "input_delay": 0.01},
    "all": {k: v for k, v in physical_settings().items() if k not in recommended_settings()},
}


def scenario_for(case: str):
    if case == "pickup":
        return paper_scenario("c", payload_at_s=0.5)
    return paper_scenario(case)


def measure(effect: str, case: str, law: str) -> dict:
    kind, params = LAWS[law]
    if law == "adaptive_recommended_fixed":
        params = {**params, **FIXES.get(effect, {})}
    scenario = scenario_for(case)
    end = scenario.move_end_sample
    result = run_offline(scenario, kind, params, effects=single_effect(effect, puma560_effects()))
    err = np.rad2deg(np.abs(result.error))
    return {
        "max_deg": err[: end + 1].max(axis=0).round(4).tolist(),
        "final_deg": err[end].round(4).tolist(),
    }


def beats(row: dict, law: str) -> bool:
    """``law`` has a smaller max and final error than every baseline on every joint."""
    mine = row[law]
    return all(
        np.all(np.array(mine[key]) < np.array(row[base][key]))
        for base in BASELINES
        for key in ("max_deg", "final_deg")
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/effects_sweep.json"))
    args = parser.parse_args()
    t0 = time.perf_counter()
    results: dict = {"effects": {}, "settings": {}, "fixes": FIXES}
    for law, (kind, params) in LAWS.items():
        results["settings"][law] = {"controller": kind, **(params or {})}
    for effect in EFFECTS:
        results["effects"][effect] = {}
        for case in CASES:
            row = {law: measure(effect, case, law) for law in LAWS}
            for law in ("adaptive_recommended", "adaptive_recommended_fixed"):
                row[f"{law}_beats_baselines"] = beats(row, law)
            results["effects"][effect][case] = row
    results["wall_s"] = round(time.perf_counter() - t0, 1)
    args.out.write_text(json.dumps(results, indent=1) + "\n")
    print(f"| effect | case | {' | '.join(LAWS)} |")
    print("|---|---|" + "---|" * len(LAWS))
    for effect, cases in results["effects"].items():
        for case, row in cases.items():
            cells = [
                "/".join(f"{v:.2f}" for v in row[law]["max_deg"])
                + " ("
                + "/".join(f"{v:.2f}" for v in row[law]["final_deg"])
                + ")"
                for law in LAWS
            ]
            print(f"| {effect} | {case} | {' | '.join(cells)} |")
    print()
    print(summary(results["effects"]))
    print(f"wrote {args.out} in {results['wall_s']} s")


def summary(effects: dict) -> str:
    """Per effect: each law's worst joint over the cases (max / final, deg) and the cases
    in which each adaptive column beats both baselines (docs/paper.md's table)."""
    lines = [
        f"| effect | {' | '.join(LAWS)} | wins recommended · fixed |",
        "|---|" + "---|" * (len(LAWS) + 1),
    ]
    for effect, cases in effects.items():
        cells = []
        for law in LAWS:
            worst_max = max(max(row[law]["max_deg"]) for row in cases.values())
            worst_final = max(max(row[law]["final_deg"]) for row in cases.values())
            cells.append(f"{worst_max:.2f} / {worst_final:.2f}")
        wins = [
            sum(row[f"{law}_beats_baselines"] for row in cases.values())
            for law in ("adaptive_recommended", "adaptive_recommended_fixed")
        ]
        lines.append(
            f"| {effect} | {' | '.join(cells)} | {wins[0]}/{len(cases)} · {wins[1]}/{len(cases)} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main()
