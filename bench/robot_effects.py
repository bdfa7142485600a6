"""Which physical-arm effect breaks a law through the robot interface: one effect at a time.

The 3-joint PUMA 560 on robot_sim (MuJoCo, sim time) with the robot-mode controllers
(:mod:`apc_plant_sim.robot_compare`), cases (b) and (c), each effect of robot_sim's
``puma560`` preset alone (friction, armature, quantisation, velocity noise, velocity
differenced by the drive, a one-driver-period delay), then all of them: the recommended preset
against PID and computed torque, max and final error per joint (deg), and whether the
recommended preset beats both on every joint. About a minute on one core.

    .venv/bin/python bench/robot_effects.py --out bench/robot_effects.json
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from apc_plant_sim import robot_compare as rc
from apc_plant_sim.effects import EFFECT_FIELDS

EFFECTS = (*EFFECT_FIELDS, "physical")
CASES = ("b", "c")
LAWS = ("computed torque", "PID", "adaptive recommended")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/robot_effects.json"))
    args = parser.parse_args()
    t0 = time.perf_counter()
    cases = [rc.RobotCase("puma3", case, effect, law)
             for effect in EFFECTS for case in CASES for law in LAWS]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        results = rc.execute(cases, Path(tmp), progress=False)
    verdicts = rc.beats_baselines(cases, results, "adaptive recommended")
    rows = {}
    print("| effect | case | " + " | ".join(f"{law}: max / final" for law in LAWS) + " | beats |")
    print("|---|---|" + "---|" * (len(LAWS) + 1))
    for effect in EFFECTS:
        for case in CASES:
            cells, row = [], {}
            for law in LAWS:
                m = results[rc.RobotCase("puma3", case, effect, law).name].get("metrics")
                row[law] = m and {k: m[k] for k in ("max_error_deg", "final_error_deg")}
                cells.append("failed" if m is None else
                             " ".join(f"{v:.2f}" for v in m["max_error_deg"]) + " / " +
                             " ".join(f"{v:.2f}" for v in m["final_error_deg"]))  # fmt: skip
            verdict = verdicts[f"puma3 {effect} {case} sim"]
            row["beats"] = verdict["beats"]
            rows[f"{effect} {case}"] = row
            print(f"| {effect} | {case} | {' | '.join(cells)} | "
                  f"{'yes' if verdict['beats'] else 'no'} |")  # fmt: skip
    out = {"rows": rows, "wall_s": round(time.perf_counter() - t0, 1)}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out} in {out['wall_s']} s")


if __name__ == "__main__":
    main()
