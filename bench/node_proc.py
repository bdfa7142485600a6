"""One benchmark process: apc nodes composed here, the plant instrumented from outside.

Started by ``bench/ros_loop.py`` and ``bench/multi_arm.py``; not meant to be run by hand.

    node_proc.py --role {plant,feedforward,feedback,arm,recorder} --params FILE.json
                 [--ns /arm0] [--executor {events,single}] [--recorder-out X.mcap]
                 [--out RESULT.json] [--started FILE] [--profile PROF.json]
                 [--no-param-services]

``--params`` is a JSON file ``{node_name: {parameter: value}}`` (``RunSpec.node_parameters()``).
``composed`` puts feedforward, feedback and plant (and, with ``--recorder-out``, a recorder) on one
executor in this process; the other roles run one node. The spin loop is ``run_node``'s
(``spin_once(timeout_sec=0.1)`` until the plant is done or a signal arrives) on
``nodeutil.make_executor`` (EventsExecutor by default), so a process here behaves like the
shipped executables.

The plant is measured only through public attributes, without touching ``src/``: its
``js_pub.publish`` is wrapped to note when each ``joint_states(k)`` first leaves, and the
``callback`` of ``ff_sub`` / ``fb_sub`` to note when the torques stamped ``kT`` first reach the
plant (the callback's start, which is when the single-threaded plant can use them). At exit
the process writes those times (``time.monotonic()``, one clock for every process on the
machine) and the plant's ``diagnostics.counters`` to ``--out``. ``--started`` is written once
the plant has completed sample 0 (k >= 1). ``--profile`` runs the spin loop under cProfile.
``--no-param-services`` is a what-if (see ``--help``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter


def _stamp_ns(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


class PlantProbe:
    """First publish time of each ``joint_states(k)`` and first arrival of each torque."""

    def __init__(self, plant: Any) -> None:
        self.plant = plant
        self.published: dict[int, float] = {}
        self.cpu_marks: list[tuple[float, float, int]] = []  # (monotonic, CPU s, k)
        self.arrived: dict[str, dict[int, float]] = {"ff": {}, "fb": {}}
        publish = plant.js_pub.publish

        def timed_publish(msg: Any) -> None:
            self.published.setdefault(_stamp_ns(msg), time.monotonic())
            publish(msg)

        plant.js_pub.publish = timed_publish
        for key, sub in (("ff", plant.ff_sub), ("fb", plant.fb_sub)):
            sub.callback = self._timed(sub.callback, self.arrived[key])

    @staticmethod
    def _timed(callback: Any, log: dict[int, float]) -> Any:
        def timed(msg: Any) -> Any:
            log.setdefault(_stamp_ns(msg), time.monotonic())
            return callback(msg)

        return timed

    def mark_cpu(self) -> None:
        """Note this process's CPU time (all its threads) now, with the sample index."""
        self.cpu_marks.append((time.monotonic(), time.process_time(), self.plant.k))

    def dump(self) -> dict[str, Any]:
        self.mark_cpu()
        plant = self.plant
        period_ns = plant.period_ns
        stamps = sorted(self.published)
        return {
            "mode": plant.mode,
            "period_ns": period_ns,
            "k": plant.k,
            "done": plant.done,
            "exit_code": plant.exit_code,
            "counters": dict(plant.diagnostics.counters),
            "cpu_marks": self.cpu_marks,
            "k_index": [s // period_ns for s in stamps],
            "published": [self.published[s] for s in stamps],
            "ff": [self.arrived["ff"].get(s) for s in stamps],
            "fb": [self.arrived["fb"].get(s) for s in stamps],
        }


def write_profile(profiler: Any, path: Path, samples: int, top: int = 25) -> None:
    """The ``top`` functions by own time, per sample, as JSON."""
    import pstats

    st = pstats.Stats(profiler)
    rows = []
    for (file, line, func), (_cc, ncalls, tottime, cumtime, _callers) in st.stats.items():
        rows.append(
            {
                "function": f"{Path(file).name}:{line}({func})" if line else func,
                "calls_per_sample": round(ncalls / max(samples, 1), 2),
                "own_us_per_sample": round(1e6 * tottime / max(samples, 1), 1),
                "cum_us_per_sample": round(1e6 * cumtime / max(samples, 1), 1),
            }
        )
    rows.sort(key=lambda r: -r["own_us_per_sample"])
    total = sum(r["own_us_per_sample"] for r in rows)
    from benchlib import profile_buckets

    path.write_text(
        json.dumps(
            {
                "samples": samples,
                "total_us_per_sample": round(total, 1),
                "buckets_us_per_sample": profile_buckets(st, samples),
                "top": rows[:top],
            }
        )
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--role", required=True, choices=("plant", "feedforward", "feedback", "arm", "recorder")
    )
    parser.add_argument("--params", required=True)
    parser.add_argument("--ns", default="")
    parser.add_argument("--executor", choices=("single", "events"), default="events")
    parser.add_argument("--recorder-out")
    parser.add_argument("--out")
    parser.add_argument("--started")
    parser.add_argument(
        "--no-param-services",
        action="store_true",
        help="Node(start_parameter_services=False): six fewer services per node to wait on",
    )
    parser.add_argument("--profile", help="cProfile the spin loop; top entries as JSON here")
    args = parser.parse_args(argv)

    from apc_core.nodeutil import destroy_nodes, make_executor, spin_once_or_stop
    from apc_feedback.node import FeedbackNode
    from apc_feedforward.node import FeedforwardNode
    from apc_plant_sim.node import PlantNode
    from apc_recording.recorder import RecorderNode

    params = json.loads(Path(args.params).read_text())

    def overrides(name: str) -> list[Parameter]:
        return [Parameter(k, value=v) for k, v in params[name].items()]

    rclpy.init(args=["node_proc"])
    context = rclpy.get_default_context()
    ns: dict[str, Any] = {"namespace": args.ns} if args.ns else {}
    if args.no_param_services:
        ns["start_parameter_services"] = False
    nodes: list[Any] = []
    plant = None
    probe: PlantProbe | None = None
    executor = None
    profiler = None
    started_written = False
    try:
        if args.role == "recorder" or (args.role == "arm" and args.recorder_out):
            nodes.append(
                RecorderNode(
                    output=args.recorder_out,
                    parameter_overrides=[Parameter("use_sim_time", value=True)],
                    **ns,
                )
            )
        if args.role in ("feedforward", "arm"):
            nodes.append(FeedforwardNode(parameter_overrides=overrides("feedforward_node"), **ns))
        if args.role in ("feedback", "arm"):
            nodes.append(FeedbackNode(parameter_overrides=overrides("feedback_node"), **ns))
        if args.role in ("plant", "arm"):
            plant = PlantNode(parameter_overrides=overrides("plant_node"), **ns)
            probe = PlantProbe(plant)  # before add_node: executors may cache callbacks
            nodes.append(plant)
        executor = make_executor(args.executor, context)
        for node in nodes:
            executor.add_node(node)
        if args.profile:
            import cProfile

            profiler = cProfile.Profile()
            profiler.enable()
        while spin_once_or_stop(executor):
            if plant is not None:
                if not started_written and args.started and plant.k >= 1:
                    Path(args.started).write_text(f"{time.monotonic()}\n")
                    started_written = True
                    if probe is not None:
                        probe.mark_cpu()
                if plant.done:
                    break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if profiler is not None:
            profiler.disable()
            counts = [plant.k if plant is not None else 0]
            for node in nodes:
                diagnostics = getattr(node, "diagnostics", None)
                if diagnostics is not None:
                    counts.append(diagnostics.counters.get("samples", 0))
            write_profile(profiler, Path(args.profile), max(counts))
        if probe is not None and args.out:
            Path(args.out).write_text(json.dumps(probe.dump()))
        destroy_nodes(nodes, executor=executor)
    return 0 if plant is None else plant.exit_code


if __name__ == "__main__":
    sys.exit(main())
