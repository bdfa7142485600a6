"""What every apc node shares: the robot from parameters, diagnostics, and ``main``.

- :data:`ROBOT_PARAMS` and :func:`robot_from_params` — the arm every node loads, from
  ``robot_description`` (URDF XML, the ROS convention) or ``robot_description_path``.
- :class:`Diagnostics` — counters and timing, published on ``/diagnostics`` at 1 Hz wall time.
- :func:`run_node` — ``main`` for a node executable: ``--help``, one-line start-up errors with
  exit code 2, clean shutdown on SIGINT/SIGTERM (Jazzy: try/finally and ``try_shutdown``).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from apc_msgs_py.params import ConfigError, Param
from apc_msgs_py.robot import PAPER_GRAVITY_M_S2, Robot, RobotModelError, load_robot
from apc_msgs_py.wire import DIAGNOSTICS, DIAGNOSTICS_QOS, WireError

#: Where ``config/`` is in a source checkout (src/apc_msgs_py/apc_msgs_py/ -> repo root).
_REPO_CONFIG = Path(__file__).resolve().parents[3] / "config"

ROBOT_PARAMS: tuple[Param, ...] = (
    Param(
        "robot_description",
        "",
        "URDF XML of the arm; when empty, robot_description_path is loaded instead",
    ),
    Param(
        "robot_description_path",
        "puma560_3dof.urdf",
        "URDF file: absolute, relative to the working directory, or a file name in apc's "
        "config directory (share/apc_msgs_py/config in a ROS install)",
    ),
    Param("gravity", PAPER_GRAVITY_M_S2, "gravity along -z of the base frame (m/s^2)", 0.0, 100.0),
    Param(
        "lock_joints",
        [],
        "URDF joints frozen at 0 (e.g. a gripper), so the rest is a serial chain",
        array_of=str,
    ),
    Param(
        "period",
        0.010,
        "sampling period T (s): torques are held for T, states are sampled every T",
        1e-4,
        1.0,
    ),
)


def config_dirs() -> list[Path]:
    """Directories searched for config files: the ROS share dir, then the source checkout."""
    dirs = []
    try:
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory("apc_msgs_py")) / "config")
    except Exception:  # no ament index (plain venv without AMENT_PREFIX_PATH)
        pass
    dirs.append(_REPO_CONFIG)
    return dirs


def resolve_config_path(name: str) -> Path:
    """Find a config file by absolute path, path relative to the cwd, or name in config dirs."""
    path = Path(os.path.expanduser(name))
    if path.is_absolute() or path.exists():
        return path
    for base in config_dirs():
        candidate = base / name
        if candidate.exists():
            return candidate
        candidate = base / path.name
        if candidate.exists():
            return candidate
    return path


def robot_from_params(values: dict[str, Any]) -> Robot:
    """Load the arm named by :data:`ROBOT_PARAMS` values; errors name the parameter."""
    xml = values.get("robot_description", "")
    source_param = "robot_description" if xml else "robot_description_path"
    source = xml if xml else resolve_config_path(values["robot_description_path"])
    try:
        return load_robot(
            source,
            gravity=float(values["gravity"]),
            lock_joints=tuple(values.get("lock_joints", ())),
        )
    except RobotModelError as exc:
        raise ConfigError(f"parameter '{source_param}': {exc}") from None


class Diagnostics:
    """Counters and per-sample timings of one node, turned into a ``DiagnosticStatus``.

    Counters (``rejected``, ``late`` ...) only go up. Timings keep the last ``window`` values
    and are reported as median / max in microseconds.
    """

    def __init__(self, name: str, hardware_id: str = "apc", window: int = 1000) -> None:
        self.name = name
        self.hardware_id = hardware_id
        self.counters: dict[str, int] = {}
        self.values: dict[str, str] = {}
        self._timings: dict[str, deque[float]] = {}
        self._window = window
        self.level = DiagnosticStatus.OK
        self.message = "ok"

    def count(self, key: str, n: int = 1) -> int:
        self.counters[key] = self.counters.get(key, 0) + n
        return self.counters[key]

    def time(self, key: str, seconds: float) -> None:
        self._timings.setdefault(key, deque(maxlen=self._window)).append(seconds)

    def set(self, key: str, value: Any) -> None:
        self.values[key] = str(value)

    def status(self) -> DiagnosticStatus:
        values = [KeyValue(key=k, value=str(v)) for k, v in sorted(self.counters.items())]
        for key, samples in sorted(self._timings.items()):
            if samples:
                values.append(
                    KeyValue(
                        key=f"{key}_median_us", value=f"{1e6 * statistics.median(samples):.1f}"
                    )
                )
                values.append(KeyValue(key=f"{key}_max_us", value=f"{1e6 * max(samples):.1f}"))
        values += [KeyValue(key=k, value=v) for k, v in sorted(self.values.items())]
        return DiagnosticStatus(
            level=self.level,
            name=self.name,
            message=self.message,
            hardware_id=self.hardware_id,
            values=values,
        )


class DiagnosticsPublisher:
    """Publishes a node's :class:`Diagnostics` on ``/diagnostics`` every ``period_s`` wall time."""

    def __init__(self, node: Node, diagnostics: Diagnostics, period_s: float = 1.0) -> None:
        self._node = node
        self._diagnostics = diagnostics
        self._pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS, DIAGNOSTICS_QOS)
        self._timer = node.create_timer(
            period_s, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )

    def publish(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.status = [self._diagnostics.status()]
        self._pub.publish(msg)


class Stopwatch:
    """``with Stopwatch(diag, "compute"):`` records the block's wall time."""

    def __init__(self, diagnostics: Diagnostics, key: str) -> None:
        self._d, self._key = diagnostics, key

    def __enter__(self) -> Stopwatch:
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self._d.time(self._key, time.perf_counter() - self._t0)


def reject(node: Node, diagnostics: Diagnostics, topic: str, exc: Exception) -> None:
    """Count and log (throttled) a message that failed validation; the node carries on."""
    n = diagnostics.count(f"rejected.{topic}")
    diagnostics.count("rejected")
    node.get_logger().warn(
        f"rejected message on '{topic}' ({n} so far): {exc}", throttle_duration_sec=1.0
    )


def print_help(prog: str, summary: str, params: Iterable[Param]) -> None:
    print(f"usage: {prog} [--ros-args -p NAME:=VALUE ... --params-file FILE]\n")
    print(summary.strip() + "\n")
    print("parameters:")
    for p in params:
        rng = f" [{p.low}, {p.high}]" if p.low is not None else ""
        ro = " (read-only)" if p.read_only else ""
        print(f"  {p.name} = {p.default!r}{rng}{ro}\n      {p.description}")


def _user_args(argv: Sequence[str]) -> list[str]:
    args = list(argv)
    return args[: args.index("--ros-args")] if "--ros-args" in args else args


def run_node(
    make_node: Callable[[], Node],
    *,
    prog: str,
    summary: str,
    params: Iterable[Param],
    args: Sequence[str] | None = None,
    spin_until: Callable[[Node], bool] | None = None,
) -> int:
    """``main`` of a node executable; returns the process exit code.

    ``--help`` prints the parameters. A :class:`ConfigError` (or a model/wire error) while the
    node is built prints one line naming the parameter and returns 2. SIGINT/SIGTERM end the
    spin and the node is destroyed before ``rclpy`` shuts down. ``spin_until(node)`` returning
    True ends a finite run (e.g. the plant after ``n_samples``).
    """
    argv = list(sys.argv[1:] if args is None else args)
    if {"-h", "--help"} & set(_user_args(argv)):
        print_help(prog, summary, params)
        return 0
    rclpy.init(args=[prog, *argv])
    node: Node | None = None
    code = 0
    try:
        try:
            node = make_node()
        except (ConfigError, RobotModelError, WireError, ValueError) as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 2
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        node.get_logger().info(f"{prog} running (namespace '{node.get_namespace()}')")
        while rclpy.ok():
            try:
                executor.spin_once(timeout_sec=0.1)
            except Exception:
                # A signal between ok() and spin_once() invalidates the context: that is a
                # shutdown, not an error. Anything else is re-raised.
                if rclpy.ok():
                    raise
                break
            if spin_until is not None and spin_until(node):
                code = getattr(node, "exit_code", 0)
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            closer = getattr(node, "close", None)
            if callable(closer):
                closer()
            node.destroy_node()
        rclpy.try_shutdown()
    return code


def finite(values: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(values)))
