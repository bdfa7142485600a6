"""The paper's Table 2 from the offline closed loop (no ROS), next to the printed numbers.

Cases (a) no load, (b) 1.134 kg, (c) 2.268 kg (5 lb) at the wrist centre, +-10 % inertia error
in the controllers; computed torque (Kp = 100, Kv = 20) and adaptive control with the printed
settings (Q = 0.1 I, R = 1e-6 I, rho = 0.95, P(0) = 1500 I or 150000 I, no wind-up guard).

    .venv/bin/python bench/paper_table_offline.py            # Markdown table
    .venv/bin/python bench/paper_table_offline.py --json     # the numbers as JSON
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from apc_lab.metrics import compute_metrics
from apc_lab.scenario import CONFIG_DIR, build, paper_scenario, paper_settings, run_offline

CASES = {"a": "a_no_load", "b": "b_half_load", "c": "c_max_load"}
CONTROLLERS = {
    "computed_torque": ("computed_torque", None),
    "adaptive_P1": ("adaptive", paper_settings(1500.0)),
    "adaptive_P2": ("adaptive", paper_settings(1.5e5)),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    paper = json.loads((CONFIG_DIR / "reference" / "paper.json").read_text())["table2"]
    rows = []
    for case in CASES:
        scenario = paper_scenario(case)
        robot = build(scenario).plant_robot
        for label, (controller, settings) in CONTROLLERS.items():
            r = run_offline(scenario, controller, settings)
            applied = np.vstack([r.applied[:-1], np.full((1, 3), np.nan)])
            m = compute_metrics(
                r.joint_names, r.q, r.q_d, applied, scenario.move_end_sample, robot=robot
            )
            rows.append({"case": case, "controller": label, **m.as_dict()})
    if args.json:
        print(json.dumps({"runs": rows, "paper": paper}, indent=1))
        return
    print(
        "| case | joint | CT max (deg) | CT mm | CT final | APC-P1 max | APC-P2 max | APC-P2 mm "
        "| APC-P2 final | paper PD max / mm / final | paper APC max / mm / final |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for case, key in CASES.items():
        ct, p1, p2 = (
            next(r for r in rows if r["case"] == case and r["controller"] == c) for c in CONTROLLERS
        )
        for j in range(3):
            pp = paper[key][f"joint{j + 1}"]
            print(
                f"| {case} | {j + 1} | {ct['max_error_deg'][j]:.3f} | {ct['max_tip_mm'][j]:.2f} "
                f"| {ct['final_error_deg'][j]:.3f} | {p1['max_error_deg'][j]:.3f} "
                f"| {p2['max_error_deg'][j]:.3f} | {p2['max_tip_mm'][j]:.2f} "
                f"| {p2['final_error_deg'][j]:.3f} | {pp[0]} / {pp[1]} / {pp[2]} "
                f"| {pp[3]} / {pp[4]} / {pp[5]} |"
            )


if __name__ == "__main__":
    main()
