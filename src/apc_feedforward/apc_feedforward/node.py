"""``feedforward_node``: set points and nominal torques (Eqs. 2-8), one per joint state.

On ``joint_states`` stamped ``kT`` it samples the current plan and publishes, stamped ``jT``,
the set point on ``feedforward/setpoint`` and ``u_n(j)`` on ``feedforward/torque`` for every
``j`` up to ``k + lookahead`` not sent yet. Driving both lockstep and real time from the plant's
samples keeps every node on the same sample index ``k`` without a shared clock.

Why ahead: the plan does not depend on the measured state (only its start does), so sample
``k + 1`` can leave as soon as ``k``'s joint state arrives. The feedback then has set point
``k`` in hand when joint state ``k`` arrives and the loop's critical path is plant -> feedback ->
plant, one DDS hop shorter (the paper's parallel feedforward and feedback). With
``lookahead = 0`` set point ``k`` answers joint state ``k`` (serial, one hop more). A goal that
arrives mid-motion starts ``lookahead`` samples later than it would otherwise; the numbers of a
lockstep run do not change.

The plan: at the first joint state the arm's measured position becomes the start; if
``move.goal_deg`` is set the 4-3-4 move to it starts there, else the arm holds. Goals on
``feedforward/trajectory`` (any joint order) are planned from the end of the current motion
and start when it ends; after the last motion the final set point is held.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from apc_core import wire
from apc_core.nodeutil import (
    ROBOT_PARAMS,
    Diagnostics,
    DiagnosticsPublisher,
    Stopwatch,
    guarded,
    reject,
    robot_from_params,
    run_node,
    sample_index,
)
from apc_core.params import ConfigError, Param, declare
from apc_core.robot import with_inertia_error
from apc_feedforward.nominal import Feedforward, FeedforwardError, Setpoint
from apc_feedforward.trajectory import (
    FourThreeFour,
    Quintic,
    Trajectory,
    TrajectoryError,
    Waypoints,
)

#: Goals waiting for the current motion to end; one more is rejected (a flood is not a plan).
MAX_QUEUED_GOALS = 100
#: A goal's plan is checked on at most this many sample times before it is accepted.
PLAN_CHECK_SAMPLES = 10_000

PARAMS: tuple[Param, ...] = (
    *ROBOT_PARAMS,
    Param(
        "inertia_error",
        [],
        "relative error of the controller's link inertia tensors, one per joint (the paper's "
        "simulation study: [0.1, -0.1, 0.1]); empty = the URDF as is",
    ),
    Param(
        "move.goal_deg",
        [],
        "first move: 4-3-4 from the first measured position to this goal (deg, URDF angles); "
        "empty = hold the first measured position until a goal arrives",
    ),
    Param("move.segment_times", [0.2, 0.6, 0.2], "4-3-4 segment durations (s)"),
    Param("move.lift_off", 0.1, "4-3-4 lift-off point, fraction of travel", 0.0, 1.0),
    Param("move.set_down", 0.9, "4-3-4 set-down point, fraction of travel", 0.0, 1.0),
    Param(
        "lookahead",
        1,
        "publish set points and nominal torques this many samples ahead of the joint state "
        "(0 = answer joint state k with sample k)",
        0,
        wire.MAX_LOOKAHEAD,
    ),
)


class FeedforwardNode(Node):
    """Composable feedforward node (see module docstring).

    Parameters
    ----------
    qos : QoSProfile
        Profile of the control-loop topics (default :data:`apc_core.wire.CONTROL_QOS`).
    kwargs :
        Passed to ``rclpy.node.Node`` (namespace, parameter_overrides, ...).
    """

    def __init__(
        self, node_name: str = "feedforward_node", *, qos: QoSProfile | None = None, **kwargs: Any
    ) -> None:
        super().__init__(node_name, **kwargs)
        qos = qos or wire.CONTROL_QOS
        values = declare(self, PARAMS)
        robot = robot_from_params(values)
        self.joint_names = robot.joint_names
        n = robot.n_joints
        error = values["inertia_error"] or [0.0] * n
        if len(error) != n:
            raise ConfigError(f"parameter 'inertia_error': needs {n} values, got {len(error)}")
        self.controller_robot = with_inertia_error(robot, error)
        goal = values["move.goal_deg"]
        if goal and len(goal) != n:
            raise ConfigError(f"parameter 'move.goal_deg': needs {n} values, got {len(goal)}")
        segments = values["move.segment_times"]
        if len(segments) != 3 or min(segments) <= 0.0:
            raise ConfigError("parameter 'move.segment_times': needs 3 positive durations (s)")
        self._goal = np.deg2rad(goal) if goal else None
        self._move = dict(
            segment_times=tuple(segments),
            lift_off=values["move.lift_off"],
            set_down=values["move.set_down"],
        )
        self.period = values["period"]
        self.period_ns = wire.seconds_to_ns(self.period)
        self.feedforward: Feedforward | None = None
        self._pending: list[wire.Waypoints] = []
        self.lookahead = int(values["lookahead"])
        self._last_stamp: int | None = None  # newest joint state handled
        self._sent: dict[int, Setpoint] = {}  # samples published for it, for a resend
        self._next_k: int | None = None  # first sample not published yet
        self._last_q: np.ndarray | None = None  # last published q_d (where a fallback holds)
        self.diagnostics = Diagnostics(self.get_fully_qualified_name())
        self._setpoint_msg = JointTrajectory()
        self._torque_msg = JointState()

        self.setpoint_pub = self.create_publisher(JointTrajectory, wire.SETPOINT, qos)
        self.torque_pub = self.create_publisher(JointState, wire.FEEDFORWARD_TORQUE, qos)
        diag = self.diagnostics
        self.create_subscription(
            JointState,
            wire.JOINT_STATES,
            guarded(self, diag, wire.JOINT_STATES, self._on_joint_state),
            qos,
        )
        self.create_subscription(
            JointTrajectory,
            wire.TRAJECTORY_GOAL,
            guarded(self, diag, wire.TRAJECTORY_GOAL, self._on_goal),
            wire.TRAJECTORY_GOAL_QOS,
        )
        DiagnosticsPublisher(self, self.diagnostics)

    # -- plan -----------------------------------------------------------------------------------
    def _start(self, q: np.ndarray, k: int) -> None:
        if self._goal is not None:
            plan: Trajectory = FourThreeFour(q, self._goal, **self._move)
        else:
            plan = Quintic(q, q, self.period)
        self.feedforward = Feedforward(self.controller_robot.model, plan, self.period, k)

    def _advance(self, k: int) -> None:
        """Start the next queued goal once the current motion has ended.

        A goal is planned when it becomes active, from the last set point of the motion before
        it, so goals can be queued before the first joint state or during a motion.
        """
        ff = self.feedforward
        while self._pending and ff is not None and k >= ff.end_k():
            goal = self._pending.pop(0)
            start = ff.trajectory.sample(ff.trajectory.duration)[0]
            try:
                plan = self._plan(start, goal)
                self._check_plan(plan)
            except ValueError as exc:  # TrajectoryError, or a plan that cannot be published
                reject(self, self.diagnostics, wire.TRAJECTORY_GOAL, exc)
                continue
            ff.set_trajectory(plan, max(k, ff.end_k()))
            self.diagnostics.count("goals_started")
            self.get_logger().info(f"sample {k}: starting a {plan.duration:.3f} s goal")

    @staticmethod
    def _plan(start: np.ndarray, goal: wire.Waypoints) -> Trajectory:
        return Waypoints(
            start,
            goal.times_s,
            goal.positions,
            velocities=goal.velocities,
            accelerations=goal.accelerations,
        )

    def _check_limits(self, positions: np.ndarray) -> None:
        """Refuse waypoints outside the URDF's joint position limits."""
        lower, upper = self.controller_robot.position_limits
        if lower.shape != positions.shape[1:] or upper.shape != positions.shape[1:]:
            return  # a model without position limits
        outside = (positions < lower) | (positions > upper)
        if outside.any():
            j, i = (int(v) for v in np.argwhere(outside)[0])
            raise wire.WireError(
                f"points[{j}].positions: {positions[j, i]:.6g} rad at joint "
                f"{self.joint_names[i]!r} is outside the URDF limits "
                f"[{lower[i]:.6g}, {upper[i]:.6g}]"
            )

    def _check_plan(self, plan: Trajectory) -> None:
        """Refuse a plan whose set points could not go on the wire (beyond its bound)."""
        count = int(min(np.ceil(plan.duration / self.period) + 1, PLAN_CHECK_SAMPLES))
        times = np.linspace(0.0, plan.duration, max(count, 2))
        for field, values in zip(
            ("positions", "velocities", "accelerations"), plan.sample_many(times), strict=True
        ):
            peak = float(np.max(np.abs(values)))
            if not peak <= wire.DEFAULT_MAX_ABS:  # also NaN
                raise TrajectoryError(
                    f"points: the planned {field} reach {peak:.3g} (more than "
                    f"{wire.DEFAULT_MAX_ABS:g}); the goal is too fast for its distance"
                )

    def _on_goal(self, msg: JointTrajectory) -> None:
        try:
            goal = wire.msg_to_waypoints(msg, self.joint_names)
            self._check_limits(goal.positions)
            if len(self._pending) >= MAX_QUEUED_GOALS:
                raise wire.WireError(f"points: {MAX_QUEUED_GOALS} goals already queued")
            # Check the goal now (timing, shapes, speed) with its first point as a stand-in
            # start; it is planned for real from the end of the motion before it when it starts.
            self._check_plan(self._plan(goal.positions[0], goal))
        except ValueError as exc:  # WireError, TrajectoryError
            reject(self, self.diagnostics, wire.TRAJECTORY_GOAL, exc)
            return
        self._pending.append(goal)
        self.diagnostics.count("goals_accepted")
        self.get_logger().info(
            f"goal accepted: {len(goal.times_s)} point(s), {goal.times_s[-1]:.3f} s, "
            f"{len(self._pending)} queued"
        )

    # -- loop -----------------------------------------------------------------------------------
    def _on_joint_state(self, msg: JointState) -> None:
        try:
            sample = wire.joint_state_to_arrays(msg, self.joint_names, require=("position",))
            k = sample_index(sample.stamp_ns, self.period_ns)
        except wire.WireError as exc:
            reject(self, self.diagnostics, wire.JOINT_STATES, exc)
            return
        stamp = sample.stamp_ns
        if self._last_stamp is not None and stamp <= self._last_stamp:
            if stamp == self._last_stamp:
                # The plant re-sent sample k (lockstep resend): send what answered it again.
                self.diagnostics.count("resent")
                for j in sorted(self._sent):
                    self._publish(self._sent[j])
            else:
                error = wire.WireError(
                    f"header.stamp: {stamp} ns is stale (sample {self._last_stamp} ns already done)"
                )
                reject(self, self.diagnostics, wire.JOINT_STATES, error)
            return
        self._last_stamp = stamp
        first = k if self._next_k is None else max(self._next_k, k)
        sent: dict[int, Setpoint] = {}
        for j in range(first, k + self.lookahead + 1):
            with Stopwatch(self.diagnostics, "compute"):
                out = self._sample_or_hold(j, sample.position)
            if out is None:
                break
            sp, setpoint, torque = out
            self.setpoint_pub.publish(setpoint)
            self.torque_pub.publish(torque)
            sent[j] = sp
            self._next_k = j + 1
        # Everything that answers sample k or later (a resend of k asks for all of it).
        self._sent = {j: v for j, v in {**self._sent, **sent}.items() if j >= k}
        self.diagnostics.count("samples")

    def _sample_or_hold(
        self, k: int, position: np.ndarray
    ) -> tuple[Setpoint, JointTrajectory, JointState] | None:
        """Set point ``k`` and its messages; on a plan that cannot be published, hold the last
        set point."""
        try:
            return self._compute(k, position)
        except (wire.WireError, TrajectoryError, FeedforwardError, ValueError) as exc:
            # The plan cannot be published (e.g. a motion too fast for the wire's bound):
            # drop it and hold the last set point, so the loop keeps its nominal torque.
            self.diagnostics.count("plan_errors")
            self.get_logger().error(
                f"sample {k}: {exc}; dropping the plan and holding the last set point",
                throttle_duration_sec=1.0,
            )
            hold = self._last_q if self._last_q is not None else position
            self.feedforward = Feedforward(
                self.controller_robot.model, Quintic(hold, hold, self.period), self.period, k
            )
            try:
                return self._compute(k, position)
            except (wire.WireError, TrajectoryError, FeedforwardError, ValueError) as exc2:
                reject(self, self.diagnostics, "feedforward_compute", exc2)
                return None

    def _compute(
        self, k: int, position: np.ndarray
    ) -> tuple[Setpoint, JointTrajectory, JointState]:
        """Set point and nominal torque of sample ``k`` as messages (validated for the wire)."""
        if self.feedforward is None:
            self._start(position, k)
        self._advance(k)
        assert self.feedforward is not None
        sp = self.feedforward.sample(k)
        setpoint, torque = self._messages(sp)
        self._last_q = sp.q
        return sp, setpoint, torque

    def _messages(self, sp: Setpoint) -> tuple[JointTrajectory, JointState]:
        stamp = wire.sample_stamp_ns(sp.k, self.period_ns)
        t_ns = wire.seconds_to_ns(sp.t) if sp.t > 0 else 0
        setpoint = wire.setpoint_to_msg(
            stamp, self.joint_names, sp.q, sp.qd, sp.qdd, sp.u_n, t_ns, self._setpoint_msg
        )
        torque = wire.torque_to_msg(stamp, self.joint_names, sp.u_n, self._torque_msg)
        return setpoint, torque

    def _publish(self, sp: Setpoint) -> None:
        setpoint, torque = self._messages(sp)
        self.setpoint_pub.publish(setpoint)
        self.torque_pub.publish(torque)


def main(args: list[str] | None = None) -> int:
    return run_node(
        FeedforwardNode,
        prog="feedforward_node",
        summary=__doc__ or "",
        params=PARAMS,
        args=args,
    )


if __name__ == "__main__":
    sys.exit(main())
