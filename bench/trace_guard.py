"""Does the RLS trace guard help? Long holds with and without it (offline loop, no ROS).

Runs the paper's move followed by a long hold (poor excitation, where trace(P) winds up) for
cases (a) and (c), adaptive control with the printed settings (P2(0) = 150000 I) and with a
position-weighted Q, with ``trace_max`` = -1 (off) and 0 (= trace(P(0)) = alpha (3n+1),
the default).
Prints JSON: per configuration the max |error| during the move and during the hold (deg),
final trace(P), max |du| (N m) during the hold.

    .venv/bin/python bench/trace_guard.py [--hold 20]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from apc_lab.scenario import paper_scenario, paper_settings, run_offline


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hold", type=float, default=20.0, help="hold after the move (s)")
    args = parser.parse_args()
    rows = []
    for case in ("a", "c"):
        scenario = paper_scenario(case, hold_s=args.hold)
        end = scenario.move_end_sample
        for label, base in (
            ("printed Q", paper_settings(1.5e5)),
            ("position-weighted Q", dict(paper_settings(1.5e5), q_position=1e3)),
        ):
            for guard in (-1.0, 0.0):
                result = run_offline(scenario, "adaptive", dict(base, trace_max=guard))
                err = np.rad2deg(np.abs(result.error))
                rows.append(
                    {
                        "case": case,
                        "settings": label,
                        "trace_max": guard,
                        "move_max_error_deg": err[: end + 1].max(axis=0).round(4).tolist(),
                        "hold_max_error_deg": err[end:].max(axis=0).round(4).tolist(),
                        "final_trace_p": float(f"{result.trace_p[-1]:.4g}"),
                        "peak_trace_p": float(f"{np.nanmax(result.trace_p):.4g}"),
                        "rejected_updates": int(result.rejected.sum()),
                        "hold_max_abs_du_nm": np.abs(result.du[end:]).max(axis=0).round(3).tolist(),
                    }
                )
    print(json.dumps({"hold_s": args.hold, "runs": rows}, indent=1))


if __name__ == "__main__":
    main()
