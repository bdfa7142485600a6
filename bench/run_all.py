"""Run every benchmark and write ``bench/results.json`` and ``bench/results.md``.

Parts, in this order (each also runs alone and then merges its figures into results.json):

1. ``bench/compute.py``   per-sample compute for n = 3, 6, 7, 12, 24 joints (no ROS)
2. ``bench/hotspots.py``  cProfile of the per-sample code and of the lockstep loop
3. ``bench/ros_loop.py``  lockstep samples/s (one / three processes, recorder on / off) and
                          real time at 100, 500, 1000 Hz in three processes
4. ``bench/multi_arm.py`` N = 1, 2, 5, 10 namespaced arms at 100 Hz in one ROS domain
5. ``bench/robot_loop.py`` the robot path at 1 kHz: ``robot_sim`` + ``robot_node`` in two
                          processes (late fraction, latency, how far the held arm strays)
6. ``bench/robot_clock.py`` the robot path on wall time as users run it: tracking error per
                          driver rate, arm, effects and law, runs lost, the supervisor's
                          hand-overs (``--quick``: the PUMA, physical, 500 Hz, one run per law)

Every DDS participant runs on a random ``ROS_DOMAIN_ID``, localhost only; every process
started is stopped. Parts 1-5 take about 7-8 minutes on 2 cores, under 10; ``robot_clock``'s
full grid (48 cells x 3 runs of ~8-9 s) 20-25 more (``--quick``: about 4 + 0.5). No
figure is asserted: the Markdown table compares them with apc's targets and the paper's
7.5 ms.

    make bench                                   # = .venv/bin/python bench/run_all.py
    .venv/bin/python bench/run_all.py --quick
    .venv/bin/python bench/run_all.py --only compute ros_loop
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

import benchlib
import report

PARTS = ("compute", "hotspots", "ros_loop", "multi_arm", "robot_loop", "robot_clock")


def run_part(name: str, quick: bool) -> dict[str, Any]:
    if name == "compute":
        import compute

        return compute.run(quick)
    if name == "hotspots":
        import hotspots

        return hotspots.run(quick)
    if name == "ros_loop":
        import ros_loop

        return ros_loop.run(quick)
    if name == "multi_arm":
        import multi_arm

        return multi_arm.run(quick)
    if name == "robot_loop":
        import robot_loop

        return robot_loop.run(quick)
    if name == "robot_clock":
        import robot_clock

        return robot_clock.run(quick)
    raise ValueError(name)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions, shorter runs")
    parser.add_argument("--only", nargs="+", choices=PARTS, help="run only these parts")
    args = parser.parse_args(argv)
    parts = args.only or list(PARTS)
    domain = benchlib.isolate_dds()
    t0 = time.monotonic()
    load_before = benchlib.load_average()
    benchlib.progress(
        f"running {', '.join(parts)}{' (quick)' if args.quick else ''} on ROS_DOMAIN_ID "
        f"{domain}; load average {load_before}"
    )
    results: dict[str, Any] = {
        "command": benchlib.command_line(),
        "started_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "quick": args.quick,
        "load_average_before": load_before,
        "part_wall_s": {},
        "machine_load": {},
        "failures": {},
    }
    for name in parts:
        t_part = time.monotonic()
        account = benchlib.CpuAccount()
        try:
            results.update(run_part(name, args.quick))
        except Exception as exc:  # report the others even if one part fails
            results["failures"][name] = f"{type(exc).__name__}: {exc}"
            benchlib.progress(f"{name} FAILED: {type(exc).__name__}: {exc}")
        results["part_wall_s"][name] = round(time.monotonic() - t_part, 1)
        results["machine_load"][name] = load = account.result()
        benchlib.progress(
            f"{name} done in {results['part_wall_s'][name]} s; other jobs used "
            f"{load['other_cores']} cores meanwhile"
        )
    results["total_wall_s"] = round(time.monotonic() - t0, 1)
    results["load_average_after"] = benchlib.load_average()
    # A partial run (--only) keeps the other parts' figures from the previous results.json.
    data = benchlib.read_results() if args.only else {}
    data.update(results)
    data["targets"] = [
        {"figure": f, "measured": m, "target": t, "verdict": v.strip("*")}
        for f, m, t, v in report.target_rows(data)
    ]
    benchlib.write_results(data, replace=True)
    print(benchlib.RESULTS_MD.read_text())
    benchlib.progress(
        f"wrote {benchlib.RESULTS_JSON} and {benchlib.RESULTS_MD} in {results['total_wall_s']} s"
        + (" (over the 10-minute budget)" if results["total_wall_s"] > 600 else "")
    )
    return 1 if results["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
