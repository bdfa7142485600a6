"""Figures of apc runs, as PNG files, one function per figure.

Which function makes which of the paper's figures (the paper's simulation section,
"Computer simulation: a three-joint PUMA robot arm"):

- :func:`errors_by_load` — Figures 3-5: joint 1/2/3 position error under various loads
  (adaptive control, P(0) = P2(0)); one subplot per joint.
- :func:`controller_comparison` — Figures 6-8: case (c), joint 1/2/3 position error using both
  controllers (computed torque, adaptive with P1(0) and P2(0)).
- :func:`applied_torques` — Figure 9: case (c), applied torques of the PD (computed torque) and
  adaptive controllers.
- :func:`pickup` — not in the paper: position errors when the payload is picked up mid-motion.

The identified parameters and the payload sweep are in :mod:`apc_lab.plots_beyond`;
how many samples a run takes to recover from a pick-up is
:func:`apc_lab.metrics.recovery_samples`.

Conventions
-----------
- Error is ``q - q_d`` (deg), torque is the torque applied to the joint (N m).
- apc's angles are the URDF's (standard DH); the paper's joints 2 and 3 turn the other way
  (:func:`apc_lab.scenario.joint_sign_to_paper`). With ``paper_signs=True`` (the default
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

from apc_lab.scenario import joint_sign_to_paper

if TYPE_CHECKING:
    from apc_recording.runs import RecordedRun

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


__all__: Sequence[str] = (
    "applied_torques",
    "controller_comparison",
    "error_deg",
    "errors_by_load",
    "pickup",
)
