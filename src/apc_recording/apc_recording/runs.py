"""Read an apc recording (MCAP) back into per-sample arrays, aligned by header stamp.

Row ``i`` of every array is the sample stamped ``t[i]`` (s). Where a topic has no message for a
sample (a real-time run that lost one, or the last sample's torques), the row is NaN.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

import apc_msgs_py as wire
from apc_recording.bag import bag_info, read_messages


@dataclass
class RecordedRun:
    """Arrays of one recording; joints in ``joint_names`` order.

    Attributes
    ----------
    t : (N,) ndarray
        Sample times (s) of the ``joint_states`` messages.
    q, qd : (N, n)
        Measured state (rad, rad/s).
    applied : (N, n)
        Torque applied over the period that *ended* at the sample, as ``joint_states(k)``
        reports it in ``effort`` (N m); NaN at the first.
    q_d, qd_d, qdd_d, u_n : (N, n)
        Set point and nominal torque.
    du : (N, n)
        Feedback torque.
    trace_p, residual_norm : (N,)
        Identification telemetry (NaN without an adaptive law).
    theta_t : (N, 2n, 3n+1) or None (with L input lags (N, 2n, 2n + (L+1) n + 1))
        Θᵀ = ``[F̂ Ĝ ŵ]`` per sample.
    run : dict
        The experiment description stored in the file (``custom_data['apc.run']``), if any.
    robot_description : str
        The arm's URDF as recorded on ``robot_description`` ("" if none was).
    """

    path: Path
    joint_names: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    applied: np.ndarray
    q_d: np.ndarray
    qd_d: np.ndarray
    qdd_d: np.ndarray
    u_n: np.ndarray
    du: np.ndarray
    trace_p: np.ndarray
    residual_norm: np.ndarray
    theta_t: np.ndarray | None
    run: dict[str, Any] = field(default_factory=dict)
    robot_description: str = ""

    @property
    def error(self) -> np.ndarray:
        return self.q - self.q_d

    @property
    def move_end_index(self) -> int:
        """Row of the end of the move (from the stored scenario), else the last row."""
        scenario = self.run.get("scenario", {})
        if "segment_times" in scenario and "period" in scenario:
            end = round(sum(scenario["segment_times"]) / scenario["period"])
            return int(min(end, len(self.t) - 1))
        return len(self.t) - 1


_TOPICS = (
    wire.JOINT_STATES,
    wire.SETPOINT,
    wire.FEEDBACK_TORQUE,
    wire.ESTIMATE,
    wire.ROBOT_DESCRIPTION,
)


def _custom_run(path: Path) -> dict[str, Any]:
    """The experiment description stored in the file (``custom_data['apc.run']``), or {}."""
    meta = bag_info(path).get("rosbag2_metadata") or {}
    custom = (meta.get("rosbag2_bagfile_information") or meta).get("custom_data") or {}
    return (yaml.safe_load(custom["apc.run"]) if "apc.run" in custom else None) or {}


def load_run(path: str | Path) -> RecordedRun:
    """Read ``joint_states``, set points, torques and estimates of a recording."""
    path = Path(path)
    run = _custom_run(path)
    states: dict[int, Any] = {}
    setpoints: dict[int, Any] = {}
    feedback: dict[int, Any] = {}
    estimates: dict[int, Any] = {}
    names: tuple[str, ...] | None = None
    description = ""
    for m in read_messages(path):
        # Recorded names are resolved (``/joint_states``, ``/puma/joint_states`` ...).
        tail = next((t for t in _TOPICS if m.topic.endswith("/" + t)), None)
        if tail == wire.JOINT_STATES:
            msg = m.decode()
            names = names or tuple(msg.name)
            states[wire.stamp_to_ns(msg.header.stamp)] = msg
        elif tail == wire.SETPOINT:
            msg = m.decode()
            setpoints[wire.stamp_to_ns(msg.header.stamp)] = msg
        elif tail == wire.FEEDBACK_TORQUE:
            msg = m.decode()
            feedback[wire.stamp_to_ns(msg.header.stamp)] = msg
        elif tail == wire.ESTIMATE:
            est = wire.msg_to_estimate(m.decode())
            estimates[est.stamp_ns] = est
        elif tail == wire.ROBOT_DESCRIPTION:
            description = m.decode().data
    if names is None:
        raise ValueError(f"{path}: no joint_states recorded")
    stamps = sorted(states)
    n, rows = len(names), len(stamps)

    def blank(*shape: int) -> np.ndarray:
        return np.full((rows, *shape), np.nan)

    q, qd, applied = blank(n), blank(n), blank(n)
    q_d, qd_d, qdd_d, u_n, du = blank(n), blank(n), blank(n), blank(n), blank(n)
    trace_p, residual = blank(), blank()
    theta_t = None
    for i, stamp in enumerate(stamps):
        js = wire.joint_state_to_arrays(states[stamp], names, require=("position", "velocity"))
        q[i], qd[i] = js.position, js.velocity
        if js.effort is not None:
            applied[i] = js.effort
        if stamp in setpoints:
            sp = wire.msg_to_setpoint(setpoints[stamp], names)
            q_d[i], qd_d[i], qdd_d[i], u_n[i] = sp.q, sp.qd, sp.qdd, sp.u_n
        if stamp in feedback:
            du[i] = wire.msg_to_torque(feedback[stamp], names).effort
        if stamp in estimates:
            est = estimates[stamp]
            trace_p[i], residual[i] = est.trace_p, est.residual_norm
            if theta_t is None:
                theta_t = np.full((rows, *est.theta_t.shape), np.nan)
            theta_t[i] = est.theta_t
    return RecordedRun(
        path=path,
        joint_names=names,
        t=np.array(stamps, dtype=float) / wire.NS_PER_S,
        q=q,
        qd=qd,
        applied=applied,
        q_d=q_d,
        qd_d=qd_d,
        qdd_d=qdd_d,
        u_n=u_n,
        du=du,
        trace_p=trace_p,
        residual_norm=residual,
        theta_t=theta_t,
        run=run,
        robot_description=description,
    )


def load_robot_run(path: str | Path) -> RecordedRun:
    """Read a robot-mode recording: rows from the start of the move, ``t = 0`` there.

    A ros2_control driver stamps ``/joint_states`` with its own clock at its own rate, so the
    rows are the samples the controllers took (``feedback/sample``, stamped ``kT``: what the law
    measured, with the driver's quantisation and velocity), each with the set point of its
    stamp. The move starts at the last sample before the first set point that moves (a goal
    starts after a hold; its time on the recording's clock is ``run["move_start_s"]``).
    ``applied`` is the torque of the driver's first state after the sample (the torque over the
    driver period that followed it). There is no feedback-torque topic in robot mode (the
    commanding node adds ``u_n + du`` itself): ``du`` is NaN, and so is the identification
    telemetry. ``run["hold_max_error_deg"]`` is the worst ``|q - q_d|`` (deg) over the samples
    before the set point first moves: the sag of the hold before the goal.
    """
    path = Path(path)
    run = _custom_run(path)
    samples: dict[int, Any] = {}
    setpoints: dict[int, Any] = {}
    driver: list[tuple[int, Any]] = []
    names: tuple[str, ...] | None = None
    description = ""
    for m in read_messages(path):
        if m.topic.endswith("/" + wire.SAMPLE):
            msg = m.decode()
            names = names or tuple(msg.name)
            samples[wire.stamp_to_ns(msg.header.stamp)] = msg
        elif m.topic.endswith("/" + wire.SETPOINT):
            msg = m.decode()
            setpoints[wire.stamp_to_ns(msg.header.stamp)] = msg
        elif m.topic.endswith("/" + wire.JOINT_STATES):
            msg = m.decode()
            driver.append((wire.stamp_to_ns(msg.header.stamp), msg))
        elif m.topic.endswith("/" + wire.ROBOT_DESCRIPTION):
            description = m.decode().data
    if names is None:
        raise ValueError(f"{path}: no {wire.SAMPLE} recorded (not a robot-mode run)")
    stamps = sorted(samples)
    n, rows = len(names), len(stamps)
    q, qd = np.full((rows, n), np.nan), np.full((rows, n), np.nan)
    q_d, qd_d, qdd_d, u_n = (np.full((rows, n), np.nan) for _ in range(4))
    for i, stamp in enumerate(stamps):
        js = wire.joint_state_to_arrays(samples[stamp], names, require=("position", "velocity"))
        q[i], qd[i] = js.position, js.velocity
        if stamp in setpoints:
            sp = wire.msg_to_setpoint(setpoints[stamp], names)
            q_d[i], qd_d[i], qdd_d[i], u_n[i] = sp.q, sp.qd, sp.qdd, sp.u_n
    moving = np.flatnonzero(np.any(np.nan_to_num(np.abs(qd_d)) > 0.0, axis=1))
    start = max(int(moving[0]) - 1, 0) if moving.size else 0
    still = slice(0, int(moving[0]) if moving.size else rows)
    hold_error = np.abs(np.rad2deg(q[still] - q_d[still]))
    hold_max = float(np.nanmax(hold_error)) if np.isfinite(hold_error).any() else 0.0
    applied = np.full((rows, n), np.nan)
    driver.sort(key=lambda item: item[0])
    driver_stamps = np.array([stamp for stamp, _ in driver], dtype=np.int64)
    for i, stamp in enumerate(stamps):
        j = int(np.searchsorted(driver_stamps, stamp, side="right"))
        if j < len(driver):
            state = wire.joint_state_to_arrays(
                driver[j][1], names, require=("position",), allow_extra=True
            )
            if state.effort is not None:
                applied[i] = state.effort
    t = (np.array(stamps, dtype=float) - stamps[start]) / wire.NS_PER_S
    rest = slice(start, None)
    return RecordedRun(
        path=path,
        joint_names=names,
        t=t[rest],
        q=q[rest],
        qd=qd[rest],
        applied=applied[rest],
        q_d=q_d[rest],
        qd_d=qd_d[rest],
        qdd_d=qdd_d[rest],
        u_n=u_n[rest],
        du=np.full((rows - start, n), np.nan),
        trace_p=np.full(rows - start, np.nan),
        residual_norm=np.full(rows - start, np.nan),
        theta_t=None,
        run={**run, "move_start_s": stamps[start] / wire.NS_PER_S, "hold_max_error_deg": hold_max},
        robot_description=description,
    )
