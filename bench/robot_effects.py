"""Which physical-arm effect breaks a law through the robot interface: one effect at a time.

An arm on robot_sim (MuJoCo, sim time) with the robot-mode controllers
(:mod:`apc_lab.robot_compare`), each effect of robot_sim's preset for the arm alone
(``puma560``: friction, armature, quantisation, velocity noise, the velocity differenced by the
drive, a one-driver-period delay; ``panda``: friction, quantisation, the differenced velocity,
the delay), then all of them: the recommended preset against PID and computed torque, max and
final error per joint (deg), and whether the recommended preset beats both on every joint.
About a minute on one core per arm and two cases.

    .venv/bin/python bench/robot_effects.py --out bench/robot_effects.json
    .venv/bin/python bench/robot_effects.py --arm panda --cases a c --out /tmp/panda_effects.json
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from apc_lab import robot_compare as rc
from apc_lab import robot_report
from apc_plant_sim.effects import EFFECT_FIELDS, ArmEffects

CASES = ("b", "c")
LAWS = ("computed torque", "PID", "adaptive recommended")


def effects_of(arm: str) -> tuple[str, ...]:
    """The effects the arm's preset has (one at a time), then all of them."""
    preset, none = rc.ARM_EFFECTS[arm](), ArmEffects()
    present = [name for name, fields in EFFECT_FIELDS.items()
               if any(getattr(preset, f) != getattr(none, f) for f in fields)]  # fmt: skip
    return (*present, "physical")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/robot_effects.json"))
    parser.add_argument("--arm", default="puma3", choices=sorted(rc.ARM_EFFECTS))
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=rc.CASES)
    args = parser.parse_args()
    t0 = time.perf_counter()
    arm, effects = args.arm, effects_of(args.arm)
    cases = [rc.RobotCase(arm, case, effect, law)
             for effect in effects for case in args.cases for law in LAWS]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        results = rc.execute(cases, Path(tmp), progress=False)
    verdicts = robot_report.beats_baselines(cases, results, "adaptive recommended")
    rows = {}
    print("| effect | case | " + " | ".join(f"{law}: max / final" for law in LAWS) + " | beats |")
    print("|---|---|" + "---|" * (len(LAWS) + 1))
    for effect in effects:
        for case in args.cases:
            cells, row = [], {}
            for law in LAWS:
                m = results[rc.RobotCase(arm, case, effect, law).name].get("metrics")
                row[law] = m and {k: m[k] for k in ("max_error_deg", "final_error_deg")}
                cells.append("failed" if m is None else
                             " ".join(f"{v:.2f}" for v in m["max_error_deg"]) + " / " +
                             " ".join(f"{v:.2f}" for v in m["final_error_deg"]))  # fmt: skip
            verdict = verdicts[f"{arm} {effect} {case} sim"]
            row["beats"] = verdict["beats"]
            rows[f"{effect} {case}"] = row
            print(f"| {effect} | {case} | {' | '.join(cells)} | "
                  f"{'yes' if verdict['beats'] else 'no'} |")  # fmt: skip
    out = {"arm": arm, "rows": rows, "wall_s": round(time.perf_counter() - t0, 1)}
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {args.out} in {out['wall_s']} s")


if __name__ == "__main__":
    main()
