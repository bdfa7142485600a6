"""``experiment``: run one trajectory through the real nodes and record it, without launch files.

Starts plant, feedforward, feedback and recorder in one process on one executor (default), or
the three control nodes as separate processes (``--processes``) with the recorder here; runs
the move and its hold; writes ``<out>/<run>.mcap``; prints progress and a one-line summary;
exits non-zero on failure. Defaults: the paper's 3-joint PUMA 560, the 4-3-4 move of its
simulation study and +-10 % inertia error in the controllers (another arm's ``--urdf`` gets
them derived from its URDF, printed), the recommended adaptive preset, lockstep timing.

    experiment --case c --controller adaptive --preset paper --alpha 150000 --out runs
    experiment --case a --controller computed_torque --mode realtime --processes
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
import yaml
from rclpy.executors import ExternalShutdownException
from rclpy.parameter import Parameter

import apc_msgs_py as wire
from apc_core.nodeutil import EXECUTORS, StopSignals, destroy_nodes, make_executor
from apc_core.params import ConfigError, params_from
from apc_feedback.laws import CONTROLLER_KINDS, LAWS
from apc_feedback.presets import DEFAULT_PRESET
from apc_lab.run_recorder import (
    drain,
    recorder_hears_controllers,
    recorder_node,
    take_what_is_queued,
    wait_for_resends,
)
from apc_lab.scenario import (
    PAPER_CASES,
    PRESETS,
    Scenario,
    for_urdf,
    paper_scenario,
)


def law_parameters(controller: str, settings: Mapping[str, Any] | None) -> dict[str, Any]:
    """The feedback law's node parameters, as ``feedback_node`` (and ``robot_node``) declare
    them: ``controller`` and every setting of the law, from ``settings`` or else its settings
    dataclass's default, which is what :func:`make_law` takes offline, so a node run does not
    depend on the node's preset."""
    settings = dict(settings or {})
    law = LAWS.get(controller)
    values: dict[str, Any] = {"controller": controller}
    if law is None or law.settings is None:
        if settings:
            raise ValueError(f"controller {controller!r} takes no settings, got {sorted(settings)}")
        return values
    for row in params_from(law.settings, law.family):
        key = row.name[len(law.family) :]
        value = settings.pop(key, row.default)
        if isinstance(value, (list, tuple)):
            if not value:
                continue  # an empty array override would reach rclpy untyped; the default is []
            value = [float(v) for v in value]
        values[row.name] = type(row.default)(value) if isinstance(row.default, float) else value
    if settings:
        # An override of an undeclared parameter would be dropped silently by rclpy.
        raise ValueError(f"setting '{sorted(settings)[0]}' is not a parameter of feedback_node")
    return values


@dataclass(frozen=True)
class RunSpec:
    """One experiment run: the scenario, the feedback law and its settings, the timing mode."""

    scenario: Scenario
    controller: str = "adaptive"
    settings: Mapping[str, Any] | None = None
    mode: str = "lockstep"
    name: str = "run"

    def description(self) -> dict[str, Any]:
        """The run as a recording describes it (``custom_data['apc.run']``, what
        :func:`apc_recording.runs.load_run` reads back)."""
        return {
            "name": self.name,
            "controller": self.controller,
            "mode": self.mode,
            "settings": dict(self.settings or {}),
            "scenario": {
                k: list(v) if isinstance(v, tuple) else v
                for k, v in dataclasses.asdict(self.scenario).items()
            },
        }

    def node_parameters(self) -> dict[str, dict[str, Any]]:
        """ROS parameters of each node, keyed by node name (a ROS parameter-file layout)."""
        sc = self.scenario
        shared = {
            "robot_description_path": str(sc.urdf),
            "gravity": float(sc.gravity),
            "period": float(sc.period),
            "lock_joints": list(sc.lock_joints),
        }
        if not shared["lock_joints"]:
            del shared["lock_joints"]
        feedforward = {
            **shared,
            "inertia_error": [float(v) for v in sc.inertia_error],
            "move.goal_deg": [float(v) for v in sc.q_goal_deg],
            "move.segment_times": [float(v) for v in sc.segment_times],
            "move.lift_off": float(sc.lift_off),
            "move.set_down": float(sc.set_down),
        }
        feedback: dict[str, Any] = {
            **shared,
            "inertia_error": [float(v) for v in sc.inertia_error],
            **law_parameters(self.controller, self.settings),
        }
        plant = {
            **shared,
            "step": float(sc.step),
            "mode": self.mode,
            "payload.mass_kg": float(sc.payload_kg),
            "payload.frame": sc.payload_frame or "",
            "payload.com_m": [float(v) for v in sc.payload_com_m],
            "payload.at_s": float(sc.payload_at_s),
            "q_initial_deg": [float(v) for v in sc.q_start_deg],
            "n_samples": int(sc.n_samples),
            "wait_for_subscribers": 3,
        }
        return {"feedforward_node": feedforward, "feedback_node": feedback, "plant_node": plant}


