"""Where the time goes per sample: cProfile of the per-sample code and of the ROS loop.

- ``feedback_update_n3``: ``AdaptiveFeedback.update`` on the 3-joint PUMA, 3000 samples;
- ``plant_step_n3``: ``Plant.step`` (one period, 4 RK4 steps), 1000 periods;
- ``lockstep_one_process_recorder_on``: the four nodes on one EventsExecutor in a
  ``bench/node_proc.py`` process, lockstep, 1000 samples;
- ``lockstep_three_processes``: plant, feedforward and feedback processes, lockstep, 1000
  samples, each process profiled.

Each lists the functions with the most *own* time, in microseconds per sample. cProfile adds
overhead per Python call (roughly 1.5-2x on call-heavy code): read the ranking and the shares,
not the absolute numbers. Time inside C (numpy, Pinocchio, rclpy's pybind11 calls) is charged
to the builtin that was called; ``rclpy._rclpy_pybind11.wait`` is idle time.

    .venv/bin/python bench/hotspots.py [--quick] [--no-write]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import benchlib
from compute import Inputs
from ros_loop import ArmRun, Layout, node_parameters, run_arms


def top_functions(profiler: cProfile.Profile, samples: int, top: int = 12) -> dict[str, Any]:
    st = pstats.Stats(profiler)
    rows = []
    for (file, line, func), (_cc, ncalls, tottime, cumtime, _callers) in st.stats.items():
        rows.append(
            {
                "function": f"{Path(file).name}:{line}({func})" if line else func,
                "calls_per_sample": round(ncalls / samples, 2),
                "own_us_per_sample": round(1e6 * tottime / samples, 2),
                "cum_us_per_sample": round(1e6 * cumtime / samples, 2),
            }
        )
    rows.sort(key=lambda r: -r["own_us_per_sample"])
    total = sum(r["own_us_per_sample"] for r in rows)
    return {
        "samples": samples,
        "total_us_per_sample": round(total, 1),
        "buckets_us_per_sample": benchlib.profile_buckets(st, samples),
        "top": rows[:top],
    }


def profile_compute(samples: int) -> dict[str, Any]:
    from apc_feedback.controller import AdaptiveConfig, AdaptiveFeedback
    from apc_plant_sim.plant import Plant, PlantConfig

    robot, _ = benchlib.arm(3)
    x = Inputs(robot)
    law = AdaptiveFeedback(robot.model, AdaptiveConfig())
    law.update(0, x.q[0], x.qd[0], x.q_d[0], x.qd_d[0], x.qdd_d[0], x.u_n[0], None)
    profiler = cProfile.Profile()
    profiler.enable()
    for j in range(1, samples + 1):
        i = j % x.k
        law.update(j, x.q[i], x.qd[i], x.q_d[i], x.qd_d[i], x.qdd_d[i], x.u_n[i], x.applied[i])
    profiler.disable()
    out = {"feedback_update_n3": top_functions(profiler, samples)}

    plant = Plant(robot, PlantConfig(), x.q_d[0])
    periods = max(samples // 3, 100)
    profiler = cProfile.Profile()
    profiler.enable()
    for j in range(periods):
        i = j % x.k
        plant.q, plant.qd = x.q_d[i], x.qd_d[i]
        plant.step(x.u_n[i])
    profiler.disable()
    out["plant_step_n3"] = top_functions(profiler, periods)
    return out


def profile_ros(workdir: Path, samples: int) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for label, layout in (
        ("lockstep_one_process_recorder_on", Layout("one", recorder=True)),
        ("lockstep_three_processes", Layout("three")),
    ):
        params = node_parameters("lockstep", 0.010, samples, layout.recorder)
        arm = ArmRun(workdir, f"prof_{label}", params, layout, profile=True)
        run_arms([arm], timeout_s=120)
        profiles = arm.profiles()
        for prof in profiles.values():
            prof["top"] = prof["top"][:12]
        out[label] = profiles
        benchlib.progress(
            f"hotspots {label}: "
            + ", ".join(f"{r} {p['total_us_per_sample']:.0f} us" for r, p in profiles.items())
            + " per sample (profiled)"
        )
    return out


def run(quick: bool = False) -> dict[str, Any]:
    benchlib.isolate_dds()
    samples = 1000 if quick else 3000
    result = profile_compute(samples)
    with tempfile.TemporaryDirectory(prefix="apc_bench_prof_") as tmp:
        result.update(profile_ros(Path(tmp), 500 if quick else 1000))
    result["note"] = (
        "cProfile own time per sample (us); cProfile inflates Python-call-heavy code, read "
        "rankings and shares; rclpy._rclpy_pybind11.wait is idle time"
    )
    return {"hotspots": result}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--no-write", action="store_true")
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    benchlib.emit(run(args.quick), "hotspots", t0, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
