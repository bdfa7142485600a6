"""apc's topics: names, message types and QoS, as the table every node and the recorder use.

Names are relative, so a namespace such as ``/puma`` moves a whole arm; the clock and the
diagnostics are global.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, String
from trajectory_msgs.msg import JointTrajectory

#: plant -> all: ``q``, ``q̇`` at sample k; ``effort`` = torque applied over the period ending at k.
JOINT_STATES = "joint_states"
#: feedforward -> feedback, recorder: the planned set point of sample k (one-point trajectory);
#: in robot mode robot_node's plan, for observers.
SETPOINT = "feedforward/setpoint"
#: feedforward -> plant: the nominal torque ``u_n(k)`` (JointState, name + effort only).
FEEDFORWARD_TORQUE = "feedforward/torque"
#: feedback -> plant: the perturbation torque ``δu(k)`` (JointState, name + effort only).
FEEDBACK_TORQUE = "feedback/torque"
#: feedback -> recorder: identification telemetry (see :func:`estimate_to_msg`).
ESTIMATE = "feedback/estimate"
#: user -> feedforward (robot mode: robot_node, whose plan it is): a new goal (waypoints).
TRAJECTORY_GOAL = "feedforward/trajectory"
#: robot mode, robot_node -> observers: the sample k it took from a driver's joint states,
#: stamped ``kT`` (JointState: position, velocity): what the law measured.
SAMPLE = "feedback/sample"
#: plant -> recorder, viewers: the arm's URDF (``std_msgs/String``), as robot_state_publisher
#: publishes it, so a recording explains itself (its joints' kinematics, a viewer's model).
ROBOT_DESCRIPTION = "robot_description"
#: plant -> all: simulation time in lockstep mode (absolute: there is one clock per ROS graph).
CLOCK = "/clock"
#: every node -> monitors: loop timing, late/missing inputs, rejected messages, RLS health.
DIAGNOSTICS = "/diagnostics"

#: Most samples a feedforward may publish ahead of the joint state it answers; the plant refuses
#: a nominal torque stamped further ahead than this (no plan runs that far ahead of the arm).
MAX_LOOKAHEAD = 8

#: Control-loop topics (joint states, set point, both torques, estimate): RELIABLE, KEEP_LAST 10,
#: VOLATILE. Lockstep must not lose a sample (the plant waits for both torques of sample k, a
#: dropped one would stall it), so best effort is out. Depth 10 absorbs a short stall of a
#: subscriber without dropping (lockstep has at most one sample in flight; real time ~100 ms).
#: VOLATILE: an old control sample is meaningless to a late joiner.
CONTROL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: History a control topic's writer keeps (the nodes' readers keep :data:`CONTROL_QOS`'s 10).
#: Discovery matches a writer and a reader in two handshakes, each side in its own time: on a
#: loaded machine the reader's side can come tens of ms after the writer's, while the writer is
#: already publishing to it (the plant starts once it counts its subscribers: the writer's
#: side). Once both sides match, the writer repairs what the reader dropped meanwhile, from its
#: history: a reader matched ``m`` samples late gets them all while ``m`` is below this depth
#: (about a second of lockstep, 10 s at 100 Hz); with a depth of 10 it would get samples
#: ``m - 10`` on.
CONTROL_WRITER_DEPTH = 1000


def with_depth(qos: QoSProfile, depth: int) -> QoSProfile:
    """A copy of ``qos`` with a KEEP_LAST history at least ``depth`` deep; every other policy
    as it is."""
    deeper = copy.copy(qos)
    deeper.history = HistoryPolicy.KEEP_LAST
    deeper.depth = max(qos.depth, depth)
    return deeper


def writer_qos(qos: QoSProfile) -> QoSProfile:
    """``qos`` for a control topic's writer: a RELIABLE one with at least
    :data:`CONTROL_WRITER_DEPTH` of KEEP_LAST history (see there); a best-effort or KEEP_ALL
    one as it is."""
    if qos.reliability != ReliabilityPolicy.RELIABLE or qos.history != HistoryPolicy.KEEP_LAST:
        return qos
    return with_depth(qos, CONTROL_WRITER_DEPTH)


#: ``/clock``: KEEP_LAST 1, BEST_EFFORT, VOLATILE -- what rclpy's ``TimeSource`` subscribes with
#: (and ``rclcpp::ClockQoS``). Only the newest time matters; lockstep does not depend on the clock
#: arriving (samples are matched by their stamps), a dropped clock message only delays ``now()``.
#: A RELIABLE publisher would also match this subscriber; BEST_EFFORT keeps the plant from ever
#: blocking on a slow clock subscriber.
CLOCK_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.BEST_EFFORT,
    durability=DurabilityPolicy.VOLATILE,
)
#: Trajectory goals: RELIABLE, KEEP_LAST 10, VOLATILE. A goal must not be lost, but it must NOT be
#: TRANSIENT_LOCAL: a node that (re)starts late would receive the last goal again and replay an
#: old motion. A goal is an event, not a state.
TRAJECTORY_GOAL_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
#: ``robot_description``: RELIABLE, KEEP_LAST 1, TRANSIENT_LOCAL, what robot_state_publisher
#: offers: a node or a recorder that starts later still gets the arm's description.
ROBOT_DESCRIPTION_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)
#: ``/diagnostics``: the ROS default profile (RELIABLE, KEEP_LAST 10, VOLATILE), what
#: ``diagnostic_updater`` and ``diagnostic_aggregator`` use, so standard tools match.
DIAGNOSTICS_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


@dataclass(frozen=True)
class TopicSpec:
    """One row of the wire table: what is published on ``name``, and with which QoS.

    Attributes
    ----------
    name : str
        Topic name (relative unless it starts with ``/``).
    msg_type : type
        The rclpy message class.
    qos : rclpy.qos.QoSProfile
        The profile publishers offer and subscribers request.
    """

    name: str
    msg_type: type
    qos: QoSProfile

    @property
    def type_name(self) -> str:
        """The ROS type name, e.g. ``"sensor_msgs/msg/JointState"``."""
        pkg = self.msg_type.__module__.split(".")[0]
        return f"{pkg}/msg/{self.msg_type.__name__}"


#: The whole wire, in the order of the design table; the recorder records all of it.
TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec(JOINT_STATES, JointState, CONTROL_QOS),
    TopicSpec(SETPOINT, JointTrajectory, CONTROL_QOS),
    TopicSpec(FEEDFORWARD_TORQUE, JointState, CONTROL_QOS),
    TopicSpec(FEEDBACK_TORQUE, JointState, CONTROL_QOS),
    TopicSpec(ESTIMATE, Float64MultiArray, CONTROL_QOS),
    TopicSpec(TRAJECTORY_GOAL, JointTrajectory, TRAJECTORY_GOAL_QOS),
    TopicSpec(SAMPLE, JointState, CONTROL_QOS),
    TopicSpec(ROBOT_DESCRIPTION, String, ROBOT_DESCRIPTION_QOS),
    TopicSpec(CLOCK, Clock, CLOCK_QOS),
    TopicSpec(DIAGNOSTICS, DiagnosticArray, DIAGNOSTICS_QOS),
)


def topic_spec(name: str) -> TopicSpec:
    """Return the :data:`TOPICS` row of topic ``name``.

    Raises
    ------
    KeyError
        If ``name`` is not one of apc's topics.
    """
    for spec in TOPICS:
        if spec.name == name:
            return spec
    raise KeyError(f"{name!r} is not an apc topic; known: {[s.name for s in TOPICS]}")
