"""The Franka Panda's move with 5 lb its controllers do not know, on a 100 Hz driver: robot
mode's loop closed offline in simulated time (:func:`apc_lab.robot_offline.run_robot_loop`),
the driver's cycles 3.7 ms after a multiple of T, states 0.3 ms on their way; case (c)'s move
after a 0.2 s hold, the grid's 10 % inertia error."""

from __future__ import annotations

from typing import Any

from apc_lab.robot_compare import arm_scenario
from apc_lab.robot_offline import RobotRun, run_robot_loop

PANDA = arm_scenario("panda", "c")


def panda_100hz_move(duration_s: float = 2.5, **options: Any) -> RobotRun:
    """The move; ``options`` go to ``run_robot_loop`` (the payload, the arm, the effects, the
    driver's period, the supervisor, the settings...), over the defaults above."""
    defaults: dict[str, Any] = {
        "goal_deg": PANDA.q_goal_deg,
        "driver_ms": 10.0,
        "phase_ms": 3.7,
        "transport_ms": 0.3,
        "payload_kg": PANDA.payload_kg,
        "arm": PANDA,
    }
    return run_robot_loop(duration_s, **{**defaults, **options})


def physical_panda_move(duration_s: float, driver_ms: float, **options: Any) -> RobotRun:
    """The move on the Panda in MuJoCo with every effect of ``robot_sim``'s ``effects: panda``
    (its controllers told what the benchmarks tell them), on a driver of ``driver_ms`` whose
    cycles are 0.37 of a period after a multiple of T (the offline grid's); ``options`` go to
    ``run_robot_loop``."""
    from apc_lab.robot_compare import ARM_EFFECTS, controller_armature

    defaults: dict[str, Any] = {
        "phase_ms": 0.37 * driver_ms,
        "effects": ARM_EFFECTS["panda"](),
        "armature": controller_armature("panda", "physical"),
    }
    return panda_100hz_move(duration_s, driver_ms=driver_ms, **{**defaults, **options})
