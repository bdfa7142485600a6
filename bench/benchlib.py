"""Shared pieces of the benchmarks: statistics, the machine, random arms, DDS isolation, results.

Not a benchmark itself. ``bench/compute.py``, ``bench/ros_loop.py`` and ``bench/multi_arm.py``
import it; ``bench/run_all.py`` runs them all and writes ``bench/results.json`` and
``bench/results.md`` (:func:`write_results`).
"""

from __future__ import annotations

import json
import os
import platform
import random
import shlex
import subprocess
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from apc_lab.loop_timing import latency_stats  # noqa: F401  (re-exported for the benchmarks)

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
CONFIG = REPO / "config"
RESULTS_JSON = BENCH_DIR / "results.json"
RESULTS_MD = BENCH_DIR / "results.md"
PUMA3_URDF = CONFIG / "puma560_3dof.urdf"
PUMA6_URDF = CONFIG / "puma560.urdf"


# ------------------------------------------------------------------------------------ statistics
def stats(values: Iterable[float], digits: int = 4) -> dict[str, Any]:
    """Median and spread (p10, p90, quartiles, min, max) of repeated measurements."""
    a = np.asarray([float(v) for v in values], dtype=float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return {"median": None, "n": 0}
    p = np.percentile(a, [10, 25, 50, 75, 90])

    def r(v: float) -> float:
        return float(f"{v:.{digits}g}")

    return {
        "median": r(p[2]),
        "p10": r(p[0]),
        "p90": r(p[4]),
        "q1": r(p[1]),
        "q3": r(p[3]),
        "min": r(a.min()),
        "max": r(a.max()),
        "n": int(a.size),
    }


def growth_exponent(ns: Sequence[float], values: Sequence[float]) -> float:
    """Least-squares slope of log(value) against log(n): value ~ c n^slope over the range."""
    x, y = np.log(np.asarray(ns, float)), np.log(np.asarray(values, float))
    return round(float(np.polyfit(x, y, 1)[0]), 2)


# ------------------------------------------------------------------------------------ machine
def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions: dict[str, str] = {}
    for dist in ("ros-rclpy", "rclpy", "pin", "numpy", "mcap"):
        try:
            from importlib.metadata import version

            versions[dist] = version(dist)
        except Exception:
            continue
    try:
        import pinocchio

        versions["pinocchio"] = pinocchio.__version__
    except Exception:
        pass
    return {
        "platform": platform.platform(),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "usable_cores": len(os.sched_getaffinity(0)),
        "python": platform.python_version(),
        "rmw": os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp (default)"),
        "versions": versions,
    }


def load_average() -> list[float]:
    """The 1/5/15-minute load averages (other work on the machine skews every figure)."""
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return []


def _machine_busy_s() -> tuple[float, float]:
    """Busy and stolen CPU seconds of the whole machine since boot, from /proc/stat."""
    fields = Path("/proc/stat").read_text().splitlines()[0].split()[1:]
    v = [int(x) for x in fields] + [0] * 10
    user, nice, system, _idle, _iowait, irq, softirq, steal = v[:8]
    tick = os.sysconf("SC_CLK_TCK")
    return (user + nice + system + irq + softirq) / tick, steal / tick


def _own_cpu_s() -> float:
    """CPU seconds of this process and of every child it has waited for."""
    import resource

    total = 0.0
    for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN):
        r = resource.getrusage(who)
        total += r.ru_utime + r.ru_stime
    return total


class CpuAccount:
    """How busy the machine was while a part ran, and how much of that was someone else.

    ``other_cores`` = (machine busy time - this process and its waited-for children) / wall
    time: the average number of cores other jobs used meanwhile. Every benchmark figure here
    assumes they used none.
    """

    def __init__(self) -> None:
        self.t0 = time.monotonic()
        self.busy0, self.steal0 = _machine_busy_s()
        self.own0 = _own_cpu_s()

    def result(self) -> dict[str, float]:
        wall = max(time.monotonic() - self.t0, 1e-9)
        busy, steal = _machine_busy_s()
        own = _own_cpu_s() - self.own0
        busy -= self.busy0
        return {
            "wall_s": round(wall, 1),
            "machine_busy_cores": round(busy / wall, 2),
            "bench_cores": round(own / wall, 2),
            "other_cores": round(max(busy - own, 0.0) / wall, 2),
            "steal_cores": round((steal - self.steal0) / wall, 2),
        }


