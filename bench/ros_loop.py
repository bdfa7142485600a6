"""The ROS loop: lockstep throughput and real-time lateness of the three nodes over DDS.

The arm is the paper's (3-joint PUMA 560, case c, adaptive law with the node defaults); the
nodes run in ``bench/node_proc.py`` processes on a random ``ROS_DOMAIN_ID``, localhost only.

- ``lockstep_samples_per_s``: samples per second of a lockstep run, the nodes in one process
  (one executor) or in three, with and without the recorder (a fourth node: in the same
  process, or its own process). Each repetition is a window of 100 consecutive samples of the
  steady run (the first 20 samples are skipped); three runs are pooled.
- ``realtime_late_fraction`` / ``realtime_latency_us``: mode ``realtime`` at 100, 500 and
  1000 Hz (``period`` 10/2/1 ms, ``step`` = period/4), three processes, three runs of
  ``n_samples`` = 2.2 s of samples. Latency of sample k: from ``joint_states(k)`` leaving the
  plant to the later of the two torques stamped kT reaching it. A sample is late when either
  torque reaches the plant after it has stepped to k+1 (what the plant's ``late_samples``
  counter counts; both are reported). The first 0.2 s after the clock starts are skipped.
- every process spins ``rclpy.experimental.EventsExecutor`` (as every executable does unless
  ``APC_EXECUTOR=single``); variants,
  as evidence for the choices made: ``SingleThreadedExecutor``, the feedforward without its
  lookahead (``lookahead: 0``, set point k answers joint state k), the nodes in one process,
  and ``Node(start_parameter_services=False)``.

    .venv/bin/python bench/ros_loop.py [--quick] [--no-write] [--skip-variants]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import benchlib
import numpy as np

NODE_PROC = benchlib.BENCH_DIR / "node_proc.py"
RATES_HZ = (100, 500, 1000)


@dataclass(frozen=True)
class Layout:
    """How the nodes of one arm are spread over processes."""

    processes: str = "three"  # "three" (ff, fb, plant) or "one" (all on one executor)
    executor: str = "events"  # "events" (EventsExecutor, as shipped) or "single"
    recorder: bool = False
    param_services: bool = True  # False: Node(start_parameter_services=False) everywhere
    lookahead: int = 1  # the feedforward's lookahead parameter (0: serial ff -> fb)


def node_parameters(
    mode: str,
    period: float,
    n_samples: int,
    recorder: bool,
    publish_clock: bool = True,
    lookahead: int = 1,
) -> dict[str, dict[str, Any]]:
    """Parameters of the three nodes: the paper's case (c), adaptive law, at ``period``."""
    from apc_lab.experiment import RunSpec
    from apc_lab.scenario import paper_scenario

    scenario = paper_scenario("c", hold_s=0.5)
    scenario = replace(scenario, period=period, step=period / 4.0)
    params = RunSpec(scenario, "adaptive", None, mode, "bench").node_parameters()
    params["plant_node"]["n_samples"] = int(n_samples)
    params["plant_node"]["wait_for_subscribers"] = 3 if recorder else 2
    params["plant_node"]["publish_clock"] = publish_clock
    params["feedforward_node"]["lookahead"] = int(lookahead)
    return params


