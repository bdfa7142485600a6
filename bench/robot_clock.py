"""The robot path on wall time, as users run it: ``robot_sim`` and ``robot_node`` apart.

Every robot figure of ``robot_compare`` is in simulated time. Here the simulated ros2_control
robot (``robot_sim``, engine ``mujoco``, ``sim_time: false``: its wall timer at ``state_rate``)
runs in one process and apc's controllers in another, started the way a user starts them::

    robot_sim --ros-args --params-file <robot_sim.yaml>
    robot_node --ros-args --params-file config/<arm>_robot.yaml -p robot_node:...

on a random ``ROS_DOMAIN_ID``, localhost only (:func:`benchlib.isolate_dds`); node logs go to
files in a temporary directory, progress is one line per run.

Cells: the driver at 100, 250, 500 and 1000 Hz; the ideal arm and robot_sim's physical preset
for the arm (``effects: puma560`` / ``panda``: friction, rotor inertia, encoder quantisation,
the drive's differenced velocity, a one-driver-period command delay); the 3-joint PUMA 560 and
the Franka Panda, each carrying robot_compare's case-(c) payload (5 lb; at the PUMA's wrist
centre) that the controllers do not know; the laws computed torque, the JTC-style PID and the
adaptive law with the recommended preset as the robot file ships it, minus any per-arm
``adaptive.*`` override a robot file carries (the shipped ones carry none); on a physical
arm every law is told its friction (``friction``, ``damping``) and, on the PUMA, its rotor
inertia (``armature``), as its user tells a geared arm's:
:func:`apc_lab.robot_compare.controller_arm_parameters`. The robot
file's ``path_tolerance`` is opened (0: no check) for every law, so that every run finishes
and the loss rule below is the benchmark's, not the node's abort.

Each run (``--runs`` per cell, default 3): ``robot_node`` is configured, then activated through
its lifecycle service at a random phase of the driver's cycle (drawn from ``--seed``) after a
joint state's stamp; the arm holds :data:`HOLD_BEFORE_S` from the first sample robot_node
publishes (the time to it is in the JSON); robot_compare's case-(c) move
(``goal_message``) goes to robot_node on ``feedforward/trajectory``; the run ends
:data:`HOLD_AFTER_S` after the move. The benchmark process subscribes to the samples the
controllers took (``feedback/sample``, stamped kT) and their set points (``feedforward/setpoint``,
stamped kT) and pairs them by stamp: max error per joint over the move and the error at its
end (deg), as robot_compare measures them; a run is lost when any joint's error goes beyond
:data:`LOST_DEG` at any sample after activation, or the move's end is never sampled. The
supervisor's hand-overs are read from robot_node's last status on ``/diagnostics`` after the
run (every ``supervisor.*`` counter; absent = 0).

Per cell: the worst max and final error per joint over its runs, the runs lost, the hand-overs.
Written to ``bench/robot_clock.json`` and ``bench/robot_clock.md`` (and by ``run_all.py`` into
``results.json`` / ``results.md``), labelled with the machine and the other load on it.

The errors, the loss rule, the cells, the table and the processes' parameters are
:mod:`apc_lab.wall_clock`'s; this script starts the processes, drives each run and collects
what the controllers sampled.

About 8-9 s per run on 2 cores (process start and discovery take half of it): the full grid
(48 cells x 3 runs) takes ~20-25 minutes; ``--quick`` is the PUMA with every physical effect
on at 500 Hz, one run per law (~25 s).

    .venv/bin/python bench/robot_clock.py                       # the full grid, 3 runs per cell
    .venv/bin/python bench/robot_clock.py --quick
    .venv/bin/python bench/robot_clock.py --arms puma3 --effects ideal --rates 100 1000 --runs 1
    .venv/bin/python bench/robot_clock.py --quick --logs LOGDIR --json OUT.json --md OUT.md
    .venv/bin/python bench/robot_clock.py --arms panda --effects physical --rates 250 \
        --velocity-source exact --no-write      # a drive that measures the arm's velocity
    .venv/bin/python bench/robot_clock.py --rates 100 --laws "adaptive recommended" \
        --robot-node feedforward_ahead=false --no-write  # a robot_node parameter of every law
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import benchlib
import yaml

from apc_lab.wall_clock import (
    ARMS,
    EFFECTS,
    HOLD_BEFORE_S,
    LAWS,
    LOST_DEG,
    PATH_TOLERANCE,
    QUICK,
    RATES_HZ,
    aggregate_cell,
    controller_arguments,
    degrees_text,
    is_lost,
    markdown,
    plan,
    robot_sim_parameters,
    run_errors,
    status_counters,
    supervisor_counts,
)

RESULTS_JSON = benchlib.BENCH_DIR / "robot_clock.json"
RESULTS_MD = benchlib.BENCH_DIR / "robot_clock.md"
#: Where the console scripts are (``robot_sim``, ``robot_node``): beside this interpreter.
BIN = Path(sys.executable).parent
#: Wall seconds after the move's planned end before the run ends.
HOLD_AFTER_S = 0.5
#: Wall seconds between robot_node's topics appearing in the graph and activation: the graph
#: can list an endpoint before DDS has matched it (the first samples would be lost to the
#: observer).
MATCH_SETTLE_S = 0.5
#: Wall seconds for the processes to start, be discovered and configure robot_node.
START_TIMEOUT_S = 60.0
#: Wall seconds from activation to robot_node's first sample before a run fails (the hold
#: before the move counts from that sample).
FIRST_SAMPLE_TIMEOUT_S = 5.0
#: Wall seconds to wait after the run for each node's next ``/diagnostics`` (sent every 1 s).
DIAGNOSTICS_WAIT_S = 2.5


# ---------------------------------------------------------------------------------- one run
@dataclass
class RunSpec:
    arm: str
    effects: str
    rate_hz: float
    law: str
    index: int
    phase_s: float
    velocity_source: str = ""  # a physical arm's drive velocity, if not its preset's
    node_settings: tuple[str, ...] = ()  # NAME=VALUE: robot_node parameters of every law

    @property
    def tag(self) -> str:
        law = self.law.replace(" ", "_")
        velocity = f"_{self.velocity_source}" if self.velocity_source else ""
        return f"{self.arm}_{self.effects}{velocity}_{self.rate_hz:g}_{law}_{self.index}"


class Observer:
    """The benchmark's node: joint-state stamps until activation, samples, set points,
    ``/diagnostics``; the goal publisher and robot_node's lifecycle client."""

    def __init__(self, context: Any) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from lifecycle_msgs.srv import ChangeState
        from rclpy.node import Node
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import JointState
        from trajectory_msgs.msg import JointTrajectory

        import apc_msgs_py as wire

        self.wire = wire
        self.node = Node("robot_clock_bench", context=context)
        self.newest_state_ns: int | None = None
        self.names: tuple[str, ...] | None = None
        self.samples: dict[int, list[float]] = {}
        self.setpoints: dict[int, tuple[tuple[str, ...], list[float], list[float]]] = {}
        #: node name -> (monotonic receipt time, key-values) of its newest status
        self.status: dict[str, tuple[float, dict[str, str]]] = {}
        n = self.node
        self.state_sub = n.create_subscription(
            JointState, "/" + wire.JOINT_STATES, self._on_state, qos_profile_sensor_data
        )
        self.sample_sub = n.create_subscription(
            JointState, wire.SAMPLE, self._on_sample, wire.CONTROL_QOS
        )
        self.setpoint_sub = n.create_subscription(
            JointTrajectory, wire.SETPOINT, self._on_setpoint, wire.CONTROL_QOS
        )
        n.create_subscription(
            DiagnosticArray, wire.DIAGNOSTICS, self._on_diagnostics, wire.DIAGNOSTICS_QOS
        )
        self.goal_pub = n.create_publisher(
            JointTrajectory, wire.TRAJECTORY_GOAL, wire.TRAJECTORY_GOAL_QOS
        )
        self.lifecycle = n.create_client(ChangeState, "/robot_node/change_state")

    def _on_state(self, msg: Any) -> None:
        self.newest_state_ns = self.wire.stamp_to_ns(msg.header.stamp)

    def _on_sample(self, msg: Any) -> None:
        self.names = self.names or tuple(msg.name)
        self.samples[self.wire.stamp_to_ns(msg.header.stamp)] = list(msg.position)

    def _on_setpoint(self, msg: Any) -> None:
        if msg.points:
            p = msg.points[0]
            self.setpoints[self.wire.stamp_to_ns(msg.header.stamp)] = (
                tuple(msg.joint_names),
                list(p.positions),
                list(p.velocities),
            )

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            self.status[status.name] = (
                time.monotonic(),
                {kv.key: kv.value for kv in status.values},
            )

    def status_of(self, node: str) -> tuple[float, dict[str, str]] | None:
        """The newest status of the node named ``node`` (any namespace), if any arrived."""
        return next((v for k, v in self.status.items() if k.endswith("/" + node)), None)

    def controllers_heard(self) -> bool:
        # Matched, not only listed in the graph: robot_node publishes samples and set points
        # only to a matched listener.
        return (
            self.newest_state_ns is not None
            and self.sample_sub.get_publisher_count() >= 1
            and self.setpoint_sub.get_publisher_count() >= 1
            and self.goal_pub.get_subscription_count() >= 1
        )

    def paired(self) -> tuple[dict[int, Any], dict[int, Any], dict[int, Any]]:
        """Samples and set points (positions, velocities) in the samples' joint order."""
        names = self.names or ()
        q_d, qd_d = {}, {}
        for stamp, (joints, pos, vel) in self.setpoints.items():
            index = {j: i for i, j in enumerate(joints)}
            if all(j in index for j in names):
                q_d[stamp] = [pos[index[j]] for j in names]
                if vel:
                    qd_d[stamp] = [vel[index[j]] for j in names]
        return dict(self.samples), q_d, qd_d


