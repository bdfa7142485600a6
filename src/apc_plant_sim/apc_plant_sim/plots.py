"""Figures of apc runs, as PNG files, one function per figure.

Which function makes which of the paper's figures (the paper's simulation section,
"Computer simulation: a three-joint PUMA robot arm"):

- :func:`errors_by_load` — Figures 3-5: joint 1/2/3 position error under various loads
  (adaptive control, P(0) = P2(0)); one subplot per joint.
- :func:`controller_comparison` — Figures 6-8: case (c), joint 1/2/3 position error using both
  controllers (computed torque, adaptive with P1(0) and P2(0)).
- :func:`applied_torques` — Figure 9: case (c), applied torques of the PD (computed torque) and
  adaptive controllers.
- :func:`identified_parameters` — not in the paper: the RLS-identified F̂, Ĝ, ŵ (Eqs. 29-31)
  over time, trace(P) and the identification residual.
- :func:`payload_sweep` — not in the paper (extends Table 2): maximum tracking error against
  payload, per controller.
- :func:`pickup` — not in the paper: position errors when the payload is picked up mid-motion.

:func:`recovery_samples` is not a plot: how many samples a run takes to bring every joint back
within a tolerance after a payload pick-up.

Conventions
-----------
- Error is ``q - q_d`` (deg), torque is the torque applied to the joint (N m).
- apc's angles are the URDF's (standard DH); the paper's joints 2 and 3 turn the other way
  (:func:`apc_plant_sim.scenario.joint_sign_to_paper`). With ``paper_signs=True`` (the default
  of the PUMA figures) errors and torques are drawn in the paper's convention and the axis label
  says so ("joint 2 error (deg, paper's sign)").
- Time is the recording's sample time (s); a dotted vertical line marks the end of the move
  (:attr:`RecordedRun.move_end_index`; none when the recording has no scenario).
- An error panel whose lines' peaks span more than 2 decades gets a symmetric-log y axis
  (``yscale="auto"``), labelled as such; pass ``yscale="linear"`` to force a linear one.
- Identified parameters are in apc's sign convention (the diagonal entries drawn do not depend
  on it; ŵ does).

Every figure is built with the object-oriented API (:class:`matplotlib.figure.Figure` on an Agg
canvas): no pyplot, no global state, safe from threads and headless machines. The public
functions write the PNG and return its path; the ``_figure_*`` builders return the
:class:`~matplotlib.figure.Figure` itself (the tests inspect labels and line data there).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from apc_plant_sim.scenario import joint_sign_to_paper

if TYPE_CHECKING:
    from apc_plant_sim.recording import RecordedRun

#: Resolution of every PNG (dots per inch).
DPI = 120
#: Size (in) of a one-panel figure and of three stacked panels.
SIZE_SINGLE = (8.0, 6.0)
SIZE_STACKED = (10.0, 8.0)
KG_PER_LB = 0.45359237

_LINESTYLES = ("-", "--", "-.", ":")
_JOINT_STYLES = ("--", "-.", ":", (0, (5, 2, 1, 2, 1, 2)), (0, (1, 3)), (0, (8, 3)))
_END_STYLE = {"color": "0.25", "linestyle": ":", "linewidth": 1.5}
_PICKUP_STYLE = {"color": "tab:red", "linestyle": "--", "linewidth": 1.2}
_ZERO_STYLE = {"color": "0.75", "linewidth": 0.8, "zorder": 0}
_END_LABEL = "end of move"


# --------------------------------------------------------------------------------------------
# helpers


def _new_figure(size: tuple[float, float], nrows: int = 1, ncols: int = 1, **subplot_kw):
    """A constrained-layout figure on an Agg canvas and its axes (always a 2-D array)."""
    fig = Figure(figsize=size, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False, **subplot_kw)
    return fig, axes


def _save(fig: Figure, out: str | Path) -> Path:
    """Write ``fig`` as PNG to ``out`` (parents created) and return the path."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, format="png", dpi=DPI)
    return out


def _suptitle(fig: Figure, title: str | None, default: str, reference: str) -> None:
    """Title on the first line, the paper figure it corresponds to on the second."""
    fig.suptitle(f"{title or default}\n{reference}", fontsize=12)


def _check_runs(runs: Mapping[str, RecordedRun]) -> int:
    """Number of joints shared by all runs; ValueError if none or if they differ."""
    if not runs:
        raise ValueError("no runs to plot")
    counts = {run.q.shape[1] for run in runs.values()}
    if len(counts) != 1:
        raise ValueError(f"runs have different numbers of joints: {sorted(counts)}")
    return counts.pop()


