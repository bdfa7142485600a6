"""The plant node's arm from its parameters (apc_plant_sim.true_arm) and the feedforward's
first move from its parameters (GoalQueue.from_params), no ROS graph: a bad value names its
parameter; a payload picked up mid-motion comes on at its sample."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from apc_core.params import ConfigError
from apc_core.robot import load_robot
from apc_feedforward.goals import MOVE_PARAMS, GoalQueue
from apc_plant_sim.true_arm import TRUE_ARM_PARAMS, TrueArm

URDF = Path(__file__).resolve().parents[1] / "config" / "puma560_3dof.urdf"


@pytest.fixture(scope="module")
def robot():
    return load_robot(URDF)


def defaults(params, **changes):
    values = {p.name: p.default for p in params}
    values["period"] = 0.01
    values.update({k.replace("__", "."): v for k, v in changes.items()})
    return values


def test_the_defaults_build_an_arm_at_zero_without_payload(robot):
    arm = TrueArm.from_params(robot, defaults(TRUE_ARM_PARAMS))
    assert arm.pickup_k == 0 and not arm.pick_up()
    assert_array_equal(arm.plant.q, np.zeros(3))
    assert arm.plant.config.step == 0.0025 and arm.plant.config.forward_dynamics == "aba"


@pytest.mark.parametrize(
    ("changes", "parameter"),
    [
        ({"step": 0.003}, "step"),  # does not divide the period
        ({"forward_dynamics": "euler"}, "forward_dynamics"),
        ({"q_initial_deg": [0.0]}, "q_initial_deg"),
        ({"payload__frame": "nope", "payload__mass_kg": 1.0}, "payload.frame"),
        ({"payload__com_m": [0.0, 0.0]}, "payload.com_m"),
    ],
)
def test_a_bad_arm_parameter_is_named(robot, changes, parameter):
    with pytest.raises(ConfigError, match=f"parameter '{parameter}'"):
        TrueArm.from_params(robot, defaults(TRUE_ARM_PARAMS, **changes))


def test_a_payload_picked_up_mid_motion_comes_on_at_its_sample(robot):
    values = defaults(TRUE_ARM_PARAMS, payload__mass_kg=2.0, payload__at_s=0.03)
    arm = TrueArm.from_params(robot, values)
    assert arm.pickup_k == 3
    unloaded = arm.plant.robot
    for _ in range(3):
        assert not arm.pick_up()
        arm.plant.step(np.zeros(3))
    assert arm.pick_up() and arm.plant.robot is arm.loaded and arm.loaded is not unloaded
    arm.plant.step(np.zeros(3))
    assert not arm.pick_up()


def test_a_payload_from_the_start_is_carried_at_once(robot):
    arm = TrueArm.from_params(robot, defaults(TRUE_ARM_PARAMS, payload__mass_kg=2.0))
    assert arm.pickup_k == 0 and arm.plant.robot is arm.loaded


def test_the_first_move_comes_from_its_parameters(robot):
    queue = GoalQueue.from_params(robot, defaults(MOVE_PARAMS, move__goal_deg=[10.0, 0.0, 0.0]))
    assert_array_equal(queue.first_goal, np.deg2rad([10.0, 0.0, 0.0]))
    assert queue.move == {"segment_times": (0.2, 0.6, 0.2), "lift_off": 0.1, "set_down": 0.9}
    assert GoalQueue.from_params(robot, defaults(MOVE_PARAMS)).first_goal is None


@pytest.mark.parametrize(
    ("changes", "parameter"),
    [
        ({"move__goal_deg": [1.0, 2.0]}, "move.goal_deg"),
        ({"move__segment_times": [0.2, 0.6]}, "move.segment_times"),
        ({"move__segment_times": [0.2, 0.0, 0.2]}, "move.segment_times"),
    ],
)
def test_a_bad_move_parameter_is_named(robot, changes, parameter):
    with pytest.raises(ConfigError, match=f"parameter '{parameter}'"):
        GoalQueue.from_params(robot, defaults(MOVE_PARAMS, **changes))