class WallRun:
    """robot_sim and the controllers as two processes, driven through one run."""

    def __init__(self, workdir: Path, spec: RunSpec) -> None:
        self.workdir, self.spec = workdir, spec
        self.procs: list[subprocess.Popen] = []

    def _spawn(self, role: str, cmd: list[str]) -> None:
        log = open(self.workdir / f"{self.spec.tag}.{role}.log", "w")
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy())
        log.close()
        self.procs.append(proc)

    def start(self) -> None:
        s = self.spec
        sim_file = self.workdir / f"{s.tag}.robot_sim.yaml"
        params = {
            "robot_sim": {
                "ros__parameters": robot_sim_parameters(
                    s.arm, s.effects, s.rate_hz, s.velocity_source
                )
            }
        }
        sim_file.write_text(yaml.safe_dump(params, sort_keys=False))
        self._spawn(
            "robot_sim", [str(BIN / "robot_sim"), "--ros-args", "--params-file", str(sim_file)]
        )
        from apc_lab import robot_compare as rc

        robot_file = benchlib.CONFIG / rc.ROBOT_FILES[s.arm]
        cmd = [str(BIN / "robot_node"), "--ros-args", "--params-file", str(robot_file)]
        settings = [
            a for nv in s.node_settings for a in ("-p", f"robot_node:{nv.replace('=', ':=', 1)}")
        ]
        self._spawn("controllers", cmd + controller_arguments(s.arm, s.law, s.effects) + settings)

    def log_tail(self) -> str:
        return benchlib.log_tail(self.workdir, self.spec.tag)

    def _spin_until(
        self, executor: Any, done: Callable[[], bool], timeout_s: float, what: str
    ) -> None:
        deadline = time.monotonic() + timeout_s
        while not done():
            for p in self.procs:
                if p.poll() is not None:
                    raise RuntimeError(f"a process exited (code {p.returncode}) {what}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"timed out after {timeout_s:g} s {what}")
            executor.spin_once(timeout_sec=0.01)

    def _transition(self, executor: Any, obs: Observer, transition: int, what: str) -> None:
        from lifecycle_msgs.srv import ChangeState

        request = ChangeState.Request()
        request.transition.id = transition
        future = obs.lifecycle.call_async(request)
        self._spin_until(executor, future.done, 10.0, f"waiting for robot_node to {what}")
        if not future.result().success:
            raise RuntimeError(f"robot_node refused to {what}")

    def execute(self) -> dict[str, Any]:
        """Start, hold, move, hold, read the diagnostics; every process stopped at the end."""
        import rclpy
        from lifecycle_msgs.msg import Transition

        from apc_core.nodeutil import make_executor
        from apc_lab import robot_compare as rc

        s = self.spec
        scenario = rc.arm_scenario(s.arm, "c")
        context = rclpy.Context()
        rclpy.init(context=context)
        executor = make_executor("single", context)
        obs = Observer(context)
        executor.add_node(obs.node)
        try:
            self.start()
            self._spin_until(
                executor,
                obs.lifecycle.service_is_ready,
                START_TIMEOUT_S,
                "waiting for robot_node's lifecycle service",
            )
            self._transition(executor, obs, Transition.TRANSITION_CONFIGURE, "configure")
            self._spin_until(
                executor, obs.controllers_heard, START_TIMEOUT_S, "waiting for robot_node's topics"
            )
            settle = time.monotonic() + MATCH_SETTLE_S
            self._spin_until(executor, lambda: time.monotonic() > settle, 5.0, "settling")
            # Activate at phase_s after a joint state's stamp (the driver's clock is this
            # machine's system clock): the request leaves then; robot_node takes it a little
            # later, at a random phase of the driver's cycle either way.
            assert obs.newest_state_ns is not None
            period_ns = round(1e9 / s.rate_hz)
            target = obs.newest_state_ns + round(s.phase_s * 1e9)
            while target < time.time_ns() + 200_000:
                target += period_ns
            while (left := target - time.time_ns()) > 0:
                time.sleep(min(left * 1e-9, 1e-4))
            self._transition(executor, obs, Transition.TRANSITION_ACTIVATE, "activate")
            obs.node.destroy_subscription(obs.state_sub)  # 1 kHz of callbacks saved
            activated = time.monotonic()
            self._spin_until(
                executor,
                lambda: obs.names is not None,
                FIRST_SAMPLE_TIMEOUT_S,
                "waiting for robot_node's first sample after activation",
            )
            first_sample = time.monotonic()
            self._spin_until(
                executor,
                lambda: time.monotonic() > first_sample + HOLD_BEFORE_S,
                HOLD_BEFORE_S + 5.0,
                "holding",
            )
            obs.goal_pub.publish(rc.goal_message(scenario, obs.names))
            sent = time.monotonic()
            end = sent + scenario.duration + HOLD_AFTER_S
            self._spin_until(executor, lambda: time.monotonic() > end, 30.0, "moving")

            def fresh_status() -> bool:
                got = [obs.status_of(name) for name in ("robot_node", "robot_sim")]
                return all(status is not None and status[0] > end for status in got)

            # Counters only go up: a status from before the end (one lost) still counts most.
            deadline = time.monotonic() + DIAGNOSTICS_WAIT_S
            while not fresh_status() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.01)
            status, sim_status = obs.status_of("robot_node"), obs.status_of("robot_sim")
            if status is None:
                raise RuntimeError("no /diagnostics from robot_node: hand-overs unknown")
            values = status[1]
            errors = run_errors(*obs.paired(), round(scenario.period * 1e9), scenario.duration)
            return {
                **errors,
                "lost": is_lost(errors),
                "supervisor": supervisor_counts(values),
                "robot_node_counters": status_counters(values),
                "robot_sim_counters": status_counters(sim_status[1]) if sim_status else {},
                "diagnostics_after_end": fresh_status(),
                "first_sample_after_activation_s": round(first_sample - activated, 4),
            }
        finally:
            executor.remove_node(obs.node)
            obs.node.destroy_node()
            executor.shutdown()
            rclpy.shutdown(context=context)
            # The controllers first: the driver then holds their last command while they stop.
            benchlib.stop_processes(self.procs[1:])
            benchlib.stop_processes(self.procs[:1])