def _signs(n: int, paper_signs: bool) -> np.ndarray:
    return joint_sign_to_paper(n) if paper_signs else np.ones(n)


def _joint_label(j: int, quantity: str, unit: str, paper_signs: bool) -> str:
    """``"joint 2 error (deg, paper's sign)"``, on two lines so stacked panels' labels fit."""
    convention = ", paper's sign" if paper_signs else ""
    return f"joint {j + 1} {quantity}\n({unit}{convention})"


def error_deg(run: RecordedRun, paper_signs: bool = False) -> np.ndarray:
    """Position error ``q - q_d`` (deg), (N, n), in the paper's sign convention if asked."""
    return np.rad2deg(run.error) * _signs(run.q.shape[1], paper_signs)


def _end_time(run: RecordedRun) -> float:
    """Time of the end of the move; NaN (no line drawn) when the recording has no scenario."""
    scenario = run.run.get("scenario", {}) if run.run else {}
    if "segment_times" not in scenario or "period" not in scenario:
        return float("nan")
    return float(run.t[run.move_end_index])


def _mark_times(axes: Iterable[Axes], times: Iterable[float], style: dict, label: str) -> None:
    """A vertical line at each distinct time on every axis; labelled on the first only."""
    distinct = sorted({round(float(t), 9) for t in times if np.isfinite(t)})
    for i, ax in enumerate(axes):
        for k, t in enumerate(distinct):
            ax.axvline(t, label=label if (i == 0 and k == 0) else None, **style)