def command_line() -> str:
    """How this run was started, with the interpreter relative to the repository."""
    exe = Path(sys.executable)
    try:
        exe = exe.relative_to(REPO)
    except ValueError:
        pass
    return " ".join(shlex.quote(str(a)) for a in [exe, *sys.argv])


# ------------------------------------------------------------------------------------ arms
def random_arm(n: int, seed: int = 0) -> Any:
    """A random serial chain of ``n`` revolute joints built in Pinocchio, as an apc ``Robot``.

    Each joint turns about a random one of x/y/z, sits 0.1-0.4 m from its parent at a random
    orientation, and carries a body of 0.5-5 kg with a random centre of mass and a random
    physically valid inertia tensor (principal moments obeying the triangle inequality).
    """
    import pinocchio as pin

    from apc_core.robot import Robot

    rng = np.random.default_rng(seed)
    model = pin.Model()
    model.name = f"random_{n}"
    joint_types = (pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ)
    parent = 0
    names = []
    for i in range(n):
        rotation = pin.utils.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        translation = rng.uniform(0.1, 0.4) * _unit(rng)
        placement = pin.SE3(rotation, translation) if i else pin.SE3.Identity()
        name = f"joint_{i + 1}"
        jid = model.addJoint(
            parent,
            joint_types[int(rng.integers(3))](),
            placement,
            name,
            np.array([100.0]),  # max effort
            np.array([10.0]),  # max velocity
            np.array([-np.pi]),
            np.array([np.pi]),
        )
        mass = rng.uniform(0.5, 5.0)
        com = rng.uniform(-0.1, 0.1, 3)
        a, b = rng.uniform(0.01, 0.1, 2)
        c = rng.uniform(abs(a - b) + 1e-3, a + b)  # triangle inequality
        axes = pin.utils.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))
        inertia = axes @ np.diag([a, b, c]) @ axes.T
        model.appendBodyToJoint(jid, pin.Inertia(mass, com, inertia), pin.SE3.Identity())
        parent = jid
        names.append(name)
    model.gravity.linear = np.array([0.0, 0.0, -9.81])
    return Robot(
        model=model,
        joint_names=tuple(names),
        effort_limit=np.full(n, 100.0),
        source=f"<random seed={seed}>",
    )


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def arm(n: int, seed: int = 0) -> tuple[Any, str]:
    """The arm used for ``n`` joints and its label: the PUMA URDFs for 3 and 6, else random."""
    from apc_core.robot import load_robot

    if n == 3:
        return load_robot(PUMA3_URDF), "PUMA 560, 3 joints (config/puma560_3dof.urdf)"
    if n == 6:
        return load_robot(PUMA6_URDF), "PUMA 560, 6 joints (config/puma560.urdf)"
    return random_arm(n, seed), f"random serial chain, {n} revolute joints (seed {seed})"


# ------------------------------------------------------------------------------------ DDS
def _udp_ports_in_use() -> set[int]:
    ports: set[int] = set()
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            try:
                ports.add(int(line.split()[1].rsplit(":", 1)[1], 16))
            except (IndexError, ValueError):
                continue
    return ports


