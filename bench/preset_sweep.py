"""Which fix of the printed recipe? Sweep Q weighting, horizon and integral action offline.

For each candidate adaptive setting (all within the paper's structure: RLS-identified
perturbation model plus optimal control of it) runs the paper's three cases with +-10 % inertia
error and reports, per case, the worst-joint ratio of adaptive to computed-torque maximum error
and final error, the max error (deg), the peak-torque ratio, and the worst error when the payload
is picked up mid-motion (t = 0.5 s). A candidate "wins" a case when both error ratios are < 1
on every joint and the peak torque is within 1.5x computed torque's.

    .venv/bin/python bench/preset_sweep.py [--json]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from apc_lab.scenario import paper_scenario, run_offline

BASE = {"r": 1e-6, "rho": 0.95, "alpha": 1.5e5, "trace_max": 0.0}
CANDIDATES = {
    "paper Q": {"q_position": 0.1, "q_velocity": 0.1},
    "paper Q, N=10": {"q_position": 0.1, "q_velocity": 0.1, "horizon": 10},
    "Qp=1e3": {"q_position": 1e3, "q_velocity": 0.1},
    "Qp=1e4": {"q_position": 1e4, "q_velocity": 0.1},
    "Qp=1e5": {"q_position": 1e5, "q_velocity": 0.1},
    "Qp=1e3, QI=1e6": {"q_position": 1e3, "q_velocity": 0.1, "q_integral": 1e6},
    "Qp=1e3, QI=1e7": {"q_position": 1e3, "q_velocity": 0.1, "q_integral": 1e7},
    "Qp=1e3, N=10": {"q_position": 1e3, "q_velocity": 0.1, "horizon": 10},
    "Qp=1e4, N=10": {"q_position": 1e4, "q_velocity": 0.1, "horizon": 10},
    "Qp=2e3 Qv=1, N=3": {"q_position": 2e3, "q_velocity": 1.0, "horizon": 3},
    "Qp=2e3 Qv=1, N=3, QI=1e6": {
        "q_position": 2e3, "q_velocity": 1.0, "horizon": 3, "q_integral": 1e6,
    },
    "recommended (+ projection)": {
        "q_position": 2e3, "q_velocity": 1.0, "horizon": 3, "q_integral": 1e6,
        "project_g": True,
    },
}  # fmt: skip


def measure(settings: dict, ct: dict) -> dict:
    out = {}
    for case in "abc":
        scenario = paper_scenario(case)
        end = scenario.move_end_sample
        r = run_offline(scenario, "adaptive", {**BASE, **settings})
        err = np.abs(r.error)
        mx, fin = err[: end + 1].max(axis=0), err[end]
        peak = np.abs(r.applied[:-1]).max(axis=0)
        c = ct[case]
        out[case] = {
            "max_deg": np.rad2deg(mx).round(4).tolist(),
            "final_deg": np.rad2deg(fin).round(4).tolist(),
            "max_ratio": float((mx / c["max"]).max()),
            "final_ratio": float((fin / c["final"]).max()),
            "peak_torque_ratio": float((peak / c["peak"]).max()),
            "hold_end_deg": np.rad2deg(err[-1]).round(4).tolist(),
        }
        pick = run_offline(
            paper_scenario(case, payload_at_s=0.5, hold_s=1.0), "adaptive", {**BASE, **settings}
        )
        out[case]["pickup_max_deg"] = float(np.rad2deg(np.abs(pick.error)).max())
        out[case]["wins"] = (
            out[case]["max_ratio"] < 1
            and out[case]["final_ratio"] < 1
            and out[case]["peak_torque_ratio"] <= 1.5
        )
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    ct = {}
    for case in "abc":
        scenario = paper_scenario(case)
        end = scenario.move_end_sample
        r = run_offline(scenario, "computed_torque")
        err = np.abs(r.error)
        ct[case] = {
            "max": err[: end + 1].max(axis=0),
            "final": err[end],
            "peak": np.abs(r.applied[:-1]).max(axis=0),
        }
    results = {}
    for name, settings in CANDIDATES.items():
        t0 = time.perf_counter()
        results[name] = measure(settings, ct)
        results[name]["settings"] = {**BASE, **settings}
        results[name]["wall_s"] = round(time.perf_counter() - t0, 2)
    if args.json:
        print(json.dumps(results, indent=1))
        return
    print(
        "| candidate | case | max err (deg) | final err (deg) | max/CT | final/CT | peak tau/CT "
        "| wins | max err, payload at 0.5 s (deg) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, res in results.items():
        for case in "abc":
            c = res[case]
            print(
                f"| {name} | {case} | {c['max_deg']} | {c['final_deg']} | {c['max_ratio']:.2f} "
                f"| {c['final_ratio']:.2f} | {c['peak_torque_ratio']:.2f} | {c['wins']} "
                f"| {c['pickup_max_deg']:.3f} |"
            )


if __name__ == "__main__":
    main()
