"""The robot path at 1 kHz: ``robot_sim`` and apc's controllers over DDS, in real time.

``robot_sim`` (a simulated ros2_control robot, engine ``pinocchio``, wall time, ``state_rate``
1000 Hz, the 3-joint PUMA 560 with the 5 lb payload at the wrist centre) runs in its own
process; ``robot_node`` with ``config/puma560_3dof_robot.yaml`` (the adaptive law, recommended
preset: :data:`CONTROLLER`, the feedforward's plan sampled inside it) runs at ``period`` = 1 ms
in another. The arm holds its start pose (the law runs every sample as it does on a move).
Processes are ``bench/robot_proc.py``, on a random ``ROS_DOMAIN_ID``, localhost only.

Per layout, ``runs`` runs (pooled) of ``seconds`` of steady run after a ``warmup_s`` from the
first command:

- ``late_fraction``: driver cycles that got no new command since the previous cycle (the
  controller's answer missed that write, so the drive re-applied the one it held), over all
  cycles: the driver's ``held_command_cycles`` counter (:class:`RobotDriver`);
- ``latency_us``: from the stamp of the joint state a command was computed from (the driver's
  clock when it read the arm and published) to the command's arrival at the driver, per
  command; split into ``state_age_at_sample_us`` (the state's trip to ``robot_node``: samples
  are taken on arrival) and ``sample_to_arrival_us`` (the plan's set point, the law and the
  command's trip);
- ``robot_node`` is activated once a joint state is in, at a set phase of the driver's cycle
  (:data:`LAYOUTS`);
- ``late_after_next_cycle``: commands that arrived after the driver's next cycle following
  their state (the ``ros_loop`` definition of a late sample);
- ``max_deviation_deg``: the largest deviation of a sampled position from the first, per run
  (the law holds the arm).

The figures come from the processes' records by :mod:`apc_lab.loop_timing`; this script starts
the processes and collects the records.

    .venv/bin/python bench/robot_loop.py [--seconds 10] [--runs 3] [--quick]
        [--controller adaptive] [--command-first] [--no-write]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import benchlib

from apc_core.robot import PAPER_START_DEG
from apc_lab.loop_timing import LAYOUTS, RATE_HZ, run_samples, summary

ROBOT_PROC = benchlib.BENCH_DIR / "robot_proc.py"
CONTROLLERS_FILE = benchlib.CONFIG / "puma560_3dof_robot.yaml"
#: The law at T = 1 ms: the adaptive law with the recommended preset, the robot file's. Its
#: weights are per sample and its horizon three samples; they carry over from T = 10 ms to
#: 1 ms (``test_robot_loop``'s periods test, simulated time).
CONTROLLER = "adaptive"

#: robot_sim's side: docs/robot.md's "Running on a robot" example at 1 kHz in wall time.
ROBOT_SIM_PARAMS: dict[str, Any] = {
    "robot_description_path": "puma560_3dof.urdf",
    "engine": "pinocchio",
    "state_rate": float(RATE_HZ),
    "payload.mass_kg": 2.268,
    "payload.frame": "wrist_center",
    "q_initial_deg": list(PAPER_START_DEG),
}


def _yaml_value(value: Any) -> str:
    return json.dumps(value)  # JSON scalars and lists are YAML


def write_robot_sim_params(path: Path) -> None:
    lines = ["robot_sim:", "  ros__parameters:"]
    lines += [f"    {k}: {_yaml_value(v)}" for k, v in ROBOT_SIM_PARAMS.items()]
    path.write_text("\n".join(lines) + "\n")


class RobotRun:
    """The processes of one run: robot_sim, then robot_node."""

    def __init__(
        self,
        workdir: Path,
        tag: str,
        layout: str,
        controller: str = CONTROLLER,
        command_first: bool = False,
    ) -> None:
        self.workdir, self.tag, self.layout = workdir, tag, layout
        self.controller, self.command_first = controller, command_first
        self.sim_params = workdir / f"{tag}.robot_sim.yaml"
        write_robot_sim_params(self.sim_params)
        self.started_file = workdir / f"{tag}.started"
        self.procs: list[subprocess.Popen] = []

    def out(self, role: str) -> Path:
        return self.workdir / f"{self.tag}.{role}.json"

    def _spawn(self, role: str, params: Path, *extra: str) -> subprocess.Popen:
        cmd = [sys.executable, str(ROBOT_PROC), "--role", role, "--params", str(params)]
        cmd += ["--out", str(self.out(role)), *extra]
        log = open(self.workdir / f"{self.tag}.{role}.log", "w")
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy())
        log.close()
        self.procs.append(proc)
        return proc

    def start(self) -> None:
        self._spawn("robot_sim", self.sim_params, "--started", str(self.started_file))
        args = ["-p", f"period:={1.0 / RATE_HZ}", "-p", f"robot_node:controller:={self.controller}"]
        args += ["-p", f"command_first:={str(self.command_first).lower()}"]
        args += ["--activation-phase", str(LAYOUTS[self.layout])]
        self._spawn("robot_node", CONTROLLERS_FILE, *args)

    def started_at(self) -> float | None:
        try:
            return float(self.started_file.read_text())
        except (OSError, ValueError):
            return None

    def run(self, seconds: float, timeout_s: float = 60.0) -> None:
        """Start, wait for the first command, run ``seconds``, stop every process."""
        t0 = time.monotonic()
        try:
            self.start()
            while (started := self.started_at()) is None:
                for p in self.procs:
                    if p.poll() is not None:
                        raise RuntimeError(f"{self.tag}: a process exited\n{self.log_tail()}")
                if time.monotonic() - t0 > timeout_s:
                    raise RuntimeError(
                        f"{self.tag}: no command in {timeout_s} s\n{self.log_tail()}"
                    )
                time.sleep(0.05)
            time.sleep(max(0.0, started + seconds - time.monotonic()))
        finally:
            # The controllers first: the driver then notes no command after the window ends.
            benchlib.stop_processes(self.procs[1:])
            benchlib.stop_processes(self.procs[:1])

    def result(self, role: str) -> dict[str, Any]:
        try:
            return json.loads(self.out(role).read_text())
        except (OSError, ValueError):
            raise RuntimeError(f"{self.tag}: no {role} result\n{self.log_tail()}") from None

    def log_tail(self, lines: int = 5) -> str:
        return benchlib.log_tail(self.workdir, self.tag, lines)


def measure(
    workdir: Path,
    layout: str,
    seconds: float,
    warmup_s: float,
    runs: int = 1,
    controller: str = CONTROLLER,
    command_first: bool = False,
) -> dict[str, Any]:
    samples = []
    account = benchlib.CpuAccount()
    for i in range(runs):
        run = RobotRun(workdir, f"robot_{layout}_{i}", layout, controller, command_first)
        run.run(seconds + warmup_s + 0.2)
        samples.append(
            run_samples(run.result("robot_sim"), run.result("robot_node"), warmup_s, seconds)
        )
    out = summary(samples)
    out["seconds_per_run"], out["warmup_s"] = seconds, warmup_s
    out["machine_load"] = account.result()  # other_cores: other jobs on the machine meanwhile
    lat = out["latency_us"]
    benchlib.progress(
        f"robot 1 kHz {layout}: late {100 * (out['late_fraction'] or 0):.2f} % "
        f"({out['held_cycles']}/{out['cycles']}; per run {out['late_fraction_per_run']}), "
        f"latency median {lat.get('median')} us, p99 {lat.get('p99')} us (state age at sample "
        f"median per run {out['state_age_median_us_per_run']} us), achieved "
        f"{out['achieved_hz']} Hz; hold deviation per run {out['max_deviation_deg_per_run']} deg; "
        f"other jobs used {out['machine_load']['other_cores']} cores"
    )
    return out


def run(
    quick: bool = False,
    seconds: float | None = None,
    runs: int | None = None,
    controller: str = CONTROLLER,
    command_first: bool = False,
) -> dict[str, Any]:
    benchlib.isolate_dds()
    seconds = seconds if seconds is not None else (3.0 if quick else 10.0)
    runs = runs if runs is not None else (1 if quick else 3)
    warmup_s = 0.5 if seconds >= 2.0 else 0.2
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="apc_bench_") as tmp:
        for layout in LAYOUTS:
            out[layout] = measure(
                Path(tmp), layout, seconds, warmup_s, runs, controller, command_first
            )
    out["settings"] = {
        "robot": "robot_sim, engine pinocchio, wall time, state_rate 1000 Hz, 3-joint PUMA 560, "
        "2.268 kg at wrist_center, holding q = [0, -45, -45] deg",
        "controllers": "robot_node with config/puma560_3dof_robot.yaml, period 0.001 s, "
        f"controller {controller}, preset recommended, command_first {command_first}; "
        "robot_sim in its own process",
        "layouts": "robot_node activated at "
        + ", ".join(f"{k} {1e3 * v:g} ms" for k, v in LAYOUTS.items())
        + " after a joint state's stamp (samples are taken on arrival)",
        "late": "driver cycles with no command arrived since the previous cycle / cycles",
        "latency": "joint state stamp (driver clock at read) -> command taken by the driver",
    }
    return {"robot_loop": out}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, help="steady seconds per layout (default 10)")
    parser.add_argument("--runs", type=int, help="runs per layout, pooled (default 3)")
    parser.add_argument("--quick", action="store_true", help="one run of 3 s per layout")
    parser.add_argument(
        "--controller",
        default=CONTROLLER,
        help=f"robot_node's controller (default {CONTROLLER}; e.g. computed_torque)",
    )
    parser.add_argument(
        "--command-first",
        action="store_true",
        help="robot_node's command_first: the command from the gain planned the sample before",
    )
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args(argv)
    t0 = time.monotonic()
    benchlib.emit(
        run(args.quick, args.seconds, args.runs, args.controller, args.command_first),
        "robot_loop",
        t0,
        write=not args.no_write,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