class ArmRun:
    """The processes of one arm: start, wait, stop, read the plant's probe."""

    def __init__(
        self,
        workdir: Path,
        tag: str,
        params: dict[str, dict[str, Any]],
        layout: Layout,
        namespace: str = "",
        profile: bool = False,
    ) -> None:
        self.tag = tag
        self.profile = profile
        self.layout = layout
        self.workdir = workdir
        self.params_file = workdir / f"{tag}.params.json"
        self.params_file.write_text(json.dumps(params))
        self.out = workdir / f"{tag}.plant.json"
        self.started_file = workdir / f"{tag}.started"
        self.namespace = namespace
        self.procs: list[subprocess.Popen] = []
        self.roles: dict[str, subprocess.Popen] = {}
        self.plant_proc: subprocess.Popen | None = None
        self.cpu: dict[str, list[tuple[float, dict[str, float]]]] = {}

    def _spawn(self, role: str, *extra: str) -> subprocess.Popen:
        cmd = [
            sys.executable,
            str(NODE_PROC),
            "--role",
            role,
            "--params",
            str(self.params_file),
            "--executor",
            self.layout.executor,
            *extra,
        ]
        if self.namespace:
            cmd += ["--ns", self.namespace]
        if self.profile:
            cmd += ["--profile", str(self.profile_path(role))]
        if not self.layout.param_services:
            cmd += ["--no-param-services"]
        log = open(self.workdir / f"{self.tag}.{role}.log", "w")
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy())
        log.close()
        self.procs.append(proc)
        self.roles[role] = proc
        return proc

    def mark_cpu(self, label: str) -> None:
        """Note the CPU seconds used so far by each live process of this arm, by role."""
        now = time.monotonic()
        used = {r: cpu_seconds(p.pid) for r, p in self.roles.items() if p.poll() is None}
        self.cpu.setdefault(label, []).append((now, {r: v for r, v in used.items() if v >= 0}))

    def cpu_usage(self) -> dict[str, Any]:
        """Per role: share of one core and CPU microseconds per sample, started -> end.

        The plant's own figure comes from its probe (its process may be gone at the end).
        """
        out: dict[str, Any] = {}
        probe = self.result()
        if not probe or "start" not in self.cpu or "end" not in self.cpu:
            return out
        (t0, c0), (t1, c1) = self.cpu["start"][0], self.cpu["end"][0]
        published = np.asarray(probe["published"], dtype=float)
        for role in c0:
            if role in c1 and t1 > t0:
                n = int(((published >= t0) & (published < t1)).sum())
                out[role] = {
                    "core_share": round((c1[role] - c0[role]) / (t1 - t0), 3),
                    "us_per_sample": round(1e6 * (c1[role] - c0[role]) / n, 1) if n else None,
                }
        marks = probe.get("cpu_marks") or []
        if len(marks) >= 2:
            (m0, p0, k0), (m1, p1, k1) = marks[0], marks[-1]
            role = "arm" if self.layout.processes == "one" else "plant"
            if m1 > m0 and k1 > k0:
                out[role] = {
                    "core_share": round((p1 - p0) / (m1 - m0), 3),
                    "us_per_sample": round(1e6 * (p1 - p0) / (k1 - k0), 1),
                }
        return out

    def start(self) -> None:
        probe = ["--out", str(self.out), "--started", str(self.started_file)]
        mcap = ["--recorder-out", str(self.workdir / f"{self.tag}.mcap")]
        if self.layout.processes == "one":
            self.plant_proc = self._spawn("arm", *probe, *(mcap if self.layout.recorder else ()))
            return
        if self.layout.recorder:
            self._spawn("recorder", *mcap)
        self._spawn("feedforward")
        self._spawn("feedback")
        self.plant_proc = self._spawn("plant", *probe)

    def profile_path(self, role: str) -> Path:
        return self.workdir / f"{self.tag}.{role}.prof.json"

    def profiles(self) -> dict[str, Any]:
        out = {}
        for role in self.roles:
            try:
                out[role] = json.loads(self.profile_path(role).read_text())
            except (OSError, ValueError):
                continue
        return out

    def started_at(self) -> float | None:
        try:
            return float(self.started_file.read_text())
        except (OSError, ValueError):
            return None

    def plant_exited(self) -> bool:
        return self.plant_proc is not None and self.plant_proc.poll() is not None

    def failed_early(self) -> str | None:
        for p in self.procs:
            if p is not self.plant_proc and p.poll() is not None:
                return f"a {self.tag} process exited with {p.returncode}"
        return None

    def stop(self) -> None:
        # The plant first (it writes its probe on SIGINT), then the rest.
        if self.plant_proc is not None:
            benchlib.stop_processes([self.plant_proc])
        benchlib.stop_processes(self.procs)

    def result(self) -> dict[str, Any] | None:
        try:
            return json.loads(self.out.read_text())
        except (OSError, ValueError):
            return None

    def log_tail(self, lines: int = 5) -> str:
        return benchlib.log_tail(self.workdir, self.tag, lines)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process from /proc (-1 if it is gone)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return -1.0


