"""Figures beyond the paper's, as PNG files, in the style of :mod:`apc_lab.plots`.

- :func:`identified_parameters` — the RLS-identified F̂, Ĝ, ŵ (Eqs. 29-31) over time, trace(P)
  and the identification residual.
- :func:`payload_sweep` — maximum tracking error against payload, per controller (extends
  Table 2).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from apc_lab.plots import (
    _END_LABEL,
    _END_STYLE,
    _JOINT_STYLES,
    KG_PER_LB,
    SIZE_SINGLE,
    _decades,
    _end_time,
    _mark_times,
    _new_figure,
    _positive,
    _save,
    _suptitle,
)

if TYPE_CHECKING:
    from apc_recording.runs import RecordedRun

__all__ = ["identified_parameters", "payload_sweep"]


# --------------------------------------------------------------------------------------------
# identified parameters


def _figure_identified_parameters(run: RecordedRun, title: str | None = None) -> Figure:
    """Build the figure of :func:`identified_parameters` without saving it."""
    if run.theta_t is None:
        raise ValueError(
            "this run has no identified parameters (theta_t is None): only the adaptive law "
            "publishes estimates"
        )
    theta_t = np.asarray(run.theta_t, dtype=float)
    n = run.q.shape[1]
    columns = theta_t.shape[2] if theta_t.ndim == 3 else 0
    if theta_t.shape[1:2] != (2 * n,) or columns < 3 * n + 1 or (columns - 1) % n:
        raise ValueError(
            f"theta_t has shape {theta_t.shape}, expected (N, {2 * n}, {2 * n} + (L+1) {n} + 1)"
        )
    # Ĝ of a model with input lags is [Ĝ₀ … Ĝ_L]: their sum is the effect of a held input.
    g_sum = theta_t[:, :, 2 * n : columns - 1].reshape(len(theta_t), 2 * n, -1, n).sum(axis=2)
    fig, axes = _new_figure((12.0, 8.0), 2, 2, sharex=True)
    ax_g, ax_f, ax_w, ax_p = axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1]
    t = run.t
    for i in range(n):
        style = {"color": f"C{i}", "linewidth": 1.3, "label": f"joint {i + 1}"}
        ax_g.plot(t, g_sum[:, n + i, i], **style)
        ax_f.plot(t, theta_t[:, n + i, i], **style)
        ax_w.plot(t, theta_t[:, n + i, columns - 1], **style)
    ax_g.set_title("(a) Ĝ velocity block, diagonal (≈ T D⁻¹; with lags Σ Ĝ_j)", fontsize=10)
    ax_g.set_ylabel("Ĝ[n+i, i] (rad/s per N m)")
    ax_f.set_title("(b) F̂ gravity stiffness (velocity row i, position column i)", fontsize=10)
    ax_f.set_ylabel("F̂[n+i, i] (1/s)")
    ax_w.set_title("(c) ŵ velocity rows (apc's sign)", fontsize=10)
    ax_w.set_ylabel("ŵ[n+i] (rad/s)")
    ax_p.set_title("(d) RLS covariance and residual", fontsize=10)
    ax_p.plot(t, _positive(run.trace_p), color="k", linewidth=1.3, label="trace(P)")
    ax_p.set_yscale("log")
    ax_p.margins(y=0.08)  # a guarded trace(P) sits on its cap for long: keep it off the frame
    ax_p.set_ylabel("trace(P)")
    ax_r = ax_p.twinx()
    ax_r.plot(
        t, _positive(run.residual_norm), color="tab:purple", linewidth=1.0, linestyle="--",
        label="residual norm",
    )  # fmt: skip
    ax_r.set_yscale("log")
    ax_r.set_ylabel("a-priori residual ‖e(k)‖ (Eq. 26)", color="tab:purple")
    ax_r.tick_params(axis="y", colors="tab:purple")
    for ax in axes.ravel():
        ax.grid(True, alpha=0.3)
    _mark_times(axes.ravel(), [_end_time(run)], _END_STYLE, _END_LABEL)
    for ax in (ax_g, ax_f, ax_w):  # the end-of-move line joins each panel's legend
        ax.legend(loc="best", fontsize=9)
    handles = ax_p.get_legend_handles_labels()[0] + ax_r.get_legend_handles_labels()[0]
    ax_p.legend(handles, [h.get_label() for h in handles], loc="best", fontsize=9)
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    ax_g.set_xlim(float(np.nanmin(t)), float(np.nanmax(t)))
    _suptitle(
        fig,
        title,
        "Identified perturbation model",
        "not in the paper: RLS estimates of δx(k+1) = F̂ δx(k) + Ĝ δu(k) + ŵ, δx = [δq; δq'] "
        "(Eqs. 16, 29-31)",
    )
    return fig


def identified_parameters(run: RecordedRun, out: str | Path, title: str | None = None) -> Path:
    """Identified parameters of an adaptive run over time, in four panels.

    (a) the diagonal of Ĝ's velocity block, ``Ĝ[n+i, i]`` (≈ T D⁻¹, rad/s per N m; with input
        lags, of their sum);
    (b) the gravity stiffness ``F̂[n+i, i]`` (velocity row, position column, 1/s);
    (c) the velocity rows of ``ŵ`` (rad/s, apc's sign convention);
    (d) trace(P) (log scale, left axis) and the residual norm (log scale, right axis).

    Parameters
    ----------
    run : RecordedRun
        A run of the adaptive law (``theta_t`` of shape (N, 2n, 3n+1), or with ``L`` input
        lags (N, 2n, 2n + (L+1) n + 1)).
    out : path
        PNG file to write.
    title : str, optional
        First line of the figure title.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ValueError
        If the run has no identified parameters (``theta_t is None``: not an adaptive run).
    """
    fig = _figure_identified_parameters(run, title)
    return _save(fig, out)


# --------------------------------------------------------------------------------------------
# payload sweep


def _figure_payload_sweep(
    sweep: Mapping[str, Sequence[tuple[float, Sequence[float]]]],
    title: str | None = None,
    *,
    per_joint: bool = True,
) -> Figure:
    """Build the figure of :func:`payload_sweep` without saving it."""
    if not sweep:
        raise ValueError("no sweep to plot")
    fig, axes = _new_figure(SIZE_SINGLE)
    ax = axes[0, 0]
    plotted = []
    n_joints = 0
    for i, (label, points) in enumerate(sweep.items()):
        if not points:
            raise ValueError(f"{label!r}: no points")
        ordered = sorted(points, key=lambda p: p[0])
        kg = np.array([p[0] for p in ordered], dtype=float)
        per = np.array([np.asarray(p[1], dtype=float) for p in ordered])  # (points, joints)
        if per.ndim != 2:
            raise ValueError(f"{label!r}: every point needs the same number of joint errors")
        worst = np.nanmax(per, axis=1)
        color = f"C{i % 10}"
        ax.plot(kg, worst, color=color, marker="o", linewidth=2.2, label=label, zorder=3)
        plotted.append(worst)
        n_joints = max(n_joints, per.shape[1])
        if per_joint:
            for j in range(per.shape[1]):
                ax.plot(
                    kg, per[:, j], color=color, linewidth=0.9, alpha=0.75,
                    linestyle=_JOINT_STYLES[j % len(_JOINT_STYLES)], marker=".", zorder=2,
                )  # fmt: skip
                plotted.append(per[:, j])
    values = np.concatenate([np.ravel(v) for v in plotted])
    if _decades(values) > 2.0:
        ax.set_yscale("log")
    ax.set_xlabel("payload (kg)")
    ax.set_ylabel("maximum |q − q_d| over the move (deg)\nthick: worst joint, thin: each joint")
    lb = ax.secondary_xaxis("top", functions=(lambda x: x / KG_PER_LB, lambda x: x * KG_PER_LB))
    lb.set_xlabel("payload (lb)")
    ax.grid(True, which="both", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if per_joint:  # one key per joint's dash pattern, in grey
        for j in range(n_joints):
            handles.append(
                Line2D([], [], color="0.4", linewidth=0.9, marker=".",
                       linestyle=_JOINT_STYLES[j % len(_JOINT_STYLES)])
            )  # fmt: skip
            labels.append(f"joint {j + 1}")
    ncols = len(handles) if len(handles) <= 4 else -(-len(handles) // 2)
    fig.legend(handles, labels, loc="outside lower center", ncols=ncols, frameon=False)
    _suptitle(
        fig,
        title,
        "Maximum tracking error against payload",
        "not in the paper (extends its Table 2: 0, 2.5 and 5 lb)",
    )
    return fig


def payload_sweep(
    sweep: Mapping[str, Sequence[tuple[float, Sequence[float]]]],
    out: str | Path,
    title: str | None = None,
    *,
    per_joint: bool = True,
) -> Path:
    """Maximum tracking error against payload, one thick line per controller (worst joint).

    Parameters
    ----------
    sweep : mapping of str to sequence of (float, sequence of float)
        Controller label to ``[(payload_kg, max_error_deg_per_joint), ...]`` (any order).
    out : path
        PNG file to write.
    title : str, optional
        First line of the figure title.
    per_joint : bool
        Also draw each joint's maximum error as a thin line of the controller's colour.

    Returns
    -------
    Path
        ``out``.

    Notes
    -----
    The y axis is logarithmic when the plotted errors span more than 2 decades; the top axis
    gives the payload in lb.
    """
    fig = _figure_payload_sweep(sweep, title, per_joint=per_joint)
    return _save(fig, out)
