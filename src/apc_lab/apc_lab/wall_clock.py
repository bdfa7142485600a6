"""The robot path on wall time: the loss rule, the cells and the table of the wall-time
benchmark, and the parameters it starts ``robot_sim`` and ``robot_node`` with.

``bench/robot_clock.py`` runs the simulated ros2_control robot (``robot_sim`` on its wall
timer) and apc's controllers (``robot_node``) as two processes, the way a user starts them, and
collects per run the samples the controllers took and their set points, stamped on the sample
grid kT, and robot_node's last ``/diagnostics``. What is measured and judged from those, and
what the processes are started with, is here, apart from the processes (it starts nothing
and reads no clock), so that it is tested on synthetic runs and the script stays a driver of
processes:

- the tracking error of a run over robot_compare's case-(c) move and at its end, as
  robot_compare measures it (:func:`run_errors`), and the loss rule (:func:`is_lost`,
  :data:`LOST_DEG`);
- the supervisor's hand-overs and robot_node's timing faults read from its diagnostics
  (:func:`supervisor_counts`, :func:`status_counters`);
- a cell's runs summed up (:func:`aggregate_cell`) and the table of every cell
  (:func:`markdown`);
- the cells (:func:`plan`: arms, physical effects, driver rates, laws) and each process's
  parameters (:func:`robot_sim_parameters`, :func:`controller_arguments`).

``robot_compare`` (and through it rclpy and pinocchio) is imported only by the functions that
build parameters: the loss rule and the table serve ``bench/report.py`` without them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import yaml

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

#: Seconds the arm holds after activation before the goal is sent (the offline grid holds as
#: long: a law that has learnt through a longer hold moves otherwise, docs/robot.md).
HOLD_BEFORE_S = 1.0
#: A run is lost when a joint's tracking error goes beyond this (deg) after activation.
LOST_DEG = 10.0
#: ``path_tolerance`` for every law (rad; 0 = no check): the loss rule is :data:`LOST_DEG`.
PATH_TOLERANCE = [0.0]


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


def status_counters(values: Mapping[str, str]) -> dict[str, int]:
    """Every integer value of a ``DiagnosticStatus``'s key-values (a node's counters)."""
    out = {}
    for k, v in values.items():
        try:
            out[k] = int(v)
        except ValueError:
            continue
    return out


def _worst(rows: list[list[float] | None]) -> list[float] | None:
    present = [np.asarray(r, dtype=float) for r in rows if r is not None]
    return np.max(present, axis=0).tolist() if present else None


def aggregate_cell(runs: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """One cell's runs summed up: the worst max and final error per joint over the runs that
    did not fail, runs lost and failed, every supervisor counter and robot_node's
    :data:`TIMING_COUNTERS` summed over the runs, and the most cores other jobs used, and the
    most the hypervisor took from the machine (steal), during one of them (None when no run
    says)."""
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
        "other_cores_max": max(other) if (other := _load(runs, "other_cores")) else None,
        "steal_cores_max": max(steal) if (steal := _load(runs, "steal_cores")) else None,
    }


def _load(runs: Sequence[Mapping[str, Any]], key: str) -> list[float]:
    loads = [(r.get("machine_load") or {}).get(key) for r in runs]
    return [float(v) for v in loads if v is not None]


def _or_dash(value: Any) -> str:
    return "-" if value is None else str(value)


def degrees_text(values: Sequence[float] | None) -> str:
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
        f"{load.get('other_cores', '?')} cores on average meanwhile and the hypervisor took "
        f"{load.get('steal_cores', '?')} (steal: time the machine's cores ran someone else; a "
        f"run it takes from misses its driver's cycles) "
        f"({result.get('wall_s', '?')} s, {result.get('started_utc', '?')}).",
        "",
        f"Errors: the controllers' samples against their set points, worst run per joint (deg); "
        f"lost: a joint beyond {result.get('lost_deg', LOST_DEG):g} deg or the move not "
        "finished; hand-overs / hand-backs: the supervisor's, summed over the runs.",
        "",
        "| arm | effects | driver Hz | law | runs lost / failed | max error | final error "
        "| hand-overs / hand-backs | other supervisor counts | "
        + " / ".join(k.replace("_", " ") for k in TIMING_COUNTERS)
        + " | other jobs / steal (cores, worst run) |",
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
            f"| {s['lost']}/{s['runs']} / {s['failed']} | {degrees_text(s['worst_max_error_deg'])} "
            f"| {degrees_text(s['worst_final_error_deg'])} | {over} / {back} | {others or '-'} "
            f"| {faults} "
            f"| {_or_dash(s.get('other_cores_max'))} / {_or_dash(s.get('steal_cores_max'))} |"
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
    from apc_lab.scenario import CONFIG_DIR

    params = yaml.safe_load((CONFIG_DIR / rc.ROBOT_FILES[arm]).read_text())
    node = params["robot_node"]["ros__parameters"]
    preset = law_parameters("adaptive", PRESETS[node.get("preset", DEFAULT_PRESET)]())
    return {k: preset[k] for k in node if k.startswith("adaptive.")}


def controller_arguments(arm: str, law: str, effects: str) -> list[str]:
    """``-p`` overrides of the robot file for one law (lifecycle driven by the benchmark) on the
    arm with ``effects``: a physical arm's rotor inertia, told to every law as its user tells
    it, and its friction (:func:`apc_lab.robot_compare.controller_arm_parameters`)."""
    from apc_lab.robot_compare import controller_arm_parameters

    controller = LAWS[law]
    values: dict[str, Any] = {
        "autostart": False,
        "controller": controller,
        "path_tolerance": PATH_TOLERANCE,
    }
    if law == "adaptive recommended":
        values.update(robot_file_overrides(arm))
    values.update(controller_arm_parameters(arm, effects))
    args: list[str] = []
    for key, value in values.items():
        args += ["-p", f"robot_node:{key}:={json.dumps(value)}"]
    return args


def robot_sim_parameters(
    arm: str, effects: str, rate_hz: float, velocity_source: str = ""
) -> dict[str, Any]:
    """robot_sim's parameters: robot_compare's case (c) for the arm on wall time at ``rate_hz``.

    The ideal arm publishes positions only, as a joint_state_broadcaster over hardware without
    a velocity state interface (the issue's driver, and the offline grid's ideal arm,
    ``bench/robot_clock_offline.py``); the physical presets publish their drive's velocity,
    the preset's (a difference of the encoder's positions) or ``velocity_source``'s (robot_sim's
    parameter: ``exact`` for a drive that measures the arm's).
    """
    from apc_lab import robot_compare as rc

    case = rc.RobotCase(arm, "c", effects, "computed torque", timing="realtime")
    params = rc.node_parameters(case)["robot_sim"]
    period = float(case.scenario.period)
    params.update(
        state_rate=float(rate_hz),
        sim_time=False,
        command_latency=0.0,  # wall time: the transport is real
        sim_cycles_per_command=round(rate_hz * period),
        publish_velocity=effects != "ideal",
    )
    if velocity_source and effects != "ideal":
        params["velocity_source"] = velocity_source
    return params