def run_arms(arms: Sequence[ArmRun], *, timeout_s: float, hold_s: float | None = None) -> float:
    """Start every arm; return when all plants have exited (``n_samples``), or, with
    ``hold_s``, ``hold_s`` after the last arm started (then the plants are stopped). Returns the
    time (``time.monotonic()``) at which every arm was running.

    Raises RuntimeError on a timeout or a process that died; every process is stopped anyway.
    """
    t0 = time.monotonic()
    all_started = math.nan
    try:
        for arm in arms:
            arm.start()
        while True:
            time.sleep(0.05)
            for arm in arms:
                problem = arm.failed_early()
                if problem:
                    raise RuntimeError(f"{problem}\n{arm.log_tail()}")
            starts = [a.started_at() for a in arms]
            for arm, s in zip(arms, starts, strict=True):
                if s is not None and "start" not in arm.cpu:
                    arm.mark_cpu("start")
                if hold_s is None and arm.plant_exited() and "end" not in arm.cpu:
                    arm.mark_cpu("end")
            if math.isnan(all_started) and all(s is not None for s in starts):
                all_started = max(s for s in starts if s is not None)
            if hold_s is None:
                if all(a.plant_exited() for a in arms):
                    break
            elif not math.isnan(all_started) and time.monotonic() > all_started + hold_s:
                for arm in arms:
                    arm.mark_cpu("end")
                break
            if time.monotonic() - t0 > timeout_s:
                waiting = [a.tag for a in arms if a.started_at() is None]
                raise RuntimeError(
                    f"timed out after {timeout_s:.0f} s (not started: {waiting})\n"
                    + "\n".join(a.log_tail() for a in arms[:2])
                )
    finally:
        for arm in arms:
            if arm.plant_proc is not None:
                benchlib.stop_processes([arm.plant_proc])
        benchlib.stop_processes([p for arm in arms for p in arm.procs])
    return all_started


# ---------------------------------------------------------------------------------- analysis
def lockstep_rates(probe: dict[str, Any], window: int = 100, skip: int = 20) -> list[float]:
    """Samples per second in consecutive windows of ``window`` samples."""
    t = np.asarray(probe["published"][skip:], dtype=float)
    return [window / (t[i + window] - t[i]) for i in range(0, len(t) - window, window)]


def realtime_samples(
    probe: dict[str, Any], t_from: float = -math.inf, t_to: float = math.inf
) -> dict[str, np.ndarray]:
    """Per sample k (published in [t_from, t_to) and followed by k+1): latency and lateness."""
    t = np.asarray(probe["published"], dtype=float)
    ff = np.asarray([math.nan if v is None else v for v in probe["ff"]], dtype=float)
    fb = np.asarray([math.nan if v is None else v for v in probe["fb"]], dtype=float)
    k = np.asarray(probe["k_index"])
    consecutive = np.diff(k) == 1
    both = np.fmax(ff, fb)  # NaN only when both are missing
    both[np.isnan(ff) | np.isnan(fb)] = math.nan
    latency = (both - t)[:-1]
    late = ~(both[:-1] <= t[1:])  # missing (NaN) counts as late
    keep = consecutive & (t[:-1] >= t_from) & (t[:-1] < t_to)
    return {
        "t": t[:-1][keep],
        "latency": latency[keep],
        "late": late[keep],
        "interval": np.diff(t)[keep],
    }


def late_summary(runs: Sequence[dict[str, np.ndarray]], window_s: float) -> dict[str, Any]:
    """Pooled late fraction over runs, with the spread over windows of ``window_s``."""
    fractions = []
    late = samples = 0
    for r in runs:
        late += int(r["late"].sum())
        samples += int(r["late"].size)
        if r["t"].size:
            edges = np.arange(r["t"][0], r["t"][-1] + 1e-9, window_s)
            idx = np.digitize(r["t"], edges)
            for i in np.unique(idx):
                sel = idx == i
                if sel.sum() >= 0.5 * window_s / np.median(r["interval"]):
                    fractions.append(float(r["late"][sel].mean()))
    out = benchlib.stats(fractions, 3)
    out["pooled"] = round(late / samples, 5) if samples else None
    out["late"], out["samples"], out["window_s"] = late, samples, window_s
    return out


