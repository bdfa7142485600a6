"""The wire contract of apc: topic names, QoS, message <-> numpy conversion and validation.

What ``sensor_msgs_py`` is to ``sensor_msgs``, this package is to the messages apc exchanges.

Every node takes its topic names and QoS from here (no topic string literal in a ``node.py``),
and every message that crosses the wire goes through one of the converters below, so that a
malformed message is rejected at the border with a :class:`WireError` that names the field.
Callers use this package's names (``import apc_msgs_py as wire``; ``wire.JOINT_STATES``); its
modules each hold one job:

- :mod:`~apc_msgs_py.topics`: topic names, QoS profiles, :data:`TOPICS` (the table the
  recorder records);
- :mod:`~apc_msgs_py.stamps`: integer nanoseconds, ROS stamps and durations, the sample grid;
- :mod:`~apc_msgs_py.fields`: :class:`WireError` and the checks every converter applies;
- :mod:`~apc_msgs_py.joint_state`: ``JointState`` as joint states and torque commands;
- :mod:`~apc_msgs_py.joint_trajectory`: ``JointTrajectory`` as set points and goals;
- :mod:`~apc_msgs_py.estimate`: ``Float64MultiArray`` as the identification estimate.

Topics (relative, so a namespace such as ``/puma`` moves a whole arm; clock and diagnostics global)
---------------------------------------------------------------------------------------------------
- ``JOINT_STATES``: ``sensor_msgs/JointState``, :data:`CONTROL_QOS`
- ``SETPOINT``: ``trajectory_msgs/JointTrajectory`` with one point, :data:`CONTROL_QOS`
- ``FEEDFORWARD_TORQUE``, ``FEEDBACK_TORQUE``: ``sensor_msgs/JointState`` (name + effort),
  :data:`CONTROL_QOS`
- ``ESTIMATE``: ``std_msgs/Float64MultiArray`` (:func:`estimate_to_msg`), :data:`CONTROL_QOS`
- ``TRAJECTORY_GOAL``: ``trajectory_msgs/JointTrajectory``, :data:`TRAJECTORY_GOAL_QOS`
- ``SAMPLE`` (robot mode, for observers): ``sensor_msgs/JointState`` (position, velocity),
  :data:`CONTROL_QOS`
- ``ROBOT_DESCRIPTION``: ``std_msgs/String`` (URDF XML), :data:`ROBOT_DESCRIPTION_QOS`
- ``CLOCK`` (absolute): ``rosgraph_msgs/Clock``, :data:`CLOCK_QOS`
- ``DIAGNOSTICS`` (absolute): ``diagnostic_msgs/DiagnosticArray``, :data:`DIAGNOSTICS_QOS`

The control topics' writers keep a deeper history (:func:`writer_qos`,
:data:`CONTROL_WRITER_DEPTH`): a reader matched late on its side still gets the samples it
missed, up to that many.

Conventions
-----------
- Time is integer nanoseconds everywhere. Sample ``k`` is stamped ``k * T`` computed in integers
  (:func:`sample_stamp_ns`), so stamps are exact for any run length (no float drift).
- Joint order comes from ``name`` (``joint_names``), never from the position in the array: every
  reader reorders to the order the caller asks for.
- Units: positions rad (or m), velocities rad/s, accelerations rad/s², torques N·m (or N).
- A reading keeps the message's field names (``JointSample.effort``); past the border apc
  names a torque by what it is: ``applied`` for what ``joint_states(k).effort`` carries, the
  torque the arm applied over the period that ended at sample k; ``u_n`` and ``du`` for the two
  commands. ``theta_t`` is Θᵀ = [F G w] (the estimate), never Θ = [F G w]ᵀ of Eq. 22.
- Nothing non-finite is published or accepted: the writers raise :class:`WireError` rather than
  publish garbage, the readers raise it rather than hand garbage to a controller.
"""

from apc_msgs_py.estimate import (
    ESTIMATE_COLS_LABEL,
    ESTIMATE_ROWS_LABEL,
    ESTIMATE_TRAILER,
    Estimate,
    estimate_to_msg,
    msg_to_estimate,
    theta_t_to_estimate_msg,
)
from apc_msgs_py.fields import DEFAULT_MAX_ABS, WireError
from apc_msgs_py.joint_state import (
    JOINT_STATE_FIELDS,
    JointSample,
    Torque,
    arrays_to_joint_state,
    joint_state_to_arrays,
    msg_to_torque,
    torque_to_msg,
)
from apc_msgs_py.joint_trajectory import (
    SetpointStamped,
    TrajectoryGoal,
    msg_to_setpoint,
    msg_to_trajectory_goal,
    setpoint_to_msg,
)
from apc_msgs_py.stamps import (
    NS_PER_S,
    duration_to_ns,
    ns_to_duration,
    ns_to_stamp,
    sample_index,
    sample_stamp_ns,
    seconds_to_ns,
    stamp_to_ns,
)
from apc_msgs_py.topics import (
    CLOCK,
    CLOCK_QOS,
    CONTROL_QOS,
    CONTROL_WRITER_DEPTH,
    DIAGNOSTICS,
    DIAGNOSTICS_QOS,
    ESTIMATE,
    FEEDBACK_TORQUE,
    FEEDFORWARD_TORQUE,
    JOINT_STATES,
    MAX_LOOKAHEAD,
    ROBOT_DESCRIPTION,
    ROBOT_DESCRIPTION_QOS,
    SAMPLE,
    SETPOINT,
    TOPICS,
    TRAJECTORY_GOAL,
    TRAJECTORY_GOAL_QOS,
    TopicSpec,
    topic_spec,
    with_depth,
    writer_qos,
)

__all__ = [
    "CLOCK",
    "CLOCK_QOS",
    "CONTROL_QOS",
    "CONTROL_WRITER_DEPTH",
    "DEFAULT_MAX_ABS",
    "DIAGNOSTICS",
    "DIAGNOSTICS_QOS",
    "ESTIMATE",
    "ESTIMATE_COLS_LABEL",
    "ESTIMATE_ROWS_LABEL",
    "ESTIMATE_TRAILER",
    "FEEDBACK_TORQUE",
    "FEEDFORWARD_TORQUE",
    "JOINT_STATES",
    "JOINT_STATE_FIELDS",
    "MAX_LOOKAHEAD",
    "NS_PER_S",
    "ROBOT_DESCRIPTION",
    "ROBOT_DESCRIPTION_QOS",
    "SAMPLE",
    "SETPOINT",
    "TOPICS",
    "TRAJECTORY_GOAL",
    "TRAJECTORY_GOAL_QOS",
    "Estimate",
    "JointSample",
    "SetpointStamped",
    "TopicSpec",
    "Torque",
    "TrajectoryGoal",
    "WireError",
    "arrays_to_joint_state",
    "duration_to_ns",
    "estimate_to_msg",
    "joint_state_to_arrays",
    "msg_to_estimate",
    "msg_to_setpoint",
    "msg_to_torque",
    "msg_to_trajectory_goal",
    "ns_to_duration",
    "ns_to_stamp",
    "sample_index",
    "sample_stamp_ns",
    "seconds_to_ns",
    "setpoint_to_msg",
    "stamp_to_ns",
    "theta_t_to_estimate_msg",
    "topic_spec",
    "torque_to_msg",
    "with_depth",
    "writer_qos",
]