def isolate_dds() -> str:
    """Put this process (and its children) on a random free DDS domain, on localhost only.

    Must run before any rclpy context is created. The domain is drawn from 1-101 (the range
    whose RTPS ports stay below Linux's ephemeral ports) among those with no UDP port of their
    block (7400 + 250 d ... + 249) bound, so that a test suite running meanwhile on the same
    machine is neither disturbed nor disturbing. Returns the domain id.
    """
    if os.environ.get("_APC_BENCH_DOMAIN") != os.environ.get("ROS_DOMAIN_ID", "-"):
        used = _udp_ports_in_use()
        rng = random.SystemRandom()
        candidates = list(range(1, 102))
        rng.shuffle(candidates)
        domain = next(
            (d for d in candidates if not any(7400 + 250 * d + i in used for i in range(250))),
            candidates[0],
        )
        os.environ["ROS_DOMAIN_ID"] = os.environ["_APC_BENCH_DOMAIN"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return os.environ["ROS_DOMAIN_ID"]


def log_tail(workdir: Path, tag: str, lines: int = 5) -> str:
    """The last ``lines`` of each ``<tag>.*.log`` in ``workdir``, one line per file."""
    tails = []
    for log in sorted(workdir.glob(f"{tag}.*.log")):
        text = log.read_text(errors="replace").strip().splitlines()[-lines:]
        if text:
            tails.append(f"{log.name}: " + " | ".join(text))
    return "\n".join(tails)


def stop_processes(procs: Sequence[subprocess.Popen], timeout_s: float = 5.0) -> None:
    """SIGINT, then SIGTERM, then SIGKILL, each with a timeout: every child ends."""
    from apc_lab.experiment import stop_processes as stop

    stop(procs, timeout_s=timeout_s)


# ------------------------------------------------------------------------------------ output
def progress(message: str) -> None:
    """One progress line on stderr (stdout may carry JSON)."""
    print(f"[bench {time.strftime('%H:%M:%S')}] {message}", file=sys.stderr, flush=True)


def emit(result: dict[str, Any], part: str, t0: float, write: bool = True) -> None:
    """Finish one part: record its wall time, print it as JSON, merge it into results.json."""
    result[f"{part}_wall_s"] = round(time.monotonic() - t0, 1)
    json.dump(result, sys.stdout, indent=1)
    print()
    if write:
        write_results(result)


def read_results(path: Path = RESULTS_JSON) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def write_results(
    update: dict[str, Any], *, path: Path = RESULTS_JSON, replace: bool = False
) -> dict[str, Any]:
    """Merge ``update`` into ``bench/results.json`` (or replace it) and rewrite results.md."""
    data = {} if replace else read_results(path)
    data.update(update)
    data["machine"] = machine()
    path.write_text(json.dumps(data, indent=1, sort_keys=False) + "\n")
    from report import markdown  # bench/report.py (bench/ is on sys.path)

    RESULTS_MD.write_text(markdown(data))
    return data


# ------------------------------------------------------------------------------------ profiles
#: Where a function's own time goes, by its file (first match wins). Builtins and numpy or
#: standard-library internals are charged to whoever called them (see :func:`profile_buckets`).
BUCKETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("idle (rcl wait)", ("_rclpy_pybind11.wait>",)),
    ("DDS publish / take", ("_rclpy_pybind11.publish>", "_rclpy_pybind11.take_message>")),
    ("plant dynamics", ("apc_plant_sim/plant.py", "pinocchio")),
    ("feedback law", ("apc_feedback/rls.py", "apc_feedback/optimal.py", "controller.py")),
    ("feedforward (trajectory, RNEA)", ("apc_feedforward/trajectory.py", "nominal.py")),
    ("recorder (MCAP)", ("recorder.py", "apc_core/bag/", "/mcap/", "zstandard")),
    (
        "messages (wire, msg classes)",
        ("apc_msgs_py/", "/msg/_", "builtin_interfaces", "/rosgraph_msgs/"),
    ),
    ("apc nodes (callbacks, diagnostics)", ("/node.py", "nodeutil.py", "node_proc.py")),
    (
        "rclpy executor (Python)",
        ("/rclpy/", "contextlib.py", "_rclpy_pybind11", "threading.py", "inspect.py"),
    ),
)


def _bucket(file: str, func: str) -> str | None:
    where = f"{file}:{func}"
    for name, patterns in BUCKETS:
        if any(p in where for p in patterns):
            return name
    return None


def profile_buckets(stats: Any, samples: int) -> dict[str, float]:
    """Own time per sample (us) by :data:`BUCKETS`, from a ``pstats.Stats``.

    Time of a function that matches no bucket (numpy, builtins, the standard library) is
    split among its callers in proportion to the time each call site spent in it, up to four
    levels up; what is still unmatched is "other".
    """
    entries = stats.stats

    def shares(key: Any, depth: int) -> dict[str, float]:
        file, _line, func = key
        name = _bucket(file, func)
        if name is not None or depth == 0:
            return {name or "other": 1.0}
        callers = entries[key][4]
        total = sum(v[2] for v in callers.values())
        if not callers or total <= 0:
            return {"other": 1.0}
        out: dict[str, float] = {}
        for caller, v in callers.items():
            if caller not in entries:
                continue
            for b, f in shares(caller, depth - 1).items():
                out[b] = out.get(b, 0.0) + f * v[2] / total
        return out or {"other": 1.0}

    buckets: dict[str, float] = {}
    for key, (_cc, _nc, tottime, _ct, _callers) in entries.items():
        for b, f in shares(key, 4).items():
            buckets[b] = buckets.get(b, 0.0) + 1e6 * tottime * f / max(samples, 1)
    return {b: round(v, 1) for b, v in sorted(buckets.items(), key=lambda kv: -kv[1])}