def run_one(workdir: Path, spec: RunSpec) -> dict[str, Any]:
    """One run's result; a run that cannot be carried out says why in ``failed``."""
    account = benchlib.CpuAccount()
    run = WallRun(workdir, spec)
    try:
        result = run.execute()
        result["failed"] = None
    except RuntimeError as exc:
        tail = run.log_tail()
        result = {"failed": f"{exc}" + (f"\n{tail}" if tail else ""), "lost": None}
    result["phase_s"] = spec.phase_s
    result["machine_load"] = account.result()
    return result


def _progress_line(spec: RunSpec, runs: int, r: Mapping[str, Any]) -> str:
    head = f"{spec.arm} {spec.effects} {spec.rate_hz:g} Hz {spec.law} run {spec.index + 1}/{runs}"
    load = r["machine_load"]
    tail = (
        f"other jobs {load['other_cores']} cores, steal {load['steal_cores']} cores, "
        f"{load['wall_s']} s"
    )
    if r.get("failed"):
        return f"{head}: FAILED {r['failed'].splitlines()[0]}; {tail}"
    sup = r.get("supervisor") or {}
    at = r.get("beyond_limit_at_s")
    lost = f" LOST (beyond {LOST_DEG:g} deg at {at:+.2f} s)" if at is not None else " LOST"
    return (
        f"{head}: max {degrees_text(r.get('max_error_deg'))} final "
        f"{degrees_text(r.get('final_error_deg'))} deg{lost if r.get('lost') else ''}; "
        f"hand-overs {sup.get('supervisor.handovers', 0)}; {tail}"
    )