# ---------------------------------------------------------------------------------- parts
def lockstep(workdir: Path, quick: bool) -> dict[str, Any]:
    n_samples = 600 if quick else 1200
    runs = 1 if quick else 3
    layouts = {
        ("one_process", "recorder_on"): Layout("one", recorder=True),
        ("one_process", "recorder_off"): Layout("one"),
        ("three_processes", "recorder_on"): Layout("three", recorder=True),
        ("three_processes", "recorder_off"): Layout("three"),
        ("one_process", "recorder_on_single_threaded_executor"): Layout("one", "single", True),
        ("one_process", "recorder_on_no_parameter_services"): Layout(
            "one", recorder=True, param_services=False
        ),
        ("three_processes", "recorder_on_single_threaded_executor"): Layout(
            "three", "single", True
        ),
        ("three_processes", "recorder_on_no_lookahead"): Layout(
            "three", recorder=True, lookahead=0
        ),
    }
    out: dict[str, Any] = {"one_process": {}, "three_processes": {}}
    for (where, variant), layout in layouts.items():
        rates: list[float] = []
        overall = []
        cpu: dict[str, Any] = {}
        for i in range(runs):
            params = node_parameters(
                "lockstep", 0.010, n_samples, layout.recorder, lookahead=layout.lookahead
            )
            arm = ArmRun(workdir, f"lockstep_{where}_{variant}_{i}", params, layout)
            run_arms([arm], timeout_s=120)
            probe = arm.result()
            if not probe or probe["exit_code"] != 0 or len(probe["published"]) < 200:
                raise RuntimeError(f"lockstep {where} {variant}: no result\n{arm.log_tail()}")
            rates += lockstep_rates(probe)
            cpu = arm.cpu_usage()
            t = probe["published"]
            overall.append((len(t) - 21) / (t[-1] - t[20]))
        s = benchlib.stats(rates, 4)
        s["overall_per_run"] = [round(v) for v in overall]
        s["n_samples_per_run"] = n_samples
        s["cpu_last_run"] = cpu
        out[where][variant] = s
        benchlib.progress(
            f"lockstep {where} {variant}: {s['median']:.0f} samples/s "
            f"[{s['p10']:.0f}-{s['p90']:.0f}]"
        )
    out["settings"] = {
        "arm": "PUMA 560 3 joints, paper case c, adaptive (node defaults), T = 10 ms",
        "repetition": "window of 100 consecutive samples (first 20 skipped)",
        "runs_per_variant": runs,
        "executor": "rclpy.experimental.EventsExecutor (spin_once) unless the variant says "
        "single_threaded_executor",
        "lookahead": "feedforward one sample ahead unless the variant says no_lookahead",
    }
    return out


def realtime_once(
    workdir: Path, tag: str, hz: int, layout: Layout, seconds: float, warmup_s: float = 0.2
) -> dict[str, Any]:
    period = 1.0 / hz
    n_samples = round((seconds + warmup_s) / period) + 1
    params = node_parameters(
        "realtime", period, n_samples, recorder=False, lookahead=layout.lookahead
    )
    arm = ArmRun(workdir, tag, params, layout)
    run_arms([arm], timeout_s=60 + 3 * seconds)
    probe = arm.result()
    if not probe or len(probe["published"]) < 10:
        raise RuntimeError(f"realtime {tag}: no result\n{arm.log_tail()}")
    t_clock = probe["published"][1]  # the clock starts once sample 0 is answered
    samples = realtime_samples(probe, t_from=t_clock + warmup_s)
    late_at = samples["t"][samples["late"]] - t_clock
    return {
        "late_at_s": [round(float(v), 3) for v in late_at[:40]],
        "samples": samples,
        "counters": probe["counters"],
        "k": probe["k"],
        "cpu": arm.cpu_usage(),
    }


