"""Several arms at once: N namespaced arms (/arm0 .. /armN-1) in one ROS domain, real time.

Each arm is the paper's (3-joint PUMA 560, case c, adaptive law) at 100 Hz in mode
``realtime``, its plant running until stopped. Two layouts:

- ``three_processes_per_arm``: plant, feedforward and feedback each in its own process
  (3N processes), EventsExecutor (the executables' default);
- ``one_process_per_arm``: the three nodes of an arm on one EventsExecutor in one process
  (N processes);
- ``three_processes_per_arm_single_threaded_executor``: as the first with
  ``SingleThreadedExecutor`` (``APC_EXECUTOR=single``).

All arms are started, the bench waits until every plant's clock runs, lets them run for
``--seconds`` more, and stops them. Per arm, over the window from 0.5 s after the last arm
started to the end, the late fraction (a torque of sample k reached the plant after it stepped
to k+1, or never) and the latency (joint_states(k) out -> both torques in) are computed from
the plant probe of ``bench/node_proc.py``. ``/clock`` is off (``publish_clock: false``): N
plants publishing one global clock would make no sense.

    .venv/bin/python bench/multi_arm.py [--quick] [--no-write] [--arms 1 2 5 10]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import benchlib
import numpy as np
from ros_loop import ArmRun, Layout, late_summary, node_parameters, realtime_samples, run_arms

ARMS = (1, 2, 5, 10)
LAYOUTS = {
    "three_processes_per_arm": Layout("three"),
    "one_process_per_arm": Layout("one"),
    "three_processes_per_arm_single_threaded_executor": Layout("three", "single"),
}


def measure(
    workdir: Path, n_arms: int, variant: str, layout: Layout, seconds: float, warmup_s: float = 0.5
) -> dict[str, Any]:
    params = node_parameters("realtime", 0.010, 0, recorder=False, publish_clock=False)
    arms = [
        ArmRun(workdir, f"multi_{variant}_{n_arms}_{i}", params, layout, namespace=f"/arm{i}")
        for i in range(n_arms)
    ]
    t_launch = time.monotonic()
    all_started = run_arms(arms, timeout_s=90 + 6 * n_arms, hold_s=seconds + warmup_s)
    t_from, t_to = all_started + warmup_s, all_started + warmup_s + seconds
    per_arm = []
    runs = []
    for arm in arms:
        probe = arm.result()
        if not probe:
            raise RuntimeError(f"{arm.tag}: no probe written\n{arm.log_tail()}")
        samples = realtime_samples(probe, t_from=t_from, t_to=t_to)
        runs.append(samples)
        per_arm.append(float(samples["late"].mean()) if samples["late"].size else float("nan"))
    pooled = late_summary(runs, window_s=0.5)
    cpu = [arm.cpu_usage() for arm in arms]
    roles = sorted({role for c in cpu for role in c})
    cpu_summary = {
        role: {
            "us_per_sample_median": benchlib.stats(
                [c[role]["us_per_sample"] for c in cpu if role in c], 3
            )["median"],
            "core_share_total": round(sum(c[role]["core_share"] for c in cpu if role in c), 2),
        }
        for role in roles
    }
    latency = benchlib.latency_stats(np.concatenate([r["latency"] for r in runs]))
    intervals = np.concatenate([r["interval"] for r in runs])
    return {
        "per_arm": [round(v, 4) for v in per_arm],
        "worst_arm_late_fraction": round(float(np.nanmax(per_arm)), 4),
        "pooled_late_fraction": pooled["pooled"],
        "late_fraction_windows": pooled,
        "samples_per_arm": [int(r["late"].size) for r in runs],
        "latency_us": latency,
        "tick_interval_us": benchlib.latency_stats(intervals),
        "processes": len([p for arm in arms for p in arm.procs]),
        "cpu": cpu_summary,
        "startup_s": round(all_started - t_launch, 1),
        "window_s": seconds,
    }


def run(quick: bool = False, arms: Sequence[int] = ARMS) -> dict[str, Any]:
    benchlib.isolate_dds()
    seconds = 2.0 if quick else 4.0
    out: dict[str, Any] = {name: {} for name in LAYOUTS}
    with tempfile.TemporaryDirectory(prefix="apc_bench_multi_") as tmp:
        for n_arms in arms:
            for variant, layout in LAYOUTS.items():
                t0 = time.monotonic()
                try:
                    r = measure(Path(tmp), n_arms, variant, layout, seconds)
                except RuntimeError as exc:
                    benchlib.progress(f"multi-arm {variant} N={n_arms}: FAILED: {exc}")
                    out[variant][str(n_arms)] = {"error": str(exc).splitlines()[0]}
                    continue
                out[variant][str(n_arms)] = r
                benchlib.progress(
                    f"multi-arm {variant} N={n_arms}: worst arm "
                    f"{100 * r['worst_arm_late_fraction']:.2f} % late, all "
                    f"{100 * (r['pooled_late_fraction'] or 0):.2f} %, latency p99 "
                    f"{r['latency_us']['p99']} us, {r['processes']} processes, start-up "
                    f"{r['startup_s']} s ({time.monotonic() - t0:.0f} s)"
                )
    out["settings"] = {
        "arm": "PUMA 560 3 joints, paper case c, adaptive (node defaults), 100 Hz real time",
        "namespaces": "/arm0 .. /armN-1, one ROS domain, publish_clock false",
        "window": f"{seconds} s from 0.5 s after the last arm's clock started",
    }
    return {"multi_arm": out}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 s windows instead of 4 s")
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--arms", type=int, nargs="+", default=list(ARMS))
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    benchlib.emit(run(args.quick, tuple(args.arms)), "multi_arm", t0, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