def wait_for(executor: Any, condition: Any, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what} not discovered within {timeout_s} s")
        executor.spin_once(timeout_sec=0.02)


def overrides(values: Mapping[str, Any]) -> list[Parameter]:
    return [Parameter(name, value=value) for name, value in values.items()]


class Progress:
    """Progress on stderr: a one-line bar on a terminal, else one line per named step (a log
    or CI keeps one line per run, not a bar's redraws)."""

    def __init__(self, total: int, label: str, enabled: bool = True) -> None:
        self.total, self.label = max(total, 1), label
        self.tty = sys.stderr.isatty()
        self.enabled = enabled
        self._last = -1

    def update(self, k: int, name: str = "") -> None:
        """Step ``k`` (of ``total``) starts; ``name`` says what it is."""
        if not self.enabled:
            return
        if not self.tty:
            if name:
                print(f"{self.label} {k + 1}/{self.total}: {name}", file=sys.stderr, flush=True)
            return
        pct = min(100, int(100 * k / self.total))
        if pct != self._last:
            bar = "#" * (pct // 4)
            sys.stderr.write(f"\r{self.label} [{bar:<25}] {pct:3d}%")
            sys.stderr.flush()
            self._last = pct

    def close(self) -> None:
        if self.enabled and self.tty:
            sys.stderr.write("\n")


@dataclass
class RunOutcome:
    path: Path
    ok: bool
    message: str
    samples: int
    wall_s: float


def run_in_process(
    spec: RunSpec,
    out_dir: Path,
    *,
    progress: bool = True,
    timeout_s: float = 600.0,
    executor_kind: str = "events",
) -> RunOutcome:
    """Run the four nodes in this process on one executor (:func:`make_executor`).

    SIGINT and SIGTERM end the run between two ``spin_once`` calls (``StopSignals``: rclpy
    installs no handlers for a context of our own): the recording is finished, every node
    destroyed, and the outcome says ``interrupted``.
    """
    from apc_feedback.node import FeedbackNode
    from apc_feedforward.node import FeedforwardNode
    from apc_plant_sim.node import PlantNode

    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{spec.name}.mcap"
    params = spec.node_parameters()
    with StopSignals() as stop:
        context = rclpy.Context()
        rclpy.init(context=context)
        nodes = []
        plant = None
        executor = None
        t0 = time.monotonic()
        try:
            recorder = recorder_node(path, context, spec.description())
            nodes.append(recorder)
            nodes.append(
                FeedforwardNode(
                    context=context, parameter_overrides=overrides(params["feedforward_node"])
                )
            )
            nodes.append(
                FeedbackNode(
                    context=context, parameter_overrides=overrides(params["feedback_node"])
                )
            )
            executor = make_executor(executor_kind, context)
            for node in nodes:
                executor.add_node(node)
            wait_for(
                executor,
                lambda: stop.check() or recorder_hears_controllers(recorder, spec.controller),
                30.0,
                "the controllers' publishers",
            )
            # The plant comes last: it starts the run once everything listens
            # (wait_for_subscribers).
            plant = PlantNode(context=context, parameter_overrides=overrides(params["plant_node"]))
            nodes.append(plant)
            executor.add_node(plant)
            bar = Progress(plant.n_samples, spec.name, progress)
            while not plant.done and time.monotonic() - t0 < timeout_s:
                executor.spin_once(timeout_sec=0.05)
                stop.check()
                bar.update(plant.k)
            bar.close()
            drain(executor, recorder, plant.n_samples if plant.done else 0, stop)
            if not plant.done:
                return RunOutcome(
                    path, False, f"timed out after {timeout_s} s", plant.k, _since(t0)
                )
            ok = plant.exit_code == 0
            message = "ok" if ok else plant.diagnostics.message
            return RunOutcome(path, ok, message, plant.k, _since(t0))
        except (KeyboardInterrupt, ExternalShutdownException) as exc:
            samples = plant.k if plant is not None else 0
            if plant is not None and executor is not None and context.ok():
                executor.remove_node(plant)  # it publishes no more
                take_what_is_queued(executor, recorder)
            return RunOutcome(
                path, False, f"interrupted ({exc})".replace(" ()", ""), samples, _since(t0)
            )
        except TimeoutError as exc:
            return RunOutcome(path, False, str(exc), 0, _since(t0))
        finally:
            destroy_nodes(nodes, context, executor)


def run_in_processes(
    spec: RunSpec, out_dir: Path, *, progress: bool = True, timeout_s: float = 600.0
) -> RunOutcome:
    """Plant, feedforward and feedback as three processes; the recorder in this one.

    SIGINT and SIGTERM end the run between two ``spin_once`` calls: the children get SIGINT
    and are waited for (:func:`stop_processes`), the recording is finished, and the outcome
    says ``interrupted``. No child outlives the runner.
    """

    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{spec.name}.mcap"
    params = spec.node_parameters()
    modules = {
        "plant_node": "apc_plant_sim.node",
        "feedforward_node": "apc_feedforward.node",
        "feedback_node": "apc_feedback.node",
    }
    with StopSignals() as stop:
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as handle:
            yaml.safe_dump({k: {"ros__parameters": v} for k, v in params.items()}, handle)
            params_file = handle.name
        context = rclpy.Context()
        rclpy.init(context=context)
        procs: dict[str, subprocess.Popen] = {}
        recorder = None
        executor = None
        stop_s = 3.0  # per step of stop_processes; INTERRUPTED_STOP_S on a signal
        t0 = time.monotonic()

        def samples() -> int:
            return max(recorder.counts.get("/joint_states", 0) - 1, 0) if recorder else 0

        try:
            recorder = recorder_node(path, context, spec.description())
            executor = make_executor("events", context)
            executor.add_node(recorder)

            def start(name: str) -> None:
                stop.check()
                procs[name] = subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        modules[name],
                        "--ros-args",
                        "--params-file",
                        params_file,
                    ],
                    env=os.environ.copy(),
                )

            start("feedforward_node")
            start("feedback_node")
            wait_for(
                executor,
                lambda: stop.check() or recorder_hears_controllers(recorder, spec.controller),
                60.0,
                "the controllers' publishers",
            )
            start("plant_node")
            bar = Progress(spec.scenario.n_samples, spec.name, progress)
            plant = procs["plant_node"]
            while plant.poll() is None and time.monotonic() - t0 < timeout_s:
                executor.spin_once(timeout_sec=0.05)
                stop.check()
                bar.update(recorder.counts.get("/joint_states", 0))
                for name, proc in procs.items():
                    if name != "plant_node" and proc.poll() is not None:
                        return RunOutcome(
                            path,
                            False,
                            f"{name} exited with {proc.returncode}",
                            samples(),
                            _since(t0),
                        )
            bar.close()
            drain(executor, recorder, spec.scenario.n_samples if plant.poll() == 0 else 0, stop)
            code = plant.poll()
            if code is None:
                return RunOutcome(
                    path, False, f"timed out after {timeout_s} s", samples(), _since(t0)
                )
            return RunOutcome(
                path,
                code == 0,
                "ok" if code == 0 else f"plant_node exited with {code}",
                samples(),
                _since(t0),
            )
        except (KeyboardInterrupt, ExternalShutdownException) as exc:
            stop_s = INTERRUPTED_STOP_S
            plant = procs.get("plant_node")
            if plant is not None and recorder is not None and executor is not None:
                if context.ok():
                    # The recorder is on the plant's /clock: its time says how many samples
                    # the plant has published.
                    period_ns = wire.seconds_to_ns(spec.scenario.period)
                    published = recorder.get_clock().now().nanoseconds // period_ns
                    wait_for_resends(executor, recorder, lambda: plant.poll() is None, published)
                killed = stop_processes([plant], stop_s)  # it publishes no more
                _name_killed({"plant_node": plant}, killed, stop_s)
                if context.ok():
                    take_what_is_queued(executor, recorder)
            return RunOutcome(
                path, False, f"interrupted ({exc})".replace(" ()", ""), samples(), _since(t0)
            )
        except TimeoutError as exc:
            return RunOutcome(path, False, str(exc), samples(), _since(t0))
        finally:
            _name_killed(procs, stop_processes(procs.values(), stop_s), stop_s)
            destroy_nodes([recorder] if recorder is not None else [], context, executor)
            Path(params_file).unlink(missing_ok=True)


