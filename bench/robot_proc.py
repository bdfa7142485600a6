"""One benchmark process of the robot path: ``robot_sim`` or apc's controllers, probed.

Started by ``bench/robot_loop.py``; not meant to be run by hand.

    robot_proc.py --role {robot_sim,robot_node} --params FILE.yaml
                  [-p NAME:=VALUE ...] --out RESULT.json [--started FILE]

Each role runs one node. Parameters come from the ROS parameters file and ``-p`` overrides, as
on the command line. The spin loop is ``run_node``'s
(``spin_once`` on ``nodeutil.make_executor``, the events executor).

Measured without touching ``src/``, through public attributes:

- ``robot_sim``: every command its driver takes (``driver.offer``: the data and the driver's
  clock at arrival) and every driver cycle (``driver.advance``: its time, and whether the
  driver's ``held_command_cycles`` counter went up, i.e. no command arrived since the
  previous cycle). ``--started`` is written at the first command.
- ``robot_node``: configured at start and activated once a joint state has arrived,
  ``--activation-phase`` seconds after a joint state's stamp (where in the driver's cycle
  activation falls; samples are taken on the states' arrival whatever it is). For every
  command ``robot_node`` publishes: the data, the stamp of the joint state its sample was
  taken from (``loop.sampler.last``), the time
  that state was sampled (its arrival) and the publish time (all on the node clock, the system
  clock here, as the driver's); and the largest deviation of a sampled position from the
  first (the arm holds its start pose).

At SIGINT the process writes what it noted to ``--out``; ``robot_loop.py`` matches commands to
their joint states by their data (bit-exact floats across DDS).
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


class DriverProbe:
    """Arrival time and data of each command, time and held flag of each driver cycle."""

    def __init__(self, sim: Any) -> None:
        driver = sim.driver
        self.driver = driver
        self.commands: list[tuple[list[float], float]] = []
        self.cycles: list[tuple[float, bool]] = []
        offer, advance = driver.offer, driver.advance

        def timed_offer(data: Any, now: float) -> str | None:
            self.commands.append((list(data), now))
            return offer(data, now)

        def timed_advance(now: float) -> Any:
            held = driver.counts.held_command_cycles
            applied = advance(now)
            self.cycles.append((now, driver.counts.held_command_cycles > held))
            return applied

        driver.offer = timed_offer
        driver.advance = timed_advance

    def dump(self) -> dict[str, Any]:
        counts = self.driver.counts
        return {
            "commands": self.commands,
            "cycles": self.cycles,
            "counts": {k: v for k, v in vars(counts).items() if isinstance(v, int)},
        }


class CommandProbe:
    """For each command ``robot_node`` publishes: data, state stamp, tick and publish time."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.sent: list[tuple[list[float], int, int, int]] = []
        self._state_ns = -1
        self._tick_ns = -1
        self._first_position: Any = None
        self.max_deviation_rad = 0.0  # of a sampled position from the first (the arm holds)
        loop = node.loop
        on_joint_state, publish = loop.on_joint_state, node._publish

        def timed_on_joint_state(state: Any, now_ns: int, newest_ns: int | None = None) -> Any:
            step = on_joint_state(state, now_ns, newest_ns)
            if step.sample is not None:  # sampled on the state's arrival
                self._state_ns, self._tick_ns = loop.sampler.last.state_ns, now_ns
                position = step.sample.position
                if self._first_position is None:
                    self._first_position = position.copy()
                deviation = float(abs(position - self._first_position).max())
                self.max_deviation_rad = max(self.max_deviation_rad, deviation)
            return step

        def timed_publish(step: Any) -> None:
            publish(step)
            if step.command is not None:
                now_ns = node.get_clock().now().nanoseconds
                self.sent.append((step.command.tolist(), self._state_ns, self._tick_ns, now_ns))

        loop.on_joint_state = timed_on_joint_state
        node._publish = timed_publish

    def dump(self) -> dict[str, Any]:
        return {
            "sent": self.sent,
            "counters": dict(self.node.diagnostics.counters),
            "max_deviation_rad": self.max_deviation_rad,
        }


def _activate(node: Any, phase_s: float) -> bool:
    """Activate ``node`` once a joint state is in, at ``phase_s`` after a joint state's stamp.
    True once done."""
    newest = node.loop.sampler.newest
    if newest is None:
        return False
    period_ns = node.loop.period_ns
    target = newest.stamp_ns + round(phase_s * 1e9)
    while target < node.get_clock().now().nanoseconds + 100_000:  # 0.1 ms to wait exactly
        target += period_ns
    while (left := target - node.get_clock().now().nanoseconds) > 0:
        time.sleep(min(left * 1e-9, 1e-4))
    node.trigger_activate()
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--role", required=True, choices=("robot_sim", "robot_node"))
    parser.add_argument("--params", required=True, help="ROS parameters file (YAML)")
    parser.add_argument("-p", action="append", default=[], help="NAME:=VALUE override")
    parser.add_argument("--out", required=True)
    parser.add_argument("--started")
    parser.add_argument(
        "--activation-phase",
        type=float,
        default=0.0,
        help="activate robot_node this many seconds after the stamp of a joint state (its "
        "samples are taken on the states' arrival whatever it is)",
    )
    args = parser.parse_args(argv)

    from apc_core.nodeutil import (
        destroy_nodes,
        leave_sigint_to_rclpy,
        make_executor,
        spin_once_or_stop,
    )
    from apc_feedback.robot_node import RobotNode
    from apc_plant_sim.robot_sim import RobotSimNode

    cli = ["--ros-args", "--params-file", args.params]
    for item in args.p:
        cli += ["-p", item]
    leave_sigint_to_rclpy()  # as apc's executables do (apc_core.nodeutil.run_nodes)
    rclpy.init(args=["robot_proc"])
    context = rclpy.get_default_context()
    nodes: list[Any] = []
    probe: DriverProbe | CommandProbe | None = None
    executor = None
    started = False
    activated = False
    try:
        if args.role == "robot_sim":
            sim = RobotSimNode(cli_args=cli)
            probe = DriverProbe(sim)
            nodes.append(sim)
        if args.role == "robot_node":
            # Configured here, activated below at the phase asked for.
            robot = RobotNode(cli_args=[*cli, "-p", "robot_node:autostart:=false"])
            robot.trigger_configure()
            probe = CommandProbe(robot)
            nodes.append(robot)
        executor = make_executor("events", context)
        for node in nodes:
            executor.add_node(node)
        while spin_once_or_stop(executor):
            if isinstance(probe, CommandProbe) and not activated:
                activated = _activate(probe.node, args.activation_phase)
            if not started and args.started and isinstance(probe, DriverProbe):
                if probe.driver.has_command:
                    Path(args.started).write_text(f"{time.monotonic()}\n")
                    started = True
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        Path(args.out).write_text(json.dumps(probe.dump() if probe is not None else {}))
        destroy_nodes(nodes, executor=executor)
    return 0


if __name__ == "__main__":
    sys.exit(main())
