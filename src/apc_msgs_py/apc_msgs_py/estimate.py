"""``std_msgs/Float64MultiArray`` on the wire: the feedback's identification estimate."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from apc_msgs_py.fields import WireError, check_finite, to_double_array

# Θ is the paper's parameter matrix [F G w]ᵀ, (3n+1, 2n) (Eq. 22); the estimate carries its
# transpose Θᵀ = [F G w], (2n, 3n+1), one row per state entry, as the identifier holds it.
# ``theta_t`` names Θᵀ here and wherever an estimate is read; the two labels below are part of
# the recorded message format and keep their spelling.
#: ``layout.dim[0].label`` of an estimate: the rows of Θᵀ = [F G w] (p = 2n).
ESTIMATE_ROWS_LABEL = "theta_rows"
#: ``layout.dim[1].label`` of an estimate: the columns of Θᵀ (p + n + 1 = 3n + 1; with L input
#: lags p + (L+1) n + 1).
ESTIMATE_COLS_LABEL = "theta_cols"
#: The scalars after Θᵀ in ``data``, in order.
ESTIMATE_TRAILER = ("trace_p", "residual_norm", "stamp_ns")


@dataclass(frozen=True, eq=False)  # arrays: compare fields with numpy
class Estimate:
    """Identification telemetry of one sample (the feedback's RLS state).

    Attributes
    ----------
    stamp_ns : int
        Sample time ``kT`` the estimate was computed at (after the update with sample k).
    F : (p, p) ndarray
        State matrix estimate F̂ of ``δx(k+1) = F δx(k) + G δu(k) + w``.
    G : (p, n) ndarray
        Input matrix estimate Ĝ; with ``L`` input lags ``[Ĝ₀ Ĝ₁ … Ĝ_L]``, (p, (L+1) n).
    w : (p,) ndarray
        Offset estimate ŵ.
    trace_p : float
        trace(P) of the RLS covariance.
    residual_norm : float
        Norm of the one-step prediction residual.
    """

    stamp_ns: int
    F: np.ndarray
    G: np.ndarray
    w: np.ndarray
    trace_p: float
    residual_norm: float

    @property
    def theta_t(self) -> np.ndarray:
        """Θᵀ = [F G w], shape (p, p + n + 1), so that ``δx(k+1) = Θᵀ z(k)`` (Eq. 25)."""
        return np.hstack([self.F, self.G, self.w[:, None]])


def estimate_to_msg(
    F: Any,
    G: Any,
    w: Any,
    trace_p: float,
    residual_norm: float,
    *,
    stamp_ns: int,
    msg: Float64MultiArray | None = None,
) -> Float64MultiArray:
    """Pack an RLS estimate into a ``std_msgs/Float64MultiArray``.

    Layout (``p`` = state size 2n, ``n`` = input size, ``c = p + n + 1`` = 3n + 1):

    - ``layout.dim[0]``: label ``"theta_rows"``, size ``p``, stride ``p * c``;
      ``layout.dim[1]``: label ``"theta_cols"``, size ``c``, stride ``c``; ``data_offset = 0``.
      So the layout describes, in the standard MultiArray way, the matrix Θᵀ = [F G w] stored
      row-major in ``data[0 : p*c]`` (any MultiArray viewer shows Θᵀ correctly).
    - ``data[p*c : p*c + 3]`` = ``[trace_p, residual_norm, stamp_ns]``
      (:data:`ESTIMATE_TRAILER`): two health scalars, then the sample time.

    ``Float64MultiArray`` has no header, so the sample time travels in the data, as a float64
    holding integer nanoseconds: exact up to 2**53 ns (104 days of run time). Recordings also log
    it with log time = the sample time, but the message must say which sample it is on its own.

    Parameters
    ----------
    F : (p, p) array_like
    G : (p, n) array_like
    w : (p,) array_like
    trace_p, residual_norm : float
    stamp_ns : int
        Sample time ``kT`` (keyword-only so it cannot be forgotten or swapped).
    msg : std_msgs.msg.Float64MultiArray, optional
        A preallocated message to refill.

    Returns
    -------
    std_msgs.msg.Float64MultiArray

    Raises
    ------
    WireError
        On inconsistent shapes, non-finite values, or a stamp outside ``[0, 2**53]`` ns.
    """
    F = np.asarray(F, dtype=np.float64)
    G = np.asarray(G, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    if F.ndim != 2 or F.shape[0] != F.shape[1] or F.shape[0] == 0:
        raise WireError(f"F: shape {F.shape}, expected square (p, p) with p > 0")
    p = F.shape[0]
    if G.ndim != 2 or G.shape[0] != p or G.shape[1] == 0:
        raise WireError(f"G: shape {G.shape}, expected ({p}, n) with n > 0")
    if w.shape != (p,):
        raise WireError(f"w: shape {w.shape}, expected ({p},)")
    for field, values in (("F", F), ("G", G), ("w", w)):
        check_finite(values, field, (), math.inf)
    return theta_t_to_estimate_msg(
        np.hstack([F, G, w[:, None]]), trace_p, residual_norm, stamp_ns=stamp_ns, msg=msg
    )


def theta_t_to_estimate_msg(
    theta_t: Any,
    trace_p: float,
    residual_norm: float,
    *,
    stamp_ns: int,
    msg: Float64MultiArray | None = None,
) -> Float64MultiArray:
    """:func:`estimate_to_msg` from ``Θᵀ = [F G w]`` in one (p, 3n+1) array, as the identifier
    holds it (``Rls.model_view()``): no copies of F, G, w on the way.

    Raises
    ------
    WireError
        On a shape that is not (p, p + n + 1) with n > 0, non-finite values, or a stamp outside
        ``[0, 2**53]`` ns.
    """
    theta_t = np.asarray(theta_t, dtype=np.float64)
    if theta_t.ndim != 2 or theta_t.shape[0] == 0 or theta_t.shape[1] < theta_t.shape[0] + 2:
        raise WireError(f"theta_t: shape {theta_t.shape}, expected (p, p + n + 1) with n > 0")
    if isinstance(stamp_ns, bool) or not isinstance(stamp_ns, (int, np.integer)):
        raise WireError(f"stamp_ns: must be integer nanoseconds, got {type(stamp_ns).__name__}")
    if not 0 <= stamp_ns <= 2**53:
        raise WireError(f"stamp_ns: {stamp_ns} is outside [0, 2**53] (not exact as float64)")
    rows, cols = theta_t.shape
    data = np.empty(rows * cols + 3)
    data[: rows * cols] = theta_t.ravel()
    data[rows * cols :] = (trace_p, residual_norm, float(stamp_ns))
    check_finite(data[: rows * cols], "theta_t", (), math.inf)
    check_finite(data[rows * cols : rows * cols + 1], "trace_p", (), math.inf)
    check_finite(data[rows * cols + 1 : rows * cols + 2], "residual_norm", (), math.inf)
    if msg is None:
        msg = Float64MultiArray()
    if len(msg.layout.dim) != 2:
        msg.layout.dim = [MultiArrayDimension(), MultiArrayDimension()]
    d0, d1 = msg.layout.dim
    d0.label, d0.size, d0.stride = ESTIMATE_ROWS_LABEL, rows, rows * cols
    d1.label, d1.size, d1.stride = ESTIMATE_COLS_LABEL, cols, cols
    msg.layout.data_offset = 0
    msg.data = to_double_array(data)
    return msg


def msg_to_estimate(msg: Float64MultiArray) -> Estimate:
    """Unpack an estimate message (see :func:`estimate_to_msg` for the layout).

    Returns
    -------
    Estimate

    Raises
    ------
    WireError
        Naming the field: ``layout.dim`` not the two labelled dimensions, strides inconsistent,
        ``layout.data_offset`` not 0, ``data`` of the wrong length, NaN/Inf, or a stamp that is
        not a non-negative integer.
    """
    dims = msg.layout.dim
    if len(dims) != 2:
        raise WireError(
            f"layout.dim: expected 2 dimensions (rows and columns of Θᵀ), got {len(dims)}"
        )
    d0, d1 = dims
    if (d0.label, d1.label) != (ESTIMATE_ROWS_LABEL, ESTIMATE_COLS_LABEL):
        raise WireError(
            f"layout.dim: labels ({d0.label!r}, {d1.label!r}), expected "
            f"({ESTIMATE_ROWS_LABEL!r}, {ESTIMATE_COLS_LABEL!r})"
        )
    p, c = d0.size, d1.size
    if p == 0 or c < p + 2:
        raise WireError(f"layout.dim: sizes ({p}, {c}), expected (p, p + n + 1) with p, n > 0")
    if d1.stride != c or d0.stride != p * c:
        raise WireError(
            f"layout.dim: strides ({d0.stride}, {d1.stride}), expected ({p * c}, {c}) (row-major)"
        )
    if msg.layout.data_offset != 0:
        raise WireError(f"layout.data_offset: {msg.layout.data_offset}, expected 0")
    expected = p * c + len(ESTIMATE_TRAILER)
    if len(msg.data) != expected:
        raise WireError(f"data: length {len(msg.data)}, expected {expected} (p*c + 3)")
    data = np.array(msg.data, dtype=np.float64)
    check_finite(data[: p * c], "data", (), math.inf)
    theta_t = data[: p * c].reshape(p, c)
    trace_p, residual_norm, stamp = (float(v) for v in data[p * c :])
    for name, v in (("trace_p", trace_p), ("residual_norm", residual_norm)):
        if not math.isfinite(v):
            raise WireError(f"data ({name}): {'NaN' if math.isnan(v) else 'Inf'}")
    if not (math.isfinite(stamp) and stamp >= 0 and stamp == math.floor(stamp)):
        raise WireError(f"data (stamp_ns): {stamp} is not a non-negative integer")
    return Estimate(
        stamp_ns=int(stamp),
        F=theta_t[:, :p].copy(),
        G=theta_t[:, p : c - 1].copy(),
        w=theta_t[:, c - 1].copy(),
        trace_p=float(trace_p),
        residual_norm=float(residual_norm),
    )