#: On a signal the runner gives each child this long per step of :func:`stop_processes`
#: (SIGINT, SIGTERM, then SIGKILL: 1 s in all), so that it ends within the 2 s it promises.
#: A child's teardown took 0.35 s at most in 1570 timed idle and under load (2026-11-29);
#: a node process whose teardown blocked in rclpy's ``destroy_node`` (the Fast DDS
#: participant's deletion) until its own 5 s limit (``apc_core.nodeutil``) was seen four
#: times in the signal tests, never reproduced in 800 rounds here, its native stack unknown,
#: and kept the runner 5.6 s. Once the plant has stopped the children hold nothing of the
#: run (the recording is the runner's); a child killed is named on stderr.
INTERRUPTED_STOP_S = 0.5


def _name_killed(
    procs: Mapping[str, subprocess.Popen], killed: list[subprocess.Popen], step_s: float
) -> None:
    for name, proc in procs.items():
        if proc in killed:
            print(
                f"experiment: {name} did not stop on SIGINT or SIGTERM within "
                f"{2 * step_s:g} s; killed",
                file=sys.stderr,
            )


def stop_processes(
    procs: Iterable[subprocess.Popen], timeout_s: float = 3.0
) -> list[subprocess.Popen]:
    """SIGINT, then SIGTERM, then SIGKILL, each with a timeout: every child ends, even a ROS
    process that ignores SIGTERM (one that raised inside a callback can, and one blocked in
    native code never runs the Python handler). The processes that took SIGKILL."""
    procs = list(procs)
    killed: list[subprocess.Popen] = []
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        alive = [p for p in procs if p.poll() is None]
        if not alive:
            return killed
        if sig == signal.SIGKILL:
            killed = alive
        for p in alive:
            try:
                p.send_signal(sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + timeout_s
        for p in alive:
            try:
                p.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
    return killed


def _since(t0: float) -> float:
    return time.monotonic() - t0


def summarize(path: Path) -> str:
    """One line: max and final |q - q_d| per joint (deg) read back from the recording."""
    from apc_recording.runs import load_run

    run = load_run(path)
    err = np.rad2deg(np.abs(run.q - run.q_d))
    end = run.move_end_index
    fmt = lambda a: "/".join(f"{v:.3f}" for v in a)  # noqa: E731
    return (
        f"{path.name}: {len(run.t)} samples, max |e| {fmt(err[: end + 1].max(axis=0))} deg, "
        f"final |e| {fmt(err[end])} deg, peak |tau| "
        f"{'/'.join(f'{v:.1f}' for v in np.nanmax(np.abs(run.applied), axis=0))} N m"
    )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="experiment", description=__doc__.split("\n\n")[0] if __doc__ else None
    )
    parser.add_argument("--case", choices=sorted(PAPER_CASES), default="c", help="paper load case")
    parser.add_argument("--controller", choices=CONTROLLER_KINDS, default="adaptive")
    parser.add_argument(
        "--alpha", type=float, default=1.5e5, help="P(0) = alpha I (paper: 1500, 150000)"
    )
    parser.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        default=DEFAULT_PRESET,
        help=f"adaptive settings (default {DEFAULT_PRESET}: measured to work; paper: as printed)",
    )
    parser.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    parser.add_argument(
        "--payload-at", type=float, default=0.0, help="payload appears at this time (s)"
    )
    parser.add_argument(
        "--urdf",
        help="arm URDF (default: the 3-joint PUMA 560 and the paper's move); the start pose, "
        "move, inertia error and payload frame are derived from it and printed",
    )
    parser.add_argument(
        "--lock-joints", nargs="+", default=[], help="URDF joints to freeze (e.g. a gripper's)"
    )
    parser.add_argument("--payload", type=float, help="payload mass (kg); overrides --case")
    parser.add_argument("--hold", type=float, default=0.5, help="hold after the move (s)")
    parser.add_argument("--scenario", help="YAML file of Scenario fields (overrides the case)")
    parser.add_argument("--out", default="runs", help="output directory")
    parser.add_argument("--name", help="run name (file stem); default from the settings")
    parser.add_argument("--processes", action="store_true", help="one process per control node")
    parser.add_argument(
        "--executor",
        choices=EXECUTORS,
        default="events",
        help="executor of the one-process run (events: rclpy's EventsExecutor)",
    )
    parser.add_argument("--timeout", type=float, default=600.0, help="wall-clock limit (s)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    return parser


def spec_from_args(args: argparse.Namespace) -> RunSpec:
    """The run the command line asks for. An arm given by ``--urdf`` (or in ``--scenario``)
    gets the per-joint values not given derived from its URDF, each printed in one line."""

    def tell(line: str) -> None:
        print(f"experiment: {line}", file=sys.stderr)

    overrides: dict[str, Any] = {"hold_s": args.hold}
    if args.lock_joints:
        overrides["lock_joints"] = tuple(args.lock_joints)
    if args.scenario:
        values = yaml.safe_load(Path(args.scenario).read_text()) or {}
        if args.urdf:
            values["urdf"] = args.urdf
        scenario = Scenario.from_dict({**values, **overrides}, report=tell)
    elif args.urdf:
        scenario = for_urdf(args.urdf, tell, payload_kg=PAPER_CASES[args.case], **overrides)
    else:
        scenario = paper_scenario(args.case, **overrides)
    if args.payload is not None:
        from dataclasses import replace

        scenario = replace(scenario, payload_kg=args.payload)
    if args.payload_at:
        from dataclasses import replace

        scenario = replace(scenario, payload_at_s=args.payload_at)
    settings = PRESETS[args.preset](args.alpha) if args.controller == "adaptive" else None
    name = args.name or (
        f"{args.controller}"
        + (f"_{args.preset}_alpha{args.alpha:g}" if args.controller == "adaptive" else "")
        + f"_{scenario.payload_kg:.3f}kg_{args.mode}"
    )
    return RunSpec(scenario, args.controller, settings, args.mode, name)


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        spec = spec_from_args(args)
    except (ValueError, OSError) as exc:
        print(f"experiment: {exc}", file=sys.stderr)
        return 2
    runner = run_in_processes if args.processes else run_in_process
    try:
        extra = {} if args.processes else {"executor_kind": args.executor}
        outcome = runner(
            spec, Path(args.out), progress=not args.quiet, timeout_s=args.timeout, **extra
        )
    except ConfigError as exc:
        print(f"experiment: {exc}", file=sys.stderr)
        return 2
    if not outcome.ok:
        print(
            f"experiment: FAILED ({outcome.message}) after {outcome.samples} samples",
            file=sys.stderr,
        )
        return 1
    print(f"{summarize(outcome.path)} [{outcome.wall_s:.1f} s wall]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
