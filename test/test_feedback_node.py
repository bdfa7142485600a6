"""The feedback node's wiring, without a ROS graph: its callbacks are called directly with
messages and what it would publish is recorded, so every verdict of the sample pairer is checked
to reach its counter or its publisher, and every run-time setting rule its answer.

The rules themselves are unit-tested on the plain classes (``test_sampling.py``,
``test_controller.py``); ``test_faults_input.py`` keeps end-to-end checks over DDS.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import rclpy
from rclpy.parameter import Parameter
from support.nodes import counter, overrides

import apc_msgs_py as wire
from apc_core.params import ConfigError
from apc_core.robot_params import CONTROLLER_ROBOT_PARAMS, controller_robot_from_params
from apc_feedback.node import FeedbackNode
from apc_lab.experiment import RunSpec
from apc_lab.scenario import paper_scenario

pytestmark = pytest.mark.ros

T = 10_000_000


class Recorder:
    """Stands in for a publisher: keeps what is published, reports one listener."""

    def __init__(self) -> None:
        self.sent: list = []

    def publish(self, msg) -> None:
        self.sent.append(msg)

    def get_subscription_count(self) -> int:
        return 1


@pytest.fixture(scope="module")
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


@pytest.fixture
def node_of(context):
    made = []

    def make(controller: str, **values) -> FeedbackNode:
        params = {**RunSpec(paper_scenario("a"), controller).node_parameters()["feedback_node"]}
        params.update(values)
        node = FeedbackNode(context=context, parameter_overrides=overrides(params))
        made.append(node)
        node.torque_pub, node.estimate_pub = Recorder(), Recorder()
        return node

    yield make
    for node in made:
        node.destroy_node()


def joint_state(node, stamp: int, q, qd=None) -> None:
    qd = np.zeros(len(q)) if qd is None else qd
    msg = wire.arrays_to_joint_state(stamp, node.joint_names, q, velocity=qd)
    node._on_joint_state(msg)


def setpoint(node, stamp: int, q_d) -> None:
    zero = np.zeros(len(q_d))
    node._on_setpoint(wire.setpoint_to_msg(stamp, node.joint_names, q_d, zero, zero, zero, 0))


def torques(node) -> list[np.ndarray]:
    return [wire.msg_to_torque(m, node.joint_names).effort for m in node.torque_pub.sent]


def test_every_verdict_reaches_its_counter_or_publisher(node_of):
    fb = node_of("pd")
    q_d, e = np.array([0.1, -0.2, 0.3]), np.array([0.01, -0.02, 0.03])
    joint_state(fb, 0, q_d - e)
    joint_state(fb, 0, q_d + e)  # the first one stands
    assert counter(fb, "duplicate.joint_states") == 1 and not fb.torque_pub.sent
    setpoint(fb, 0, q_d)
    np.testing.assert_array_equal(
        torques(fb), [100.0 * (q_d - (q_d - e))]
    )  # Kp (q_d - q), first state
    joint_state(fb, T, q_d)
    setpoint(fb, T, q_d)
    assert len(fb.torque_pub.sent) == 2 and counter(fb, "samples") == 2
    setpoint(fb, 0, q_d)  # copies of set points used: the feedforward answering a resend
    setpoint(fb, T, q_d)
    assert counter(fb, "resent.feedforward/setpoint") == 2
    setpoint(fb, T, q_d + e)
    assert counter(fb, "duplicate.feedforward/setpoint") == 1
    setpoint(fb, 0, q_d + e)
    setpoint(fb, T // 2, q_d)
    assert counter(fb, "rejected.feedforward/setpoint") == 2
    joint_state(fb, T, q_d + e)  # a resend: answered with the torque already published
    assert counter(fb, "resent") == 1
    assert len(fb.torque_pub.sent) == 3 and fb.torque_pub.sent[2] is fb.torque_pub.sent[1]
    for stamp in (0, -T, T + 1):
        joint_state(fb, stamp, q_d)
    assert counter(fb, "rejected.joint_states") == 3
    assert counter(fb, "rejected") == 5 and counter(fb, "callback_errors") == 0
    assert len(fb.torque_pub.sent) == 3


def test_a_failed_law_step_publishes_nothing_and_is_not_run_again(node_of):
    fb = node_of("pd", **{"gains.kp": 1e9})  # du beyond the wire's bound
    q_d = np.array([0.1, -0.2, 0.3])
    joint_state(fb, 0, q_d - 0.5)
    setpoint(fb, 0, q_d)
    assert counter(fb, "rejected.feedback_law") == 1 and not fb.torque_pub.sent
    joint_state(fb, 0, q_d - 0.5)  # its resend: nothing to answer with, the law is not run
    assert counter(fb, "resent") == 1 and counter(fb, "rejected.feedback_law") == 1
    assert not fb.torque_pub.sent


def test_adaptive_law_publishes_its_estimate_and_answers_a_resend_with_both(node_of):
    fb = node_of("adaptive")
    q_d = np.array([0.1, -0.2, 0.3])
    for k in (0, 1):
        joint_state(fb, k * T, q_d + 1e-3)
        setpoint(fb, k * T, q_d)
    assert len(fb.torque_pub.sent) == len(fb.estimate_pub.sent) == 2
    joint_state(fb, T, q_d)
    assert len(fb.torque_pub.sent) == len(fb.estimate_pub.sent) == 3
    assert "trace_p" in fb.diagnostics.values


def set_params(fb, *params: Parameter):
    return fb._on_set_parameters(list(params))


@pytest.mark.parametrize(
    ("controller", "name", "value", "why"),
    [
        ("pd", "gains.kp", "fast", "must be a number"),
        ("pd", "gains.kv", True, "must be a number"),
        ("pd", "gains.kv", [1.0, 2.0], "must be a number"),
        ("pd", "gains.kp", -1.0, "out of range"),
        ("pd", "gains.kp", math.nan, "out of range"),
        ("pd", "adaptive.r", 1.0, "not used by controller 'pd'"),
        ("none", "gains.kp", 1.0, "not used by controller 'none'"),
        ("adaptive", "adaptive.r", 0.0, "out of range"),
        ("adaptive", "adaptive.q_velocity", "x", "must be a number"),
        ("adaptive", "gains.kp", 50.0, "not used by controller 'adaptive'"),
    ],
)
def test_run_time_settings_are_refused_with_the_parameter_named(
    node_of, controller, name, value, why
):
    result = set_params(node_of(controller), Parameter(name, value=value))
    assert not result.successful
    assert result.reason.startswith(f"parameter '{name}': ") and why in result.reason


def test_run_time_settings_apply_at_the_next_sample_all_or_none(node_of):
    fb = node_of("pd")
    q_d, e = np.array([0.2, -0.3, 0.4]), np.array([0.01, -0.02, 0.005])
    assert set_params(fb, Parameter("gains.kp", value=200)).successful  # an integer is fine
    assert fb.law.gains.kp == 100.0  # not before the next sample
    refused = set_params(fb, Parameter("gains.kv", value=5.0), Parameter("gains.kp", value=-1.0))
    assert not refused.successful and "gains.kp" in refused.reason
    assert set_params(fb, Parameter("use_sim_time", value=False)).successful  # not ours
    joint_state(fb, 0, q_d - e)
    setpoint(fb, 0, q_d)
    np.testing.assert_array_equal(torques(fb), [200.0 * (q_d - (q_d - e))])
    assert (fb.law.gains.kp, fb.law.gains.kv) == (200.0, 20.0)  # kv of the refused set: no
    assert isinstance(fb.law.gains.kp, float)
    assert counter(fb, "parameter_updates") == 1


@pytest.mark.parametrize(
    ("error", "words"), [([0.1], "needs 3 values"), ([-1.0, 0.0, 0.0], "> -1")]
)
def test_the_controllers_robot_names_a_bad_inertia_error(error, words):
    values = {p.name: p.default for p in CONTROLLER_ROBOT_PARAMS}
    assert controller_robot_from_params(values).n_joints == 3  # empty: the URDF as is
    with pytest.raises(ConfigError, match=words) as info:
        controller_robot_from_params({**values, "inertia_error": error})
    assert str(info.value).startswith("parameter 'inertia_error': ")


@pytest.mark.parametrize(
    ("armature", "words"), [([0.1], "needs 3 values"), ([0.1, -1.0, 0.0], ">= 0")]
)
def test_the_controllers_robot_names_a_bad_armature(armature, words):
    values = {p.name: p.default for p in CONTROLLER_ROBOT_PARAMS}
    with pytest.raises(ConfigError, match=words) as info:
        controller_robot_from_params({**values, "armature": armature})
    assert str(info.value).startswith("parameter 'armature': ")


def test_the_controllers_robot_carries_the_armature_and_the_inertia_error():
    values = {p.name: p.default for p in CONTROLLER_ROBOT_PARAMS}
    robot = controller_robot_from_params(
        {**values, "armature": [0.2, 0.3, 0.4], "inertia_error": [0.1, -0.1, 0.1]}
    )
    np.testing.assert_array_equal(robot.model.armature, [0.2, 0.3, 0.4])
    plain = controller_robot_from_params({**values, "inertia_error": [0.1, -0.1, 0.1]})
    np.testing.assert_array_equal(robot.model.inertias[2].inertia, plain.model.inertias[2].inertia)


@pytest.mark.parametrize("name", ["friction", "damping"])
def test_the_controllers_robot_carries_its_friction_and_names_a_bad_one(name):
    values = {p.name: p.default for p in CONTROLLER_ROBOT_PARAMS}
    robot = controller_robot_from_params({**values, name: [1.0, 2.0, 0.5]})
    np.testing.assert_array_equal(getattr(robot.model, name), [1.0, 2.0, 0.5])  # Pinocchio's
    plain = controller_robot_from_params(values)
    np.testing.assert_array_equal(getattr(plain.model, name), np.zeros(3))  # empty: none
    for bad, words in (([0.1], "needs 3 values"), ([0.1, -1.0, 0.0], ">= 0")):
        with pytest.raises(ConfigError, match=words) as info:
            controller_robot_from_params({**values, name: bad})
        assert str(info.value).startswith(f"parameter '{name}': ")


def test_pid_takes_its_parameter_family(node_of):
    fb = node_of("pid", **{"pid.bandwidth": 8.0, "pid.i_clamp": [1.0, 2.0, 3.0]})
    assert fb.law.requested.bandwidth == 8.0 and fb.law.requested.i_clamp == (1.0, 2.0, 3.0)
    q_d = np.array([0.1, -0.2, 0.3])
    joint_state(fb, 0, q_d - 0.01)
    setpoint(fb, 0, q_d)
    assert len(fb.torque_pub.sent) == 1 and counter(fb, "rejected") == 0


def test_pid_gains_given_in_part_name_the_missing_one(node_of):
    with pytest.raises(ConfigError, match=r"^parameter 'pid\.i': pid gains p, i and d"):
        node_of("pid", **{"pid.p": [1.0, 1.0, 1.0], "pid.d": [1.0, 1.0, 1.0]})
