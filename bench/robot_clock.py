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
adaptive law with the recommended preset as the robot file ships it, minus the file's per-arm
``adaptive.*`` overrides (the Panda's ``q_velocity: 10``: the preset itself runs). The robot
file's ``path_tolerance`` is opened (0: no check) for every law, so that every run finishes
and the loss rule below is the benchmark's, not the node's abort.

Each run (``--runs`` per cell, default 3): ``robot_node`` is configured, then activated through
its lifecycle service at a random phase of the driver's cycle (drawn from ``--seed``) after a
joint state's stamp; the arm holds :data:`HOLD_BEFORE_S`; robot_compare's case-(c) move
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

About 8-9 s per run on 2 cores (process start and discovery take half of it): the full grid
(48 cells x 3 runs) takes ~20-25 minutes; ``--quick`` is the PUMA with every physical effect
on at 500 Hz, one run per law (~25 s).

    .venv/bin/python bench/robot_clock.py                       # the full grid, 3 runs per cell
    .venv/bin/python bench/robot_clock.py --quick
    .venv/bin/python bench/robot_clock.py --arms puma3 --effects ideal --rates 100 1000 --runs 1
    .venv/bin/python bench/robot_clock.py --quick --logs LOGDIR --json OUT.json --md OUT.md
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
import numpy as np
import yaml

RESULTS_JSON = benchlib.BENCH_DIR / "robot_clock.json"
RESULTS_MD = benchlib.BENCH_DIR / "robot_clock.md"
#: Where the console scripts are (``robot_sim``, ``robot_node``): beside this interpreter.
BIN = Path(sys.executable).parent

RATES_HZ = (100.0, 250.0, 500.0, 1000.0)
ARMS = ("puma3", "panda")
EFFECTS = ("ideal", "physical")
#: Law label -> robot_node's ``controller``.
LAWS: dict[str, str] = {
    "computed torque": "computed_torque",
    "PID": "pid",
    "adaptive recommended": "adaptive",
    "adaptive robot file": "adaptive",
}
#: The robot file as shipped, run only for an arm whose file sets ``adaptive.*`` values.
ROBOT_FILE_LAW = "adaptive robot file"
#: The ``--quick`` subset (``make bench BENCH_ARGS=--quick``): one driver, every law, one run.
QUICK = {"arms": ("puma3",), "effects": ("physical",), "rates": (500.0,), "runs": 1}

#: A run is lost when a joint's tracking error goes beyond this (deg) after activation.
LOST_DEG = 10.0
#: Wall seconds the arm holds after activation before the goal is sent.
HOLD_BEFORE_S = 1.0
#: Wall seconds after the move's planned end before the run ends.
HOLD_AFTER_S = 0.5
#: Wall seconds between robot_node's topics appearing in the graph and activation: the graph
#: can list an endpoint before DDS has matched it (the first samples would be lost to the
#: observer).
MATCH_SETTLE_S = 0.5
#: ``path_tolerance`` for every law (rad; 0 = no check): the loss rule is :data:`LOST_DEG`.
PATH_TOLERANCE = [0.0]
#: Wall seconds for the processes to start, be discovered and configure robot_node.
START_TIMEOUT_S = 60.0
#: Wall seconds to wait after the run for each node's next ``/diagnostics`` (sent every 1 s).
DIAGNOSTICS_WAIT_S = 2.5


# ---------------------------------------------------------------------------------- pure parts
def run_errors(
    q: Mapping[int, Sequence[float]],
    q_d: Mapping[int, Sequence[float]],
    qd_d: Mapping[int, Sequence[float]],
    period_ns: int,
    move_s: float,
    limit_deg: float = LOST_DEG,
) -> dict[str, Any]:
    """Tracking error of one run from the samples ``q`` and set points ``q_d``, ``qd_d`` (rad,
    rad/s), each keyed by its stamp (ns, on the sample grid kT).

    The move starts at the last paired sample before the first set point that moves (as
    :func:`apc_recording.runs.load_robot_run`) and ends ``move_s`` later. Returns the max
    error per joint over the move and the error at its end (deg; None when the move's end was
    not sampled; else at the last paired sample up to it, should the end's own sample be
    missed), ``run_max_error_deg`` over every paired sample (a non-finite position counts
    as an infinite error), whether the move started and was sampled to its end, and
    ``beyond_limit_at_s``: when a joint's error first went beyond ``limit_deg``, in s from the
    move's start (negative: in the hold before it; None: never, or no move to time it from).
    """
    stamps = sorted(set(q) & set(q_d))
    if not stamps:
        return {
            "samples": 0,
            "started": False,
            "completed": False,
            "max_error_deg": None,
            "final_error_deg": None,
            "run_max_error_deg": None,
            "beyond_limit_at_s": None,
        }
    measured = np.asarray([q[s] for s in stamps], dtype=float)
    planned = np.asarray([q_d[s] for s in stamps], dtype=float)
    err = np.rad2deg(np.abs(measured - planned))
    err = np.where(np.isfinite(err), err, np.inf)
    moving = [i for i, s in enumerate(stamps) if s in qd_d and np.any(np.asarray(qd_d[s]) != 0.0)]
    out: dict[str, Any] = {
        "samples": len(stamps),
        "started": bool(moving),
        "completed": False,
        "max_error_deg": None,
        "final_error_deg": None,
        "run_max_error_deg": err.max(axis=0).tolist(),
        "beyond_limit_at_s": None,
    }
    if not moving:
        return out
    start = stamps[max(moving[0] - 1, 0)]
    beyond = np.flatnonzero(np.any(err > limit_deg, axis=1))
    if beyond.size:
        out["beyond_limit_at_s"] = (stamps[int(beyond[0])] - start) * 1e-9
    end = start + round(move_s * 1e9 / period_ns) * period_ns
    rows = [i for i, s in enumerate(stamps) if start <= s <= end]
    out["max_error_deg"] = err[rows].max(axis=0).tolist()
    if stamps[-1] >= end:  # sampled to the move's end (a sample missed there aside)
        out["completed"] = True
        out["final_error_deg"] = err[rows[-1]].tolist()
    return out


def is_lost(errors: Mapping[str, Any], limit_deg: float = LOST_DEG) -> bool:
    """A run is lost when the move never started or was not sampled to its end, or any joint's
    error went beyond ``limit_deg`` at any sample after activation."""
    worst = errors.get("run_max_error_deg")
    if not errors.get("completed") or worst is None:
        return True
    return bool(np.any(~(np.asarray(worst, dtype=float) <= limit_deg)))


#: robot_node's counters of the wall clock's faults, summed per cell in the table (absent = 0).
TIMING_COUNTERS = ("missed_samples", "missed_setpoint", "stale", "watchdog")
#: The supervisor's counters every result carries (absent from the diagnostics = 0).
SUPERVISOR_KEYS = ("supervisor.handovers", "supervisor.handbacks")


def supervisor_counts(values: Mapping[str, str]) -> dict[str, int]:
    """Every integer ``supervisor.*`` value of a ``DiagnosticStatus``'s key-values, with
    :data:`SUPERVISOR_KEYS` at 0 when absent (no supervisor, or none counted yet)."""
    counts = dict.fromkeys(SUPERVISOR_KEYS, 0)
    for key, value in values.items():
        if key.startswith("supervisor."):
            try:
                counts[key] = int(value)
            except ValueError:
                continue  # a state or a name, not a counter
    return counts


def _worst(rows: list[list[float] | None]) -> list[float] | None:
    present = [np.asarray(r, dtype=float) for r in rows if r is not None]
    return np.max(present, axis=0).tolist() if present else None


def aggregate_cell(runs: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One cell's runs summed up: the worst max and final error per joint over the runs that
    did not fail, runs lost and failed, every supervisor counter and robot_node's
    :data:`TIMING_COUNTERS` summed over the runs, and the most cores other jobs used during one
    of them (None when no run says)."""
    done = [r for r in runs if not r.get("failed")]
    supervisor: dict[str, int] = {}
    for r in done:
        for key, n in (r.get("supervisor") or {}).items():
            supervisor[key] = supervisor.get(key, 0) + int(n)
    return {
        "runs": len(runs),
        "failed": len(runs) - len(done),
        "lost": sum(bool(r.get("lost")) for r in done),
        "worst_max_error_deg": _worst([r.get("max_error_deg") for r in done]),
        "worst_final_error_deg": _worst([r.get("final_error_deg") for r in done]),
        "supervisor": supervisor,
        "timing_faults": {
            k: sum(int((r.get("robot_node_counters") or {}).get(k, 0)) for r in done)
            for k in TIMING_COUNTERS
        },
        "other_cores_max": max(other) if (other := _other_cores(runs)) else None,
    }


def _other_cores(runs: Sequence[Mapping[str, Any]]) -> list[float]:
    loads = [(r.get("machine_load") or {}).get("other_cores") for r in runs]
    return [float(v) for v in loads if v is not None]


def _degrees(values: Sequence[float] | None) -> str:
    if values is None:
        return "-"
    return " ".join("inf" if not np.isfinite(v) else f"{v:.2f}" for v in values)


def markdown(result: Mapping[str, Any], heading: str = "#") -> str:
    """The benchmark's table: one row per cell and law, labelled with the machine and its load."""
    m = result.get("machine") or {}
    load = result.get("machine_load") or {}
    lines = [
        f"{heading} Robot path on wall time (robot_sim and `robot_node` in two processes)",
        "",
        f"Wall time, not simulated time: {m.get('cpu', '?')}, {m.get('cores', '?')} cores; "
        f"load average before/after {result.get('load_average_before', '?')} / "
        f"{result.get('load_average_after', '?')}; other jobs used "
        f"{load.get('other_cores', '?')} cores on average meanwhile "
        f"({result.get('wall_s', '?')} s, {result.get('started_utc', '?')}).",
        "",
        f"Errors: the controllers' samples against their set points, worst run per joint (deg); "
        f"lost: a joint beyond {result.get('lost_deg', LOST_DEG):g} deg or the move not "
        "finished; hand-overs / hand-backs: the supervisor's, summed over the runs.",
        "",
        "| arm | effects | driver Hz | law | runs lost / failed | max error | final error "
        "| hand-overs / hand-backs | other supervisor counts | "
        + " / ".join(k.replace("_", " ") for k in TIMING_COUNTERS)
        + " | other jobs (cores, worst run) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for cell in result.get("cells", []):
        s = cell["summary"]
        sup = dict(s.get("supervisor") or {})
        over, back = (sup.pop(k, 0) for k in SUPERVISOR_KEYS)
        others = ", ".join(f"{k.removeprefix('supervisor.')} {v}" for k, v in sorted(sup.items()))
        faults = " / ".join(str((s.get("timing_faults") or {}).get(k, 0)) for k in TIMING_COUNTERS)
        lines.append(
            f"| {cell['arm']} | {cell['effects']} | {cell['rate_hz']:g} | {cell['law']} "
            f"| {s['lost']}/{s['runs']} / {s['failed']} | {_degrees(s['worst_max_error_deg'])} "
            f"| {_degrees(s['worst_final_error_deg'])} | {over} / {back} | {others or '-'} "
            f"| {faults} "
            f"| {'-' if s.get('other_cores_max') is None else s['other_cores_max']} |"
        )
    failures = [
        f"- {c['arm']} {c['effects']} {c['rate_hz']:g} Hz {c['law']} run {i + 1}: {r['failed']}"
        for c in result.get("cells", [])
        for i, r in enumerate(c["runs"])
        if r.get("failed")
    ]
    if failures:
        lines += ["", "Failed runs:", "", *failures]
    return "\n".join(lines) + "\n"


def plan(
    arms: Sequence[str], effects: Sequence[str], rates: Sequence[float], laws: Sequence[str]
) -> list[tuple[str, str, float, str]]:
    """The cells in the order they run: (arm, effects, driver rate, law); the robot file's law
    only for an arm whose file differs from the preset."""
    return [
        (a, e, float(r), law)
        for a in arms
        for e in effects
        for r in rates
        for law in laws
        if law != ROBOT_FILE_LAW or robot_file_overrides(a)
    ]


def robot_file_overrides(arm: str) -> dict[str, Any]:
    """``robot_node`` values that put the arm's robot file back on its preset: each
    ``adaptive.*`` the file sets, at the preset's value (or the law's default)."""
    from apc_feedback.presets import DEFAULT_PRESET, PRESETS
    from apc_lab import robot_compare as rc
    from apc_lab.experiment import law_parameters

    params = yaml.safe_load((benchlib.CONFIG / rc.ROBOT_FILES[arm]).read_text())
    node = params["robot_node"]["ros__parameters"]
    preset = law_parameters("adaptive", PRESETS[node.get("preset", DEFAULT_PRESET)]())
    return {k: preset[k] for k in node if k.startswith("adaptive.")}


def controller_arguments(arm: str, law: str) -> list[str]:
    """``-p`` overrides of the robot file for one law (lifecycle driven by the benchmark)."""
    controller = LAWS[law]
    values: dict[str, Any] = {
        "autostart": False,
        "controller": controller,
        "path_tolerance": PATH_TOLERANCE,
    }
    if law == "adaptive recommended":
        values.update(robot_file_overrides(arm))
    args: list[str] = []
    for key, value in values.items():
        args += ["-p", f"robot_node:{key}:={json.dumps(value)}"]
    return args


def robot_sim_parameters(arm: str, effects: str, rate_hz: float) -> dict[str, Any]:
    """robot_sim's parameters: robot_compare's case (c) for the arm on wall time at ``rate_hz``."""
    from apc_lab import robot_compare as rc

    case = rc.RobotCase(arm, "c", effects, "computed torque", timing="realtime")
    params = rc.node_parameters(case)["robot_sim"]
    period = float(case.scenario.period)
    params.update(
        state_rate=float(rate_hz),
        sim_time=False,
        command_latency=0.0,  # wall time: the transport is real
        sim_cycles_per_command=round(rate_hz * period),
    )
    return params


# ---------------------------------------------------------------------------------- one run
@dataclass
class RunSpec:
    arm: str
    effects: str
    rate_hz: float
    law: str
    index: int
    phase_s: float

    @property
    def tag(self) -> str:
        law = self.law.replace(" ", "_")
        return f"{self.arm}_{self.effects}_{self.rate_hz:g}_{law}_{self.index}"


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
        n.create_subscription(JointState, wire.SAMPLE, self._on_sample, wire.CONTROL_QOS)
        n.create_subscription(JointTrajectory, wire.SETPOINT, self._on_setpoint, wire.CONTROL_QOS)
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
        wire, n = self.wire, self.node
        return (
            self.newest_state_ns is not None
            and n.count_publishers(wire.SETPOINT) >= 1
            and n.count_publishers(wire.SAMPLE) >= 1
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


def _counters(values: Mapping[str, str]) -> dict[str, int]:
    out = {}
    for k, v in values.items():
        try:
            out[k] = int(v)
        except ValueError:
            continue
    return out


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
            "robot_sim": {"ros__parameters": robot_sim_parameters(s.arm, s.effects, s.rate_hz)}
        }
        sim_file.write_text(yaml.safe_dump(params, sort_keys=False))
        self._spawn(
            "robot_sim", [str(BIN / "robot_sim"), "--ros-args", "--params-file", str(sim_file)]
        )
        from apc_lab import robot_compare as rc

        robot_file = benchlib.CONFIG / rc.ROBOT_FILES[s.arm]
        cmd = [str(BIN / "robot_node"), "--ros-args", "--params-file", str(robot_file)]
        self._spawn("controllers", cmd + controller_arguments(s.arm, s.law))

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
                lambda: time.monotonic() > activated + HOLD_BEFORE_S,
                HOLD_BEFORE_S + 5.0,
                "holding",
            )
            if obs.names is None:
                raise RuntimeError(f"no sample within {HOLD_BEFORE_S:g} s of activation")
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
                "robot_node_counters": _counters(values),
                "robot_sim_counters": _counters(sim_status[1]) if sim_status else {},
                "diagnostics_after_end": fresh_status(),
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
    tail = f"other jobs {load['other_cores']} cores, {load['wall_s']} s"
    if r.get("failed"):
        return f"{head}: FAILED {r['failed'].splitlines()[0]}; {tail}"
    sup = r.get("supervisor") or {}
    at = r.get("beyond_limit_at_s")
    lost = f" LOST (beyond {LOST_DEG:g} deg at {at:+.2f} s)" if at is not None else " LOST"
    return (
        f"{head}: max {_degrees(r.get('max_error_deg'))} final "
        f"{_degrees(r.get('final_error_deg'))} deg{lost if r.get('lost') else ''}; "
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
) -> dict[str, Any]:
    """Every cell (``quick``: :data:`QUICK`'s), ``runs`` runs each; {"robot_clock": result}.
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
                spec = RunSpec(arm, eff, rate, law, i, rng.uniform(0.0, 1.0 / rate))
                r = run_one(workdir, spec)
                benchlib.progress(_progress_line(spec, runs, r))
                cell_runs.append(r)
            result["cells"].append(
                {
                    "arm": arm,
                    "effects": eff,
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