def _figure_legend(fig: Figure, ax: Axes) -> None:
    """One legend for the figure, below the panels (hides no line), from ``ax``'s artists.

    Up to four entries (or five short ones) go on one row, more on two rows, so a long
    label is not cut at the figure's edge.
    """
    handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return
    one_row = len(handles) <= 4 or (len(handles) == 5 and sum(map(len, labels)) <= 90)
    ncols = len(handles) if one_row else -(-len(handles) // 2)
    fig.legend(handles, labels, loc="outside lower center", ncols=ncols, frameon=False)


def _style(i: int) -> dict:
    """Colour and dash pattern of the i-th line: lines that coincide stay distinguishable."""
    return {"color": f"C{i % 10}", "linestyle": _LINESTYLES[i % len(_LINESTYLES)]}


def _positive(values: np.ndarray) -> np.ndarray:
    """``values`` with non-positive entries as NaN (for log axes)."""
    values = np.asarray(values, dtype=float).copy()
    values[~(values > 0)] = np.nan
    return values


def _decades(values: np.ndarray) -> float:
    """log10(max / min) of the positive finite entries (0 when fewer than two)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    if v.size < 2:
        return 0.0
    return float(np.log10(v.max() / v.min()))


def _symlog_if_spread(ax: Axes, peaks: Sequence[float], unit: str) -> bool:
    """Symmetric-log y axis when the lines' peak magnitudes span more than 2 decades.

    A linear axis would flatten the smallest line to zero. The linear region is ``±10^m`` with
    ``10^m <= smallest peak < 10^(m+1)``: the smallest line peaks in the first logarithmic decade
    and keeps its shape; a small title over the panel's right end says the axis is not linear.
    """
    if _decades(np.asarray(peaks)) <= 2.0:
        return False
    smallest = min(p for p in peaks if np.isfinite(p) and p > 0)
    linthresh = 10.0 ** np.floor(np.log10(smallest))
    ax.set_yscale("symlog", linthresh=linthresh, linscale=0.5)
    ax.set_title(
        f"symmetric log scale, linear within ±{linthresh:g} {unit}",
        loc="right", fontsize=8, color="0.3", pad=2,
    )  # fmt: skip
    return True


def _figure_joint_series(
    runs: Mapping[str, RecordedRun],
    *,
    title: str | None,
    default_title: str,
    reference: str,
    paper_signs: bool,
    yscale: str,
    extra_times: Sequence[tuple[float, dict, str]] = (),
) -> Figure:
    """Position error of every joint (one panel each), one line per run."""
    n = _check_runs(runs)
    fig, axes = _new_figure(SIZE_STACKED if n <= 3 else (10.0, 2.4 * n + 1.0), n, 1, sharex=True)
    axes = axes[:, 0]
    errors = {label: error_deg(run, paper_signs) for label, run in runs.items()}
    for j, ax in enumerate(axes):
        ax.axhline(0.0, **_ZERO_STYLE)
        peaks = []
        for i, (label, run) in enumerate(runs.items()):
            e = errors[label][:, j]
            ax.plot(run.t, e, label=label, linewidth=1.4, **_style(i))
            peaks.append(float(np.nanmax(np.abs(e))) if np.isfinite(e).any() else np.nan)
        if yscale == "auto":
            _symlog_if_spread(ax, peaks, "deg")
        elif yscale != "linear":
            ax.set_yscale(yscale)
        ax.set_ylabel(_joint_label(j, "error", "deg", paper_signs))
        ax.grid(True, alpha=0.3)
    _mark_times(axes, [_end_time(r) for r in runs.values()], _END_STYLE, _END_LABEL)
    for t, style, label in extra_times:
        _mark_times(axes, [t], style, label)
    t_min = min(float(np.nanmin(r.t)) for r in runs.values())
    t_max = max(float(np.nanmax(r.t)) for r in runs.values())
    axes[-1].set_xlim(t_min, t_max)
    axes[-1].set_xlabel("time (s)")
    _suptitle(fig, title, default_title, reference)
    _figure_legend(fig, axes[0])
    return fig


# --------------------------------------------------------------------------------------------
# Figures 3-5, 6-8 and pick-up: position errors


def _figure_errors_by_load(
    runs: Mapping[str, RecordedRun],
    title: str | None = None,
    *,
    paper_signs: bool = True,
    yscale: str = "auto",
) -> Figure:
    """Build the figure of :func:`errors_by_load` without saving it."""
    return _figure_joint_series(
        runs,
        title=title,
        default_title="Position error under various loads",
        reference="cf. the paper's Figures 3-5 (position error under various loads); "
        "error = q − q_d",
        paper_signs=paper_signs,
        yscale=yscale,
    )


def errors_by_load(
    runs: Mapping[str, RecordedRun],
    out: str | Path,
    title: str | None = None,
    *,
    paper_signs: bool = True,
    yscale: str = "auto",
) -> Path:
    """The paper's Figures 3-5 in one figure: position error per joint, one line per load.

    Parameters
    ----------
    runs : mapping of str to RecordedRun
        Legend label (e.g. ``"no load"``, ``"1.134 kg"``, ``"2.268 kg"``) to run, in legend
        order; all runs must have the same joints.
    out : path
        PNG file to write (parent folders are created).
    title : str, optional
        First line of the figure title; the second names the paper's figures.
    paper_signs : bool
        Draw errors in the paper's sign convention (PUMA: joints 2 and 3 negated).
    yscale : {"auto", "linear", "symlog", ...}
        ``"auto"``: symmetric-log on a panel whose lines' peaks span more than 2 decades.

    Returns
    -------
    Path
        ``out``.
    """
    fig = _figure_errors_by_load(runs, title, paper_signs=paper_signs, yscale=yscale)
    return _save(fig, out)


def _figure_controller_comparison(
    runs: Mapping[str, RecordedRun],
    title: str | None = None,
    *,
    paper_signs: bool = True,
    yscale: str = "auto",
) -> Figure:
    """Build the figure of :func:`controller_comparison` without saving it."""
    return _figure_joint_series(
        runs,
        title=title,
        default_title="Case (c): position error using both controllers",
        reference="cf. the paper's Figures 6-8 (maximum load, 10 % inertia error); error = q − q_d",
        paper_signs=paper_signs,
        yscale=yscale,
    )


def controller_comparison(
    runs: Mapping[str, RecordedRun],
    out: str | Path,
    title: str | None = None,
    *,
    paper_signs: bool = True,
    yscale: str = "auto",
) -> Path:
    """The paper's Figures 6-8 in one figure: case (c) position error per joint, per controller.

    Parameters
    ----------
    runs : mapping of str to RecordedRun
        Legend label (e.g. ``"computed torque"``, ``"adaptive P1(0)"``, ``"adaptive P2(0)"``) to
        run, in legend order.
    out : path
        PNG file to write.
    title : str, optional
        First line of the figure title.
    paper_signs : bool
        Draw errors in the paper's sign convention.
    yscale : {"auto", "linear", "symlog", ...}
        ``"auto"``: symmetric-log on a panel whose lines' peaks span more than 2 decades (a
        controller with errors a hundred times smaller would otherwise be a flat line at 0).

    Returns
    -------
    Path
        ``out``.
    """
    fig = _figure_controller_comparison(runs, title, paper_signs=paper_signs, yscale=yscale)
    return _save(fig, out)


def _figure_pickup(
    runs: Mapping[str, RecordedRun],
    pickup_s: float,
    title: str | None = None,
    *,
    paper_signs: bool = True,
    yscale: str = "auto",
) -> Figure:
    """Build the figure of :func:`pickup` without saving it."""
    return _figure_joint_series(
        runs,
        title=title,
        default_title=f"Payload picked up at t = {pickup_s:g} s",
        reference="not in the paper: payload picked up mid-motion; error = q − q_d",
        paper_signs=paper_signs,
        yscale=yscale,
        extra_times=[(pickup_s, _PICKUP_STYLE, f"payload picked up ({pickup_s:g} s)")],
    )


def pickup(
    runs: Mapping[str, RecordedRun],
    pickup_s: float,
    out: str | Path,
    title: str | None = None,
    *,
    paper_signs: bool = True,
    yscale: str = "auto",
) -> Path:
    """Position error per joint when the payload is picked up mid-motion, one line per controller.

    Parameters
    ----------
    runs : mapping of str to RecordedRun
        Legend label to run.
    pickup_s : float
        Time the payload appears (s, on the runs' time axis); a dashed red line marks it.
    out : path
        PNG file to write.
    title : str, optional
        First line of the figure title.
    paper_signs : bool
        Draw errors in the paper's sign convention.
    yscale : {"auto", "linear", "symlog", ...}
        As in :func:`controller_comparison`.

    Returns
    -------
    Path
        ``out``.
    """
    fig = _figure_pickup(runs, pickup_s, title, paper_signs=paper_signs, yscale=yscale)
    return _save(fig, out)


# --------------------------------------------------------------------------------------------
# Figure 9: applied torques


def _figure_applied_torques(
    runs: Mapping[str, RecordedRun],
    title: str | None = None,
    *,
    paper_signs: bool = True,
    show_nominal: bool = True,
) -> Figure:
    """Build the figure of :func:`applied_torques` without saving it."""
    n = _check_runs(runs)
    signs = _signs(n, paper_signs)
    fig, axes = _new_figure(SIZE_STACKED if n <= 3 else (10.0, 2.4 * n + 1.0), n, 1, sharex=True)
    axes = axes[:, 0]
    first = next(iter(runs.values()))
    for j, ax in enumerate(axes):
        ax.axhline(0.0, **_ZERO_STYLE)
        if show_nominal:
            # u_n(k) is commanded at t[k] and held over [t[k], t[k+1]).
            ax.step(
                first.t,
                first.u_n[:, j] * signs[j],
                where="post",
                color="0.75",
                linewidth=3.0,
                zorder=1,
                label="nominal u_n (feedforward)",
            )
        for i, (label, run) in enumerate(runs.items()):
            # applied[k] is the torque over [t[k-1], t[k]): a "pre" step draws it on that interval.
            ax.step(
                run.t, run.applied[:, j] * signs[j], where="pre", label=label, linewidth=1.3,
                **_style(i),
            )  # fmt: skip
        ax.set_ylabel(_joint_label(j, "torque", "N m", paper_signs))
        ax.grid(True, alpha=0.3)
    _mark_times(axes, [_end_time(r) for r in runs.values()], _END_STYLE, _END_LABEL)
    axes[-1].set_xlim(
        min(float(np.nanmin(r.t)) for r in runs.values()),
        max(float(np.nanmax(r.t)) for r in runs.values()),
    )
    axes[-1].set_xlabel("time (s)")
    _suptitle(
        fig,
        title,
        "Case (c): applied torques",
        "cf. the paper's Figure 9 (PD and adaptive controllers); "
        "each step is the torque held over one sampling period",
    )
    _figure_legend(fig, axes[0])
    return fig


def applied_torques(
    runs: Mapping[str, RecordedRun],
    out: str | Path,
    title: str | None = None,
    *,
    paper_signs: bool = True,
    show_nominal: bool = True,
) -> Path:
    """The paper's Figure 9: applied torque per joint against time, one line per controller.

    ``applied[k]`` is the torque applied over ``[t[k-1], t[k])`` and is drawn as a step over that
    interval (``where="pre"``); row 0 (NaN) draws nothing.

    Parameters
    ----------
    runs : mapping of str to RecordedRun
        Legend label to run.
    out : path
        PNG file to write.
    title : str, optional
        First line of the figure title.
    paper_signs : bool
        Draw torques in the paper's sign convention (joints 2 and 3 negated).
    show_nominal : bool
        Also draw the first run's nominal (feedforward) torque ``u_n`` as a thin dotted step.

    Returns
    -------
    Path
        ``out``.
    """
    fig = _figure_applied_torques(runs, title, paper_signs=paper_signs, show_nominal=show_nominal)
    return _save(fig, out)


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


# --------------------------------------------------------------------------------------------
# recovery after a pick-up


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


__all__: Sequence[str] = (
    "applied_torques",
    "controller_comparison",
    "error_deg",
    "errors_by_load",
    "identified_parameters",
    "payload_sweep",
    "pickup",
    "recovery_samples",
)
