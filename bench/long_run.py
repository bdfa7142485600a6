"""Long runs offline (:mod:`apc_lab.long_run`): an hour of repeated moves and holds with
payload changes, no ROS. Prints JSON: per configuration and segment the max |error| per joint
(deg) during moves and during holds, max trace(P), refused RLS updates
(``FeedbackOutput.rejected``), saturated samples, finiteness, and the wall time.

    .venv/bin/python bench/long_run.py                # one hour each of guarded and paper
                                                      # (1.5 min per hour on an idle core here)
    .venv/bin/python bench/long_run.py --config all   # and of the two position-weighted ones
    .venv/bin/python bench/long_run.py --seconds 600 --config guarded
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

from apc_lab.long_run import CONFIGS, HOLDS_S, PAYLOADS_KG, POSES_DEG, Schedule, run_long


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--hours", type=float, default=1.0, help="simulated time (h)")
    parser.add_argument("--seconds", type=float, help="simulated time (s); overrides --hours")
    parser.add_argument(
        "--config",
        choices=(*CONFIGS, "both", "all"),
        default="both",
        help="both = guarded and paper (the default settings and the printed ones); all = four",
    )
    parser.add_argument("--segment-minutes", type=float, default=10.0, help="report granularity")
    parser.add_argument("--quiet", action="store_true", help="no progress on stderr")
    args = parser.parse_args(argv)
    seconds = args.seconds if args.seconds is not None else 3600.0 * args.hours
    names = {"both": ["guarded", "paper"], "all": list(CONFIGS)}.get(args.config, [args.config])
    report: dict[str, Any] = {
        "simulated_s": seconds,
        "schedule": {
            "poses_deg": [list(p) for p in POSES_DEG],
            "holds_s": list(HOLDS_S),
            "payloads_kg": list(PAYLOADS_KG),
            "moves_per_payload": Schedule().moves_per_payload,
            "move_s": sum(Schedule().segment_times),
        },
        "runs": {},
    }
    for name in names:
        if not args.quiet:
            print(f"{name}: {seconds:g} s simulated", file=sys.stderr)
        report["runs"][name] = run_long(
            CONFIGS[name], seconds, segment_s=60.0 * args.segment_minutes, progress=not args.quiet
        )
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