def run(
    quick: bool = False,
    *,
    arms: Sequence[str] | None = None,
    effects: Sequence[str] | None = None,
    rates: Sequence[float] | None = None,
    laws: Sequence[str] | None = None,
    runs: int | None = None,
    seed: int = 0,
    logs: Path | None = None,
    velocity_source: str = "",
    node_settings: Sequence[str] = (),
) -> dict[str, Any]:
    """Every cell (``quick``: :data:`QUICK`'s), ``runs`` runs each; {"robot_clock": result}.
    ``velocity_source``: the physical arms' drive velocity instead of their preset's;
    ``node_settings``: ``NAME=VALUE`` robot_node parameters given to every law's node.
    Node logs and parameter files go to ``logs`` (kept) or a temporary directory."""
    benchlib.isolate_dds()
    base: dict[str, Any] = QUICK if quick else {
        "arms": ARMS, "effects": EFFECTS, "rates": RATES_HZ, "runs": 3
    }  # fmt: skip
    arms = arms or base["arms"]
    effects = effects or base["effects"]
    rates = rates or base["rates"]
    laws = laws or tuple(LAWS)
    runs = runs or base["runs"]
    rng = random.Random(seed)
    t0 = time.monotonic()
    account = benchlib.CpuAccount()
    result: dict[str, Any] = {
        "clock": "wall time",
        "command": benchlib.command_line(),
        "started_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "load_average_before": benchlib.load_average(),
        "machine": benchlib.machine(),
        "lost_deg": LOST_DEG,
        "seed": seed,
        "settings": {
            "robot_sim": "engine mujoco, sim_time false, robot_compare's case (c) arm and payload",
            "controllers": "robot_node --ros-args --params-file config/<arm>_robot.yaml "
            "-p robot_node:autostart:=false -p robot_node:controller:=<law> "
            f"-p robot_node:path_tolerance:={PATH_TOLERANCE} (adaptive: the file's adaptive.* "
            "overrides put back to the preset's values)",
            "physical arms' velocity": velocity_source or "the preset's",
            "robot_node settings": list(node_settings),
            "run": f"configure, activate at a random phase of the driver's cycle, hold "
            f"{HOLD_BEFORE_S:g} s, case (c) goal, hold {HOLD_AFTER_S:g} s",
        },
        "cells": [],
    }
    with tempfile.TemporaryDirectory(prefix="apc_robot_clock_") as tmp:
        workdir = Path(logs) if logs else Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        for arm, eff, rate, law in plan(arms, effects, rates, laws):
            cell_runs = []
            for i in range(runs):
                phase = rng.uniform(0.0, 1.0 / rate)
                spec = RunSpec(arm, eff, rate, law, i, phase, velocity_source, tuple(node_settings))
                r = run_one(workdir, spec)
                benchlib.progress(_progress_line(spec, runs, r))
                cell_runs.append(r)
            result["cells"].append(
                {
                    "arm": arm,
                    "effects": eff
                    if not velocity_source or eff == "ideal"
                    else f"{eff}, {velocity_source} velocity",
                    "rate_hz": rate,
                    "law": law,
                    "summary": aggregate_cell(cell_runs),
                    "runs": cell_runs,
                }
            )
    result["wall_s"] = round(time.monotonic() - t0, 1)
    result["machine_load"] = account.result()
    result["load_average_after"] = benchlib.load_average()
    return {"robot_clock": result}


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the PUMA, physical, 500 Hz, 1 run")
    parser.add_argument("--arms", nargs="+", choices=ARMS)
    parser.add_argument("--effects", nargs="+", choices=EFFECTS)
    parser.add_argument("--rates", nargs="+", type=float, help="driver rates (Hz)")
    parser.add_argument("--laws", nargs="+", choices=tuple(LAWS))
    parser.add_argument("--runs", type=int, help="runs per cell (default 3; --quick 1)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the activation phases")
    parser.add_argument("--logs", type=Path, help="keep the node logs in this directory")
    parser.add_argument("--json", type=Path, default=RESULTS_JSON, help="where the JSON goes")
    parser.add_argument("--md", type=Path, default=RESULTS_MD, help="where the table goes")
    parser.add_argument(
        "--velocity-source",
        choices=("exact", "noisy", "difference"),
        default="",
        help="the physical arms' drive velocity (robot_sim's velocity_source) instead of the "
        "preset's difference: exact for a drive that measures the arm's",
    )
    parser.add_argument(
        "--robot-node",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a robot_node parameter for every law (repeatable), e.g. feedforward_ahead=false",
    )
    parser.add_argument("--no-write", action="store_true", help="print only")
    args = parser.parse_args(argv)
    out = run(
        args.quick,
        arms=args.arms,
        effects=args.effects,
        rates=args.rates,
        laws=args.laws,
        runs=args.runs,
        seed=args.seed,
        logs=args.logs,
        velocity_source=args.velocity_source,
        node_settings=args.robot_node,
    )["robot_clock"]
    text = markdown(out)
    print(text)
    if not args.no_write:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
        args.md.write_text(text)
        benchlib.progress(f"wrote {args.json} and {args.md} in {out['wall_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
