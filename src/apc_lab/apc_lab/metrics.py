"""Tracking metrics of a run, per joint, as the paper's Table 2 reports them and a few more.

Definitions
-----------
- *maximum error* (deg): ``max |q_i - q_d,i|`` from the start to the end of the move.
- *tip displacement* (mm): the displacement of the tip point (the ``wrist_center`` frame, else
  the last joint's frame) that joint i's error alone causes, ``|J_i(q)| |e_i|`` with ``J_i`` the
  i-th column of the point's translational Jacobian; the maximum over the move. This is the
  paper's "trajectory tracking maximum error (mm)": its ratios mm/deg in Table 2 (17.4 mm/deg
  for joints 1-2, 8.7 for joint 3) are arc lengths at the distance from each axis to the tip.
- *final error* (deg): ``|e_i|`` at the end of the move (t = move duration).
- *hold error* (deg): ``max |e_i|`` over the hold after the move, and its value at the last sample.
- *RMS error* (deg) over the move; *peak* and *RMS torque* (N m) of the applied torque;
  *RLS residual*: RMS of the identification residual norm (adaptive law only).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from apc_core.robot import Robot

if TYPE_CHECKING:
    from apc_recording.runs import RecordedRun


@dataclass(frozen=True)
class JointMetrics:
    """Per-joint metrics of one run (lists in joint order); see the module docstring."""

    joints: list[str]
    max_error_deg: list[float]
    max_tip_mm: list[float]
    final_error_deg: list[float]
    hold_max_error_deg: list[float]
    hold_final_error_deg: list[float]
    rms_error_deg: list[float]
    peak_torque_nm: list[float]
    rms_torque_nm: list[float]
    rls_residual_rms: float | None

    def as_dict(self) -> dict:
        return asdict(self)


def tip_frame(robot: Robot) -> int:
    """Frame whose displacement the tip metric measures: ``wrist_center`` if present."""
    model = robot.model
    if model.existFrame("wrist_center"):
        return model.getFrameId("wrist_center")
    return len(model.frames) - 1


def tip_lever_arms(robot: Robot, q: np.ndarray) -> np.ndarray:
    """``|J_i(q)|`` (m/rad) for each joint, at each row of ``q`` (N, n) -> (N, n)."""
    model = robot.model
    data = model.createData()
    frame = tip_frame(robot)
    out = np.zeros_like(q)
    for row, qk in enumerate(q):
        J = pin.computeFrameJacobian(model, data, qk, frame, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        out[row] = np.linalg.norm(J[:3], axis=0)
    return out


def compute_metrics(
    joint_names: tuple[str, ...],
    q: np.ndarray,
    q_d: np.ndarray,
    applied: np.ndarray,
    move_end: int,
    robot: Robot | None = None,
    residual_norm: np.ndarray | None = None,
) -> JointMetrics:
    """Metrics of one run from its arrays (rows = samples; see module docstring).

    Parameters
    ----------
    q, q_d : (N, n) ndarray
        Measured and planned positions (rad).
    applied : (N, n) ndarray
        Applied torque per sample (N m); NaN rows are ignored.
    move_end : int
        Row of the end of the move.
    robot : Robot, optional
        The arm (for the tip metric); without it ``max_tip_mm`` is NaN.
    """
    err = np.abs(q - q_d)
    move = slice(0, move_end + 1)
    hold = err[move_end:]
    if robot is not None:
        lever = tip_lever_arms(robot, q[move])
        tip = (lever * err[move]).max(axis=0) * 1e3
    else:
        tip = np.full(len(joint_names), np.nan)
    residual = None
    if residual_norm is not None and np.any(np.isfinite(residual_norm)):
        r = residual_norm[np.isfinite(residual_norm)]
        residual = float(np.sqrt(np.mean(r**2)))

    def deg(a: np.ndarray) -> list[float]:
        return [float(v) for v in np.rad2deg(a)]

    return JointMetrics(
        joints=list(joint_names),
        max_error_deg=deg(err[move].max(axis=0)),
        max_tip_mm=[float(v) for v in tip],
        final_error_deg=deg(err[move_end]),
        hold_max_error_deg=deg(hold.max(axis=0)),
        hold_final_error_deg=deg(err[-1]),
        rms_error_deg=deg(np.sqrt(np.mean(err[move] ** 2, axis=0))),
        peak_torque_nm=[float(v) for v in np.nanmax(np.abs(applied), axis=0)],
        rms_torque_nm=[float(v) for v in np.sqrt(np.nanmean(applied**2, axis=0))],
        rls_residual_rms=residual,
    )


def recovery_samples(run: RecordedRun, pickup_s: float, tolerance_deg: float) -> int | None:
    """Samples after a pick-up until every joint stays within a tolerance for good.

    Definition: let ``k0`` be the first sample at or after ``pickup_s`` (``t[k0] >= pickup_s``,
    with 1e-9 s of slack for rounding). The result is the smallest ``m >= 0`` such that every
    joint's ``|q - q_d| < tolerance_deg`` at every sample from ``k0 + m`` to the end of the
    run. So 0 means the error never leaves the tolerance after the pick-up, and ``m`` means
    sample ``k0 + m`` is the first of an unbroken run of in-tolerance samples that lasts to the
    end. Samples with a NaN error (lost in a real-time recording) are skipped: they neither
    break nor end that run.

    Parameters
    ----------
    run : RecordedRun
    pickup_s : float
        Time of the pick-up (s, on the run's time axis).
    tolerance_deg : float
        Tolerance on every joint's absolute position error (deg), > 0.

    Returns
    -------
    int or None
        The number of samples, or None if the error is not within tolerance at the last valid
        sample (it never recovers for good).

    Raises
    ------
    ValueError
        If ``tolerance_deg <= 0`` or no sample lies at or after ``pickup_s``.
    """
    if not tolerance_deg > 0:
        raise ValueError(f"tolerance_deg must be > 0, got {tolerance_deg}")
    t = np.asarray(run.t, dtype=float)
    after = np.flatnonzero(t >= pickup_s - 1e-9)
    if after.size == 0:
        raise ValueError(f"no sample at or after pickup_s = {pickup_s} s (last at {t[-1]} s)")
    k0 = int(after[0])
    err = np.abs(np.rad2deg(run.error[k0:]))
    valid = np.all(np.isfinite(err), axis=1)
    inside = np.all(err < tolerance_deg, axis=1)
    valid_rows = np.flatnonzero(valid)
    if valid_rows.size == 0 or not inside[valid_rows[-1]]:
        return None
    outside = np.flatnonzero(valid & ~inside)
    if outside.size == 0:
        return 0
    # The first valid in-tolerance sample after the last excursion.
    later = valid_rows[valid_rows > outside[-1]]
    return int(later[0])