def realtime(
    workdir: Path, quick: bool, rates: Sequence[int] = RATES_HZ, variants: bool = True
) -> dict[str, Any]:
    seconds = 1.0 if quick else 2.0
    runs = 1 if quick else 3
    late_out: dict[str, Any] = {}
    lat_out: dict[str, Any] = {}
    extra: dict[str, Any] = {}

    def measure(hz: int, layout: Layout, label: str) -> tuple[dict[str, Any], dict[str, Any]]:
        results = [
            realtime_once(workdir, f"rt_{label}_{hz}_{i}", hz, layout, seconds) for i in range(runs)
        ]
        late = late_summary([r["samples"] for r in results], window_s=0.2)
        late["runs"] = runs
        late["seconds_per_run"] = seconds
        counters = [r["counters"] for r in results]
        late["plant_counters"] = {
            "late_samples": sum(c.get("late_samples", 0) for c in counters),
            "samples": sum(c.get("samples", 0) for c in counters),
            "feedback_missing_samples": sum(c.get("feedback_missing_samples", 0) for c in counters),
            "braked_samples": sum(c.get("braked_samples", 0) for c in counters),
        }
        intervals = np.concatenate([r["samples"]["interval"] for r in results])
        late["achieved_hz"] = round(float(1.0 / np.mean(intervals)), 1) if intervals.size else None
        late["tick_interval_us"] = benchlib.latency_stats(intervals)
        late["cpu_last_run"] = results[-1]["cpu"]
        late["late_at_s_per_run"] = [r["late_at_s"] for r in results]
        latency = benchlib.latency_stats(np.concatenate([r["samples"]["latency"] for r in results]))
        benchlib.progress(
            f"realtime {label} {hz} Hz: late {100 * (late['pooled'] or 0):.2f} % "
            f"({late['late']}/{late['samples']}), latency median {latency['median']} us, "
            f"p99 {latency['p99']} us, max {latency['max']} us, achieved {late['achieved_hz']} Hz"
        )
        return late, latency

    for hz in rates:
        late, latency = measure(hz, Layout("three"), "three_processes")
        late_out[str(hz)] = late
        lat_out[str(hz)] = latency
    if variants:
        for label, layout in (
            ("three_processes_single_threaded_executor", Layout("three", "single")),
            ("three_processes_no_lookahead", Layout("three", lookahead=0)),
            ("one_process", Layout("one")),
        ):
            late, latency = measure(1000, layout, label)
            extra[f"1000 Hz, {label.replace('_', ' ')}"] = {
                "late_fraction": late,
                "latency_us": latency,
            }
    out: dict[str, Any] = {
        "realtime_late_fraction": late_out,
        "realtime_latency_us": lat_out,
        "realtime_settings": {
            "arm": "PUMA 560 3 joints, paper case c, adaptive (node defaults)",
            "layout": "three processes (plant, feedforward, feedback), EventsExecutor, "
            "feedforward one sample ahead",
            "step": "period / 4 (4 RK4 substeps per period)",
            "warmup_s": 0.2,
            "latency": "joint_states(k) published -> later of the two torques stamped kT taken "
            "by the plant (start of its callback)",
            "late": "a torque of sample k reached the plant after it stepped to k+1, or never",
            "spread": "p10/p90 of the late fraction over 0.2 s windows",
        },
    }
    if extra:
        out["realtime_variants"] = extra
    return out


def run(quick: bool = False, variants: bool = True) -> dict[str, Any]:
    benchlib.isolate_dds()
    with tempfile.TemporaryDirectory(prefix="apc_bench_") as tmp:
        workdir = Path(tmp)
        result: dict[str, Any] = {"lockstep_samples_per_s": lockstep(workdir, quick)}
        result.update(realtime(workdir, quick, variants=variants))
    return result


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs, one of each")
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--skip-variants", action="store_true", help="no variant runs")
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    benchlib.emit(run(args.quick, not args.skip_variants), "ros_loop", t0, write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
